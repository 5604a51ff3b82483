"""benchmarks/correlator_live_stream.py recognises the node's report of the whole stream: the level of a
DiagnosticStatus is a bytes object in rclpy, and the probe compared its ``str`` with ``"3"``, so no report ever
matched and every run waited out the 120-s bound (the benchmark's "hang": 12 runs of about 2.5 min)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from rfi_node_common.diagnostics import diagnostic_array

ROOT = Path(__file__).resolve().parents[1]


def bench():
    sys.path.insert(0, str(ROOT / 'benchmarks'))
    try:
        spec = importlib.util.spec_from_file_location('correlator_live_stream',
                                                      ROOT / 'benchmarks' / 'correlator_live_stream.py')
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # its dataclasses look their module up
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(ROOT / 'benchmarks'))


def test_the_stale_report_of_the_whole_stream_is_recognised():
    b = bench()
    values = {'blocks_received': '290', 'input./rfi/if_samples.lost': '10', 'blocks_held_for_acquisition': '0'}
    # built as the node builds its reports (rfi_node_common.diagnostics), then read as the probe reads them
    stale = diagnostic_array(1, 'gnss_correlator', 'gnss_receiver', DiagnosticStatus.STALE, 'no input', values)
    last = b.status_values(stale.status[0])
    assert last['level'] == '3' and last['blocks_received'] == '290'
    assert b.stream_reported(last, 300)
    assert not b.stream_reported(last, 301)  # a block neither received nor counted lost: not the end yet
    ok = DiagnosticStatus(level=DiagnosticStatus.OK, name='gnss_correlator',
                          values=[KeyValue(key=k, value=v) for k, v in values.items()])
    assert not b.stream_reported(b.status_values(ok), 300)
    held = b.status_values(stale.status[0]) | {'blocks_held_for_acquisition': '3'}
    assert not b.stream_reported(held, 300)  # the first acquisition still running: its blocks not answered yet


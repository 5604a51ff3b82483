"""The default experiment (bags/default) replayed through the three nodes, checked against bars
from the papers and the issues, with every input accounted for.

The whole bag goes through the nodes with the direct transport (the same callbacks, messages handed
over in-process: 180 s of data in about 15 s); a window goes through the middleware on one
executor, at maximum rate and at 1x, and must give the same outputs.

Bars (loose enough to hold across seeds, tight enough to fail when an algorithm breaks):
- rfi_monitor: no false alarm on jammer-free blocks; >= 80 % of the blocks with a detectable jammer
  (true J/N >= 6 dB) or none classified right; sweep period within 1 % (Kang et al. / issue);
  J/S within 2 dB where a jammer is reported;
- uwb_gnss_fusion: with 3 anchors, horizontal RMS < 0.2 m in every J/S phase up to 22 dB (issue
  goal after Cao et al.), and better than the GNSS-only filter;
- imm_carrier: zero IMM half-cycle slips and IMM phase error std <= 12 deg (Zhao et al.).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import rclpy
from ros_fixtures import make_context

from imm_carrier.imm_carrier_node import ImmCarrierNode
from rfi_experiments.bag_io import BagReader
from rfi_experiments.replay import ReplayHarness
from rfi_experiments.report import write_report
from rfi_experiments.run import load_params_files, overrides_for
from rfi_monitor.rfi_monitor_node import RfiMonitorNode
from uwb_gnss_fusion.fusion_node import FusionNode

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
PARAMS = load_params_files([str(ROOT / 'bags' / 'default.params.yaml')])
INPUTS = ['/gnss/correlators', '/gnss/measurements', '/rfi/if_samples', '/uwb/ranges']
NODES = (('rfi_monitor', RfiMonitorNode), ('uwb_gnss_fusion', FusionNode), ('imm_carrier', ImmCarrierNode))


def replay(transport, *, rate=None, window_s=None):
    context = make_context()
    nodes = []
    try:
        nodes = [cls(context=context, parameter_overrides=overrides_for(name, PARAMS)) for name, cls in NODES]
        harness = ReplayHarness(nodes, context=context, transport=transport)
        result = harness.run(BAG, topics=INPUTS, rate=rate, window_s=window_s)
        harness.destroy()
        return result
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.fixture(scope='module')
def full(tmp_path_factory):
    result = replay('direct')
    outputs = {t: result.messages(t) for t in ('/rfi/jammer_state', '/fusion/odometry', '/carrier/estimates')}
    summary = write_report(BAG, outputs, tmp_path_factory.mktemp('report'))
    return result, summary.values


def test_every_input_replayed(full):
    result, _ = full
    with BagReader(BAG) as reader:
        assert result.inputs == {t: reader.topics[t][1] for t in INPUTS}


def last_status(result, name):
    for array in reversed(result.messages('/diagnostics')):
        for status in array.status:
            if status.name == name:
                stamp_ns = array.header.stamp.sec * 1_000_000_000 + array.header.stamp.nanosec
                return stamp_ns, {kv.key: kv.value for kv in status.values}
    raise AssertionError(f'no diagnostics from {name}')


def accounted(topic, received, stamp_ns):
    """A node's diagnostics at ``stamp_ns`` count every input stamped before it; an input with that
    very stamp may come just after the one that triggered the report."""
    with BagReader(BAG) as reader:
        stamps = [m.stamp_ns for m in reader.messages([topic])]
    before = sum(1 for t in stamps if t < stamp_ns)
    up_to = sum(1 for t in stamps if t <= stamp_ns)
    return before <= int(received) <= up_to and before > 0


def test_every_input_accounted_for_in_diagnostics(full):
    result, _ = full
    stamp_ns, monitor = last_status(result, 'rfi_monitor')
    assert monitor['accounting_ok'] == 'True'
    assert accounted('/rfi/if_samples', monitor['blocks_received'], stamp_ns)
    stamp_ns, fusion = last_status(result, 'uwb_gnss_fusion')
    assert fusion['accounting_ok'] == 'True'
    assert accounted('/gnss/measurements', fusion['gnss_received'], stamp_ns)
    assert accounted('/uwb/ranges', fusion['uwb_received'], stamp_ns)
    stamp_ns, carrier = last_status(result, 'imm_carrier')
    assert carrier['accounting_ok'] == 'True'
    assert accounted('/gnss/correlators', carrier['arrays_received'], stamp_ns)


def test_rfi_monitor_bars(full):
    _, values = full
    assert values['jammer_false_alarms'] == 0
    assert values['jammer_type_correct'] >= 0.8 * values['jammer_blocks_scored']
    assert values['sweep_period_error_median_pct'] < 1.0
    assert values['js_error_median_abs_db'] < 2.0


def jammer_pairs(result):
    """(truth, state) of every /rfi/jammer_state with a /truth/jammer of the same stamp."""
    with BagReader(BAG) as reader:
        truth = {(m.header.stamp.sec, m.header.stamp.nanosec): m
                 for m in (b.decode() for b in reader.messages(['/truth/jammer']))}
    return [(truth[k], s) for s in result.messages('/rfi/jammer_state')
            if (k := (s.header.stamp.sec, s.header.stamp.nanosec)) in truth]


def test_jammer_figure_shows_what_it_says(full):
    """Issue 27 item 5, what the demo's jammer figure draws: every sweep period published is within 1 % of the truth
    (before: 3 blocks of the +6 dB chirp phase at 10.2 us, twice the 5.10 us), and a block reported NONE carries no
    J/S (before: about -2 dB, drawn through the jammer-free blocks)."""
    result, _ = full
    pairs = jammer_pairs(result)
    assert len(pairs) == 180
    periods = [(t.header.stamp.sec, s.sweep_period_s / t.sweep_period_s) for t, s in pairs
               if s.type == 2 and t.type == 2 and math.isfinite(s.sweep_period_s)]
    assert len(periods) >= 70
    assert all(abs(q - 1.0) < 0.01 for _, q in periods), [p for p in periods if abs(p[1] - 1.0) >= 0.01]
    none = [s for _, s in pairs if s.type == 0]
    assert len(none) >= 40
    assert all(math.isnan(s.jammer_to_signal_db) and math.isfinite(s.jammer_to_noise_db) for s in none)
    assert all(math.isfinite(s.jammer_to_signal_db) for _, s in pairs if s.type in (1, 2))


def test_fusion_bars(full):
    _, values = full
    assert values['fusion_worst_phase_rms_up_to_22db_m'] < 0.2
    assert values['horizontal_rms_m[GNSS+UWB (fusion_node)]'] < values['horizontal_rms_m[GNSS filter]']


def test_carrier_bars(full):
    _, values = full
    assert values['imm_slips'] == 0
    assert values['imm_worst_std_deg'] <= 12.0


def fields(msg):
    """A message as nested tuples, NaN-safe, for comparing outputs whatever their padding bytes."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return tuple((name, fields(getattr(msg, name))) for name in msg.get_fields_and_field_types())
    if isinstance(msg, (list, tuple)) or type(msg).__name__ == 'array' or hasattr(msg, 'tolist'):
        return tuple(fields(v) for v in (msg.tolist() if hasattr(msg, 'tolist') else msg))
    if isinstance(msg, float) and math.isnan(msg):
        return 'nan'
    return msg


def outputs_of(result):
    return {t: [fields(m) for m in result.messages(t)] for t in result.outputs}


def test_middleware_replay_matches_direct_and_does_not_depend_on_speed():
    # 3 s around the CW onset: every input type, jammer states reaching the fusion
    window = (28.0, 31.0)
    over_dds = replay('dds', window_s=window)
    paced = replay('dds', rate=1.0, window_s=window)
    direct = replay('direct', window_s=window)
    assert sum(over_dds.inputs.values()) > 300
    assert outputs_of(over_dds) == outputs_of(paced) == outputs_of(direct)

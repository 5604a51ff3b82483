"""Pure helpers of `run` and `play`: the bag window, the --ros-args to pass on, and how a processes
run splits the bag into play runs (no ROS graph)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.play import due_offset_s, window_ns, window_s
from rfi_experiments.processes import _segment, reliable_input_arguments, ros_arguments

BAG = Path(__file__).resolve().parents[3] / 'bags' / 'default'
INPUTS = ['/gnss/correlators', '/gnss/measurements', '/rfi/if_samples', '/uwb/ranges']


def test_window_seconds_and_nanoseconds():
    assert window_s(0.0, None) is None
    assert window_s(2.0, None) == (2.0, math.inf)
    assert window_s(2.0, 3.0) == (2.0, 5.0)
    assert window_ns(100, None) == (None, None)
    assert window_ns(100, (2.0, math.inf)) == (2_000_000_100, None)
    assert window_ns(100, (2.0, 5.0)) == (2_000_000_100, 5_000_000_100)


@pytest.mark.parametrize('start, duration, word', [(-1.0, None, '--start'), (math.nan, None, '--start'),
                                                   (0.0, 0.0, '--duration'), (0.0, math.inf, '--duration')])
def test_bad_window_is_a_clear_error(start, duration, word):
    with pytest.raises(ValueError, match=word):
        window_s(start, duration)


def test_ros_arguments_are_the_ros_args_sections_only():
    argv = ['run', 'bag', '--out', 'x', '--ros-args', '-r', '/a:=/b', '--', '--rate', '2', '--ros-args', '-p', 'k:=1']
    assert ros_arguments(argv) == ['--ros-args', '-r', '/a:=/b', '--', '--ros-args', '-p', 'k:=1']
    assert ros_arguments(['run', 'bag']) == []


def test_window_segment_counts_and_last_stamps():
    with BagReader(BAG) as reader:
        seg = _segment(reader, INPUTS, 28.0, 3.0)
        tail = _segment(reader, INPUTS, 178.0, None)
    assert seg.counts == {'/gnss/correlators': 150, '/gnss/measurements': 15, '/rfi/if_samples': 3,
                          '/uwb/ranges': 180}
    # the last IF block (30 s), GNSS or UWB input (a range at 30.983 s) and correlator array (30.98 s)
    # of the window, header stamps: what each node's last output must be stamped with
    assert seg.last_input == {'rfi_monitor': 1437267613_000_000_000, 'uwb_gnss_fusion': 1437267613_983_333_333,
                              'imm_carrier': 1437267613_980_000_000}   # ROS (UTC) stamps: GPS time - 17 s
    assert tail.duration_s is None and tail.counts['/rfi/if_samples'] == 2


def test_play_pace_with_a_slow_start():
    assert due_offset_s(2.0, 1.0) == 2.0
    assert due_offset_s(0.3, 2.0, warmup_s=0.5, warmup_rate=0.1) == pytest.approx(3.0)
    assert due_offset_s(1.5, 2.0, warmup_s=0.5, warmup_rate=0.1) == pytest.approx(5.0 + 0.5)


def test_processes_make_each_nodes_inputs_reliable():
    """The nodes' inputs are best effort by default; a replay through processes overrides them to
    reliable (also under the remapped name, which is what the node declares the override for)."""
    assert reliable_input_arguments(['/rfi/if_samples']) == [
        '-p', 'qos_overrides./rfi/if_samples.subscription.reliability:=reliable']
    remap = {'/rfi/jammer_state': '/truth/jammer_state'}
    assert reliable_input_arguments(['/uwb/ranges', '/rfi/jammer_state'], lambda t: remap.get(t, t))[1::2] == [
        'qos_overrides./uwb/ranges.subscription.reliability:=reliable',
        'qos_overrides./rfi/jammer_state.subscription.reliability:=reliable',
        'qos_overrides./truth/jammer_state.subscription.reliability:=reliable']


def test_delivery_warnings_name_late_rejections_and_losses():
    """`run` states in its summary what the nodes rejected as late or counted lost (issue #12: 566
    UWB ranges rejected by the fusion in one replay through processes, with no word in the summary)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from rfi_experiments.replay import ReplayResult
    from rfi_experiments.run import delivery_warnings
    from rfi_msgs.msg import FusionStatus

    def diagnostics(name, values):
        return DiagnosticArray(status=[DiagnosticStatus(name=name, values=[
            KeyValue(key=k, value=str(v)) for k, v in values.items()])])

    one_rejection = diagnostics('uwb_gnss_fusion', {'rejected.stamp_far_past': 1})
    quiet = ReplayResult(outputs={'/diagnostics': [(1, one_rejection)]},
                         output_types={'/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'})
    assert delivery_warnings(quiet) == []
    status = FusionStatus(rejection_reasons=['innovation_gate_pseudorange', 'late_beyond_reorder_window'],
                          rejection_counts=[3, 566])
    loaded = ReplayResult(
        outputs={'/fusion/status': [(2, status)],
                 '/diagnostics': [(1, diagnostics('uwb_gnss_fusion', {'rejected.late_beyond_reorder_window': 500,
                                                                      'reorder_window_s': 0.75,
                                                                      'input./uwb/ranges.lost': 0})),
                                  (3, diagnostics('rfi_monitor', {'input./rfi/if_samples.lost': 1,
                                                                  'input./rfi/if_samples.middleware_lost': 2}))]},
        output_types={'/fusion/status': 'rfi_msgs/msg/FusionStatus',
                      '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'})
    late, lost = delivery_warnings(loaded)
    assert 'the fusion node rejected 566 messages' in late and 'now 0.75 s' in late
    assert lost.endswith('/rfi/if_samples 2')  # issue 27: the same loss seen twice is not counted twice


def test_parameters_file_follows_the_namespace(tmp_path):
    """A plain node key means the node at the root; under --namespace the suite's file is rewritten
    so /robot1/rfi_monitor gets its parameters (a J/S off by 10 dB showed it did not)."""
    import yaml

    from rfi_experiments.processes import namespaced_params_file

    src = tmp_path / 'p.yaml'
    src.write_text('rfi_monitor:\n  ros__parameters:\n    noise_bandwidth_hz: 2.0e6\n'
                   '/**:\n  ros__parameters:\n    use_sim_time: false\n')
    assert namespaced_params_file(src, '/', tmp_path / 'w') == src.resolve()
    text = namespaced_params_file(src, '/robot1', tmp_path / 'w').read_text()
    # the key moved, every value kept as written (2.0e6 stays a double for rcl)
    assert text == src.read_text().replace('rfi_monitor:', '/robot1/rfi_monitor:')
    assert set(yaml.safe_load(text)) == {'/robot1/rfi_monitor', '/**'}

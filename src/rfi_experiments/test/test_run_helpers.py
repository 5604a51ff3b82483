"""Pure helpers of `run` and `play`: the bag window, the --ros-args to pass on, and how a processes
run splits the bag into play runs (no ROS graph)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from rfi_experiments.bag_io import BagReader
from rfi_experiments.play import due_offset_s, window_ns, window_s
from rfi_experiments.run import _segment, ros_arguments

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
    # the last IF block (30 s) and correlator array (30.98 s) of the window, header stamps
    assert seg.last_input == {'rfi_monitor': 1437267630_000_000_000, 'imm_carrier': 1437267630_980_000_000}
    assert tail.duration_s is None and tail.counts['/rfi/if_samples'] == 2


def test_play_pace_with_a_slow_start():
    assert due_offset_s(2.0, 1.0) == 2.0
    assert due_offset_s(0.3, 2.0, warmup_s=0.5, warmup_rate=0.1) == pytest.approx(3.0)
    assert due_offset_s(1.5, 2.0, warmup_s=0.5, warmup_rate=0.1) == pytest.approx(5.0 + 0.5)

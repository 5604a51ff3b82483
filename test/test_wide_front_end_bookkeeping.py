"""The bookkeeping of benchmarks/rfi_monitor_wide_front_end.py (issue 26 item 4): what counts as "every block analysed
in full, on time", which rate of the ladder is the deliverable, and the CPU read between two instants. No timing."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'benchmarks'))

import rfi_monitor_wide_front_end as wide  # noqa: E402


def _result(band='l1', blocks=4, light=0, shed=0, lost=0, latencies=(5.0, 6.0, 7.0, 8.0)) -> wide.BandResult:
    processed = blocks - shed
    r = wide.BandResult(band, blocks, blocks, processed, light, shed, lost, 0)
    r.latencies_ms = list(latencies)
    return r


def test_band_result_reads_the_nodes_report():
    diag = {'blocks_received': '10', 'blocks_processed': '8', 'blocks_light': '3', 'blocks_shed': '1',
            'rejected_blank_block': '1', 'rejected_stamp_not_increasing': '0',
            'input./wide_l1/rfi/if_samples.lost': '2', 'input./wide_l1/rfi/if_samples.received': '10'}
    r = wide.band_result('l1', 12, diag)
    assert (r.received, r.processed, r.light, r.shed, r.lost, r.rejected) == (10, 8, 3, 1, 2, 1)
    assert r.full == 5


def test_in_full_on_time_needs_every_block_full_and_every_answer_under_the_bound():
    assert _result().in_full_on_time()
    assert not _result(light=1).in_full_on_time()
    assert not _result(shed=1, latencies=(5.0, 6.0, 7.0)).in_full_on_time()
    assert not _result(lost=1).in_full_on_time()
    assert not _result(latencies=(5.0, 6.0, 7.0)).in_full_on_time()          # an answer missing here
    assert not _result(latencies=(5.0, 6.0, 7.0, wide.LATENCY_GOAL_MS)).in_full_on_time()
    assert _result(latencies=(5.0, 6.0, 7.0, wide.LATENCY_GOAL_MS - 0.1)).in_full_on_time()


def test_the_deliverable_is_the_highest_rate_below_the_first_failure():
    good, bad = [_result('l1'), _result('l2')], [_result('l1'), _result('l2', light=2)]
    assert wide.highest_rate_in_full([(10e6, bad), (2.5e6, good), (20e6, good), (5e6, good)]) == 5e6
    assert wide.highest_rate_in_full([(2.5e6, good), (5e6, good), (5e6, bad)]) == 2.5e6   # every repeat must pass
    assert wide.highest_rate_in_full([(2.5e6, bad), (5e6, good)]) is None
    assert wide.highest_rate_in_full([(2.5e6, [])]) is None


def test_cpu_between_interpolates_and_holds_after_the_process_ended():
    samples = [(10.0, 1.0), (11.0, 1.5), (12.0, 2.5)]
    assert wide.cpu_between(samples, 10.5, 11.5) == pytest.approx(0.75)
    assert wide.cpu_between(samples, 11.0, 20.0) == pytest.approx(1.0)     # ended at 12 s: its last reading holds
    assert math.isnan(wide.cpu_between(samples[:1], 10.0, 11.0))
    assert math.isnan(wide.cpu_between(samples, 11.0, 11.0))


def test_the_81_ms_s_extrapolation_follows_the_dearer_case_on_a_straight_line():
    costs = {2.5e6: ((1.0, 0.1), (0.5, 0.2)), 10e6: ((9.0, 0.0), (9.0, 0.0)), 20e6: ((2.0, 0.3), (3.0, 0.3))}
    assert wide.extrapolated_full_ms(costs, 81e6) == pytest.approx(1.0 + 2.0 * (81 - 2.5) / (20 - 2.5))
    assert math.isnan(wide.extrapolated_full_ms({2.5e6: ((1.0, 0.1), (0.5, 0.2))}, 81e6))

"""The load policy (issue 26 item 1): replays in full, always; shedding and the light analysis for live streams only.

Pure: clock readings are passed in, no rclpy.
"""

from __future__ import annotations

import math

import pytest

from rfi_monitor.load_policy import (
    FULL,
    LIGHT,
    LIGHT_QUEUE_S,
    LIVE_BOUND_S,
    SHED,
    SHED_CREDIT_CAP_S,
    LoadPolicy,
    LoadPolicyParams,
    is_live_stamp,
)

NOW_NS = 1_800_000_000_000_000_000
MS = 1_000_000


def test_live_is_a_stamp_within_the_bound_of_the_receive_clock_either_side():
    bound_ns = int(LIVE_BOUND_S * 1e9)
    assert is_live_stamp(NOW_NS, NOW_NS)
    assert is_live_stamp(NOW_NS - bound_ns, NOW_NS) and is_live_stamp(NOW_NS + bound_ns, NOW_NS)
    assert not is_live_stamp(NOW_NS - bound_ns - 1, NOW_NS) and not is_live_stamp(NOW_NS + bound_ns + 1, NOW_NS)
    assert not is_live_stamp(1_700_000_000_000_000_000, NOW_NS)          # a bag recorded in 2023
    assert is_live_stamp(NOW_NS - 3 * 10**9, NOW_NS, live_bound_s=5.0)


@pytest.mark.parametrize('params', [LoadPolicyParams(), LoadPolicyParams(max_cpu_load=1e-6),
                                    LoadPolicyParams(max_cpu_load=1e-6, light_analysis_debt_s=0.0),
                                    LoadPolicyParams(max_block_age_s=0.0)])
@pytest.mark.parametrize('pace', ['max', 'rate 1', 'rate 10'])
def test_a_replay_gets_the_full_analysis_on_every_block_whatever_it_costs(params, pace):
    """A stream whose first block is stamped 10 s in the past (a bag): every block FULL, however much CPU each
    block costs, however long it waited in the queue and however far behind the clock it is; none light, none shed,
    all counted as not live."""
    policy = LoadPolicy(params)
    step_ns = {'max': 0, 'rate 1': MS, 'rate 10': MS // 10}[pace]
    t0 = NOW_NS - 10 * 10**9
    modes = []
    for k in range(200):
        receive = NOW_NS + k * step_ns
        modes.append(policy.decide(t0 + k * MS, receive, covered_s=1e-3, queued_s=0.5 if pace == 'max' else 0.0))
        policy.spend(5e-3)                                 # 5 ms per 1 ms block: far over any budget
    assert modes == [FULL] * 200
    assert policy.live is False
    assert policy.counts == {'full': 200, 'not_live': 200}
    assert policy.debt_s == 0.0


def test_a_live_stream_over_budget_gets_light_then_shed_and_counts_each():
    """A live stream at 1 ms per block that costs 3 ms of CPU per block (light 1.5 ms) with max_cpu_load 0.9: in
    credit at first (FULL), then LIGHT while the debt is within light_analysis_debt_s, then SHED; each counted."""
    policy = LoadPolicy(LoadPolicyParams(max_cpu_load=0.9, light_analysis_debt_s=0.02, max_block_age_s=0.0))
    modes = []
    for k in range(300):
        stamp = NOW_NS + k * MS
        mode = policy.decide(stamp, stamp + MS // 2, covered_s=1e-3, queued_s=0.0)
        modes.append(mode)
        policy.spend({FULL: 3e-3, LIGHT: 1.5e-3, SHED: 1e-5}[mode])
    assert policy.live is True
    assert modes[0] == FULL
    assert LIGHT in modes and SHED in modes
    assert modes.index(LIGHT) < modes.index(SHED)
    c = policy.counts
    assert c['full'] == modes.count(FULL) and c['light'] == modes.count(LIGHT) and c['shed'] == modes.count(SHED)
    assert c['full'] + c['light'] + c['shed'] == 300 and c['not_live'] == 0
    assert policy.debt_s <= SHED_CREDIT_CAP_S


def test_a_live_stream_within_budget_is_analysed_in_full():
    policy = LoadPolicy(LoadPolicyParams(max_cpu_load=0.9))
    for k in range(100):
        stamp = NOW_NS + k * MS
        assert policy.decide(stamp, stamp + MS, covered_s=1e-3, queued_s=0.0) == FULL
        policy.spend(0.5e-3)
    assert policy.counts['full'] == 100


def test_live_blocks_that_waited_or_lag_get_the_light_analysis_and_stale_ones_are_shed():
    """LIGHT_QUEUE_S and LIGHT_LAG_FRACTION of max_block_age_s (live only), max_block_age_s sheds (counted as
    shed_stale); the light analysis needs light_allowed (estimator stft) and light_analysis_debt_s > 0."""
    policy = LoadPolicy(LoadPolicyParams(max_block_age_s=0.05))
    assert policy.decide(NOW_NS, NOW_NS, 1e-3, queued_s=0.0) == FULL
    assert policy.decide(NOW_NS + MS, NOW_NS + MS, 1e-3, queued_s=5 * LIGHT_QUEUE_S) == LIGHT
    assert policy.decide(NOW_NS + 2 * MS, NOW_NS + 2 * MS + 20 * MS, 1e-3, queued_s=None) == LIGHT   # 20 ms behind
    assert policy.decide(NOW_NS + 3 * MS, NOW_NS + 3 * MS + 60 * MS, 1e-3, queued_s=None) == SHED    # 60 ms behind
    assert policy.counts['shed_stale'] == 1 and policy.counts['shed'] == 1
    for params in (LoadPolicyParams(light_allowed=False), LoadPolicyParams(light_analysis_debt_s=0.0),
                   LoadPolicyParams(max_cpu_load=0.0)):
        p = LoadPolicy(params)
        assert p.decide(NOW_NS, NOW_NS, 1e-3, queued_s=5 * LIGHT_QUEUE_S) == FULL


def test_liveness_is_judged_again_after_a_stamp_restart():
    """A replay whose time line restarts at the clock (a confirmed stamp jump) becomes live, and the reverse."""
    policy = LoadPolicy(LoadPolicyParams(max_cpu_load=1e-6))
    assert policy.decide(NOW_NS - 100 * 10**9, NOW_NS, 1e-3) == FULL and policy.live is False
    policy.restart()
    assert policy.live is None
    assert policy.decide(NOW_NS, NOW_NS, 1e-3) == FULL and policy.live is True   # first block: in credit
    policy.spend(1.0)
    assert policy.decide(NOW_NS + MS, NOW_NS + MS, 1e-3) in (LIGHT, SHED)
    policy.restart()
    assert policy.decide(NOW_NS - 100 * 10**9, NOW_NS + 2 * MS, 1e-3) == FULL and policy.live is False
    assert policy.debt_s == 0.0


@pytest.mark.parametrize('name', ['max_cpu_load', 'light_analysis_debt_s', 'max_block_age_s', 'live_bound_s'])
@pytest.mark.parametrize('value', [-1.0, math.nan])
def test_invalid_settings_raise(name, value):
    with pytest.raises(ValueError, match=name):
        LoadPolicyParams(**{name: value})


def test_a_live_block_received_on_time_but_queued_past_the_age_limit_is_shed():
    """The age limit bounds the answer's lag: it is judged when the block is handled (reception + time queued), so a
    block that arrived on time and then waited behind slow analyses is shed, not analysed late (before: light)."""
    policy = LoadPolicy(LoadPolicyParams(max_cpu_load=0.9, light_analysis_debt_s=0.02, max_block_age_s=0.05))
    assert policy.decide(NOW_NS, NOW_NS, 1e-3, queued_s=0.0) == FULL
    assert policy.decide(NOW_NS + MS, NOW_NS + MS, 1e-3, queued_s=0.2) == SHED
    assert policy.counts['shed_stale'] == 1
    assert policy.decide(NOW_NS + 2 * MS, NOW_NS + 2 * MS, 1e-3, queued_s=0.03) == LIGHT   # 30 ms: light, not shed

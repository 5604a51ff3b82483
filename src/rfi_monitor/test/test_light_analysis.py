"""The light analysis of a block (``RfiMonitor.process(light=True)``, session 11, issue 14 item 6): what a node behind
its stream asks for instead of shedding a block. It must never publish what the full analysis would contradict: it
keeps the last full analysis's type only while the block's spectrum agrees, and escalates to the full analysis when
a jammer appears, leaves, changes power or the last full analysis is too old."""

import dataclasses
import math

import numpy as np
import pytest

from rfi_monitor.classifier import CHIRP, CW, NONE
from rfi_monitor.light_analysis import LIGHT_JN_TOLERANCE_DB, LIGHT_MAX_AGE_QUIET_S, LIGHT_MAX_AGE_S
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams

FS = 16.368e6
FIF = 4.092e6
N = 16368                       # 1 ms blocks
BLOCK_NS = 1_000_000


def noise(k: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed * 1000 + k).standard_normal(N)


def sawtooth(k: int, jn_db: float, seed: int = 0) -> np.ndarray:
    """Block k of a continuous saw-tooth, 6 MHz in 12 us around the IF, at J/N jn_db, plus unit noise."""
    t = (np.arange(N) + k * N) / FS
    tau = np.mod(t, 12e-6)
    phase = 2 * np.pi * (FIF * t - 3e6 * tau + 0.5 * (6e6 / 12e-6) * tau ** 2)
    return math.sqrt(2 * 10 ** (jn_db / 10)) * np.cos(phase) + noise(k, seed)


def tone(k: int, jn_db: float, f_hz: float = 1.2e6, seed: int = 0) -> np.ndarray:
    t = (np.arange(N) + k * N) / FS
    return math.sqrt(2 * 10 ** (jn_db / 10)) * np.cos(2 * np.pi * (FIF + f_hz) * t) + noise(k, seed)


def feed(mon: RfiMonitor, k: int, x: np.ndarray, light: bool, stamp_ns: int | None = None):
    return mon.process(x, FS, FIF, k * N, k * BLOCK_NS if stamp_ns is None else stamp_ns, light=light)


def quiet_monitor(blocks: int = 12, seed: int = 1) -> RfiMonitor:
    """A monitor that has learned its floor on noise blocks 0..blocks-1 (full analyses)."""
    mon = RfiMonitor(RfiMonitorParams())
    for k in range(blocks):
        est = feed(mon, k, noise(k, seed), light=False)
    assert est.type == NONE and not est.light
    return mon


def test_quiet_blocks_get_a_light_none_and_a_chirp_that_switches_on_escalates():
    mon = quiet_monitor()
    est = feed(mon, 12, noise(12, 1), light=True)
    assert est.valid and est.light and est.type == NONE and math.isfinite(est.jammer_to_noise_db)
    assert est.counters["light_blocks"] == 1 and est.counters["light_escalations"] == 0
    # the chirp switches on: the light request is answered by the full analysis (a frequency tracked)
    on = feed(mon, 13, sawtooth(13, 15.0), light=True)
    assert not on.light and on.type == CHIRP and math.isfinite(on.frequency_hz)
    assert on.counters["light_escalations"] == 1


def test_a_tracked_chirp_keeps_its_sweep_and_loses_its_frequency_in_light_blocks():
    mon = RfiMonitor(RfiMonitorParams())
    full = [feed(mon, k, sawtooth(k, 15.0), light=False) for k in range(4)]
    assert all(e.type == CHIRP for e in full)
    last = full[-1]
    twin = RfiMonitor(RfiMonitorParams())
    for k in range(4):
        feed(twin, k, sawtooth(k, 15.0), light=False)
    for k in range(4, 8):
        x = sawtooth(k, 15.0)
        est = feed(mon, k, x, light=True)
        ref = feed(twin, k, x, light=False)            # what the full analysis says of the same block
        assert est.light and est.type == CHIRP == ref.type
        assert math.isnan(est.frequency_hz) and math.isnan(est.frequency_std_hz)
        assert est.sweep_period_s == last.sweep_period_s and est.sweep_shape == last.sweep_shape
        assert est.sweep_bandwidth_hz == last.sweep_bandwidth_hz
        assert abs(est.sweep_period_s - 12e-6) < 0.01 * 12e-6
        assert abs(est.jammer_to_noise_db - ref.jammer_to_noise_db) < 1.0
        assert est.stamp_ns == k * BLOCK_NS and est.first_sample_index == k * N


def test_a_chirp_that_switches_off_or_changes_power_escalates():
    mon = RfiMonitor(RfiMonitorParams())
    for k in range(4):
        feed(mon, k, sawtooth(k, 15.0), light=False)
    weaker = feed(mon, 4, sawtooth(4, 15.0 - 2 * LIGHT_JN_TOLERANCE_DB), light=True)
    assert not weaker.light and weaker.type == CHIRP
    off = feed(mon, 5, noise(5, 3), light=True)
    assert not off.light and off.type != CHIRP
    assert off.counters["light_escalations"] == 2


def test_a_cw_keeps_its_frequency_measured_in_the_light_block():
    mon = quiet_monitor()
    twin = quiet_monitor()
    for k in (12, 13):
        feed(mon, k, tone(k, 10.0), light=False)
        feed(twin, k, tone(k, 10.0), light=False)
    x = tone(14, 10.0)
    est = feed(mon, 14, x, light=True)
    ref = feed(twin, 14, x, light=False)
    assert est.light and est.type == CW == ref.type
    assert est.frequency_hz == pytest.approx(ref.frequency_hz, abs=1e-6)
    assert abs(est.frequency_hz - 1.2e6) < FS / 256


def test_an_old_full_analysis_is_not_carried():
    """A NONE is carried for LIGHT_MAX_AGE_QUIET_S of stamps, a jammer for LIGHT_MAX_AGE_S; older: the full analysis."""
    mon = quiet_monitor()
    last = 11 * BLOCK_NS
    within = feed(mon, 12, noise(12, 1), light=True, stamp_ns=last + int(LIGHT_MAX_AGE_QUIET_S * 1e9))
    assert within.light
    mon = quiet_monitor()
    late = feed(mon, 12, noise(12, 1), light=True, stamp_ns=last + int(LIGHT_MAX_AGE_QUIET_S * 1e9) + 1)
    assert not late.light and late.counters["light_escalations"] == 1
    mon = RfiMonitor(RfiMonitorParams())
    for k in range(4):
        feed(mon, k, sawtooth(k, 15.0), light=False)
    est = feed(mon, 4, sawtooth(4, 15.0), light=True, stamp_ns=3 * BLOCK_NS + int(LIGHT_MAX_AGE_S * 1e9) + 1)
    assert not est.light and est.type == CHIRP


def test_before_the_floor_is_learned_a_light_none_uses_the_last_in_block_noise_level():
    """A node behind its stream from its first blocks (its start-up) answers them light too: before a floor is learned
    the light NONE's power J/N is against the last full analysis's in-block noise level; a jammer still escalates."""
    mon = RfiMonitor(RfiMonitorParams())
    feed(mon, 0, noise(0, 1), light=False)
    est = feed(mon, 1, noise(1, 1), light=True)
    assert est.light and est.type == NONE and est.noise_reference == 0      # REF_IN_BLOCK, as the full analysis's
    on = feed(mon, 2, tone(2, 10.0), light=True)
    assert not on.light and on.type == CW


def test_the_kalman_estimator_ignores_the_light_request():
    mon = RfiMonitor(dataclasses.replace(RfiMonitorParams(), estimator="kalman"))
    for k in range(3):
        est = feed(mon, k, noise(k, 1), light=True)
        assert not est.light

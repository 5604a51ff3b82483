"""Tracking mode (ours): the LPD / AR(10) / peak pass is suspended while the step-fit lattice is
confirmed and resumed when fits fail (tracker module docstring). Checks that the estimates do not
change while it is suspended, that a jammer change is still noticed at once, and that block
splitting still gives bit-identical traces across suspensions and resumptions."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rfi_monitor.classifier import CHIRP, CW, NONE
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_monitor.sweep_analysis import SweepAnalysisParams
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator

FS = 38.192e6
FIF = 9.548e6
JN_DB = 15.0
F0 = 0.1832 * FS - FIF
PAPER_CHIRP = ChirpJammer(start_frequency_hz=F0)                     # 1e12 Hz/s, 5.1 us
SLOWER_CHIRP = ChirpJammer(start_frequency_hz=F0, sweep_rate_hz_per_s=7e11, sweep_period_s=2 * abs(F0) / 7e11)
BLK = 3819                                                           # 0.1 ms


def _front_end() -> FrontEndConfig:
    # J/N over the sampled band (benchmarks/rfi_monitor_paper.py), J/S 30 dB
    return FrontEndConfig(noise_density_dbm_per_mhz=-130.0 + 30.0 - JN_DB - 10 * math.log10(FS / 2 / 1e6))


def _params(tracking: bool) -> RfiMonitorParams:
    fe = _front_end()
    p = RfiMonitorParams(estimator="kalman", noise_floor_power=fe.noise_power_mw, calibration_blocks=1)
    if not tracking:
        p = dataclasses.replace(p, confirm_fits=0, analysis=SweepAnalysisParams(skip_while_tracking=False))
    return p


def _stream(second: tuple, n1: int, n2: int) -> np.ndarray:
    fe = _front_end()
    return np.concatenate([IfSimulator(fe, (PAPER_CHIRP,), seed=3).generate(n1).values(),
                           IfSimulator(fe, second, seed=4).generate(n2).values()])


def _calibrated(p: RfiMonitorParams) -> RfiMonitor:
    mon = RfiMonitor(p)
    mon.process(IfSimulator(_front_end(), (), seed=9).generate(38192).values(), FS, FIF, 0, 0)
    mon.reset()
    return mon


def test_estimates_unchanged_while_suspended() -> None:
    """The step-fit lattice does not use the LPD peaks while it exists: same per-sample track."""
    x = IfSimulator(_front_end(), (PAPER_CHIRP,), seed=3).generate(4 * 38192).values()
    out = {}
    for tracking in (True, False):
        mon = _calibrated(_params(tracking))
        f, types = [], []
        for k in range(x.size // 38192):
            e = mon.process(x[k * 38192:(k + 1) * 38192], FS, FIF, k * 38192, 0, return_traces=True)
            assert e.traces is not None
            f.append(e.traces.f)
            types.append(e.type)
        out[tracking] = (np.concatenate(f), types, mon)
    mon_t = out[True][2]
    assert mon_t.state_summary["tracking_mode"] == 1.0
    assert mon_t._counters()["period_search_suspensions"] >= 1
    assert out[False][2]._counters()["period_search_suspensions"] == 0
    np.testing.assert_array_equal(out[True][0], out[False][0])
    assert out[True][1] == out[False][1]
    assert out[True][1][1:] == [CHIRP] * 3


@pytest.mark.parametrize("case", ["cw", "off", "period"])
def test_jammer_change_noticed(case: str) -> None:
    """Chirp (5.1 us) in tracking mode for 3 ms, then a CW, nothing, or a 7.3 us chirp: the first
    0.1 ms block after the change already has the new type (and the new period within 0.3 ms)."""
    n1 = 30 * BLK
    second = {"cw": (CwJammer(frequency_hz=1.3e6),), "off": (), "period": (SLOWER_CHIRP,)}[case]
    x = _stream(second, n1, 8 * BLK)
    mon = _calibrated(_params(True))
    rows = []
    for k in range(x.size // BLK):
        e = mon.process(x[k * BLK:(k + 1) * BLK], FS, FIF, k * BLK, 0)
        s = mon.state_summary
        rows.append((e.type, s["tracking_mode"], s["period_samples"]))
    before, after = rows[:30], rows[30:]
    assert before[-1][1] == 1.0                        # the change comes in tracking mode
    assert all(r[0] == CHIRP for r in before[5:])
    if case == "period":
        per = SLOWER_CHIRP.sweep_period_s * FS
        assert all(r[0] == CHIRP for r in after)
        assert all(abs(r[2] - per) < 0.01 * per for r in after[2:])
        assert after[-1][1] == 1.0                     # tracking the new chirp again
    else:
        want = CW if case == "cw" else NONE
        assert [r[0] for r in after] == [want] * len(after)
        assert all(math.isnan(r[2]) and r[1] == 0.0 for r in after)


def test_block_split_invariance_across_suspend_and_resume() -> None:
    """Uneven block cuts give bit-identical traces and states through tracking-mode switches."""
    x = _stream((), 20 * BLK, 6 * BLK)
    rng = np.random.default_rng(5)
    cuts = np.unique(np.concatenate([[0, x.size], rng.integers(1100, x.size - 1100, 40)]))
    cuts = cuts[np.concatenate([[True], np.diff(cuts) >= 1024])]
    cuts[-1] = x.size
    res = []
    for bounds in (np.arange(0, x.size + 1, BLK * 2), cuts):
        bounds = np.asarray(bounds)
        if bounds[-1] != x.size:
            bounds = np.append(bounds[:-1] if x.size - bounds[-1] < 1024 else bounds, x.size)
        mon = _calibrated(_params(True))
        tr = []
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            e = mon.process(x[a:b], FS, FIF, int(a), 0, return_traces=True)
            assert e.traces is not None
            tr.append(e.traces)
        res.append(({k: np.concatenate([getattr(t, k) for t in tr]) for k in ("f", "df", "z_ar", "reset")},
                    mon._counters()["period_search_suspensions"]))
    assert res[0][1] >= 1
    assert res[0][1] == res[1][1]
    for k in res[0][0]:
        np.testing.assert_array_equal(res[0][0][k], res[1][0][k])

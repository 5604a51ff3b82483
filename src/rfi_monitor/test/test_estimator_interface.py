"""The monitor checks blocks and hands them to an estimator passed in (issue 26 item 5): the paper's Kalman tracker and
the STFT analysis are two implementations of ``estimate.Estimator``; any other can be given to ``RfiMonitor``."""

import math

import numpy as np
import pytest

from rfi_monitor.estimate import NON_FINITE, Block, BlockCounters, Estimator, JammerEstimate
from rfi_monitor.kalman_estimator import KalmanEstimator
from rfi_monitor.monitor import RfiMonitor
from rfi_monitor.params import RfiMonitorParams
from rfi_monitor.stft_estimator import StftEstimator


class Recording:
    """An estimator that records what the monitor hands it and answers NONE."""

    def __init__(self, params: RfiMonitorParams, counters: BlockCounters) -> None:
        self.counters_ = counters
        self.calls: list[tuple] = []

    @property
    def calibrated(self) -> bool:
        return True

    def counters(self) -> dict[str, int]:
        return {"recorded": len(self.calls)}

    def reset(self, keep_calibration: bool) -> None:
        self.calls.append(("reset", keep_calibration))

    def gap(self, missing_samples: int, stamp_ns: int, short: bool) -> None:
        self.calls.append(("gap", missing_samples, stamp_ns, short))

    def skip_invalid(self, block: Block) -> None:
        self.calls.append(("skip", block))

    def analyse(self, block: Block, return_traces: bool, light: bool) -> JammerEstimate:
        self.calls.append(("analyse", block, light))
        nan = math.nan
        return JammerEstimate(block.stamp_ns, 0, 1.0, nan, nan, nan, nan, nan, nan, nan, nan, block.fs, block.first,
                              block.n, True, self.counters_.snapshot())


def test_both_shipped_estimators_implement_the_interface():
    for cls, estimator in ((KalmanEstimator, "kalman"), (StftEstimator, "stft")):
        mon = RfiMonitor(RfiMonitorParams(estimator=estimator))
        assert type(mon.estimator) is cls
        est: Estimator = mon.estimator                  # the protocol (checked by mypy)
        for name in ("calibrated", "reset", "gap", "skip_invalid", "analyse", "counters"):
            assert hasattr(est, name), (cls.__name__, name)


def test_the_monitor_hands_checked_blocks_to_the_estimator_passed_in():
    rec: list[Recording] = []

    def build(params, counters):
        rec.append(Recording(params, counters))
        return rec[-1]

    mon = RfiMonitor(RfiMonitorParams(), estimator=build)
    r = rec[0]
    assert r.calls == [("reset", True)]
    x = np.random.default_rng(1).standard_normal(4096)
    e = mon.process(x, 4e6, 1e6, 0, 10**9, full_scale=2.0, bits=2)
    kind, block, light = r.calls[-1]
    assert kind == "analyse" and not light and block.n == 4096 and block.coarse and block.first == 0
    assert block.clipped == np.count_nonzero(np.abs(x) >= 2.0) / 4096
    assert e.counters["blocks"] == 1 and e.counters["recorded"] == 2 and e.counters["clipped_blocks"] == 1
    # a short gap (one block shed, 1 ms of stamps), then a long one: the estimator is told which
    mon.process(x, 4e6, 1e6, 2 * 4096, 10**9 + 2 * 1024000)
    assert r.calls[-2] == ("gap", 4096, 10**9 + 2 * 1024000, True)
    mon.process(x, 4e6, 1e6, 10**7, 10**9 + 5 * 10**9)
    assert r.calls[-2][0] == "gap" and r.calls[-2][3] is False
    # a change of rate is a new stream: calibration forgotten
    mon.process(x, 8e6, 1e6, 0, 10**10)
    assert ("reset", False) in r.calls
    # a block of non-finite samples is not analysed: rejected, counted, the estimator told (zeroed samples)
    y = x.copy()
    y[:1000] = np.nan
    e = mon.process(y, 8e6, 1e6, 4096, 10**10 + 512000)
    assert not e.valid and e.rejection == NON_FINITE and e.counters["blocks_rejected"] == 1
    kind, block = r.calls[-1]
    assert kind == "skip" and np.all(block.samples[:1000] == 0) and np.all(np.isfinite(block.samples))


def test_an_estimator_choice_the_params_do_not_know_is_refused():
    with pytest.raises(ValueError, match="estimator"):
        RfiMonitorParams(estimator="ml")


def test_make_estimate_is_the_dataclass() -> None:
    """``estimate.make_estimate`` (the fast constructor the estimators use on every block) builds the same frozen
    JammerEstimate as its ``__init__``: every field, the defaults of those left out, equality, immutability."""
    import dataclasses

    from rfi_monitor.estimate import make_estimate
    counts = {"blocks": 3}
    full = (7, 2, 0.5, 12.0, 40.0, 1e6, 2e3, 1e12, 1e-5, -4e6, 8e6, 10e6, 100, 10000, True, counts, None, "", 1,
            True, 0.25, 1, 0.75, True)
    for k in range(16, len(full) + 1):
        a, b = make_estimate(*full[:k]), JammerEstimate(*full[:k])
        assert a == b
        names = [f.name for f in dataclasses.fields(JammerEstimate)]
        assert [getattr(a, n) for n in names] == [getattr(b, n) for n in names]
        with pytest.raises(dataclasses.FrozenInstanceError):
            a.type = 0  # type: ignore[misc]
    with pytest.raises(TypeError):
        make_estimate(*full[:15])
    with pytest.raises(TypeError):
        make_estimate(*full, 1)

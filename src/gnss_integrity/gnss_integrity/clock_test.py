"""Spoofing tests on the receiver clock: bias and drift steps or rates outside the oscillator's model.

Pure (no rclpy). A spoofer that pushes the receiver's time (a time push of tens to thousands of ns/s)
or takes over its tracking loops moves the receiver clock bias ``c dt`` and drift ``c ddt`` that the
snapshot solution estimates every epoch. A real oscillator cannot: its bias and drift follow the
two-state clock model of its h-coefficients (``gnss_common.clock_model``; Zhao et al., eq. 6-8 with
the Brown & Hwang discretisation), so a Kalman filter of that model predicts the next epoch's bias
and drift, and the normalised innovation says whether the clock did something the oscillator cannot.

Two statistics (category CLOCK), each with a false-alarm probability parameter:

- ``clock_step``: the normalised innovation squared (NIS) of one epoch, chi-square with 2 degrees
  of freedom on clean data: a bias or drift step (an abrupt time push, a takeover's clock jump).
- ``clock_rate``: the change of the drift over lags of ``drift_lags_s`` (drift averaged in 1 s
  bins) against the random walk of the oscillator's frequency, ``var = f c^2 S_g L + 2 var(bin)``
  (``S_g = 2 pi^2 h_-2``), as a squared normal statistic (chi-square, 1 dof) with the false-alarm
  probability shared among the lags: a push whose rate is ramped up slowly enough for the Kalman
  filter to follow it (a careful spoofer) still changes the frequency far more than an oscillator can.

The snapshot's clock estimate carries correlated errors that the fix's covariance does not (the
same multipath and atmosphere every epoch), so the measurement variance has a floor
(``bias_floor_m``, ``drift_floor_mps``) and the NIS is divided by a scale learned from passing
epochs (the running median of the NIS over the clean history divided by the chi-square median,
never below 1, frozen while any test is SUSPECT or worse); the thresholds stay those of the
stated false-alarm probability.

Receiver clock steps that receivers make on purpose (a whole millisecond, 299,792.458 m, when a
free-running clock is re-aligned) are recognised exactly and re-align the filter without an alarm
(counted in ``counts['receiver_millisecond_steps']``). A gap longer than ``max_gap_s`` or a new
constellation as the clock reference restarts the filter (counted).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gnss_common.clock_model import PRESETS, ClockHCoefficients, clock_process_noise_m, transition_matrix
from gnss_common.constants import NS_PER_S, SPEED_OF_LIGHT_MPS
from rfi_node_common.params import USER, check_positive_finite, parameter

from .kernels import RunningMedian, clock_kalman_step
from .outcome import (
    CATEGORY_CLOCK,
    DECISION_SUSPECT,
    SCOPE_ALL,
    TestOutcome,
    chi2_threshold,
    decide,
    normal_threshold,
    unknown,
)

MILLISECOND_M = SPEED_OF_LIGHT_MPS * 1e-3
"""A receiver clock step of 1 ms as a pseudorange (clock bias) step, m."""
MAX_NOISE_SCALE = 4.0
"""Largest learned NIS scale: a slow push just below the threshold must not teach the scale away."""


@dataclass(frozen=True)
class ClockTestParams:
    """Parameters of the clock tests.

    ``oscillator`` is also a parameter of gnss_integrity_node (:func:`rfi_node_common.params.parameter`:
    its default, description and range are written here once).

    Attributes:
        h0, h_minus2: h-coefficients when ``oscillator`` is "custom" (s and 1/s).
        process_noise_factor: multiplies the model's process noise (temperature and flicker terms
            the two-state model lacks), >= 1.
        bias_floor_m: 1-sigma floor of the snapshot's clock bias, m (correlated errors).
        drift_floor_mps: 1-sigma floor of the snapshot's clock drift, m/s.
        step_false_alarm_probability: per-epoch probability of a clean ``clock_step`` SUSPECT.
        rate_false_alarm_probability: per-epoch probability of a clean ``clock_rate`` SUSPECT.
        alarm_false_alarm_probability: the same for ALARM (both tests).
        drift_lags_s: lags of ``clock_rate``, s.
        max_gap_s: longer gaps between epochs restart the filter, s.
        millisecond_tolerance_m: a bias innovation within this of a whole number of milliseconds
            (and at least 1 ms) is a receiver clock step, m.
        warmup_epochs: epochs after a (re)start before the tests decide.
        scale_history: clean epochs whose NIS median sets the noise scale.
    """

    oscillator: str = parameter(
        "tcxo",
        "Receiver oscillator whose h-coefficients bound the clock tests (gnss_common.clock_model presets): tcxo "
        "(Van Dierendonck's TCXO in Kaplan & Hegarty: u-blox and most COTS receivers), ocxo, ocxo_brown_hwang, "
        "compensated_crystal_brown_hwang, rubidium. A "
        "more stable class makes the clock tests more sensitive; a class more stable than the real one "
        "false-alarms.",
        choices=(*PRESETS, "custom"), group=USER)
    h0: float = 1e-21
    h_minus2: float = 2e-20
    process_noise_factor: float = 3.0
    bias_floor_m: float = 1.0
    drift_floor_mps: float = 0.1
    step_false_alarm_probability: float = 1e-6
    rate_false_alarm_probability: float = 1e-6
    alarm_false_alarm_probability: float = 1e-9
    drift_lags_s: tuple[float, ...] = (5.0, 15.0, 30.0, 60.0)
    max_gap_s: float = 10.0
    millisecond_tolerance_m: float = 1000.0
    warmup_epochs: int = 5
    scale_history: int = 600

    def __post_init__(self) -> None:
        if self.oscillator != "custom" and self.oscillator not in PRESETS:
            raise ValueError(f"ClockTestParams.oscillator must be 'custom' or one of {sorted(PRESETS)}, "
                             f"got {self.oscillator!r}")
        if not self.drift_lags_s or any(not (math.isfinite(v) and v >= 1.0) for v in self.drift_lags_s):
            raise ValueError(f"ClockTestParams.drift_lags_s must be non-empty, each >= 1 s, got {self.drift_lags_s}")
        check_positive_finite(self, ("h0", "h_minus2", "bias_floor_m", "drift_floor_mps", "max_gap_s",
                                     "millisecond_tolerance_m"))
        if not (math.isfinite(self.process_noise_factor) and self.process_noise_factor >= 1.0):
            raise ValueError(f"ClockTestParams.process_noise_factor must be >= 1, got {self.process_noise_factor}")
        for name in ("step_false_alarm_probability", "rate_false_alarm_probability",
                     "alarm_false_alarm_probability"):
            value = getattr(self, name)
            if not 0.0 < value < 0.5:
                raise ValueError(f"ClockTestParams.{name} must be in (0, 0.5), got {value}")
        if self.alarm_false_alarm_probability > min(self.step_false_alarm_probability,
                                                    self.rate_false_alarm_probability):
            raise ValueError("ClockTestParams.alarm_false_alarm_probability must not exceed the suspect ones")
        if self.millisecond_tolerance_m >= MILLISECOND_M / 2.0:
            raise ValueError("ClockTestParams.millisecond_tolerance_m must be below half a millisecond")
        if int(self.warmup_epochs) < 1 or int(self.scale_history) < 10:
            raise ValueError("ClockTestParams.warmup_epochs must be >= 1 and scale_history >= 10")

    @property
    def clock(self) -> ClockHCoefficients:
        """The oscillator's h-coefficients."""
        if self.oscillator == "custom":
            return ClockHCoefficients(h0=self.h0, h_minus2=self.h_minus2, name="custom")
        return PRESETS[self.oscillator]


@dataclass
class _Filter:
    x: np.ndarray  # [c dt (m), c ddt (m/s)]
    p: np.ndarray  # (2, 2)
    stamp_ns: int
    reference: int  # constellation whose clock is tracked
    epochs: int = 0


@dataclass
class ClockTest:
    """The receiver clock against its oscillator model, epoch by epoch.

    Call :meth:`update` once per GNSS epoch with the snapshot's clock; it returns the two
    :class:`~gnss_integrity.outcome.TestOutcome` of the epoch (``clock_step``, ``clock_rate``).
    """

    params: ClockTestParams = field(default_factory=ClockTestParams)
    counts: dict[str, int] = field(default_factory=lambda: {
        "restarts": 0, "receiver_millisecond_steps": 0, "epochs_without_clock": 0})

    def __post_init__(self) -> None:
        p = self.params
        self._filter: _Filter | None = None
        self._bins: deque[tuple[int, float, float, int]] = deque()  # (second, drift sum, var sum, n)
        self._by_second: dict[int, tuple[int, float, float, int]] = {}  # the same bins by second
        self._clean_nis = RunningMedian(p.scale_history)
        self._scale = 1.0
        self._step_thr = chi2_threshold(p.step_false_alarm_probability, 2)
        self._step_alarm = chi2_threshold(p.alarm_false_alarm_probability, 2)
        self._median_chi2_2 = chi2_threshold(0.5, 2)
        n_lags = len(p.drift_lags_s)
        self._rate_thr = (normal_threshold(p.rate_false_alarm_probability / n_lags, two_sided=True) ** 2,
                          normal_threshold(p.alarm_false_alarm_probability / n_lags, two_sided=True) ** 2)
        self._rate_q = p.process_noise_factor * SPEED_OF_LIGHT_MPS**2 * p.clock.s_g  # m^2/s^3
        self._lags = [(lag, int(round(lag))) for lag in p.drift_lags_s]
        self._max_lag = max(p.drift_lags_s)
        self._models: dict[float, tuple[np.ndarray, np.ndarray]] = {}  # dt -> (F, f W(h, dt))

    def reset(self) -> None:
        """Forget the clock and the windows (the learned noise scale stays)."""
        self._filter = None
        self._bins.clear()
        self._by_second.clear()

    # ------------------------------------------------------------------------------------------
    def update(self, stamp_ns: int, clock_bias_m: float, clock_bias_std_m: float, clock_drift_mps: float,
               clock_drift_std_mps: float, reference: int) -> tuple[TestOutcome, TestOutcome]:
        """One epoch of the snapshot's receiver clock.

        Args:
            stamp_ns: the epoch's stamp, ns.
            clock_bias_m: c dt of the reference constellation's clock, m (NaN: no fix).
            clock_bias_std_m: its 1-sigma from the fix, m.
            clock_drift_mps: c ddt, m/s (NaN: no velocity solution).
            clock_drift_std_mps: its 1-sigma, m/s.
            reference: constellation whose clock ``clock_bias_m`` is (a change restarts the filter).

        Returns:
            (``clock_step``, ``clock_rate``) outcomes; UNKNOWN while the filter warms up or without
            a clock.

        Notes:
            Prediction ``x_k = F x_{k-1}``, ``P_k = F P F^T + f W(h, dt)`` (Zhao et al., eq. 7-8,
            ``gnss_common.clock_model.clock_process_noise_m``), innovation ``nu = z - x_k`` with
            ``S = P_k + R``, NIS ``nu^T S^-1 nu / scale`` (chi-square, 2 dof).
        """
        p = self.params
        if not (math.isfinite(clock_bias_m) and math.isfinite(clock_drift_mps)):
            self.counts["epochs_without_clock"] += 1
            return self._unknown()
        r_bias = (max(clock_bias_std_m, p.bias_floor_m) ** 2 if math.isfinite(clock_bias_std_m)
                  else p.bias_floor_m**2 * 100.0)
        r_drift = (max(clock_drift_std_mps, p.drift_floor_mps) ** 2 if math.isfinite(clock_drift_std_mps)
                   else p.drift_floor_mps**2 * 100.0)
        r = np.array([[r_bias, 0.0], [0.0, r_drift]])
        z = np.array([clock_bias_m, clock_drift_mps], dtype=float)
        f = self._filter
        if f is None or f.reference != reference or not (0 < stamp_ns - f.stamp_ns <= p.max_gap_s * NS_PER_S):
            if f is not None:
                self.counts["restarts"] += 1
            self._start(stamp_ns, z, r, reference)
            return self._unknown()
        phi, q = self._model((stamp_ns - f.stamp_ns) / NS_PER_S)
        # predict, recognise a receiver's own millisecond clock step (re-align, no alarm), update
        f.x, f.p, nis, steps = clock_kalman_step(f.x, f.p, phi, q, r, z, MILLISECOND_M, p.millisecond_tolerance_m)
        if steps != 0:
            self.counts["receiver_millisecond_steps"] += 1
        f.stamp_ns = stamp_ns
        f.epochs += 1
        nis_scaled = nis / self._scale
        self._add_drift(stamp_ns, clock_drift_mps, r_drift)
        if f.epochs < p.warmup_epochs:
            self._learn(nis)
            return self._unknown()
        step = self._outcome("clock_step", nis_scaled, self._step_thr, self._step_alarm,
                             p.step_false_alarm_probability)
        rate = self._drift_change()
        if step.decision < DECISION_SUSPECT and rate.decision < DECISION_SUSPECT:
            self._learn(nis)
        return step, rate

    # ------------------------------------------------------------------------------------------
    def _model(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Transition matrix and scaled process noise for a step of ``dt`` s (kept per step length: a
        receiver's epochs repeat a few)."""
        model = self._models.get(dt)
        if model is None:
            if len(self._models) > 64:
                self._models.clear()
            p = self.params
            model = self._models[dt] = (np.ascontiguousarray(transition_matrix(dt), dtype=float),
                                        p.process_noise_factor * clock_process_noise_m(p.clock, dt))
        return model

    def _start(self, stamp_ns: int, z: np.ndarray, r: np.ndarray, reference: int) -> None:
        self._filter = _Filter(z.copy(), r.copy(), stamp_ns, reference)
        self._bins.clear()
        self._by_second.clear()

    def _add_drift(self, stamp_ns: int, drift_mps: float, var_m2ps2: float) -> None:
        second = stamp_ns // NS_PER_S
        if self._bins and self._bins[-1][0] == second:
            _, s, v, n = self._bins[-1]
            self._bins[-1] = (second, s + drift_mps, v + var_m2ps2, n + 1)
        else:
            self._bins.append((second, drift_mps, var_m2ps2, 1))
        self._by_second[second] = self._bins[-1]
        while self._bins and second - self._bins[0][0] > self._max_lag + 1:
            old = self._bins.popleft()
            if self._by_second.get(old[0]) is old:
                del self._by_second[old[0]]

    def _drift_change(self) -> TestOutcome:
        """``clock_rate``: the largest normalised drift change over the lags (module docstring)."""
        p = self.params
        suspect, alarm = self._rate_thr
        if not self._bins:
            return unknown("clock_rate", CATEGORY_CLOCK, suspect, alarm, p.rate_false_alarm_probability)
        second, s1, v1, n1 = self._bins[-1]
        by_second = self._by_second
        q = self._rate_q
        best = math.nan
        for lag, back in self._lags:
            old = by_second.get(second - back)
            if old is None:
                continue
            _, s0, v0, n0 = old
            var = q * lag + v1 / n1**2 + v0 / n0**2
            z2 = (s1 / n1 - s0 / n0) ** 2 / var / self._scale
            best = z2 if not math.isfinite(best) else max(best, z2)
        if not math.isfinite(best):
            return unknown("clock_rate", CATEGORY_CLOCK, suspect, alarm, p.rate_false_alarm_probability)
        return self._outcome("clock_rate", best, suspect, alarm, p.rate_false_alarm_probability)

    def _learn(self, nis: float) -> None:
        self._clean_nis.append(nis)
        if len(self._clean_nis) >= 20:
            self._scale = min(MAX_NOISE_SCALE, max(1.0, self._clean_nis.median() / self._median_chi2_2))

    @property
    def noise_scale(self) -> float:
        """The learned NIS scale (>= 1) that the clean snapshot clock needs beyond its covariance."""
        return self._scale

    def _outcome(self, name: str, statistic: float, suspect: float, alarm: float, pfa: float) -> TestOutcome:
        return TestOutcome(name, CATEGORY_CLOCK, decide(statistic, suspect, alarm), statistic, suspect, alarm,
                           pfa, "1", SCOPE_ALL)

    def _unknown(self) -> tuple[TestOutcome, TestOutcome]:
        p = self.params
        return (unknown("clock_step", CATEGORY_CLOCK, self._step_thr, self._step_alarm,
                        p.step_false_alarm_probability),
                unknown("clock_rate", CATEGORY_CLOCK, false_alarm_probability=p.rate_false_alarm_probability))

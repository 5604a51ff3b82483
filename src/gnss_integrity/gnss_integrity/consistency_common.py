"""What the consistency tests share: their parameters, the outcome helper, iterative exclusion, scope.

Pure (no rclpy). The tests are :mod:`.consistency` (``constellation_agreement``, ``raim_subset`` and
the suite) and :mod:`.doppler_pseudorange` (``doppler_vs_pseudorange``); the clean-data models are in
the docstring of :mod:`.consistency`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .outcome import (
    CATEGORY_CONSISTENCY,
    DECISION_SUSPECT,
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    SCOPE_SATELLITES,
    TestOutcome,
    decide,
)

Sat = tuple[int, int]


@dataclass(frozen=True)
class ConsistencyParams:
    """Parameters of the consistency tests (validated).

    Attributes:
        agreement_false_alarm_probability, doppler_false_alarm_probability, raim_false_alarm_probability:
            per-evaluation probability of a clean SUSPECT of each test; alarm_false_alarm_probability:
            of a clean ALARM (every test), <= the suspect ones.
        agreement_min_satellites: satellites a constellation needs to be tested (its own fix: 4).
        agreement_smoothing_s: time constant T of the average of the position difference, s.
        agreement_lag_s: lag of the change statistic, s (>= 2 T).
        agreement_correlation_time_s: correlation time tau of the correlated errors, s.
        noise_correlation_time_s: code noise is taken as independent only between epochs this far
            apart (tracking loops, smoothing), s.
        doppler_window_s: window of the code-minus-Doppler sums, s.
        doppler_sigma_mps: the receiver's Doppler noise (orbit errors cancel) as a rate 1-sigma at zenith
            and reference C/N0, m/s, scaled by ``fix.sigma_scales``; a stated rate std overrides it.
        doppler_code_drift_mps: 1-sigma rate of change of the code's slowly varying errors over a window
            (ionospheric code-carrier divergence 2 dI/dt, slow multipath), m/s; adds ``(rate span)^2``.
        doppler_min_satellites: satellites needed for a Doppler test (one dof goes to the clock).
        raim_max_exclusions: satellites ``raim_subset`` (and the Doppler test) exclude at most.
        max_gap_s: a longer gap between epochs restarts every average and window, s.
    """

    agreement_false_alarm_probability: float = 1e-6
    doppler_false_alarm_probability: float = 1e-6
    raim_false_alarm_probability: float = 1e-6
    alarm_false_alarm_probability: float = 1e-9
    agreement_min_satellites: int = 5
    agreement_smoothing_s: float = 5.0
    agreement_lag_s: float = 30.0
    agreement_correlation_time_s: float = 600.0
    noise_correlation_time_s: float = 1.0
    doppler_window_s: float = 30.0
    doppler_sigma_mps: float = 0.05
    doppler_code_drift_mps: float = 0.01
    doppler_min_satellites: int = 4
    raim_max_exclusions: int = 4
    max_gap_s: float = 60.0

    def __post_init__(self) -> None:
        probabilities = [f"{t}_false_alarm_probability" for t in ("agreement", "doppler", "raim", "alarm")]
        positive = ("agreement_smoothing_s", "agreement_lag_s", "agreement_correlation_time_s",
                    "noise_correlation_time_s", "doppler_window_s", "doppler_sigma_mps", "max_gap_s")
        for name in (*probabilities, *positive, "doppler_code_drift_mps"):
            v = getattr(self, name)
            low_ok = v >= 0.0 if name == "doppler_code_drift_mps" else v > 0.0
            if not (isinstance(v, (int, float)) and math.isfinite(v) and low_ok and (name not in probabilities
                                                                                  or v < 0.5)):
                raise ValueError(f"ConsistencyParams.{name} out of range: {v!r}")
        if self.alarm_false_alarm_probability > min(getattr(self, n) for n in probabilities[:3]):
            raise ValueError("ConsistencyParams.alarm_false_alarm_probability must not exceed the suspect ones")
        if self.agreement_lag_s < 2.0 * self.agreement_smoothing_s:
            raise ValueError("ConsistencyParams.agreement_lag_s must be >= 2 agreement_smoothing_s")
        for name, low in (("agreement_min_satellites", 4), ("doppler_min_satellites", 3), ("raim_max_exclusions", 0)):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= low):
                raise ValueError(f"ConsistencyParams.{name} must be an int >= {low}, got {getattr(self, name)!r}")


def consistency_outcome(name: str, statistic: float, suspect: float, alarm: float, pfa: float,
                        scope: int = SCOPE_ALL, constellations: tuple[int, ...] = (),
                        satellites: tuple[Sat, ...] = ()) -> TestOutcome:
    """The CONSISTENCY outcome of a statistic; what it implicates only when SUSPECT or worse."""
    decision = decide(statistic, suspect, alarm)
    if decision < DECISION_SUSPECT:
        scope, constellations, satellites = SCOPE_ALL, (), ()
    return TestOutcome(name, CATEGORY_CONSISTENCY, decision, statistic, suspect, alarm, pfa, "1", scope,
                       constellations, satellites)


def exclude_largest(e: np.ndarray, v: np.ndarray, dof_lost: int, threshold_of: Callable[[int], float],
                    max_exclusions: int, min_left: int) -> tuple[float, list[int], bool]:
    """Chi-square of weighted-mean-removed values; iteratively exclude the largest until it passes.

    Returns (statistic of all, excluded indices, passes after exclusion).
    """
    keep = np.ones(e.size, dtype=bool)
    excluded: list[int] = []
    first = math.nan
    while True:
        w = 1.0 / v[keep]
        z = (e[keep] - np.sum(w * e[keep]) / np.sum(w)) * np.sqrt(w)
        q = float(np.sum(z * z))
        if not excluded:
            first = q
        if q < threshold_of(int(keep.sum()) - dof_lost):
            return first, excluded, True
        if len(excluded) >= max_exclusions or keep.sum() - 1 < min_left:
            return first, excluded, False
        worst = int(np.flatnonzero(keep)[int(np.argmax(np.abs(z)))])
        keep[worst] = False
        excluded.append(worst)


def implicated_scope(implicated: list[Sat], passed: bool, tested: list[Sat]
                     ) -> tuple[int, tuple[int, ...], tuple[Sat, ...]]:
    """Scope of a set of implicated satellites: whole constellations, satellites, or ALL."""
    if not passed or not implicated or 2 * len(implicated) > len(tested):
        return SCOPE_ALL, (), tuple(sorted(implicated))
    whole = tuple(sorted({c for c, _ in implicated if sum(1 for s in tested if s[0] == c) >= 2
                          and all(s in implicated for s in tested if s[0] == c)}))
    if whole and all(s[0] in whole for s in implicated):
        return SCOPE_CONSTELLATIONS, whole, tuple(sorted(implicated))
    return SCOPE_SATELLITES, (), tuple(sorted(implicated))

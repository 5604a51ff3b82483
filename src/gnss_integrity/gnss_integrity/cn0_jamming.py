"""Jamming from C/N0 alone: the common C/N0 drop against the clean model, and a J/S estimate.

Pure (no rclpy). Per epoch, on the references of :meth:`gnss_integrity.cn0_model.Cn0Models.reference`:

* every satellite's drop ``d_i = expected_i - cn0_i`` (dB; positive: weaker than clean), against
  the elevation model (``EVIDENCE_CN0_ELEVATION``) or, without elevations, against the satellite's own
  recent clean level (``EVIDENCE_CN0_COMMON_DROP``, ``elevation_model_in_use = False``);
* satellites **lost**: tracked in the last clean epochs, at least ``lost_min_margin_db`` above the
  receiver's loss of lock, above ``lost_min_elevation_deg`` when their elevation is known, and missing
  now. A jammer that pushes C/N0 below loss of lock (about 30 dB-Hz) makes them vanish; each enters
  the common drop with the lower bound ``d >= last_clean_cn0 - loss_of_lock_dbhz``;
* the **common drop** ``D = median(d)`` over tracked and lost satellites (robust to a few blocked or
  reflected satellites; with lower bounds for lost ones it is itself a lower bound);
* its clean-data model: ``D ~ N(0, s^2)`` with ``s^2 = (1.2533 sigma_rms)^2 / n + floor^2`` (median
  of n independent residuals of 1-sigma ``sigma_i`` from the model, plus ``common_std_floor_db`` for
  errors common to all satellites: receiver temperature, antenna, the model's own bias);
* thresholds ``max(min_drop_suspect_db, z(p_fa) s)`` and ``max(min_drop_alarm_db, z(p_alarm) s)``
  with ``z`` the one-sided normal quantile;
* **persistence** (time from the stamps, never the wall clock): the published statistic is the
  smallest D of the last ``persistence_epochs`` evaluations spanning at least ``persistence_s``, so
  a drop must hold that long (the per-evaluation false-alarm probability of the persistent statistic
  is at most ``false_alarm_probability``);
* **J/S** by inverting Cao et al. eq. 4 per satellite (:func:`jammer_to_signal_from_cn0`) from its
  clean and observed C/N0, for satellites whose drop is at least ``jsr_min_drop_db`` and 2 sigma (the
  inverse is ill-conditioned for small drops), with 1-sigma ``sigma_i sqrt(g^2 + (g - 1)^2)``,
  ``g = 1 / (1 - 10^(-d_i/10))``; combined by the inverse-variance weighted median, 1-sigma the larger
  of the combined one and the spread (1.2533 x 1.4826 MAD / sqrt(n)), with ``jsr_std_floor_db`` in
  quadrature. Lost satellites bound J/S from below (``jsr_lower_bound_db``); the estimate is raised
  to that bound (the survivors of a strong jammer are those with C/N0 noise upwards) and is the bound
  when no satellite survives, then flagged as a lower bound (``jammer_to_signal_is_lower_bound``: at
  J/S above about 30 dB a receiver with a 30 dB-Hz loss of lock tracks nothing, and C/N0 cannot say
  by how much the jammer exceeds what lost them). Reported only while the decision is SUSPECT or ALARM; otherwise NaN
  with the upper bound ``jsr_upper_bound_db`` (the J/S that drops the median satellite by the suspect
  threshold).

Foliage or a body blocking the sky also lowers C/N0 on many satellites; the AGC
(:mod:`gnss_integrity.receiver_agc`) tells the two apart where the receiver reports it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ
from gnss_integrity.cn0_epoch import Cn0Reference
from gnss_integrity.cn0_model import MODEL_READY
from gnss_integrity.outcome import (
    CATEGORY_JAMMING,
    DECISION_SUSPECT,
    EVIDENCE_CN0_COMMON_DROP,
    EVIDENCE_CN0_ELEVATION,
    TestOutcome,
    decide,
    normal_threshold,
    unknown,
)

from .outcome import check_false_alarm_probabilities

TEST_NAME = "cn0_drop"
MEDIAN_EFFICIENCY = 1.2533  # std of the median of n normal samples = 1.2533 sigma / sqrt(n)


def jammer_to_signal_from_cn0(clean_cn0_dbhz, effective_cn0_dbhz, quality_factor: float = 1.0,
                              chip_rate_hz: float = GPS_CA_CHIP_RATE_HZ) -> np.ndarray:
    """J/S that lowers a clean C/N0 to an effective one: Cao et al. eq. 4 solved for J/S.

    Args:
        clean_cn0_dbhz: jammer-free C/N0, dB-Hz (array or scalar).
        effective_cn0_dbhz: observed (effective) C/N0, dB-Hz, broadcast against it.
        quality_factor: Q of eq. 4, dimensionless, > 0.
        chip_rate_hz: R_c of eq. 4, chip/s.

    Returns:
        J/S, dB; NaN where the effective C/N0 is not below the clean one.

    Notes:
        ``(C/N0)_eff = -10 log10(10^(-C/N0/10) + 10^(J/S/10) / (Q R_c))`` gives
        ``J/S = 10 log10(Q R_c (10^(-(C/N0)_eff/10) - 10^(-C/N0/10)))``. The inverse is
        ill-conditioned for small drops ``d = C/N0 - (C/N0)_eff``: dJ/S / d(C/N0)_eff =
        -1 / (1 - 10^(-d/10)), dJ/S / dC/N0 = (1 - 10^(-d/10))^-1 - 1 (x4.8 and x3.8 at d = 1 dB).
    """
    clean = np.asarray(clean_cn0_dbhz, dtype=float)
    eff = np.asarray(effective_cn0_dbhz, dtype=float)
    diff = 10.0 ** (-eff / 10.0) - 10.0 ** (-clean / 10.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(diff > 0, 10.0 * np.log10(quality_factor * chip_rate_hz * np.where(diff > 0, diff, 1.0)),
                        np.nan)


def fast_median(values: np.ndarray) -> float:
    """Median of a non-empty 1-D array (np.partition; np.median's overhead dominates at 30 values)."""
    n = values.size
    lo, hi = (n - 1) // 2, n // 2
    part = np.partition(values, (lo, hi))
    return 0.5 * float(part[lo] + part[hi])


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """Median of ``values`` with non-negative ``weights`` (NaN when empty)."""
    if values.size == 0:
        return math.nan
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cw, 0.5 * cw[-1])])


class PersistentStatistic:
    """Smallest statistic of the last ``epochs`` evaluations spanning at least ``duration_s``.

    Args:
        epochs: evaluations the window holds at least.
        duration_s: time the window spans at least, s (from the stamps).
        max_age_s: evaluations older than this are forgotten (a gap restarts the window), s.
    """

    def __init__(self, epochs: int, duration_s: float, max_age_s: float) -> None:
        self.epochs = int(epochs)
        self.duration_ns = int(duration_s * 1e9)
        self.max_age_ns = int(max(max_age_s, duration_s) * 1e9)
        self._hist: deque[tuple[int, float, float, float]] = deque()

    def update(self, stamp_ns: int, statistic: float, suspect: float, alarm: float) -> tuple[float, float, float]:
        """Add one evaluation (NaN: none this epoch). Returns the persistent statistic and the largest
        thresholds in the window (NaN statistic: not enough history)."""
        h = self._hist
        if math.isfinite(statistic):
            h.append((stamp_ns, statistic, suspect, alarm))
        while h and h[0][0] < stamp_ns - self.max_age_ns:
            h.popleft()
        while len(h) > self.epochs and h[1][0] <= stamp_ns - self.duration_ns:
            h.popleft()
        if not math.isfinite(statistic) or len(h) < self.epochs or h[0][0] > stamp_ns - self.duration_ns:
            return math.nan, suspect, alarm
        return min(e[1] for e in h), max(e[2] for e in h), max(e[3] for e in h)


@dataclass(frozen=True)
class Cn0JammingParams:
    """Parameters of :class:`Cn0JammingDetector` (clean-data model in the module docstring).

    Attributes:
        false_alarm_probability: per-evaluation probability that D reaches the suspect threshold on
            clean data.
        alarm_false_alarm_probability: the same for the alarm threshold.
        min_drop_suspect_db, min_drop_alarm_db: smallest thresholds of D, dB (physical relevance).
        common_std_floor_db: 1-sigma of clean errors common to all satellites, dB.
        min_satellites: fewer tracked + lost satellites with a reference: UNKNOWN.
        persistence_epochs, persistence_s: D must hold this many evaluations and this long, s.
        history_max_age_s: a gap this long restarts the persistence window, s.
        loss_of_lock_dbhz: C/N0 below which the receiver stops tracking, dB-Hz (a higher value is
            conservative: smaller lower bounds).
        lost_min_margin_db: a lost satellite counts when its last clean C/N0 was at least this far
            above loss of lock, dB (weak satellites vanish on their own).
        lost_min_elevation_deg: and its last elevation, when known, above this, deg (setting).
        quality_factor, chip_rate_hz: Q and R_c of eq. 4 for the J/S estimate.
        jsr_min_drop_db: a satellite enters the J/S estimate when its drop is at least this, dB, and
            at least 2 sigma.
        jsr_std_floor_db: floor of the J/S 1-sigma, dB.
    """

    false_alarm_probability: float = 1e-4
    alarm_false_alarm_probability: float = 1e-7
    min_drop_suspect_db: float = 3.0
    min_drop_alarm_db: float = 5.0
    common_std_floor_db: float = 0.5
    min_satellites: int = 4
    persistence_epochs: int = 3
    persistence_s: float = 1.0
    history_max_age_s: float = 120.0
    loss_of_lock_dbhz: float = 30.0
    lost_min_margin_db: float = 6.0
    lost_min_elevation_deg: float = 15.0
    quality_factor: float = 1.0
    chip_rate_hz: float = GPS_CA_CHIP_RATE_HZ
    jsr_min_drop_db: float = 1.5
    jsr_std_floor_db: float = 0.5

    def __post_init__(self) -> None:
        check_false_alarm_probabilities(self)
        if not (0 <= self.min_drop_suspect_db <= self.min_drop_alarm_db):
            raise ValueError("need 0 <= min_drop_suspect_db <= min_drop_alarm_db")
        for name in ("common_std_floor_db", "persistence_s", "lost_min_margin_db", "jsr_min_drop_db",
                     "jsr_std_floor_db"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0")
        if not (self.min_satellites >= 1 and self.persistence_epochs >= 1 and self.history_max_age_s > 0):
            raise ValueError("min_satellites, persistence_epochs >= 1 and history_max_age_s > 0")
        if not (self.quality_factor > 0 and self.chip_rate_hz > 0):
            raise ValueError("quality_factor and chip_rate_hz must be > 0")


@dataclass(frozen=True)
class Cn0JammingResult:
    """One epoch of :class:`Cn0JammingDetector`.

    Attributes:
        outcome: the ``cn0_drop`` TestOutcome (statistic: persistent common drop, dB).
        elevation_model_in_use: the elevation model judged (False: satellite levels, or none).
        evidence: ``EVIDENCE_CN0_ELEVATION`` or ``EVIDENCE_CN0_COMMON_DROP`` when the decision is
            SUSPECT or ALARM, else 0.
        common_drop_db, common_drop_std_db: this epoch's D and its clean 1-sigma s, dB (NaN: unknown).
        satellites_used, satellites_lost: tracked satellites with a reference, lost satellites counted.
        jammer_to_signal_db, jammer_to_signal_std_db: J/S estimate and 1-sigma, dB (NaN: none). With
            every significantly dropped satellite lost, the lost satellites' bound and its spread.
        jsr_lower_bound_db: J/S implied by the lost satellites (NaN: none lost): the median over them
            of the J/S that takes their last clean C/N0 to ``loss_of_lock_dbhz``.
        jsr_upper_bound_db: with no jamming reported, J/S is below this, dB (NaN otherwise).
        epoch_clean: this epoch's D is below the suspect threshold (True when the test cannot run):
            one input of the learning gate.
        model_state: ``cn0_model.MODEL_*``.
        drop_db: per input row, the drop d_i, dB (NaN: no reference).
        jammer_to_signal_is_lower_bound: every satellite with a significant drop was lost, so
            ``jammer_to_signal_db`` is the lost satellites' bound: the J/S is at least that, not
            about that (C/N0 says nothing more once the receiver tracks nothing).
    """

    outcome: TestOutcome
    elevation_model_in_use: bool
    evidence: int
    common_drop_db: float
    common_drop_std_db: float
    satellites_used: int
    satellites_lost: int
    jammer_to_signal_db: float
    jammer_to_signal_std_db: float
    jsr_lower_bound_db: float
    jsr_upper_bound_db: float
    epoch_clean: bool
    model_state: int
    drop_db: np.ndarray
    jammer_to_signal_is_lower_bound: bool = False


class Cn0JammingDetector:
    """The ``cn0_drop`` test and the J/S estimate (see the module docstring)."""

    def __init__(self, params: Cn0JammingParams | None = None) -> None:
        self.params = params or Cn0JammingParams()
        p = self.params
        self._z_suspect = normal_threshold(p.false_alarm_probability)
        self._z_alarm = normal_threshold(p.alarm_false_alarm_probability)
        self._persist = PersistentStatistic(p.persistence_epochs, p.persistence_s, p.history_max_age_s)

    def evaluate(self, ref: Cn0Reference) -> Cn0JammingResult:
        """Judge one epoch (call once per epoch, in stamp order)."""
        p = self.params
        cn0 = ref.epoch.cn0_dbhz
        use = ref.valid & np.isfinite(ref.expected_dbhz)
        drop = np.where(use, ref.expected_dbhz - cn0, np.nan)
        lost = ref.lost_cn0_dbhz >= p.loss_of_lock_dbhz + p.lost_min_margin_db
        lost &= ~(ref.lost_elevation_rad < math.radians(p.lost_min_elevation_deg))
        if ref.model_state != MODEL_READY:
            lost[:] = False
        d_all = np.concatenate([drop[use], ref.lost_cn0_dbhz[lost] - p.loss_of_lock_dbhz])
        n_used, n_lost = int(np.count_nonzero(use)), int(np.count_nonzero(lost))
        if d_all.size < p.min_satellites:
            self._persist.update(ref.epoch.stamp_ns, math.nan, math.nan, math.nan)
            none = unknown(TEST_NAME, CATEGORY_JAMMING, false_alarm_probability=p.false_alarm_probability, unit="dB")
            return Cn0JammingResult(none, ref.elevation_model_in_use, 0, math.nan, math.nan, n_used, n_lost,
                                    math.nan, math.nan, math.nan, math.nan, True, ref.model_state, drop)
        common = fast_median(d_all)
        sig = ref.std_db[use]
        sig_rms = math.sqrt(float(np.mean(sig**2))) if sig.size else p.common_std_floor_db
        std = math.hypot(MEDIAN_EFFICIENCY * sig_rms / math.sqrt(d_all.size), p.common_std_floor_db)
        sus = max(p.min_drop_suspect_db, self._z_suspect * std)
        alarm = max(p.min_drop_alarm_db, self._z_alarm * std, sus)
        stat, sus_w, alarm_w = self._persist.update(ref.epoch.stamp_ns, common, sus, alarm)
        decision = decide(stat, sus_w, alarm_w)
        js, js_std, js_lb, js_ub, bound_only = math.nan, math.nan, math.nan, math.nan, False
        if decision >= DECISION_SUSPECT:
            js, js_std, js_lb, bound_only = self._jsr(ref, use, drop, lost)
        elif math.isfinite(stat) and n_used:  # the J/S that drops the median satellite by the threshold
            med = fast_median(ref.expected_dbhz[use])
            js_ub = 10.0 * math.log10(p.quality_factor * p.chip_rate_hz * 10.0 ** (-med / 10.0)
                                      * (10.0 ** (sus_w / 10.0) - 1.0))
        evidence = 0
        if decision >= DECISION_SUSPECT:
            evidence = EVIDENCE_CN0_ELEVATION if ref.elevation_model_in_use else EVIDENCE_CN0_COMMON_DROP
        outcome = TestOutcome(TEST_NAME, CATEGORY_JAMMING, decision, stat, sus_w, alarm_w,
                              p.false_alarm_probability, "dB")
        return Cn0JammingResult(outcome, ref.elevation_model_in_use, evidence, common, std, n_used, n_lost,
                                js, js_std, js_lb, js_ub, common < sus, ref.model_state, drop, bound_only)

    def _jsr(self, ref: Cn0Reference, use: np.ndarray, drop: np.ndarray,
             lost: np.ndarray) -> tuple[float, float, float, bool]:
        """J/S, its 1-sigma and the lost satellites' lower bound, dB, and whether the J/S is that bound
        alone (no satellite with a significant drop survived; module docstring)."""
        p = self.params
        std_i = ref.std_db
        cand = use & (drop >= np.maximum(p.jsr_min_drop_db, 2.0 * np.nan_to_num(std_i, nan=np.inf)))
        lb = jammer_to_signal_from_cn0(ref.lost_cn0_dbhz[lost], p.loss_of_lock_dbhz, p.quality_factor, p.chip_rate_hz)
        lb = lb[np.isfinite(lb)]
        js_lb = fast_median(lb) if lb.size else math.nan
        lb_std = math.hypot(1.4826 * fast_median(np.abs(lb - js_lb)), p.jsr_std_floor_db) if lb.size else math.nan
        js_i = jammer_to_signal_from_cn0(ref.expected_dbhz[cand], ref.epoch.cn0_dbhz[cand], p.quality_factor,
                                         p.chip_rate_hz)
        g_eff = 1.0 / (1.0 - 10.0 ** (-drop[cand] / 10.0))
        s_i = std_i[cand] * np.hypot(g_eff, g_eff - 1.0)
        ok = np.isfinite(js_i) & np.isfinite(s_i)
        js_i, s_i = js_i[ok], s_i[ok]
        if js_i.size == 0:  # every satellite with a significant drop lost: J/S is at least the bound
            return js_lb, lb_std, js_lb, math.isfinite(js_lb)
        w = 1.0 / s_i**2
        js = weighted_median(js_i, w)
        spread = 1.4826 * float(np.median(np.abs(js_i - js))) * MEDIAN_EFFICIENCY / math.sqrt(js_i.size)
        std = math.hypot(max(math.sqrt(1.0 / float(w.sum())), spread), p.jsr_std_floor_db)
        if math.isfinite(js_lb) and js_lb > js:
            js = js_lb  # survivors of a strong jammer are those whose C/N0 noise was high: biased low
        return js, std, js_lb, False

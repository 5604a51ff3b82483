"""Spoofing from C/N0 (CATEGORY_CN0): power too high, no elevation dependence, common fluctuation.

Pure (no rclpy). Each test runs per **group**: every constellation with at least
``min_group_satellites`` satellites, plus all satellites pooled when two or more constellations are
present. A test's statistic is the largest group z-score (unit "1", standard normal on clean data);
its thresholds are the one-sided normal quantiles of ``false_alarm_probability / G`` and
``alarm_false_alarm_probability / G`` over the G groups tested (Bonferroni). Like ``cn0_drop``, the
published statistic is the smallest of the last ``persistence_epochs`` evaluations spanning
``persistence_s``. A test at SUSPECT or ALARM implicates the constellations whose group is over its
suspect threshold (``SCOPE_CONSTELLATIONS``: one spoofed constellation among clean ones is named), or
every constellation present (``SCOPE_ALL``) when only the pooled group is or all of them are. The
tests run at most every ``evaluation_interval_s`` (C/N0 estimates are correlated over about a second;
a faster receiver gets the last result in between).

* ``cn0_too_high``: residuals ``e_i = cn0_i - expected_i`` against the clean reference (elevation
  model, else the satellite's recent clean level). Group z = ``median(e) / s`` with
  ``s^2 = (1.2533 sigma_rms)^2 / n + group_std_floor_db^2`` (clean: independent residuals of the
  model's 1-sigma, plus common errors). A +3 dB takeover lifts every satellite. Satellites whose own
  ``e_i / sigma_i`` exceeds the normal quantile of ``satellite_false_alarm_probability / n`` are
  listed (``satellites_high``; in the outcome those of the implicated constellations).
* ``cn0_elevation_dependence``: the slope ``c`` of the residuals on sin(elevation), against the
  model's own slope ``b`` (of expected C/N0 on sin(elevation), 10-15 dB for a clean receiver). One
  transmitter gives every satellite the same power: ``c = -b`` (the dependence lost). Accumulated over
  ``slope_window_epochs`` evaluations: ``c = sum S_xr / sum S_xx``; clean model: ``c ~ N(0, v)`` with
  ``v = W sum_t Q_t / (sum_t S_xx,t)^2 + slope_std_floor_db^2`` (``Q_t = sum (s_i - s_bar)^2
  sigma_i^2``; residuals treated as fully persistent across epochs: conservative),
  z = ``-c / sqrt(v)``. Needs the elevation model; ``fraction_lost = -c / b`` is reported.
* ``cn0_common_fluctuation``: the satellites' C/N0 over the last ``fluctuation_window_epochs``
  evaluations, each detrended (mean and slope removed), split into the common mode ``c_t`` (mean over
  the group's n satellites) and the rest. Independent per-satellite noise gives the common mode the
  variance sigma^2 / n, so the ratio of mean squares
  ``F = (n sum_t c_t^2 / (W - 2)) / (sum_t,i (x_ti - c_t)^2 / ((n - 1)(W - 2)) + n floor^2)`` is
  F(d1, (n - 1) d1)-distributed, ``d1 = min(W - 2, span / decorrelation_s)`` (time-correlated C/N0
  holds fewer independent epochs than W), floor = ``common_mode_std_floor_db`` (the clean receiver's
  own common-mode wander: 0.3 dB, from ARL1). z is the normal quantile of F's p-value. One
  transmitter moving relative to the antenna lifts and lowers every satellite together. A jammed
  epoch (``cn0_drop`` at its suspect threshold) empties this window and the elevation window (a
  jammer also moves every C/N0 together and flattens the elevation dependence). A sustained common
  step below the jamming threshold (a weak jammer switched on, the antenna entering foliage) can
  raise it for one window.

Per-epoch use: ``Cn0SpoofingTests.evaluate(ref, jamming_result)`` after ``Cn0JammingDetector.evaluate``
on the same reference, before ``Cn0Models.learn``. The tests say UNKNOWN when their reference,
elevations or satellites are missing, never PASS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import fdtrc, ndtri

from gnss_integrity.cn0_epoch import N_CONSTELLATION_CODES, Cn0Reference
from gnss_integrity.cn0_jamming import MEDIAN_EFFICIENCY, Cn0JammingResult, PersistentStatistic
from gnss_integrity.outcome import (
    CATEGORY_CN0,
    DECISION_SUSPECT,
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    TestOutcome,
    decide,
    normal_threshold,
    unknown,
)

from .outcome import check_false_alarm_probabilities

TOO_HIGH = "cn0_too_high"
ELEVATION_DEPENDENCE = "cn0_elevation_dependence"
COMMON_FLUCTUATION = "cn0_common_fluctuation"
TEST_NAMES = (TOO_HIGH, ELEVATION_DEPENDENCE, COMMON_FLUCTUATION)
_ALL = 0  # group index of all satellites pooled
_NG = N_CONSTELLATION_CODES


@dataclass(frozen=True)
class Cn0SpoofingParams:
    """Parameters of :class:`Cn0SpoofingTests` (clean-data models in the module docstring).

    Attributes:
        false_alarm_probability, alarm_false_alarm_probability: per-evaluation probabilities of the
            suspect and alarm thresholds on clean data (shared over the groups).
        min_group_satellites: a group needs this many satellites.
        persistence_epochs, persistence_s, history_max_age_s: as in ``Cn0JammingParams``.
        group_std_floor_db: common clean error of a group's median residual, dB (too high).
        satellite_false_alarm_probability: per epoch, for listing single satellites as too high.
        slope_window_epochs: epochs the elevation slope accumulates.
        min_sin_elevation_std: a group's satellites must spread over sin(elevation) at least this much
            (standard deviation).
        min_model_slope_db: the model's slope must be at least this (dB per unit sin(elevation)).
        slope_std_floor_db: floor of the slope's 1-sigma, dB per unit sin(elevation) (model error).
        fluctuation_window_epochs: samples of the common-fluctuation window (>= 4), one per evaluation.
        evaluation_interval_s: the tests run at most this often (C/N0 estimates are correlated over
            about a second; a faster receiver gets the last result in between), s.
        decorrelation_s: C/N0 estimates closer than this are not independent, s.
        common_mode_std_floor_db: clean common-mode C/N0 jitter, dB.
        max_gap_s: a gap between epochs longer than this restarts the windows, s.
        too_high_learning_block_s: ``cn0_too_high`` at its suspect threshold blocks learning for at
            most this long without a break, s (then the rise is taken as the new clean level: a model
            learned while obstructed or weakly jammed would otherwise report spoofing for ever).
    """

    false_alarm_probability: float = 1e-4
    alarm_false_alarm_probability: float = 1e-7
    min_group_satellites: int = 4
    persistence_epochs: int = 3
    persistence_s: float = 1.0
    history_max_age_s: float = 120.0
    group_std_floor_db: float = 0.5
    satellite_false_alarm_probability: float = 1e-4
    slope_window_epochs: int = 10
    min_sin_elevation_std: float = 0.1
    min_model_slope_db: float = 4.0
    slope_std_floor_db: float = 1.0
    fluctuation_window_epochs: int = 50
    evaluation_interval_s: float = 0.2
    decorrelation_s: float = 1.0
    common_mode_std_floor_db: float = 0.3
    max_gap_s: float = 120.0
    too_high_learning_block_s: float = 300.0

    def __post_init__(self) -> None:
        check_false_alarm_probabilities(self)
        if not 0 < self.satellite_false_alarm_probability < 0.5:
            raise ValueError("satellite_false_alarm_probability must be in (0, 0.5)")
        if not (self.min_group_satellites >= 3 and self.persistence_epochs >= 1 and self.slope_window_epochs >= 1
                and self.fluctuation_window_epochs >= 4):
            raise ValueError("min_group_satellites >= 3, persistence and slope windows >= 1, fluctuation >= 4")
        for name in ("persistence_s", "group_std_floor_db", "min_sin_elevation_std", "min_model_slope_db",
                     "slope_std_floor_db", "common_mode_std_floor_db"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0")
        if not (self.decorrelation_s > 0 and self.max_gap_s > 0 and self.history_max_age_s > 0
                and self.evaluation_interval_s >= 0):
            raise ValueError("decorrelation_s, max_gap_s, history_max_age_s > 0 and evaluation_interval_s >= 0")


@dataclass(frozen=True)
class Cn0SpoofingResult:
    """One epoch of :class:`Cn0SpoofingTests`.

    Attributes:
        outcomes: ``cn0_too_high``, ``cn0_elevation_dependence``, ``cn0_common_fluctuation``.
        epoch_clean: no test at its suspect threshold this epoch (a learning gate), except that
            ``cn0_too_high`` alone stops blocking after ``too_high_learning_block_s`` without a break.
        elevation_model_in_use: ``cn0_too_high`` judged against the elevation model.
        satellites_high: ``(constellation, svid)`` individually too high this epoch.
        fraction_lost: largest fraction of the elevation dependence lost over the groups (NaN: unknown).
    """

    outcomes: tuple[TestOutcome, TestOutcome, TestOutcome]
    epoch_clean: bool
    elevation_model_in_use: bool
    satellites_high: tuple[tuple[int, int], ...]
    fraction_lost: float


def _groups(constellation: np.ndarray, mask: np.ndarray, min_n: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``mask`` in their constellation's group, and all of them again in group 0 (all) when
    two or more constellations are present; groups with fewer than ``min_n`` rows dropped.

    Returns:
        (rows, group index of each)."""
    rows = np.flatnonzero(mask)
    g = np.minimum(np.maximum(constellation[rows], 1), _NG - 1)
    counts = np.bincount(g, minlength=_NG)
    keep = counts[g] >= min_n
    if np.count_nonzero(counts) >= 2 and rows.size >= min_n:
        return np.concatenate([rows[keep], rows]), np.concatenate([g[keep], np.zeros(rows.size, dtype=np.int64)])
    return rows[keep], g[keep]


def _group_median(values: np.ndarray, groups: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Median of ``values`` per group index (``counts`` rows each; NaN for empty groups), vectorised."""
    sv = values[np.lexsort((values, groups))]
    starts = np.cumsum(counts) - counts
    last = max(sv.size - 1, 0)
    lo = np.minimum(starts + (counts - 1) // 2, last)
    hi = np.minimum(starts + counts // 2, last)
    return np.where(counts > 0, 0.5 * (sv[lo] + sv[hi]), np.nan) if sv.size else np.full(_NG, np.nan)


_Raw = tuple[float, np.ndarray, int, tuple[tuple[int, int], ...]]
"""A test's raw evaluation: largest group z, groups over the suspect threshold, groups tested,
satellites individually implicated."""
_NONE: _Raw = (math.nan, np.zeros(_NG, dtype=bool), 0, ())


class Cn0SpoofingTests:
    """The three C/N0 spoofing tests (module docstring); ``evaluate`` once per epoch in stamp order."""

    def __init__(self, params: Cn0SpoofingParams | None = None) -> None:
        self.params = params or Cn0SpoofingParams()
        p = self.params
        self._persist = {n: PersistentStatistic(p.persistence_epochs, p.persistence_s, p.history_max_age_s)
                         for n in TEST_NAMES}
        self._thresholds: dict[int, tuple[float, float]] = {}
        self._slope = np.zeros((p.slope_window_epochs, 4, _NG))  # S_xr, S_xE, S_xx, Q per group
        self._slope_n = np.zeros((p.slope_window_epochs, _NG), dtype=bool)
        self._slope_i = 0
        w = p.fluctuation_window_epochs
        self._fx = np.full((w, 0), np.nan)  # C/N0 per (sample in window, satellite slot)
        self._fx_group = np.zeros(0, dtype=np.int64)
        self._ft = np.full(w, np.nan)  # stamps, s
        self._fi = 0
        self._last_ns: int | None = None
        self._last: Cn0SpoofingResult | None = None
        self._fraction_lost = math.nan
        self._high_since_ns: int | None = None
        # Detrending projector of the window (sample index as time): x - A (A'A)^-1 A' x.
        a = np.column_stack([np.ones(w), np.arange(w) - 0.5 * (w - 1)])
        self._proj = np.eye(w) - a @ np.linalg.solve(a.T @ a, a.T)
        self._eye = np.eye(_NG)

    def _thr(self, n_groups: int) -> tuple[float, float]:
        """Suspect and alarm z thresholds over ``n_groups`` groups (Bonferroni)."""
        t = self._thresholds.get(n_groups)
        if t is None:
            n = max(n_groups, 1)
            t = self._thresholds[n_groups] = (normal_threshold(self.params.false_alarm_probability / n),
                                              normal_threshold(self.params.alarm_false_alarm_probability / n))
        return t

    def evaluate(self, ref: Cn0Reference, jamming: Cn0JammingResult | None = None) -> Cn0SpoofingResult:
        """Judge one epoch; ``jamming``: this epoch's ``cn0_drop`` result (a jammed epoch, its
        ``epoch_clean`` False, suspends the elevation and common-fluctuation windows)."""
        p = self.params
        stamp = ref.epoch.stamp_ns
        jammed = jamming is not None and not jamming.epoch_clean
        if self._last_ns is not None:
            dt = (stamp - self._last_ns) * 1e-9
            if not 0 < dt <= p.max_gap_s:
                self._reset_windows()
            elif dt < p.evaluation_interval_s and self._last is not None and not jammed:
                return self._last
        self._last_ns = stamp
        raw = [self._too_high(ref), self._elevation(ref, jammed), self._fluctuation(ref, jammed)]
        outcomes = []
        clean = True
        consts: tuple[int, ...]
        implicated: tuple[tuple[int, int], ...]
        for name, (z, groups, n_groups, sats) in zip(TEST_NAMES, raw, strict=True):
            zs, za = self._thr(n_groups)
            stat, s_w, a_w = self._persist[name].update(stamp, z, zs, za)
            if name == TOO_HIGH:
                since = self._high_since_ns = (self._high_since_ns or stamp) if z >= zs else None
                if since is not None and stamp - since < p.too_high_learning_block_s * 1e9:
                    clean = False
            elif z >= zs:
                clean = False
            decision = decide(stat, s_w, a_w)
            if decision == 0:
                outcomes.append(unknown(name, CATEGORY_CN0, s_w, a_w, p.false_alarm_probability))
                continue
            scope, consts, implicated = 0, (), ()
            if decision >= DECISION_SUSPECT:
                scope, consts = self._scope(ref, groups)
                implicated = tuple(sat for sat in sats if sat[0] in consts)
            outcomes.append(TestOutcome(name, CATEGORY_CN0, decision, stat, s_w, a_w, p.false_alarm_probability,
                                        "1", scope, consts, implicated))
        self._last = Cn0SpoofingResult((outcomes[0], outcomes[1], outcomes[2]), clean, ref.elevation_model_in_use,
                                       raw[0][3], self._fraction_lost)
        return self._last

    def _reset_windows(self) -> None:
        self._slope[:] = 0.0
        self._slope_n[:] = False
        self._fx[:] = np.nan
        self._ft[:] = np.nan

    @staticmethod
    def _scope(ref: Cn0Reference, groups: np.ndarray) -> tuple[int, tuple[int, ...]]:
        """Scope and constellations implicated by the groups over their suspect threshold."""
        present = set(ref.epoch.constellation[ref.valid].tolist())
        named = {int(g) for g in np.flatnonzero(groups)} - {_ALL}
        if named and not named >= present:
            return SCOPE_CONSTELLATIONS, tuple(sorted(named))
        return SCOPE_ALL, tuple(sorted(present))

    # ------------------------------------------------------------------ the tests
    def _too_high(self, ref: Cn0Reference) -> _Raw:
        p = self.params
        e = ref.epoch.cn0_dbhz - ref.expected_dbhz
        use = e == e  # valid C/N0 and a reference (expected is NaN where not valid)
        rows, g = _groups(ref.epoch.constellation, use, p.min_group_satellites)
        n_use = int(np.count_nonzero(use))
        if n_use == 0:
            return _NONE
        sig = ref.std_db
        hi = use & (e >= normal_threshold(p.satellite_false_alarm_probability / n_use) * sig)
        sats = tuple(zip(ref.epoch.constellation[hi].tolist(), ref.epoch.svid[hi].tolist(), strict=True))
        if rows.size == 0:
            return math.nan, _NONE[1], 0, sats
        n = np.bincount(g, minlength=_NG)
        med = _group_median(e[rows], g, n)
        nn = np.maximum(n, 1)
        std = np.sqrt(MEDIAN_EFFICIENCY**2 * np.bincount(g, weights=sig[rows] ** 2, minlength=_NG) / nn**2
                      + p.group_std_floor_db**2)
        z = np.where(n > 0, med / std, -np.inf)
        n_groups = int(np.count_nonzero(n))
        return float(z.max()), z >= self._thr(n_groups)[0], n_groups, sats

    def _elevation(self, ref: Cn0Reference, jammed: bool) -> _Raw:
        p = self.params
        self._fraction_lost = math.nan
        i = self._slope_i
        self._slope_i = (i + 1) % p.slope_window_epochs
        self._slope[i] = 0.0
        self._slope_n[i] = False
        exp = ref.elevation_expected_dbhz
        rows, g = _groups(ref.epoch.constellation, (exp == exp) & (not jammed), p.min_group_satellites)
        if rows.size == 0:
            return _NONE
        s = np.sin(ref.epoch.elevation_rad[rows])
        n = np.bincount(g, minlength=_NG)
        ds = s - (np.bincount(g, weights=s, minlength=_NG) / np.maximum(n, 1))[g]
        ds2 = ds * ds
        sxx = np.bincount(g, weights=ds2, minlength=_NG)
        ok = (n >= p.min_group_satellites) & (sxx >= n * p.min_sin_elevation_std**2)
        if not ok.any():
            return _NONE
        self._slope[i, 0] = np.bincount(g, weights=ds * (ref.epoch.cn0_dbhz[rows] - exp[rows]), minlength=_NG)
        self._slope[i, 1] = np.bincount(g, weights=ds * exp[rows], minlength=_NG)
        self._slope[i, 2] = sxx
        self._slope[i, 3] = np.bincount(g, weights=ds2 * ref.elevation_std_db[rows] ** 2, minlength=_NG)
        self._slope[i] *= ok
        self._slope_n[i] = ok
        tot = self._slope.sum(axis=0)
        sxx_w = np.where(tot[2] > 0, tot[2], np.inf)
        c, b = tot[0] / sxx_w, tot[1] / sxx_w
        v = self._slope_n.sum(axis=0) * tot[3] / sxx_w**2 + p.slope_std_floor_db**2
        live = ok & (b >= p.min_model_slope_db)
        if not live.any():
            return _NONE
        z = np.where(live, -c / np.sqrt(v), -np.inf)
        self._fraction_lost = float(np.max(np.where(live, -c / np.where(live, b, 1.0), -np.inf)))
        n_groups = int(np.count_nonzero(live))
        return float(z.max()), z >= self._thr(n_groups)[0], n_groups, ()

    def _fluctuation(self, ref: Cn0Reference, jammed: bool) -> _Raw:
        p = self.params
        w = p.fluctuation_window_epochs
        if jammed:
            self._fx[:] = np.nan
            self._ft[:] = np.nan
            return _NONE
        n_slots = int(ref.slots.max()) + 1 if ref.slots.size else 0
        if n_slots > self._fx.shape[1]:
            grow = max(n_slots, 2 * self._fx.shape[1]) - self._fx.shape[1]
            self._fx = np.hstack([self._fx, np.full((w, grow), np.nan)])
            self._fx_group = np.concatenate([self._fx_group, np.zeros(grow, dtype=np.int64)])
        i = self._fi
        self._fi = (i + 1) % w
        self._fx[i] = np.nan
        self._fx[i, ref.slots[ref.valid]] = ref.epoch.cn0_dbhz[ref.valid]
        self._fx_group[ref.slots] = ref.epoch.constellation
        self._ft[i] = ref.epoch.stamp_ns * 1e-9
        if self._ft[self._fi] != self._ft[self._fi]:  # window not full yet
            return _NONE
        complete = ~np.isnan(self._fx.sum(axis=0))
        rows, g = _groups(self._fx_group, complete, p.min_group_satellites)
        if rows.size == 0:
            return _NONE
        x = self._proj @ np.roll(self._fx[:, rows], -self._fi, axis=0)  # detrended, time order, (w, k)
        n = np.bincount(g, minlength=_NG)
        common = (x @ self._eye[g]) / np.maximum(n, 1)  # (w, groups)
        between = n * np.einsum("ij,ij->j", common, common)
        resid = x - common[:, g]
        within = np.bincount(g, weights=np.einsum("ij,ij->j", resid, resid), minlength=_NG)
        # Mean squares per degree of freedom of white noise; with time-correlated C/N0 they keep their
        # means but hold only d1 (and (n - 1) d1) independent terms.
        d1 = min(w - 2.0, max(1.0, (self._ft.max() - self._ft.min()) / p.decorrelation_s))
        den = within / np.maximum((n - 1) * (w - 2.0), 1.0) + n * p.common_mode_std_floor_db**2
        live = n >= p.min_group_satellites
        f = np.where(live, between / (w - 2.0) / np.where(den > 0, den, np.inf), 0.0)
        z = np.where(live, -ndtri(np.maximum(fdtrc(d1, np.maximum((n - 1) * d1, 1.0), f), 1e-300)), -np.inf)
        n_groups = int(np.count_nonzero(live))
        return float(z.max()), z >= self._thr(n_groups)[0], n_groups, ()

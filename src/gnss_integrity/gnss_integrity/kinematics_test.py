"""Spoofing tests on the GNSS solution's motion: against UWB ranges and against its own Doppler.

Pure (no rclpy). A spoofer that drags the position slowly (0.1-10 m/s) passes any single-epoch
gate: each epoch's snapshot is self-consistent. What it cannot hide is how the error of the GNSS
position *changes* against independent evidence:

- ``uwb_displacement`` (category KINEMATICS): each UWB anchor's range r_j to the tag measures the
  true distance; ``e_j = |p_gnss - a_j| - r_j`` is the GNSS position error projected on the anchor's
  direction (``e_j = u_j . delta + noise``, u_j the unit vector from the anchor to the tag). A clean
  GNSS error changes slowly (a first-order Gauss-Markov process of horizontal 1-sigma
  ``error_std_m``, vertical ``vertical_factor`` times that, correlation time ``error_tau_s``);
  a drag moves it at the spoofer's speed.
- ``motion_consistency`` (category KINEMATICS): the change of the snapshot position over a lag
  against the integral of the snapshot's Doppler velocity over the same lag: a spoofer whose
  Doppler does not follow its pseudoranges (a simple spoofer, or a meaconer's geometry) shows here
  without any anchor. A careful spoofer (consistent Doppler) passes: the blind spot of a receiver
  with no anchor (docs/gnss_integrity/tests.md).

Both use one engine, :class:`LaggedDisplacement`: the residual series is averaged in bins of
``bin_s`` seconds; at every epoch the displacement ``d = y(now) - y(now - L)`` for each lag L in
``lags_s`` is tested with the chi-square statistic ``d^T C^-1 d`` (k components), where
``C = U C_delta(L) U^T + 2 R_bin`` with the Gauss-Markov displacement covariance
``C_delta(L) = 2 (1 - exp(-L / tau)) diag(s_h^2, s_h^2, s_v^2)`` (ENU) and the white noise of the
bin means. The thresholds are chi-square quantiles at the false-alarm probability divided by the
number of lags (Bonferroni), and the statistic is divided by a noise scale learned from passing
epochs (median NIS over the clean history / chi-square median, never below 1) so that a receiver
noisier than the prior does not alarm. The level test ``uwb_level`` checks ``e`` itself against
``level_std_m`` (a jump, or a drag that has already gone far).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gnss_common.constants import NS_PER_S
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar
from gnss_common.multilateration import multilaterate
from rfi_node_common.params import USER, check_positive_finite, parameter

from .kernels import RunningMedian, chi2_form, lagged_chi2
from .outcome import (
    CATEGORY_KINEMATICS,
    DECISION_PASS,
    SCOPE_ALL,
    TestOutcome,
    check_false_alarm_probabilities,
    chi2_threshold,
    decide,
    unknown,
)

MAX_NOISE_SCALE = 4.0
"""Largest learned noise scale (a receiver twice as noisy as the prior): without a bound, a drag just
below the threshold raised the scale with the statistic (0.3 m/s with one anchor: scale 114, never
detected, 49.5 m off; benchmarks/integrity_detection.py)."""
_EYE = np.eye(3)
_EYE.flags.writeable = False
_AXES = {"e": _EYE[0], "n": _EYE[1], "u": _EYE[2]}  # ENU components and their directions
_HORIZONTAL = {"e": _EYE[0], "n": _EYE[1]}


@dataclass(frozen=True)
class KinematicsTestParams:
    """Parameters of the kinematic tests.

    ``error_std_m`` and ``uwb_std_m`` are also parameters of gnss_integrity_node (``gnss_error_std_m``,
    ``uwb_std_m``; :func:`rfi_node_common.params.parameter`: default, description and range written here once).

    Attributes:
        vertical_factor: vertical 1-sigma over horizontal.
        error_tau_s: correlation time of the clean GNSS position error, s.
        white_std_m: epoch-to-epoch (white) 1-sigma of the snapshot position per axis, m.
        max_range_age_s: a UWB range older than this at the GNSS epoch is not used, s.
        tag_speed_allowance_mps: tag speed allowed for the range's age (adds speed x age to the
            range's 1-sigma), m/s.
        lags_s: displacement lags tested, s.
        bin_s: averaging bin, s.
        false_alarm_probability: per-epoch probability of a clean SUSPECT of each test.
        alarm_false_alarm_probability: the same for ALARM.
        level_std_m: 1-sigma of the GNSS error for the level test ``uwb_level``, m.
        velocity_std_mps: 1-sigma of the Doppler velocity per axis (motion_consistency), m/s.
        max_gap_s: a longer gap between epochs restarts the history, s.
        scale_history: passing epochs whose NIS median sets the noise scale.
    """

    error_std_m: float = parameter(
        2.0,
        "Horizontal 1-sigma of the clean snapshot position error the kinematic tests allow, m (vertical twice "
        "that). Raise it for a receiver with poor sky (urban canyon), lower it for a geodetic antenna to see a "
        "slow drag sooner.",
        minimum=0.1, maximum=100.0, group=USER)
    vertical_factor: float = 2.0
    error_tau_s: float = 120.0
    white_std_m: float = 1.0
    uwb_std_m: float = parameter(
        0.1, "UWB range 1-sigma when a range carries none, m (kinematic and UWB range-rate tests).",
        minimum=0.001, maximum=10.0)
    max_range_age_s: float = 0.5
    tag_speed_allowance_mps: float = 2.0
    lags_s: tuple[float, ...] = (5.0, 10.0, 30.0, 100.0, 300.0)
    bin_s: float = 1.0
    false_alarm_probability: float = 1e-6
    alarm_false_alarm_probability: float = 1e-9
    level_std_m: float = 8.0
    velocity_std_mps: float = 0.2
    max_gap_s: float = 10.0
    scale_history: int = 600

    def __post_init__(self) -> None:
        check_positive_finite(self, ("error_std_m", "vertical_factor", "error_tau_s", "white_std_m", "uwb_std_m",
                                     "max_range_age_s", "bin_s", "level_std_m", "velocity_std_mps", "max_gap_s"))
        if not (math.isfinite(self.tag_speed_allowance_mps) and self.tag_speed_allowance_mps >= 0.0):
            raise ValueError("KinematicsTestParams.tag_speed_allowance_mps must be >= 0")
        if not self.lags_s or any(not (math.isfinite(v) and v >= self.bin_s) for v in self.lags_s):
            raise ValueError(f"KinematicsTestParams.lags_s must be non-empty, each >= bin_s, got {self.lags_s}")
        check_false_alarm_probabilities(self)
        if int(self.scale_history) < 10:
            raise ValueError("KinematicsTestParams.scale_history must be >= 10")


@dataclass(frozen=True)
class AnchorRange:
    """One UWB range, anchor in ECEF (the integrity node converts map-frame anchors first).

    Attributes:
        stamp_ns: stamp of the range, ns.
        anchor_id: anchor identifier.
        anchor_ecef_m: anchor position, ECEF, m, shape (3,).
        range_m: measured tag-anchor distance, m.
        range_std_m: its 1-sigma, m (NaN: ``uwb_std_m``).
    """

    stamp_ns: int
    anchor_id: str
    anchor_ecef_m: np.ndarray
    range_m: float
    range_std_m: float = math.nan


class LaggedDisplacement:
    """Chi-square tests of a residual series' displacement over several lags (module docstring).

    Args:
        params: :class:`KinematicsTestParams`.
        name: the test name of the outcome.
    """

    def __init__(self, params: KinematicsTestParams, name: str) -> None:
        self.p = params
        self.name = name
        self._bins: deque[tuple[int, dict[str, tuple[float, float, int]]]] = deque()
        # current bin: index -> {component: (sum, sum of variances, count)}
        self._by_index: dict[int, dict[str, tuple[float, float, int]]] = {}  # the same bins by index
        self._n_lags = len(params.lags_s)
        self._suspect = {k: chi2_threshold(params.false_alarm_probability / self._n_lags, k) for k in range(1, 33)}
        self._alarm = {k: chi2_threshold(params.alarm_false_alarm_probability / self._n_lags, k) for k in range(1, 33)}
        self._median = {k: chi2_threshold(0.5, k) for k in range(1, 33)}
        self._clean = RunningMedian(params.scale_history)
        self._scale = 1.0
        self._last_ns: int | None = None
        sh2 = params.error_std_m**2
        self._cov_axes = np.array([sh2, sh2, (params.vertical_factor * params.error_std_m) ** 2])
        self._white_axes = np.array([1.0, 1.0, params.vertical_factor**2]) * params.white_std_m**2
        # per lag: (bins back, Gauss-Markov factor 2 (1 - exp(-L / tau)))
        self._lags = [(lag, int(round(lag / params.bin_s)), 2.0 * (1.0 - math.exp(-lag / params.error_tau_s)))
                      for lag in params.lags_s]
        self._bin_ns = int(params.bin_s * NS_PER_S)
        self._horizon = int(max(params.lags_s) / params.bin_s) + 2

    def reset(self) -> None:
        """Forget the history (the learned scale stays)."""
        self._bins.clear()
        self._by_index.clear()
        self._last_ns = None

    def add(self, stamp_ns: int, components: dict[str, tuple[float, float]]) -> None:
        """Add one epoch's residuals: component name -> (value m, its own white variance m^2, beyond
        the snapshot's white error ``white_std_m`` that :meth:`test` adds through the directions)."""
        p = self.p
        if self._last_ns is not None and not (0 < stamp_ns - self._last_ns <= p.max_gap_s * NS_PER_S):
            self.reset()
        self._last_ns = stamp_ns
        index = int(stamp_ns // self._bin_ns)
        if not self._bins or self._bins[-1][0] != index:
            self._bins.append((index, {}))
            self._by_index[index] = self._bins[-1][1]
        cur = self._bins[-1][1]
        for key, (value, var) in components.items():
            s, v, n = cur.get(key, (0.0, 0.0, 0))
            cur[key] = (s + value, v + var, n + 1)
        while self._bins and index - self._bins[0][0] > self._horizon:
            old_index, old = self._bins.popleft()
            if self._by_index.get(old_index) is old:
                del self._by_index[old_index]

    def test(self, directions: dict[str, np.ndarray], lag_var_mps2: float = 0.0) -> TestOutcome:
        """The largest scaled chi-square over the lags, from the newest bin.

        Args:
            directions: component -> its direction in ENU (unit 3-vector: the component is the
                GNSS error projected on it), for every component that may be tested.
            lag_var_mps2: variance per second of lag added to each displacement's diagonal, m^2/s
                (an integrated white velocity error).
        """
        p = self.p
        if not self._bins:
            return self._unknown()
        now_index, now = self._bins[-1]
        lags = []  # per lag tested: (lag s, Gauss-Markov factor, components, displacement, own variance, n_eff)
        for lag, back, g in self._lags:
            old = self._by_index.get(now_index - back)
            if old is None:
                continue
            keys = [k for k in now if k in old and k in directions]
            if not keys:
                continue
            # the snapshot's white error is common to every component (one position): it enters
            # through the directions, averaged over each bin's epochs (n_eff)
            lags.append((lag, g, keys, [now[k][0] / now[k][2] - old[k][0] / old[k][2] for k in keys],
                         [now[k][1] / now[k][2] ** 2 + old[k][1] / old[k][2] ** 2 for k in keys],
                         1.0 / (1.0 / min(now[k][2] for k in keys) + 1.0 / min(old[k][2] for k in keys))))
        if not lags:
            return self._unknown()
        if all(t[2] == lags[0][2] for t in lags):  # the usual case: one compiled call for every lag
            stats = lagged_chi2(np.array([directions[k] for k in lags[0][2]], dtype=float),
                                np.array([t[3] for t in lags]), np.array([t[4] for t in lags]),
                                np.array([t[1] for t in lags]), np.array([t[5] for t in lags]),
                                np.array([t[0] for t in lags], dtype=float), self._cov_axes, self._white_axes,
                                float(lag_var_mps2)).tolist()
        else:
            stats = [chi2_form(np.array([directions[k] for k in keys], dtype=float),
                               g * self._cov_axes + (self._white_axes / n_eff + lag_var_mps2 * lag),
                               np.array(own), np.array(d)) for lag, g, keys, d, own, n_eff in lags]
        best_ratio, best = -math.inf, None
        for t, chi2 in zip(lags, stats, strict=True):
            stat = chi2 / self._scale
            k = min(len(t[2]), 32)
            ratio = stat / self._suspect[k]
            if ratio > best_ratio:
                best_ratio, best = ratio, (stat, self._suspect[k], self._alarm[k], k)
        if best is None:
            return self._unknown()
        stat, suspect, alarm, k = best
        out = TestOutcome(self.name, CATEGORY_KINEMATICS, decide(stat, suspect, alarm), stat, suspect, alarm,
                          p.false_alarm_probability, "1", SCOPE_ALL)
        if out.decision == DECISION_PASS:
            self._clean.append(stat * self._scale / self._median[k])
            if len(self._clean) >= 30:
                self._scale = min(MAX_NOISE_SCALE, max(1.0, self._clean.median()))
        return out

    def _unknown(self) -> TestOutcome:
        return unknown(self.name, CATEGORY_KINEMATICS, false_alarm_probability=self.p.false_alarm_probability)


class _LocalFrame:
    """ECEF -> ENU rotation at the first position seen (directions only; recomputed beyond 10 km)."""

    def __init__(self) -> None:
        self.origin: np.ndarray | None = None
        self.rot = np.eye(3)

    def rotation(self, position_ecef_m: np.ndarray) -> np.ndarray:
        if self.origin is None or np.linalg.norm(position_ecef_m - self.origin) > 1e4:
            lat, lon, _ = ecef_to_geodetic_scalar(*map(float, position_ecef_m))
            self.origin = np.asarray(position_ecef_m, float).copy()
            self.rot = ecef_to_enu_rotation(lat, lon)
        return self.rot


@dataclass
class KinematicsTest:
    """The GNSS snapshot against UWB ranges and against its own Doppler, epoch by epoch."""

    params: KinematicsTestParams = field(default_factory=KinematicsTestParams)
    counts: dict[str, int] = field(default_factory=lambda: {"stale_ranges": 0, "epochs_without_fix": 0})

    def __post_init__(self) -> None:
        self._uwb = LaggedDisplacement(self.params, "uwb_displacement")
        self._motion = LaggedDisplacement(self.params, "motion_consistency")
        self._ranges: dict[str, AnchorRange] = {}
        self._frame = _LocalFrame()
        self._integral: np.ndarray | None = None  # integral of the Doppler velocity, ENU m
        self._last: tuple[int, np.ndarray] | None = None
        q = self.params.false_alarm_probability
        p = self.params
        self._level_axes = np.array([1.0, 1.0, p.vertical_factor**2]) * (p.level_std_m**2 + p.white_std_m**2)
        self._level_suspect = {k: chi2_threshold(q, k) for k in range(1, 33)}
        self._level_alarm = {k: chi2_threshold(self.params.alarm_false_alarm_probability, k) for k in range(1, 33)}

    def reset(self) -> None:
        """Forget every history (after a restart of the input)."""
        self._uwb.reset()
        self._motion.reset()
        self._ranges.clear()
        self._integral = None
        self._last = None

    def add_range(self, rng: AnchorRange) -> None:
        """Keep the newest range of each anchor."""
        old = self._ranges.get(rng.anchor_id)
        if old is None or rng.stamp_ns >= old.stamp_ns:
            self._ranges[rng.anchor_id] = rng

    def update(self, stamp_ns: int, position_ecef_m: np.ndarray, velocity_ecef_mps: np.ndarray | None
               ) -> tuple[TestOutcome, TestOutcome, TestOutcome]:
        """One GNSS epoch's snapshot fix.

        Args:
            stamp_ns: the epoch's stamp, ns.
            position_ecef_m: snapshot position, ECEF, m, shape (3,) (NaN: no fix).
            velocity_ecef_mps: snapshot Doppler velocity, ECEF, m/s (None or NaN: none).

        Returns:
            (``uwb_displacement``, ``uwb_level``, ``motion_consistency``) outcomes; UNKNOWN where
            the inputs are missing (no anchor heard, no fix, no velocity, not enough history).
        """
        pos = np.asarray(position_ecef_m, dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            self.counts["epochs_without_fix"] += 1
            return (self._uwb._unknown(), self._level_unknown(), self._motion._unknown())
        rot = self._frame.rotation(pos)
        uwb, level = self._uwb_tests(stamp_ns, pos, rot)
        motion = self._motion_test(stamp_ns, pos, velocity_ecef_mps, rot)
        return uwb, level, motion

    # ------------------------------------------------------------------------------------------
    def _uwb_tests(self, stamp_ns: int, pos: np.ndarray, rot: np.ndarray) -> tuple[TestOutcome, TestOutcome]:
        """The GNSS error seen by the anchors heard within ``max_range_age_s``.

        With three or more anchors the tag is multilaterated (Gauss-Newton from the GNSS position,
        so the solution on the GNSS side of a coplanar set's mirror) and the horizontal GNSS error
        ``p_gnss - p_uwb`` is tested (east, north: the mirror and the anchors' weak vertical
        geometry make the vertical unreliable). With one or two anchors each range's residual
        ``e_j = |p_gnss - a_j| - r_j = u_j . delta + |delta_perp|^2 / (2 r_j)`` is tested, the
        second-order term's fluctuation added to its variance (anchors are metres away, GNSS
        errors metres too).
        """
        p = self.params
        heard = [r for r in self._ranges.values()
                 if abs(stamp_ns - r.stamp_ns) <= p.max_range_age_s * NS_PER_S and r.range_m > 0.0]
        if not heard:
            return self._uwb._unknown(), self._level_unknown()
        var = np.array([(r.range_std_m if math.isfinite(r.range_std_m) and r.range_std_m > 0 else p.uwb_std_m) ** 2
                        + (p.tag_speed_allowance_mps * abs(stamp_ns - r.stamp_ns) / NS_PER_S) ** 2 for r in heard])
        anchors = np.array([r.anchor_ecef_m for r in heard])
        ranges = np.array([r.range_m for r in heard])
        tag = multilaterate(anchors, ranges, pos, max_iterations=8, step_tol_m=1e-4) if len(heard) >= 3 else None
        if tag is not None:
            delta = rot @ (pos - tag)
            comps = {"e": (float(delta[0]), 0.0), "n": (float(delta[1]), 0.0)}
            dirs = _HORIZONTAL
            e_level, u_level, var_level = delta[:2], _EYE[:2].copy(), np.zeros(2)
        else:
            diff = pos - anchors
            dist = np.linalg.norm(diff, axis=1)
            u_level = (rot @ (diff / dist[:, None]).T).T
            e_level = dist - ranges
            perp2 = (2.0 + p.vertical_factor**2) * p.error_std_m**2  # E |delta_perp|^2
            var_level = var + 2.0 * (perp2 / (2.0 * ranges)) ** 2
            comps = {r.anchor_id: (float(e_level[j]), float(var_level[j])) for j, r in enumerate(heard)}
            dirs = {r.anchor_id: u_level[j] for j, r in enumerate(heard)}
        self._uwb.add(stamp_ns, comps)
        disp = self._uwb.test(dirs)
        stat = chi2_form(np.ascontiguousarray(u_level, dtype=float), self._level_axes,
                         np.asarray(var_level, dtype=float), np.asarray(e_level, dtype=float))
        k = min(len(e_level), 32)
        level = TestOutcome("uwb_level", CATEGORY_KINEMATICS,
                            decide(stat, self._level_suspect[k], self._level_alarm[k]), stat,
                            self._level_suspect[k], self._level_alarm[k], p.false_alarm_probability, "1", SCOPE_ALL)
        return disp, level

    def _motion_test(self, stamp_ns: int, pos: np.ndarray, vel: np.ndarray | None, rot: np.ndarray) -> TestOutcome:
        p = self.params
        v = None if vel is None else np.asarray(vel, dtype=float)
        if v is None or v.shape != (3,) or not np.all(np.isfinite(v)):
            self._integral, self._last = None, None
            self._motion.reset()
            return self._motion._unknown()
        v_enu = rot @ v
        if self._last is None or not (0 < stamp_ns - self._last[0] <= p.max_gap_s * NS_PER_S):
            self._integral = np.zeros(3)
            self._motion.reset()
        else:
            dt = (stamp_ns - self._last[0]) / NS_PER_S
            assert self._integral is not None
            self._integral = self._integral + 0.5 * (self._last[1] + v_enu) * dt
        self._last = (stamp_ns, v_enu)
        assert self._integral is not None
        e, n, u = (rot @ pos - self._integral).tolist()
        self._motion.add(stamp_ns, {"e": (e, 0.0), "n": (n, 0.0), "u": (u, 0.0)})
        # the Doppler velocity's error, white with a correlation time of about one bin, integrates
        # to a variance of sigma_v^2 * bin_s per second of lag
        return self._motion.test(_AXES, p.velocity_std_mps**2 * p.bin_s)

    def _level_unknown(self) -> TestOutcome:
        return unknown("uwb_level", CATEGORY_KINEMATICS, false_alarm_probability=self.params.false_alarm_probability)

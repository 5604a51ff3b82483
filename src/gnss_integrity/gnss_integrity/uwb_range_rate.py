"""Spoofing test ``uwb_range_rate``: the GNSS Doppler velocity against the UWB ranges' rates.

Pure (no rclpy). A careful spoofer keeps its Doppler consistent with the position it pushes, so the
receiver's velocity carries the push rate (a 1 m/s push: 1 m/s of velocity error from the first
spoofed epoch), while the UWB anchors keep measuring the true distance. The position tests
(:mod:`.kinematics_test`: ``uwb_level``, ``uwb_displacement`` over 5-300 s) see the drag once the
position has moved; the velocity shows it at once. This is the test that lets the fusion exclude
GNSS before the spoofer has dragged it (docs/gnss_integrity/README.md, fusion_spoofing.md).

Statistic, at every GNSS epoch t with a velocity, over the window W = [t - ``window_s``, t]:

* per anchor j heard at least ``min_ranges`` times in W over at least half of it: the least-squares
  slope ``b_j`` of its ranges against time (m/s; variance ``s_r^2 / sum (tau - mean tau)^2``, s_r the
  range's stated 1-sigma or ``uwb_std_m``). For a tag whose range is a smooth function of time the
  slope is the range's mean rate over the ranges' span [tau_0, tau_1];
* the same mean rate predicted by GNSS: ``f_j = (1 / (tau_1 - tau_0)) integral u_j(t) . v(t) dt``
  over [tau_0, tau_1], with the snapshot Doppler velocity v and the unit vector u_j from the anchor
  to the tag, both linear between epochs (trapezoids), so that a moving robot's acceleration does
  not bias the comparison. The tag at the epoch is multilaterated from the fitted lines' ranges
  when three or more anchors are fitted (``uwb_position_std_m``), else the GNSS position
  (``position_std_m``); at the window's earlier epochs it is moved back along the integrated
  velocity;
* ``d_j = b_j - f_j``; the statistic ``d^T C^-1 d`` with ``C = U S_v U^T + diag(o_j)``: ``S_v`` the
  fix's velocity covariance (mean over W; each axis at least ``velocity_std_floor_mps``^2) common to
  every anchor, ``o_j`` the slope's variance, ``model_std_mps``^2 (the UWB tag's lever arm on a
  turning robot, the ranges' timing) and the line of sight's error for a moving tag
  ``(|v| position 1-sigma / distance_j)^2``. On clean data it is chi-square with k (anchors) degrees of
  freedom; the thresholds are the chi-square quantiles at ``false_alarm_probability`` (SUSPECT) and
  ``alarm_false_alarm_probability`` (ALARM), and the statistic is divided by a noise scale learned
  from passing epochs (median of the clean statistic over its chi-square median, between 0.25 and 4:
  :data:`MIN_NOISE_SCALE` says why this test may learn a receiver quieter than its prior).

An anchor whose ranges do not fit a line within ``max_fit_rms_factor`` times their 1-sigma RMS (a
non-line-of-sight jump inside the window) is left out of the epoch (``counts['anchors_unfit']``).
Blind spot: a push along no anchor's line of sight (one anchor perpendicular to the push), and
a push slower than the velocity noise (about 0.1 m/s with the defaults).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gnss_common.multilateration import multilaterate
from rfi_node_common.params import check_positive_finite

from .kernels import RunningMedian
from .kinematics_test import AnchorRange, KinematicsTestParams
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

NAME = "uwb_range_rate"
MAX_NOISE_SCALE = 4.0
"""The learned noise scale's ceiling (as the other kinematic tests): a push just below the threshold
must not teach the test to accept it."""
MIN_NOISE_SCALE = 0.25
"""The learned noise scale's floor. Unlike the position tests (floor 1), this one may learn that the
receiver is quieter than its prior, down to half the prior's 1-sigma: the prior velocity noise (the
fix's weight model, 0.1 m/s per satellite at zenith) is a low-cost receiver's worst case, and the
statistic of a 1 m/s push is about (1 m/s / velocity 1-sigma)^2, which that prior would keep below the
3-anchor SUSPECT threshold (30.7 at 1e-6)."""
NS = 1_000_000_000


@dataclass(frozen=True)
class UwbRangeRateParams:
    """Parameters of ``uwb_range_rate`` (module docstring).

    Attributes:
        window_s: the window over which ranges are fitted and the velocity averaged, s.
        min_ranges: fewest ranges of an anchor in the window for it to be tested.
        uwb_std_m: 1-sigma of a range that states none, m.
        velocity_std_floor_mps: the least 1-sigma per axis of the GNSS velocity, m/s (the fix's
            covariance is used above it).
        model_std_mps: 1-sigma of what neither side models (lever arm, timing), m/s.
        position_std_m: 1-sigma of the GNSS position for the line of sight of a moving tag, m.
        uwb_position_std_m: the same for the tag multilaterated from three or more anchors, m.
        max_fit_rms_factor: an anchor whose line fit leaves an RMS above this times its 1-sigma is
            left out of the epoch.
        max_gap_s: a longer gap between GNSS velocities restarts the velocity history, s.
        false_alarm_probability: per-epoch probability of a clean SUSPECT.
        alarm_false_alarm_probability: the same for ALARM.
        scale_history: passing epochs whose median sets the noise scale.
    """

    window_s: float = 1.0
    min_ranges: int = 8
    uwb_std_m: float = KinematicsTestParams.uwb_std_m  # one default: the node sets both from uwb_std_m
    velocity_std_floor_mps: float = 0.03
    model_std_mps: float = 0.05
    position_std_m: float = 3.0
    uwb_position_std_m: float = 0.3
    max_fit_rms_factor: float = 3.0
    max_gap_s: float = 1.0
    false_alarm_probability: float = 1e-6
    alarm_false_alarm_probability: float = 1e-9
    scale_history: int = 600

    def __post_init__(self) -> None:
        check_positive_finite(self, ("window_s", "uwb_std_m", "velocity_std_floor_mps", "model_std_mps",
                                     "position_std_m", "uwb_position_std_m", "max_fit_rms_factor", "max_gap_s"))
        if int(self.min_ranges) < 3:
            raise ValueError("UwbRangeRateParams.min_ranges must be >= 3")
        check_false_alarm_probabilities(self)
        if int(self.scale_history) < 10:
            raise ValueError("UwbRangeRateParams.scale_history must be >= 10")


RING = 256
"""Ranges kept per anchor (a ring; at 20 Hz, 12 s: far more than ``window_s`` + ``max_gap_s``)."""
GNSS_RING = 128
"""GNSS velocities kept (a ring; at 20 Hz, 6 s)."""


class _AnchorRing:
    """The newest :data:`RING` ranges of one anchor: stamps, ranges, 1-sigmas, and its position."""

    def __init__(self) -> None:
        self.t_ns = np.full(RING, np.iinfo(np.int64).min, dtype=np.int64)
        self.r = np.zeros(RING)
        self.s = np.zeros(RING)
        self.anchor = np.zeros(3)
        self.head = 0

    def add(self, stamp_ns: int, range_m: float, std_m: float, anchor: np.ndarray) -> None:
        i = self.head % RING
        self.t_ns[i], self.r[i], self.s[i] = stamp_ns, range_m, std_m
        self.anchor = anchor
        self.head += 1


@dataclass
class UwbRangeRateTest:
    """``uwb_range_rate`` (module docstring): feed ranges with :meth:`add_range`, test each epoch with
    :meth:`update`."""

    params: UwbRangeRateParams = field(default_factory=UwbRangeRateParams)
    counts: dict[str, int] = field(default_factory=lambda: {"anchors_unfit": 0, "epochs_tested": 0})

    def __post_init__(self) -> None:
        p = self.params
        self._ranges: dict[str, _AnchorRing] = {}
        self._g_t = np.zeros(GNSS_RING, dtype=np.int64)  # GNSS epochs, oldest first, _g_n of them
        self._g_v = np.zeros((GNSS_RING, 3))
        self._g_c = np.zeros((GNSS_RING, 3, 3))
        self._g_n = 0
        self._keep_ns = int((p.window_s + p.max_gap_s) * NS)
        self._window_ns = int(p.window_s * NS)
        self._suspect = {k: chi2_threshold(p.false_alarm_probability, k) for k in range(1, 33)}
        self._alarm = {k: chi2_threshold(p.alarm_false_alarm_probability, k) for k in range(1, 33)}
        self._median = {k: chi2_threshold(0.5, k) for k in range(1, 33)}
        self._clean = RunningMedian(int(p.scale_history))
        self._scale = 1.0
        self._floor = np.eye(3) * p.velocity_std_floor_mps**2
        self._last_tag: tuple[int, np.ndarray] | None = None  # the last multilaterated tag (stamp, ECEF)

    def reset(self) -> None:
        """Forget the histories (after a restart of the input or a jammed epoch); the noise scale stays."""
        self._ranges.clear()
        self._g_n = 0
        self._last_tag = None

    def add_range(self, rng: AnchorRange) -> None:
        """One UWB range (anchor in ECEF)."""
        if not (math.isfinite(rng.range_m) and np.all(np.isfinite(rng.anchor_ecef_m))):
            return
        ring = self._ranges.get(rng.anchor_id)
        if ring is None:
            ring = self._ranges[rng.anchor_id] = _AnchorRing()
        std = rng.range_std_m if math.isfinite(rng.range_std_m) and rng.range_std_m > 0 else self.params.uwb_std_m
        ring.add(int(rng.stamp_ns), float(rng.range_m), float(std), np.asarray(rng.anchor_ecef_m, dtype=float))

    def _add_gnss(self, stamp_ns: int, vel: np.ndarray, cov: np.ndarray) -> None:
        """Append an epoch's velocity; restart on a stamp going back or a gap; drop what is too old."""
        n = self._g_n
        if n and (stamp_ns <= self._g_t[n - 1] or stamp_ns - self._g_t[n - 1] > self.params.max_gap_s * NS):
            n = 0
        if n == GNSS_RING:
            self._g_t[:-1], self._g_v[:-1], self._g_c[:-1] = self._g_t[1:], self._g_v[1:], self._g_c[1:]
            n -= 1
        self._g_t[n], self._g_v[n], self._g_c[n] = stamp_ns, vel, cov
        n += 1
        first = int(np.searchsorted(self._g_t[:n], stamp_ns - self._keep_ns, side="left"))
        if first:
            self._g_t[:n - first] = self._g_t[first:n]
            self._g_v[:n - first] = self._g_v[first:n]
            self._g_c[:n - first] = self._g_c[first:n]
            n -= first
        self._g_n = n

    def update(self, stamp_ns: int, position_ecef_m: np.ndarray, velocity_ecef_mps: np.ndarray | None,
               velocity_covariance: np.ndarray | None) -> TestOutcome:
        """One GNSS epoch: its snapshot position, Doppler velocity (ECEF, m/s; None: none) and the
        velocity's covariance ((3, 3), (m/s)^2; None or NaN: the floor). UNKNOWN without a velocity,
        without a window of velocities, or without an anchor to test."""
        p = self.params
        pos = np.asarray(position_ecef_m, dtype=float)
        if velocity_ecef_mps is None or pos.shape != (3,) or not np.all(np.isfinite(pos)):
            return self._unknown()
        vel = np.asarray(velocity_ecef_mps, dtype=float)
        if vel.shape != (3,) or not np.all(np.isfinite(vel)):
            return self._unknown()
        cov = np.zeros((3, 3)) if velocity_covariance is None else np.asarray(velocity_covariance, dtype=float)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
            cov = np.zeros((3, 3))
        self._add_gnss(int(stamp_ns), vel, cov)
        n = self._g_n
        start_ns = stamp_ns - self._window_ns
        if self._g_t[0] > start_ns + self._window_ns // 10:
            return self._unknown()  # the velocities do not cover the window yet
        ts = (self._g_t[:n] - stamp_ns) / NS
        vs = self._g_v[:n]
        fits = []  # per anchor: slope, its variance, the line's range now, the anchor, tau_0, tau_1
        for ring in self._ranges.values():
            count, slope, slope_var, line0, tau0, tau1, rms, sig = line_fit(
                ring.t_ns, ring.r, ring.s, int(start_ns), int(stamp_ns))
            if count < p.min_ranges or tau1 - tau0 < 0.5 * p.window_s:
                continue
            if rms > p.max_fit_rms_factor * sig:
                self.counts["anchors_unfit"] += 1
                continue
            fits.append((slope, slope_var, line0, ring.anchor, tau0, tau1))
        if not fits:
            return self._unknown()
        # where the tag was at each GNSS epoch: from the anchors when three or more are fitted (the
        # GNSS position's metres of error, and the spoofer's drag, would turn the lines of sight of a
        # moving tag), else from GNSS; back in time along the integrated Doppler velocity
        tag, pos_std = pos, p.position_std_m
        anchors = np.array([f[3] for f in fits])
        if len(fits) >= 3:
            # from the last epoch's tag (a few iterations; the GNSS velocity is not trusted to move it),
            # else the GNSS position
            guess = pos
            if self._last_tag is not None and 0 < stamp_ns - self._last_tag[0] <= self._window_ns:
                guess = self._last_tag[1]
            solved = multilaterate(anchors, np.array([f[2] for f in fits]), guess)
            if solved is not None:
                tag, pos_std = solved, p.uwb_position_std_m
                self._last_tag = (int(stamp_ns), solved)
        k = min(len(fits), 32)
        predicted, u, dist, s_v, speed = predicted_rates(
            ts, vs, self._g_c[:n], np.ascontiguousarray(tag), anchors[:k],
            np.array([f[4] for f in fits[:k]]), np.array([f[5] for f in fits[:k]]), -p.window_s - 1e-9)
        s_v += self._floor
        dv = np.array([f[0] for f in fits[:k]]) - predicted
        own = (np.array([f[1] for f in fits[:k]]) + p.model_std_mps**2 + (speed * pos_std / dist) ** 2)
        c = u @ s_v @ u.T
        c[np.diag_indices(k)] += own
        chi2 = float(dv @ np.linalg.solve(c, dv))
        self.counts["epochs_tested"] += 1
        stat = chi2 / self._scale
        out = TestOutcome(NAME, CATEGORY_KINEMATICS, decide(stat, self._suspect[k], self._alarm[k]), stat,
                          self._suspect[k], self._alarm[k], p.false_alarm_probability, "1", SCOPE_ALL)
        if out.decision == DECISION_PASS:
            self._clean.append(chi2 / self._median[k])
            if len(self._clean) >= 30:
                self._scale = min(MAX_NOISE_SCALE, max(MIN_NOISE_SCALE, self._clean.median()))
        return out

    def _unknown(self) -> TestOutcome:
        return unknown(NAME, CATEGORY_KINEMATICS, false_alarm_probability=self.params.false_alarm_probability)


@njit(cache=True)
def line_fit(t_ns: np.ndarray, r: np.ndarray, s: np.ndarray, start_ns: int, stamp_ns: int
             ) -> tuple[int, float, float, float, float, float, float, float]:
    """Least-squares line through the ranges stamped in [start_ns, stamp_ns] (any order).

    Returns:
        ``(count, slope m/s, its variance, the line at stamp_ns m, first and last tau s (relative to
        stamp_ns), fit RMS m, RMS of the ranges' 1-sigmas m)``; NaN fields with fewer than 3 ranges.
    """
    n = 0
    st = 0.0
    sr = 0.0
    ss = 0.0
    t_min = math.inf
    t_max = -math.inf
    for i in range(t_ns.size):
        if start_ns <= t_ns[i] <= stamp_ns:
            tau = (t_ns[i] - stamp_ns) / 1e9
            n += 1
            st += tau
            sr += r[i]
            ss += s[i] * s[i]
            t_min = min(t_min, tau)
            t_max = max(t_max, tau)
    if n < 3:
        return n, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan
    t_mean = st / n
    r_mean = sr / n
    sxx = 0.0
    sxy = 0.0
    for i in range(t_ns.size):
        if start_ns <= t_ns[i] <= stamp_ns:
            tc = (t_ns[i] - stamp_ns) / 1e9 - t_mean
            sxx += tc * tc
            sxy += tc * (r[i] - r_mean)
    if not sxx > 0.0:
        return n, math.nan, math.nan, math.nan, t_min, t_max, math.nan, math.nan
    slope = sxy / sxx
    sq = 0.0
    for i in range(t_ns.size):
        if start_ns <= t_ns[i] <= stamp_ns:
            tc = (t_ns[i] - stamp_ns) / 1e9 - t_mean
            e = r[i] - r_mean - slope * tc
            sq += e * e
    sig2 = ss / n
    return n, slope, sig2 / sxx, r_mean - slope * t_mean, t_min, t_max, math.sqrt(sq / n), math.sqrt(sig2)


@njit(cache=True)
def predicted_rates(ts: np.ndarray, vs: np.ndarray, covs: np.ndarray, tag: np.ndarray, anchors: np.ndarray,
                    tau0: np.ndarray, tau1: np.ndarray, window_start: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """GNSS's mean range rate of each anchor over its ranges' span (module docstring).

    Args:
        ts: GNSS epochs, s relative to now (ascending, the last 0), (n,). vs: their velocities, (n, 3).
        covs: their velocity covariances, (n, 3, 3). tag: the tag now, (3,). anchors: (k, 3).
        tau0, tau1: each anchor's ranges' span, s relative to now, (k,). window_start: the window's
        start, s relative to now (for the mean covariance and speed).

    Returns:
        ``(predicted mean rates (k,), unit lines of sight now (k, 3), distances now (k,), mean velocity
        covariance over the window (3, 3), |mean velocity| over the window)``.
    """
    n = ts.size
    k = anchors.shape[0]
    # the tag at each epoch: back from now along the trapezoid-integrated velocity
    ps = np.empty((n, 3))
    for a in range(3):
        ps[n - 1, a] = tag[a]
    for i in range(n - 2, -1, -1):
        dt = ts[i + 1] - ts[i]
        for a in range(3):
            ps[i, a] = ps[i + 1, a] - (vs[i + 1, a] + vs[i, a]) / 2.0 * dt
    predicted = np.empty(k)
    u = np.empty((k, 3))
    dist = np.empty(k)
    rate = np.empty(n)
    for j in range(k):
        for i in range(n):
            d0 = ps[i, 0] - anchors[j, 0]
            d1 = ps[i, 1] - anchors[j, 1]
            d2 = ps[i, 2] - anchors[j, 2]
            dd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            rate[i] = (d0 * vs[i, 0] + d1 * vs[i, 1] + d2 * vs[i, 2]) / dd
            if i == n - 1:
                dist[j] = dd
                u[j, 0], u[j, 1], u[j, 2] = d0 / dd, d1 / dd, d2 / dd
        predicted[j] = _mean_of_piecewise_linear(ts, rate, tau0[j], tau1[j])
    s_v = np.zeros((3, 3))
    v_mean = np.zeros(3)
    m = 0
    for i in range(n):
        if ts[i] >= window_start:
            m += 1
            for a in range(3):
                v_mean[a] += vs[i, a]
                for b in range(3):
                    s_v[a, b] += covs[i, a, b]
    s_v /= max(m, 1)
    v_mean /= max(m, 1)
    return predicted, u, dist, s_v, math.sqrt(v_mean[0] ** 2 + v_mean[1] ** 2 + v_mean[2] ** 2)


@njit(cache=True)
def _mean_of_piecewise_linear(t: np.ndarray, f: np.ndarray, t0: float, t1: float) -> float:
    """Mean over [t0, t1] of the function linear between the samples (t, f) (held beyond them)."""
    total = 0.0
    x_prev = t0
    y_prev = np.interp(t0, t, f)
    for i in range(t.size):
        if t0 < t[i] < t1:
            total += (f[i] + y_prev) * (t[i] - x_prev)
            x_prev, y_prev = t[i], f[i]
    y1 = np.interp(t1, t, f)
    total += (y1 + y_prev) * (t1 - x_prev)
    return total / 2.0 / (t1 - t0)


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels of this module on throwaway inputs."""
    t = np.arange(10, dtype=np.int64) * 100_000_000
    line_fit(t, np.ones(10), np.ones(10), 0, int(t[-1]))
    ts = np.linspace(-1.0, 0.0, 6)
    predicted_rates(ts, np.ones((6, 3)), np.zeros((6, 3, 3)), np.full(3, 5.0), np.zeros((2, 3)),
                    np.full(2, -0.9), np.zeros(2), -1.0)

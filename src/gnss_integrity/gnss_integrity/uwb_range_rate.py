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
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gnss_common.multilateration import multilaterate

from .kernels import RunningMedian
from .kinematics_test import AnchorRange
from .outcome import (
    CATEGORY_KINEMATICS,
    DECISION_PASS,
    SCOPE_ALL,
    TestOutcome,
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
    uwb_std_m: float = 0.1
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
        for name in ("window_s", "uwb_std_m", "velocity_std_floor_mps", "model_std_mps", "position_std_m",
                     "uwb_position_std_m",
                     "max_fit_rms_factor", "max_gap_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"UwbRangeRateParams.{name} must be a finite number > 0, got {value!r}")
        if int(self.min_ranges) < 3:
            raise ValueError("UwbRangeRateParams.min_ranges must be >= 3")
        if not 0.0 < self.alarm_false_alarm_probability <= self.false_alarm_probability < 0.5:
            raise ValueError("UwbRangeRateParams: need 0 < alarm_false_alarm_probability <= "
                             "false_alarm_probability < 0.5")
        if int(self.scale_history) < 10:
            raise ValueError("UwbRangeRateParams.scale_history must be >= 10")


@dataclass
class UwbRangeRateTest:
    """``uwb_range_rate`` (module docstring): feed ranges with :meth:`add_range`, test each epoch with
    :meth:`update`."""

    params: UwbRangeRateParams = field(default_factory=UwbRangeRateParams)
    counts: dict[str, int] = field(default_factory=lambda: {"anchors_unfit": 0, "epochs_tested": 0})

    def __post_init__(self) -> None:
        p = self.params
        self._ranges: dict[str, deque[tuple[int, float, float, np.ndarray]]] = {}
        self._gnss: deque[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = deque()  # stamp, pos, vel, cov
        self._keep_ns = int((p.window_s + p.max_gap_s) * NS)
        self._window_ns = int(p.window_s * NS)
        self._suspect = {k: chi2_threshold(p.false_alarm_probability, k) for k in range(1, 33)}
        self._alarm = {k: chi2_threshold(p.alarm_false_alarm_probability, k) for k in range(1, 33)}
        self._median = {k: chi2_threshold(0.5, k) for k in range(1, 33)}
        self._clean = RunningMedian(int(p.scale_history))
        self._scale = 1.0

    def reset(self) -> None:
        """Forget the histories (after a restart of the input or a jammed epoch); the noise scale stays."""
        self._ranges.clear()
        self._gnss.clear()

    def add_range(self, rng: AnchorRange) -> None:
        """One UWB range (anchor in ECEF)."""
        if not (math.isfinite(rng.range_m) and np.all(np.isfinite(rng.anchor_ecef_m))):
            return
        q = self._ranges.setdefault(rng.anchor_id, deque())
        std = rng.range_std_m if math.isfinite(rng.range_std_m) and rng.range_std_m > 0 else self.params.uwb_std_m
        q.append((int(rng.stamp_ns), float(rng.range_m), float(std), np.asarray(rng.anchor_ecef_m, dtype=float)))
        while q and q[-1][0] - q[0][0] > self._keep_ns:
            q.popleft()

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
        if self._gnss and (stamp_ns <= self._gnss[-1][0] or stamp_ns - self._gnss[-1][0] > p.max_gap_s * NS):
            self._gnss.clear()
        self._gnss.append((int(stamp_ns), pos, vel, cov))
        while self._gnss and stamp_ns - self._gnss[0][0] > self._keep_ns:
            self._gnss.popleft()
        start_ns = stamp_ns - self._window_ns
        if self._gnss[0][0] > start_ns + self._window_ns // 10:
            return self._unknown()  # the velocities do not cover the window yet
        ts = np.array([(g[0] - stamp_ns) / NS for g in self._gnss])
        vs = np.array([g[2] for g in self._gnss])
        in_window = ts >= -p.window_s - 1e-9
        s_v = np.mean([g[3] for g, w in zip(self._gnss, in_window, strict=True) if w], axis=0)
        s_v = s_v + np.eye(3) * p.velocity_std_floor_mps**2
        speed = float(np.linalg.norm(vs[in_window].mean(axis=0)))
        fits = []  # per anchor: slope, its variance, the line's range now, the anchor
        for q in self._ranges.values():
            sel = [r for r in q if start_ns <= r[0] <= stamp_ns]
            if len(sel) < p.min_ranges:
                continue
            tau = np.array([(r[0] - stamp_ns) / NS for r in sel])
            if tau.max() - tau.min() < 0.5 * p.window_s:
                continue
            rng = np.array([r[1] for r in sel])
            sig = float(np.sqrt(np.mean(np.array([r[2] for r in sel]) ** 2)))
            tc = tau - tau.mean()
            sxx = float(np.dot(tc, tc))
            slope = float(np.dot(tc, rng - rng.mean()) / sxx)
            fit = rng - rng.mean() - slope * tc
            if math.sqrt(float(np.mean(fit**2))) > p.max_fit_rms_factor * sig:
                self.counts["anchors_unfit"] += 1
                continue
            fits.append((slope, sig**2 / sxx, float(rng.mean() - slope * tau.mean()), sel[-1][3],
                         float(tau.min()), float(tau.max())))
        if not fits:
            return self._unknown()
        # where the tag was at each GNSS epoch: from the anchors when three or more are fitted (the
        # GNSS position's metres of error, and the spoofer's drag, would turn the lines of sight of a
        # moving tag), else from GNSS; back in time along the integrated Doppler velocity
        tag, pos_std = pos, p.position_std_m
        if len(fits) >= 3:
            solved = multilaterate(np.array([f[3] for f in fits]), np.array([f[2] for f in fits]), pos)
            if solved is not None:
                tag, pos_std = solved, p.uwb_position_std_m
        steps = (vs[1:] + vs[:-1]) / 2.0 * np.diff(ts)[:, None]
        back = np.concatenate((np.cumsum(steps[::-1], axis=0)[::-1], np.zeros((1, 3))))
        ps = tag - back  # (n, 3): the tag at each GNSS epoch
        rows, d, own = [], [], []
        for slope, slope_var, _, anchor, tau0, tau1 in fits:
            los = ps - anchor
            dist = np.linalg.norm(los, axis=1)
            rate = np.einsum("ij,ij->i", los, vs) / dist  # u_j . v at each GNSS epoch
            rows.append(los[-1] / dist[-1])
            d.append(slope - _mean_of_piecewise_linear(ts, rate, tau0, tau1))
            own.append(slope_var + p.model_std_mps**2 + (speed * pos_std / dist[-1]) ** 2)
        if not rows:
            return self._unknown()
        k = min(len(rows), 32)
        u = np.array(rows[:k])
        c = u @ s_v @ u.T + np.diag(own[:k])
        dv = np.array(d[:k])
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


def _mean_of_piecewise_linear(t: np.ndarray, f: np.ndarray, t0: float, t1: float) -> float:
    """Mean over [t0, t1] of the function linear between the samples (t, f) (held beyond them)."""
    inner = t[(t > t0) & (t < t1)]
    x = np.concatenate(([t0], inner, [t1]))
    y = np.interp(x, t, f)
    return float(np.sum((y[1:] + y[:-1]) * np.diff(x)) / 2.0 / (t1 - t0))

"""Position-error metrics shared by the benchmarks and the integration tests (pure numpy, no ROS).

* :func:`interpolate_truth`: truth position at the estimate stamps (linear; NaN outside its span).
* :func:`ecef_errors_enu`: ECEF estimate - truth, rotated into ENU at the truth position.
* :func:`horizontal_error_m`, :func:`error_3d_m`: norms of ENU (or local-frame) error vectors.
* :func:`error_stats`: RMS, 95th percentile, max (non-finite samples excluded and counted).
* :func:`empirical_cdf`: sorted errors and their cumulative probabilities.
* :func:`time_to_recover_s`: recovery time after a jamming burst.
* :func:`hanyang_authors_rmse`: 3D / 2D RMSE scored as the Hanyang UWB dataset's authors score it
  (window from the truth path, tag height, truth kept only near the ground plane).

Times are integer ns (``stamp_ns``) or float seconds where named ``_s``.

Notes
-----
ENU rotation: Hofmann-Wellenhof et al. 2008, eq. 10.41 (via :mod:`gnss_common.coordinates`).
The 95th percentile is numpy's linear-interpolation percentile (Hyndman and Fan 1996, definition 7).
Time to recover is this suite's own definition (no paper equation): the first instant after the
burst end from which the error stays within k times its pre-burst RMS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic


def _points(xyz: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(xyz, dtype=float)
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) or (3,), got {np.shape(xyz)}")
    return arr


def interpolate_truth(truth_stamp_ns: np.ndarray, truth_position_m: np.ndarray,
                      stamp_ns: np.ndarray) -> np.ndarray:
    """Linearly interpolate a truth trajectory at the given stamps.

    Args:
        truth_stamp_ns: truth stamps, integer ns, (M,), strictly increasing, M >= 2 (M == 1 allowed
            for a static truth: it is then returned at every stamp).
        truth_position_m: truth positions, m, (M, 3), any frame.
        stamp_ns: query stamps, integer ns, (N,).

    Returns:
        Positions, m, (N, 3); rows outside [first, last] truth stamp are NaN (no extrapolation).

    Raises:
        ValueError: shape mismatch, empty truth, non-increasing truth stamps.
    """
    t_truth = np.asarray(truth_stamp_ns, dtype=np.int64).reshape(-1)
    pos = _points(truth_position_m, "truth_position_m")
    t = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
    if t_truth.size == 0 or pos.shape[0] != t_truth.size:
        raise ValueError(f"need M >= 1 truth stamps and (M, 3) positions, got {t_truth.size} and {pos.shape}")
    if t_truth.size == 1:
        return np.repeat(pos, t.size, axis=0)
    if np.any(np.diff(t_truth) <= 0):
        raise ValueError("truth_stamp_ns must be strictly increasing")
    # Interpolate on ns offsets from the first truth stamp (exact integers, no float64 loss at 1e18).
    x = (t - t_truth[0]).astype(float)
    xp = (t_truth - t_truth[0]).astype(float)
    out = np.stack([np.interp(x, xp, pos[:, k]) for k in range(3)], axis=1)
    out[(t < t_truth[0]) | (t > t_truth[-1])] = np.nan
    return out


def ecef_errors_enu(estimate_ecef_m: np.ndarray, truth_ecef_m: np.ndarray) -> np.ndarray:
    """Estimate - truth in ECEF, expressed in the ENU frame at the truth position.

    Args:
        estimate_ecef_m: estimated ECEF positions, m, (N, 3) or (3,).
        truth_ecef_m: truth ECEF positions, m, (N, 3), or (3,) for a static truth.

    Returns:
        ENU error vectors, m, (N, 3); rows with a non-finite input are NaN.

    Raises:
        ValueError: wrong shapes.

    Notes
    -----
    e_enu = R(lat_t, lon_t) (x_est - x_truth), R of Hofmann-Wellenhof et al. 2008, eq. 10.41.
    """
    est = _points(estimate_ecef_m, "estimate_ecef_m")
    truth = _points(truth_ecef_m, "truth_ecef_m")
    if truth.shape[0] == 1:
        truth = np.repeat(truth, est.shape[0], axis=0)
    if truth.shape != est.shape:
        raise ValueError(f"truth_ecef_m {truth.shape} does not match estimate_ecef_m {est.shape}")
    out = np.full(est.shape, np.nan)
    ok = np.all(np.isfinite(est), axis=1) & np.all(np.isfinite(truth), axis=1)
    if np.any(ok):
        geo = np.atleast_2d(ecef_to_geodetic(truth[ok]))
        diff = est[ok] - truth[ok]
        rot = np.stack([ecef_to_enu_rotation(lat, lon) for lat, lon in geo[:, :2]])
        out[ok] = np.einsum("nij,nj->ni", rot, diff)
    return out


def horizontal_error_m(error_enu_m: np.ndarray) -> np.ndarray:
    """Horizontal error norm sqrt(e^2 + n^2), m, (N,), of ENU (or local x/y/z) errors (N, 3)."""
    e = _points(error_enu_m, "error_enu_m")
    return np.hypot(e[:, 0], e[:, 1])


def error_3d_m(error_m: np.ndarray) -> np.ndarray:
    """3D error norm, m, (N,), of error vectors (N, 3)."""
    e = _points(error_m, "error_m")
    return np.linalg.norm(e, axis=1)


@dataclass(frozen=True)
class ErrorStats:
    """Summary of an error series, m.

    Attributes:
        count: finite samples used.
        rejected_non_finite: NaN / inf samples excluded (e.g. no estimate or outside the truth span).
        rms_m: root mean square.
        p95_m: 95th percentile (linear interpolation).
        max_m: maximum.
        mean_m: mean.
    """

    count: int
    rejected_non_finite: int
    rms_m: float
    p95_m: float
    max_m: float
    mean_m: float


def error_stats(errors_m: np.ndarray) -> ErrorStats:
    """RMS, 95th percentile, max and mean of non-negative error norms.

    Args:
        errors_m: error norms, m, (N,); non-finite entries are excluded and counted.

    Returns:
        :class:`ErrorStats`.

    Raises:
        ValueError: no finite sample, or a negative error.
    """
    e = np.asarray(errors_m, dtype=float).reshape(-1)
    finite = np.isfinite(e)
    good = e[finite]
    if good.size == 0:
        raise ValueError(f"no finite error samples among {e.size}")
    if np.any(good < 0.0):
        raise ValueError("errors_m must be norms (>= 0)")
    return ErrorStats(
        count=int(good.size),
        rejected_non_finite=int(e.size - good.size),
        rms_m=float(np.sqrt(np.mean(good**2))),
        p95_m=float(np.percentile(good, 95.0)),
        max_m=float(good.max()),
        mean_m=float(good.mean()),
    )


def empirical_cdf(errors_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Empirical CDF of an error series.

    Args:
        errors_m: errors, m, (N,); non-finite entries are dropped.

    Returns:
        ``(x_m, p)``: sorted finite errors (K,) and P(error <= x) = (i + 1) / K, (K,).

    Raises:
        ValueError: no finite sample.
    """
    e = np.asarray(errors_m, dtype=float).reshape(-1)
    x = np.sort(e[np.isfinite(e)])
    if x.size == 0:
        raise ValueError("no finite error samples")
    return x, np.arange(1, x.size + 1) / x.size


def time_to_recover_s(
    t_s: np.ndarray,
    error_m: np.ndarray,
    burst_start_s: float,
    burst_end_s: float,
    k: float = 2.0,
    pre_burst_window_s: float | None = None,
    hold_s: float | None = None,
) -> float:
    """Time after a burst until the error returns to, and stays within, k times its pre-burst level.

    Args:
        t_s: sample times, s, (N,), strictly increasing.
        error_m: error norms at ``t_s``, m, (N,); non-finite samples count as "not recovered"
            (no estimate is not a good estimate).
        burst_start_s: burst start, s.
        burst_end_s: burst end, s (>= burst_start_s).
        k: tolerance factor (> 0) on the pre-burst level.
        pre_burst_window_s: the pre-burst level is the RMS of the finite errors in
            [burst_start - window, burst_start); None uses every sample before the burst.
        hold_s: the error must stay within the bound for this long (s) after the recovery
            instant; None requires it until the end of the series.

    Returns:
        ``t_rec - burst_end_s`` in s, where t_rec is the first sample time >= burst_end_s from
        which the error stays within ``k * level``; 0.0 if already within at the burst end;
        ``math.inf`` if it never recovers (or the series ends before ``hold_s`` is observed).

    Raises:
        ValueError: bad shapes, unordered times, invalid k / window / burst, no finite pre-burst
            sample.
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    e = np.asarray(error_m, dtype=float).reshape(-1)
    if t.shape != e.shape or t.size == 0:
        raise ValueError(f"t_s and error_m must be non-empty and of equal length, got {t.size}, {e.size}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be finite and strictly increasing")
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"k must be finite and > 0, got {k}")
    if not (math.isfinite(burst_start_s) and math.isfinite(burst_end_s) and burst_end_s >= burst_start_s):
        raise ValueError(f"need finite burst_start_s <= burst_end_s, got {burst_start_s}, {burst_end_s}")
    if pre_burst_window_s is not None and not (math.isfinite(pre_burst_window_s) and pre_burst_window_s > 0):
        raise ValueError(f"pre_burst_window_s must be None or > 0, got {pre_burst_window_s}")
    if hold_s is not None and not (math.isfinite(hold_s) and hold_s >= 0):
        raise ValueError(f"hold_s must be None or >= 0, got {hold_s}")
    lo = -math.inf if pre_burst_window_s is None else burst_start_s - pre_burst_window_s
    pre = e[(t >= lo) & (t < burst_start_s) & np.isfinite(e)]
    if pre.size == 0:
        raise ValueError("no finite error sample before the burst to define the pre-burst level")
    bound = k * float(np.sqrt(np.mean(pre**2)))
    after = np.flatnonzero(t >= burst_end_s)
    if after.size == 0:
        return math.inf
    bad = ~(np.isfinite(e) & (e <= bound))
    if hold_s is None:
        bad_after = after[bad[after]]
        if bad_after.size == 0:
            return float(t[after[0]] - burst_end_s)
        j = int(bad_after[-1]) + 1
        return math.inf if j >= t.size else float(t[j] - burst_end_s)
    for i in after:
        if bad[i]:
            continue
        if t[-1] - t[i] < hold_s:
            return math.inf
        window = (t >= t[i]) & (t <= t[i] + hold_s)
        if not np.any(bad[window]):
            return float(t[i] - burst_end_s)
    return math.inf


@dataclass(frozen=True)
class HanyangWindowRule:
    """Start/end of the scored window of a Hanyang dynamic case, from the truth path (local frame, m).

    The window starts at the first truth row whose (x, y) satisfies ``start`` and ends at the first
    later row that satisfies ``end``. Each rule is a pair of half-planes per axis; ``None`` leaves an
    axis free. Bounds are strict or not as the authors wrote them (see the module constants).
    """

    start_x_gt_m: float | None = None
    start_x_lt_m: float | None = None
    start_y_gt_m: float | None = None
    start_y_lt_m: float | None = None
    end_x_le_m: float | None = None
    end_x_gt_m: float | None = None
    end_y_gt_m: float | None = None
    end_y_lt_m: float | None = None

    def starts(self, x: float, y: float) -> bool:
        return _half_planes(x, y, gt=(self.start_x_gt_m, self.start_y_gt_m), lt=(self.start_x_lt_m, self.start_y_lt_m))

    def ends(self, x: float, y: float) -> bool:
        if self.end_x_le_m is not None and not x <= self.end_x_le_m:
            return False
        return _half_planes(x, y, gt=(self.end_x_gt_m, self.end_y_gt_m), lt=(None, self.end_y_lt_m))


def _half_planes(x: float, y: float, gt: tuple[float | None, float | None],
                 lt: tuple[float | None, float | None]) -> bool:
    for v, g, le in ((x, gt[0], lt[0]), (y, gt[1], lt[1])):
        if g is not None and not v > g:
            return False
        if le is not None and not v < le:
            return False
    return True


HANYANG_WINDOWS = {
    "Trajectory_A": HanyangWindowRule(start_x_gt_m=49.3, start_y_gt_m=-5.0, end_x_le_m=12.0, end_y_gt_m=3.4),
    "Trajectory_B": HanyangWindowRule(start_x_lt_m=8.6, start_y_lt_m=-7.0, end_x_gt_m=8.6, end_y_lt_m=-7.0),
}
"""Scored windows of the dataset's two dynamic trajectories, as the dataset authors' own analysis
script (``localization_error_analysis.py`` of cucudasluv/UWB-dataset, commit 5701fb04) sets them:
trajectory A's rule is the script's active one, trajectory B's its commented alternative. With these,
:func:`hanyang_authors_rmse` reproduces the ``RMSD_results.txt`` of LOS/Trajectory_A/Case_1,
LOS/Trajectory_B/Case_3 and NLOS/Trajectory_A/Case_1 to the last printed digit."""

HANYANG_TAG_HEIGHT_M = 1.0
"""Height of the UWB tag above the GNSS truth reference, m: the authors compare estimate z with
truth z + 1 m (their truth z is near 0, the tag is carried about 1 m up)."""

HANYANG_TRUTH_MAX_ABS_Z_M = 0.5
"""Truth rows with |z| at or above this (m) are left out by the authors' scoring (RTK height outliers)."""


def hanyang_authors_rmse(truth: np.ndarray, stamp_ns: np.ndarray, position_m: np.ndarray,
                         rule: HanyangWindowRule) -> tuple[float, float, int]:
    """3D and 2D RMSE of a solution, scored as the Hanyang dataset's authors score LS.csv / ESKF.csv.

    Steps (the authors' analysis, re-implemented; no paper equation):

    1. window ``[t_start, t_end]``: the truth stamps where ``rule`` starts and then ends;
    2. truth rows inside the window with ``|z| < 0.5 m`` are the reference (times relative to the
       first truth row of the window, before the z filter);
    3. each solution row inside the window is compared with the truth linearly interpolated at its
       time (the nearest end row outside the truth's span), with ``z_truth + 1 m`` as the height;
    4. RMSE over all those rows: 3D (x, y, z) and 2D (x, y).

    Args:
        truth: ``trajectory.csv`` as an (M, >=4) array: stamp ns, x, y, z (m, anchors' local frame),
            in time order.
        stamp_ns: solution stamps, ns (N,).
        position_m: solution positions, m, (N, 3), same frame.
        rule: the case's window rule (:data:`HANYANG_WINDOWS`).

    Returns:
        ``(rmse_3d_m, rmse_2d_m, n_scored)``.

    Raises:
        ValueError: bad shapes, a window that never starts or ends, or no solution row inside it.
    """
    tr = np.asarray(truth, dtype=float)
    if tr.ndim != 2 or tr.shape[1] < 4 or tr.shape[0] < 2:
        raise ValueError(f"truth must have shape (M>=2, >=4), got {tr.shape}")
    ts = np.asarray(stamp_ns, dtype=float).reshape(-1)
    xyz = _points(position_m, "position_m")
    if ts.size != xyz.shape[0]:
        raise ValueError(f"stamp_ns ({ts.size}) and position_m ({xyz.shape[0]}) differ in length")
    start = end = None
    for t, x, y in tr[:, :3]:
        if start is None and rule.starts(x, y):
            start = t
        if start is not None and rule.ends(x, y):
            end = t
            break
    if start is None or end is None:
        raise ValueError(f"the truth path never {'starts' if start is None else 'ends'} the scored window of {rule}")
    inside = (tr[:, 0] >= start) & (tr[:, 0] <= end)
    base = tr[inside][0, 0]
    ref = tr[inside]
    ref = ref[np.abs(ref[:, 3]) < HANYANG_TRUTH_MAX_ABS_Z_M]
    t_ref = ref[:, 0] - base
    m = (ts >= start) & (ts <= end)
    if not np.any(m):
        raise ValueError("no solution row inside the scored window")
    t_est = ts[m] - base
    k = np.searchsorted(t_ref, t_est, side="right")
    lo = np.clip(k - 1, 0, len(t_ref) - 1)
    hi = np.clip(k, 0, len(t_ref) - 1)
    span = t_ref[hi] - t_ref[lo]
    ratio = np.where(span > 0, (t_est - t_ref[lo]) / np.where(span > 0, span, 1.0), 0.0)
    truth_xyz = ref[lo, 1:4] + ratio[:, None] * (ref[hi, 1:4] - ref[lo, 1:4])
    d = xyz[m] - truth_xyz
    sq2 = d[:, 0] ** 2 + d[:, 1] ** 2
    sq3 = sq2 + (truth_xyz[:, 2] + HANYANG_TAG_HEIGHT_M - xyz[m][:, 2]) ** 2
    return float(np.sqrt(np.mean(sq3))), float(np.sqrt(np.mean(sq2))), int(sq3.size)

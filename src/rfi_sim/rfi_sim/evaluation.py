"""Position-error metrics shared by the benchmarks and the integration tests (pure numpy, no ROS).

* :func:`interpolate_truth`: truth position at the estimate stamps (linear; NaN outside its span).
* :func:`ecef_errors_enu`: ECEF estimate - truth, rotated into ENU at the truth position.
* :func:`horizontal_error_m`, :func:`error_3d_m`: norms of ENU (or local-frame) error vectors.
* :func:`error_stats`: RMS, 95th percentile, max (non-finite samples excluded and counted).
* :func:`empirical_cdf`: sorted errors and their cumulative probabilities.
* :func:`time_to_recover_s`: recovery time after a jamming burst.

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

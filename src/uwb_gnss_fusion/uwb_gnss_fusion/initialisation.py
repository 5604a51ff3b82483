"""Initialisation and re-initialisation policy of the fusion filter: where a first state comes from.

Pure core (no rclpy). Three sources, each a function here:

* a GNSS snapshot fix (:func:`snapshot_fix`): robust least squares on one epoch (Cao et al., eq. 5
  and 6), refused when the recent UWB ranges contradict it (:func:`fix_agrees_with_uwb`);
* UWB multilateration (:func:`multilaterate`), multi-start because three anchors leave two mirror
  solutions (:func:`uwb_init_ready` waits for a fourth anchor or a whole window);
* the caller's reference solution (the node's SPP), chosen by the filter itself.

The clock drift of a lost state is kept across a re-initialisation (:func:`initial_drift`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from itertools import combinations

import numpy as np
from scipy.stats import chi2

from gnss_common.multilateration import multilaterate as gnss_multilaterate
from gnss_common.positioning import SINGULAR, least_squares_position, weighted_least_squares

from .fusion_params import FRAME_EARTH, FusionParams
from .input_checks import PreparedEpoch
from .measurement_models import STATE_DIM, pseudorange_model

NS_PER_S = 1_000_000_000

RecentRanges = Mapping[str, tuple[int, np.ndarray, float, str]]
"""anchor id -> (stamp ns, anchor position m (3,), range m, frame id) of its latest range."""


def snapshot_fix(
    prep: PreparedEpoch, min_satellites: int
) -> tuple[np.ndarray, float, np.ndarray, float, np.ndarray] | None:
    """Robust snapshot least squares (position, clock; then velocity, drift) for initialisation.

    Args:
        prep: the validated satellites of one epoch with their 1-sigmas.
        min_satellites: fewest satellites a fix may rest on (``min_satellites_init``).

    Returns:
        ``(position_m (3,), clock_bias_m, velocity_mps (3,), clock_drift_mps, covariance_m2 (4, 4))``
        (velocity zero and drift NaN without four pseudorange rates; the covariance of position and
        clock bias is ``(H^T W H)^-1`` scaled by the a-posteriori variance factor when that exceeds
        1), or None (also with fewer than ``min_satellites``).

    Notes:
        Gauss-Newton on Cao et al., eq. 5 from the Earth's centre
        (:func:`gnss_common.positioning.least_squares_position`, weights 1 / sigma^2). When the weighted
        sum of squares fails a 0.999 chi-square test, fault exclusion over subsets
        (:func:`_exclude_faults`, ours): several satellites may be faulty at once under jamming, and
        dropping the largest residual one at a time can keep a wrong consistent set. The velocity and
        drift from eq. 6 in one least-squares step.
    """
    if prep.pr.size < min_satellites:
        return None
    n = prep.pr.size
    whole = _fit_subset(prep, np.arange(n))
    if whole is None:
        return None
    if whole[2]:
        keep = np.ones(n, dtype=bool)
        x, cov = whole[0], whole[1]
    else:
        found = _exclude_faults(prep, min_satellites)
        if found is None:
            return None
        keep, x, cov = found
    vel = np.zeros(3)
    drift = math.nan  # unobserved without >= 4 Dopplers
    ridx = np.flatnonzero(keep & np.isfinite(prep.rate))
    if ridx.size >= 4:
        d = prep.sat_pos[ridx] - x[0:3]
        e = d / np.linalg.norm(d, axis=1)[:, None]
        h = np.hstack([-e, np.ones((ridx.size, 1))])
        y = prep.rate[ridx] - np.einsum("ij,ij->i", prep.sat_vel[ridx], e) + prep.sat_drift[ridx]
        solved = weighted_least_squares(h, y, np.ones(ridx.size))
        if solved is not None:
            vel, drift = solved[0][0:3], float(solved[0][3])
    if not np.all(np.isfinite(cov)):
        return None
    return x[0:3].copy(), float(x[3]), vel, drift, cov


MAX_EXCLUDED = 2
"""Most satellites the snapshot fix excludes (``_exclude_faults``): all subsets without 1 or 2 satellites are
tried (at most 91 least-squares fits for 14 satellites; only at (re)initialisation)."""
AGREE_SIGMA = 3.0
"""Two consistent subsets of the same size agree when their positions differ by at most this many 1-sigmas of the
difference along it (its variance from both covariances, taken as independent: conservative)."""


def _fit_subset(prep: PreparedEpoch, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool, float] | None:
    """Snapshot least squares (position and clock) on the satellites ``idx``: ``(x (4,), covariance (4, 4),
    consistent, weighted sum of squares)``, or None (singular, not finite, or inside the Earth). Consistent: the
    weighted sum of squares passes a 0.999 chi-square test (always, without redundancy). The covariance is
    ``(H^T W H)^-1`` scaled by the a-posteriori variance factor when that exceeds 1."""
    hx = pseudorange_model(prep.sat_pos[idx], prep.sat_clk[idx], prep.iono[idx], prep.tropo[idx])
    sp = prep.sat_pos[idx]
    w2 = 1.0 / prep.sigma_pr[idx] ** 2

    def model(x4: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = sp - x4[0:3]
        return hx(_full_state(x4))[0], d / np.linalg.norm(d, axis=1)[:, None], w2

    sol = least_squares_position(model, prep.pr[idx], np.zeros(4), 10, 1e-4, max_variance_m2=math.inf)
    if sol.status == SINGULAR:
        return None
    x = sol.x
    res = (prep.pr[idx] - hx(_full_state(x))[0]) / prep.sigma_pr[idx]
    if not np.isfinite(res).all() or np.linalg.norm(x[0:3]) < 6.0e6:
        return None
    dof = idx.size - 4
    ssq = float(res @ res)
    consistent = dof == 0 or ssq <= chi2.ppf(0.999, dof)
    factor = 1.0 if dof == 0 else max(1.0, ssq / dof)
    cov = np.asarray(sol.covariance, dtype=float) * factor
    if not np.all(np.isfinite(cov)):
        return None
    return x, cov, consistent, ssq


def _exclude_faults(prep: PreparedEpoch, min_satellites: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Fault exclusion for a snapshot fix that fails its consistency test (ours, not Cao et al.): the subsets
    without 1, then 2 satellites (``MAX_EXCLUDED``) that keep at least ``min_satellites`` and at least one
    redundant satellite are fitted; the first size with consistent subsets decides. Their fix is the one with the
    smallest weighted sum of squares, accepted only when every consistent subset of that size agrees with it
    (``AGREE_SIGMA``): with several faulty satellites a subset that keeps one can also pass the test, and then
    the epoch cannot say which position is right, so it gives none (the filter waits for the next epoch).
    Returns ``(kept mask, x (4,), covariance (4, 4))`` or None."""
    n = prep.pr.size
    for k in range(1, MAX_EXCLUDED + 1):
        size = n - k
        if size < max(min_satellites, 5):
            return None
        fits = []
        for out in combinations(range(n), k):
            idx = np.setdiff1d(np.arange(n), np.asarray(out))
            f = _fit_subset(prep, idx)
            if f is not None and f[2]:
                fits.append((f[3], idx, f[0], f[1]))
        if not fits:
            continue
        fits.sort(key=lambda t: t[0])
        _, idx, x, cov = fits[0]
        for _, _, x2, cov2 in fits[1:]:
            d = x2[0:3] - x[0:3]
            dn = float(np.linalg.norm(d))
            if dn == 0.0:
                continue
            u = d / dn
            sd = math.sqrt(float(u @ cov[0:3, 0:3] @ u) + float(u @ cov2[0:3, 0:3] @ u))
            if dn > AGREE_SIGMA * sd:
                return None
        keep = np.zeros(n, dtype=bool)
        keep[idx] = True
        return keep, x, cov
    return None


def _full_state(x4: np.ndarray) -> np.ndarray:
    """The (1, 8) navigation state of ``[x, y, z, c dt]`` (zero velocity and drift)."""
    x = np.zeros((1, STATE_DIM))
    x[0, 0:3] = x4[0:3]
    x[0, 6] = x4[3]
    return x


def fix_agrees_with_uwb(
    recent: RecentRanges,
    stamp_ns: int,
    position_m: np.ndarray,
    position_std_m: float,
    lever_m: np.ndarray,
    gate_nis: float,
    params: FusionParams,
) -> bool:
    """Consistency of a GNSS snapshot fix with the recent UWB ranges (ECEF anchors only).

    Every range of the last ``uwb_init_window_s`` must pass the filter's chi-square gate with
    the variance ``position_std_m^2 + uwb_range_std_m^2`` (the fix's 1-sigma projected on the
    line of sight plus the range noise). A jammed epoch whose outliers the snapshot could not
    exclude (few satellites) is refused instead of replacing a state the UWB still supports.
    """
    if not params.use_uwb or math.isinf(gate_nis):
        return True
    win = params.uwb_init_window_s * NS_PER_S
    var = position_std_m**2 + params.uwb_range_std_m**2
    for t, anchor, rng, frame in recent.values():
        if frame != FRAME_EARTH or abs(stamp_ns - t) > win:
            continue
        res = rng - float(np.linalg.norm(position_m + lever_m - anchor))
        if res * res > gate_nis * var:
            return False
    return True


def initial_drift(clock_drift_mps: float, drift_memory_mps: float | None, params: FusionParams) -> tuple[float, float]:
    """(drift m/s, 1-sigma m/s) for a (re)initialisation: the given value, else the drift of
    the previous state, else zero with the wide unobserved-drift sigma."""
    if math.isfinite(clock_drift_mps):
        return float(clock_drift_mps), params.init_clock_drift_std_mps
    if drift_memory_mps is not None:
        return drift_memory_mps, params.init_clock_drift_std_mps
    return 0.0, params.init_clock_drift_unobserved_std_mps


def uwb_init_ready(recent: RecentRanges, stamp_ns: int, frame: str, waiting_since_ns: int, window_s: float) -> bool:
    """Whether multilateration may be tried now. Three anchors leave two mirror solutions (across
    the anchors' plane) with zero residual, so with fewer than four anchors in the window the
    filter waits until ranges have been collected for a whole ``window_s`` (every anchor of a
    >= 1 Hz set has then reported) before accepting a three-anchor solution."""
    win = window_s * NS_PER_S
    n_recent = sum(1 for (t, _, _, f) in recent.values() if f == frame and stamp_ns - t <= win)
    return not (n_recent < 4 and stamp_ns - waiting_since_ns < win)


def multilaterate(
    recent: RecentRanges,
    stamp_ns: int,
    frame: str,
    window_s: float,
    lever_m: np.ndarray,
    guess: np.ndarray | None = None,
) -> np.ndarray | None:
    """Multilateration from the latest range of each anchor within the window
    (:func:`gnss_common.multilateration.multilaterate`: from ``guess``, e.g. the diverged estimate,
    which keeps the solution on the right side of a flat anchor cluster; multi-start without one).

    Returns:
        The tag position minus the lever arm, m, (3,), or None (fewer than three anchors, or an
        RMS residual above 1 m).

    Notes:
        Cao et al., eq. 7 (UWB range) solved for the position alone.
    """
    win = window_s * NS_PER_S
    ranged = [(a, r) for (t, a, r, f) in recent.values() if f == frame and stamp_ns - t <= win]
    if len(ranged) < 3:
        return None
    # the state is the tag minus the lever arm: solve for it against the anchors moved by -lever
    anchors = np.array([a for a, _ in ranged]) - lever_m
    return gnss_multilaterate(anchors, np.array([r for _, r in ranged]), guess)

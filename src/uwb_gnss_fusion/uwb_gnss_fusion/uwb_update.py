"""The UWB update of the fusion filter: one two-way range applied to the error-state CKF.

Pure core (no rclpy). The range is applied by the CKF's compiled update
(:meth:`.ckf.CubatureKalmanFilter.update_range_compiled`); when the leading covariance block has no
Cholesky factor, by the generic cubature update (:meth:`.ckf.CubatureKalmanFilter.update`), which
symmetrises, adds jitter or raises :class:`.ckf.CholeskyError`.

Notes
-----
Cao et al., eq. 7 (range model), eq. 13 and 17-24 (cubature update) and eq. 25 (status correction),
with the position-only cubature shortcut (``active_dims``), which equals the 16-point update.
Beyond the paper: the range noise variance ``R`` of eq. 13 can carry the second-order (curvature)
variance of the range over the position uncertainty (``FusionParams.uwb_range_curvature_noise``,
:func:`.ckf_kernels.range_curvature_variance`), and :class:`RangeNoiseEstimate` estimates each
anchor's range noise from its innovations (``FusionParams.uwb_range_noise_adaptive``).
"""

from __future__ import annotations

import numpy as np

from .ckf import CubatureKalmanFilter
from .ckf_kernels import (  # noqa: F401 (the statuses re-exported)
    STATUS_APPLIED,
    STATUS_CHOLESKY_FAILED,
    STATUS_GATED,
    range_curvature_variance,
)
from .fusion_params import FusionParams
from .measurement_models import uwb_range_model


def apply_range(
    ckf: CubatureKalmanFilter,
    nominal: np.ndarray,
    anchor_m: np.ndarray,
    lever_m: np.ndarray,
    range_m: float,
    range_std_m: float,
    gate_nis: float,
    params: FusionParams,
    scratch: np.ndarray,
    max_iterations: int | None = None,
) -> tuple[bool, float]:
    """Apply one range to ``ckf`` and fold the correction into ``nominal`` (in place).

    Args:
        ckf: the filter (its error mean is zero).
        nominal: nominal state, shape (8,), corrected in place.
        anchor_m: anchor position in the state frame, m, (3,).
        lever_m: UWB tag minus GNSS antenna, m, (3,).
        range_m: measured range, m.
        range_std_m: its 1-sigma (the sensor noise), m.
        gate_nis: innovation gate (NIS threshold).
        params: ``uwb_latency_s``, the Huber thresholds, the iteration settings and
            ``uwb_range_curvature_noise``.
        scratch: (6,) diagnostics buffer of the compiled update: [innovation, prior innovation
            variance (with the noise), NIS, Huber scale, iterations, nonlinearity]; NaN when the
            generic update was used.

    Returns:
        ``(accepted, nis)``.

    Notes:
        With ``params.uwb_range_curvature_noise`` the noise variance is ``range_std_m^2`` plus
        :func:`.ckf_kernels.range_curvature_variance` at the prior (the second-order term of the
        innovation covariance): while the tag is uncertain across the line of sight by ``s``, a
        range linearised at the estimate is wrong by about ``s^2 / rho``, an error that changes
        slowly with the estimate and is not independent from range to range. Without the term,
        ranges far more precise than that are each taken at face value, and the information they
        pile up along lines of sight that turn as the estimate moves leaks into the directions
        across them (docs/uwb_gnss_fusion/fusion_never_worse.md). Once the position is known to
        well under ``sqrt(rho * range_std_m)`` the term vanishes.

    Raises:
        CholeskyError: the generic update could not factor the covariance either.
    """
    lat = params.uwb_latency_s
    dims = 6 if lat > 0.0 else 3
    iterations = params.max_update_iterations if max_iterations is None else int(max_iterations)
    r = range_std_m * range_std_m
    if params.uwb_range_curvature_noise:
        r += range_curvature_variance(ckf.p, nominal, anchor_m, lever_m, lat)
    status = ckf.update_range_compiled(
        nominal, anchor_m, lever_m, lat, dims, range_m, r, gate_nis,
        params.uwb_huber_k, params.uwb_huber_k_positive, iterations,
        params.nonlinearity_threshold, scratch,
    )
    if status != STATUS_CHOLESKY_FAILED:
        return status == STATUS_APPLIED, float(scratch[2])
    # The model acts on the error state directly: the anchor is expressed relative to the nominal
    # tag position (back-propagated over the latency), which also keeps the ECEF magnitudes out of
    # the range difference.
    scratch[:] = np.nan
    rel = anchor_m - nominal[0:3] + lat * nominal[3:6] if lat > 0.0 else anchor_m - nominal[0:3]
    res = ckf.update(
        np.array([range_m]),
        np.array([r]),
        uwb_range_model(rel[None, :], lever_m, lat),
        gate_nis,
        active_dims=dims,
        huber_k=params.uwb_huber_k,
        huber_k_positive=params.uwb_huber_k_positive,
        max_iterations=iterations,
        nonlinearity_threshold=params.nonlinearity_threshold,
    )
    nominal += ckf.reset_error_state()
    return bool(res.accepted[0]), float(res.nis)


def range_curvature_variance_reference(p_tag: np.ndarray, los_m: np.ndarray) -> float:
    """``0.5 tr(A P A P)`` with ``A`` the Hessian of the range, ``(I - u u^T) / |los|``; numpy
    reference of :func:`.ckf_kernels.range_curvature_variance` (the test oracle).

    Args:
        p_tag: covariance of the tag position, m^2, (3, 3).
        los_m: tag minus anchor, m, (3,).
    """
    rho = float(np.linalg.norm(los_m))
    u = np.asarray(los_m, dtype=float) / rho
    a = (np.eye(3) - np.outer(u, u)) / rho
    ap = a @ np.asarray(p_tag, dtype=float)
    return 0.5 * float(np.trace(ap @ ap))


class RangeNoiseEstimate:
    """Innovation-based estimate of one anchor's range noise (beyond the paper).

    The filter states a 1-sigma for each range (the message's ``range_std_m`` or
    ``FusionParams.uwb_range_std_m``); this estimates a factor ``alpha`` on that variance from the
    anchor's own innovations, so that the weight of the ranges against the pseudoranges follows
    the hardware, not a configured guess. For a consistent filter the prior innovation ``nu`` of a
    range has ``E[nu^2] = H P H^T + R`` (the innovation-based adaptive estimate: Mehra 1970, IEEE
    Trans. Autom. Control 15(2); Mohamed & Schwarz 1999, J. Geodesy 73), so each applied range gives the sample
    ``(nu^2 - (S - R)) / sigma^2`` of ``alpha`` (``S`` the filter's prior innovation variance,
    ``S - R`` its state part, including the curvature term). A sample's variance is
    ``2 S^2 / sigma^4`` (``nu`` Gaussian), so each is weighted by ``(sigma^2 / S)^2`` (inverse
    variance, up to a constant): while the state is uncertain along the line of sight (``S`` much
    larger than ``sigma^2``, e.g. just after an initialisation) the samples say next to nothing
    about the noise and barely move the estimate. The estimate is the weighted mean of the
    samples, started from ``alpha = 1`` with the weight of ``prior_weight`` full samples and with a
    fading memory of ``window`` full samples once that much weight is in (a sensor whose noise
    changes is followed). ``sigma sqrt(alpha)`` is kept within ``[min(floor_m, sigma), max(ceiling_m, sigma)]``.

    Gated ranges and ranges down-weighted by the Huber rule are not samples (they are the
    outliers the gate is for, not the noise).
    """

    __slots__ = ("alpha", "weight", "window", "prior_weight", "floor_m", "ceiling_m")

    def __init__(self, window: int, prior_weight: int, floor_m: float, ceiling_m: float) -> None:
        self.alpha = 1.0
        self.weight = 0.0  # samples' total weight so far (full samples)
        self.window = int(window)
        self.prior_weight = int(prior_weight)
        self.floor_m = float(floor_m)
        self.ceiling_m = float(ceiling_m)

    def std_m(self, stated_std_m: float) -> float:
        """The 1-sigma to use for a range whose stated 1-sigma is ``stated_std_m``, m."""
        s = stated_std_m * max(self.alpha, 0.0) ** 0.5
        lo = min(self.floor_m, stated_std_m)
        hi = max(self.ceiling_m, stated_std_m)
        return lo if s < lo else (hi if s > hi else s)

    def add(self, innovation_m: float, innovation_var_m2: float, used_std_m: float, stated_std_m: float) -> None:
        """One applied range: its prior innovation, the filter's prior innovation variance (noise
        ``used_std_m^2`` included) and the stated 1-sigma. Non-finite values are ignored."""
        var = stated_std_m * stated_std_m
        sample = (innovation_m * innovation_m - (innovation_var_m2 - used_std_m * used_std_m)) / var
        if not (sample == sample and abs(sample) < 1e12 and innovation_var_m2 > 0.0):  # NaN, overflow
            return
        w = min(1.0, (used_std_m * used_std_m / innovation_var_m2) ** 2)
        self.weight += w
        total = min(self.weight + self.prior_weight, float(self.window))
        self.alpha += (sample - self.alpha) * (w / total)

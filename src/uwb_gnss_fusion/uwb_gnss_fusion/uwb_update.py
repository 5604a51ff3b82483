"""The UWB update of the fusion filter: one two-way range applied to the error-state CKF.

Pure core (no rclpy). The range is applied by the CKF's compiled update
(:meth:`.ckf.CubatureKalmanFilter.update_range_compiled`); when the leading covariance block has no
Cholesky factor, by the generic cubature update (:meth:`.ckf.CubatureKalmanFilter.update`), which
symmetrises, adds jitter or raises :class:`.ckf.CholeskyError`.

Notes
-----
Cao et al., eq. 7 (range model), eq. 13 and 17-24 (cubature update) and eq. 25 (status correction),
with the position-only cubature shortcut (``active_dims``), which equals the 16-point update.
"""

from __future__ import annotations

import numpy as np

from .ckf import CubatureKalmanFilter
from .ckf_kernels import STATUS_APPLIED, STATUS_CHOLESKY_FAILED, STATUS_GATED  # noqa: F401 (re-exported)
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
) -> tuple[bool, float]:
    """Apply one range to ``ckf`` and fold the correction into ``nominal`` (in place).

    Args:
        ckf: the filter (its error mean is zero).
        nominal: nominal state, shape (8,), corrected in place.
        anchor_m: anchor position in the state frame, m, (3,).
        lever_m: UWB tag minus GNSS antenna, m, (3,).
        range_m: measured range, m.
        range_std_m: its 1-sigma, m.
        gate_nis: innovation gate (NIS threshold).
        params: ``uwb_latency_s``, the Huber thresholds and the iteration settings.
        scratch: (6,) diagnostics buffer of the compiled update.

    Returns:
        ``(accepted, nis)``.

    Raises:
        CholeskyError: the generic update could not factor the covariance either.
    """
    lat = params.uwb_latency_s
    dims = 6 if lat > 0.0 else 3
    status = ckf.update_range_compiled(
        nominal, anchor_m, lever_m, lat, dims, range_m, range_std_m * range_std_m, gate_nis,
        params.uwb_huber_k, params.uwb_huber_k_positive, params.max_update_iterations,
        params.nonlinearity_threshold, scratch,
    )
    if status != STATUS_CHOLESKY_FAILED:
        return status == STATUS_APPLIED, float(scratch[2])
    # The model acts on the error state directly: the anchor is expressed relative to the nominal
    # tag position (back-propagated over the latency), which also keeps the ECEF magnitudes out of
    # the range difference.
    rel = anchor_m - nominal[0:3] + lat * nominal[3:6] if lat > 0.0 else anchor_m - nominal[0:3]
    res = ckf.update(
        np.array([range_m]),
        np.array([range_std_m * range_std_m]),
        uwb_range_model(rel[None, :], lever_m, lat),
        gate_nis,
        active_dims=dims,
        huber_k=params.uwb_huber_k,
        huber_k_positive=params.uwb_huber_k_positive,
        max_iterations=params.max_update_iterations,
        nonlinearity_threshold=params.nonlinearity_threshold,
    )
    nominal += ckf.reset_error_state()
    return bool(res.accepted[0]), float(res.nis)

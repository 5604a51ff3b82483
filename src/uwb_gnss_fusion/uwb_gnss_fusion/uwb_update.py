"""The UWB update of the fusion filter: one two-way range through the filter, start to end.

Pure core (no rclpy). :func:`process_uwb` is the whole range in the order it happens: checks
(:func:`.input_checks.validate_uwb_range`), the anchor's noise (:class:`RangeNoiseEstimate`), the
stamp, a start by multilateration (:mod:`.lifecycle`), the time update, the shared-bias weighting
(:func:`range_std_with_shared_bias`), the update (:func:`apply_range`), the side of the anchors'
plane (:mod:`.mirror_handling`) and the divergence rules (:mod:`.lifecycle`).

The range is applied by the CKF's compiled update
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

import collections
import math

import numpy as np

from gnss_common.observations import UwbRangeMeasurement

from .ckf import CholeskyError, CubatureKalmanFilter
from .ckf_kernels import (  # noqa: F401 (the statuses re-exported)
    STATUS_APPLIED,
    STATUS_CHOLESKY_FAILED,
    STATUS_GATED,
    range_curvature_variance,
)
from .filter_state import FilterFacade, check_stamp_type
from .fusion_output import FusionOutput
from .fusion_params import FRAME_EARTH, UWB_NOISE_PRIOR_WEIGHT, FusionParams
from .input_checks import validate_uwb_range
from .lifecycle import consistent_uwb_fix, declare_divergence, init_from_uwb, state_lost
from .measurement_models import uwb_range_model
from .mirror_handling import side_prior_uwb

_NS = 1_000_000_000
UWB_FIX_MIN_ANCHORS = 3
"""Anchors needed for ranges alone to fix the position (up to the mirror of their plane): below this,
with GNSS in use, the shared-bias rule (``uwb_range_bias_std_m``) weights the ranges."""


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
        ``used_std_m^2`` included) and the stated 1-sigma. Non-finite values are ignored, and so is a stated
        1-sigma whose square is not positive (a subnormal 1-sigma underflows to 0: no scale to measure against)."""
        var = stated_std_m * stated_std_m
        if not var > 0.0:
            return
        sample = (innovation_m * innovation_m - (innovation_var_m2 - used_std_m * used_std_m)) / var
        if not (sample == sample and abs(sample) < 1e12 and innovation_var_m2 > 0.0):  # NaN, overflow
            return
        w = min(1.0, (used_std_m * used_std_m / innovation_var_m2) ** 2)
        self.weight += w
        total = min(self.weight + self.prior_weight, float(self.window))
        self.alpha += (sample - self.alpha) * (w / total)


def process_uwb(f: FilterFacade, meas: UwbRangeMeasurement) -> FusionOutput:
    """Predict to the range's stamp and apply it.

    Args:
        meas: one UWB two-way range; ``meas.stamp_ns`` in ns, anchor position in ``meas.frame_id``.

    Returns:
        :class:`FusionOutput` after the update (or the unchanged state if rejected).

    Notes:
        Cao et al., eq. 7, 13 and 17-25, with gating.
    """
    s = f.state
    if not isinstance(meas, UwbRangeMeasurement):
        raise TypeError(f"process_uwb expects a UwbRangeMeasurement, got {type(meas).__name__}")
    stamp = check_stamp_type(meas.stamp_ns)
    p = f.params
    if not p.use_uwb:
        f.count("uwb_disabled")
        return f.output(False)
    anchor = validate_uwb_range(meas, p, f.anchor_registry, f.count)
    if anchor is None:
        return f.output(False, uwb_rej=1)
    rng = float(meas.range_m)
    stated = float(meas.range_std_m) if math.isfinite(meas.range_std_m) else p.uwb_range_std_m
    noise = None
    if p.uwb_range_noise_adaptive and (
        p.uwb_range_noise_adaptive_without_gnss or (p.use_gnss and meas.frame_id == FRAME_EARTH)
    ):
        noise = f.uwb_noise.get(meas.anchor_id)
        if noise is None:
            noise = f.uwb_noise[meas.anchor_id] = RangeNoiseEstimate(
                p.uwb_range_noise_window, UWB_NOISE_PRIOR_WEIGHT, p.uwb_range_std_floor_m, p.uwb_range_std_ceiling_m
            )
            f.count("uwb_noise_estimates")
        std = noise.std_m(stated)
    else:
        std = stated
    if not f.admit_stamp(stamp):
        return f.output(False, uwb_rej=1)
    if s.initialized and meas.frame_id != s.frame:
        f.count("uwb_frame_mismatch")
        return f.output(False, uwb_rej=1)
    if s.motion.static:  # the detector watches GNSS epochs alone (.motion_model)
        s.motion.reset()
        f.count("motion_static_left_uwb")
    prev = s.recent_uwb.get(meas.anchor_id)
    if (prev is None or stamp - prev[0] > p.uwb_init_window_s * _NS or prev[3] != meas.frame_id
        or prev[1][0] != anchor[0] or prev[1][1] != anchor[1] or prev[1][2] != anchor[2]):
        s.anchor_version += 1
    s.recent_uwb[meas.anchor_id] = (stamp, anchor, rng, meas.frame_id)
    if not s.initialized:
        if not init_from_uwb(f, stamp, meas.frame_id):
            f.count("uwb_waiting_for_init")
            return f.output(False)
        return f.output(False, uwb_used=1)
    s.predict_to(stamp, f.params, f.clock_q)
    heard = anchors_heard(f, stamp)
    std_apply = range_std_with_shared_bias(f, stamp, meas.anchor_id, std, heard)
    try:
        ok, nis = apply_range(
            s.ckf, s.nominal, anchor, f.lever, rng, std_apply, f.gate, p, s.uwb_scratch,
            range_iterations(f, heard),
        )
    except CholeskyError:
        f.count("numerical_failure")
        return declare_divergence(f, stamp)
    s.uwb_gated.push(ok)
    if ok and noise is not None and s.uwb_scratch[3] == 1.0 and std_apply == std:
        noise.add(float(s.uwb_scratch[0]), float(s.uwb_scratch[1]), std, stated)
    if ok:
        if s.anchor_gated_run:
            s.anchor_gated_run.pop(meas.anchor_id, None)
        s.last_uwb_stamp = stamp
        if p.uwb_tag_side_of_anchor_plane and not (p.use_gnss and s.frame == FRAME_EARTH):
            side_prior_uwb(f, stamp)
        if state_lost(f):
            f.count("divergence")
            return declare_divergence(f, stamp)
        return f.output(False, uwb_used=1, nis=nis)
    f.count("innovation_gate_uwb")
    run = s.anchor_gated_run.get(meas.anchor_id, 0) + 1
    s.anchor_gated_run[meas.anchor_id] = run
    if run >= p.divergence_uwb_ranges and p.uwb_gated_anchor_reinit and meas.anchor_id not in s.gated_restarted:
        s.anchor_gated_run[meas.anchor_id] = 0
        pos = consistent_uwb_fix(f, stamp, meas.frame_id, std)
        if pos is not None:
            s.gated_restarted.add(meas.anchor_id)
            # every anchor agrees with a fix and the state gates one of them: the state sits in
            # a wrong local minimum of the ranges (e.g. near the mirror of three of four
            # anchors). Once per anchor id in the filter's life: a biased anchor whose fix also
            # explains the ranges (weak geometry) must not make the filter cycle.
            f.reinits += 1
            f.count("uwb_anchor_gated_reinit")
            f.initialize(stamp, pos, frame_id=meas.frame_id, position_std_m=1.0)
            s.last_uwb_stamp = stamp
            return f.output(True, uwb_rej=1)
    # Divergence: most of the recent ranges (all anchors together) inconsistent with the state.
    # A single anchor that still agrees (the state sits on its range sphere) does not mask it.
    if s.uwb_gated.diverged(p.divergence_uwb_gated_fraction):
        f.count("divergence")
        return declare_divergence(f, stamp)
    return f.output(False, uwb_rej=1)


def range_iterations(f: FilterFacade, heard: int) -> int:
    """Refinement steps allowed for a range (``uwb_iterate_min_anchors``): none while GNSS is used and fewer
    anchors than that were heard within ``uwb_init_window_s`` (``heard``, -1: not counted), else
    ``max_update_iterations``."""
    p = f.params
    k = p.uwb_iterate_min_anchors
    if k <= 0 or heard < 0:
        return p.max_update_iterations
    return p.max_update_iterations if heard >= k else 0


def anchors_heard(f: FilterFacade, stamp_ns: int) -> int:
    """Anchors of the filter's frame with a range within ``uwb_init_window_s`` before ``stamp_ns``, when GNSS
    is used in the earth frame and a rule needs the count (``uwb_iterate_min_anchors``,
    ``uwb_range_bias_std_m``); else -1."""
    s = f.state
    p = f.params
    if not (p.use_gnss and s.frame == FRAME_EARTH) or (p.uwb_iterate_min_anchors <= 0
                                                       and p.uwb_range_bias_std_m <= 0.0):
        return -1
    oldest = stamp_ns - int(p.uwb_init_window_s * 1e9)
    frame = s.frame
    n = 0
    for t, _, _, fr in s.recent_uwb.values():
        if t >= oldest and fr == frame:
            n += 1
    return n


def uwb_anchors_heard(f: FilterFacade, stamp_ns: int) -> int:
    """Anchors (of the filter's frame, when it has one) with a range within ``uwb_init_window_s`` before
    ``stamp_ns``: for diagnostics (three anchors leave a mirror solution across their plane that the ranges cannot
    rule out, ``uwb_tag_side_of_anchor_plane``)."""
    s = f.state
    oldest = stamp_ns - int(f.params.uwb_init_window_s * 1e9)
    frame = s.frame if s.initialized else None
    return sum(1 for t, _, _, fr in s.recent_uwb.values() if t >= oldest and (frame is None or fr == frame))


def range_std_with_shared_bias(f: FilterFacade, stamp_ns: int, anchor_id: str, std_m: float, heard: int) -> float:
    """The 1-sigma a range is applied with under the shared-bias rule (``uwb_range_bias_std_m``).

    While GNSS is used and fewer than :data:`UWB_FIX_MIN_ANCHORS` anchors were heard within
    ``uwb_init_window_s`` (the ranges alone do not fix the position), the ranges of one anchor
    are taken to share an unknown bias of 1-sigma ``sigma_b`` over ``uwb_range_bias_time_s``:
    the ``n``-th range of the anchor within that time gets the variance
    ``std_m^2 + n sigma_b^2``. Along one line of sight ``n`` ranges so weighted carry about
    ``ln(n sigma_b^2 / std_m^2) / sigma_b^2`` of information instead of ``n / std_m^2``: a
    stream of ranges tells a few times ``sigma_b`` along a line of sight, not millimetres (a
    variance inflation for errors correlated from range to range; the exact sequential weight
    of a constant bias would grow like ``n^2`` and leave the ranges almost unused; cf.
    Bar-Shalom, Li & Kirubarajan 2001 on correlated measurement noise). Without it a 20 Hz
    stream of 3 cm ranges counts as millimetre knowledge along a line of sight that turns with the estimate, and
    that information leaks across it: with one anchor at +30 dB the height went 6-10 m wrong
    with a 0.4 m 1-sigma (docs/uwb_gnss_fusion/fusion_never_worse.md, fifth round). Beyond the
    paper. ``heard``: :meth:`_anchors_heard` (-1: GNSS not in use). Returns ``std_m`` unchanged when the
    rule does not act.
    """
    s = f.state
    p = f.params
    if p.uwb_range_bias_std_m <= 0.0 or heard < 0:
        return std_m
    if heard >= UWB_FIX_MIN_ANCHORS:
        if s.shared_bias_stamps:
            s.shared_bias_stamps.pop(anchor_id, None)
        return std_m
    stamps = s.shared_bias_stamps.setdefault(anchor_id, collections.deque())
    stamps.append(stamp_ns)
    oldest = stamp_ns - int(p.uwb_range_bias_time_s * 1e9)
    while stamps and stamps[0] < oldest:
        stamps.popleft()
    n = len(stamps)
    if n <= 1:
        return std_m
    return math.sqrt(std_m * std_m + n * p.uwb_range_bias_std_m**2)

"""One GNSS epoch through the fusion filter, start to end (Cao et al., eq. 4-6, 12, 15-25).

Pure core (no rclpy). :func:`process_gnss` is the whole epoch in the order it happens; it calls the
maths of other modules and comes back:

1. admission: GNSS in use, the stamp (:meth:`.fusion_filter.FusionFilter.admit_stamp`), the frame;
2. the satellites and their weights from C/N0 and the J/S (eq. 4, 12: :func:`.gnss_update.prepare_epoch`);
3. no state yet: a snapshot fix starts the filter (eq. 5-6; :mod:`.lifecycle`);
4. the time update (eq. 15-16, :meth:`.filter_state.FilterState.predict_to`); the clock from the
   residuals after a UWB start; the inter-system bias and correlated-error states of the epoch;
5. the motion model's exit test (:func:`motion_before_update`, :mod:`.motion_model`);
6. the common-mode screen and a receiver clock step (:func:`.gnss_update.screen_common_mode`,
   :mod:`.clock_steps`);
7. the gated cubature update (eq. 5, 6, 17-24: :func:`.gnss_update.update_gnss`) and the status
   correction (eq. 25);
8. the motion model's entry test (:func:`motion_after_update`), the mirror of coplanar anchors
   (:mod:`.mirror_handling`);
9. the divergence rules (:mod:`.divergence`, :mod:`.lifecycle`).
"""

from __future__ import annotations

import math

import numpy as np

from gnss_common.observations import GnssEpoch

from . import initialisation as init
from .ckf import CholeskyError
from .clock_steps import apply_clock_step, receiver_clock_step
from .divergence import clock_reset_variances, gnss_epoch_inconsistent
from .filter_state import FilterFacade, check_stamp_type
from .fusion_output import FusionOutput
from .fusion_params import FRAME_EARTH
from .gnss_update import prepare_epoch, screen_common_mode, update_gnss
from .input_checks import PreparedEpoch, skipped_constellations
from .lifecycle import (
    declare_divergence,
    fix_agrees_with_uwb,
    fix_confirmed,
    reset_clock_keep_position,
    snapshot_fix,
    state_lost,
    uwb_agrees,
)
from .measurement_models import white_acceleration_noise
from .mirror_handling import mirror_check
from .motion_model import static_exit_statistic, zero_velocity_update

_NS = 1_000_000_000


def process_gnss(f: FilterFacade, epoch: GnssEpoch) -> FusionOutput:
    """Predict to the epoch's stamp and apply its pseudoranges (and pseudorange rates).

    Args:
        epoch: one receive epoch; ``epoch.stamp_ns`` is the receive time in ns.

    Returns:
        :class:`FusionOutput` after the update (or the unchanged state if the epoch was
        rejected; the reason is counted in ``rejection_counts``).

    Notes:
        Cao et al., eq. 5, 6, 12 and 17-25, with per-measurement gating and the weights of
        :func:`gnss_common.jamming_weights.measurement_sigmas`.
    """
    s = f.state
    if not isinstance(epoch, GnssEpoch):
        raise TypeError(f"process_gnss expects a GnssEpoch, got {type(epoch).__name__}")
    stamp = check_stamp_type(epoch.stamp_ns)
    if not f.params.use_gnss:
        f.count("gnss_disabled")
        return f.output(False)
    if not f.admit_stamp(stamp):
        return f.output(False)
    if s.initialized and s.frame != FRAME_EARTH:
        f.count("gnss_in_map_frame")
        return f.output(False)
    # Constellations not in use are skipped (counted per constellation), not rejected satellites.
    n_obs = len(epoch.observations) - skipped_constellations(epoch.observations, f.params.multi_gnss)
    if n_obs == 0:
        f.count("no_satellites")
        return f.output(False)
    receiver = s.nominal[0:3] + s.nominal[3:6] * ((stamp - s.t_ns) / _NS) if s.initialized else None
    prep = prepare_epoch(epoch, receiver, f.current_js_db(stamp), f.params, f.count)
    if prep is None:
        f.count("no_valid_satellites")
        return f.output(False, sat_rej=n_obs)
    n = prep.pr.size
    pre_rejected = n_obs - n
    if n < 4:
        f.count("fewer_than_4_satellites")
    s.last_prep = (stamp, prep)
    if not s.initialized:
        return start_from_fix(f, stamp, prep, n_obs, pre_rejected)
    dt_s = (stamp - s.t_ns) / _NS
    s.predict_to(stamp, f.params, f.clock_q)
    if not s.clock_initialized:
        initialise_clock(f, prep)
    cols = s.update_bias_states(stamp, prep, f.count)
    err_cols = s.update_error_states(stamp, prep, f.params, f.count)
    motion_before_update(f, prep, cols, err_cols, dt_s)
    n_screened = 0
    find_step = f.params.receiver_clock_steps
    if f.params.common_mode_screen:
        prep, n_screened, step = screen_common_mode(prep, s.nominal, s.ckf.p, f.gate, f.count, cols, err_cols,
                                                    find_step)
        apply_clock_step(s.nominal, s.ckf, step, f.count)
        if prep.pr.size == 0:
            f.count("no_valid_satellites")
            return f.output(False, sat_rej=n_obs)
        n = prep.pr.size
        if n_screened:
            cols = s.bias_columns(prep)
            err_cols = s.error_columns(prep)
    elif find_step:
        step = receiver_clock_step(prep, s.nominal, s.ckf.p, f.gate, cols, err_cols)
        apply_clock_step(s.nominal, s.ckf, step, f.count)
    try:
        res = update_gnss(s.ckf, s.nominal, prep, f.gate, f.params, cols, err_cols)
    except CholeskyError:
        f.count("numerical_failure")
        return declare_divergence(f, stamp)
    acc_pr = res.accepted[:n]
    acc_rate = res.accepted[n:]
    gated_pr = int(n - acc_pr.sum())
    f.count("innovation_gate_pseudorange", gated_pr)
    f.count("innovation_gate_doppler", int(acc_rate.size - acc_rate.sum()))
    s.correct()
    motion_after_update(f, stamp)
    if (f.params.uwb_mirror_test or f.params.uwb_tag_side_of_anchor_plane) and f.params.use_uwb:
        mirror_check(f, stamp, prep, acc_pr, cols)
    used = int(acc_pr.sum())
    if prep.sat_id is not None:
        s.last_used_satellites = (stamp, prep.sat_id[acc_pr])
    if used or acc_rate.any():
        s.last_gnss_stamp = stamp
    n_applied = int(res.accepted.sum())
    nis = res.nis / n_applied if n_applied else math.nan
    # Divergence: most pseudoranges of a well-observed epoch inconsistent with the state, for
    # several epochs in a row (a single jammed epoch with outliers does not trip it).
    if gnss_epoch_inconsistent(n, n_screened, gated_pr):
        s.bad_gnss_epochs += 1
    else:
        s.bad_gnss_epochs = 0
    if s.bad_gnss_epochs >= f.params.divergence_gnss_epochs or state_lost(f):
        f.count("divergence")
        if not state_lost(f) and uwb_agrees(f, stamp):
            return reset_clock_keep_position(f, stamp, prep)
        return declare_divergence(f, stamp, gnss_only=not state_lost(f))
    return f.output(False, sat_used=used, sat_rej=pre_rejected + n_screened + gated_pr, nis=nis)


def start_from_fix(f: FilterFacade, stamp: int, prep: PreparedEpoch, n_obs: int, pre_rejected: int) -> FusionOutput:
    """No state yet: start the filter from a snapshot fix of the epoch (Cao et al., eq. 5-6 by least
    squares, :func:`.lifecycle.snapshot_fix`), unless it fails the gate against a recent UWB range or,
    with ``divergence_fix_confirm_s``, waits for a second fix to confirm it (:func:`.lifecycle.fix_confirmed`).
    ``n_obs``: the epoch's satellites of the systems in use; ``pre_rejected``: those ``prepare_epoch`` dropped."""
    s = f.state
    fix, fix_system = snapshot_fix(f, prep)
    if fix is None:
        f.count("gnss_init_failed")
        return f.output(False, sat_rej=n_obs)
    if not fix_agrees_with_uwb(f, stamp, fix[0], f.params.init_position_std_m):
        f.count("gnss_fix_inconsistent_with_uwb")
        return f.output(False, sat_rej=n_obs)
    if f.params.divergence_fix_confirm_s > 0 and not fix_confirmed(f, stamp, fix):
        # divergence_fix_confirm_s: a second fix must agree. The epoch's pseudoranges are held in that
        # fix, not rejected (the status shows neither used nor rejected satellites).
        f.count("gnss_init_unconfirmed")
        return f.output(False)
    pos, clk, vel, drift, cov = fix
    f.initialize(stamp, pos, velocity_mps=vel, clock_bias_m=clk, clock_drift_mps=drift,
                 position_clock_covariance_m2=cov)
    s.ref_system = fix_system
    s.update_bias_states(stamp, prep, f.count)
    s.last_gnss_stamp = stamp
    if prep.sat_id is not None:
        s.last_used_satellites = (stamp, prep.sat_id)
    return f.output(False, sat_used=prep.pr.size, sat_rej=pre_rejected)


def initialise_clock(f: FilterFacade, prep: PreparedEpoch) -> None:
    """The position is known from UWB, the clock is not: the clock bias from the pseudorange residuals
    (eq. 5 with the position fixed, :meth:`.filter_state.FilterState.clock_from_residuals`), the drift
    remembered from a previous state (or zero), and their variances reset."""
    s = f.state
    drift, drift_std = init.initial_drift(math.nan, s.drift_memory_mps, f.params)
    s.nominal[6] = s.clock_from_residuals(prep)
    s.nominal[7] = drift
    s.ckf.reset_block(
        slice(6, 8), clock_reset_variances(s.ckf.p, f.params.init_clock_bias_std_m, drift_std)
    )
    s.clock_initialized = True


def motion_before_update(f: FilterFacade, prep: PreparedEpoch, cols: np.ndarray | None, err_cols: np.ndarray | None,
                         dt_s: float) -> None:
    """Static model: the exit test on the predicted innovations (:mod:`.motion_model`). A failing
    epoch opens the covariance by the moving model's process noise minus the static one over
    ``dt_s`` (adaptive process noise); leaving the static model raises the position and velocity
    variances to the moving model's at entry."""
    s = f.state
    if not s.motion.static:
        return
    # tested against the moving model's uncertainty at entry: the static average's own covariance
    # shrinks like 1 / epochs (white errors), the solution's time-correlated errors do not
    p_test = s.ckf.p.copy()
    p_test[0:6, 0:6] += np.diag(np.maximum(s.moving_pv_var - np.diag(p_test)[0:6], 0.0))
    parts = static_exit_statistic(prep, s.nominal, p_test, cols, err_cols)
    decision = s.motion.observe_static(parts)
    if decision.open_covariance:
        p = f.params
        s.ckf.p[0:6, 0:6] += white_acceleration_noise(p.accel_psd_m2ps3 - p.static_accel_psd_m2ps3, dt_s)
        f.count("motion_epoch_opened")
    if decision.left_static:
        # back to the moving model's uncertainty: the static average's covariance assumed white errors
        # and no motion since the entry, both now doubtful
        s.ckf.p[0:6, 0:6] += np.diag(np.maximum(s.moving_pv_var - np.diag(s.ckf.p)[0:6], 0.0))
        f.count("motion_static_left")


def motion_after_update(f: FilterFacade, stamp_ns: int) -> None:
    """Moving model: the entry test on the updated state; on entry, a zero-velocity update."""
    s = f.state
    p = f.params
    if not p.motion_detection or s.frame != FRAME_EARTH or s.motion.static:
        return
    if s.last_uwb_stamp is not None and stamp_ns - s.last_uwb_stamp <= p.uwb_init_window_s * _NS:
        return  # GNSS epochs alone: ranges at 10-50 Hz follow the motion (.motion_model)
    if not s.motion.observe_moving(stamp_ns, s.nominal[0:3], s.ckf.p[0:3, 0:3],
                                   s.nominal[3:6], s.ckf.p[3:6, 3:6]):
        return
    f.count("motion_static_entered")
    s.moving_pv_var = np.diag(s.ckf.p)[0:6].copy()
    dx, s.ckf.p = zero_velocity_update(s.ckf.p, s.nominal[3:6], p.static_velocity_std_mps)
    s.nominal = s.nominal + dx

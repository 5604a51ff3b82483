"""Start-up and divergence of the fusion filter: from what it starts, when it gives up a state, and how
it starts again (beyond Cao et al., whose filter starts once and never diverges).

Pure core (no rclpy). Functions of a :class:`.fusion_filter.FusionFilter` (its state,
:class:`.filter_state.FilterState`); the maths live in :mod:`.initialisation` (snapshot fix, eq. 5-6;
multilateration, eq. 7) and :mod:`.divergence` (the rules).

* Start-up: a snapshot fix of one system's satellites (:func:`snapshot_fix`), confirmed by a second
  one (:func:`fix_confirmed`, ``divergence_fix_confirm_s``) and refused if it fails the gate against a
  recent UWB range (:func:`fix_agrees_with_uwb`); or UWB multilateration (:func:`init_from_uwb`).
* Divergence (:func:`declare_divergence`): re-initialised from UWB multilateration, the caller's
  reference solution, a snapshot fix of the epoch, or reset to uninitialised; a GNSS-declared
  divergence that the UWB ranges do not confirm re-solves the clock only
  (:func:`reset_clock_keep_position`); one anchor gated while a multilateration explains every anchor
  restarts from that fix (:func:`consistent_uwb_fix`).
* Spoofing: :func:`reanchor_on_uwb` starts again from the ranges alone.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from gnss_common.observations import GPS

from . import initialisation as init
from .divergence import clock_reset_variances, position_lost
from .filter_state import FilterFacade
from .fusion_output import FusionOutput
from .fusion_params import FRAME_EARTH, UWB_FIX_CONSISTENT_SIGMA
from .gnss_update import clock_offset_from_residuals
from .input_checks import PreparedEpoch
from .mirror_handling import on_wrong_side
from .mirror_test import anchor_plane, reflect

_NS = 1_000_000_000
FIX_AGREEMENT_CHI2_3DOF = float(chi2.ppf(0.9973, 3))
"""Two snapshot fixes agree (``divergence_fix_confirm_s``) when their position difference is within this
chi-square (3 dof, the probability of 3 standard deviations) of their combined covariance."""
FIX_CONFIRM_MAX_GAP_S = 300.0
"""Longest interval over which consecutive snapshot fixes are compared (``divergence_fix_confirm_s``) when the
receiver reports more slowly than ten times that setting (RINEX observation files at 30 s), s."""
FIX_CONFIRM_UNKNOWN_SPEED_MPS = 30.0
"""Speed, per axis, allowed between two compared fixes when the earlier one has no velocity (fewer than four
pseudorange rates): a road vehicle's, m/s."""


def snapshot_fix(f: FilterFacade, prep: PreparedEpoch) -> tuple[tuple | None, int]:
    """A snapshot fix (:func:`.initialisation.snapshot_fix`) on one system's satellites: GPS
    when it has ``min_satellites_init``, else the system with the most satellites (one
    receiver clock); returns ``(fix or None, its system)``."""
    system = prep.system
    if system is None or (system == GPS).all():
        return init.snapshot_fix(prep, f.params.min_satellites_init), GPS
    values, counts = np.unique(system, return_counts=True)
    n_gps = int(counts[values == GPS].sum())
    best = GPS if n_gps >= f.params.min_satellites_init else int(values[np.argmax(counts)])
    return init.snapshot_fix(prep.subset(system == best), f.params.min_satellites_init), best


def fix_confirmed(f: FilterFacade, stamp_ns: int, fix: tuple) -> bool:
    """``divergence_fix_confirm_s``: whether the held fix agrees with ``fix`` within 3 combined standard
    deviations (chi-square, 3 dof, of the position difference).

    The held fix must be at least ``divergence_fix_confirm_s`` older than ``fix`` and at most ten times that,
    or, when it is the fix attempt just before this one (a receiver that reports every 30 s), at most
    :data:`FIX_CONFIRM_MAX_GAP_S`. It is moved by its velocity over the interval when it has one (four or
    more pseudorange rates), and the comparison allows ``init_velocity_std_mps`` (with a velocity) or
    :data:`FIX_CONFIRM_UNKNOWN_SPEED_MPS` (without) per axis times the interval for the motion in between.
    A newer fix replaces the held one when it is compared and disagrees, or when the held one is too old; a
    fix too soon after the held one is not compared (the held one stays)."""
    s = f.state
    new = (int(stamp_ns), np.asarray(fix[0], float), np.asarray(fix[4], float),
           np.asarray(fix[2], float) if math.isfinite(fix[3]) else None)
    held = s.held_fix
    previous_attempt = s.fix_attempt_ns
    s.fix_attempt_ns = int(stamp_ns)
    lo = f.params.divergence_fix_confirm_s
    if held is None:
        s.held_fix = new
        return False
    dt_s = (stamp_ns - held[0]) / _NS
    if dt_s < lo and dt_s >= 0:
        return False
    hi = 10.0 * lo
    if previous_attempt == held[0]:
        hi = max(hi, FIX_CONFIRM_MAX_GAP_S)
    if not lo <= dt_s <= hi:
        s.held_fix = new
        return False
    predicted = held[1] if held[3] is None else held[1] + held[3] * dt_s
    speed_std = f.params.init_velocity_std_mps if held[3] is not None else FIX_CONFIRM_UNKNOWN_SPEED_MPS
    d = new[1] - predicted
    c = held[2][0:3, 0:3] + new[2][0:3, 0:3] + np.eye(3) * (speed_std * dt_s) ** 2
    try:
        q = float(d @ np.linalg.solve(c, d))
    except np.linalg.LinAlgError:
        q = math.inf
    if q <= FIX_AGREEMENT_CHI2_3DOF:
        s.held_fix = None
        return True
    s.held_fix = new
    return False


def fix_agrees_with_uwb(f: FilterFacade, stamp_ns: int, position_m: np.ndarray, position_std_m: float) -> bool:
    s = f.state
    return init.fix_agrees_with_uwb(
        s.recent_uwb, stamp_ns, position_m, position_std_m, f.lever, f.gate, f.params
    )


def multilaterate(f: FilterFacade, stamp_ns: int, frame: str, guess: np.ndarray | None = None) -> np.ndarray | None:
    s = f.state
    return init.multilaterate(s.recent_uwb, stamp_ns, frame, f.params.uwb_init_window_s, f.lever, guess)


def init_from_uwb(f: FilterFacade, stamp_ns: int, frame: str) -> bool:
    """Initialise by multilateration once :func:`.initialisation.uwb_init_ready`."""
    s = f.state
    if s.uwb_wait_since_ns is None:
        s.uwb_wait_since_ns = stamp_ns
    if not init.uwb_init_ready(s.recent_uwb, stamp_ns, frame, s.uwb_wait_since_ns,
                               f.params.uwb_init_window_s):
        return False
    pos = multilaterate(f, stamp_ns, frame)
    if pos is None:
        return False
    f.initialize(stamp_ns, pos, frame_id=frame, position_std_m=1.0)
    s.last_uwb_stamp = stamp_ns
    return True


def state_lost(f: FilterFacade) -> bool:
    s = f.state
    return position_lost(s.ckf.p, s.nominal, f.params.max_position_std_m)


def uwb_agrees(f: FilterFacade, stamp_ns: int) -> bool:
    """True if the UWB ranges still agree with the state (GNSS-declared divergence is then a
    GNSS fault, not a lost state): a range was accepted within ``uwb_init_window_s`` and fewer
    than ``divergence_uwb_gated_fraction`` of the (at least half-full) range window were gated."""
    s = f.state
    p = f.params
    return (
        p.use_uwb
        and s.last_uwb_stamp is not None
        and stamp_ns - s.last_uwb_stamp <= p.uwb_init_window_s * _NS
        and s.uwb_gated.agrees(p.divergence_uwb_gated_fraction)
    )


def reset_clock_keep_position(f: FilterFacade, stamp_ns: int, prep: PreparedEpoch) -> FusionOutput:
    """GNSS-declared divergence while UWB agrees with the state: keep position and velocity,
    re-solve the clock bias from the median pseudorange residual and reset the clock
    covariance (as when the clock is first initialised after a UWB start)."""
    s = f.state
    f.reinits += 1
    f.count("clock_reset_uwb_consistent")
    s.nominal[6] += clock_offset_from_residuals(prep, s.nominal, s.bias_columns(prep))
    p = f.params
    s.ckf.reset_block(
        slice(6, 8), clock_reset_variances(s.ckf.p, p.init_clock_bias_std_m, p.init_clock_drift_std_mps)
    )
    s.bad_gnss_epochs = 0
    return f.output(True)


def declare_divergence(f: FilterFacade, stamp_ns: int, gnss_only: bool = False) -> FusionOutput:
    """Reinitialise from (a) the caller's reference solution, (b) a snapshot LS fix of the last
    GNSS epoch, (c) UWB multilateration; else reset to uninitialised. ``gnss_only``: declared by the
    GNSS rule alone on a state still within bounds (``divergence_fix_confirm_s`` applies)."""
    s = f.state
    f.reinits += 1
    frame = s.frame
    if s.initialized and f.params.use_uwb:
        # Three or more anchors heard: their multilateration (from the state, so on its side of a
        # coplanar set's mirror) is the position, the clock is kept. A GNSS fix would bring back
        # whatever made the filter diverge (a spoofer's position: issue 25; a jammed epoch).
        pos = multilaterate(f, stamp_ns, frame, s.nominal[0:3])
        if pos is not None:
            clock_ok = s.clock_initialized
            f.initialize(max(stamp_ns, s.t_ns), pos, frame_id=frame, position_std_m=1.0,
                         clock_bias_m=float(s.nominal[6]) if clock_ok else math.nan,
                         clock_drift_mps=float(s.nominal[7]) if clock_ok else math.nan)
            f.count("reinit_from_uwb")
            return f.output(True)
    if f.reference_provider is not None and frame == FRAME_EARTH:
        supplied = f.reference_provider(stamp_ns)
        if supplied is not None:
            f.supply_reference_solution(*supplied)
    ref = s.reference
    done = False
    if (
        ref is not None
        and frame == FRAME_EARTH
        and abs(stamp_ns - ref[0]) <= f.params.reference_max_age_s * _NS
    ):
        f.initialize(max(stamp_ns, s.t_ns), ref[1], clock_bias_m=ref[3], position_std_m=ref[2])
        done = True
    if (
        not done
        and frame == FRAME_EARTH
        and s.last_prep is not None
        and s.last_prep[0] == stamp_ns
    ):
        prep = s.last_prep[1]
        fix, fix_system = snapshot_fix(f, prep)
        if fix is not None and not fix_agrees_with_uwb(f, stamp_ns, fix[0], f.params.init_position_std_m):
            f.count("gnss_fix_inconsistent_with_uwb")
            fix = None
        if gnss_only and f.params.divergence_fix_confirm_s > 0 and s.initialized:
            if fix is None or not fix_confirmed(f, stamp_ns, fix):
                # divergence_fix_confirm_s: keep the state until a second fix agrees with this one
                f.reinits -= 1
                f.count("divergence_unconfirmed")
                s.bad_gnss_epochs = 0
                return f.output(False)
        if fix is not None:
            f.initialize(
                stamp_ns, fix[0], velocity_mps=fix[2], clock_bias_m=fix[1], clock_drift_mps=fix[3],
                position_clock_covariance_m2=fix[4],
            )
            s.ref_system = fix_system
            s.update_bias_states(stamp_ns, prep, f.count)
            done = True
    if not done:
        pos = multilaterate(f, stamp_ns, frame, s.nominal[0:3] if s.initialized else None)
        if pos is not None:
            f.initialize(stamp_ns, pos, frame_id=frame, position_std_m=1.0)
            done = True
    if not done:
        s.reset(f.params)
        s.t_ns = stamp_ns
        f.count("reset_uninitialized")
    return f.output(True)


def consistent_uwb_fix(f: FilterFacade, stamp_ns: int, frame: str, range_std_m: float) -> np.ndarray | None:
    """A multi-start multilateration on the latest range of at least four anchors (three, on
    the installer's side of their plane, with ``uwb_tag_side_of_anchor_plane``) within
    ``uwb_init_window_s`` whose residuals are all within ``UWB_FIX_CONSISTENT_SIGMA`` range
    1-sigmas, else None (beyond the paper). Asked when one anchor has had
    ``divergence_uwb_ranges`` consecutive ranges gated: if such a fix exists the ranges are
    consistent and the state is wrong; if not, that anchor's ranges are faulty (e.g. NLOS) and
    stay gated. The fix must also disagree with the state: squared Mahalanobis distance
    ``d^T (P_pos + C_fix)^-1 d`` above the 3-dof chi-square quantile of ``gate_probability``,
    with ``C_fix = sigma^2 (H^T H)^-1`` the fix's covariance (``H``: unit lines of sight), so
    that a fix a slightly biased anchor moves by decimetres does not restart the filter."""
    s = f.state
    win = f.params.uwb_init_window_s * _NS
    ranged = [(a, r) for (t, a, r, fr) in s.recent_uwb.values() if fr == frame and stamp_ns - t <= win]
    side = f.params.uwb_tag_side_of_anchor_plane
    if len(ranged) < (3 if side else 4):
        return None
    pos = init.multilaterate(s.recent_uwb, stamp_ns, frame, f.params.uwb_init_window_s, f.lever)
    if pos is None:
        return None
    anchors = np.array([a for a, _ in ranged])
    if len(ranged) == 3:
        # three anchors fix two points, mirrors across their plane: the installer's side picks one
        plane = anchor_plane(anchors)
        if plane is None:
            return None
        if on_wrong_side(f, pos + f.lever, plane):
            pos = reflect(pos + f.lever, *plane) - f.lever
    rel = pos + f.lever - anchors
    dist = np.linalg.norm(rel, axis=1)
    res = np.array([r for _, r in ranged]) - dist
    if float(np.max(np.abs(res))) > UWB_FIX_CONSISTENT_SIGMA * range_std_m:
        return None
    h = rel / dist[:, None]
    try:
        cov = range_std_m**2 * np.linalg.inv(h.T @ h) + s.ckf.p[0:3, 0:3]
        d = pos - s.nominal[0:3]
        far = float(d @ np.linalg.solve(cov, d)) > f.gate_3d
    except np.linalg.LinAlgError:
        return None
    return pos if far else None


def reanchor_on_uwb(f: FilterFacade, stamp_ns: int) -> bool:
    """GNSS was found spoofed (gnss_integrity): drop what it put into the state and start again from
    the UWB ranges alone, before the caller excludes GNSS.

    A spoofer drags the state before it is detected (and may have re-initialised it from its own
    fix); with GNSS excluded the filter would coast on that state's velocity while its small
    covariance gates the anchors' ranges. So the state is re-initialised from UWB multilateration
    (the current position as the starting guess, which keeps the side of a coplanar set's mirror),
    with zero velocity and the clock unknown, as after a UWB start. Returns False (state unchanged,
    counted ``reanchor_without_uwb``) when the ranges of the last ``uwb_init_window_s`` do not
    multilaterate (fewer than three anchors): the filter then coasts on its motion model.
    """
    s = f.state
    if not s.initialized:
        return False
    pos = multilaterate(f, stamp_ns, s.frame, s.nominal[0:3])
    if pos is None:  # the guess is far off (dragged): the multi-start of a UWB start
        pos = multilaterate(f, stamp_ns, s.frame)
    if pos is None:
        f.count("reanchor_without_uwb")
        return False
    f.initialize(max(stamp_ns, s.t_ns), pos, frame_id=s.frame, position_std_m=1.0)
    f.count("reanchor_on_uwb")
    return True

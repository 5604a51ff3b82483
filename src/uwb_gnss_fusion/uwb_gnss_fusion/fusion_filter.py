"""Tightly-coupled GNSS/UWB error-state cubature Kalman filter, robust to jamming (Cao et al.).

Pure core (no ROS). The node converts messages to the ``gnss_common.observations`` dataclasses
and calls :meth:`FusionFilter.process_gnss`, :meth:`FusionFilter.process_uwb`,
:meth:`FusionFilter.set_jammer_to_signal` and (optionally) :meth:`FusionFilter.supply_reference_solution`;
each processing call returns a frozen :class:`FusionOutput`. Time is passed in as integer
nanoseconds (``stamp_ns``) and never read from a clock, so replays are bit-identical.

State: nominal ``[p (3), v (3), c*dt, c*ddt]`` in m, m/s, m, m/s (ECEF, frame "earth"; or the
anchors' local frame "map" in UWB-only mode, where the clock states are frozen and unused) and an
8-state error vector (Cao et al., eq. 8) estimated by the CKF and folded into the nominal after
every update (eq. 25). With several GNSS (``FusionParams.multi_gnss``), ``c*dt`` is the receiver
clock in the reference system's time (GPS, unless the filter started from a fix of another
system) and each other system seen gets an inter-system bias state ``b_sys`` (m, a random walk)
appended after the clock, in the order the systems appear: a GPS-only stream keeps 8 states.
With ``FusionParams.pseudorange_correlated_std_m`` > 0, each tracked satellite has a first-order
Gauss-Markov pseudorange-error state ``e_sat`` (m) after the inter-system biases, allocated when
the satellite appears and removed (marginalised) when it has been unseen for a while.

:class:`FusionFilter` is the facade; the pieces live in their own modules:

=========================  ==================================================================
:mod:`.fusion_params`      :class:`FusionParams`, frame and mode codes
:mod:`.fusion_output`      :class:`FusionOutput`
:mod:`.input_checks`       satellite and UWB range validation, :class:`.input_checks.PreparedEpoch`
:mod:`.reorder_buffer`     :class:`ReorderBuffer` (late inputs) and its window-growth policy
:mod:`.initialisation`     snapshot fix (eq. 5-6), multilateration (eq. 7), drift memory
:mod:`.gnss_update`        weights (eq. 4, 12), common-mode screen, GNSS update (eq. 5, 6, 17-24)
:mod:`.uwb_update`         UWB update (eq. 7, 13, 17-25)
:mod:`.divergence`         divergence rules
:mod:`.mirror_test`        the mirror ambiguity of coplanar anchors, resolved by GNSS
:mod:`.motion_model`       static or moving: the stationarity detector and the zero-velocity update
:mod:`.ckf`                the CKF, which owns the error covariance (eq. 14-24)
=========================  ==================================================================
"""

from __future__ import annotations

import collections
import copy
import math
from collections.abc import Callable, Mapping

import numpy as np
from scipy.stats import chi2

from gnss_common.clock_model import clock_process_noise_m as _clock_q
from gnss_common.observations import GPS, GnssEpoch, UwbRangeMeasurement

from . import initialisation as init
from .ckf import CholeskyError, CubatureKalmanFilter
from .divergence import GatedWindow, clock_reset_variances, gnss_epoch_inconsistent, position_lost
from .fusion_output import FusionOutput
from .fusion_params import (  # noqa: F401 (re-exported: the filter's public names)
    CORRELATED_ERROR_MAX_GAP_TAU,
    FRAME_EARTH,
    FRAME_MAP,
    INTER_SYSTEM_BIAS_INIT_STD_M,
    INTER_SYSTEM_BIAS_MAX_GAP_S,
    INTER_SYSTEM_BIAS_PSD_M2PS,
    MODE_GNSS,
    MODE_GNSS_UWB,
    MODE_NONE,
    MODE_UWB,
    UWB_FIX_CONSISTENT_SIGMA,
    UWB_NOISE_PRIOR_WEIGHT,
    FusionParams,
)
from .gnss_update import (
    clock_offset_from_residuals,
    prepare_epoch,
    receiver_clock_step,
    screen_common_mode,
    update_gnss,
)
from .input_checks import CONSTELLATION_NAMES, PreparedEpoch, skipped_constellations, validate_uwb_range
from .measurement_models import STATE_DIM, constant_velocity_transition, pseudorange_model, white_acceleration_noise
from .mirror_test import (
    MIRROR_MAX_RANGE_CHANGE_SIGMA,
    MirrorTest,
    anchor_plane,
    clock_free_chi2,
    householder,
    is_range_ambiguous,
    mirror_wrong_side_probability,
    reflect,
)
from .motion_model import StationarityDetector, static_exit_statistic, zero_velocity_update
from .reorder_buffer import ReorderBuffer  # noqa: F401 (re-exported)
from .uwb_update import RangeNoiseEstimate, apply_range

_NS = 1_000_000_000
UWB_FIX_MIN_ANCHORS = 3
"""Anchors needed for ranges alone to fix the position (up to the mirror of their plane): below this,
with GNSS in use, the shared-bias rule (``uwb_range_bias_std_m``) weights the ranges."""
FIX_AGREEMENT_CHI2_3DOF = float(chi2.ppf(0.9973, 3))
"""Two snapshot fixes agree (``divergence_fix_confirm_s``) when their position difference is within this
chi-square (3 dof, the probability of 3 standard deviations) of their combined covariance."""
FIX_CONFIRM_MAX_GAP_S = 300.0
"""Longest interval over which consecutive snapshot fixes are compared (``divergence_fix_confirm_s``) when the
receiver reports more slowly than ten times that setting (RINEX observation files at 30 s), s."""
FIX_CONFIRM_UNKNOWN_SPEED_MPS = 30.0
"""Speed, per axis, allowed between two compared fixes when the earlier one has no velocity (fewer than four
pseudorange rates): a road vehicle's, m/s."""



class FusionFilter:
    """GNSS/UWB tightly-coupled CKF (Cao et al.), with gating, jammer-aware weights and reinit.

    Args:
        params: :class:`FusionParams`.
        reference_provider: optional callable ``provider(stamp_ns)`` returning the caller's
            independent solution at or before ``stamp_ns`` as ``(stamp_ns, ecef_position_m (3,),
            position_std_m, clock_bias_m)``, or None. It is asked only when the filter diverges
            (the pull form of :meth:`supply_reference_solution`: a caller whose solver is expensive,
            e.g. the node's SPP, then solves only the epochs needed instead of every epoch).

    Notes:
        Cao et al., eq. 5-7 (models, :mod:`.measurement_models`), eq. 8-10 (constant-velocity error
        state), eq. 14-24 (CKF, :mod:`.ckf`), eq. 25 (status correction), eq. 4 (effective C/N0,
        :mod:`.jamming_weights`). Beyond the paper: per-measurement chi-square gating, divergence
        detection with reinitialisation, asynchronous GNSS/UWB with an out-of-order policy
        (older-than-filter-time messages are rejected and counted "out_of_order"; use
        :class:`ReorderBuffer` in front to re-order within a window), GNSS-only / UWB-only / both;
        an iterated (Gauss-Newton) refinement of strongly nonlinear updates
        (``max_update_iterations``; 0 restores the paper's plain CKF update), a windowed UWB
        divergence test (``divergence_uwb_gated_fraction``), an optional UWB range latency and an
        optional skewed Huber weighting of UWB ranges, and an elevation weighting (sigma / sin(el)) of
        satellites that report no C/N0. A UWB range is applied with the exact
        position-only cubature shortcut (``active_dims``), which equals the 16-point update.
        Reinitialisation trusts the unjammed sensor: a GNSS-declared divergence the UWB ranges do
        not confirm re-solves the clock and keeps the position; a GNSS snapshot fix that fails the
        gate against a recent UWB range is refused; a reinitialisation keeps the clock drift.
        UWB multilateration is multi-start and waits for a fourth anchor (or a whole
        ``uwb_init_window_s``) because three anchors have two mirror solutions. One anchor gated
        ``divergence_uwb_ranges`` times in a row while a multilateration explains every anchor
        restarts the position from that fix (``uwb_gated_anchor_reinit``: a wrong local minimum of
        the ranges). Optionally (``uwb_mirror_test``) the mirror of coplanar anchors is resolved by
        an accumulated GNSS log-likelihood ratio (:mod:`.mirror_test`), or by the installer's side
        of the anchors' plane (``uwb_tag_side_of_anchor_plane``; with and without GNSS). Optionally
        the range noise carries the second-order variance of the range over the position
        uncertainty (``uwb_range_curvature_noise``) and each anchor's noise is estimated from its
        innovations (``uwb_range_noise_adaptive``, :class:`.uwb_update.RangeNoiseEstimate`).

    Example:
        >>> f = FusionFilter(FusionParams(use_gnss=False))
        >>> out = f.initialize(0, np.zeros(3), frame_id="map")
        >>> out.initialized, out.frame_id
        (True, 'map')
    """

    def __init__(
        self,
        params: FusionParams | None = None,
        reference_provider: Callable[[int], tuple[int, np.ndarray, float, float] | None] | None = None,
    ) -> None:
        self.params = params if params is not None else FusionParams()
        self._reference_provider = reference_provider
        self._gate = self.params.gate_nis
        self._gate_3d = (
            math.inf if self.params.gate_probability >= 1.0 else float(chi2.ppf(self.params.gate_probability, 3))
        )
        self._transition_cache: dict[tuple[int, bool, int, int, bool], tuple[np.ndarray, np.ndarray]] = {}
        self._counts_tuple: tuple[tuple[str, int], ...] | None = None
        clock = self.params.clock
        self._clock_q = lambda dt_s: _clock_q(clock, dt_s)
        self._lever = np.asarray(self.params.uwb_lever_arm_m, dtype=float)
        self._lever_floats = tuple(float(v) for v in self._lever)
        self._uwb_scratch = np.zeros(6)  # diagnostics of the compiled UWB update (.ckf_kernels)
        self._gated_restarted: set[str] = set()  # anchors that restarted the filter (uwb_gated_anchor_reinit)
        self._side_last_ns: int | None = None  # last side-prior check without GNSS (_side_prior_uwb)
        # per-anchor range noise estimates (uwb_range_noise_adaptive); a property of the hardware,
        # kept across reinitialisations
        self._uwb_noise: dict[str, RangeNoiseEstimate] = {}
        self._anchor_registry: Mapping[str, np.ndarray] = {
            a[0]: np.array([float(a[1]), float(a[2]), float(a[3])]) for a in self.params.anchors
        }
        self._counts: dict[str, int] = {}
        self._reinits = 0
        self._js_db = math.nan
        self._js_stamp_ns: int | None = None
        self._reference: tuple[int, np.ndarray, float, float] | None = None
        self._recent_uwb: dict[str, tuple[int, np.ndarray, float, str]] = {}
        self._last_gnss_stamp: int | None = None
        self._last_uwb_stamp: int | None = None
        self._last_prep: tuple[int, PreparedEpoch] | None = None
        self._initialized = False
        self._drift_memory_mps: float | None = None
        self._uwb_wait_since_ns: int | None = None
        # the test assumes the filter's pseudorange error model: white (tau -> 0, every epoch
        # independent) unless the correlated errors are modelled
        self._mirror = MirrorTest(
            self.params.pseudorange_correlated_tau_s if self.params.pseudorange_correlated_std_m > 0.0 else 0.0,
            self.params.uwb_mirror_switch_log_lr,
        )
        self._mirror_last_ns: int | None = None
        # uwb_mirror_covariance: the plane of the anchors heard, per (_anchor_version, frame), until
        # _mirror_valid_until_ns
        self._mirror_plane_key: tuple = (-1, "")
        self._mirror_valid_until_ns = -1
        self._mirror_plane: tuple | None = None  # (n n^T in 6x6, c . n, normal, anchors with their off-plane distance)
        self._anchor_version = 0  # counts changes of the set of anchors heard: new, back after silence, moved
        self._motion = StationarityDetector(self.params.static_enter_s)
        self._moving_pv_var = np.zeros(6)  # position/velocity variances when the static model was entered
        self._reset_state()

    # ------------------------------------------------------------------ state handling
    def _reset_state(self) -> None:
        self._remember_drift()
        self._initialized = False
        self._clock_initialized = False
        self._frame = FRAME_EARTH
        self._t_ns = 0
        self._nominal = np.zeros(STATE_DIM)
        self._ckf = CubatureKalmanFilter(np.zeros(STATE_DIM), np.eye(STATE_DIM))
        self._reset_systems(GPS)
        self._bad_gnss_epochs = 0
        self._held_fix: tuple[int, np.ndarray, np.ndarray, np.ndarray | None] | None = None
        self._fix_attempt_ns: int | None = None
        self._uwb_gated = GatedWindow(self.params.divergence_uwb_ranges)
        self._anchor_gated_run: dict[str, int] = {}
        self._shared_bias_stamps: dict[str, collections.deque[int]] = {}
        self._reset_mirror()
        self._motion.reset()

    def _reset_mirror(self, key: object = None) -> None:
        self._mirror.reset(key)
        self._mirror_last_ns = None

    def _reset_systems(self, reference: int) -> None:
        """No inter-system bias states; ``reference`` is the system whose time ``c*dt`` is in."""
        self._ref_system = int(reference)
        self._bias_systems: list[int] = []  # system of state column STATE_DIM + i
        self._bias_seen_ns: dict[int, int] = {}
        self._err_sats: list[int] = []  # satellite key of correlated-error column _err_base() + i
        self._err_seen_ns: dict[int, int] = {}

    def _err_base(self) -> int:
        """First state column of the correlated pseudorange errors (after the inter-system biases)."""
        return STATE_DIM + len(self._bias_systems)

    def _remember_drift(self) -> None:
        """Keep the clock drift of a state about to be replaced (reinitialisation, reset)."""
        if self._initialized and self._clock_initialized and self._frame == FRAME_EARTH:
            drift = float(self._nominal[7])
            if math.isfinite(drift):
                self._drift_memory_mps = drift

    def _count(self, reason: str, n: int = 1) -> None:
        if n > 0:
            self._counts[reason] = self._counts.get(reason, 0) + n
            self._counts_tuple = None

    @property
    def rejection_counts(self) -> dict[str, int]:
        """Cumulative rejection/event counts by reason (a copy)."""
        return dict(self._counts)

    def rejection_counts_key(self) -> tuple[tuple[str, int], ...]:
        """The cumulative counts as a sorted tuple (cached until a count changes; cheap to compare)."""
        return self._rejection_tuple()

    @property
    def initialized(self) -> bool:
        """True once the filter has a state."""
        return self._initialized

    @property
    def awaiting_fix_confirmation(self) -> bool:
        """True while the filter has no state and holds a snapshot fix for a later one to confirm
        (``divergence_fix_confirm_s``)."""
        return not self._initialized and self._held_fix is not None

    @property
    def time_ns(self) -> int:
        """Filter time, ns."""
        return self._t_ns

    @property
    def state_dimension(self) -> int:
        """Size of the state: 8, plus one inter-system bias per system other than the reference seen,
        plus one correlated pseudorange error per tracked satellite (when modelled)."""
        return int(self._nominal.size)

    @property
    def inter_system_biases_m(self) -> dict[str, tuple[float, float]]:
        """Inter-system clock biases: system name -> (estimate, 1-sigma), m, relative to the
        reference system's clock (:attr:`reference_system`)."""
        out = {}
        for i, sysc in enumerate(self._bias_systems):
            col = STATE_DIM + i
            var = max(float(self._ckf.p[col, col]), 0.0)
            out[CONSTELLATION_NAMES.get(sysc, f"code_{sysc}")] = (float(self._nominal[col]), math.sqrt(var))
        return out

    @property
    def correlated_errors_m(self) -> dict[int, tuple[float, float]]:
        """Time-correlated pseudorange errors: satellite key (``constellation * 1000 + svid``) ->
        (estimate, 1-sigma), m (empty when they are not modelled)."""
        base = self._err_base()
        return {
            sat: (float(self._nominal[base + i]), math.sqrt(max(float(self._ckf.p[base + i, base + i]), 0.0)))
            for i, sat in enumerate(self._err_sats)
        }

    @property
    def reference_system(self) -> str:
        """The system whose time the receiver clock state ``c*dt`` is in ("gps" unless the filter
        started from a fix of another system)."""
        return CONSTELLATION_NAMES.get(self._ref_system, f"code_{self._ref_system}")

    def initialize(
        self,
        stamp_ns: int,
        position_m: np.ndarray,
        *,
        frame_id: str = FRAME_EARTH,
        velocity_mps: np.ndarray | None = None,
        clock_bias_m: float = math.nan,
        clock_drift_mps: float = math.nan,
        position_std_m: float | None = None,
        position_clock_covariance_m2: np.ndarray | None = None,
    ) -> FusionOutput:
        """(Re)initialise the state from an external solution (e.g. the caller's SPP).

        Args:
            stamp_ns: time of the solution, ns.
            position_m: position in ``frame_id``, m, shape (3,).
            frame_id: "earth" (ECEF) or "map" (UWB-only local frame).
            velocity_mps: velocity, m/s, shape (3,) (None: zero with ``init_velocity_std_mps``).
            clock_bias_m: receiver c*dt, m (NaN: set from the next GNSS epoch).
            clock_drift_mps: receiver c*ddt, m/s (NaN: the drift of the previous state if there was
                one, with ``init_clock_drift_std_mps``; else zero with
                ``init_clock_drift_unobserved_std_mps``).
            position_std_m: 1-sigma per axis, m (None: ``init_position_std_m``).
            position_clock_covariance_m2: covariance of (x, y, z, c*dt) of the solution, m^2,
                (4, 4), e.g. a snapshot fix's (None: ``position_std_m`` per axis, uncorrelated).
                The filter never starts more confident than ``position_std_m`` (eigenvalues of the
                position block floored at its square) or ``init_clock_bias_std_m``, but keeps the
                solution's larger variances along its weak directions (a fix on few jammed
                satellites is often tens of metres off in height) and its position-clock
                correlation, so a UWB range or the next epochs correct both consistently.

        Returns:
            The output at ``stamp_ns``.

        Raises:
            ValueError: on a non-finite position, a wrong shape or an unknown frame.
        """
        stamp_ns = self._check_stamp_type(stamp_ns)
        pos = np.asarray(position_m, dtype=float)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise ValueError(f"position_m must be 3 finite numbers, got {position_m!r}")
        if frame_id not in (FRAME_EARTH, FRAME_MAP):
            raise ValueError(f"frame_id must be 'earth' or 'map', got {frame_id!r}")
        vel = np.zeros(3) if velocity_mps is None else np.asarray(velocity_mps, dtype=float)
        if vel.shape != (3,) or not np.isfinite(vel).all():
            raise ValueError("velocity_mps must be 3 finite numbers")
        p = self.params
        std_p = p.init_position_std_m if position_std_m is None else float(position_std_m)
        if not (math.isfinite(std_p) and std_p > 0.0):
            raise ValueError("position_std_m must be finite and > 0")
        self._remember_drift()
        self._uwb_wait_since_ns = None
        self._frame = frame_id
        self._t_ns = stamp_ns
        self._nominal = np.zeros(STATE_DIM)
        self._nominal[0:3] = pos
        self._nominal[3:6] = vel
        clock_ok = math.isfinite(clock_bias_m) and frame_id == FRAME_EARTH
        self._nominal[6] = clock_bias_m if clock_ok else 0.0
        drift, drift_std = self._initial_drift(clock_drift_mps if clock_ok else math.nan)
        self._nominal[7] = drift if clock_ok else 0.0
        var = np.array(
            [std_p**2] * 3
            + [p.init_velocity_std_mps**2] * 3
            + [p.init_clock_bias_std_m**2, drift_std**2]
        )
        cov0 = np.diag(var)
        if position_clock_covariance_m2 is not None:
            cov0 = _with_solution_covariance(cov0, position_clock_covariance_m2, clock_ok)
        self._ckf = CubatureKalmanFilter(np.zeros(STATE_DIM), cov0)
        self._reset_systems(GPS)
        self._initialized = True
        self._clock_initialized = clock_ok
        self._bad_gnss_epochs = 0
        self._uwb_gated = GatedWindow(self.params.divergence_uwb_ranges)
        self._anchor_gated_run = {}
        self._reset_mirror()
        self._motion.reset()
        return self._output(False)

    def _initial_drift(self, clock_drift_mps: float) -> tuple[float, float]:
        return init.initial_drift(clock_drift_mps, self._drift_memory_mps, self.params)

    def supply_reference_solution(
        self, stamp_ns: int, position_m: np.ndarray, position_std_m: float, clock_bias_m: float = math.nan
    ) -> None:
        """Give the filter an independent solution (e.g. SPP) to reinitialise from on divergence.

        Args:
            stamp_ns: time of the solution, ns.
            position_m: ECEF position, m, shape (3,).
            position_std_m: its 1-sigma per axis, m, > 0.
            clock_bias_m: receiver c*dt, m (NaN if unknown).
        """
        pos = np.asarray(position_m, dtype=float)
        if pos.shape != (3,) or not np.isfinite(pos).all() or not (position_std_m > 0.0):
            self._count("invalid_reference")
            return
        self._reference = (int(stamp_ns), pos.copy(), float(position_std_m), float(clock_bias_m))

    def reanchor_on_uwb(self, stamp_ns: int) -> bool:
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
        if not self._initialized:
            return False
        pos = self._multilaterate(stamp_ns, self._frame, self._nominal[0:3])
        if pos is None:  # the guess is far off (dragged): the multi-start of a UWB start
            pos = self._multilaterate(stamp_ns, self._frame)
        if pos is None:
            self._count("reanchor_without_uwb")
            return False
        self.initialize(max(stamp_ns, self._t_ns), pos, frame_id=self._frame, position_std_m=1.0)
        self._count("reanchor_on_uwb")
        return True

    _NOT_IN_SNAPSHOT = frozenset({"params", "_counts", "_counts_tuple", "_reinits", "_reference_provider",
                                  "_clock_q", "_uwb_noise"})
    """What :meth:`snapshot` leaves out: the parameters (the caller's, now), the cumulative counts (they
    never go back), the caller's reference provider, and the per-anchor range noise (a property of the
    hardware, learned across re-initialisations)."""

    def snapshot(self) -> dict:
        """A deep copy of the filter's state, for :meth:`restore` (``rollback.RollbackHistory``)."""
        return copy.deepcopy({k: v for k, v in self.__dict__.items() if k not in self._NOT_IN_SNAPSHOT})

    def restore(self, snapshot: dict) -> None:
        """Go back to a :meth:`snapshot` (which stays usable): state, time, histories; the parameters, the
        counts and the reference provider stay as they are now. Counted ``rolled_back``."""
        self.__dict__.update(copy.deepcopy(snapshot))
        self._count("rolled_back")

    def side_of_anchor_plane(self, stamp_ns: int, min_distance_m: float = 0.1) -> int:
        """The side of the anchors' plane the state's tag is on: +1 above, -1 below (the local vertical,
        as ``uwb_tag_side_of_anchor_plane``), 0 when not initialised, fewer than three anchors were heard
        within ``uwb_init_window_s``, they span no plane, or the tag is within ``min_distance_m`` of it.
        While GNSS holds the state, this is the side GNSS chose; the caller may keep it for a period
        without GNSS (:meth:`reanchor_on_uwb`), when three anchors alone cannot tell the mirror apart."""
        if not self._initialized:
            return 0
        win = self.params.uwb_init_window_s * _NS
        anchors = [a for (t, a, _, f) in self._recent_uwb.values() if f == self._frame and stamp_ns - t <= win]
        plane = anchor_plane(np.array(anchors)) if len(anchors) >= 3 else None
        if plane is None:
            return 0
        tag = self._nominal[0:3] + self._lever
        up = tag / max(float(np.linalg.norm(tag)), 1.0) if self._frame == FRAME_EARTH else np.array([0.0, 0.0, 1.0])
        n_up = plane[1] if float(plane[1] @ up) >= 0.0 else -plane[1]
        distance = float((tag - plane[0]) @ n_up)
        return 0 if abs(distance) < min_distance_m else (1 if distance > 0.0 else -1)

    def set_jammer_to_signal(self, stamp_ns: int, jammer_to_signal_db: float) -> None:
        """Record the J/S reported by the RFI monitor (rfi_msgs/JammerState.jammer_to_signal_db).

        Args:
            stamp_ns: time of the monitor output, ns.
            jammer_to_signal_db: J/S, dB (NaN: no information; clears the previous value).
        """
        if not math.isfinite(jammer_to_signal_db):
            self._js_db = math.nan
            self._js_stamp_ns = None
            return
        self._js_db = float(jammer_to_signal_db)
        self._js_stamp_ns = int(stamp_ns)

    def process(self, measurement: GnssEpoch | UwbRangeMeasurement) -> FusionOutput:
        """Dispatch a GNSS epoch or a UWB range to :meth:`process_gnss` / :meth:`process_uwb`."""
        if isinstance(measurement, GnssEpoch):
            return self.process_gnss(measurement)
        if isinstance(measurement, UwbRangeMeasurement):
            return self.process_uwb(measurement)
        raise TypeError(f"unsupported measurement type {type(measurement).__name__}")

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_stamp_type(stamp_ns) -> int:
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)):
            raise TypeError(f"stamp_ns must be an integer number of ns, got {type(stamp_ns).__name__}")
        return int(stamp_ns)

    def _admit_stamp(self, stamp_ns: int) -> bool:
        """Out-of-order / time-gap policy. Returns False if the message must be dropped."""
        if stamp_ns < 0:
            self._count("invalid_stamp")
            return False
        if not self._initialized:
            return True
        if stamp_ns < self._t_ns:
            self._count("out_of_order")
            return False
        if (stamp_ns - self._t_ns) > self.params.max_prediction_s * _NS:
            self._count("time_gap_reset")
            self._reset_state()
        return True

    def _predict_to(self, stamp_ns: int) -> None:
        dt_ns = stamp_ns - self._t_ns
        if dt_ns <= 0:
            return
        nb = len(self._bias_systems)
        ne = len(self._err_sats)
        static = self._motion.static
        key = (dt_ns, self._frame == FRAME_EARTH, nb, ne, static)
        cached = self._transition_cache.get(key)
        if cached is None:
            dt = dt_ns / _NS
            tau = self.params.pseudorange_correlated_tau_s
            phi = constant_velocity_transition(dt, nb, ne, tau)
            q = np.zeros((STATE_DIM + nb + ne, STATE_DIM + nb + ne))
            psd = self.params.static_accel_psd_m2ps3 if static else self.params.accel_psd_m2ps3
            q[0:6, 0:6] = white_acceleration_noise(psd, dt)
            if key[1]:
                q[6:8, 6:8] = self._clock_q(dt)
                # inter-system biases: random walks
                isb = slice(STATE_DIM, STATE_DIM + nb)
                q[isb, isb] = np.eye(nb) * (INTER_SYSTEM_BIAS_PSD_M2PS * dt)
                if ne:
                    # Gauss-Markov: x_k+1 = exp(-dt/tau) x_k + w, var(w) = sigma^2 (1 - exp(-2 dt/tau))
                    # (Brown & Hwang, 4th ed., eq. 4.2.11-4.2.12)
                    idx = np.arange(STATE_DIM + nb, STATE_DIM + nb + ne)
                    q[idx, idx] = self.params.pseudorange_correlated_std_m**2 * (1.0 - math.exp(-2.0 * dt / tau))
            cached = (phi, q)
            if len(self._transition_cache) >= 64:  # the few distinct steps of a stream recur
                self._transition_cache.clear()
            self._transition_cache[key] = cached
        phi, q = cached
        # Nominal propagation (positioning status prediction) and error-covariance time update
        # (Cao et al., eq. 15-16), compiled and in place; the error mean is zero after every
        # correction.
        self._ckf.predict_with_nominal(self._nominal, phi, q)
        self._t_ns = stamp_ns

    def _correct(self) -> None:
        """Status correction, Cao et al. eq. 25, and error-state reset."""
        self._nominal = self._nominal + self._ckf.reset_error_state()

    def _mode(self) -> int:
        t = self._t_ns
        g = self._last_gnss_stamp is not None and t - self._last_gnss_stamp <= _NS
        u = self._last_uwb_stamp is not None and t - self._last_uwb_stamp <= _NS
        return (MODE_GNSS if g else 0) | (MODE_UWB if u else 0)

    def _current_js_db(self, stamp_ns: int) -> float:
        if self._js_stamp_ns is None:
            return math.nan
        if abs(stamp_ns - self._js_stamp_ns) > self.params.jammer_info_timeout_s * _NS:
            return math.nan
        return self._js_db

    def _rejection_tuple(self) -> tuple[tuple[str, int], ...]:
        if self._counts_tuple is None:
            self._counts_tuple = tuple(sorted(self._counts.items()))
        return self._counts_tuple

    def _output(
        self,
        diverged: bool,
        sat_used: int = 0,
        sat_rej: int = 0,
        uwb_used: int = 0,
        uwb_rej: int = 0,
        nis: float = math.nan,
    ) -> FusionOutput:
        init = self._initialized
        if init:
            pos = self._nominal[0:3].copy()
            vel = self._nominal[3:6].copy()
            extra = self._mirror_covariance() if self.params.uwb_mirror_covariance and self.params.use_uwb else None
            cov = self._ckf.p[0:6, 0:6].copy() if extra is None else self._ckf.p[0:6, 0:6] + extra[0] * extra[1]
        else:
            pos = np.full(3, math.nan)
            vel = np.full(3, math.nan)
            cov = np.full((6, 6), math.nan)
        clk_ok = init and self._clock_initialized and self._frame == FRAME_EARTH
        return FusionOutput(
            stamp_ns=self._t_ns,
            frame_id=self._frame,
            initialized=init,
            diverged=diverged,
            mode=self._mode() if init else MODE_NONE,
            position_m=pos,
            velocity_mps=vel,
            covariance_pv=cov,
            clock_bias_m=float(self._nominal[6]) if clk_ok else math.nan,
            clock_drift_mps=float(self._nominal[7]) if clk_ok else math.nan,
            satellites_used=sat_used,
            satellites_rejected=sat_rej,
            uwb_used=uwb_used,
            uwb_rejected=uwb_rej,
            normalized_innovation_squared=nis,
            jammer_to_signal_db=self._current_js_db(self._t_ns),
            rejection_counts=self._rejection_tuple(),
            reinitializations=self._reinits,
            motion_static=self._motion.static,
        )

    # ------------------------------------------------------------------ GNSS
    def process_gnss(self, epoch: GnssEpoch) -> FusionOutput:
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
        if not isinstance(epoch, GnssEpoch):
            raise TypeError(f"process_gnss expects a GnssEpoch, got {type(epoch).__name__}")
        stamp = self._check_stamp_type(epoch.stamp_ns)
        if not self.params.use_gnss:
            self._count("gnss_disabled")
            return self._output(False)
        if not self._admit_stamp(stamp):
            return self._output(False)
        if self._initialized and self._frame != FRAME_EARTH:
            self._count("gnss_in_map_frame")
            return self._output(False)
        # Constellations not in use are skipped (counted per constellation), not rejected satellites.
        n_obs = len(epoch.observations) - skipped_constellations(epoch.observations, self.params.multi_gnss)
        if n_obs == 0:
            self._count("no_satellites")
            return self._output(False)
        receiver = (
            self._nominal[0:3] + self._nominal[3:6] * ((stamp - self._t_ns) / _NS)
            if self._initialized
            else None
        )
        prep = prepare_epoch(epoch, receiver, self._current_js_db(stamp), self.params, self._count)
        if prep is None:
            self._count("no_valid_satellites")
            return self._output(False, sat_rej=n_obs)
        n = prep.pr.size
        pre_rejected = n_obs - n
        if n < 4:
            self._count("fewer_than_4_satellites")
        self._last_prep = (stamp, prep)
        if not self._initialized:
            fix, fix_system = self._snapshot_fix(prep)
            if fix is None:
                self._count("gnss_init_failed")
                return self._output(False, sat_rej=n_obs)
            if not self._fix_agrees_with_uwb(stamp, fix[0], self.params.init_position_std_m):
                self._count("gnss_fix_inconsistent_with_uwb")
                return self._output(False, sat_rej=n_obs)
            if self.params.divergence_fix_confirm_s > 0 and not self._fix_confirmed(stamp, fix):
                # divergence_fix_confirm_s: a second fix must agree. The epoch's pseudoranges are held in that
                # fix, not rejected (the status shows neither used nor rejected satellites).
                self._count("gnss_init_unconfirmed")
                return self._output(False)
            pos, clk, vel, drift, cov = fix
            self.initialize(stamp, pos, velocity_mps=vel, clock_bias_m=clk, clock_drift_mps=drift,
                            position_clock_covariance_m2=cov)
            self._ref_system = fix_system
            self._update_bias_states(stamp, prep)
            self._last_gnss_stamp = stamp
            return self._output(False, sat_used=n, sat_rej=pre_rejected)
        dt_s = (stamp - self._t_ns) / _NS
        self._predict_to(stamp)
        if not self._clock_initialized:
            # position known from UWB, clock not: set the clock from the pseudorange residuals.
            drift, drift_std = self._initial_drift(math.nan)
            self._nominal[6] = self._clock_from_residuals(prep)
            self._nominal[7] = drift
            self._ckf.reset_block(
                slice(6, 8), clock_reset_variances(self._ckf.p, self.params.init_clock_bias_std_m, drift_std)
            )
            self._clock_initialized = True
        cols = self._update_bias_states(stamp, prep)
        err_cols = self._update_error_states(stamp, prep)
        self._motion_before_update(prep, cols, err_cols, dt_s)
        n_screened = 0
        find_step = self.params.receiver_clock_steps
        if self.params.common_mode_screen:
            prep, n_screened, step = screen_common_mode(
                prep, self._nominal, self._ckf.p, self._gate, self._count, cols, err_cols, find_step
            )
            self._apply_clock_step(step)
            if prep.pr.size == 0:
                self._count("no_valid_satellites")
                return self._output(False, sat_rej=n_obs)
            n = prep.pr.size
            if n_screened:
                cols = self._bias_columns(prep)
                err_cols = self._error_columns(prep)
        elif find_step:
            self._apply_clock_step(receiver_clock_step(prep, self._nominal, self._ckf.p, self._gate, cols, err_cols))
        try:
            res = update_gnss(self._ckf, self._nominal, prep, self._gate, self.params, cols, err_cols)
        except CholeskyError:
            self._count("numerical_failure")
            return self._declare_divergence(stamp)
        acc_pr = res.accepted[:n]
        acc_rate = res.accepted[n:]
        gated_pr = int(n - acc_pr.sum())
        self._count("innovation_gate_pseudorange", gated_pr)
        self._count("innovation_gate_doppler", int(acc_rate.size - acc_rate.sum()))
        self._correct()
        self._motion_after_update(stamp)
        if (self.params.uwb_mirror_test or self.params.uwb_tag_side_of_anchor_plane) and self.params.use_uwb:
            self._mirror_check(stamp, prep, acc_pr, cols)
        used = int(acc_pr.sum())
        if used or acc_rate.any():
            self._last_gnss_stamp = stamp
        n_applied = int(res.accepted.sum())
        nis = res.nis / n_applied if n_applied else math.nan
        # Divergence: most pseudoranges of a well-observed epoch inconsistent with the state, for
        # several epochs in a row (a single jammed epoch with outliers does not trip it).
        if gnss_epoch_inconsistent(n, n_screened, gated_pr):
            self._bad_gnss_epochs += 1
        else:
            self._bad_gnss_epochs = 0
        if self._bad_gnss_epochs >= self.params.divergence_gnss_epochs or self._position_lost():
            self._count("divergence")
            if not self._position_lost() and self._uwb_agrees(stamp):
                return self._reset_clock_keep_position(stamp, prep)
            return self._declare_divergence(stamp, gnss_only=not self._position_lost())
        return self._output(False, sat_used=used, sat_rej=pre_rejected + n_screened + gated_pr, nis=nis)

    # ------------------------------------------------------------------ motion model
    def _motion_before_update(self, prep: PreparedEpoch, cols: np.ndarray | None, err_cols: np.ndarray | None,
                              dt_s: float) -> None:
        """Static model: the exit test on the predicted innovations (:mod:`.motion_model`). A failing
        epoch opens the covariance by the moving model's process noise minus the static one over
        ``dt_s`` (adaptive process noise); leaving the static model raises the position and velocity
        variances to the moving model's at entry."""
        if not self._motion.static:
            return
        # tested against the moving model's uncertainty at entry: the static average's own covariance
        # shrinks like 1 / epochs (white errors), the solution's time-correlated errors do not
        p_test = self._ckf.p.copy()
        p_test[0:6, 0:6] += np.diag(np.maximum(self._moving_pv_var - np.diag(p_test)[0:6], 0.0))
        parts = static_exit_statistic(prep, self._nominal, p_test, cols, err_cols)
        decision = self._motion.observe_static(parts)
        if decision.open_covariance:
            p = self.params
            self._ckf.p[0:6, 0:6] += white_acceleration_noise(p.accel_psd_m2ps3 - p.static_accel_psd_m2ps3, dt_s)
            self._count("motion_epoch_opened")
        if decision.left_static:
            # back to the moving model's uncertainty: the static average's covariance assumed white errors
            # and no motion since the entry, both now doubtful
            self._ckf.p[0:6, 0:6] += np.diag(np.maximum(self._moving_pv_var - np.diag(self._ckf.p)[0:6], 0.0))
            self._count("motion_static_left")

    def _motion_after_update(self, stamp_ns: int) -> None:
        """Moving model: the entry test on the updated state; on entry, a zero-velocity update."""
        p = self.params
        if not p.motion_detection or self._frame != FRAME_EARTH or self._motion.static:
            return
        if self._last_uwb_stamp is not None and stamp_ns - self._last_uwb_stamp <= p.uwb_init_window_s * _NS:
            return  # GNSS epochs alone: ranges at 10-50 Hz follow the motion (.motion_model)
        if not self._motion.observe_moving(stamp_ns, self._nominal[0:3], self._ckf.p[0:3, 0:3],
                                           self._nominal[3:6], self._ckf.p[3:6, 3:6]):
            return
        self._count("motion_static_entered")
        self._moving_pv_var = np.diag(self._ckf.p)[0:6].copy()
        dx, self._ckf.p = zero_velocity_update(self._ckf.p, self._nominal[3:6], p.static_velocity_std_mps)
        self._nominal = self._nominal + dx

    @property
    def motion_static(self) -> bool:
        """True while the static model runs (:mod:`.motion_model`)."""
        return self._motion.static

    def _apply_clock_step(self, step: tuple[float, bool, float]) -> None:
        """``receiver_clock_steps``: move the clock bias by a step of the receiver clock
        (:func:`.gnss_update.receiver_clock_step`, found with the common-mode screen) before the update. A
        whole number of milliseconds is a known adjustment: the clock keeps its variance (counted as
        ``receiver_clock_step_ms``); any other step moves it by the consensus's common innovation and
        adds that estimate's variance to the clock's (``receiver_clock_step``; resetting the clock block
        instead, as after a divergence, gave the same errors on the real stations of
        ``benchmarks/fusion_clock_steps.py``). Beyond the paper."""
        step_m, whole_ms, step_var = step
        if step_m == 0.0:
            return
        self._nominal[6] += step_m
        if whole_ms:
            self._count("receiver_clock_step_ms")
            return
        self._count("receiver_clock_step")
        self._ckf.p[6, 6] += step_var

    # ------------------------------------------------------------------ mirror ambiguity
    def _mirror_check(self, stamp_ns: int, prep: PreparedEpoch, accepted: np.ndarray,
                      bias_column: np.ndarray | None) -> None:
        """Add the epoch to the mirror test (:mod:`.mirror_test`) and jump to the mirror when the
        GNSS evidence says so (beyond the paper).

        The anchors are those heard within ``uwb_init_window_s`` (the test restarts when that set
        changes); the mirror is the reflection of the tag (antenna plus lever arm) across their
        best-fit plane, tested only if it leaves every range within ``MIRROR_MAX_RANGE_CHANGE_SIGMA``
        range 1-sigmas. The residuals are the raw pseudorange residuals (inter-system biases
        applied, correlated-error states not: the test scales for the correlation itself) of the
        pseudoranges the update accepted. The jump reflects position and velocity and applies the
        same reflection to the error covariance (``P <- T P T^T``, exact for a linear map).
        """
        p = self.params
        if self._frame != FRAME_EARTH or int(accepted.sum()) < 4:
            return
        window_ns = p.uwb_init_window_s * _NS
        recent = sorted(
            (aid, v[1]) for aid, v in self._recent_uwb.items() if v[3] == FRAME_EARTH and stamp_ns - v[0] <= window_ns
        )
        key = tuple(aid for aid, _ in recent)
        if key != self._mirror.key:
            self._reset_mirror(key)
        plane = anchor_plane(np.array([a for _, a in recent])) if len(recent) >= 3 else None
        if plane is None:
            return
        anchors = np.array([a for _, a in recent])
        tag = self._nominal[0:3] + self._lever
        tag_m = reflect(tag, *plane)
        if not is_range_ambiguous(tag, tag_m, anchors, p.uwb_range_std_m):
            return
        if p.uwb_tag_side_of_anchor_plane:
            if self._on_wrong_side(tag, plane):
                self._jump_to_mirror(tag_m, plane[1])
                self._count("uwb_side_prior_flip")
                self._reset_mirror(key)
            return
        states = np.stack([self._nominal, self._nominal])
        states[1, 0:3] = tag_m - self._lever
        hx = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column)
        res = prep.pr[None, :] - hx(states)
        chi2_pair = clock_free_chi2(res[:, accepted], prep.sigma_pr[accepted])
        dt_s = 0.0 if self._mirror_last_ns is None else (stamp_ns - self._mirror_last_ns) / _NS
        self._mirror_last_ns = stamp_ns
        if not self._mirror.add(chi2_pair, int(accepted.sum()), dt_s):
            return
        self._jump_to_mirror(tag_m, plane[1])
        self._count("uwb_mirror_switch")

    def _mirror_covariance(self) -> tuple[float, np.ndarray] | None:
        """``uwb_mirror_covariance``: the covariance the mirror ambiguity adds to the published position,
        ``p d^2 n n^T`` (``d`` the distance from the tag to its mirror across the anchors' plane, ``n`` the
        plane's normal, ``p`` :func:`.mirror_test.mirror_wrong_side_probability`), as ``(p d^2, n n^T
        padded to the (6, 6) position-velocity block)``, or None when there is none: fewer than three
        anchors heard within ``uwb_init_window_s``, anchors that do not span a plane, a mirror that
        changes some range by a range 1-sigma (four or more anchors off their plane), or the side
        given by ``uwb_tag_side_of_anchor_plane``. The filter's own covariance is not changed: it
        describes the solution on the side the filter holds. With GNSS the probability of the wrong
        side uses ``uwb_mirror_gnss_std_m``, without GNSS it is 0.5. Beyond the paper."""
        p = self.params
        if p.uwb_tag_side_of_anchor_plane:
            return None
        t = self._t_ns
        frame = self._frame
        if (t > self._mirror_valid_until_ns or self._anchor_version != self._mirror_plane_key[0]
                or frame != self._mirror_plane_key[1]):
            # the anchors heard within uwb_init_window_s: recomputed when an anchor appears, comes back,
            # moves or changes frame (_anchor_version), or when the first of them may have fallen silent
            window_ns = p.uwb_init_window_s * _NS
            heard = [(aid, v) for aid, v in self._recent_uwb.items() if v[3] == frame and t - v[0] <= window_ns]
            self._mirror_plane_key = (self._anchor_version, frame)
            self._mirror_valid_until_ns = int(min((v[0] for _, v in heard), default=t) + window_ns)
            self._mirror_plane = None
            if len(heard) >= 3:
                anchors = np.array([v[1] for _, v in heard])
                plane = anchor_plane(anchors)
                if plane is not None:
                    nn6 = np.zeros((6, 6))
                    nn6[0:3, 0:3] = np.outer(plane[1], plane[1])
                    off_plane = (anchors - plane[0]) @ plane[1]  # each anchor's distance from the plane
                    # farthest from the plane first: the one whose range the mirror changes most, usually
                    # the only one the test below has to look at
                    listed = tuple(sorted(((*map(float, a), float(o)) for a, o in zip(anchors, off_plane, strict=True)),
                                          key=lambda row: -abs(row[3])))
                    self._mirror_plane = (nn6, float(plane[0] @ plane[1]), tuple(float(v) for v in plane[1]), listed)
        cached = self._mirror_plane
        if cached is None:
            return None
        nn6, c_dot_n, (n0, n1, n2), anchors = cached
        # in Python floats (this runs at every output): s the tag's signed distance from the plane, d = 2 |s|
        x0, x1, x2 = self._nominal[0:3].tolist()
        l0, l1, l2 = self._lever_floats
        t0, t1, t2 = x0 + l0, x1 + l1, x2 + l2
        s = t0 * n0 + t1 * n1 + t2 * n2 - c_dot_n
        d = 2.0 * abs(s)
        if len(anchors) > 3:
            # four or more anchors: ambiguous only if the mirror (tag - 2 s n) changes no range by a range
            # 1-sigma (MIRROR_MAX_RANGE_CHANGE_SIGMA, as mirror_test.is_range_ambiguous); its squared range
            # to anchor i is r_i^2 + 4 s o_i, o_i the anchor's distance from the plane
            limit = MIRROR_MAX_RANGE_CHANGE_SIGMA * p.uwb_range_std_m
            for a0, a1, a2, o in anchors:
                r2 = (a0 - t0) ** 2 + (a1 - t1) ** 2 + (a2 - t2) ** 2
                if abs(math.sqrt(max(r2 + 4.0 * s * o, 0.0)) - math.sqrt(r2)) >= limit:
                    return None
        with_gnss = p.use_gnss and frame == FRAME_EARTH and self._clock_initialized
        prob = mirror_wrong_side_probability(d, p.uwb_mirror_gnss_std_m if with_gnss else None)
        return prob * d * d, nn6

    def _on_wrong_side(self, tag: np.ndarray, plane: tuple[np.ndarray, np.ndarray]) -> bool:
        """True if ``tag`` lies on the other side of the anchors' ``plane`` (centroid, unit normal)
        than ``uwb_tag_side_of_anchor_plane`` says (a prior, not a test). "Up" is the local vertical:
        in the earth frame the radial direction, in the map frame (local ENU) +z."""
        centroid, normal = plane
        if self._frame == FRAME_EARTH:
            up = tag / max(float(np.linalg.norm(tag)), 1.0)
        else:
            up = np.array([0.0, 0.0, 1.0])
        n_up = normal if float(normal @ up) >= 0.0 else -normal
        return float((tag - centroid) @ n_up) * int(self.params.uwb_tag_side_of_anchor_plane) < 0.0

    def _side_prior_uwb(self, stamp_ns: int) -> None:
        """The installer's side of the anchors' plane without GNSS (UWB alone, or the map frame),
        checked after an accepted range at most once per ``uwb_init_window_s``: with GNSS the check
        runs at every GNSS epoch (:meth:`_mirror_check`); without it the side the UWB
        multilateration start happened to pick would otherwise stand. Beyond the paper."""
        p = self.params
        if self._side_last_ns is not None and stamp_ns - self._side_last_ns < p.uwb_init_window_s * _NS:
            return
        self._side_last_ns = stamp_ns
        window_ns = p.uwb_init_window_s * _NS
        anchors = [v[1] for v in self._recent_uwb.values() if v[3] == self._frame and stamp_ns - v[0] <= window_ns]
        if len(anchors) < 3:
            return
        arr = np.array(anchors)
        plane = anchor_plane(arr)
        if plane is None:
            return
        tag = self._nominal[0:3] + self._lever
        tag_m = reflect(tag, *plane)
        if is_range_ambiguous(tag, tag_m, arr, p.uwb_range_std_m) and self._on_wrong_side(tag, plane):
            self._jump_to_mirror(tag_m, plane[1])
            self._count("uwb_side_prior_flip")

    def _jump_to_mirror(self, tag_m: np.ndarray, normal: np.ndarray) -> None:
        """Move the state to the mirror image ``tag_m`` of the tag across the anchors' plane (unit
        ``normal``): position and velocity reflected, the error covariance by the same linear map
        (``P <- T P T^T``, exact)."""
        m = householder(normal)
        t = np.eye(self._nominal.size)
        t[0:3, 0:3] = m
        t[3:6, 3:6] = m
        self._nominal[0:3] = tag_m - self._lever
        self._nominal[3:6] = m @ self._nominal[3:6]
        self._ckf = CubatureKalmanFilter(np.zeros(self._nominal.size), t @ self._ckf.p @ t.T)

    # ------------------------------------------------------------------ several GNSS
    def _bias_columns(self, prep: PreparedEpoch) -> np.ndarray | None:
        """State column of each satellite's inter-system bias (-1: the reference system), or None
        when every satellite is of the reference system (the single-clock model exactly)."""
        system = prep.system
        ref = self._ref_system
        if system is None:  # all GPS
            if ref == GPS:
                return None
            system = np.full(prep.pr.size, GPS, dtype=np.int64)
        if not self._bias_systems:
            return None if (system == ref).all() else np.full(system.size, -1, dtype=np.int64)
        cols = np.full(system.size, -1, dtype=np.int64)
        for i, sysc in enumerate(self._bias_systems):
            cols[system == sysc] = STATE_DIM + i
        return None if (cols < 0).all() and (system == ref).all() else cols

    def _update_bias_states(self, stamp_ns: int, prep: PreparedEpoch) -> np.ndarray | None:
        """Add a bias state for each system seen for the first time, re-initialise those of
        systems back after more than ``INTER_SYSTEM_BIAS_MAX_GAP_S``; return the bias columns.

        A new (or returning) system's bias is the median residual of its pseudoranges at the
        predicted state with the reference clock (:func:`.gnss_update.clock_offset_from_residuals`),
        with variance ``INTER_SYSTEM_BIAS_INIT_STD_M^2`` and no correlation: its satellites then
        fix their bias first and the position only through their differences, so that a system
        appearing cannot move the position by its bias.
        """
        system = prep.system
        ref = self._ref_system
        if self._frame != FRAME_EARTH or (system is None and ref == GPS):
            return None
        if system is None:  # all GPS, the reference another system
            system = np.full(prep.pr.size, GPS, dtype=np.int64)
        if (system == ref).all():
            return None
        var0 = INTER_SYSTEM_BIAS_INIT_STD_M**2
        for sysc in np.unique(system).tolist():
            if sysc == ref:
                continue
            rows = system == sysc
            if sysc not in self._bias_systems:
                value = clock_offset_from_residuals(prep, self._nominal, None, rows)
                n = self._nominal.size
                at = self._err_base()  # before the correlated-error columns (if any)
                cov = np.insert(np.insert(self._ckf.p, at, 0.0, axis=0), at, 0.0, axis=1)
                cov[at, at] = var0
                self._nominal = np.insert(self._nominal, at, value)
                self._ckf = CubatureKalmanFilter(np.zeros(n + 1), cov)
                self._bias_systems.append(int(sysc))
                self._count("inter_system_bias_added")
            elif stamp_ns - self._bias_seen_ns[sysc] > INTER_SYSTEM_BIAS_MAX_GAP_S * _NS:
                col = STATE_DIM + self._bias_systems.index(sysc)
                self._nominal[col] = clock_offset_from_residuals(prep, self._nominal, None, rows)
                self._ckf.reset_block(slice(col, col + 1), np.array([var0]))
                self._count("inter_system_bias_reset")
            self._bias_seen_ns[int(sysc)] = stamp_ns
        return self._bias_columns(prep)

    # ------------------------------------------------------------------ correlated errors
    def _error_columns(self, prep: PreparedEpoch) -> np.ndarray | None:
        """State column of each satellite's correlated pseudorange error, or None when not modelled."""
        if not self._err_sats or prep.sat_id is None:
            return None
        base = self._err_base()
        index = {sat: base + i for i, sat in enumerate(self._err_sats)}
        return np.array([index[s] for s in prep.sat_id.tolist()], dtype=np.int64)

    def _update_error_states(self, stamp_ns: int, prep: PreparedEpoch) -> np.ndarray | None:
        """Free the correlated-error states of satellites unseen for more than
        ``CORRELATED_ERROR_MAX_GAP_TAU`` correlation times, allocate one for each satellite of the
        epoch without one; return the error columns of the epoch's satellites.

        Removing a state (its row and column of P) is the exact marginalisation of a Gaussian; a
        new state starts at zero with the stationary variance ``sigma^2`` and no correlation (the
        error of a satellite just acquired is unknown). Counted: ``correlated_error_added``,
        ``correlated_error_removed``.
        """
        p = self.params
        if p.pseudorange_correlated_std_m <= 0.0 or self._frame != FRAME_EARTH or prep.sat_id is None:
            return None
        base = self._err_base()
        limit_ns = CORRELATED_ERROR_MAX_GAP_TAU * p.pseudorange_correlated_tau_s * _NS
        stale = [i for i, sat in enumerate(self._err_sats) if stamp_ns - self._err_seen_ns[sat] > limit_ns]
        if stale:
            keep = np.ones(self._nominal.size, dtype=bool)
            keep[[base + i for i in stale]] = False
            for i in reversed(stale):
                del self._err_seen_ns[self._err_sats.pop(i)]
            self._nominal = self._nominal[keep]
            self._ckf = CubatureKalmanFilter(np.zeros(self._nominal.size), self._ckf.p[np.ix_(keep, keep)])
            self._count("correlated_error_removed", len(stale))
        known = set(self._err_sats)
        new = [sat for sat in prep.sat_id.tolist() if sat not in known]
        if new:
            n = self._nominal.size
            k = len(new)
            cov = np.zeros((n + k, n + k))
            cov[:n, :n] = self._ckf.p
            idx = np.arange(n, n + k)
            cov[idx, idx] = p.pseudorange_correlated_std_m**2
            self._nominal = np.concatenate([self._nominal, np.zeros(k)])
            self._ckf = CubatureKalmanFilter(np.zeros(n + k), cov)
            self._err_sats.extend(new)
            self._count("correlated_error_added", k)
        for sat in prep.sat_id.tolist():
            self._err_seen_ns[sat] = stamp_ns
        return self._error_columns(prep)

    def _clock_from_residuals(self, prep: PreparedEpoch) -> float:
        """The receiver clock from the pseudorange residuals (position trusted): over the
        reference system's satellites, and those of systems with a bias state; when the epoch has
        none of them, the largest system present becomes the reference."""
        system = prep.system
        if system is None:
            if self._ref_system == GPS:
                return clock_offset_from_residuals(prep, self._nominal)
            system = np.full(prep.pr.size, GPS, dtype=np.int64)
        known = (system == self._ref_system) | np.isin(system, self._bias_systems)
        if not known.any():
            values, counts = np.unique(system, return_counts=True)
            self._ref_system = int(values[np.argmax(counts)])
            known = system == self._ref_system
        return clock_offset_from_residuals(prep, self._nominal, self._bias_columns(prep), known)

    def _snapshot_fix(self, prep: PreparedEpoch) -> tuple[tuple | None, int]:
        """A snapshot fix (:func:`.initialisation.snapshot_fix`) on one system's satellites: GPS
        when it has ``min_satellites_init``, else the system with the most satellites (one
        receiver clock); returns ``(fix or None, its system)``."""
        system = prep.system
        if system is None or (system == GPS).all():
            return init.snapshot_fix(prep, self.params.min_satellites_init), GPS
        values, counts = np.unique(system, return_counts=True)
        n_gps = int(counts[values == GPS].sum())
        best = GPS if n_gps >= self.params.min_satellites_init else int(values[np.argmax(counts)])
        return init.snapshot_fix(prep.subset(system == best), self.params.min_satellites_init), best

    # ------------------------------------------------------------------ UWB
    def _range_iterations(self, heard: int) -> int:
        """Refinement steps allowed for a range (``uwb_iterate_min_anchors``): none while GNSS is used and fewer
        anchors than that were heard within ``uwb_init_window_s`` (``heard``, -1: not counted), else
        ``max_update_iterations``."""
        p = self.params
        k = p.uwb_iterate_min_anchors
        if k <= 0 or heard < 0:
            return p.max_update_iterations
        return p.max_update_iterations if heard >= k else 0

    def _anchors_heard(self, stamp_ns: int) -> int:
        """Anchors of the filter's frame with a range within ``uwb_init_window_s`` before ``stamp_ns``, when GNSS
        is used in the earth frame and a rule needs the count (``uwb_iterate_min_anchors``,
        ``uwb_range_bias_std_m``); else -1."""
        p = self.params
        if not (p.use_gnss and self._frame == FRAME_EARTH) or (p.uwb_iterate_min_anchors <= 0
                                                              and p.uwb_range_bias_std_m <= 0.0):
            return -1
        oldest = stamp_ns - int(p.uwb_init_window_s * 1e9)
        frame = self._frame
        n = 0
        for t, _, _, f in self._recent_uwb.values():
            if t >= oldest and f == frame:
                n += 1
        return n

    def uwb_anchors_heard(self, stamp_ns: int) -> int:
        """Anchors (of the filter's frame, when it has one) with a range within ``uwb_init_window_s`` before
        ``stamp_ns``: for diagnostics (three anchors leave a mirror solution across their plane that the ranges cannot
        rule out, ``uwb_tag_side_of_anchor_plane``)."""
        oldest = stamp_ns - int(self.params.uwb_init_window_s * 1e9)
        frame = self._frame if self._initialized else None
        return sum(1 for t, _, _, f in self._recent_uwb.values() if t >= oldest and (frame is None or f == frame))

    def _range_std_with_shared_bias(self, stamp_ns: int, anchor_id: str, std_m: float, heard: int) -> float:
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
        p = self.params
        if p.uwb_range_bias_std_m <= 0.0 or heard < 0:
            return std_m
        if heard >= UWB_FIX_MIN_ANCHORS:
            if self._shared_bias_stamps:
                self._shared_bias_stamps.pop(anchor_id, None)
            return std_m
        stamps = self._shared_bias_stamps.setdefault(anchor_id, collections.deque())
        stamps.append(stamp_ns)
        oldest = stamp_ns - int(p.uwb_range_bias_time_s * 1e9)
        while stamps and stamps[0] < oldest:
            stamps.popleft()
        n = len(stamps)
        if n <= 1:
            return std_m
        return math.sqrt(std_m * std_m + n * p.uwb_range_bias_std_m**2)

    def process_uwb(self, meas: UwbRangeMeasurement) -> FusionOutput:
        """Predict to the range's stamp and apply it.

        Args:
            meas: one UWB two-way range; ``meas.stamp_ns`` in ns, anchor position in ``meas.frame_id``.

        Returns:
            :class:`FusionOutput` after the update (or the unchanged state if rejected).

        Notes:
            Cao et al., eq. 7, 13 and 17-25, with gating.
        """
        if not isinstance(meas, UwbRangeMeasurement):
            raise TypeError(f"process_uwb expects a UwbRangeMeasurement, got {type(meas).__name__}")
        stamp = self._check_stamp_type(meas.stamp_ns)
        p = self.params
        if not p.use_uwb:
            self._count("uwb_disabled")
            return self._output(False)
        anchor = validate_uwb_range(meas, p, self._anchor_registry, self._count)
        if anchor is None:
            return self._output(False, uwb_rej=1)
        rng = float(meas.range_m)
        stated = float(meas.range_std_m) if math.isfinite(meas.range_std_m) else p.uwb_range_std_m
        noise = None
        if p.uwb_range_noise_adaptive and (
            p.uwb_range_noise_adaptive_without_gnss or (p.use_gnss and meas.frame_id == FRAME_EARTH)
        ):
            noise = self._uwb_noise.get(meas.anchor_id)
            if noise is None:
                noise = self._uwb_noise[meas.anchor_id] = RangeNoiseEstimate(
                    p.uwb_range_noise_window, UWB_NOISE_PRIOR_WEIGHT, p.uwb_range_std_floor_m, p.uwb_range_std_ceiling_m
                )
                self._count("uwb_noise_estimates")
            std = noise.std_m(stated)
        else:
            std = stated
        if not self._admit_stamp(stamp):
            return self._output(False, uwb_rej=1)
        if self._initialized and meas.frame_id != self._frame:
            self._count("uwb_frame_mismatch")
            return self._output(False, uwb_rej=1)
        if self._motion.static:  # the detector watches GNSS epochs alone (.motion_model)
            self._motion.reset()
            self._count("motion_static_left_uwb")
        prev = self._recent_uwb.get(meas.anchor_id)
        if (prev is None or stamp - prev[0] > p.uwb_init_window_s * _NS or prev[3] != meas.frame_id
                or prev[1][0] != anchor[0] or prev[1][1] != anchor[1] or prev[1][2] != anchor[2]):
            self._anchor_version += 1
        self._recent_uwb[meas.anchor_id] = (stamp, anchor, rng, meas.frame_id)
        if not self._initialized:
            if not self._init_from_uwb(stamp, meas.frame_id):
                self._count("uwb_waiting_for_init")
                return self._output(False)
            return self._output(False, uwb_used=1)
        self._predict_to(stamp)
        heard = self._anchors_heard(stamp)
        std_apply = self._range_std_with_shared_bias(stamp, meas.anchor_id, std, heard)
        try:
            ok, nis = apply_range(
                self._ckf, self._nominal, anchor, self._lever, rng, std_apply, self._gate, p, self._uwb_scratch,
                self._range_iterations(heard),
            )
        except CholeskyError:
            self._count("numerical_failure")
            return self._declare_divergence(stamp)
        self._uwb_gated.push(ok)
        if ok and noise is not None and self._uwb_scratch[3] == 1.0 and std_apply == std:
            noise.add(float(self._uwb_scratch[0]), float(self._uwb_scratch[1]), std, stated)
        if ok:
            if self._anchor_gated_run:
                self._anchor_gated_run.pop(meas.anchor_id, None)
            self._last_uwb_stamp = stamp
            if p.uwb_tag_side_of_anchor_plane and not (p.use_gnss and self._frame == FRAME_EARTH):
                self._side_prior_uwb(stamp)
            if self._position_lost():
                self._count("divergence")
                return self._declare_divergence(stamp)
            return self._output(False, uwb_used=1, nis=nis)
        self._count("innovation_gate_uwb")
        run = self._anchor_gated_run.get(meas.anchor_id, 0) + 1
        self._anchor_gated_run[meas.anchor_id] = run
        if run >= p.divergence_uwb_ranges and p.uwb_gated_anchor_reinit and meas.anchor_id not in self._gated_restarted:
            self._anchor_gated_run[meas.anchor_id] = 0
            pos = self._consistent_uwb_fix(stamp, meas.frame_id, std)
            if pos is not None:
                self._gated_restarted.add(meas.anchor_id)
                # every anchor agrees with a fix and the state gates one of them: the state sits in
                # a wrong local minimum of the ranges (e.g. near the mirror of three of four
                # anchors). Once per anchor id in the filter's life: a biased anchor whose fix also
                # explains the ranges (weak geometry) must not make the filter cycle.
                self._reinits += 1
                self._count("uwb_anchor_gated_reinit")
                self.initialize(stamp, pos, frame_id=meas.frame_id, position_std_m=1.0)
                self._last_uwb_stamp = stamp
                return self._output(True, uwb_rej=1)
        # Divergence: most of the recent ranges (all anchors together) inconsistent with the state.
        # A single anchor that still agrees (the state sits on its range sphere) does not mask it.
        if self._uwb_gated.diverged(p.divergence_uwb_gated_fraction):
            self._count("divergence")
            return self._declare_divergence(stamp)
        return self._output(False, uwb_rej=1)

    def _consistent_uwb_fix(self, stamp_ns: int, frame: str, range_std_m: float) -> np.ndarray | None:
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
        win = self.params.uwb_init_window_s * _NS
        ranged = [(a, r) for (t, a, r, f) in self._recent_uwb.values() if f == frame and stamp_ns - t <= win]
        side = self.params.uwb_tag_side_of_anchor_plane
        if len(ranged) < (3 if side else 4):
            return None
        pos = init.multilaterate(self._recent_uwb, stamp_ns, frame, self.params.uwb_init_window_s, self._lever)
        if pos is None:
            return None
        anchors = np.array([a for a, _ in ranged])
        if len(ranged) == 3:
            # three anchors fix two points, mirrors across their plane: the installer's side picks one
            plane = anchor_plane(anchors)
            if plane is None:
                return None
            if self._on_wrong_side(pos + self._lever, plane):
                pos = reflect(pos + self._lever, *plane) - self._lever
        rel = pos + self._lever - anchors
        dist = np.linalg.norm(rel, axis=1)
        res = np.array([r for _, r in ranged]) - dist
        if float(np.max(np.abs(res))) > UWB_FIX_CONSISTENT_SIGMA * range_std_m:
            return None
        h = rel / dist[:, None]
        try:
            cov = range_std_m**2 * np.linalg.inv(h.T @ h) + self._ckf.p[0:3, 0:3]
            d = pos - self._nominal[0:3]
            far = float(d @ np.linalg.solve(cov, d)) > self._gate_3d
        except np.linalg.LinAlgError:
            return None
        return pos if far else None

    def _multilaterate(self, stamp_ns: int, frame: str, guess: np.ndarray | None = None) -> np.ndarray | None:
        return init.multilaterate(self._recent_uwb, stamp_ns, frame, self.params.uwb_init_window_s, self._lever, guess)

    def _init_from_uwb(self, stamp_ns: int, frame: str) -> bool:
        """Initialise by multilateration once :func:`.initialisation.uwb_init_ready`."""
        if self._uwb_wait_since_ns is None:
            self._uwb_wait_since_ns = stamp_ns
        if not init.uwb_init_ready(self._recent_uwb, stamp_ns, frame, self._uwb_wait_since_ns,
                                   self.params.uwb_init_window_s):
            return False
        pos = self._multilaterate(stamp_ns, frame)
        if pos is None:
            return False
        self.initialize(stamp_ns, pos, frame_id=frame, position_std_m=1.0)
        self._last_uwb_stamp = stamp_ns
        return True

    # ------------------------------------------------------------------ divergence
    def _position_lost(self) -> bool:
        return position_lost(self._ckf.p, self._nominal, self.params.max_position_std_m)

    def _uwb_agrees(self, stamp_ns: int) -> bool:
        """True if the UWB ranges still agree with the state (GNSS-declared divergence is then a
        GNSS fault, not a lost state): a range was accepted within ``uwb_init_window_s`` and fewer
        than ``divergence_uwb_gated_fraction`` of the (at least half-full) range window were gated."""
        p = self.params
        return (
            p.use_uwb
            and self._last_uwb_stamp is not None
            and stamp_ns - self._last_uwb_stamp <= p.uwb_init_window_s * _NS
            and self._uwb_gated.agrees(p.divergence_uwb_gated_fraction)
        )

    def _fix_agrees_with_uwb(self, stamp_ns: int, position_m: np.ndarray, position_std_m: float) -> bool:
        return init.fix_agrees_with_uwb(
            self._recent_uwb, stamp_ns, position_m, position_std_m, self._lever, self._gate, self.params
        )

    def _reset_clock_keep_position(self, stamp_ns: int, prep: PreparedEpoch) -> FusionOutput:
        """GNSS-declared divergence while UWB agrees with the state: keep position and velocity,
        re-solve the clock bias from the median pseudorange residual and reset the clock
        covariance (as when the clock is first initialised after a UWB start)."""
        self._reinits += 1
        self._count("clock_reset_uwb_consistent")
        self._nominal[6] += clock_offset_from_residuals(prep, self._nominal, self._bias_columns(prep))
        p = self.params
        self._ckf.reset_block(
            slice(6, 8), clock_reset_variances(self._ckf.p, p.init_clock_bias_std_m, p.init_clock_drift_std_mps)
        )
        self._bad_gnss_epochs = 0
        return self._output(True)

    def _fix_confirmed(self, stamp_ns: int, fix: tuple) -> bool:
        """``divergence_fix_confirm_s``: whether the held fix agrees with ``fix`` within 3 combined standard
        deviations (chi-square, 3 dof, of the position difference).

        The held fix must be at least ``divergence_fix_confirm_s`` older than ``fix`` and at most ten times that,
        or, when it is the fix attempt just before this one (a receiver that reports every 30 s), at most
        :data:`FIX_CONFIRM_MAX_GAP_S`. It is moved by its velocity over the interval when it has one (four or
        more pseudorange rates), and the comparison allows ``init_velocity_std_mps`` (with a velocity) or
        :data:`FIX_CONFIRM_UNKNOWN_SPEED_MPS` (without) per axis times the interval for the motion in between.
        A newer fix replaces the held one when it is compared and disagrees, or when the held one is too old; a
        fix too soon after the held one is not compared (the held one stays)."""
        new = (int(stamp_ns), np.asarray(fix[0], float), np.asarray(fix[4], float),
               np.asarray(fix[2], float) if math.isfinite(fix[3]) else None)
        held = self._held_fix
        previous_attempt = self._fix_attempt_ns
        self._fix_attempt_ns = int(stamp_ns)
        lo = self.params.divergence_fix_confirm_s
        if held is None:
            self._held_fix = new
            return False
        dt_s = (stamp_ns - held[0]) / _NS
        if dt_s < lo and dt_s >= 0:
            return False
        hi = 10.0 * lo
        if previous_attempt == held[0]:
            hi = max(hi, FIX_CONFIRM_MAX_GAP_S)
        if not lo <= dt_s <= hi:
            self._held_fix = new
            return False
        predicted = held[1] if held[3] is None else held[1] + held[3] * dt_s
        speed_std = self.params.init_velocity_std_mps if held[3] is not None else FIX_CONFIRM_UNKNOWN_SPEED_MPS
        d = new[1] - predicted
        c = held[2][0:3, 0:3] + new[2][0:3, 0:3] + np.eye(3) * (speed_std * dt_s) ** 2
        try:
            q = float(d @ np.linalg.solve(c, d))
        except np.linalg.LinAlgError:
            q = math.inf
        if q <= FIX_AGREEMENT_CHI2_3DOF:
            self._held_fix = None
            return True
        self._held_fix = new
        return False

    def _declare_divergence(self, stamp_ns: int, gnss_only: bool = False) -> FusionOutput:
        """Reinitialise from (a) the caller's reference solution, (b) a snapshot LS fix of the last
        GNSS epoch, (c) UWB multilateration; else reset to uninitialised. ``gnss_only``: declared by the
        GNSS rule alone on a state still within bounds (``divergence_fix_confirm_s`` applies)."""
        self._reinits += 1
        frame = self._frame
        if self._initialized and self.params.use_uwb:
            # Three or more anchors heard: their multilateration (from the state, so on its side of a
            # coplanar set's mirror) is the position, the clock is kept. A GNSS fix would bring back
            # whatever made the filter diverge (a spoofer's position: issue 25; a jammed epoch).
            pos = self._multilaterate(stamp_ns, frame, self._nominal[0:3])
            if pos is not None:
                clock_ok = self._clock_initialized
                self.initialize(max(stamp_ns, self._t_ns), pos, frame_id=frame, position_std_m=1.0,
                                clock_bias_m=float(self._nominal[6]) if clock_ok else math.nan,
                                clock_drift_mps=float(self._nominal[7]) if clock_ok else math.nan)
                self._count("reinit_from_uwb")
                return self._output(True)
        if self._reference_provider is not None and frame == FRAME_EARTH:
            supplied = self._reference_provider(stamp_ns)
            if supplied is not None:
                self.supply_reference_solution(*supplied)
        ref = self._reference
        done = False
        if (
            ref is not None
            and frame == FRAME_EARTH
            and abs(stamp_ns - ref[0]) <= self.params.reference_max_age_s * _NS
        ):
            self.initialize(max(stamp_ns, self._t_ns), ref[1], clock_bias_m=ref[3], position_std_m=ref[2])
            done = True
        if (
            not done
            and frame == FRAME_EARTH
            and self._last_prep is not None
            and self._last_prep[0] == stamp_ns
        ):
            prep = self._last_prep[1]
            fix, fix_system = self._snapshot_fix(prep)
            if fix is not None and not self._fix_agrees_with_uwb(stamp_ns, fix[0], self.params.init_position_std_m):
                self._count("gnss_fix_inconsistent_with_uwb")
                fix = None
            if gnss_only and self.params.divergence_fix_confirm_s > 0 and self._initialized:
                if fix is None or not self._fix_confirmed(stamp_ns, fix):
                    # divergence_fix_confirm_s: keep the state until a second fix agrees with this one
                    self._reinits -= 1
                    self._count("divergence_unconfirmed")
                    self._bad_gnss_epochs = 0
                    return self._output(False)
            if fix is not None:
                self.initialize(
                    stamp_ns, fix[0], velocity_mps=fix[2], clock_bias_m=fix[1], clock_drift_mps=fix[3],
                    position_clock_covariance_m2=fix[4],
                )
                self._ref_system = fix_system
                self._update_bias_states(stamp_ns, prep)
                done = True
        if not done:
            pos = self._multilaterate(stamp_ns, frame, self._nominal[0:3] if self._initialized else None)
            if pos is not None:
                self.initialize(stamp_ns, pos, frame_id=frame, position_std_m=1.0)
                done = True
        if not done:
            self._reset_state()
            self._t_ns = stamp_ns
            self._count("reset_uninitialized")
        return self._output(True)


def _with_solution_covariance(cov0: np.ndarray, sol_cov: np.ndarray, clock_ok: bool) -> np.ndarray:
    """The initial covariance ``cov0`` (diagonal) with a solution's (x, y, z, c*dt) covariance.

    Position block: the solution's, its eigenvalues floored at ``cov0``'s position variance; clock:
    the larger of the two variances; cross terms: the solution's. Only variances are raised, so the
    result is the solution's covariance plus a positive semi-definite matrix. Without a clock
    (``clock_ok`` False) the clock row keeps ``cov0``'s and no cross term.
    """
    c = np.asarray(sol_cov, dtype=float)
    if c.shape != (4, 4) or not np.all(np.isfinite(c)):
        raise ValueError(f"position_clock_covariance_m2 must be a finite (4, 4) array, got shape {c.shape}")
    c = 0.5 * (c + c.T)
    lam, vec = np.linalg.eigh(c[0:3, 0:3])
    if lam[0] < -1e-9 * max(1.0, float(lam[-1])):
        raise ValueError("position_clock_covariance_m2 is not positive semi-definite")
    out = cov0.copy()
    out[0:3, 0:3] = (vec * np.maximum(lam, cov0[0, 0])) @ vec.T
    if clock_ok:
        out[6, 6] = max(cov0[6, 6], float(c[3, 3]))
        out[0:3, 6] = c[0:3, 3]
        out[6, 0:3] = c[3, 0:3]
    return out

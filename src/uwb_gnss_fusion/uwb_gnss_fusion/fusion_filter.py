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
the satellite appears and removed (marginalised) when it has been unseen for a while; otherwise,
with ``FusionParams.glonass_satellite_bias_std_m`` > 0 (the default), each GLONASS satellite has a
random-constant code-bias state there (its FDMA channel's inter-frequency bias).

:class:`FusionFilter` is the facade: it holds the parameters, the counts and one
:class:`.filter_state.FilterState`, and hands each message to the module of its kind. By lifecycle
and measurement:

=========================  ==================================================================
:mod:`.filter_state`       the state and its time update (eq. 8-10, 15-16, 25), inter-system
                           bias and correlated-error states
:mod:`.gnss_epoch`         one GNSS epoch, start to end (eq. 4-6, 12, 15-25)
:mod:`.uwb_update`         one UWB range, start to end (eq. 7, 13, 17-25)
:mod:`.lifecycle`          start-up and divergence: first fix, confirmation, re-initialisation
:mod:`.mirror_handling`    the mirror of coplanar anchors in the state (maths: :mod:`.mirror_test`)
:mod:`.clock_steps`        receiver clock steps, found and applied
=========================  ==================================================================

and the maths they call: :mod:`.fusion_params` (:class:`FusionParams`, frame and mode codes),
:mod:`.fusion_output` (:class:`FusionOutput`), :mod:`.input_checks` (satellite and UWB range
validation), :mod:`.gnss_update` (weights, eq. 4, 12; common-mode screen; GNSS update, eq. 5, 6,
17-24), :mod:`.initialisation` (snapshot fix, eq. 5-6; multilateration, eq. 7; drift memory),
:mod:`.divergence` (divergence rules), :mod:`.mirror_test`, :mod:`.motion_model` (static or moving),
:mod:`.ckf` (the CKF, which owns the error covariance, eq. 14-24); :mod:`.reorder_buffer`
(:class:`ReorderBuffer`, late inputs, for the caller).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping

import numpy as np
from scipy.stats import chi2

from gnss_common.clock_model import clock_process_noise_m as _clock_q
from gnss_common.observations import GPS, GnssEpoch, UwbRangeMeasurement

from . import initialisation as init
from .ckf import CubatureKalmanFilter
from .divergence import GatedWindow
from .filter_state import FilterState, check_stamp_type
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
from .gnss_epoch import process_gnss
from .input_checks import CONSTELLATION_NAMES
from .lifecycle import reanchor_on_uwb
from .measurement_models import STATE_DIM
from .mirror_handling import mirror_covariance, side_of_anchor_plane
from .reorder_buffer import ReorderBuffer  # noqa: F401 (re-exported)
from .uwb_update import RangeNoiseEstimate, process_uwb, uwb_anchors_heard

_NS = 1_000_000_000


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

    __slots__ = ("params", "state", "reference_provider", "gate", "gate_3d", "lever", "lever_floats",
                 "anchor_registry", "clock_q", "uwb_noise", "reinits", "_counts", "_counts_tuple")

    NOT_IN_SNAPSHOT = {
        "params": "the caller's parameters, as they are now",
        "reference_provider": "the caller's",
        "gate": "from the parameters at construction (gate_nis), never changed",
        "gate_3d": "from the parameters at construction (gate_probability), never changed",
        "lever": "from the parameters at construction (uwb_lever_arm_m), never changed",
        "lever_floats": "the same as Python floats",
        "anchor_registry": "from the parameters at construction (anchors), never changed",
        "clock_q": "from the parameters at construction (clock), never changed",
        "uwb_noise": "the per-anchor range noise: a property of the hardware, learned across re-initialisations",
        "reinits": "cumulative: it never goes back",
        "_counts": "cumulative: they never go back",
        "_counts_tuple": "a cache of _counts",
    }
    """Every attribute of the filter but :attr:`state`, and why :meth:`snapshot` leaves it out. The
    attributes are ``__slots__``: one not declared there cannot be set, and a test checks that the slots
    are ``state`` and these, so a new attribute is either state (a field of
    :class:`.filter_state.FilterState`, in every snapshot) or listed here with its reason."""

    def __init__(
        self,
        params: FusionParams | None = None,
        reference_provider: Callable[[int], tuple[int, np.ndarray, float, float] | None] | None = None,
    ) -> None:
        self.params = params if params is not None else FusionParams()
        p = self.params
        self.reference_provider = reference_provider
        self.gate = p.gate_nis
        self.gate_3d = math.inf if p.gate_probability >= 1.0 else float(chi2.ppf(p.gate_probability, 3))
        self._counts: dict[str, int] = {}
        self._counts_tuple: tuple[tuple[str, int], ...] | None = None
        clock = p.clock
        self.clock_q: Callable[[float], np.ndarray] = lambda dt_s: _clock_q(clock, dt_s)
        self.lever = np.asarray(p.uwb_lever_arm_m, dtype=float)
        self.lever_floats = tuple(float(v) for v in self.lever)
        # per-anchor range noise estimates (uwb_range_noise_adaptive)
        self.uwb_noise: dict[str, RangeNoiseEstimate] = {}
        self.anchor_registry: Mapping[str, np.ndarray] = {
            a[0]: np.array([float(a[1]), float(a[2]), float(a[3])]) for a in p.anchors
        }
        self.reinits = 0
        self.state = FilterState.create(p)

    # ------------------------------------------------------------------ counts
    def count(self, reason: str, n: int = 1) -> None:
        """Add ``n`` (> 0) to the cumulative count of ``reason``."""
        if n > 0:
            self._counts[reason] = self._counts.get(reason, 0) + n
            self._counts_tuple = None

    @property
    def rejection_counts(self) -> dict[str, int]:
        """Cumulative rejection/event counts by reason (a copy)."""
        return dict(self._counts)

    def rejection_counts_key(self) -> tuple[tuple[str, int], ...]:
        """The cumulative counts as a sorted tuple (cached until a count changes; cheap to compare)."""
        if self._counts_tuple is None:
            self._counts_tuple = tuple(sorted(self._counts.items()))
        return self._counts_tuple

    # ------------------------------------------------------------------ what the state says
    @property
    def initialized(self) -> bool:
        """True once the filter has a state."""
        return self.state.initialized

    @property
    def awaiting_fix_confirmation(self) -> bool:
        """True while the filter has no state and holds a snapshot fix for a later one to confirm
        (``divergence_fix_confirm_s``)."""
        return not self.state.initialized and self.state.held_fix is not None

    @property
    def time_ns(self) -> int:
        """Filter time, ns."""
        return self.state.t_ns

    @property
    def state_dimension(self) -> int:
        """Size of the state: 8, plus one inter-system bias per system other than the reference seen,
        plus one correlated pseudorange error per tracked satellite (when modelled)."""
        return int(self.state.nominal.size)

    @property
    def inter_system_biases_m(self) -> dict[str, tuple[float, float]]:
        """Inter-system clock biases: system name -> (estimate, 1-sigma), m, relative to the
        reference system's clock (:attr:`reference_system`)."""
        s = self.state
        out = {}
        for i, sysc in enumerate(s.bias_systems):
            col = STATE_DIM + i
            var = max(float(s.ckf.p[col, col]), 0.0)
            out[CONSTELLATION_NAMES.get(sysc, f"code_{sysc}")] = (float(s.nominal[col]), math.sqrt(var))
        return out

    @property
    def correlated_errors_m(self) -> dict[int, tuple[float, float]]:
        """Time-correlated pseudorange errors: satellite key (``constellation * 1000 + svid``) ->
        (estimate, 1-sigma), m (empty when they are not modelled)."""
        s = self.state
        base = s.err_base()
        return {
            sat: (float(s.nominal[base + i]), math.sqrt(max(float(s.ckf.p[base + i, base + i]), 0.0)))
            for i, sat in enumerate(s.err_sats)
        }

    @property
    def reference_system(self) -> str:
        """The system whose time the receiver clock state ``c*dt`` is in ("gps" unless the filter
        started from a fix of another system)."""
        return CONSTELLATION_NAMES.get(self.state.ref_system, f"code_{self.state.ref_system}")

    @property
    def motion_static(self) -> bool:
        """True while the static model runs (:mod:`.motion_model`)."""
        return self.state.motion.static

    def uwb_anchors_heard(self, stamp_ns: int) -> int:
        """:func:`.uwb_update.uwb_anchors_heard` (for diagnostics)."""
        return uwb_anchors_heard(self, stamp_ns)

    def side_of_anchor_plane(self, stamp_ns: int, min_distance_m: float = 0.1) -> int:
        """:func:`.mirror_handling.side_of_anchor_plane`."""
        return side_of_anchor_plane(self, stamp_ns, min_distance_m)

    # ------------------------------------------------------------------ inputs
    def process(self, measurement: GnssEpoch | UwbRangeMeasurement) -> FusionOutput:
        """Dispatch a GNSS epoch or a UWB range to :meth:`process_gnss` / :meth:`process_uwb`."""
        if isinstance(measurement, GnssEpoch):
            return self.process_gnss(measurement)
        if isinstance(measurement, UwbRangeMeasurement):
            return self.process_uwb(measurement)
        raise TypeError(f"unsupported measurement type {type(measurement).__name__}")

    def process_gnss(self, epoch: GnssEpoch) -> FusionOutput:
        """Predict to the epoch's stamp and apply its pseudoranges (and pseudorange rates):
        :func:`.gnss_epoch.process_gnss` (Cao et al., eq. 4-6, 12, 15-25)."""
        return process_gnss(self, epoch)

    def process_uwb(self, meas: UwbRangeMeasurement) -> FusionOutput:
        """Predict to the range's stamp and apply it: :func:`.uwb_update.process_uwb` (Cao et al., eq. 7,
        13, 17-25)."""
        return process_uwb(self, meas)

    def set_jammer_to_signal(self, stamp_ns: int, jammer_to_signal_db: float) -> None:
        """Record the J/S reported by the RFI monitor (rfi_msgs/JammerState.jammer_to_signal_db).

        Args:
            stamp_ns: time of the monitor output, ns.
            jammer_to_signal_db: J/S, dB (NaN: no information; clears the previous value).
        """
        s = self.state
        if not math.isfinite(jammer_to_signal_db):
            s.js_db = math.nan
            s.js_stamp_ns = None
            return
        s.js_db = float(jammer_to_signal_db)
        s.js_stamp_ns = int(stamp_ns)

    def current_js_db(self, stamp_ns: int) -> float:
        """The J/S in use at ``stamp_ns``, dB: NaN when none was set or it is older than
        ``jammer_info_timeout_s`` (Cao et al., eq. 4 takes it)."""
        s = self.state
        if s.js_stamp_ns is None:
            return math.nan
        if abs(stamp_ns - s.js_stamp_ns) > self.params.jammer_info_timeout_s * _NS:
            return math.nan
        return s.js_db

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
            self.count("invalid_reference")
            return
        self.state.reference = (int(stamp_ns), pos.copy(), float(position_std_m), float(clock_bias_m))

    def reanchor_on_uwb(self, stamp_ns: int) -> bool:
        """GNSS found spoofed: start again from the UWB ranges alone (:func:`.lifecycle.reanchor_on_uwb`)."""
        return reanchor_on_uwb(self, stamp_ns)

    def admit_stamp(self, stamp_ns: int) -> bool:
        """Out-of-order / time-gap policy. Returns False if the message must be dropped."""
        s = self.state
        if stamp_ns < 0:
            self.count("invalid_stamp")
            return False
        if not s.initialized:
            return True
        if stamp_ns < s.t_ns:
            self.count("out_of_order")
            return False
        if (stamp_ns - s.t_ns) > self.params.max_prediction_s * _NS:
            self.count("time_gap_reset")
            s.reset(self.params)
        return True

    # ------------------------------------------------------------------ snapshot
    def snapshot(self) -> FilterState:
        """A deep copy of the filter's state (:class:`.filter_state.FilterState`), for :meth:`restore`
        (``rollback.RollbackHistory``); what it leaves out: :attr:`NOT_IN_SNAPSHOT`."""
        return copy.deepcopy(self.state)

    def restore(self, snapshot: FilterState) -> None:
        """Go back to a :meth:`snapshot` (which stays usable): state, time, histories; the parameters, the
        counts and the reference provider stay as they are now. Counted ``rolled_back``."""
        self.state = copy.deepcopy(snapshot)
        self.count("rolled_back")

    # ------------------------------------------------------------------ start and output
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
        s = self.state
        stamp_ns = check_stamp_type(stamp_ns)
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
        s.remember_drift()
        s.uwb_wait_since_ns = None
        s.frame = frame_id
        s.t_ns = stamp_ns
        s.nominal = np.zeros(STATE_DIM)
        s.nominal[0:3] = pos
        s.nominal[3:6] = vel
        clock_ok = math.isfinite(clock_bias_m) and frame_id == FRAME_EARTH
        s.nominal[6] = clock_bias_m if clock_ok else 0.0
        drift, drift_std = init.initial_drift(clock_drift_mps if clock_ok else math.nan, s.drift_memory_mps, p)
        s.nominal[7] = drift if clock_ok else 0.0
        var = np.array(
            [std_p**2] * 3
            + [p.init_velocity_std_mps**2] * 3
            + [p.init_clock_bias_std_m**2, drift_std**2]
        )
        cov0 = np.diag(var)
        if position_clock_covariance_m2 is not None:
            cov0 = _with_solution_covariance(cov0, position_clock_covariance_m2, clock_ok)
        s.ckf = CubatureKalmanFilter(np.zeros(STATE_DIM), cov0)
        s.reset_systems(GPS)
        s.initialized = True
        s.clock_initialized = clock_ok
        s.bad_gnss_epochs = 0
        s.uwb_gated = GatedWindow(self.params.divergence_uwb_ranges)
        s.anchor_gated_run = {}
        s.reset_mirror()
        s.motion.reset()
        return self.output(False)

    def output(
        self,
        diverged: bool,
        sat_used: int = 0,
        sat_rej: int = 0,
        uwb_used: int = 0,
        uwb_rej: int = 0,
        nis: float = math.nan,
    ) -> FusionOutput:
        """The output of the filter now (:class:`FusionOutput`), with the counts of the message just
        processed; the position covariance carries the mirror ambiguity with ``uwb_mirror_covariance``
        (:func:`.mirror_handling.mirror_covariance`)."""
        s = self.state
        init = s.initialized
        if init:
            pos = s.nominal[0:3].copy()
            vel = s.nominal[3:6].copy()
            extra = mirror_covariance(self) if self.params.uwb_mirror_covariance and self.params.use_uwb else None
            cov = s.ckf.p[0:6, 0:6].copy() if extra is None else s.ckf.p[0:6, 0:6] + extra[0] * extra[1]
        else:
            pos = np.full(3, math.nan)
            vel = np.full(3, math.nan)
            cov = np.full((6, 6), math.nan)
        clk_ok = init and s.clock_initialized and s.frame == FRAME_EARTH
        return FusionOutput(
            stamp_ns=s.t_ns,
            frame_id=s.frame,
            initialized=init,
            diverged=diverged,
            mode=s.mode() if init else MODE_NONE,
            position_m=pos,
            velocity_mps=vel,
            covariance_pv=cov,
            clock_bias_m=float(s.nominal[6]) if clk_ok else math.nan,
            clock_drift_mps=float(s.nominal[7]) if clk_ok else math.nan,
            satellites_used=sat_used,
            satellites_rejected=sat_rej,
            uwb_used=uwb_used,
            uwb_rejected=uwb_rej,
            normalized_innovation_squared=nis,
            jammer_to_signal_db=self.current_js_db(s.t_ns),
            rejection_counts=self.rejection_counts_key(),
            reinitializations=self.reinits,
            motion_static=s.motion.static,
        )


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

"""The fusion filter's state and its time update (Cao et al., eq. 8-10, 15-16, 25).

Pure core (no rclpy). :class:`FilterState` is everything :class:`.fusion_filter.FusionFilter` carries
from one message to the next: the nominal state and the CKF's error covariance, the filter time, the
inter-system bias and correlated-error states that the state grows and sheds, and the histories of
the start-up, divergence, mirror and motion rules. It is one explicit object so that
:meth:`.fusion_filter.FusionFilter.snapshot` copies all of it: a field added here is in every
snapshot (``test_fusion_filter.py`` checks that the filter holds nothing else that changes).

State vector: nominal ``[p (3), v (3), c*dt, c*ddt]`` in m, m/s, m, m/s (ECEF, frame "earth"; or
the anchors' local frame "map" in UWB-only mode, where the clock states are frozen and unused);
then one inter-system bias ``b_sys`` (m, a random walk) per system other than the reference seen,
in the order they appear; then one first-order Gauss-Markov pseudorange error ``e_sat`` (m) per
tracked satellite when ``pseudorange_correlated_std_m`` > 0, or else, with
``glonass_satellite_bias_std_m`` > 0, one random-constant code bias per GLONASS satellite (its FDMA
channel's inter-frequency bias and untransmitted equipment delay; removed after
``GLONASS_BIAS_MAX_GAP_S`` unseen). The CKF estimates the error state
(eq. 8), folded into the nominal after every update (eq. 25, :meth:`FilterState.correct`).
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from gnss_common.observations import GLONASS, GPS

from .ckf import CubatureKalmanFilter
from .divergence import GatedWindow
from .fusion_output import FusionOutput
from .fusion_params import (
    CORRELATED_ERROR_MAX_GAP_TAU,
    FRAME_EARTH,
    GLONASS_BIAS_MAX_GAP_S,
    INTER_SYSTEM_BIAS_INIT_STD_M,
    INTER_SYSTEM_BIAS_MAX_GAP_S,
    INTER_SYSTEM_BIAS_PSD_M2PS,
    MODE_GNSS,
    MODE_UWB,
    FusionParams,
)
from .gnss_update import clock_offset_from_residuals
from .input_checks import Count, PreparedEpoch
from .measurement_models import STATE_DIM, constant_velocity_transition, white_acceleration_noise
from .mirror_test import MirrorTest
from .motion_model import StationarityDetector

_NS = 1_000_000_000

RecentRange = tuple[int, np.ndarray, float, str]
"""The latest range of an anchor: (stamp ns, anchor position m (3,), range m, frame)."""


@dataclass(eq=False)
class FilterState:
    """What the filter carries from message to message (module docstring); built by :meth:`create`.

    Attributes are grouped by the rule that owns them; every one of them is part of a snapshot.
    """

    # ---- estimator (eq. 8): nominal state, error covariance, time, frame, augmented states
    nominal: np.ndarray
    ckf: CubatureKalmanFilter
    mirror: MirrorTest
    motion: StationarityDetector
    uwb_gated: GatedWindow
    initialized: bool = False
    clock_initialized: bool = False
    frame: str = FRAME_EARTH
    t_ns: int = 0
    ref_system: int = GPS  # the system whose time c*dt is in
    bias_systems: list[int] = field(default_factory=list)  # system of state column STATE_DIM + i
    bias_seen_ns: dict[int, int] = field(default_factory=dict)
    err_sats: list[int] = field(default_factory=list)  # satellite key of correlated-error column err_base() + i
    err_seen_ns: dict[int, int] = field(default_factory=dict)
    err_model: list[tuple[float, float]] = field(default_factory=list)  # (std m, tau s; inf: constant) per column
    transition_cache: dict[tuple[int, bool, int, tuple[tuple[float, float], ...], bool],
                           tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    # ---- inputs remembered: jammer J/S, the caller's reference solution, recent ranges and epochs
    js_db: float = math.nan
    js_stamp_ns: int | None = None
    reference: tuple[int, np.ndarray, float, float] | None = None
    recent_uwb: dict[str, RecentRange] = field(default_factory=dict)
    last_gnss_stamp: int | None = None
    last_uwb_stamp: int | None = None
    last_prep: tuple[int, PreparedEpoch] | None = None
    # (stamp, keys constellation * 1000 + svid of the pseudoranges the last GNSS epoch applied): for display
    last_used_satellites: tuple[int, np.ndarray] | None = None
    uwb_scratch: np.ndarray = field(default_factory=lambda: np.zeros(6))  # the compiled UWB update's diagnostics
    # ---- start-up and divergence (.lifecycle)
    drift_memory_mps: float | None = None
    uwb_wait_since_ns: int | None = None
    bad_gnss_epochs: int = 0
    held_fix: tuple[int, np.ndarray, np.ndarray, np.ndarray | None] | None = None
    fix_attempt_ns: int | None = None
    anchor_gated_run: dict[str, int] = field(default_factory=dict)
    gated_restarted: set[str] = field(default_factory=set)  # anchors that restarted the filter
    shared_bias_stamps: dict[str, collections.deque[int]] = field(default_factory=dict)
    # ---- mirror of coplanar anchors (.mirror_handling)
    mirror_last_ns: int | None = None
    mirror_plane_key: tuple = (-1, "")
    mirror_valid_until_ns: int = -1
    mirror_plane: tuple | None = None  # (n n^T in 6x6, c . n, normal, anchors with their off-plane distance)
    anchor_version: int = 0  # counts changes of the set of anchors heard: new, back after silence, moved
    side_last_ns: int | None = None  # last side-prior check without GNSS
    # ---- motion model (.motion_model)
    moving_pv_var: np.ndarray = field(default_factory=lambda: np.zeros(6))

    @classmethod
    def create(cls, params: FusionParams) -> FilterState:
        """The state of a new filter: uninitialised, in the earth frame, at time 0."""
        # the mirror test assumes the filter's pseudorange error model: white (tau -> 0, every epoch
        # independent) unless the correlated errors are modelled
        mirror = MirrorTest(
            params.pseudorange_correlated_tau_s if params.pseudorange_correlated_std_m > 0.0 else 0.0,
            params.uwb_mirror_switch_log_lr,
        )
        state = cls(
            nominal=np.zeros(STATE_DIM),
            ckf=CubatureKalmanFilter(np.zeros(STATE_DIM), np.eye(STATE_DIM)),
            mirror=mirror,
            motion=StationarityDetector(params.static_enter_s),
            uwb_gated=GatedWindow(params.divergence_uwb_ranges),
        )
        state.reset(params)
        return state

    # ------------------------------------------------------------------ life cycle
    def reset(self, params: FusionParams) -> None:
        """Back to uninitialised (a time gap, a divergence nothing re-initialises); the clock drift is
        remembered, the filter time is kept."""
        self.remember_drift()
        self.initialized = False
        self.clock_initialized = False
        self.frame = FRAME_EARTH
        self.t_ns = 0
        self.nominal = np.zeros(STATE_DIM)
        self.ckf = CubatureKalmanFilter(np.zeros(STATE_DIM), np.eye(STATE_DIM))
        self.reset_systems(GPS)
        self.bad_gnss_epochs = 0
        self.held_fix = None
        self.fix_attempt_ns = None
        self.uwb_gated = GatedWindow(params.divergence_uwb_ranges)
        self.anchor_gated_run = {}
        self.shared_bias_stamps = {}
        self.reset_mirror()
        self.motion.reset()

    def reset_mirror(self, key: object = None) -> None:
        """Forget the mirror test's evidence (new anchor set ``key``, re-initialisation)."""
        self.mirror.reset(key)
        self.mirror_last_ns = None

    def reset_systems(self, reference: int) -> None:
        """No inter-system bias states; ``reference`` is the system whose time ``c*dt`` is in."""
        self.ref_system = int(reference)
        self.bias_systems = []
        self.bias_seen_ns = {}
        self.err_sats = []
        self.err_seen_ns = {}
        self.err_model = []

    def remember_drift(self) -> None:
        """Keep the clock drift of a state about to be replaced (reinitialisation, reset)."""
        if self.initialized and self.clock_initialized and self.frame == FRAME_EARTH:
            drift = float(self.nominal[7])
            if math.isfinite(drift):
                self.drift_memory_mps = drift

    def err_base(self) -> int:
        """First state column of the correlated pseudorange errors (after the inter-system biases)."""
        return STATE_DIM + len(self.bias_systems)

    def mode(self) -> int:
        """MODE_GNSS / MODE_UWB bits: a measurement of that kind was used within 1 s of the filter time."""
        t = self.t_ns
        g = self.last_gnss_stamp is not None and t - self.last_gnss_stamp <= _NS
        u = self.last_uwb_stamp is not None and t - self.last_uwb_stamp <= _NS
        return (MODE_GNSS if g else 0) | (MODE_UWB if u else 0)

    # ------------------------------------------------------------------ time update
    def predict_to(self, stamp_ns: int, params: FusionParams, clock_q: Callable[[float], np.ndarray]) -> None:
        """Predict the nominal state and the error covariance to ``stamp_ns`` (nothing if not later).

        Notes:
            Cao et al., eq. 8-10 (constant velocity, clock bias and drift: :mod:`.measurement_models`)
            and eq. 15-16 (time update, compiled, in place); the error mean is zero after every
            correction. The process noise of the static model (``static_accel_psd_m2ps3``) while the
            motion model finds the receiver still (:mod:`.motion_model`).
        """
        dt_ns = stamp_ns - self.t_ns
        if dt_ns <= 0:
            return
        nb = len(self.bias_systems)
        ne = len(self.err_sats)
        static = self.motion.static
        key = (dt_ns, self.frame == FRAME_EARTH, nb, tuple(self.err_model), static)
        cached = self.transition_cache.get(key)
        if cached is None:
            dt = dt_ns / _NS
            phi = constant_velocity_transition(dt, nb)
            if ne:
                phi = np.pad(phi, ((0, ne), (0, ne)))
                idx = np.arange(STATE_DIM + nb, STATE_DIM + nb + ne)
                # Gauss-Markov decay exp(-dt/tau) (Brown & Hwang, 4th ed., eq. 4.2.11); 1 for a constant
                phi[idx, idx] = [math.exp(-dt / tau) for _, tau in self.err_model]
            q = np.zeros((STATE_DIM + nb + ne, STATE_DIM + nb + ne))
            psd = params.static_accel_psd_m2ps3 if static else params.accel_psd_m2ps3
            q[0:6, 0:6] = white_acceleration_noise(psd, dt)
            if key[1]:
                q[6:8, 6:8] = clock_q(dt)
                # inter-system biases: random walks
                isb = slice(STATE_DIM, STATE_DIM + nb)
                q[isb, isb] = np.eye(nb) * (INTER_SYSTEM_BIAS_PSD_M2PS * dt)
                if ne:
                    # Gauss-Markov: x_k+1 = exp(-dt/tau) x_k + w, var(w) = sigma^2 (1 - exp(-2 dt/tau))
                    # (Brown & Hwang, 4th ed., eq. 4.2.11-4.2.12); a random constant (tau inf): 0
                    idx = np.arange(STATE_DIM + nb, STATE_DIM + nb + ne)
                    q[idx, idx] = [std**2 * (1.0 - math.exp(-2.0 * dt / tau)) for std, tau in self.err_model]
            cached = (phi, q)
            if len(self.transition_cache) >= 64:  # the few distinct steps of a stream recur
                self.transition_cache.clear()
            self.transition_cache[key] = cached
        phi, q = cached
        self.ckf.predict_with_nominal(self.nominal, phi, q)
        self.t_ns = stamp_ns

    def correct(self) -> None:
        """Status correction, Cao et al. eq. 25, and error-state reset."""
        self.nominal = self.nominal + self.ckf.reset_error_state()

    # ------------------------------------------------------------------ several GNSS
    def bias_columns(self, prep: PreparedEpoch) -> np.ndarray | None:
        """State column of each satellite's inter-system bias (-1: the reference system), or None
        when every satellite is of the reference system (the single-clock model exactly)."""
        system = prep.system
        ref = self.ref_system
        if system is None:  # all GPS
            if ref == GPS:
                return None
            system = np.full(prep.pr.size, GPS, dtype=np.int64)
        if not self.bias_systems:
            return None if (system == ref).all() else np.full(system.size, -1, dtype=np.int64)
        cols = np.full(system.size, -1, dtype=np.int64)
        for i, sysc in enumerate(self.bias_systems):
            cols[system == sysc] = STATE_DIM + i
        return None if (cols < 0).all() and (system == ref).all() else cols

    def update_bias_states(self, stamp_ns: int, prep: PreparedEpoch, count: Count) -> np.ndarray | None:
        """Add a bias state for each system seen for the first time, re-initialise those of
        systems back after more than ``INTER_SYSTEM_BIAS_MAX_GAP_S``; return the bias columns.

        A new (or returning) system's bias is the median residual of its pseudoranges at the
        predicted state with the reference clock (:func:`.gnss_update.clock_offset_from_residuals`),
        with variance ``INTER_SYSTEM_BIAS_INIT_STD_M^2`` and no correlation: its satellites then
        fix their bias first and the position only through their differences, so that a system
        appearing cannot move the position by its bias.
        """
        system = prep.system
        ref = self.ref_system
        if self.frame != FRAME_EARTH or (system is None and ref == GPS):
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
            if sysc not in self.bias_systems:
                value = clock_offset_from_residuals(prep, self.nominal, None, rows)
                n = self.nominal.size
                at = self.err_base()  # before the correlated-error columns (if any)
                cov = np.insert(np.insert(self.ckf.p, at, 0.0, axis=0), at, 0.0, axis=1)
                cov[at, at] = var0
                self.nominal = np.insert(self.nominal, at, value)
                self.ckf = CubatureKalmanFilter(np.zeros(n + 1), cov)
                self.bias_systems.append(int(sysc))
                count("inter_system_bias_added", 1)
            elif stamp_ns - self.bias_seen_ns[sysc] > INTER_SYSTEM_BIAS_MAX_GAP_S * _NS:
                col = STATE_DIM + self.bias_systems.index(sysc)
                self.nominal[col] = clock_offset_from_residuals(prep, self.nominal, None, rows)
                self.ckf.reset_block(slice(col, col + 1), np.array([var0]))
                count("inter_system_bias_reset", 1)
            self.bias_seen_ns[int(sysc)] = stamp_ns
        return self.bias_columns(prep)

    def clock_from_residuals(self, prep: PreparedEpoch) -> float:
        """The receiver clock from the pseudorange residuals (position trusted): over the
        reference system's satellites, and those of systems with a bias state; when the epoch has
        none of them, the largest system present becomes the reference."""
        system = prep.system
        if system is None:
            if self.ref_system == GPS:
                return clock_offset_from_residuals(prep, self.nominal)
            system = np.full(prep.pr.size, GPS, dtype=np.int64)
        known = (system == self.ref_system) | np.isin(system, self.bias_systems)
        if not known.any():
            values, counts = np.unique(system, return_counts=True)
            self.ref_system = int(values[np.argmax(counts)])
            known = system == self.ref_system
        return clock_offset_from_residuals(prep, self.nominal, self.bias_columns(prep), known)

    # ------------------------------------------------------------------ correlated errors
    def error_columns(self, prep: PreparedEpoch) -> np.ndarray | None:
        """State column of each satellite's correlated pseudorange error (-1: the satellite has none),
        or None when no satellite of the epoch has one."""
        if not self.err_sats or prep.sat_id is None:
            return None
        base = self.err_base()
        index = {sat: base + i for i, sat in enumerate(self.err_sats)}
        cols = np.array([index.get(s, -1) for s in prep.sat_id.tolist()], dtype=np.int64)
        return cols if (cols >= 0).any() else None

    def update_error_states(self, stamp_ns: int, prep: PreparedEpoch, params: FusionParams,
                            count: Count) -> np.ndarray | None:
        """Free the correlated-error states of satellites unseen for more than
        ``CORRELATED_ERROR_MAX_GAP_TAU`` correlation times (a GLONASS code bias: ``GLONASS_BIAS_MAX_GAP_S``),
        allocate one for each satellite of the epoch without one that should have one; return the error
        columns of the epoch's satellites (:meth:`error_columns`).

        Which satellites: every one when ``pseudorange_correlated_std_m`` > 0 (a Gauss-Markov state;
        a GLONASS satellite's stationary sigma also holds ``glonass_satellite_bias_std_m``, root-sum-
        squared); otherwise the GLONASS satellites when ``glonass_satellite_bias_std_m`` > 0 (a random
        constant with that prior sigma). Removing a state (its row and column of P) is the exact
        marginalisation of a Gaussian; a new state starts at zero with its prior variance and no
        correlation (the error of a satellite just acquired is unknown). Counted:
        ``correlated_error_added``, ``correlated_error_removed``.
        """
        p = params
        gm = p.pseudorange_correlated_std_m > 0.0
        glo = p.glonass_satellite_bias_std_m > 0.0
        if not (gm or glo) or self.frame != FRAME_EARTH or prep.sat_id is None:
            return None
        base = self.err_base()
        stale = [i for i, sat in enumerate(self.err_sats) if stamp_ns - self.err_seen_ns[sat] > _max_gap_ns(
            self.err_model[i][1])]
        if stale:
            keep = np.ones(self.nominal.size, dtype=bool)
            keep[[base + i for i in stale]] = False
            for i in reversed(stale):
                del self.err_seen_ns[self.err_sats.pop(i)]
                self.err_model.pop(i)
            self.nominal = self.nominal[keep]
            self.ckf = CubatureKalmanFilter(np.zeros(self.nominal.size), self.ckf.p[np.ix_(keep, keep)])
            count("correlated_error_removed", len(stale))
        known = set(self.err_sats)
        new = [sat for sat in prep.sat_id.tolist() if sat not in known and (gm or sat // 1000 == GLONASS)]
        if new:
            models = [_error_model(sat, p) for sat in new]
            n = self.nominal.size
            k = len(new)
            cov = np.zeros((n + k, n + k))
            cov[:n, :n] = self.ckf.p
            idx = np.arange(n, n + k)
            cov[idx, idx] = [std**2 for std, _ in models]
            self.nominal = np.concatenate([self.nominal, np.zeros(k)])
            self.ckf = CubatureKalmanFilter(np.zeros(n + k), cov)
            self.err_sats.extend(new)
            self.err_model.extend(models)
            count("correlated_error_added", k)
        for sat in prep.sat_id.tolist():
            if sat in self.err_seen_ns or sat in new:
                self.err_seen_ns[sat] = stamp_ns
        return self.error_columns(prep)


def check_stamp_type(stamp_ns: object) -> int:
    """``stamp_ns`` as an int; TypeError unless it is an integer number of ns (a bool is not)."""
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)):
        raise TypeError(f"stamp_ns must be an integer number of ns, got {type(stamp_ns).__name__}")
    return int(stamp_ns)


class FilterFacade(Protocol):
    """What the modules of one message and of the filter's life (:mod:`.gnss_epoch`, :mod:`.uwb_update`,
    :mod:`.lifecycle`, :mod:`.mirror_handling`) use of :class:`.fusion_filter.FusionFilter`, which
    implements it: they take the filter as this protocol and never import the facade (which imports them)."""

    params: FusionParams
    state: FilterState
    reference_provider: Callable[[int], tuple[int, np.ndarray, float, float] | None] | None
    gate: float
    gate_3d: float
    lever: np.ndarray
    lever_floats: tuple[float, ...]
    anchor_registry: Mapping[str, np.ndarray]
    clock_q: Callable[[float], np.ndarray]
    uwb_noise: dict[str, Any]
    reinits: int

    def count(self, reason: str, n: int = 1) -> None: ...

    def output(self, diverged: bool, sat_used: int = 0, sat_rej: int = 0, uwb_used: int = 0, uwb_rej: int = 0,
               nis: float = math.nan) -> FusionOutput: ...

    def admit_stamp(self, stamp_ns: int) -> bool: ...

    def current_js_db(self, stamp_ns: int) -> float: ...

    def initialize(self, stamp_ns: int, position_m: np.ndarray, *, frame_id: str = FRAME_EARTH,
                   velocity_mps: np.ndarray | None = None, clock_bias_m: float = math.nan,
                   clock_drift_mps: float = math.nan, position_std_m: float | None = None,
                   position_clock_covariance_m2: np.ndarray | None = None) -> FusionOutput: ...

    def supply_reference_solution(self, stamp_ns: int, position_m: np.ndarray, position_std_m: float,
                                  clock_bias_m: float = math.nan) -> None: ...


def _error_model(sat: int, p: FusionParams) -> tuple[float, float]:
    """(prior / stationary 1-sigma m, correlation time s; inf: a random constant) of a satellite's error state."""
    glo = p.glonass_satellite_bias_std_m if sat // 1000 == GLONASS else 0.0
    if p.pseudorange_correlated_std_m > 0.0:
        return math.hypot(p.pseudorange_correlated_std_m, glo), p.pseudorange_correlated_tau_s
    return glo, math.inf


def _max_gap_ns(tau_s: float) -> float:
    """How long an error state survives its satellite unseen, ns."""
    return (GLONASS_BIAS_MAX_GAP_S if math.isinf(tau_s) else CORRELATED_ERROR_MAX_GAP_TAU * tau_s) * _NS

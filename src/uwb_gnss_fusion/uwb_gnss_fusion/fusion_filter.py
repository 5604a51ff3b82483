"""Tightly-coupled GNSS/UWB error-state cubature Kalman filter, robust to jamming (Cao et al.).

Pure core (no ROS). The node converts messages to the ``gnss_common.observations`` dataclasses
and calls :meth:`FusionFilter.process_gnss`, :meth:`FusionFilter.process_uwb`,
:meth:`FusionFilter.set_jammer_to_signal` and (optionally) :meth:`FusionFilter.supply_reference_solution`;
each processing call returns a frozen :class:`FusionOutput`. Time is passed in as integer
nanoseconds (``stamp_ns``) and never read from a clock, so replays are bit-identical.

State: nominal ``[p (3), v (3), c*dt, c*ddt]`` in m, m/s, m, m/s (ECEF, frame "earth"; or the
anchors' local frame "map" in UWB-only mode, where the clock states are frozen and unused) and an
8-state error vector (Cao et al., eq. 8) estimated by the CKF and folded into the nominal after
every update (eq. 25).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy.stats import chi2

from gnss_common.clock_model import ClockHCoefficients
from gnss_common.clock_model import clock_process_noise_m as _clock_q
from gnss_common.coordinates import (
    azimuth_elevation,
    ecef_to_geodetic_scalar,
    rotate_covariance_ecef_to_enu_scalar,
)
from gnss_common.jamming_weights import TrackingLoopParams, measurement_sigmas
from gnss_common.observations import GPS, GnssEpoch, SatelliteObservation, UwbRangeMeasurement

from .ckf import CholeskyError, CubatureKalmanFilter
from .measurement_models import (
    STATE_DIM,
    constant_velocity_transition,
    pseudorange_model,
    pseudorange_rate_model,
    stack_models,
    uwb_range_model,
    white_acceleration_noise,
)
from .robust_screen import common_mode_screen, projected_variance
from .uwb_update import STATUS_APPLIED, STATUS_CHOLESKY_FAILED, predict_inplace, range_update_inplace

MODE_NONE = 0
MODE_GNSS = 1
MODE_UWB = 2
MODE_GNSS_UWB = 3
"""Mode codes, identical to rfi_msgs/FusionStatus.msg."""

FRAME_EARTH = "earth"
FRAME_MAP = "map"

_NS = 1_000_000_000
_MIN_SIN_ELEVATION = math.sin(math.radians(5.0))
"""Floor of sin(elevation) in the elevation weighting of satellites without C/N0 (caps the factor at 11.5)."""


@dataclass(frozen=True)
class FusionParams:
    """Parameters of :class:`FusionFilter` (validated on construction).

    Attributes:
        use_gnss: apply GNSS pseudoranges (False: UWB-only filter).
        use_doppler: apply pseudorange rates as well as pseudoranges.
        use_uwb: apply UWB ranges (False: the GNSS-only baseline filter).
        accel_psd_m2ps3: white-acceleration PSD per axis, m^2/s^3 (constant-velocity model).
        clock_h0_s: receiver clock h_0, s (default: compensated crystal of Brown & Hwang, as
            ``gnss_common.clock_model.COMPENSATED_CRYSTAL_BROWN_HWANG``).
        clock_h_minus2_hz: receiver clock h_-2, 1/s. The clock-state process noise is
            ``gnss_common.clock_model.clock_process_noise_m`` (Brown & Hwang two-state model).
        uwb_range_std_m: UWB range 1-sigma used when a message gives NaN, m.
        uwb_lever_arm_m: UWB tag minus GNSS antenna, in the state frame, m.
        uwb_max_range_m: longest physical UWB range, m.
        anchors: optional registry ``((anchor_id, x, y, z), ...)`` in the anchors' frame, m. If
            non-empty, ranges from other anchor ids are rejected ("unknown_anchor") and the
            registered position is used.
        gate_probability: per-measurement innovation gate, probability of the 1-dof chi-square
            (1.0 disables gating).
        elevation_mask_deg: satellites below are rejected, deg.
        min_cn0_dbhz: pseudoranges with a lower reported C/N0 are rejected, dB-Hz.
        nominal_cn0_dbhz: jammer-free C/N0 fed to eq. 4 when a J/S is known, dB-Hz.
        jammer_quality_factor: Q of eq. 4 (1: narrowband/swept jammer, Kaplan & Hegarty).
        jammer_info_timeout_s: a J/S older than this is ignored, s.
        loop: tracking-loop parameters for the jitter-based weights.
        min_satellites_init: satellites needed to initialise from GNSS alone.
        init_position_std_m / init_velocity_std_mps / init_clock_bias_std_m /
        init_clock_drift_std_mps: initial 1-sigmas when the solver gives none.
        init_clock_drift_unobserved_std_mps: clock-drift 1-sigma at an initialisation where the
            drift is unobserved (no Doppler in the fix) and no earlier drift estimate exists, m/s
            (1000 m/s covers a crystal's +-3 ppm; GEONET receivers drift by +418 and -330 m/s). On a
            reinitialisation the drift of the lost state is kept (the oscillator did not change).
        max_prediction_s: a stamp further than this after the filter time resets the filter, s.
        max_position_std_m: a larger position 1-sigma (per axis) is declared divergence, m.
        divergence_gnss_epochs: consecutive GNSS epochs with at least half of >= 4 pseudoranges
            gated out that declare divergence.
        divergence_uwb_ranges: length of the window of recent UWB ranges (all anchors) examined
            for divergence.
        divergence_uwb_gated_fraction: divergence is declared when at least this fraction of the
            last ``divergence_uwb_ranges`` ranges was gated out, in (0, 1] (1: that many
            consecutive gated ranges, the original rule).
        reference_max_age_s: a caller-supplied reference (SPP) older than this is not used, s.
        uwb_init_window_s: ranges used for UWB multilateration must lie within this window, s.
        uwb_latency_s: age of a UWB range at its stamp, s (>= 0; 0: the paper's model). The range
            is modelled as the distance at ``stamp - uwb_latency_s`` (constant-velocity
            back-propagation). Beyond the paper; set it from the ranging hardware / time-base
            calibration, not per data set.
        max_update_iterations: Gauss-Newton (iterated) refinement steps allowed after a cubature
            update whose linearisation error is significant (0: the plain CKF update of Cao et al.
            eq. 17-24). Beyond the paper; see :meth:`.ckf.CubatureKalmanFilter.update`.
        nonlinearity_threshold: refine when the cubature linearisation-error variance exceeds this
            fraction of the measurement noise variance (> 0).
        uwb_huber_k: Huber threshold on the normalised UWB innovation (inf: off). Beyond the paper.
        uwb_huber_k_positive: Huber threshold for positive UWB innovations (measured range longer
            than predicted, the non-line-of-sight direction); inf: positive innovations are not
            down-weighted.
        common_mode_screen: before the CKF update, drop pseudoranges and pseudorange rates whose
            innovation departs from the epoch's median (common clock) innovation by more than the
            gate allows with the clock-free variance (:mod:`.robust_screen`; beyond the paper).
            Counted as ``common_mode_pseudorange`` / ``common_mode_doppler``; they count as gated
            for the divergence rule.
    """

    use_gnss: bool = True
    use_doppler: bool = True
    use_uwb: bool = True
    accel_psd_m2ps3: float = 0.1
    clock_h0_s: float = 2.0e-19
    clock_h_minus2_hz: float = 2.0e-20
    uwb_range_std_m: float = 0.1
    uwb_lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    uwb_max_range_m: float = 500.0
    anchors: tuple[tuple[str, float, float, float], ...] = ()
    gate_probability: float = 0.9999
    elevation_mask_deg: float = 10.0
    min_cn0_dbhz: float = 20.0
    nominal_cn0_dbhz: float = 45.0
    jammer_quality_factor: float = 1.0
    jammer_info_timeout_s: float = 2.0
    loop: TrackingLoopParams = field(default_factory=TrackingLoopParams)
    min_satellites_init: int = 5
    init_position_std_m: float = 10.0
    init_velocity_std_mps: float = 1.0
    init_clock_bias_std_m: float = 10.0
    init_clock_drift_std_mps: float = 1.0
    init_clock_drift_unobserved_std_mps: float = 1000.0
    max_prediction_s: float = 120.0
    max_position_std_m: float = 200.0
    divergence_gnss_epochs: int = 5
    divergence_uwb_ranges: int = 40
    reference_max_age_s: float = 5.0
    uwb_init_window_s: float = 1.0
    uwb_latency_s: float = 0.0
    divergence_uwb_gated_fraction: float = 0.5
    max_update_iterations: int = 5
    nonlinearity_threshold: float = 0.05
    uwb_huber_k: float = math.inf
    uwb_huber_k_positive: float = math.inf
    common_mode_screen: bool = True

    def __post_init__(self) -> None:
        pos = {
            "accel_psd_m2ps3": self.accel_psd_m2ps3,
            "clock_h0_s": self.clock_h0_s,
            "uwb_range_std_m": self.uwb_range_std_m,
            "uwb_max_range_m": self.uwb_max_range_m,
            "jammer_quality_factor": self.jammer_quality_factor,
            "jammer_info_timeout_s": self.jammer_info_timeout_s,
            "init_position_std_m": self.init_position_std_m,
            "init_velocity_std_mps": self.init_velocity_std_mps,
            "init_clock_bias_std_m": self.init_clock_bias_std_m,
            "init_clock_drift_std_mps": self.init_clock_drift_std_mps,
            "init_clock_drift_unobserved_std_mps": self.init_clock_drift_unobserved_std_mps,
            "max_prediction_s": self.max_prediction_s,
            "max_position_std_m": self.max_position_std_m,
            "reference_max_age_s": self.reference_max_age_s,
            "uwb_init_window_s": self.uwb_init_window_s,
            "nonlinearity_threshold": self.nonlinearity_threshold,
            # inf switches the Huber weighting off; anything else must be finite and > 0
            "uwb_huber_k": 1.0 if self.uwb_huber_k == math.inf else self.uwb_huber_k,
            "uwb_huber_k_positive": 1.0 if self.uwb_huber_k_positive == math.inf else self.uwb_huber_k_positive,
        }
        for name, value in pos.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"FusionParams.{name} must be a finite number > 0, got {value!r}")
        if not (math.isfinite(self.clock_h_minus2_hz) and self.clock_h_minus2_hz >= 0.0):
            raise ValueError(f"FusionParams.clock_h_minus2_hz must be >= 0, got {self.clock_h_minus2_hz!r}")
        if not (0.0 < self.gate_probability <= 1.0):
            raise ValueError(
                f"FusionParams.gate_probability must be in (0, 1], got {self.gate_probability!r}"
            )
        if not (-90.0 <= self.elevation_mask_deg < 90.0):
            raise ValueError(
                f"FusionParams.elevation_mask_deg must be in [-90, 90), got {self.elevation_mask_deg!r}"
            )
        for name in ("min_cn0_dbhz", "nominal_cn0_dbhz"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"FusionParams.{name} must be finite")
        if len(self.uwb_lever_arm_m) != 3 or not all(math.isfinite(v) for v in self.uwb_lever_arm_m):
            raise ValueError("FusionParams.uwb_lever_arm_m must be three finite numbers")
        if not (isinstance(self.uwb_latency_s, (int, float)) and 0.0 <= self.uwb_latency_s <= 1.0):
            raise ValueError(f"FusionParams.uwb_latency_s must be in [0, 1] s, got {self.uwb_latency_s!r}")
        if not (isinstance(self.max_update_iterations, int) and 0 <= self.max_update_iterations <= 50):
            raise ValueError(
                f"FusionParams.max_update_iterations must be an int in [0, 50], got {self.max_update_iterations!r}"
            )
        if not (0.0 < self.divergence_uwb_gated_fraction <= 1.0):
            raise ValueError(
                "FusionParams.divergence_uwb_gated_fraction must be in (0, 1], "
                f"got {self.divergence_uwb_gated_fraction!r}"
            )
        if self.min_satellites_init < 4:
            raise ValueError(f"FusionParams.min_satellites_init must be >= 4, got {self.min_satellites_init}")
        if self.divergence_gnss_epochs < 1 or self.divergence_uwb_ranges < 1:
            raise ValueError("FusionParams.divergence_gnss_epochs and divergence_uwb_ranges must be >= 1")
        if not (self.use_gnss or self.use_uwb):
            raise ValueError("FusionParams: at least one of use_gnss, use_uwb must be True")
        ids = [a[0] for a in self.anchors]
        if len(set(ids)) != len(ids):
            raise ValueError("FusionParams.anchors has duplicate anchor ids")
        for a in self.anchors:
            if len(a) != 4 or not all(math.isfinite(float(v)) for v in a[1:]):
                raise ValueError(
                    f"FusionParams.anchors entry {a!r} must be (id, x, y, z) with finite x, y, z"
                )

    @cached_property
    def clock(self) -> ClockHCoefficients:
        """Receiver clock h-coefficients for the process noise."""
        return ClockHCoefficients(h0=self.clock_h0_s, h_minus2=self.clock_h_minus2_hz, name="fusion receiver")

    @cached_property
    def gate_nis(self) -> float:
        """Per-measurement NIS threshold (inf when gating is disabled)."""
        return math.inf if self.gate_probability >= 1.0 else float(chi2.ppf(self.gate_probability, 1))


@dataclass(frozen=True)
class FusionOutput:
    """Everything the node maps onto nav_msgs/Odometry, sensor_msgs/NavSatFix and FusionStatus.

    Attributes:
        stamp_ns: filter time of this output, ns.
        frame_id: "earth" (ECEF) or "map" (anchors' local frame, UWB-only mode).
        initialized: False until the state exists; then position/velocity are NaN and invalid.
        diverged: divergence was declared at this call (the filter reinitialised or reset).
        mode: MODE_* of the recent updates (GNSS and/or UWB applied within the last second).
        position_m: position in frame_id, m, shape (3,).
        velocity_mps: velocity in frame_id, m/s, shape (3,).
        covariance_pv: covariance of [position, velocity], shape (6, 6), m^2, m^2/s, m^2/s^2
            (row-major order x, y, z, vx, vy, vz in frame_id).
        clock_bias_m: receiver c*dt, m (NaN in "map" mode or before the first GNSS epoch).
        clock_drift_mps: receiver c*ddt, m/s (NaN likewise).
        satellites_used / satellites_rejected / uwb_used / uwb_rejected: counts of this call.
        normalized_innovation_squared: NIS per applied measurement of this call (NaN if none).
        jammer_to_signal_db: J/S used for weighting, dB (NaN: none).
        rejection_counts: cumulative ``((reason, count), ...)`` sorted by reason.
        reinitializations: times the filter reinitialised since start.
    """

    stamp_ns: int
    frame_id: str
    initialized: bool
    diverged: bool
    mode: int
    position_m: np.ndarray
    velocity_mps: np.ndarray
    covariance_pv: np.ndarray
    clock_bias_m: float
    clock_drift_mps: float
    satellites_used: int
    satellites_rejected: int
    uwb_used: int
    uwb_rejected: int
    normalized_innovation_squared: float
    jammer_to_signal_db: float
    rejection_counts: tuple[tuple[str, int], ...]
    reinitializations: int

    @cached_property
    def _geodetic_rad(self) -> tuple[float, float, float]:
        """(lat_rad, lon_rad, height_m) of the ECEF estimate, computed once per output (scalar path)."""
        x, y, z = self.position_m.tolist()
        return ecef_to_geodetic_scalar(x, y, z)

    @cached_property
    def geodetic(self) -> tuple[float, float, float]:
        """(latitude_deg, longitude_deg, ellipsoidal altitude_m); NaN unless an ECEF estimate."""
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return (math.nan, math.nan, math.nan)
        lat, lon, h = self._geodetic_rad
        return (math.degrees(lat), math.degrees(lon), h)

    @cached_property
    def position_covariance_enu_m2(self) -> np.ndarray:
        """Position covariance in local ENU at the estimate, m^2, shape (3, 3) (NavSatFix order E, N, U).

        In "map" mode the map axes are taken as ENU and the covariance is returned unrotated.
        """
        cov = self.covariance_pv[:3, :3]
        if not self.initialized or self.frame_id != FRAME_EARTH:
            return cov.copy()
        lat, lon, _ = self._geodetic_rad
        return rotate_covariance_ecef_to_enu_scalar(cov, lat, lon)


@dataclass
class _Prepared:
    """Validated satellites of one epoch (internal)."""

    sat_pos: np.ndarray
    sat_vel: np.ndarray
    sat_clk: np.ndarray
    sat_drift: np.ndarray
    iono: np.ndarray
    tropo: np.ndarray
    pr: np.ndarray
    rate: np.ndarray
    sigma_pr: np.ndarray
    sigma_rate: np.ndarray


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
        ``uwb_init_window_s``) because three anchors have two mirror solutions.

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
        self._transition_cache: dict[tuple[int, bool], tuple[np.ndarray, np.ndarray]] = {}
        self._counts_tuple: tuple[tuple[str, int], ...] | None = None
        clock = self.params.clock
        self._clock_q = lambda dt_s: _clock_q(clock, dt_s)
        self._lever = np.asarray(self.params.uwb_lever_arm_m, dtype=float)
        self._uwb_scratch = np.zeros(6)  # diagnostics of the compiled UWB update (.uwb_update)
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
        self._last_prep: tuple[int, _Prepared] | None = None
        self._initialized = False
        self._drift_memory_mps: float | None = None
        self._uwb_wait_since_ns: int | None = None
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
        self._bad_gnss_epochs = 0
        self._bad_uwb = 0
        self._uwb_gated: deque[int] = deque(maxlen=self.params.divergence_uwb_ranges)

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
    def time_ns(self) -> int:
        """Filter time, ns."""
        return self._t_ns

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
        self._ckf = CubatureKalmanFilter(np.zeros(STATE_DIM), np.diag(var))
        self._initialized = True
        self._clock_initialized = clock_ok
        self._bad_gnss_epochs = 0
        self._bad_uwb = 0
        self._uwb_gated = deque(maxlen=self.params.divergence_uwb_ranges)
        return self._output(False)

    def _initial_drift(self, clock_drift_mps: float) -> tuple[float, float]:
        """(drift m/s, 1-sigma m/s) for a (re)initialisation: the given value, else the drift of
        the previous state, else zero with the wide unobserved-drift sigma."""
        p = self.params
        if math.isfinite(clock_drift_mps):
            return float(clock_drift_mps), p.init_clock_drift_std_mps
        if self._drift_memory_mps is not None:
            return self._drift_memory_mps, p.init_clock_drift_std_mps
        return 0.0, p.init_clock_drift_unobserved_std_mps

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
        key = (dt_ns, self._frame == FRAME_EARTH)
        cached = self._transition_cache.get(key)
        if cached is None:
            dt = dt_ns / _NS
            phi = constant_velocity_transition(dt)
            q = np.zeros((STATE_DIM, STATE_DIM))
            q[0:6, 0:6] = white_acceleration_noise(self.params.accel_psd_m2ps3, dt)
            if key[1]:
                q[6:8, 6:8] = self._clock_q(dt)
            cached = (phi, q)
            if len(self._transition_cache) >= 64:  # the few distinct steps of a stream recur
                self._transition_cache.clear()
            self._transition_cache[key] = cached
        phi, q = cached
        # Nominal propagation (positioning status prediction) and error-covariance time update
        # (Cao et al., eq. 15-16), compiled and in place; the error mean is zero after every
        # correction.
        self._ckf.x[:] = 0.0
        predict_inplace(self._nominal, self._ckf.p, phi, q)
        self._t_ns = stamp_ns

    def _correct(self) -> None:
        """Status correction, Cao et al. eq. 25, and error-state reset."""
        self._nominal = self._nominal + self._ckf.x
        self._ckf.x = np.zeros(STATE_DIM)

    def _shifted(self, hx):
        nominal = self._nominal

        def h(points: np.ndarray) -> np.ndarray:
            return hx(points + nominal)

        return h

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
            cov = self._ckf.p[0:6, 0:6].copy()
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
        )

    # ------------------------------------------------------------------ GNSS
    def _prepare_epoch(self, epoch: GnssEpoch, receiver_m: np.ndarray | None) -> _Prepared | None:
        """Validate satellites; count rejections per reason; compute weights."""
        p = self.params
        obs: list[SatelliteObservation] = []
        seen: dict[int, int] = {}
        for o in epoch.observations:
            if not isinstance(o, SatelliteObservation):
                self._count("malformed_observation")
                continue
            if o.constellation != GPS:
                self._count("unsupported_constellation")
                continue
            seen[o.svid] = seen.get(o.svid, 0) + 1
            obs.append(o)
        dup = {s for s, n in seen.items() if n > 1}
        if dup:
            self._count("duplicate_svid", sum(seen[s] for s in dup))
            obs = [o for o in obs if o.svid not in dup]
        rows = self._validate_satellites_vectorised(obs)
        if rows is None:
            rows = self._validate_satellites_loop(obs)
        sin_el = None
        if rows and receiver_m is not None:
            _, el = azimuth_elevation(receiver_m, np.array([r[1] for r in rows]))
            el = np.atleast_1d(el)
            above = np.degrees(el) >= p.elevation_mask_deg
            self._count("below_elevation_mask", int(above.size - above.sum()))
            rows = [r for r, a in zip(rows, above, strict=True) if a]
            sin_el = np.sin(el[above])
        if not rows:
            return None
        n = len(rows)
        has_cn0 = np.array([math.isfinite(r[0].cn0_dbhz) for r in rows])
        cn0 = np.array([r[0].cn0_dbhz if ok else p.nominal_cn0_dbhz for r, ok in zip(rows, has_cn0, strict=True)])
        js = self._current_js_db(epoch.stamp_ns)
        s_pr, s_rate, _ = measurement_sigmas(cn0, math.nan, p.loop, p.jammer_quality_factor)
        if sin_el is not None and not has_cn0.all():
            # No C/N0 reported (e.g. RINEX without S1): the nominal C/N0 holds at zenith and the
            # sigma grows as 1/sin(el), the usual elevation weighting when the signal strength is
            # unknown (Euler & Goad 1991; RTKLIB's b/sin(el) term). Without it every satellite had
            # the same weight, and low satellites (larger troposphere/multipath error) pulled the
            # solution (docs/uwb_gnss_fusion/fusion_real_gnss.md).
            scale = np.where(has_cn0, 1.0, 1.0 / np.maximum(sin_el, _MIN_SIN_ELEVATION))
            s_pr = s_pr * scale
            s_rate = s_rate * scale
        if math.isfinite(js):
            # eq. 4 on the nominal jammer-free C/N0; the weaker of (reported, predicted) is used so
            # that a receiver that already reports the degraded C/N0 is not penalised twice.
            s_pr_j, s_rate_j, _ = measurement_sigmas(
                np.full(n, p.nominal_cn0_dbhz), js, p.loop, p.jammer_quality_factor
            )
            s_pr = np.maximum(s_pr, s_pr_j)
            s_rate = np.maximum(s_rate, s_rate_j)
        given_pr = np.array([r[0].pseudorange_std_m for r in rows])
        given_rate = np.array([r[0].pseudorange_rate_std_mps for r in rows])
        ok_pr = np.isfinite(given_pr) & (given_pr > 0.0)
        ok_rate = np.isfinite(given_rate) & (given_rate > 0.0)
        s_pr = np.where(ok_pr, np.maximum(given_pr, s_pr) if math.isfinite(js) else given_pr, s_pr)
        s_rate = np.where(
            ok_rate, np.maximum(given_rate, s_rate) if math.isfinite(js) else given_rate, s_rate
        )
        rate = np.array([r[0].pseudorange_rate_mps if r[3] else math.nan for r in rows])
        return _Prepared(
            sat_pos=np.array([r[1] for r in rows]),
            sat_vel=np.array([r[2] if r[3] else np.zeros(3) for r in rows]),
            sat_clk=np.array([r[0].satellite_clock_bias_m for r in rows]),
            sat_drift=np.array([r[0].satellite_clock_drift_mps if r[3] else 0.0 for r in rows]),
            iono=np.array([r[0].ionosphere_delay_m for r in rows]),
            tropo=np.array([r[0].troposphere_delay_m for r in rows]),
            pr=np.array([r[0].pseudorange_m for r in rows]),
            rate=rate,
            sigma_pr=s_pr,
            sigma_rate=s_rate,
        )

    def _validate_satellites_loop(
        self, obs: list[SatelliteObservation]
    ) -> list[tuple[SatelliteObservation, np.ndarray, np.ndarray, bool]]:
        """The per-satellite checks of :meth:`_prepare_epoch`, one observation at a time (the
        reference for :meth:`_validate_satellites_vectorised`, and the path for observations whose
        vectors are not 3-vectors, each counted as malformed)."""
        p = self.params
        rows: list[tuple[SatelliteObservation, np.ndarray, np.ndarray, bool]] = []
        for o in obs:
            try:
                sp = np.asarray(o.satellite_position_ecef_m, dtype=float).reshape(3)
                sv = np.asarray(o.satellite_velocity_ecef_mps, dtype=float).reshape(3)
            except (ValueError, TypeError):
                self._count("malformed_observation")
                continue
            scalars = (o.pseudorange_m, o.satellite_clock_bias_m, o.ionosphere_delay_m, o.troposphere_delay_m)
            if not (np.isfinite(sp).all() and all(math.isfinite(float(v)) for v in scalars)):
                self._count("nonfinite_pseudorange")
                continue
            radius = float(np.linalg.norm(sp))
            if not (1.0e7 < radius < 5.0e7):
                self._count("nonphysical_satellite_position")
                continue
            if (
                not (1.0e6 < o.pseudorange_m < 1.0e8)
                or o.ionosphere_delay_m < 0.0
                or o.troposphere_delay_m < 0.0
            ):
                self._count("nonphysical_pseudorange")
                continue
            if math.isfinite(o.cn0_dbhz) and o.cn0_dbhz < p.min_cn0_dbhz:
                self._count("low_cn0")
                continue
            rate_ok = (
                p.use_doppler
                and math.isfinite(o.pseudorange_rate_mps)
                and np.isfinite(sv).all()
                and math.isfinite(o.satellite_clock_drift_mps)
                and abs(o.pseudorange_rate_mps) < 2.0e4
            )
            if p.use_doppler and not rate_ok:
                self._count("invalid_doppler")
            rows.append((o, sp, sv, bool(rate_ok)))
        return rows

    def _validate_satellites_vectorised(
        self, obs: list[SatelliteObservation]
    ) -> list[tuple[SatelliteObservation, np.ndarray, np.ndarray, bool]] | None:
        """The per-satellite checks of :meth:`_prepare_epoch` on arrays (speed: ~10 us per satellite
        less than the per-observation loop); the same checks in the same order, each rejected
        satellite counted under its first failing reason. None when a position or velocity is not a
        3-vector or a scalar is not a number: the caller then runs the per-observation loop."""
        p = self.params
        n = len(obs)
        if n == 0:
            return []
        try:
            sp = np.array([o.satellite_position_ecef_m for o in obs], dtype=float)
            sv = np.array([o.satellite_velocity_ecef_mps for o in obs], dtype=float)
            sc = np.array(
                [
                    (o.pseudorange_m, o.satellite_clock_bias_m, o.ionosphere_delay_m, o.troposphere_delay_m,
                     o.cn0_dbhz, o.pseudorange_rate_mps, o.satellite_clock_drift_mps)
                    for o in obs
                ],
                dtype=float,
            )
        except (ValueError, TypeError):
            return None
        if sp.shape != (n, 3) or sv.shape != (n, 3):
            return None
        pr, clk, iono, tropo, cn0, rate, sdrift = sc.T
        finite = np.isfinite(sp).all(axis=1) & np.isfinite(pr) & np.isfinite(clk)
        finite &= np.isfinite(iono) & np.isfinite(tropo)
        with np.errstate(invalid="ignore"):
            radius = np.sqrt((sp * sp).sum(axis=1))
            pos_ok = finite & (radius > 1.0e7) & (radius < 5.0e7)
            pr_ok = pos_ok & (pr > 1.0e6) & (pr < 1.0e8) & (iono >= 0.0) & (tropo >= 0.0)
            keep = pr_ok & ~(np.isfinite(cn0) & (cn0 < p.min_cn0_dbhz))
            rate_ok = (
                np.isfinite(rate) & np.isfinite(sv).all(axis=1) & np.isfinite(sdrift) & (np.abs(rate) < 2.0e4)
                if p.use_doppler
                else np.zeros(n, dtype=bool)
            )
        for reason, count in (
            ("nonfinite_pseudorange", n - int(finite.sum())),
            ("nonphysical_satellite_position", int(finite.sum() - pos_ok.sum())),
            ("nonphysical_pseudorange", int(pos_ok.sum() - pr_ok.sum())),
            ("low_cn0", int(pr_ok.sum() - keep.sum())),
            ("invalid_doppler", int((keep & ~rate_ok).sum()) if p.use_doppler else 0),
        ):
            if count:
                self._count(reason, count)
        return [(obs[i], sp[i], sv[i], bool(rate_ok[i])) for i in np.flatnonzero(keep)]

    def _snapshot_fix(self, prep: _Prepared) -> tuple[np.ndarray, float, np.ndarray, float] | None:
        """Robust snapshot LS (position, clock; then velocity, drift) for initialisation.

        Gauss-Newton on eq. 5 from the Earth's centre, then iterative exclusion of the largest
        normalised residual while the weighted sum of squares fails a 0.999 chi-square test.
        """
        keep = np.ones(prep.pr.size, dtype=bool)
        while keep.sum() >= 4:
            idx = np.flatnonzero(keep)
            hx = pseudorange_model(prep.sat_pos[idx], prep.sat_clk[idx], prep.iono[idx], prep.tropo[idx])
            w = 1.0 / prep.sigma_pr[idx]
            x = np.zeros(STATE_DIM)
            for _ in range(10):
                pred = hx(x[None, :])[0]
                d = prep.sat_pos[idx] - x[0:3]
                e = d / np.linalg.norm(d, axis=1)[:, None]
                h = np.hstack([-e, np.ones((idx.size, 1))])
                dx, *_ = np.linalg.lstsq(h * w[:, None], (prep.pr[idx] - pred) * w, rcond=None)
                x[0:3] += dx[0:3]
                x[6] += dx[3]
                if np.linalg.norm(dx) < 1e-4:
                    break
            res = (prep.pr[idx] - hx(x[None, :])[0]) * w
            dof = idx.size - 4
            if not np.isfinite(res).all() or np.linalg.norm(x[0:3]) < 6.0e6:
                return None
            if dof == 0 or float(res @ res) <= chi2.ppf(0.999, dof):
                if dof == 0 and idx.size < self.params.min_satellites_init:
                    return None
                break
            if idx.size - 1 < self.params.min_satellites_init:
                return None
            keep[idx[int(np.argmax(np.abs(res)))]] = False
        else:
            return None
        vel = np.zeros(3)
        drift = math.nan  # unobserved without >= 4 Dopplers
        ridx = np.flatnonzero(keep & np.isfinite(prep.rate))
        if ridx.size >= 4:
            d = prep.sat_pos[ridx] - x[0:3]
            e = d / np.linalg.norm(d, axis=1)[:, None]
            h = np.hstack([-e, np.ones((ridx.size, 1))])
            y = prep.rate[ridx] - np.einsum("ij,ij->i", prep.sat_vel[ridx], e) + prep.sat_drift[ridx]
            sol, *_ = np.linalg.lstsq(h, y, rcond=None)
            vel, drift = sol[0:3], float(sol[3])
        return x[0:3].copy(), float(x[6]), vel, drift

    def process_gnss(self, epoch: GnssEpoch) -> FusionOutput:
        """Predict to the epoch's stamp and apply its pseudoranges (and pseudorange rates).

        Args:
            epoch: one receive epoch; ``epoch.stamp_ns`` is the receive time in ns.

        Returns:
            :class:`FusionOutput` after the update (or the unchanged state if the epoch was
            rejected; the reason is counted in ``rejection_counts``).

        Notes:
            Cao et al., eq. 5, 6, 12 and 17-25, with per-measurement gating and the weights of
            :func:`.jamming_weights.measurement_sigmas`.
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
        n_obs = len(epoch.observations)
        if n_obs == 0:
            self._count("no_satellites")
            return self._output(False)
        receiver = (
            self._nominal[0:3] + self._nominal[3:6] * ((stamp - self._t_ns) / _NS)
            if self._initialized
            else None
        )
        prep = self._prepare_epoch(epoch, receiver)
        if prep is None:
            self._count("no_valid_satellites")
            return self._output(False, sat_rej=n_obs)
        n = prep.pr.size
        pre_rejected = n_obs - n
        if n < 4:
            self._count("fewer_than_4_satellites")
        self._last_prep = (stamp, prep)
        if not self._initialized:
            fix = self._snapshot_fix(prep) if n >= self.params.min_satellites_init else None
            if fix is None:
                self._count("gnss_init_failed")
                return self._output(False, sat_rej=n_obs)
            if not self._fix_agrees_with_uwb(stamp, fix[0], self.params.init_position_std_m):
                self._count("gnss_fix_inconsistent_with_uwb")
                return self._output(False, sat_rej=n_obs)
            pos, clk, vel, drift = fix
            self.initialize(stamp, pos, velocity_mps=vel, clock_bias_m=clk, clock_drift_mps=drift)
            self._last_gnss_stamp = stamp
            return self._output(False, sat_used=n, sat_rej=pre_rejected)
        self._predict_to(stamp)
        if not self._clock_initialized:
            # position known from UWB, clock not: set the clock from the pseudorange residuals.
            hx0 = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)
            res = prep.pr - hx0(self._nominal[None, :])[0]
            drift, drift_std = self._initial_drift(math.nan)
            self._nominal[6] = float(np.median(res))
            self._nominal[7] = drift
            self._ckf.p[6, :] = 0.0
            self._ckf.p[:, 6] = 0.0
            self._ckf.p[7, :] = 0.0
            self._ckf.p[:, 7] = 0.0
            self._ckf.p[6, 6] = self.params.init_clock_bias_std_m**2 + float(self._ckf.p[0:3, 0:3].trace())
            self._ckf.p[7, 7] = drift_std**2
            self._clock_initialized = True
        n_screened = 0
        if self.params.common_mode_screen:
            prep, n_screened = self._common_mode_screen(prep)
            if prep.pr.size == 0:
                self._count("no_valid_satellites")
                return self._output(False, sat_rej=n_obs)
            n = prep.pr.size
        models = [pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)]
        z = [prep.pr]
        var = [prep.sigma_pr**2]
        ridx = np.flatnonzero(np.isfinite(prep.rate))
        if ridx.size:
            models.append(
                pseudorange_rate_model(prep.sat_pos[ridx], prep.sat_vel[ridx], prep.sat_drift[ridx])
            )
            z.append(prep.rate[ridx])
            var.append(prep.sigma_rate[ridx] ** 2)
        try:
            res = self._ckf.update(
                np.concatenate(z),
                np.concatenate(var),
                self._shifted(stack_models(models)),
                self._gate,
                max_iterations=self.params.max_update_iterations,
                nonlinearity_threshold=self.params.nonlinearity_threshold,
            )
        except CholeskyError:
            self._count("numerical_failure")
            return self._declare_divergence(stamp)
        acc_pr = res.accepted[:n]
        acc_rate = res.accepted[n:]
        gated_pr = int(n - acc_pr.sum())
        self._count("innovation_gate_pseudorange", gated_pr)
        self._count("innovation_gate_doppler", int(acc_rate.size - acc_rate.sum()))
        self._correct()
        used = int(acc_pr.sum())
        if used or acc_rate.any():
            self._last_gnss_stamp = stamp
        n_applied = int(res.accepted.sum())
        nis = res.nis / n_applied if n_applied else math.nan
        # Divergence: most pseudoranges of a well-observed epoch inconsistent with the state, for
        # several epochs in a row (a single jammed epoch with outliers does not trip it).
        if n + n_screened >= 4 and (gated_pr + n_screened) * 2 >= n + n_screened:
            self._bad_gnss_epochs += 1
        else:
            self._bad_gnss_epochs = 0
        if self._bad_gnss_epochs >= self.params.divergence_gnss_epochs or self._position_lost():
            self._count("divergence")
            if not self._position_lost() and self._uwb_agrees(stamp):
                return self._reset_clock_keep_position(stamp, prep)
            return self._declare_divergence(stamp)
        return self._output(False, sat_used=used, sat_rej=pre_rejected + n_screened + gated_pr, nis=nis)

    def _common_mode_screen(self, prep: _Prepared) -> tuple[_Prepared, int]:
        """Drop the pseudoranges (and mark the rates) that fail the common-mode innovation screen.

        Returns:
            (the epoch without the dropped pseudoranges, how many were dropped).

        Notes:
            :mod:`.robust_screen`: innovations at the predicted state, the median removed, tested
            with ``R_i + e_i^T P e_i`` (position covariance for pseudoranges, velocity covariance
            for rates).
        """
        x = self._nominal[None, :]
        p = self._ckf.p
        d = prep.sat_pos - self._nominal[None, 0:3]
        los = d / np.linalg.norm(d, axis=1)[:, None]
        nu = prep.pr - pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)(x)[0]
        keep = common_mode_screen(nu, prep.sigma_pr**2 + projected_variance(los, p[0:3, 0:3]), self._gate)
        rate = prep.rate
        ridx = np.flatnonzero(np.isfinite(rate))
        if ridx.size >= 3:
            h_rate = pseudorange_rate_model(prep.sat_pos[ridx], prep.sat_vel[ridx], prep.sat_drift[ridx])
            nu_r = rate[ridx] - h_rate(x)[0]
            ok_r = common_mode_screen(
                nu_r, prep.sigma_rate[ridx] ** 2 + projected_variance(los[ridx], p[3:6, 3:6]), self._gate
            )
            if not ok_r.all():
                rate = rate.copy()
                rate[ridx[~ok_r]] = math.nan
                self._count("common_mode_doppler", int(ridx.size - ok_r.sum()))
        n_drop = int(keep.size - keep.sum())
        if n_drop == 0:
            return (prep if rate is prep.rate else replace(prep, rate=rate)), 0
        self._count("common_mode_pseudorange", n_drop)
        return _Prepared(
            sat_pos=prep.sat_pos[keep], sat_vel=prep.sat_vel[keep], sat_clk=prep.sat_clk[keep],
            sat_drift=prep.sat_drift[keep], iono=prep.iono[keep], tropo=prep.tropo[keep], pr=prep.pr[keep],
            rate=rate[keep], sigma_pr=prep.sigma_pr[keep], sigma_rate=prep.sigma_rate[keep],
        ), n_drop

    # ------------------------------------------------------------------ UWB
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
        anchor = self._validate_uwb(meas)
        if anchor is None:
            return self._output(False, uwb_rej=1)
        rng = float(meas.range_m)
        std = float(meas.range_std_m) if math.isfinite(meas.range_std_m) else p.uwb_range_std_m
        if not self._admit_stamp(stamp):
            return self._output(False, uwb_rej=1)
        if self._initialized and meas.frame_id != self._frame:
            self._count("uwb_frame_mismatch")
            return self._output(False, uwb_rej=1)
        self._recent_uwb[meas.anchor_id] = (stamp, anchor, rng, meas.frame_id)
        if not self._initialized:
            if not self._init_from_uwb(stamp, meas.frame_id):
                self._count("uwb_waiting_for_init")
                return self._output(False)
            return self._output(False, uwb_used=1)
        self._predict_to(stamp)
        # The model acts on the error state directly: the anchor is expressed relative to the
        # nominal tag position (back-propagated over the latency), which also keeps the ECEF
        # magnitudes out of the range difference.
        lat = p.uwb_latency_s
        nominal = self._nominal
        # Compiled update (.uwb_update, the same equations as CubatureKalmanFilter.update with
        # active_dims); the generic update handles a covariance that needs jitter (or raises).
        status = range_update_inplace(
            nominal, self._ckf.p, anchor, self._lever, lat, 6 if lat > 0.0 else 3, rng, std * std, self._gate,
            p.uwb_huber_k, p.uwb_huber_k_positive, p.max_update_iterations, p.nonlinearity_threshold,
            self._uwb_scratch,
        )
        if status == STATUS_CHOLESKY_FAILED:
            rel = anchor - nominal[0:3] + lat * nominal[3:6] if lat > 0.0 else anchor - nominal[0:3]
            try:
                res = self._ckf.update(
                    np.array([rng]),
                    np.array([std * std]),
                    uwb_range_model(rel[None, :], self._lever, lat),
                    self._gate,
                    active_dims=6 if lat > 0.0 else 3,
                    huber_k=p.uwb_huber_k,
                    huber_k_positive=p.uwb_huber_k_positive,
                    max_iterations=p.max_update_iterations,
                    nonlinearity_threshold=p.nonlinearity_threshold,
                )
            except CholeskyError:
                self._count("numerical_failure")
                return self._declare_divergence(stamp)
            self._correct()
            ok = bool(res.accepted[0])
            nis = res.nis
        else:
            ok = status == STATUS_APPLIED
            nis = float(self._uwb_scratch[2])
        window = self._uwb_gated
        if len(window) == window.maxlen:
            self._bad_uwb -= window[0]
        window.append(0 if ok else 1)
        self._bad_uwb += 0 if ok else 1
        if ok:
            self._last_uwb_stamp = stamp
            if self._position_lost():
                self._count("divergence")
                return self._declare_divergence(stamp)
            return self._output(False, uwb_used=1, nis=nis)
        self._count("innovation_gate_uwb")
        # Divergence: most of the recent ranges (all anchors together) inconsistent with the state.
        # A single anchor that still agrees (the state sits on its range sphere) does not mask it.
        if len(window) == window.maxlen and self._bad_uwb >= p.divergence_uwb_gated_fraction * window.maxlen:
            self._count("divergence")
            return self._declare_divergence(stamp)
        return self._output(False, uwb_rej=1)

    def _validate_uwb(self, meas: UwbRangeMeasurement) -> np.ndarray | None:
        p = self.params
        if meas.frame_id not in (FRAME_EARTH, FRAME_MAP):
            self._count("unknown_uwb_frame")
            return None
        if not isinstance(meas.anchor_id, str) or not meas.anchor_id:
            self._count("unknown_anchor")
            return None
        if self._anchor_registry:
            anchor = self._anchor_registry.get(meas.anchor_id)
            if anchor is None:
                self._count("unknown_anchor")
                return None
        else:
            try:
                anchor = np.asarray(meas.anchor_position_m, dtype=float).reshape(3)
            except (ValueError, TypeError):
                self._count("malformed_anchor_position")
                return None
            if not np.isfinite(anchor).all():
                self._count("nonfinite_anchor_position")
                return None
        rng = meas.range_m
        if not (isinstance(rng, (int, float, np.floating)) and math.isfinite(rng)):
            self._count("nonfinite_range")
            return None
        if rng < 0.0:
            self._count("negative_range")
            return None
        if rng > p.uwb_max_range_m:
            self._count("nonphysical_range")
            return None
        std = meas.range_std_m
        if math.isfinite(std) and std <= 0.0:
            self._count("nonphysical_range_std")
            return None
        return anchor

    def _multilaterate(self, stamp_ns: int, frame: str, guess: np.ndarray | None = None) -> np.ndarray | None:
        """Gauss-Newton multilateration from the latest range of each anchor within the window.

        Starts from ``guess`` (e.g. the diverged estimate, which keeps the solution on the right
        side of a flat anchor cluster). Without a guess it is multi-start: the anchors' centroid
        and the centroid moved by the mean range along +-x and +-y of the frame (the tag is usually
        around the anchors, not at their centroid), keeping the solution with the smallest
        residual. A single start from the centroid converged to a local minimum 12 m from the tag
        on the Hanyang NLOS case (the first second of the run then dominated its RMS error).
        """
        win = self.params.uwb_init_window_s * _NS
        recent = [(a, r) for (t, a, r, f) in self._recent_uwb.values() if f == frame and stamp_ns - t <= win]
        if len(recent) < 3:
            return None
        anchors = np.array([a for a, _ in recent])
        ranges = np.array([r for _, r in recent])
        if guess is not None:
            starts = [np.asarray(guess, float).copy()]
        else:
            c = anchors.mean(axis=0)
            rm = float(np.mean(ranges))
            starts = [c + np.array([0.1, 0.1, 0.0])] + [
                c + rm * np.array(u) for u in ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))
            ]
        best: tuple[float, np.ndarray] | None = None
        for x0 in starts:
            x = self._gauss_newton_multilateration(x0, anchors, ranges)
            if x is None:
                continue
            res = ranges - np.linalg.norm(x + self._lever - anchors, axis=1)
            rms = float(np.sqrt(np.mean(res**2)))
            if math.isfinite(rms) and (best is None or rms < best[0] - 1e-9):
                best = (rms, x)
        if best is None or best[0] > 1.0:
            return None
        return best[1]

    def _gauss_newton_multilateration(
        self, x0: np.ndarray, anchors: np.ndarray, ranges: np.ndarray
    ) -> np.ndarray | None:
        """Gauss-Newton on the ranges from ``x0`` (m, (3,)); None if it meets an anchor or NaN."""
        x = x0.copy()
        for _ in range(20):
            d = x + self._lever - anchors
            r = np.linalg.norm(d, axis=1)
            if np.any(r < 1e-9):
                return None
            h = d / r[:, None]
            dx, *_ = np.linalg.lstsq(h, ranges - r, rcond=None)
            x = x + dx
            if np.linalg.norm(dx) < 1e-6:
                break
        return x if np.isfinite(x).all() else None

    def _init_from_uwb(self, stamp_ns: int, frame: str) -> bool:
        """Initialise by multilateration. Three anchors leave two mirror solutions (across the
        anchors' plane) with zero residual, so with fewer than four anchors in the window the
        filter waits until ranges have been collected for a whole ``uwb_init_window_s`` (every
        anchor of a >= 1 Hz set has then reported) before accepting a three-anchor solution."""
        if self._uwb_wait_since_ns is None:
            self._uwb_wait_since_ns = stamp_ns
        win = self.params.uwb_init_window_s * _NS
        n_recent = sum(1 for (t, _, _, f) in self._recent_uwb.values() if f == frame and stamp_ns - t <= win)
        if n_recent < 4 and stamp_ns - self._uwb_wait_since_ns < win:
            return False
        pos = self._multilaterate(stamp_ns, frame)
        if pos is None:
            return False
        self.initialize(stamp_ns, pos, frame_id=frame, position_std_m=1.0)
        self._last_uwb_stamp = stamp_ns
        return True

    # ------------------------------------------------------------------ divergence
    def _position_lost(self) -> bool:
        p = self._ckf.p
        lim = self.params.max_position_std_m**2
        worst = max(p[0, 0], p[1, 1], p[2, 2])
        return not (worst <= lim and math.isfinite(float(self._nominal.sum())))

    def _uwb_agrees(self, stamp_ns: int) -> bool:
        """True if the UWB ranges still agree with the state (GNSS-declared divergence is then a
        GNSS fault, not a lost state): a range was accepted within ``uwb_init_window_s`` and fewer
        than ``divergence_uwb_gated_fraction`` of the (at least half-full) range window were gated."""
        p = self.params
        window = self._uwb_gated
        return (
            p.use_uwb
            and self._last_uwb_stamp is not None
            and stamp_ns - self._last_uwb_stamp <= p.uwb_init_window_s * _NS
            and 2 * len(window) >= (window.maxlen or 1)
            and self._bad_uwb < p.divergence_uwb_gated_fraction * len(window)
        )

    def _fix_agrees_with_uwb(self, stamp_ns: int, position_m: np.ndarray, position_std_m: float) -> bool:
        """Consistency of a GNSS snapshot fix with the recent UWB ranges (ECEF anchors only).

        Every range of the last ``uwb_init_window_s`` must pass the filter's chi-square gate with
        the variance ``position_std_m^2 + uwb_range_std_m^2`` (the fix's 1-sigma projected on the
        line of sight plus the range noise). A jammed epoch whose outliers the snapshot could not
        exclude (few satellites) is refused instead of replacing a state the UWB still supports.
        """
        p = self.params
        if not p.use_uwb or math.isinf(self._gate):
            return True
        win = p.uwb_init_window_s * _NS
        var = position_std_m**2 + p.uwb_range_std_m**2
        for t, anchor, rng, frame in self._recent_uwb.values():
            if frame != FRAME_EARTH or abs(stamp_ns - t) > win:
                continue
            res = rng - float(np.linalg.norm(position_m + self._lever - anchor))
            if res * res > self._gate * var:
                return False
        return True

    def _reset_clock_keep_position(self, stamp_ns: int, prep: _Prepared) -> FusionOutput:
        """GNSS-declared divergence while UWB agrees with the state: keep position and velocity,
        re-solve the clock bias from the median pseudorange residual and reset the clock
        covariance (as when the clock is first initialised after a UWB start)."""
        self._reinits += 1
        self._count("clock_reset_uwb_consistent")
        hx0 = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)
        res = prep.pr - hx0(self._nominal[None, :])[0]
        self._nominal[6] += float(np.median(res))
        pcov = self._ckf.p
        pcov[6:8, :] = 0.0
        pcov[:, 6:8] = 0.0
        pcov[6, 6] = self.params.init_clock_bias_std_m**2 + float(pcov[0:3, 0:3].trace())
        pcov[7, 7] = self.params.init_clock_drift_std_mps**2
        self._bad_gnss_epochs = 0
        return self._output(True)

    def _declare_divergence(self, stamp_ns: int) -> FusionOutput:
        """Reinitialise from (a) the caller's reference solution, (b) a snapshot LS fix of the last
        GNSS epoch, (c) UWB multilateration; else reset to uninitialised."""
        self._reinits += 1
        frame = self._frame
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
            fix = self._snapshot_fix(prep) if prep.pr.size >= self.params.min_satellites_init else None
            if fix is not None and not self._fix_agrees_with_uwb(stamp_ns, fix[0], self.params.init_position_std_m):
                self._count("gnss_fix_inconsistent_with_uwb")
                fix = None
            if fix is not None:
                self.initialize(
                    stamp_ns, fix[0], velocity_mps=fix[2], clock_bias_m=fix[1], clock_drift_mps=fix[3]
                )
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


class ReorderBuffer:
    """Re-orders time-stamped messages that arrive late by up to a fixed window.

    ``push`` stores a message; ``pop_ready(now_ns)`` returns, in stamp order, the messages with
    ``stamp_ns <= now_ns - window_ns``. Messages older than the last released stamp are returned
    by ``push`` as late (the caller counts them) instead of being released out of order.

    Args:
        window_ns: re-ordering window, ns, >= 0 (the latency it adds).
    """

    def __init__(self, window_ns: int) -> None:
        if window_ns < 0:
            raise ValueError("window_ns must be >= 0")
        self.window_ns = int(window_ns)
        self._heap: list[tuple[int, int, object]] = []
        self._seq = 0
        self._released_ns: int | None = None
        self.late = 0

    def push(self, msg) -> bool:
        """Store ``msg`` (anything with an int ``stamp_ns``). Returns False if it is already too late."""
        import heapq

        if self._released_ns is not None and msg.stamp_ns < self._released_ns:
            self.late += 1
            return False
        heapq.heappush(self._heap, (int(msg.stamp_ns), self._seq, msg))
        self._seq += 1
        return True

    def pop_ready(self, now_ns: int) -> list:
        """Messages with stamp <= now_ns - window_ns, oldest first."""
        import heapq

        out = []
        limit = now_ns - self.window_ns
        while self._heap and self._heap[0][0] <= limit:
            stamp, _, msg = heapq.heappop(self._heap)
            self._released_ns = stamp
            out.append(msg)
        return out

    def flush(self) -> list:
        """All stored messages, oldest first."""
        import heapq

        out = []
        while self._heap:
            stamp, _, msg = heapq.heappop(self._heap)
            self._released_ns = stamp
            out.append(msg)
        return out

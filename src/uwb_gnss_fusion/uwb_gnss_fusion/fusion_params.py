"""Parameters of the GNSS/UWB fusion filter, and its frame and mode codes.

Pure core (no rclpy). :class:`FusionParams` is validated on construction; the node builds it from
its ROS parameters (``fusion_node.FusionNodeParams.fusion_params``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

from scipy.stats import chi2

from gnss_common.clock_model import ClockHCoefficients
from uwb_gnss_fusion.fusion_param_groups import (
    BeyondPaperParams,
    CorrelatedErrorParams,
    DivergenceParams,
    InitialisationParams,
    MirrorAmbiguityParams,
    MultiGnssParams,
    RangeNoiseParams,
    SensorModelParams,
    StaticModelParams,
)

MODE_NONE = 0
MODE_GNSS = 1
MODE_UWB = 2
MODE_GNSS_UWB = 3
"""Mode codes, identical to rfi_msgs/FusionStatus.msg."""

FRAME_EARTH = "earth"
FRAME_MAP = "map"

INTER_SYSTEM_BIAS_PSD_M2PS = 1.0e-3
"""Random-walk PSD of each inter-system clock bias state, m^2/s (0.6 m 1-sigma drift per hour at
most, 1.9 m per hour allowed). What the bias holds: the receiver's hardware delay difference
between the systems' signals (constant while the receiver runs) and the residual offset between
the system times after the broadcast corrections (GPS-Galileo GGTO, BeiDou and GLONASS time:
a few ns, varying over days; Hegarty et al. 2017)."""

INTER_SYSTEM_BIAS_INIT_STD_M = 30.0
"""1-sigma of an inter-system bias when it is (re)initialised from the median pseudorange residual
of its system at the predicted state, m: the median holds the bias to the position error (metres)
plus noise, so 30 m covers it with margin; the system's satellites then fix it in one epoch."""

INTER_SYSTEM_BIAS_MAX_GAP_S = 300.0
"""A system absent for longer than this has its bias re-initialised from its residuals when it
returns, s (e.g. after a receiver restart its hardware biases may differ); a shorter absence keeps
the estimate, whose variance grew by the random walk meanwhile."""

UWB_FIX_CONSISTENT_SIGMA = 4.0
"""A multilateration fix explains the ranges when every residual is within this many range
1-sigmas (``FusionParams.uwb_gated_anchor_reinit``)."""

GLONASS_BIAS_MAX_GAP_S = 3600.0
"""A GLONASS satellite unseen for longer than this has its code-bias state removed, s (a satellite
that set: a pass lasts hours, and the state of one no longer seen only costs computation)."""
CORRELATED_ERROR_MAX_GAP_TAU = 2.0
"""A satellite unseen for longer than this many correlation times has its correlated-error state
removed (marginalised, exact); if it returns it gets a fresh state with the stationary variance
(after two correlation times the old estimate keeps less than 2 % of its correlation)."""

UWB_NOISE_PRIOR_WEIGHT = 20
"""The stated range 1-sigma counts as this many innovation samples when an anchor's noise estimate
starts (``FusionParams.uwb_range_noise_adaptive``): one second at 20 Hz, so that the first few
squared innovations (chi-square with one degree of freedom, often near zero) do not swing it."""


@dataclass(frozen=True)
class FusionParams(RangeNoiseParams, MirrorAmbiguityParams, CorrelatedErrorParams, MultiGnssParams, BeyondPaperParams,
                   DivergenceParams, InitialisationParams, StaticModelParams, SensorModelParams):
    """Parameters of :class:`FusionFilter` (validated on construction).

    Each field is a parameter of fusion_node written once, with its default, description, range,
    group and whether it is settable while running (:func:`rfi_node_common.params.parameter`; shown by
    ``fusion_node --help`` and config/fusion.yaml, which is generated from them). ``loop`` and
    ``anchors`` are not parameters (the node builds ``loop`` from its ``loop_*`` parameters; anchor
    positions come in the UwbRange messages).

    The fields come in groups (``fusion_param_groups``), one base class each, in this order (a dataclass takes the
    fields of its bases last base first, hence the bases listed in reverse): ``SensorModelParams``,
    ``StaticModelParams``, ``InitialisationParams``, ``DivergenceParams``, ``BeyondPaperParams``, ``MultiGnssParams``,
    ``CorrelatedErrorParams``, ``MirrorAmbiguityParams``, ``RangeNoiseParams``. Each base's docstring holds the design
    notes of its fields.
    """

    def __post_init__(self) -> None:
        pos = {
            "accel_psd_m2ps3": self.accel_psd_m2ps3,
            "static_accel_psd_m2ps3": self.static_accel_psd_m2ps3,
            "static_velocity_std_mps": self.static_velocity_std_mps,
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
            "pseudorange_correlated_tau_s": self.pseudorange_correlated_tau_s,
            "uwb_mirror_switch_log_lr": self.uwb_mirror_switch_log_lr,
            "uwb_range_std_floor_m": self.uwb_range_std_floor_m,
            "uwb_range_std_ceiling_m": self.uwb_range_std_ceiling_m,
            # inf switches the Huber weighting off; anything else must be finite and > 0
            "uwb_huber_k": 1.0 if self.uwb_huber_k == math.inf else self.uwb_huber_k,
            "uwb_huber_k_positive": 1.0 if self.uwb_huber_k_positive == math.inf else self.uwb_huber_k_positive,
        }
        for name, value in pos.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"FusionParams.{name} must be a finite number > 0, got {value!r}")
        for name in ("static_enter_s", "clock_h_minus2_hz", "pseudorange_correlated_std_m",
                     "pseudorange_broadcast_std_m", "glonass_satellite_bias_std_m", "divergence_fix_confirm_s",
                     "uwb_range_bias_std_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"FusionParams.{name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.glonass_pseudorange_error_factor) and self.glonass_pseudorange_error_factor >= 1.0):
            raise ValueError(
                "FusionParams.glonass_pseudorange_error_factor must be finite and >= 1, "
                f"got {self.glonass_pseudorange_error_factor!r}"
            )
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
        if self.uwb_tag_side_of_anchor_plane not in (-1, 0, 1) or isinstance(self.uwb_tag_side_of_anchor_plane, bool):
            raise ValueError(
                "FusionParams.uwb_tag_side_of_anchor_plane must be -1 (below), 0 (unknown) or 1 (above), "
                f"got {self.uwb_tag_side_of_anchor_plane!r}"
            )
        if not (math.isfinite(self.uwb_mirror_gnss_std_m) and self.uwb_mirror_gnss_std_m > 0.0):
            raise ValueError(
                f"FusionParams.uwb_mirror_gnss_std_m must be finite and > 0, got {self.uwb_mirror_gnss_std_m!r}"
            )
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
        if not (math.isfinite(self.uwb_range_bias_time_s) and self.uwb_range_bias_time_s > 0.0):
            raise ValueError(
                f"FusionParams.uwb_range_bias_time_s must be finite and > 0, got {self.uwb_range_bias_time_s!r}"
            )
        if not (isinstance(self.uwb_iterate_min_anchors, int) and 0 <= self.uwb_iterate_min_anchors <= 64):
            raise ValueError(
                f"FusionParams.uwb_iterate_min_anchors must be an int in [0, 64], got {self.uwb_iterate_min_anchors!r}"
            )
        if not (isinstance(self.uwb_range_noise_window, int) and self.uwb_range_noise_window >= 10):
            raise ValueError(
                f"FusionParams.uwb_range_noise_window must be an int >= 10, got {self.uwb_range_noise_window!r}"
            )
        if self.uwb_range_std_floor_m > self.uwb_range_std_ceiling_m:
            raise ValueError("FusionParams.uwb_range_std_floor_m must not exceed uwb_range_std_ceiling_m")
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


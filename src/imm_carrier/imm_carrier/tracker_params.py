"""Parameters of the per-channel carrier tracking manager (``imm_carrier.tracker.CarrierTracker``).

Pure module (no rclpy). Fields written with :func:`rfi_node_common.params.parameter` are parameters of
imm_carrier_node (``node_params``), defined once here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from imm_carrier.imm import ImmParams
from imm_carrier.measurement_model import MAX_INTEGRATION_TIME_S, MIN_INTEGRATION_TIME_S
from imm_carrier.pll import PllParams
from rfi_node_common.params import USER, parameter

METHODS = ("imm", "pll")
"""The carrier trackers: the IMM of Zhao et al. and the reference PLL."""
CORRELATOR_UNLOCKED_POLICIES = ("track", "coast")
"""What the IMM does with a correlator whose producer reports its carrier lock lost (TrackerParams)."""


@dataclass(frozen=True)
class TrackerParams:
    """Parameters of the per-channel manager.

    Fields written with :func:`rfi_node_common.params.parameter` are parameters of imm_carrier_node:
    their default, description and range are there (``--help``, config/imm_carrier.yaml).

    Attributes:
        method: "imm" or "pll".
        imm: IMM parameters.
        pll: PLL parameters.
    """

    method: str = "imm"
    imm: ImmParams = field(default_factory=ImmParams)
    pll: PllParams = field(default_factory=PllParams)
    channel_timeout_s: float = parameter(
        1.0,
        'A satellite channel not seen for longer than this (stamp time) is dropped, s.',
        minimum=0.001, maximum=3600.0,
    )
    max_gap_intervals: float = parameter(
        1.5,
        'A gap longer than this many integration times breaks phase continuity: the channel restarts, '
        'integration intervals.',
        minimum=1.01, maximum=1000000.0,
    )
    bit_period_s: float = parameter(
        0.02,
        'Known data-bit timing (GPS L1 C/A: 0.02): with T shorter than this, bit changes are allowed only on '
        'intervals starting on a bit edge of the GPS time grid (ROS stamps converted from GPS time are on it: '
        'GPS - UTC is whole seconds), s; 0 = edges unknown.',
        minimum=0.0, maximum=1.0,
    )
    min_integration_time_s: float = parameter(
        MIN_INTEGRATION_TIME_S,
        'Shortest coherent integration time T the receiver produces, s; a correlator with a shorter T is '
        'rejected (<method>.rejected_integration_time). Widen only for a receiver that really integrates '
        'shorter.',
        minimum=1e-06, maximum=1.0, group=USER,
    )
    max_integration_time_s: float = parameter(
        MAX_INTEGRATION_TIME_S,
        'Longest coherent integration time T the receiver produces, s; a correlator with a longer T is '
        "rejected (<method>.rejected_integration_time): a T of 1e6 s once threw the IMM's phase by 6000 rad. "
        'Zhao et al. use 1-20 ms; 100 ms covers pilot signals. Widen only for a receiver that really '
        'integrates longer.',
        minimum=1e-05, maximum=10.0, group=USER,
    )
    max_iq_magnitude_ratio: float = parameter(
        100.0,
        'A correlator whose magnitude sqrt(I^2 + Q^2) exceeds this many times the RMS expected from its C/N0 '
        'and T, sqrt(A^2 + 2 sigma_v^2) (Zhao et al., eq. 4-5), is rejected (rejected_iq_magnitude), '
        'dimensionless. A correlator that follows the model exceeds 10 RMS with probability below 1e-40; '
        "one EKF update moves the phase by up to about the correlator's magnitude (in units of A), so a "
        'larger one could only throw the channel off.',
        minimum=2.0, maximum=1000000.0,
    )
    correlator_unlocked: str = parameter(
        "track",
        "What the IMM does with a correlator whose producer reports its own carrier loop unlocked (Correlator."
        "carrier_lock LOST): track (update as any other, weighted by its C/N0: Zhao et al.'s IMM is meant to "
        "hold the phase where a PLL loses lock; docs/imm_carrier/correlator_lock.md) or coast (prediction "
        "only, the correlator unused). Either way such intervals are counted apart (correlator_unlocked, "
        "locked_on_correlator_unlocked, slips_on_correlator_unlocked); the PLL baseline always tracks.",
        choices=CORRELATOR_UNLOCKED_POLICIES,
    )

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not (math.isfinite(self.channel_timeout_s) and self.channel_timeout_s > 0):
            raise ValueError("channel_timeout_s must be finite and > 0")
        if not (math.isfinite(self.max_gap_intervals) and self.max_gap_intervals > 1):
            raise ValueError("max_gap_intervals must be finite and > 1")
        if not (math.isfinite(self.bit_period_s) and self.bit_period_s >= 0):
            raise ValueError("bit_period_s must be finite and >= 0")
        t_min, t_max = self.min_integration_time_s, self.max_integration_time_s
        if not (math.isfinite(t_min) and math.isfinite(t_max) and 0 < t_min < t_max):
            raise ValueError(
                f"integration time range must satisfy 0 < min_integration_time_s < max_integration_time_s, "
                f"got {t_min!r}, {t_max!r}"
            )
        if not (math.isfinite(self.max_iq_magnitude_ratio) and self.max_iq_magnitude_ratio > 1):
            raise ValueError("max_iq_magnitude_ratio must be finite and > 1")
        if self.correlator_unlocked not in CORRELATOR_UNLOCKED_POLICIES:
            raise ValueError(f"correlator_unlocked must be one of {CORRELATOR_UNLOCKED_POLICIES}, "
                             f"got {self.correlator_unlocked!r}")

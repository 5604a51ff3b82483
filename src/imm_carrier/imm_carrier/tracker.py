"""Per-channel carrier tracking manager: one IMM (or PLL) per satellite, with input checks and counters.

The node converts each CorrelatorArray into ``CorrelatorSample``s and calls
``CarrierTracker.process(stamp_ns, samples)``; it publishes the returned ``CarrierPhaseEstimate``s
and the ``counters`` as diagnostics. Time is the message stamp in integer nanoseconds (end of the
integration interval); no clock is read.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from imm_carrier.imm import ImmCarrierFilter, ImmParams
from imm_carrier.measurement_model import (
    CN0_MAX_DBHZ,
    CN0_MIN_DBHZ,
    METHOD_IMM,
    METHOD_PLL,
    CarrierPhaseEstimate,
    CorrelatorSample,
)
from imm_carrier.pll import CostasPll, PllParams

METHODS = ("imm", "pll")
MAX_SVID = 255

COUNTER_KEYS = (
    "processed",
    "channels_started",
    "channels_dropped_timeout",
    "channels_restarted_gap",
    "rejected_nonfinite_iq",
    "rejected_integration_time",
    "rejected_cn0_range",
    "cn0_missing_used_last",
    "rejected_cn0_missing",
    "rejected_predicted_phase",
    "rejected_stamp_backwards",
    "rejected_invalid_svid",
    "rejected_duplicate_channel",
    "slips_detected",
)
"""Keys of CarrierTracker.counters."""


@dataclass(frozen=True)
class TrackerParams:
    """Parameters of the per-channel manager.

    Attributes:
        method: "imm" or "pll".
        imm: IMM parameters.
        pll: PLL parameters.
        channel_timeout_s: drop a channel not seen for longer than this, s, > 0.
        max_gap_intervals: a gap longer than this many integration times breaks phase continuity
            (missed satellite-motion phase changes): the channel restarts, counted, > 1.
        bit_period_s: navigation data-bit duration, s (GPS L1 C/A: 0.02). When the integration time
            is shorter, the IMM's bit-transition probability is used only on intervals that start on
            a bit edge (stamps on the GPS time grid) and is 0 inside a bit; 0 disables this.
    """

    method: str = "imm"
    imm: ImmParams = field(default_factory=ImmParams)
    pll: PllParams = field(default_factory=PllParams)
    channel_timeout_s: float = 1.0
    max_gap_intervals: float = 1.5
    bit_period_s: float = 0.02

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not (math.isfinite(self.channel_timeout_s) and self.channel_timeout_s > 0):
            raise ValueError("channel_timeout_s must be finite and > 0")
        if not (math.isfinite(self.max_gap_intervals) and self.max_gap_intervals > 1):
            raise ValueError("max_gap_intervals must be finite and > 1")
        if not (math.isfinite(self.bit_period_s) and self.bit_period_s >= 0):
            raise ValueError("bit_period_s must be finite and >= 0")


@dataclass
class _Channel:
    filt: ImmCarrierFilter | CostasPll
    last_stamp_ns: int
    last_cn0_dbhz: float
    slips: int = 0


class CarrierTracker:
    """Tracks every (constellation, svid) seen: starts a channel on first sight, drops it after a timeout.

    ``cycle_slips`` in the estimates counts slips *detected* on line: for the IMM, steps where the
    update moved the phase by more than ``slip_jump_threshold_rad``; for the PLL, losses of the lock
    indicator. True slips against truth are counted offline by cycle_slips.count_cycle_slips.
    """

    def __init__(self, params: TrackerParams) -> None:
        if not isinstance(params, TrackerParams):
            raise ValueError("params must be a TrackerParams")
        self.params = params
        self._channels: dict[tuple[int, int], _Channel] = {}
        self._counters = dict.fromkeys(COUNTER_KEYS, 0)
        self._pll_was_locked: dict[tuple[int, int], bool] = {}

    @property
    def counters(self) -> dict[str, int]:
        """Copy of the counters (see COUNTER_KEYS)."""
        return dict(self._counters)

    @property
    def channel_keys(self) -> tuple[tuple[int, int], ...]:
        """(constellation, svid) of the live channels."""
        return tuple(self._channels)

    def _drop_stale(self, stamp_ns: int) -> None:
        limit = int(self.params.channel_timeout_s * 1e9)
        for key in [k for k, ch in self._channels.items() if stamp_ns - ch.last_stamp_ns > limit]:
            del self._channels[key]
            self._pll_was_locked.pop(key, None)
            self._counters["channels_dropped_timeout"] += 1

    def _new_channel(self, s: CorrelatorSample, stamp_ns: int, cn0: float) -> _Channel:
        if self.params.method == "imm":
            filt: ImmCarrierFilter | CostasPll = ImmCarrierFilter(self.params.imm)
        else:
            filt = CostasPll(self.params.pll)
        filt.initialize_from_correlator(s.in_phase, s.quadrature, s.predicted_phase_change_rad)
        return _Channel(filt=filt, last_stamp_ns=stamp_ns, last_cn0_dbhz=cn0)

    def _transition_probability(self, stamp_ns: int, t_s: float) -> float:
        p = self.params.imm.bit_transition_probability
        bit = self.params.bit_period_s
        if bit <= 0 or t_s >= bit - 1e-9:
            return p
        start_s = stamp_ns * 1e-9 - t_s
        phase = start_s / bit - round(start_s / bit)
        return p if abs(phase) * bit < 0.5 * t_s else 0.0

    def process(self, stamp_ns: int, samples: Sequence[CorrelatorSample]) -> tuple[CarrierPhaseEstimate, ...]:
        """Process the correlators of one interval.

        Args:
            stamp_ns: end of the integration interval, ns (int).
            samples: correlators of the channels, at most one per (constellation, svid).

        Returns:
            One estimate per accepted sample (rejected samples are counted, not returned). A new
            channel's first sample only initialises it and is returned with locked=False.
        """
        stamp_ns = int(stamp_ns)
        self._drop_stale(stamp_ns)
        out = []
        seen: set[tuple[int, int]] = set()
        c = self._counters
        for s in samples:
            key = (int(s.constellation), int(s.svid))
            if not (0 < key[1] <= MAX_SVID):
                c["rejected_invalid_svid"] += 1
                continue
            if key in seen:
                c["rejected_duplicate_channel"] += 1
                continue
            seen.add(key)
            t_s = s.integration_time_s
            if not (math.isfinite(t_s) and t_s > 0):
                c["rejected_integration_time"] += 1
                continue
            if not (math.isfinite(s.in_phase) and math.isfinite(s.quadrature)):
                c["rejected_nonfinite_iq"] += 1
                continue
            if not math.isfinite(s.predicted_phase_change_rad):
                c["rejected_predicted_phase"] += 1
                continue
            ch = self._channels.get(key)
            cn0 = s.cn0_dbhz
            if math.isnan(cn0):
                if ch is None:
                    c["rejected_cn0_missing"] += 1
                    continue
                cn0 = ch.last_cn0_dbhz
                c["cn0_missing_used_last"] += 1
            elif not (CN0_MIN_DBHZ <= cn0 <= CN0_MAX_DBHZ):
                c["rejected_cn0_range"] += 1
                continue
            if ch is not None and stamp_ns <= ch.last_stamp_ns:
                c["rejected_stamp_backwards"] += 1
                continue
            if ch is not None and (stamp_ns - ch.last_stamp_ns) > self.params.max_gap_intervals * t_s * 1e9:
                del self._channels[key]
                c["channels_restarted_gap"] += 1
                ch = None
            c["processed"] += 1
            if ch is None:
                ch = self._new_channel(s, stamp_ns, cn0)
                self._channels[key] = ch
                c["channels_started"] += 1
                out.append(self._initial_estimate(stamp_ns, key, ch))
                continue
            ch.last_stamp_ns = stamp_ns
            ch.last_cn0_dbhz = cn0
            out.append(self._step(stamp_ns, key, ch, s, cn0))
        return tuple(out)

    def _initial_estimate(self, stamp_ns: int, key: tuple[int, int], ch: _Channel) -> CarrierPhaseEstimate:
        method = METHOD_IMM if self.params.method == "imm" else METHOD_PLL
        p = self.params.imm
        phase = ch.filt.residual_phase_rad
        is_imm = method == METHOD_IMM
        return CarrierPhaseEstimate(
            stamp_ns=stamp_ns,
            constellation=key[0],
            svid=key[1],
            method=method,
            phase_rad=phase,
            phase_std_rad=p.initial_phase_std_rad if is_imm else math.nan,
            frequency_hz=0.0,
            frequency_std_hz=p.initial_frequency_std_hz if is_imm else math.nan,
            data_bit=0,
            data_bit_probability=0.5,
            mode_probabilities=(0.5, 0.5) if is_imm else (),
            locked=False,
            cycle_slips=0,
        )

    def _step(
        self, stamp_ns: int, key: tuple[int, int], ch: _Channel, s: CorrelatorSample, cn0: float
    ) -> CarrierPhaseEstimate:
        if isinstance(ch.filt, ImmCarrierFilter):
            r = ch.filt.update(
                s.in_phase,
                s.quadrature,
                cn0,
                s.integration_time_s,
                s.predicted_phase_change_rad,
                bit_transition_probability=self._transition_probability(stamp_ns, s.integration_time_s),
            )
            if r.slip_detected:
                ch.slips += 1
                self._counters["slips_detected"] += 1
            return CarrierPhaseEstimate(
                stamp_ns=stamp_ns,
                constellation=key[0],
                svid=key[1],
                method=METHOD_IMM,
                phase_rad=r.phase_rad,
                phase_std_rad=r.phase_std_rad,
                frequency_hz=r.frequency_hz,
                frequency_std_hz=r.frequency_std_hz,
                data_bit=r.data_bit,
                data_bit_probability=r.data_bit_probability,
                mode_probabilities=r.mode_probabilities,
                locked=r.locked,
                cycle_slips=ch.slips,
            )
        q = ch.filt.update(s.in_phase, s.quadrature, cn0, s.integration_time_s, s.predicted_phase_change_rad)
        was = self._pll_was_locked.get(key, False)
        if was and not q.locked:
            ch.slips += 1
            self._counters["slips_detected"] += 1
        self._pll_was_locked[key] = q.locked
        # Costas loop: the bit is the sign of the rotated prompt I (phase error within +-pi/2).
        th = ch.filt.satellite_phase_rad + q.phase_rad
        i_rot = s.in_phase * math.cos(th) + s.quadrature * math.sin(th)
        bit = 1 if i_rot > 0 else (-1 if i_rot < 0 else 0)
        finite = math.isfinite(q.phase_rad) and math.isfinite(q.frequency_hz)
        return CarrierPhaseEstimate(
            stamp_ns=stamp_ns,
            constellation=key[0],
            svid=key[1],
            method=METHOD_PLL,
            phase_rad=q.phase_rad,
            phase_std_rad=math.nan,
            frequency_hz=q.frequency_hz,
            frequency_std_hz=math.nan,
            data_bit=bit,
            data_bit_probability=0.5 if bit == 0 else 1.0,
            mode_probabilities=(),
            locked=q.locked and finite,
            cycle_slips=ch.slips,
        )

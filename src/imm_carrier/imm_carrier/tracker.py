"""Per-channel carrier tracking manager: one IMM (or PLL) per satellite, with input checks and counters.

The node hands the correlators of one interval to ``CarrierTracker.process_arrays(stamp_ns, ...)`` as
arrays (one element per channel) and gets one :class:`CarrierPhaseBatch` back (one row per accepted
correlator); ``CarrierTracker.process(stamp_ns, samples)`` is the same on ``CorrelatorSample``s and
returns ``CarrierPhaseEstimate``s. Time is the message stamp in integer nanoseconds (end of the
integration interval); no clock is read.

Speed: all channels of one interval go through ONE compiled call (:func:`_track_epoch`): channel
look-up, life cycle (start, timeout, gap restart), every input check and counter, and the filter steps
(the IMM's :func:`imm_carrier.imm.imm_step`, the PLL's :func:`imm_carrier.pll.pll_step`). The
channel states live in a 2-D array, one row per slot, and the (constellation, svid) -> slot map is a
65536-entry table, so no Python object is created per channel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from gnss_common.clock_model import PROCESS_NOISE_FORMS
from imm_carrier.imm import imm_step, wrap_phase
from imm_carrier.layout import (
    BATCH_COLUMNS,
    COUNTER_KEYS,
    IMM_OUT_LEN,
    IMM_STATE_LEN,
    KERNEL_CONFIG_LEN,
    N_BATCH_COLUMNS,
    PLL_OUT_LEN,
    PLL_STATE_LEN,
    BatchColumn,
    Counter,
    ImmOut,
    ImmState,
    KernelConfig,
    PllOut,
    PllState,
)
from imm_carrier.measurement_model import (
    CN0_MAX_DBHZ,
    CN0_MIN_DBHZ,
    CORRELATOR_LOCK_HELD,
    CORRELATOR_LOCK_LOST,
    MAX_PREDICTED_DOPPLER_HZ,
    MAX_RESIDUAL_PHASE_RAD,
    METHOD_IMM,
    METHOD_PLL,
    CarrierPhaseEstimate,
    CorrelatorSample,
    amp_sigma,
)
from imm_carrier.pll import pll_step, scheduled_bandwidth_hz
from imm_carrier.tracker_params import TrackerParams

MAX_SVID = 255
MAX_CONSTELLATION = 255

_REJECTED_INDICES = np.array([i for i, k in enumerate(COUNTER_KEYS) if k.startswith("rejected_")])

_M_IMM, _M_PLL = 0, 1
_STATE_WIDTH = 16  # >= IMM_STATE_LEN and PLL_STATE_LEN
_KEY_TABLE_SIZE = (MAX_CONSTELLATION + 1) * 256
assert _STATE_WIDTH >= max(IMM_STATE_LEN, PLL_STATE_LEN)


@dataclass(frozen=True)
class CarrierPhaseBatch:
    """Estimates of one interval, one row per accepted correlator, in input order.

    Attributes:
        stamp_ns: stamp of the interval, ns.
        method: METHOD_IMM or METHOD_PLL.
        values: shape (n, N_BATCH_COLUMNS), float64, columns BATCH_COLUMNS with the units of
            CarrierPhaseEstimate (constellation, svid, data_bit, locked (0/1) and cycle_slips hold
            integers; the mode probabilities are NaN for the PLL, which has none).
    """

    stamp_ns: int
    method: int
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def column(self, name: str) -> np.ndarray:
        """Column ``name`` (one of BATCH_COLUMNS), shape (n,), a view."""
        return self.values[:, BATCH_COLUMNS.index(name)]

    @property
    def locked(self) -> np.ndarray:
        """Lock flags, bool, shape (n,)."""
        return self.values[:, BatchColumn.LOCKED] > 0.5

    def to_estimates(self) -> tuple[CarrierPhaseEstimate, ...]:
        """The rows as CarrierPhaseEstimate dataclasses (convenient, not for the hot path)."""
        out = []
        for r in self.values.tolist():
            modes = ((r[BatchColumn.MODE_PROBABILITY_PLUS], r[BatchColumn.MODE_PROBABILITY_MINUS])
                     if self.method == METHOD_IMM else ())
            out.append(
                CarrierPhaseEstimate(
                    stamp_ns=self.stamp_ns,
                    constellation=int(r[BatchColumn.CONSTELLATION]),
                    svid=int(r[BatchColumn.SVID]),
                    method=self.method,
                    phase_rad=r[BatchColumn.PHASE_RAD],
                    phase_std_rad=r[BatchColumn.PHASE_STD_RAD],
                    frequency_hz=r[BatchColumn.FREQUENCY_HZ],
                    frequency_std_hz=r[BatchColumn.FREQUENCY_STD_HZ],
                    data_bit=int(r[BatchColumn.DATA_BIT]),
                    data_bit_probability=r[BatchColumn.DATA_BIT_PROBABILITY],
                    mode_probabilities=modes,
                    locked=r[BatchColumn.LOCKED] > 0.5,
                    cycle_slips=int(r[BatchColumn.CYCLE_SLIPS]),
                )
            )
        return tuple(out)


@njit(cache=True)
def _transition_probability(stamp_ns, t_s, p, bit_s):
    """IMM bit-transition probability of the interval ending at stamp_ns: p on a bit edge, else 0."""
    if bit_s <= 0.0 or t_s >= bit_s - 1e-9:
        return p
    start_s = stamp_ns * 1e-9 - t_s
    x = start_s / bit_s
    phase = x - math.floor(x + 0.5)
    return p if abs(phase) * bit_s < 0.5 * t_s else 0.0


@njit(cache=True)
def _sane(phase_rad, frequency_hz, t_s):
    """A tracker state that can still be meaningful: |phase| <= MAX_RESIDUAL_PHASE_RAD and |frequency| <= 1/T
    (a residual frequency of a whole cycle per interval cannot be told from zero: the tracker has lost it)."""
    return abs(phase_rad) <= MAX_RESIDUAL_PHASE_RAD and abs(frequency_hz) * t_s <= 1.0


@njit(cache=True)
def _init_channel(method, st, zi, zq, dphi, cfg, row):
    """Start a channel from its first correlator (IMM: initialize_from_correlator; PLL: the same) and
    write its first, unlocked estimate into row."""
    sat = wrap_phase(dphi)
    phase = math.atan2(zq, zi) - sat
    for m in range(st.shape[0]):
        st[m] = 0.0
    row[BatchColumn.PHASE_RAD] = phase
    row[BatchColumn.FREQUENCY_HZ] = 0.0
    row[BatchColumn.DATA_BIT] = 0.0
    row[BatchColumn.DATA_BIT_PROBABILITY] = 0.5
    row[BatchColumn.LOCKED] = 0.0
    row[BatchColumn.CYCLE_SLIPS] = 0.0
    if method == _M_IMM:
        pa = cfg[KernelConfig.INIT_PHASE_STD] ** 2
        pc = (2.0 * math.pi * cfg[KernelConfig.INIT_FREQ_STD]) ** 2
        st[ImmState.X1] = phase
        st[ImmState.X2] = phase
        st[ImmState.P1] = pa
        st[ImmState.P1 + 2] = pc
        st[ImmState.P2] = pa
        st[ImmState.P2 + 2] = pc
        st[ImmState.LOGMU] = math.log(0.5)
        st[ImmState.LOGMU + 1] = math.log(0.5)
        st[ImmState.SAT] = sat
        row[BatchColumn.PHASE_STD_RAD] = cfg[KernelConfig.INIT_PHASE_STD]
        row[BatchColumn.FREQUENCY_STD_HZ] = cfg[KernelConfig.INIT_FREQ_STD]
        row[BatchColumn.MODE_PROBABILITY_PLUS] = 0.5
        row[BatchColumn.MODE_PROBABILITY_MINUS] = 0.5
    else:
        st[PllState.NCO_PHASE] = phase
        st[PllState.SAT_PHASE] = sat
        st[PllState.EMA_DIFF] = 1.0
        st[PllState.EMA_SUM] = 1.0
        row[BatchColumn.PHASE_STD_RAD] = math.nan
        row[BatchColumn.FREQUENCY_STD_HZ] = math.nan
        row[BatchColumn.MODE_PROBABILITY_PLUS] = math.nan
        row[BatchColumn.MODE_PROBABILITY_MINUS] = math.nan


@njit(cache=True)
def _imm_update(st, i_k, q_k, amp, sig, tk, d_k, stamp_ns, cfg, imm_out, row, slot, slips, counters, coast):
    """One IMM step of a running channel and its output row; returns (finite, valid, locked) (see _track_epoch).
    coast: prediction only (the measurement not used: imm_step with NaN I/Q)."""
    p = _transition_probability(stamp_ns, tk, cfg[KernelConfig.P_BIT], cfg[KernelConfig.BIT_PERIOD])
    imm_step(
        st, math.nan if coast else i_k, math.nan if coast else q_k, amp, sig, tk, d_k, p, math.nan,
        cfg[KernelConfig.QF], cfg[KernelConfig.QG], int(cfg[KernelConfig.FORM]), imm_out
    )
    phase = imm_out[ImmOut.PHI]
    omega = imm_out[ImmOut.OMEGA]
    std = math.sqrt(max(imm_out[ImmOut.P11], 0.0))
    freq_std = math.sqrt(max(imm_out[ImmOut.P22], 0.0)) / (2.0 * math.pi)
    mu1 = imm_out[ImmOut.MU1]
    mu2 = imm_out[ImmOut.MU2]
    finite = abs(phase) < math.inf and abs(omega) < math.inf and std < math.inf and freq_std < math.inf
    if finite and abs(phase - imm_out[ImmOut.PRIOR_PHI]) > cfg[KernelConfig.SLIP_THR]:
        slips[slot] += 1
        counters[Counter.SLIPS_DETECTED] += 1
    freq = omega / (2.0 * math.pi)
    # A covariance that collapsed to 0 (cancellation) or a state beyond any trackable value: diverged.
    valid = finite and std > 0.0 and freq_std > 0.0 and _sane(phase, freq, tk)
    locked = finite and std < cfg[KernelConfig.LOCK_STD]
    if locked and not valid:  # final check at the output: locked only if valid
        locked = False
        counters[Counter.LOCKED_SUPPRESSED_INVALID] += 1
    row[BatchColumn.PHASE_RAD] = phase
    row[BatchColumn.PHASE_STD_RAD] = std
    row[BatchColumn.FREQUENCY_HZ] = freq
    row[BatchColumn.FREQUENCY_STD_HZ] = freq_std
    row[BatchColumn.DATA_BIT] = 1.0 if mu1 > mu2 else (-1.0 if mu2 > mu1 else 0.0)
    row[BatchColumn.DATA_BIT_PROBABILITY] = max(mu1, mu2)
    row[BatchColumn.MODE_PROBABILITY_PLUS] = mu1
    row[BatchColumn.MODE_PROBABILITY_MINUS] = mu2
    return finite, valid, locked


@njit(cache=True)
def _pll_update(st, i_k, q_k, amp, tk, d_k, cfg, pll_out, row, slot, slips, was_locked, counters):
    """One PLL step of a running channel and its output row; returns (finite, valid, locked) (see _track_epoch)."""
    bn = scheduled_bandwidth_hz(st[PllState.ELAPSED], cfg[KernelConfig.BW_START], cfg[KernelConfig.BW_END],
                                cfg[KernelConfig.BW_DURATION])
    alpha = min(tk / cfg[KernelConfig.LOCK_TC], 1.0)
    pll_step(st, i_k, q_k, tk, d_k, bn, amp, alpha, pll_out)
    phase = pll_out[PllOut.PHASE]
    freq = pll_out[PllOut.FREQUENCY] / (2.0 * math.pi)
    finite = abs(phase) < math.inf and abs(pll_out[PllOut.FREQUENCY]) < math.inf
    # the lock averages too
    finite = finite and abs(pll_out[PllOut.LOCK_METRIC]) < math.inf and abs(st[PllState.EMA_SUM]) < math.inf
    valid = finite and _sane(phase, freq, tk)  # the PLL has no std (NaN by definition)
    locked = finite and pll_out[PllOut.LOCK_METRIC] > cfg[KernelConfig.LOCK_THR]
    if locked and not valid:  # final check at the output: locked only if valid
        locked = False
        counters[Counter.LOCKED_SUPPRESSED_INVALID] += 1
    if was_locked[slot] and not locked:
        slips[slot] += 1
        counters[Counter.SLIPS_DETECTED] += 1
    was_locked[slot] = locked
    # Costas loop: the bit is the sign of the rotated prompt I (phase error within +-pi/2).
    th = st[PllState.SAT_PHASE] + phase
    i_rot = i_k * math.cos(th) + q_k * math.sin(th)
    bit = 1.0 if i_rot > 0.0 else (-1.0 if i_rot < 0.0 else 0.0)
    row[BatchColumn.PHASE_RAD] = phase
    row[BatchColumn.PHASE_STD_RAD] = math.nan
    row[BatchColumn.FREQUENCY_HZ] = freq
    row[BatchColumn.FREQUENCY_STD_HZ] = math.nan
    row[BatchColumn.DATA_BIT] = bit
    row[BatchColumn.DATA_BIT_PROBABILITY] = 0.5 if bit == 0.0 else 1.0
    row[BatchColumn.MODE_PROBABILITY_PLUS] = math.nan
    row[BatchColumn.MODE_PROBABILITY_MINUS] = math.nan
    return finite, valid, locked


@njit(cache=True)
def _open_channel(method, key, stamp_ns, c0, i_k, q_k, d_k, cfg, row, slot_of_key, key_of_slot, last_stamp, last_cn0,
                  slips, was_locked, state, counters):
    """Start the channel ``key`` in the first free slot (the caller guarantees one) from its first correlator."""
    slot = -1
    for s in range(key_of_slot.shape[0]):
        if key_of_slot[s] < 0:
            slot = s
            break
    slot_of_key[key] = slot
    key_of_slot[slot] = key
    last_stamp[slot] = stamp_ns
    last_cn0[slot] = c0
    slips[slot] = 0
    was_locked[slot] = False
    _init_channel(method, state[slot], i_k, q_k, d_k, cfg, row)
    counters[Counter.CHANNELS_STARTED] += 1


@njit(cache=True)
def _drop_timed_out(stamp_ns, timeout_ns, slot_of_key, key_of_slot, last_stamp, counters):
    """Channels not seen for longer than the timeout are dropped."""
    for s in range(key_of_slot.shape[0]):
        key = key_of_slot[s]
        if key >= 0 and stamp_ns - last_stamp[s] > timeout_ns:
            slot_of_key[key] = -1
            key_of_slot[s] = -1
            counters[Counter.CHANNELS_DROPPED_TIMEOUT] += 1


@njit(cache=True)
def _track_epoch(method, stamp_ns, timeout_ns, const, svid, t, zi, zq, cn0, dphi, lock, cfg, slot_of_key,
                 key_of_slot, state, last_stamp, last_cn0, slips, was_locked, seen, call_id, counters, values):
    """All channels of one interval: life cycle, input checks, counters, filter steps (see CarrierTracker).

    Returns the number of rows written into values (one per accepted correlator, input order).
    """
    _drop_timed_out(stamp_ns, timeout_ns, slot_of_key, key_of_slot, last_stamp, counters)
    imm_out = np.empty(IMM_OUT_LEN)
    pll_out = np.empty(PLL_OUT_LEN)
    unit_noise = cfg[KernelConfig.UNIT_NOISE] > 0.5
    n_out = 0
    for k in range(const.shape[0]):
        c = const[k]
        sv = svid[k]
        if c < 0 or c > MAX_CONSTELLATION or sv <= 0 or sv > MAX_SVID:
            counters[Counter.REJECTED_INVALID_SVID] += 1
            continue
        key = c * 256 + sv
        if seen[key] == call_id:
            counters[Counter.REJECTED_DUPLICATE_CHANNEL] += 1
            continue
        seen[key] = call_id
        tk = t[k]
        if not (cfg[KernelConfig.T_MIN] <= tk <= cfg[KernelConfig.T_MAX]):  # NaN fails too
            counters[Counter.REJECTED_INTEGRATION_TIME] += 1
            continue
        i_k = zi[k]
        q_k = zq[k]
        if not (abs(i_k) < math.inf and abs(q_k) < math.inf):
            counters[Counter.REJECTED_NONFINITE_IQ] += 1
            continue
        d_k = dphi[k]
        if not abs(d_k) <= 2.0 * math.pi * MAX_PREDICTED_DOPPLER_HZ * tk:  # absurd or not finite
            counters[Counter.REJECTED_PREDICTED_PHASE] += 1
            continue
        slot = slot_of_key[key]
        c0 = cn0[k]
        if c0 != c0:
            if slot < 0:
                counters[Counter.REJECTED_CN0_MISSING] += 1
                continue
            c0 = last_cn0[slot]
            counters[Counter.CN0_MISSING_USED_LAST] += 1
        elif not (CN0_MIN_DBHZ <= c0 <= CN0_MAX_DBHZ):
            counters[Counter.REJECTED_CN0_RANGE] += 1
            continue
        amp, sig = amp_sigma(c0, tk, unit_noise)
        if math.hypot(i_k, q_k) > cfg[KernelConfig.IQ_RATIO] * math.sqrt(amp * amp + 2.0 * sig * sig):
            counters[Counter.REJECTED_IQ_MAGNITUDE] += 1
            continue
        if slot >= 0 and stamp_ns <= last_stamp[slot]:
            counters[Counter.REJECTED_STAMP_BACKWARDS] += 1
            continue
        if slot >= 0 and float(stamp_ns - last_stamp[slot]) > cfg[KernelConfig.MAX_GAP] * tk * 1e9:
            slot_of_key[key] = -1
            key_of_slot[slot] = -1
            counters[Counter.CHANNELS_RESTARTED_GAP] += 1
            slot = -1
        counters[Counter.PROCESSED] += 1
        if lock[k] == CORRELATOR_LOCK_LOST:
            counters[Counter.CORRELATOR_UNLOCKED] += 1
        elif lock[k] != CORRELATOR_LOCK_HELD:  # 0, or a code this version does not know
            counters[Counter.CORRELATOR_LOCK_UNKNOWN] += 1
        row = values[n_out]
        n_out += 1
        row[BatchColumn.CONSTELLATION] = c
        row[BatchColumn.SVID] = sv
        if slot < 0:
            _open_channel(method, key, stamp_ns, c0, i_k, q_k, d_k, cfg, row, slot_of_key, key_of_slot, last_stamp,
                          last_cn0, slips, was_locked, state, counters)
            continue
        last_stamp[slot] = stamp_ns
        last_cn0[slot] = c0
        st = state[slot]
        unlocked = lock[k] == CORRELATOR_LOCK_LOST
        slips_before = slips[slot]
        if method == _M_IMM:
            coast = unlocked and cfg[KernelConfig.COAST_UNLOCKED] > 0.5
            if coast:
                counters[Counter.COASTED_CORRELATOR_UNLOCKED] += 1
            finite, valid, locked = _imm_update(st, i_k, q_k, amp, sig, tk, d_k, stamp_ns, cfg, imm_out, row, slot,
                                                slips, counters, coast)
        else:
            finite, valid, locked = _pll_update(st, i_k, q_k, amp, tk, d_k, cfg, pll_out, row, slot, slips,
                                                was_locked, counters)
        row[BatchColumn.LOCKED] = 1.0 if locked else 0.0
        row[BatchColumn.CYCLE_SLIPS] = slips[slot]
        if unlocked:
            counters[Counter.LOCKED_ON_CORRELATOR_UNLOCKED] += 1 if locked else 0
            counters[Counter.SLIPS_ON_CORRELATOR_UNLOCKED] += slips[slot] - slips_before
        if not finite:  # the filter overflowed: restart on the next sample (answer published unlocked)
            slot_of_key[key] = -1
            key_of_slot[slot] = -1
            counters[Counter.CHANNELS_RESTARTED_NONFINITE] += 1
        elif not valid:  # numerically wild (collapsed covariance, aliased frequency, runaway phase): restart
            slot_of_key[key] = -1
            key_of_slot[slot] = -1
            counters[Counter.CHANNELS_RESTARTED_DIVERGED] += 1
    return n_out


class CarrierTracker:
    """Tracks every (constellation, svid) seen: starts a channel on first sight, drops it after a timeout.

    ``cycle_slips`` in the estimates counts slips *detected* on line: for the IMM, steps where the
    update moved the phase by more than ``slip_jump_threshold_rad``; for the PLL, losses of the lock
    indicator. True slips against truth are counted offline by cycle_slips.count_cycle_slips.

    Per correlator, in order (each failure counted under its ``rejected_*`` key, COUNTER_KEYS):

    1. (constellation, svid) a channel id (0 <= constellation <= 255, 0 < svid <= 255):
       ``rejected_invalid_svid``; not repeated in the interval: ``rejected_duplicate_channel``;
    2. T in [min_integration_time_s, max_integration_time_s] (the receiver's range; NaN fails):
       ``rejected_integration_time``;
    3. I and Q finite: ``rejected_nonfinite_iq``;
    4. |predicted phase change| <= 2 pi MAX_PREDICTED_DOPPLER_HZ T (finite and physical):
       ``rejected_predicted_phase``;
    5. C/N0 in [0, 70] dB-Hz: ``rejected_cn0_range``; NaN: the channel's last value
       (``cn0_missing_used_last``), or ``rejected_cn0_missing`` for a new channel;
    6. sqrt(I^2 + Q^2) at most max_iq_magnitude_ratio times the RMS that C/N0 and T give:
       ``rejected_iq_magnitude``;
    7. the stamp increases per channel: ``rejected_stamp_backwards``.

    A gap longer than max_gap_intervals restarts the channel. After each filter step the answer is
    checked: it is published locked only if phase and frequency are finite, the IMM's standard
    deviations finite and > 0, |phase| <= MAX_RESIDUAL_PHASE_RAD and |frequency| <= 1/T (a locked
    answer that fails is published unlocked and counted as ``locked_suppressed_invalid``). A channel
    whose state is not finite (``channels_restarted_nonfinite``) or fails these checks
    (``channels_restarted_diverged``) restarts from its next correlator, so a tracker thrown off by an
    input that passed the checks never publishes garbage for long. :meth:`reset_channels` restarts every
    channel (the node calls it on a confirmed stamp jump).

    The producer's own carrier lock (``carrier_lock``, rfi_msgs/Correlator CARRIER_LOCK_*) changes no check: a
    correlator reported LOST is tracked as any other (``correlator_unlocked`` "track") or, for the IMM with
    "coast", only predicted over (its I/Q unused); either way it is counted as ``correlator_unlocked``, its
    estimate if locked as ``locked_on_correlator_unlocked``, the slips detected on it as
    ``slips_on_correlator_unlocked``; a correlator whose lock is UNKNOWN (or an unknown code) as
    ``correlator_lock_unknown`` (docs/imm_carrier/correlator_lock.md). Nothing is raised for bad input; a new
    channel's first correlator only initialises it and is returned with locked = False.
    """

    _INITIAL_SLOTS = 64
    _key_of_slot: np.ndarray
    _state: np.ndarray
    _last_stamp: np.ndarray
    _last_cn0: np.ndarray
    _slips: np.ndarray
    _was_locked: np.ndarray

    def __init__(self, params: TrackerParams) -> None:
        if not isinstance(params, TrackerParams):
            raise ValueError("params must be a TrackerParams")
        self.params = params
        self._method_code = _M_IMM if params.method == "imm" else _M_PLL
        self._method = METHOD_IMM if params.method == "imm" else METHOD_PLL
        self._timeout_ns = int(params.channel_timeout_s * 1e9)
        imm, pll = params.imm, params.pll
        q_f, q_g = imm.q_phase
        cfg = np.zeros(KERNEL_CONFIG_LEN)
        cfg[KernelConfig.QF], cfg[KernelConfig.QG] = q_f, q_g
        cfg[KernelConfig.FORM] = PROCESS_NOISE_FORMS.index(imm.process_noise_form)
        unit_noise = imm.iq_scaling == "unit_noise" if params.method == "imm" else pll.iq_scaling == "unit_noise"
        cfg[KernelConfig.UNIT_NOISE] = 1.0 if unit_noise else 0.0
        cfg[KernelConfig.P_BIT] = imm.bit_transition_probability
        cfg[KernelConfig.BIT_PERIOD] = params.bit_period_s
        cfg[KernelConfig.INIT_PHASE_STD] = imm.initial_phase_std_rad
        cfg[KernelConfig.INIT_FREQ_STD] = imm.initial_frequency_std_hz
        cfg[KernelConfig.LOCK_STD] = imm.lock_phase_std_max_rad
        cfg[KernelConfig.SLIP_THR] = imm.slip_jump_threshold_rad
        cfg[KernelConfig.MAX_GAP] = params.max_gap_intervals
        cfg[KernelConfig.BW_START] = pll.start_bandwidth_hz
        cfg[KernelConfig.BW_END] = pll.end_bandwidth_hz
        cfg[KernelConfig.BW_DURATION] = pll.tightening_duration_s
        cfg[KernelConfig.LOCK_TC] = pll.lock_time_constant_s
        cfg[KernelConfig.LOCK_THR] = pll.lock_threshold
        cfg[KernelConfig.T_MIN] = params.min_integration_time_s
        cfg[KernelConfig.T_MAX] = params.max_integration_time_s
        cfg[KernelConfig.IQ_RATIO] = params.max_iq_magnitude_ratio
        cfg[KernelConfig.COAST_UNLOCKED] = 1.0 if params.correlator_unlocked == "coast" else 0.0
        self._cfg = cfg
        self._slot_of_key = np.full(_KEY_TABLE_SIZE, -1, dtype=np.int64)
        self._seen = np.zeros(_KEY_TABLE_SIZE, dtype=np.int64)
        self._call_id = 0
        self._counters = np.zeros(len(COUNTER_KEYS), dtype=np.int64)
        self._allocate(self._INITIAL_SLOTS)

    def _allocate(self, n_slots: int) -> None:
        """(Re)allocate the slot arrays with n_slots rows, keeping the live channels."""
        old = self._key_of_slot if hasattr(self, "_key_of_slot") else None
        key_of_slot = np.full(n_slots, -1, dtype=np.int64)
        state = np.zeros((n_slots, _STATE_WIDTH))
        last_stamp = np.zeros(n_slots, dtype=np.int64)
        last_cn0 = np.zeros(n_slots)
        slips = np.zeros(n_slots, dtype=np.int64)
        was_locked = np.zeros(n_slots, dtype=np.bool_)
        if old is not None:
            m = old.size
            key_of_slot[:m] = old
            state[:m] = self._state
            last_stamp[:m] = self._last_stamp
            last_cn0[:m] = self._last_cn0
            slips[:m] = self._slips
            was_locked[:m] = self._was_locked
        self._key_of_slot, self._state, self._last_stamp = key_of_slot, state, last_stamp
        self._last_cn0, self._slips, self._was_locked = last_cn0, slips, was_locked

    @property
    def counters(self) -> dict[str, int]:
        """Copy of the counters (see COUNTER_KEYS)."""
        return dict(zip(COUNTER_KEYS, self._counters.tolist(), strict=True))

    @property
    def rejected_total(self) -> int:
        """Sum of the ``rejected_*`` counters (cheap; for the node's per-message check)."""
        return int(self._counters[_REJECTED_INDICES].sum())

    @property
    def channel_keys(self) -> tuple[tuple[int, int], ...]:
        """(constellation, svid) of the live channels."""
        return tuple((k // 256, k % 256) for k in self._key_of_slot.tolist() if k >= 0)

    def reset_channels(self) -> int:
        """Drop every channel (each restarts from its next correlator); counted as
        ``channels_restarted_stamp_jump``. Returns the number of channels dropped."""
        live = self._key_of_slot >= 0
        n = int(np.count_nonzero(live))
        self._slot_of_key[self._key_of_slot[live]] = -1
        self._key_of_slot[live] = -1
        self._counters[Counter.CHANNELS_RESTARTED_STAMP_JUMP] += n
        return n

    @property
    def channel_count(self) -> int:
        """Number of live channels."""
        return int(np.count_nonzero(self._key_of_slot >= 0))

    def _transition_probability(self, stamp_ns: int, t_s: float) -> float:
        """The IMM's bit-transition probability for the interval ending at stamp_ns (ns) of length t_s (s)."""
        return float(
            _transition_probability(
                int(stamp_ns), float(t_s), self.params.imm.bit_transition_probability, self.params.bit_period_s
            )
        )

    def process_arrays(
        self,
        stamp_ns: int,
        constellation: np.ndarray,
        svid: np.ndarray,
        integration_time_s: np.ndarray,
        in_phase: np.ndarray,
        quadrature: np.ndarray,
        cn0_dbhz: np.ndarray,
        predicted_phase_change_rad: np.ndarray,
        carrier_lock: np.ndarray | None = None,
    ) -> CarrierPhaseBatch:
        """Process the correlators of one interval, given as arrays (one element per channel).

        Args:
            stamp_ns: end of the integration interval, ns (int).
            constellation: constellation codes, shape (n,), integers.
            svid: satellite numbers, shape (n,), integers.
            integration_time_s: T, s, shape (n,).
            in_phase, quadrature: prompt I and Q, correlator units, shape (n,).
            cn0_dbhz: C/N0, dB-Hz, shape (n,) (NaN: unknown).
            predicted_phase_change_rad: satellite-motion phase change over the interval, rad, shape (n,).
            carrier_lock: the producer's carrier lock, rfi_msgs/Correlator CARRIER_LOCK_* codes (0 unknown,
                1 lost, 2 held), shape (n,), integers; None: all unknown.

        Returns:
            CarrierPhaseBatch with one row per accepted correlator, in input order. Rejections are
            counted (``counters``). The counters change only if the call returns: should the compiled
            core raise, they are left as they were before the call.

        Raises:
            ValueError: arrays of different lengths or not 1-D.
        """
        const = np.asarray(constellation, dtype=np.int64)
        n = const.shape[0] if const.ndim == 1 else -1
        sv = np.asarray(svid, dtype=np.int64)
        t, zi, zq, cn0, dphi = (np.ascontiguousarray(a, dtype=np.float64) for a in
                                (integration_time_s, in_phase, quadrature, cn0_dbhz, predicted_phase_change_rad))
        lock = (np.zeros(max(n, 0), dtype=np.int64) if carrier_lock is None
                else np.ascontiguousarray(carrier_lock, dtype=np.int64))
        if n < 0 or sv.shape != (n,) or any(a.shape != (n,) for a in (t, zi, zq, cn0, dphi, lock)):
            raise ValueError("the correlator arrays must be 1-D and of equal length")
        live = int(np.count_nonzero(self._key_of_slot >= 0))
        if live + n > self._key_of_slot.size:
            self._allocate(max(2 * self._key_of_slot.size, live + n))
        self._call_id += 1
        counters = self._counters.copy()
        values = np.empty((n, N_BATCH_COLUMNS))
        n_out = _track_epoch(
            self._method_code,
            int(stamp_ns),
            self._timeout_ns,
            np.ascontiguousarray(const),
            np.ascontiguousarray(sv),
            t,
            zi,
            zq,
            cn0,
            dphi,
            lock,
            self._cfg,
            self._slot_of_key,
            self._key_of_slot,
            self._state,
            self._last_stamp,
            self._last_cn0,
            self._slips,
            self._was_locked,
            self._seen,
            self._call_id,
            counters,
            values,
        )
        self._counters = counters
        return CarrierPhaseBatch(int(stamp_ns), self._method, values[:n_out])

    def process(self, stamp_ns: int, samples: Sequence[CorrelatorSample]) -> tuple[CarrierPhaseEstimate, ...]:
        """Process the correlators of one interval given as CorrelatorSample (see :meth:`process_arrays`).

        Args:
            stamp_ns: end of the integration interval, ns (int).
            samples: correlators of the channels, at most one per (constellation, svid).

        Returns:
            One estimate per accepted sample (rejected samples are counted, not returned). A new
            channel's first sample only initialises it and is returned with locked=False.
        """
        def ident(v: int) -> int:  # ids beyond int64 are invalid anyway: map them to -1 (rejected)
            v = int(v)
            return v if -1 <= v < 2**31 else -1

        batch = self.process_arrays(
            stamp_ns,
            np.array([ident(s.constellation) for s in samples], dtype=np.int64),
            np.array([ident(s.svid) for s in samples], dtype=np.int64),
            np.array([s.integration_time_s for s in samples], dtype=np.float64),
            np.array([s.in_phase for s in samples], dtype=np.float64),
            np.array([s.quadrature for s in samples], dtype=np.float64),
            np.array([s.cn0_dbhz for s in samples], dtype=np.float64),
            np.array([s.predicted_phase_change_rad for s in samples], dtype=np.float64),
            np.array([s.carrier_lock for s in samples], dtype=np.int64),
        )
        return batch.to_estimates()

"""The receiver behind gnss_correlator_node (pure: no rclpy): IF blocks in, one correlator array per 1-ms
interval out, in the form imm_carrier consumes.

Life cycle of a stream
----------------------
* The first block, a change of sample rate, IF or sample type, or a gap / overlap in
  ``first_sample_index`` (counted: ``restarts_format``, ``restarts_gap``) (re)starts the receiver: every
  channel is dropped and ``acquisition_ms`` of samples are buffered.
* When the buffer is full, GPS L1 C/A acquisition (:mod:`gnss_correlator.acquisition`) searches every PRN of
  ``prns``; each PRN detected gets a channel (:class:`gnss_correlator.tracking.Tracker`) started on the
  buffer's first sample, and the buffer itself is tracked, so no sample is lost.
* Every ``reacquisition_period_s`` of stream time, the PRNs not tracked are searched again on the latest
  ``acquisition_ms`` of samples, in a worker thread while the tracked channels go on; the channels it finds
  start at the first block that begins ``reacquisition_lag_s`` of stream time after that window's end (code
  phase carried forward from the window), the receiver waiting for the search there only if it has not
  finished. So the outputs do not depend on how fast the machine is (replays are repeatable), and a search
  that takes less than the lag never delays a block.
* A channel whose C/N0 estimate stays below ``min_cn0_dbhz`` (or unknown) for ``drop_after_ms`` periods in a
  row after its first estimate is dropped (``channels_dropped``); its PRN can be found again.

The first acquisition of a stream (0.3-6 s of CPU at 4-16 MHz for 32 PRNs) runs in the same worker thread
while the caller goes on handing in blocks: they are checked (format, gap) and held, up to
``acquisition_hold_s`` of stream, without being tracked (``blocks_held``); when the search is done, the next
:meth:`Receiver.process` or :meth:`Receiver.poll` starts its channels on the window's first sample and replays the
window and the held blocks one by one through the path a synchronous search would have taken (``max_blocks`` per
poll, ``replay_per_block`` per block handed in meanwhile, so that the caller takes new input between the calls and
its outputs do not leave in one burst), so the intervals are the same, whatever the search's duration and however
the replay is sliced (the node polls when the worker says it is done, and hands in new blocks without replaying:
``replay_per_block`` 0). The hold is bounded: a block handed in while the held blocks reach ``acquisition_hold_s``
of stream makes the caller wait for the search if it is still running (``acquisition_waits``), or count the bound
reached after it (``hold_bound_replays``), and replays two held blocks, one more than came in, so the hold never
grows past the bound by more than a block; with ``acquisition_hold_s`` 0 the search runs in the caller's thread
(the synchronous path). Held samples are kept in
single precision when that is exact (2- to 16-bit counts times a power-of-two scale always are).
:meth:`Receiver.close` stops the worker.

Output: correlator intervals and the NCO
----------------------------------------
The stream is cut on a 1-ms grid from the first sample of the (re)start, ``g_k = s0 + k fs / 1000`` (sample
indices). Each channel's code period (1 ms of the satellite's code, which drifts against the receiver's
grid by the code Doppler) goes into the interval of the grid in which it ends, at most one per channel per
interval (a second one, once every few hundred seconds of code drift, waits for the next interval). An
interval is emitted when the stream has passed its end; its stamp is the time of ``g_k`` from the header
stamps (the latest block's stamp plus the samples since its first one over fs). A channel's period ends
within the 1 ms before the stamp; each correlator carries its own ``integration_time_s`` (samples / fs).

Each correlator is what imm_carrier's measurement model (Zhao et al., eq. 2-3) takes, with the receiver's
carrier NCO in the role of the simulator's open-loop replica:

    I + jQ = P e^{j phi_nco,k} / s,      predicted_phase_change_rad = phi_nco,k - phi_nco,k-1 = 2 pi f_nco,k T_k,

with P the prompt (relative to the NCO), phi_nco,k the NCO's accumulated Doppler phase at the period's end
and f_nco,k its Doppler during the period. So the angle of I + jQ is the carrier's Doppler phase
(the NCO's phase plus what the NCO missed), and the phase the IMM or the PLL estimates, the angle minus the
accumulated predicted change, is the correlator's own tracking error plus a constant: the part of the carrier
that the correlator's NCO did not follow. The NCO runs whatever the IMM does (no feedback from the IMM
to the correlator). ``s`` normalises the amplitude as ``iq_scaling`` says, from the C/N0 estimate over the
last ``cn0_window_ms`` periods (the noise-reference estimator of :mod:`gnss_correlator.tracking`: signal power
from the prompts, noise power from the noise-reference correlator, so a jammer's residue counts as noise):
``unit_amplitude`` (A = 1, Zhao et al. eq. 5: s = sqrt(P_s)) or
``unit_noise`` (noise std 1 per component: s = sqrt(P_n / 2)). Periods whose C/N0 is not known yet (the
first ``cn0_window_ms`` of a channel) are withheld (``correlators_withheld``).

Bit synchronisation and 20-ms intervals
---------------------------------------
Every channel's prompts feed :class:`gnss_correlator.bit_sync.BitSync` (histogram of sign changes on the
20-period grid; its decision rule in that module; ``bit_syncs`` counted). With ``coherent_ms`` 20, a synchronised
channel publishes one correlator per data bit: the 20 NCO-relative prompts from a bit edge summed (the data sign
is constant over them), rotated by the NCO's phase at the bit's end, ``predicted_phase_change_rad`` and
``integration_time_s`` summed over the 20 periods, scaled as ``iq_scaling`` says with the noise of the sum
(20 P_n); it goes into the 1-ms interval in which the bit's last period ends (``correlators_20ms``). Until the
decision, and from it to the next bit edge, the channel's correlators are 1 ms, so the predicted changes of
consecutive correlators join without a gap. C/N0 and the lock fields of a 20-ms correlator are those of its
last period.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from gnss_correlator.acquisition import AcquisitionConfig, AcquisitionResult, acquire
from gnss_correlator.bit_sync import PERIODS_PER_BIT, BitSync, BitSyncConfig
from gnss_correlator.tracked_periods import TrackedPeriods
from gnss_correlator.tracking import Tracker, TrackingConfig

NS_PER_S = 1_000_000_000
GRID_S = 1e-3
"""Output interval, s (one C/A code period)."""
IQ_SCALINGS = ('unit_amplitude', 'unit_noise')
COHERENT_MS = (1, 20)
"""Coherent intervals the receiver publishes: 1 ms, or 20 ms (one data bit) once the channel is bit-synchronised."""


@dataclass(frozen=True)
class ReceiverConfig:
    """What the receiver searches and how it tracks (see the module docstring).

    Attributes:
        prns: PRNs searched.
        acquisition_ms: ms of samples per acquisition (non-coherent 1-ms sums), >= 2.
        doppler_max_hz: acquisition's Doppler range +-, Hz.
        false_alarm_probability: acquisition's P_fa per satellite search.
        reacquisition_period_s: stream time between searches for untracked PRNs, s (> 0).
        reacquisition_lag_s: stream time from the end of a reacquisition's window to the block where its
            channels start, s (>= 0); the search runs in a worker thread meanwhile (module docstring).
        tracking: loop parameters.
        min_cn0_dbhz: a channel below this C/N0 for drop_after_ms periods is dropped, dB-Hz.
        drop_after_ms: periods in a row below min_cn0_dbhz before a drop, >= 1.
        iq_scaling: 'unit_amplitude' or 'unit_noise' (match imm_carrier's iq_scaling).
        spectrum_inverted: complex samples whose spectrum is inverted (the signal is I - jQ): they are
            conjugated first. Real samples say it with a negative IF instead.
        coherent_ms: 1, or 20: once a channel is bit-synchronised (:mod:`gnss_correlator.bit_sync`), one
            correlator per data bit (the 20 code periods from a bit edge summed coherently), 1-ms ones before.
        bit_sync: the decision rule of the bit synchronisation.
        acquisition_hold_s: stream time held while the first acquisition runs in the worker, s (>= 0; 0: the
            first acquisition in the caller's thread); module docstring.
    """

    prns: tuple[int, ...] = tuple(range(1, 33))
    acquisition_ms: int = 10
    doppler_max_hz: float = 5000.0
    false_alarm_probability: float = 1e-3
    reacquisition_period_s: float = 10.0
    reacquisition_lag_s: float = 1.0
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    min_cn0_dbhz: float = 30.0
    drop_after_ms: int = 200
    iq_scaling: str = 'unit_amplitude'
    spectrum_inverted: bool = False
    coherent_ms: int = 1
    bit_sync: BitSyncConfig = field(default_factory=BitSyncConfig)
    acquisition_hold_s: float = 4.0

    def __post_init__(self) -> None:
        if self.acquisition_ms < 2:
            raise ValueError(f'acquisition_ms must be >= 2, got {self.acquisition_ms}')
        if not self.reacquisition_period_s > 0:
            raise ValueError(f'reacquisition_period_s must be > 0, got {self.reacquisition_period_s}')
        if not self.reacquisition_lag_s >= 0:
            raise ValueError(f'reacquisition_lag_s must be >= 0, got {self.reacquisition_lag_s}')
        if self.drop_after_ms < 1:
            raise ValueError(f'drop_after_ms must be >= 1, got {self.drop_after_ms}')
        if self.iq_scaling not in IQ_SCALINGS:
            raise ValueError(f'iq_scaling must be one of {IQ_SCALINGS}, got {self.iq_scaling!r}')
        if not self.acquisition_hold_s >= 0:
            raise ValueError(f'acquisition_hold_s must be >= 0, got {self.acquisition_hold_s}')
        if self.coherent_ms not in COHERENT_MS:
            raise ValueError(f'coherent_ms must be one of {COHERENT_MS}, got {self.coherent_ms}')
        self.acquisition()  # validates the search parameters

    def acquisition(self) -> AcquisitionConfig:
        """The acquisition's configuration."""
        return AcquisitionConfig(prns=self.prns, noncoherent_count=self.acquisition_ms,
                                 doppler_max_hz=self.doppler_max_hz,
                                 false_alarm_probability=self.false_alarm_probability)


@dataclass(frozen=True)
class IfBlock:
    """One block of the front end's stream, decoded (the node's IfSamples after its checks).

    Attributes:
        stamp_ns: time of the first sample, ns (header.stamp).
        sample_rate_hz: fs, Hz.
        intermediate_frequency_hz: IF, Hz.
        is_complex: complex samples.
        first_sample_index: absolute index of the first sample.
        samples: values, float64 (n,) real or complex128 (n,).
    """

    stamp_ns: int
    sample_rate_hz: float
    intermediate_frequency_hz: float
    is_complex: bool
    first_sample_index: int
    samples: np.ndarray = field(repr=False)


@dataclass
class _FirstSearch:
    """A first acquisition running in the worker: its window (first sample ``start``, the buffer when it was
    full, tracked from its first sample once the search is done) and the blocks held since (samples, first sample
    index, stamp in ns)."""

    future: Future[list[AcquisitionResult]]
    window: np.ndarray
    start: int
    held: list[tuple[np.ndarray, int, int]] = field(default_factory=list)
    held_samples: int = 0
    started: bool = False  # the search's channels started, its window tracked; the held blocks being replayed


def _compact(x: np.ndarray) -> np.ndarray:
    """``x`` in single precision when that is exact (a held block's memory halved), else ``x``."""
    small = x.astype(np.complex64 if np.iscomplexobj(x) else np.float32)
    return small if np.array_equal(small, x) else x


@dataclass(frozen=True)
class CorrelatorInterval:
    """The correlators of one 1-ms output interval (one CorrelatorArray).

    Attributes:
        stamp_ns: end of the interval, ns (from the header stamps).
        svid, in_phase, quadrature, cn0_dbhz, predicted_phase_change_rad, integration_time_s: one entry per
            channel with a period in the interval, shape (n,) each (module docstring); ``cn0_dbhz`` is the
            noise-reference estimate (:mod:`gnss_correlator.tracking`), the one CorrelatorArray carries.
        locked: the correlator's own PLL locked by the lock rule of :mod:`gnss_correlator.tracking` (discriminator
            std and no half-cycle wrap over the last ``lock_window_ms``), bool, shape (n,).
        phase_error_std_rad: that window's discriminator std, rad, shape (n,) (NaN until the window is full).
        half_cycle_wraps: that window's half-cycle wraps (slip candidates), shape (n,) (NaN until full).
        pll_error_rad: the period's Costas discriminator atan(Q/I), rad, shape (n,): the correlator's own carrier
            phase estimate is the accumulated predicted change plus this (modulo pi).
        cn0_m2m4_dbhz: the moments estimator's C/N0 of the same window, dB-Hz, shape (n,) (for comparison).
    ``locked`` is published as Correlator.carrier_lock (correlator_cdr.carrier_lock_codes: UNKNOWN while
    the window is not full); the other lock fields are not published: read by the core's users and the benchmarks.
    """

    stamp_ns: int
    svid: np.ndarray
    in_phase: np.ndarray
    quadrature: np.ndarray
    cn0_dbhz: np.ndarray
    predicted_phase_change_rad: np.ndarray
    integration_time_s: np.ndarray
    locked: np.ndarray
    phase_error_std_rad: np.ndarray
    half_cycle_wraps: np.ndarray
    pll_error_rad: np.ndarray
    cn0_m2m4_dbhz: np.ndarray


class Receiver:
    """Acquisition, tracking and the 1-ms output grid of one stream (module docstring)."""

    def __init__(self, config: ReceiverConfig = ReceiverConfig(),
                 on_search_done: Callable[[], None] | None = None, replay_per_block: int = 2) -> None:
        """``on_search_done``: called (in the worker thread) when a first acquisition running in the worker
        ends, so that the caller can :meth:`poll` (the node triggers a guard condition). ``replay_per_block``:
        held blocks replayed by each :meth:`process` call once that search is done (>= 0; 0: only :meth:`poll`
        replays them, and :meth:`process` only when the hold is at its bound), module docstring."""
        if replay_per_block < 0:
            raise ValueError(f'replay_per_block must be >= 0, got {replay_per_block}')
        self.config = config
        self.on_search_done = on_search_done
        self.replay_per_block = replay_per_block
        self.counts: Counter[str] = Counter()
        for key in ('blocks', 'samples', 'restarts_format', 'restarts_gap', 'acquisitions', 'channels_started',
                    'channels_dropped', 'intervals', 'correlators', 'correlators_withheld', 'bit_syncs',
                    'correlators_20ms', 'blocks_held', 'acquisition_waits', 'hold_bound_replays'):
            self.counts[key] += 0
        self._format: tuple[float, float, bool] | None = None
        self.tracker: Tracker | None = None
        self._pool: ThreadPoolExecutor | None = None
        self._reacquisition: tuple[Future[list[AcquisitionResult]], int, int] | None = None
        self._first: _FirstSearch | None = None
        self._reset_stream()

    def close(self) -> None:
        """Stop the acquisition worker (a search running is abandoned, the blocks held dropped)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        self._reacquisition = None
        self._first = None

    @property
    def acquiring(self) -> bool:
        """Whether a first acquisition runs in the worker or blocks are still held after it (:meth:`poll` when
        it is done, until this is false)."""
        return self._first is not None

    @property
    def poll_ready(self) -> bool:
        """Whether :meth:`poll` would answer now: the first acquisition is done and blocks are held."""
        return self._first is not None and self._first.future.done()

    @property
    def blocks_held(self) -> int:
        """Blocks held now, waiting for the first acquisition."""
        return len(self._first.held) if self._first is not None else 0

    def _worker(self) -> ThreadPoolExecutor:
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='gnss_correlator_acquisition')
        return self._pool

    def _reset_stream(self) -> None:
        if getattr(self, '_reacquisition', None) is not None:
            self._reacquisition[0].cancel()  # type: ignore[index]
        self._reacquisition = None
        if self._first is not None:
            self._first.future.cancel()
        self._first = None
        self.tracker = None
        self._expected_index: int | None = None
        self._buffer: list[np.ndarray] = []
        self._next_index: int | None = None
        self._grid_origin = 0
        self._next_grid = 1  # index k of the next interval to emit (its end is origin + k fs / 1000)
        self._pending: dict[int, list[tuple[float, np.ndarray]]] = {}
        self._last_grid: dict[int, int] = {}
        self._low_cn0: dict[int, int] = {}
        self._ref_stamp_ns = 0
        self._ref_index = 0
        self.bit_sync = BitSync(self.config.bit_sync)
        self._bits: dict[int, list[np.ndarray]] = {}  # PRN -> rows of the data bit being summed
        self._next_search_index = 0

    @property
    def tracked_prns(self) -> tuple[int, ...]:
        """PRNs tracked now."""
        return self.tracker.prns if self.tracker is not None else ()

    def process(self, block: IfBlock) -> list[CorrelatorInterval]:
        """One block of the stream; returns the intervals completed by it (possibly none).

        Raises:
            ValueError: samples whose type does not match ``is_complex``, or non-finite samples.
        """
        x = np.asarray(block.samples)
        if bool(np.iscomplexobj(x)) != block.is_complex or x.ndim != 1:
            raise ValueError('samples must be one-dimensional, complex iff is_complex')
        if not np.all(np.isfinite(x)):
            raise ValueError('samples hold NaN or infinity')
        if block.is_complex and self.config.spectrum_inverted:
            x = np.conj(x)
        fmt = (float(block.sample_rate_hz), float(block.intermediate_frequency_hz), bool(block.is_complex))
        if self._format is not None and fmt != self._format:
            self.counts['restarts_format'] += 1
            self._reset_stream()
        elif self._expected_index is not None and block.first_sample_index != self._expected_index:
            self.counts['restarts_gap'] += 1
            self._reset_stream()
        self._format = fmt
        fs = fmt[0]
        self.counts['blocks'] += 1
        self.counts['samples'] += x.size
        self._expected_index = int(block.first_sample_index) + x.size
        first = self._first
        if first is None:
            return self._advance(x, int(block.first_sample_index), int(block.stamp_ns))
        first.held.append((_compact(x), int(block.first_sample_index), int(block.stamp_ns)))
        first.held_samples += x.size
        self.counts['blocks_held'] += 1
        if first.held_samples >= self.config.acquisition_hold_s * fs:  # the bound: the hold shrinks by one block
            if first.future.done():                                   # more than came in
                self.counts['hold_bound_replays'] += 1
            else:
                self.counts['acquisition_waits'] += 1
            return self._finish_first_search(2)
        if first.future.done() and self.replay_per_block:
            return self._finish_first_search(self.replay_per_block)
        return []

    def poll(self, wait: bool = False, max_blocks: int | None = None) -> list[CorrelatorInterval]:
        """The intervals of the window and of the blocks held, once the first acquisition in the worker is done
        (none before, nor when none runs; ``wait``: wait for it, as at the end of a replay); at most
        ``max_blocks`` held blocks per call (all: None), so that a caller can take new input between the calls
        (:attr:`acquiring` stays true while blocks are held). Raises what the search raised."""
        if self._first is not None and (wait or self._first.future.done()):
            return self._finish_first_search(max_blocks)
        return []

    def _finish_first_search(self, max_blocks: int | None = None) -> list[CorrelatorInterval]:
        """Wait for the first acquisition; once: start its channels, track its window; then replay up to
        ``max_blocks`` of the blocks held (all: None), in their order."""
        first = self._first
        assert first is not None
        out: list[CorrelatorInterval] = []
        if not first.started:
            results = first.future.result()  # waits only when the hold is full (process counted it)
            first.started = True
            out = self._first_window(first.window, first.start, results)
        count = len(first.held) if max_blocks is None else min(max_blocks, len(first.held))
        replay, first.held = first.held[:count], first.held[count:]
        for x, index, stamp in replay:
            first.held_samples -= x.size
            out.extend(self._advance(np.asarray(x, dtype=first.window.dtype), index, stamp))
        if not first.held:
            self._first = None
        return out

    def _first_window(self, window: np.ndarray, start: int,
                      results: list[AcquisitionResult]) -> list[CorrelatorInterval]:
        """The first acquisition's ``results`` on ``window`` (first sample ``start``): channels started, the
        window tracked."""
        assert self._format is not None
        fs, if_hz, is_complex = self._format
        self.tracker = Tracker(fs, if_hz, is_complex, self.config.tracking)
        self._start_channels(results, start)
        self._next_search_index = start + round(self.config.reacquisition_period_s * fs)
        return self._after_tracking(self.tracker.process(window, start), fs)

    def _advance(self, x: np.ndarray, first_index: int, stamp_ns: int) -> list[CorrelatorInterval]:
        """One checked block (``x`` from sample ``first_index``, stamped ``stamp_ns``) through acquisition and
        tracking."""
        assert self._format is not None
        fs = self._format[0]
        if self._next_index is None:
            self._grid_origin = first_index
            self._next_search_index = first_index
        self._next_index = first_index + x.size
        self._ref_stamp_ns, self._ref_index = stamp_ns, first_index
        need = math.ceil(self.config.acquisition_ms * GRID_S * fs)
        self._buffer.append(x)
        buffered = sum(b.size for b in self._buffer)
        # keep only the latest acquisition window once tracking runs
        if self.tracker is None:
            if buffered < need:
                return []
            window = np.concatenate(self._buffer)
            self._buffer = [window[-need:]]
            start = self._next_index - window.size
            self.counts['acquisitions'] += 1
            cfg = self._config_for(None)
            if self.config.acquisition_hold_s > 0:
                future = self._worker().submit(acquire, window[:need].copy(), fs, self._format[1], cfg)
                self._first = _FirstSearch(future=future, window=window, start=start)
                if self.on_search_done is not None:
                    notify = self.on_search_done
                    future.add_done_callback(lambda _: notify())
                return []
            return self._first_window(window, start, acquire(window[:need], fs, self._format[1], cfg))
        assert self._next_index is not None
        if self._reacquisition is not None and first_index >= self._reacquisition[2]:
            future, start, _ = self._reacquisition
            self._reacquisition = None
            self._start_channels(future.result(), start)
        periods = self.tracker.process(x, first_index)
        if buffered > need:
            joined = np.concatenate(self._buffer)[-need:]
            self._buffer = [joined]
        if self._next_index >= self._next_search_index and self._reacquisition is None:
            untracked = tuple(p for p in self.config.prns if p not in self.tracker.prns)
            if untracked and buffered >= need:
                self._reacquire(self._buffer[-1].copy(), self._next_index - need, untracked)
            self._next_search_index = self._next_index + round(self.config.reacquisition_period_s * fs)
        return self._after_tracking(periods, fs)

    def _after_tracking(self, periods: TrackedPeriods, fs: float) -> list[CorrelatorInterval]:
        """Bit sync, the output queues, weak channels dropped; the intervals completed."""
        synced = {p for p in self.tracked_prns if self.bit_sync.edge(p) is not None}
        self.bit_sync.update(periods)
        self.counts['bit_syncs'] += sum(1 for p in self.tracked_prns
                                        if p not in synced and self.bit_sync.edge(p) is not None)
        self._queue(periods, fs)
        self._drop_weak(periods)
        return self._emit(fs)

    def _config_for(self, prns: tuple[int, ...] | None) -> AcquisitionConfig:
        cfg = self.config.acquisition()
        if prns is None:
            return cfg
        return AcquisitionConfig(prns=prns, noncoherent_count=cfg.noncoherent_count, doppler_max_hz=cfg.doppler_max_hz,
                                 false_alarm_probability=cfg.false_alarm_probability)

    def _reacquire(self, window: np.ndarray, start: int, prns: tuple[int, ...]) -> None:
        """Search ``prns`` on ``window`` (an owned copy; first sample ``start``) in the worker thread; its
        channels start at the first block from ``start + window + lag`` on (module docstring)."""
        assert self._format is not None
        self.counts['acquisitions'] += 1
        future = self._worker().submit(acquire, window, self._format[0], self._format[1], self._config_for(prns))
        apply_at = start + window.size + round(self.config.reacquisition_lag_s * self._format[0])
        self._reacquisition = (future, start, apply_at)

    def _start_channels(self, results: list[AcquisitionResult], start: int) -> None:
        """A channel per detected PRN not tracked yet, its code phase referred to sample ``start``."""
        assert self.tracker is not None
        for r in results:
            if r.detected and r.prn not in self.tracker.prns:
                self.tracker.add_channel(r.prn, r.code_delay_samples, r.doppler_hz, start)
                self.counts['channels_started'] += 1
                self._low_cn0[r.prn] = 0
                self._pending.setdefault(r.prn, [])

    def _queue(self, periods: TrackedPeriods, fs: float) -> None:
        if self.config.iq_scaling == 'unit_noise':
            scale = np.sqrt(periods.noise_power / 2.0)
        else:
            t = periods.n_samples / fs
            scale = np.sqrt(periods.noise_power * 10.0 ** (periods.cn0_dbhz / 10.0) * t)
        with np.errstate(invalid='ignore', divide='ignore'):  # NaN scale: C/N0 not known yet (withheld)
            iq = periods.prompt * np.exp(1j * np.mod(periods.nco_phase_rad, 2.0 * np.pi)) / scale
        dphi = 2.0 * np.pi * periods.doppler_hz * periods.n_samples / fs
        usable = np.isfinite(periods.cn0_dbhz) & np.isfinite(scale) & (scale > 0)
        self.counts['correlators_withheld'] += int(np.count_nonzero(~usable))
        for j in np.flatnonzero(usable):
            prn = int(periods.prn[j])
            row = np.array([iq[j].real, iq[j].imag, periods.cn0_dbhz[j], dphi[j], periods.n_samples[j] / fs,
                            float(periods.locked[j]), periods.phase_error_std_rad[j], periods.half_cycle_wraps[j],
                            periods.pll_error_rad[j], periods.cn0_m2m4_dbhz[j]])
            edge = self.bit_sync.edge(prn) if self.config.coherent_ms == 20 else None
            if edge is None:
                self._pending.setdefault(prn, []).append((float(periods.end_index[j]), row))
                continue
            k = int(periods.period[j])
            bit = self._bits.setdefault(prn, [])
            if k % PERIODS_PER_BIT == edge:
                bit.clear()  # a bit starts
            elif not bit:  # between the decision and the next edge: still 1 ms
                self._pending.setdefault(prn, []).append((float(periods.end_index[j]), row))
                continue
            # the prompt relative to the NCO, its noise power and the NCO phase, to be summed over the bit
            bit.append(np.array([periods.prompt[j].real, periods.prompt[j].imag, periods.noise_power[j],
                                 periods.nco_phase_rad[j], dphi[j], periods.n_samples[j] / fs, periods.cn0_dbhz[j],
                                 row[5], row[6], row[7], row[8], row[9]]))
            if len(bit) == PERIODS_PER_BIT:
                self._pending.setdefault(prn, []).append((float(periods.end_index[j]), self._bit_row(bit)))
                self.counts['correlators_20ms'] += 1
                bit.clear()

    def _bit_row(self, bit: list[np.ndarray]) -> np.ndarray:
        """One correlator of a whole data bit: the NCO-relative prompts summed (coherent over the bit: the data
        sign is constant), rotated by the NCO's phase at the bit's end, scaled as ``iq_scaling`` says with the
        noise power of the sum (20 periods' worth); predicted change and T summed; C/N0 and lock of the last
        period."""
        b = np.array(bit)
        z = complex(b[:, 0].sum(), b[:, 1].sum()) * np.exp(1j * np.mod(b[-1, 3], 2.0 * np.pi))
        t = float(b[:, 5].sum())
        noise = float(b[-1, 2]) * len(bit)
        cn0 = float(b[-1, 6])
        if self.config.iq_scaling == 'unit_noise':
            scale = math.sqrt(noise / 2.0)
        else:
            scale = math.sqrt(noise * 10.0 ** (cn0 / 10.0) * t)
        return np.array([z.real / scale, z.imag / scale, cn0, float(b[:, 4].sum()), t, *b[-1, 7:12]])

    def _drop_weak(self, periods: TrackedPeriods) -> None:
        assert self.tracker is not None
        for prn in np.unique(periods.prn):
            o = periods.of(int(prn))
            for cn0, full in zip(o.cn0_dbhz, o.period > self.config.tracking.cn0_window_ms, strict=True):
                if full:
                    weak = not cn0 >= self.config.min_cn0_dbhz
                    self._low_cn0[int(prn)] = self._low_cn0.get(int(prn), 0) + 1 if weak else 0
            if self._low_cn0.get(int(prn), 0) >= self.config.drop_after_ms:
                self.tracker.drop_channel(int(prn))
                self.bit_sync.forget(int(prn))
                self._bits.pop(int(prn), None)
                self.counts['channels_dropped'] += 1
                self._low_cn0.pop(int(prn), None)

    def _emit(self, fs: float) -> list[CorrelatorInterval]:
        assert self._next_index is not None
        step = fs * GRID_S
        out = []
        while self._grid_origin + self._next_grid * step <= self._next_index:
            k = self._next_grid
            end = self._grid_origin + k * step
            rows, svids = [], []
            for prn, queue in self._pending.items():
                if queue and queue[0][0] <= end:
                    _, row = queue.pop(0)
                    rows.append(row)
                    svids.append(prn)
                    self._last_grid[prn] = k
            self._next_grid += 1
            if not rows:
                continue
            table = np.array(rows)
            stamp = self._ref_stamp_ns + round((end - self._ref_index) / fs * NS_PER_S)
            out.append(CorrelatorInterval(
                stamp_ns=int(stamp), svid=np.array(svids, dtype=np.int64), in_phase=table[:, 0],
                quadrature=table[:, 1], cn0_dbhz=table[:, 2], predicted_phase_change_rad=table[:, 3],
                integration_time_s=table[:, 4], locked=table[:, 5] > 0.5, phase_error_std_rad=table[:, 6],
                half_cycle_wraps=table[:, 7], pll_error_rad=table[:, 8], cn0_m2m4_dbhz=table[:, 9]))
            self.counts['intervals'] += 1
            self.counts['correlators'] += len(rows)
        # channels no longer tracked: their queues go
        tracked = set(self.tracked_prns)
        for prn in [p for p in self._pending if p not in tracked and not self._pending[p]]:
            del self._pending[prn]
        return out


def continues(previous: IfBlock, block: IfBlock) -> bool:
    """Whether ``block`` follows ``previous`` in one stream: the next sample index, the same rate, IF and type."""
    return (block.first_sample_index == previous.first_sample_index + previous.samples.size
            and block.sample_rate_hz == previous.sample_rate_hz and block.is_complex == previous.is_complex
            and block.intermediate_frequency_hz == previous.intermediate_frequency_hz)

"""GNSS front-end IF sample simulator: GPS L1 C/A signals, thermal noise and jammers.

Generates what a front end delivers (quantised counts plus the volts-per-count scale) and the truth
(jammer type, instantaneous frequency per sample, sweep starts and period), seedable and in chunks
with continuous phase: a stream cut into consecutive blocks equals the same stream made at once.

Power convention: a 1-ohm load, powers in mW, so a real sample ``x`` (sqrt(mW)) has power
``mean(x**2)`` and a complex sample ``mean(|x|**2)``. A real tone ``sqrt(2 P) cos(.)`` and a complex
tone ``sqrt(P) exp(j .)`` both have power P. Thermal noise is white over the sampled band with
density ``noise_density_dbm_per_mhz`` counted over ``noise_bandwidth_hz`` (default: the whole
sampled band, fs/2 real or fs complex), i.e. the noise power is N = N0 * B_noise spread evenly
over the sampled band; J/N = J/S + S - N.

Frequencies: a jammer's ``*_hz`` frequency is relative to the RF centre (positive above it). Digital
frequency (cycles/sample) of a real IF stream: ``(IF + f_rel) / fs`` for IF > 0 and
``(|IF| - f_rel) / fs`` for IF < 0 (spectral inversion); complex: ``(IF + f_rel) / fs``.

Defaults reproduce Kang et al. (Sec. 2.1, 4): fs 38.192 MHz, IF 9.548 MHz, GPS signal -130 dBm,
noise -114 dBm/MHz, chirp sweep rate 1e12 Hz/s starting at digital frequency 0.1832, J/S 30 dB.
The paper leaves the sweep period open; the default here sweeps symmetrically about the IF
(0.1832 .. 0.3168, 5.10 MHz, period 5.10 us = 195 samples).

Real jammers and front ends (issue 14): ``SweepJammer`` (rfi_sim.jammer_waveforms) gives saw-tooth
up/down, triangular and hooked saw-tooth sweeps with non-linear rates and bands wider than the
sampled band; every jammer has a switch-on time ``on_time_s``; ``FrontEndConfig`` adds a
band-limiting filter (``filter_low_hz``/``filter_high_hz``), a gain that clips (``gain_mode``
"fixed") or settles on the total power (``gain_mode`` "agc"); 1-16 bit quantisation, real IF and
complex baseband were there before. The truth carries per block the shape, swept band, J/N over the
block and in band, in-band fraction and clipped fraction. The defaults (``gain_mode`` "ideal", no
filter, ``on_time_s`` 0) give the earlier streams bit for bit.

Example
-------
>>> sim = IfSimulator(FrontEndConfig(), jammers=(ChirpJammer(),), seed=1)
>>> blk = sim.generate(38192)          # 1 ms
>>> x = blk.values()                   # float64 volts (sqrt(mW))
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gnss_common.constants import (
    GPS_CA_CHIP_RATE_HZ,
    GPS_CA_CODE_LENGTH_CHIPS,
    GPS_L1_FREQUENCY_HZ,
    GPS_NAV_BIT_RATE_HZ,
)
from gnss_common.gps_ca import G2_DELAY_CHIPS, ca_code
from rfi_sim.jammer_waveforms import SweepJammer, SweepLaw, sweep_cycles, sweep_law

PAPER_SAMPLE_RATE_HZ = 38.192e6
"""Kang et al. front-end sample rate, Hz (Sec. 2.1)."""
PAPER_IF_HZ = 9.548e6
"""Kang et al. intermediate frequency, Hz (Sec. 2.1)."""
PAPER_CHIRP_F0_DIGITAL = 0.1832
"""Kang et al. chirp initial frequency, cycles/sample (Sec. 2.1)."""
PAPER_SWEEP_RATE_HZ_PER_S = 1e12
"""Kang et al. (after Mitch et al. 2011) chirp sweep rate, Hz/s."""

NONE, CW, CHIRP, WIDEBAND = 0, 1, 2, 3
"""Jammer type codes, identical to rfi_msgs/JammerState."""


def _db_to_lin(db: float) -> float:
    return 10.0 ** (db / 10.0)


@dataclass(frozen=True)
class FrontEndConfig:
    """Front-end and link-budget parameters.

    Attributes:
        sample_rate_hz: sample rate, Hz (complex: I/Q pairs per second), > 0.
        intermediate_frequency_hz: IF, Hz; 0 for complex baseband; < 0 for spectral inversion.
        is_complex: True for I/Q samples.
        bits: quantisation per real value, 1..16. 1-3 bits: sign/magnitude odd levels
            (+-1, +-3, ..., as MAX2769-type front ends); 4-16 bits: two's complement.
        clip_sigma: AGC full-scale half-range in units of the total input RMS (per real value).
            None: 2.0 for bits <= 3 (2-bit threshold at 1 sigma), 4.0 otherwise.
        noise_density_dbm_per_mhz: thermal noise density, dBm/MHz (Kang et al.: -114).
        noise_bandwidth_hz: bandwidth over which the noise power is counted, Hz; None: the whole
            sampled band (fs/2 real, fs complex).
        signal_power_dbm: received power of each GPS signal, dBm (Kang et al.: -130).
        filter_low_hz, filter_high_hz: pass band of the front end's band-limiting (anti-alias) filter,
            Hz relative to the RF centre; None (default): no filter. Both or neither. The filter is
            a Butterworth magnitude ``1 / sqrt(1 + ((f - f_c) / (B / 2))^(2 * filter_order))``
            applied quasi-statically to the tone jammers (CW, chirp, sweep: amplitude times the gain
            at the instantaneous frequency; exact for CW, a good approximation while the sweep
            crosses the filter's edge in many of its impulse-response lengths, i.e. rate << B^2 /
            filter_order). Thermal noise, GPS and noise jammers are not filtered (the noise is
            taken as white over the sampled band, as after the ADC's own noise).
        filter_order: order of that filter, >= 1.
        gain_mode: how the analog gain in front of the quantiser is set.
            "ideal" (default): fixed by the configured powers, jammers included (an AGC settled on
            the total power before the stream starts; the earlier behaviour, unchanged).
            "fixed": fixed by the thermal noise and GPS powers only (no AGC): a strong jammer clips.
            "agc": starts as "fixed" plus ``agc_initial_gain_db`` and settles on the total power
            measured at the quantiser input: every ``agc_update_samples`` samples the gain in dB
            moves by ``(update duration / agc_time_constant_s)`` times the error between the target
            power (the one "fixed" is set for) and the measured power (both in dB).
            In "fixed" and "agc" the block's ``scale`` is the volts per count at the nominal gain
            (the "fixed" one), so counts * scale is the input divided by the AGC gain, as a front
            end that does not report its AGC delivers it; ``IfTruth.agc_gain_db`` holds the gain.
        agc_time_constant_s: AGC time constant, s, > 0.
        agc_update_samples: AGC update interval, samples (complex: I/Q pairs), >= 1; updates fall on
            absolute sample indices (multiples of it), so the stream is split-invariant.
        agc_initial_gain_db: AGC gain at sample 0 relative to the nominal gain, dB.
    """

    sample_rate_hz: float = PAPER_SAMPLE_RATE_HZ
    intermediate_frequency_hz: float = PAPER_IF_HZ
    is_complex: bool = False
    bits: int = 8
    clip_sigma: float | None = None
    noise_density_dbm_per_mhz: float = -114.0
    noise_bandwidth_hz: float | None = None
    signal_power_dbm: float = -130.0
    filter_low_hz: float | None = None
    filter_high_hz: float | None = None
    filter_order: int = 8
    gain_mode: str = "ideal"
    agc_time_constant_s: float = 100e-6
    agc_update_samples: int = 64
    agc_initial_gain_db: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {self.sample_rate_hz}")
        if not math.isfinite(self.intermediate_frequency_hz):
            raise ValueError("intermediate_frequency_hz must be finite")
        nyq = self.sample_rate_hz if self.is_complex else self.sample_rate_hz / 2
        if abs(self.intermediate_frequency_hz) >= nyq:
            raise ValueError(f"|IF| must be below {nyq} Hz, got {self.intermediate_frequency_hz}")
        if not 1 <= int(self.bits) <= 16:
            raise ValueError(f"bits must be in 1..16, got {self.bits}")
        if self.clip_sigma is not None and not self.clip_sigma > 0:
            raise ValueError("clip_sigma must be > 0")
        if self.noise_bandwidth_hz is not None and not self.noise_bandwidth_hz > 0:
            raise ValueError("noise_bandwidth_hz must be > 0")
        if (self.filter_low_hz is None) != (self.filter_high_hz is None):
            raise ValueError("filter_low_hz and filter_high_hz must be given together")
        if self.filter_low_hz is not None and self.filter_high_hz is not None:
            if not (math.isfinite(self.filter_low_hz) and math.isfinite(self.filter_high_hz)
                    and self.filter_high_hz > self.filter_low_hz):
                raise ValueError("filter band must be finite with filter_high_hz > filter_low_hz")
        if not int(self.filter_order) >= 1:
            raise ValueError("filter_order must be >= 1")
        if self.gain_mode not in ("ideal", "fixed", "agc"):
            raise ValueError(f"gain_mode must be ideal, fixed or agc, got {self.gain_mode!r}")
        if not (math.isfinite(self.agc_time_constant_s) and self.agc_time_constant_s > 0):
            raise ValueError("agc_time_constant_s must be finite and > 0")
        if not int(self.agc_update_samples) >= 1:
            raise ValueError("agc_update_samples must be >= 1")
        if not math.isfinite(self.agc_initial_gain_db):
            raise ValueError("agc_initial_gain_db must be finite")

    def filter_gain(self, f_rel_hz: np.ndarray | float) -> np.ndarray:
        """Amplitude gain of the band-limiting filter at RF offsets ``f_rel_hz`` (Hz); 1 without one."""
        f = np.asarray(f_rel_hz, dtype=np.float64)
        if self.filter_low_hz is None or self.filter_high_hz is None:
            return np.ones_like(f)
        fc = 0.5 * (self.filter_low_hz + self.filter_high_hz)
        half = 0.5 * (self.filter_high_hz - self.filter_low_hz)
        return np.asarray(1.0 / np.sqrt(1.0 + np.abs((f - fc) / half) ** (2 * int(self.filter_order))))

    def in_sampled_band(self, f_rel_hz: np.ndarray | float) -> np.ndarray:
        """True where an RF offset (Hz) falls inside the sampled band without aliasing."""
        d = np.asarray(self.digital_frequency(f_rel_hz), dtype=np.float64)
        if self.is_complex:
            return np.asarray((d >= -0.5) & (d < 0.5))
        return np.asarray((d > 0.0) & (d < 0.5))

    @property
    def band_hz(self) -> float:
        """Sampled (Nyquist) bandwidth, Hz."""
        return self.sample_rate_hz if self.is_complex else self.sample_rate_hz / 2

    @property
    def noise_power_mw(self) -> float:
        """Thermal noise power N, mW."""
        bw = self.band_hz if self.noise_bandwidth_hz is None else self.noise_bandwidth_hz
        return _db_to_lin(self.noise_density_dbm_per_mhz) * bw / 1e6

    @property
    def signal_power_mw(self) -> float:
        """Nominal GPS signal power S, mW."""
        return _db_to_lin(self.signal_power_dbm)

    def digital_frequency(self, f_rel_hz: np.ndarray | float) -> np.ndarray | float:
        """Digital frequency, cycles/sample, of an RF offset (see module docstring)."""
        fif = self.intermediate_frequency_hz
        if not self.is_complex and fif < 0:
            return (-fif - np.asarray(f_rel_hz)) / self.sample_rate_hz
        return (fif + np.asarray(f_rel_hz)) / self.sample_rate_hz


@dataclass(frozen=True)
class CwJammer:
    """Single-tone continuous wave jammer (Kang et al., eq. 6).

    Attributes:
        frequency_hz: tone frequency relative to the RF centre, Hz (paper: 0, i.e. at the IF).
        js_db: jammer-to-signal ratio, dB.
        phase_rad: initial phase, rad.
        on_time_s: switch-on time, s since sample 0 of the stream; 0: on from the first sample.
    """

    frequency_hz: float = 0.0
    js_db: float = 30.0
    phase_rad: float = 0.0
    on_time_s: float = 0.0


@dataclass(frozen=True)
class ChirpJammer:
    """Saw-tooth chirp jammer (Kang et al., eq. 2-5) with continuous phase across sweeps.

    The instantaneous frequency is ``start_frequency_hz + sweep_rate * tau`` with
    ``tau = (t + time_offset_s) mod sweep_period_s``.

    Attributes:
        start_frequency_hz: frequency at each sweep start, relative to the RF centre, Hz.
            Default: digital 0.1832 at the paper's fs and IF.
        sweep_rate_hz_per_s: sweep rate, Hz/s (may be negative for a down-chirp).
        sweep_period_s: sweep period, s. Default: the symmetric sweep 0.1832..0.3168.
        js_db: jammer-to-signal ratio, dB.
        phase_rad: initial phase, rad.
        time_offset_s: position inside the sweep at sample 0, s.
        on_time_s: switch-on time, s since sample 0 of the stream; 0: on from the first sample.
            The sweep runs from sample 0 either way (switching on does not restart it).
    """

    start_frequency_hz: float = PAPER_CHIRP_F0_DIGITAL * PAPER_SAMPLE_RATE_HZ - PAPER_IF_HZ
    sweep_rate_hz_per_s: float = PAPER_SWEEP_RATE_HZ_PER_S
    sweep_period_s: float = 2 * (PAPER_IF_HZ - PAPER_CHIRP_F0_DIGITAL * PAPER_SAMPLE_RATE_HZ) / 1e12
    js_db: float = 30.0
    phase_rad: float = 0.0
    time_offset_s: float = 0.0
    on_time_s: float = 0.0

    @property
    def bandwidth_hz(self) -> float:
        """Swept bandwidth, Hz."""
        return abs(self.sweep_rate_hz_per_s) * self.sweep_period_s


@dataclass(frozen=True)
class NoiseJammer:
    """Band-limited Gaussian noise jammer (flat spectrum, FIR-shaped).

    Attributes:
        center_frequency_hz: centre relative to the RF centre, Hz.
        bandwidth_hz: two-sided bandwidth, Hz.
        js_db: jammer-to-signal ratio, dB.
        on_time_s: switch-on time, s since sample 0 of the stream; 0: on from the first sample.
    """

    center_frequency_hz: float = 0.0
    bandwidth_hz: float = 2.0e6
    js_db: float = 30.0
    on_time_s: float = 0.0


Jammer = CwJammer | ChirpJammer | NoiseJammer | SweepJammer


@dataclass(frozen=True)
class GpsSatellite:
    """One GPS L1 C/A signal.

    Attributes:
        prn: 1..37.
        doppler_hz: carrier Doppler, Hz (the code rate is scaled by 1 + doppler/L1).
        code_phase_chips: code phase at sample 0, chips, [0, 1023).
        carrier_phase_rad: carrier phase at sample 0, rad.
        power_dbm: received power, dBm; None: the front end's ``signal_power_dbm``.
    """

    prn: int = 1
    doppler_hz: float = 0.0
    code_phase_chips: float = 0.0
    carrier_phase_rad: float = 0.0
    power_dbm: float | None = None


@dataclass(frozen=True)
class IfTruth:
    """Truth of one generated block.

    Attributes:
        jammer_type: dominant (strongest) jammer type code (NONE, CW, CHIRP, WIDEBAND).
        jn_db: J/N of each jammer, dB, shape (n_jammers,).
        frequency_hz: instantaneous frequency of each CW/chirp jammer relative to the RF centre,
            Hz, shape (n_jammers, n); NaN for noise jammers.
        digital_frequency: the same in cycles/sample of the sampled stream, shape (n_jammers, n).
        sweep_start_indices: absolute sample indices of sweep starts inside the block, per jammer.
        sweep_period_s: sweep period per jammer, s (NaN unless chirp).
        shape: per jammer: "cw", "saw_up" / "saw_down" (ChirpJammer by the sign of its rate),
            "triangle", "hooked_saw", "noise".
        swept_band_hz: per jammer (lowest, highest) frequency it reaches, Hz relative to the RF
            centre, shape (n_jammers, 2); CW: (f, f); noise: centre -+ bandwidth / 2.
        jn_block_db: per jammer, the J/N of the jammer as the quantiser sees it over this block
            (switch-on, front-end filter and AGC gain included: its mean power in the block over N
            at the same gain), dB; -inf if absent from the whole block.
        jn_in_band_db: per jammer, the same over the samples where it is in band (on, filter gain
            >= -3 dB, inside the sampled band), dB; -inf if never in band in the block.
        in_band_fraction: per jammer, fraction of the block's samples where it is in band.
        active: per jammer, True if it is on for at least one sample of the block.
        clipped_fraction: fraction of the block's real values (I and Q counted apart) at the most
            negative or most positive code (for 1-3 bit front ends that is the outer level, which
            noise also reaches).
        agc_gain_db: mean gain in front of the quantiser over the block relative to the nominal
            gain, dB (0 unless gain_mode is "agc").
    """

    jammer_type: int
    jn_db: np.ndarray
    frequency_hz: np.ndarray
    digital_frequency: np.ndarray
    sweep_start_indices: tuple[np.ndarray, ...]
    sweep_period_s: np.ndarray
    shape: tuple[str, ...] = ()
    swept_band_hz: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    jn_block_db: np.ndarray = field(default_factory=lambda: np.zeros(0))
    jn_in_band_db: np.ndarray = field(default_factory=lambda: np.zeros(0))
    in_band_fraction: np.ndarray = field(default_factory=lambda: np.zeros(0))
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    clipped_fraction: float = 0.0
    agc_gain_db: float = 0.0


@dataclass(frozen=True)
class IfBlock:
    """One block as a front end delivers it, plus truth.

    Attributes:
        counts: quantised values; real: shape (n,); complex: shape (2n,) interleaved I, Q. int8 for
            bits <= 8, else int16.
        scale: volts (sqrt(mW) into 1 ohm) per count.
        first_sample_index: absolute index of the first sample (complex: I/Q pair index).
        sample_rate_hz, intermediate_frequency_hz, is_complex, bits: as the front end.
        truth: IfTruth.
    """

    counts: np.ndarray
    scale: float
    first_sample_index: int
    sample_rate_hz: float
    intermediate_frequency_hz: float
    is_complex: bool
    bits: int
    truth: IfTruth = field(repr=False)

    def values(self) -> np.ndarray:
        """Samples in volts: float64 shape (n,) real or complex128 shape (n,)."""
        v = self.counts.astype(np.float64) * self.scale
        if self.is_complex:
            return v[0::2] + 1j * v[1::2]
        return v


def _quantise(x: np.ndarray, bits: int, step: float) -> np.ndarray:
    """Quantise real values with the given step (volts): odd levels for bits <= 3, else two's complement."""
    if bits <= 3:
        top = 2 ** bits - 1
        c = 2.0 * np.floor(x / step) + 1.0
        return np.clip(c, -top, top)
    lo, hi = -(2 ** (bits - 1)), 2 ** (bits - 1) - 1
    return np.clip(np.round(x / step), lo, hi)


class IfSimulator:
    """Stateful, seedable IF stream generator (chunks are continuous in phase and in noise).

    Args:
        front_end: FrontEndConfig.
        jammers: tuple of CwJammer / ChirpJammer / NoiseJammer / SweepJammer.
        satellites: tuple of GpsSatellite (default: PRN 1, 1 kHz Doppler).
        seed: int seed for all random streams (noise, noise jammers, navigation bits).
        add_jammer_to: optional float/complex array of real samples (volts) to add the jammers
            and noise to instead of simulating GPS; see ``generate``.

    Notes:
        Random streams are split with ``np.random.SeedSequence(seed).spawn`` so that each draws
        sequentially regardless of the chunk sizes (float draws are split-invariant in numpy's
        Generator).
    """

    _NOISE_JAMMER_TAPS = 129

    def __init__(self, front_end: FrontEndConfig = FrontEndConfig(), jammers: tuple[Jammer, ...] = (),
                 satellites: tuple[GpsSatellite, ...] = (GpsSatellite(prn=1, doppler_hz=1000.0),),
                 seed: int = 0) -> None:
        for j in jammers:
            if not isinstance(j, (CwJammer, ChirpJammer, NoiseJammer, SweepJammer)):
                raise ValueError(f"unknown jammer {j!r}")
            if not math.isfinite(j.on_time_s):
                raise ValueError("on_time_s must be finite")
            if isinstance(j, ChirpJammer) and not j.sweep_period_s > 0:
                raise ValueError("sweep_period_s must be > 0")
            if isinstance(j, NoiseJammer) and not 0 < j.bandwidth_hz <= front_end.sample_rate_hz:
                raise ValueError("noise jammer bandwidth must be in (0, fs]")
        for s in satellites:
            if s.prn not in G2_DELAY_CHIPS:
                raise ValueError(f"unknown PRN {s.prn}")
        self.front_end = front_end
        self.jammers = tuple(jammers)
        self.satellites = tuple(satellites)
        ss = np.random.SeedSequence(seed)
        children = ss.spawn(2 + len(jammers) + len(satellites))
        self._rng_noise = np.random.default_rng(children[0])
        self._rng_jam = [np.random.default_rng(c) for c in children[2:2 + len(jammers)]]
        self._rng_nav = [np.random.default_rng(c) for c in children[2 + len(jammers):]]
        self._nav_bits: list[np.ndarray] = [np.zeros(0, dtype=np.float64) for _ in satellites]
        self._jam_hist = [np.zeros(self._NOISE_JAMMER_TAPS - 1, dtype=np.complex128) for _ in jammers]
        self._taps = [self._noise_jammer_taps(j) if isinstance(j, NoiseJammer) else None for j in jammers]
        self._codes = [ca_code(s.prn).astype(np.float64) for s in satellites]
        self._laws: list[SweepLaw | None] = [sweep_law(j) if isinstance(j, SweepJammer) else None
                                             for j in jammers]
        self._next_index = 0
        fe = front_end
        total = fe.noise_power_mw + sum(self._sat_power(s) for s in satellites)
        if fe.gain_mode == "ideal":
            total += sum(self.jammer_power_mw(j) for j in jammers)
        self._target_power = total / 2 if fe.is_complex else total
        """Power per real value the nominal gain is set for, mW (the AGC's target)."""
        self._agc_gain_db = float(fe.agc_initial_gain_db) if fe.gain_mode == "agc" else 0.0
        self._agc_acc = 0.0  # power sum of the current, unfinished AGC update interval
        self._agc_cnt = 0
        per_real = total / 2 if fe.is_complex else total
        clip = fe.clip_sigma if fe.clip_sigma is not None else (2.0 if fe.bits <= 3 else 4.0)
        levels = 2 ** fe.bits
        self.step = 2.0 * clip * math.sqrt(per_real) / levels
        """Quantiser step (volts) at the nominal gain. "ideal": fixed by the configured powers (an ideal
        AGC), not by the data; "fixed"/"agc": by the thermal noise and GPS powers."""
        self.scale = self.step / 2 if fe.bits <= 3 else self.step
        """Volts per count."""

    # ---- powers --------------------------------------------------------------------------
    def _sat_power(self, s: GpsSatellite) -> float:
        return _db_to_lin(s.power_dbm) if s.power_dbm is not None else self.front_end.signal_power_mw

    def jammer_power_mw(self, j: Jammer) -> float:
        """Jammer power J = S * 10^(J/S / 10), mW."""
        return self.front_end.signal_power_mw * _db_to_lin(j.js_db)

    def jn_db(self, j: Jammer) -> float:
        """J/N of a jammer, dB."""
        return 10 * math.log10(self.jammer_power_mw(j) / self.front_end.noise_power_mw)

    def _noise_jammer_taps(self, j: NoiseJammer) -> np.ndarray:
        from scipy.signal import firwin
        cutoff = min(j.bandwidth_hz / 2, 0.999 * self.front_end.sample_rate_hz / 2)
        h = firwin(self._NOISE_JAMMER_TAPS, cutoff, fs=self.front_end.sample_rate_hz)
        return h / np.sqrt(np.sum(h ** 2))  # unit power gain for white input

    # ---- generation ----------------------------------------------------------------------
    def _phase_to_signal(self, amp: float, phase: np.ndarray) -> np.ndarray:
        """Tone of power amp**2 (complex) / amp**2 (real, amplitude sqrt 2 amp) from its phase."""
        if self.front_end.is_complex:
            return amp * np.exp(1j * phase)
        return math.sqrt(2.0) * amp * np.cos(phase)

    def _signed(self, f_rel_hz: np.ndarray | float) -> np.ndarray | float:
        """Frequency (Hz) that the sampled stream carries for an RF offset (spectral inversion)."""
        fe = self.front_end
        if not fe.is_complex and fe.intermediate_frequency_hz < 0:
            return -fe.intermediate_frequency_hz - np.asarray(f_rel_hz)
        return fe.intermediate_frequency_hz + np.asarray(f_rel_hz)

    def _gps(self, n_idx: np.ndarray, t: np.ndarray) -> np.ndarray:
        fe = self.front_end
        out = np.zeros(n_idx.size, dtype=np.complex128 if fe.is_complex else np.float64)
        for k, s in enumerate(self.satellites):
            rate = GPS_CA_CHIP_RATE_HZ * (1.0 + s.doppler_hz / GPS_L1_FREQUENCY_HZ)
            chips = s.code_phase_chips + rate * t
            chip_idx = np.floor(chips).astype(np.int64)
            code = self._codes[k][chip_idx % GPS_CA_CODE_LENGTH_CHIPS]
            bit_idx = np.floor(chips / (GPS_CA_CHIP_RATE_HZ / GPS_NAV_BIT_RATE_HZ)).astype(np.int64)
            need = int(bit_idx.max()) + 1 if bit_idx.size else 0
            have = self._nav_bits[k].size
            if need > have:
                new = np.where(self._rng_nav[k].random(need - have) < 0.5, 1.0, -1.0)
                self._nav_bits[k] = np.concatenate([self._nav_bits[k], new])
            data = self._nav_bits[k][np.maximum(bit_idx, 0)]
            phase = 2 * np.pi * (self._signed(s.doppler_hz) * t) + s.carrier_phase_rad
            out += data * code * self._phase_to_signal(math.sqrt(self._sat_power(s)), phase)
        return out

    def _chirp(self, j: ChirpJammer, t: np.ndarray,
               n_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        T = j.sweep_period_s
        u = t + j.time_offset_s
        k = np.floor(u / T)
        tau = u - k * T
        f_start = float(self._signed(j.start_frequency_hz))
        rate = j.sweep_rate_hz_per_s if not (not self.front_end.is_complex
                                               and self.front_end.intermediate_frequency_hz < 0) \
            else -j.sweep_rate_hz_per_s
        # phase accumulated over one whole sweep, reduced mod 1 cycle (exact integer multiples)
        cyc_sweep = f_start * T + 0.5 * rate * T * T
        frac_sweep = cyc_sweep - math.floor(cyc_sweep)
        k0 = math.floor(j.time_offset_s / T)
        tau0 = j.time_offset_s - k0 * T
        cyc0 = f_start * tau0 + 0.5 * rate * tau0 * tau0
        cycles = np.mod((k - k0) * frac_sweep, 1.0) + f_start * tau + 0.5 * rate * tau * tau - cyc0
        phase = 2 * np.pi * cycles + j.phase_rad
        f_rel = j.start_frequency_hz + j.sweep_rate_hz_per_s * tau
        # sweep starts: samples whose sweep counter differs from the previous sample's
        kprev = np.floor((t - 1.0 / self.front_end.sample_rate_hz + j.time_offset_s) / T)
        starts = n_idx[(k != kprev)]
        return phase, f_rel, starts

    def _noise_jammer(self, idx: int, j: NoiseJammer, t: np.ndarray) -> np.ndarray:
        n = t.size
        rng = self._rng_jam[idx]
        g = rng.standard_normal(2 * n)  # interleaved draws keep the stream split-invariant
        w = (g[0::2] + 1j * g[1::2]) / math.sqrt(2.0)
        buf = np.concatenate([self._jam_hist[idx], w])
        self._jam_hist[idx] = buf[buf.size - (self._NOISE_JAMMER_TAPS - 1):]
        taps = self._taps[idx]
        assert taps is not None  # set for every NoiseJammer in __init__
        y: np.ndarray = np.convolve(buf, taps.astype(np.complex128), mode="valid")  # unit power, complex
        y = y * np.exp(2j * np.pi * self._signed(j.center_frequency_hz) * t)
        p = self.jammer_power_mw(j)
        if self.front_end.is_complex:
            return math.sqrt(p) * y
        return math.sqrt(2.0 * p) * y.real

    def _sweep(self, idx: int, j: SweepJammer, t: np.ndarray,
               n_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        law = self._laws[idx]
        assert law is not None  # set for every SweepJammer in __init__
        fe = self.front_end
        cyc, f_rel, k = sweep_cycles(law, t, j.time_offset_s)
        fif = fe.intermediate_frequency_hz
        if_cyc = np.mod(abs(fif) / fe.sample_rate_hz * n_idx.astype(np.float64), 1.0)
        inverted = not fe.is_complex and fif < 0
        phase = 2 * np.pi * (if_cyc - cyc if inverted else (if_cyc if fif >= 0 else -if_cyc) + cyc)
        phase = phase + j.phase_rad
        kprev = np.floor((t - 1.0 / fe.sample_rate_hz + j.time_offset_s) / j.sweep_period_s)
        return phase, f_rel, n_idx[k != kprev]

    def _apply_gain(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Front-end gain (gain_mode "fixed"/"agc") applied to the quantiser input; returns the
        scaled samples and the amplitude gain per sample (relative to nominal)."""
        fe = self.front_end
        n = x.size
        g = np.ones(n)
        if fe.gain_mode != "agc" or n == 0:
            return x, g
        L = int(fe.agc_update_samples)
        fs = fe.sample_rate_hz
        alpha = min(1.0, L / fs / fe.agc_time_constant_s)
        p = np.abs(x) ** 2
        if fe.is_complex:
            p = p / 2.0  # per real value
        pos = 0
        while pos < n:
            room = L - self._agc_cnt
            m = min(room, n - pos)
            lin = 10.0 ** (self._agc_gain_db / 20.0)
            g[pos:pos + m] = lin
            self._agc_acc += float(np.sum(p[pos:pos + m])) * lin * lin
            self._agc_cnt += m
            pos += m
            if self._agc_cnt == L:
                meas = self._agc_acc / L
                err_db = 10 * math.log10(self._target_power / max(meas, 1e-300))
                self._agc_gain_db += alpha * err_db
                self._agc_acc = 0.0
                self._agc_cnt = 0
        return x * g, g

    def generate(self, n_samples: int, add_to: np.ndarray | None = None) -> IfBlock:
        """Generate the next ``n_samples`` samples of the stream.

        Args:
            n_samples: number of samples (complex: I/Q pairs), >= 0.
            add_to: optional real recording in volts, shape (n_samples,) (complex for a complex
                front end). When given, the jammers are added to it and no GPS or thermal noise is
                simulated (half-simulated data); it is quantised with the same step.

        Returns:
            IfBlock with counts, scale and truth.
        """
        if n_samples < 0:
            raise ValueError("n_samples must be >= 0")
        fe = self.front_end
        fs = fe.sample_rate_hz
        n_idx = np.arange(self._next_index, self._next_index + n_samples, dtype=np.int64)
        t = n_idx / fs
        self._next_index += n_samples
        if add_to is not None:
            x = np.asarray(add_to)
            if x.shape != (n_samples,):
                raise ValueError("add_to must have shape (n_samples,)")
            x = x.astype(np.complex128 if fe.is_complex else np.float64)
        else:
            x = self._gps(n_idx, t)
            sig = math.sqrt(fe.noise_power_mw)
            if fe.is_complex:
                g = self._rng_noise.standard_normal(2 * n_samples)
                x = x + sig / math.sqrt(2.0) * (g[0::2] + 1j * g[1::2])
            else:
                x = x + sig * self._rng_noise.standard_normal(n_samples)
        nj = len(self.jammers)
        f_true = np.full((nj, n_samples), np.nan)
        starts: list[np.ndarray] = []
        periods = np.full(nj, np.nan)
        shapes: list[str] = []
        band = np.full((nj, 2), np.nan)
        p_block = np.zeros(nj)        # mean jammer power over the block before the AGC, mW
        p_in_band = np.zeros(nj)      # mean power over its in-band samples, mW
        in_band_frac = np.zeros(nj)
        active = np.zeros(nj, dtype=bool)
        jam_power_t: list[np.ndarray] = []  # per-sample power of each jammer (for the AGC share)
        for i, j in enumerate(self.jammers):
            amp = math.sqrt(self.jammer_power_mw(j))
            on = t >= j.on_time_s
            all_on = bool(on.all())
            if isinstance(j, NoiseJammer):
                y = self._noise_jammer(i, j, t)
                f_rel = None
                shapes.append("noise")
                band[i] = (j.center_frequency_hz - j.bandwidth_hz / 2, j.center_frequency_hz + j.bandwidth_hz / 2)
                starts.append(np.zeros(0, dtype=np.int64))
                gain = np.ones(n_samples)
            else:
                if isinstance(j, CwJammer):
                    phase = 2 * np.pi * self._signed(j.frequency_hz) * t + j.phase_rad
                    f_rel = np.full(n_samples, j.frequency_hz)
                    shapes.append("cw")
                    band[i] = (j.frequency_hz, j.frequency_hz)
                    starts.append(np.zeros(0, dtype=np.int64))
                elif isinstance(j, ChirpJammer):
                    phase, f_rel, st = self._chirp(j, t, n_idx)
                    starts.append(st)
                    periods[i] = j.sweep_period_s
                    shapes.append("saw_up" if j.sweep_rate_hz_per_s >= 0 else "saw_down")
                    f_end = j.start_frequency_hz + j.sweep_rate_hz_per_s * j.sweep_period_s
                    band[i] = (min(j.start_frequency_hz, f_end), max(j.start_frequency_hz, f_end))
                else:
                    phase, f_rel, st = self._sweep(i, j, t, n_idx)
                    starts.append(st)
                    periods[i] = j.sweep_period_s
                    shapes.append(j.shape)
                    band[i] = j.swept_band_hz
                y = self._phase_to_signal(amp, phase)
                f_true[i] = f_rel
                gain = fe.filter_gain(f_rel)
                if fe.filter_low_hz is not None:
                    y = y * gain
            if not all_on:
                y = y * on
            x = x + y
            inb = on & (gain >= 1 / math.sqrt(2.0))
            if f_rel is not None:
                inb &= fe.in_sampled_band(f_rel)
            pw = self.jammer_power_mw(j) * gain ** 2 * on
            jam_power_t.append(pw)
            active[i] = bool(on.any())
            if n_samples:
                p_block[i] = float(np.mean(pw))
                in_band_frac[i] = float(np.mean(inb))
                p_in_band[i] = float(np.mean(pw[inb])) if inb.any() else 0.0
        x, g_amp = self._apply_gain(x)
        dtype = np.int8 if fe.bits <= 8 else np.int16
        if fe.is_complex:
            c = np.empty(2 * n_samples, dtype=dtype)
            c[0::2] = _quantise(x.real, fe.bits, self.step)
            c[1::2] = _quantise(x.imag, fe.bits, self.step)
        else:
            c = _quantise(x, fe.bits, self.step).astype(dtype)
        jn = np.array([self.jn_db(j) for j in self.jammers])
        live = [i for i in range(nj) if active[i]]
        if live:
            strongest = self.jammers[max(live, key=lambda i: jn[i])]
            jtype = CW if isinstance(strongest, CwJammer) else WIDEBAND if isinstance(strongest, NoiseJammer) \
                else CHIRP
        else:
            jtype = NONE
        if fe.bits <= 3:
            top = 2 ** fe.bits - 1
            lo_code, hi_code = -top, top
        else:
            lo_code, hi_code = -(2 ** (fe.bits - 1)), 2 ** (fe.bits - 1) - 1
        clipped = float(np.mean((c == lo_code) | (c == hi_code))) if c.size else 0.0
        n0 = fe.noise_power_mw
        with np.errstate(divide="ignore"):
            g2 = g_amp ** 2
            jn_block = np.array([10 * np.log10(np.mean(jp * g2) / (n0 * np.mean(g2))) if n_samples
                                 else -np.inf for jp in jam_power_t]) if nj else np.zeros(0)
            jn_in = 10 * np.log10(p_in_band / n0) if nj else np.zeros(0)
        agc_db = float(10 * np.log10(np.mean(g2))) if n_samples else self._agc_gain_db
        truth = IfTruth(jammer_type=jtype, jn_db=jn, frequency_hz=f_true,
                        digital_frequency=np.asarray(fe.digital_frequency(f_true), dtype=np.float64),
                        sweep_start_indices=tuple(starts), sweep_period_s=periods,
                        shape=tuple(shapes), swept_band_hz=band, jn_block_db=jn_block,
                        jn_in_band_db=jn_in, in_band_fraction=in_band_frac, active=active,
                        clipped_fraction=clipped, agc_gain_db=agc_db)
        first = int(n_idx[0]) if n_samples else self._next_index
        return IfBlock(counts=c, scale=self.scale, first_sample_index=first, sample_rate_hz=fs,
                       intermediate_frequency_hz=fe.intermediate_frequency_hz,
                       is_complex=fe.is_complex, bits=fe.bits, truth=truth)


def js_for_jn_db(front_end: FrontEndConfig, jn_db: float) -> float:
    """J/S (dB) that gives a jammer the nominal J/N ``jn_db`` (dB) on ``front_end``: J/N + N - S."""
    return jn_db + 10 * math.log10(front_end.noise_power_mw / front_end.signal_power_mw)


def simulate(n_samples: int, front_end: FrontEndConfig = FrontEndConfig(), jammers: tuple[Jammer, ...] = (),
             satellites: tuple[GpsSatellite, ...] = (GpsSatellite(prn=1, doppler_hz=1000.0),),
             seed: int = 0) -> IfBlock:
    """One-shot convenience wrapper: ``IfSimulator(...).generate(n_samples)``."""
    return IfSimulator(front_end, jammers, satellites, seed).generate(n_samples)

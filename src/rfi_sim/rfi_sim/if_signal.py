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
from rfi_sim.if_scene import (
    CHIRP,
    CW,
    NONE,
    PAPER_CHIRP_F0_DIGITAL,
    PAPER_IF_HZ,
    PAPER_SAMPLE_RATE_HZ,
    PAPER_SWEEP_RATE_HZ_PER_S,
    WIDEBAND,
    ChirpJammer,
    CwJammer,
    FrontEndConfig,
    GpsSatellite,
    Jammer,
    NoiseJammer,
    db_to_linear,
)
from rfi_sim.jammer_waveforms import SweepJammer, SweepLaw, sweep_cycles, sweep_law

__all__ = ["CHIRP", "CW", "ChirpJammer", "CwJammer", "FrontEndConfig", "GpsSatellite", "IfBlock", "IfSimulator",
           "IfTruth", "Jammer", "NONE", "NoiseJammer", "PAPER_CHIRP_F0_DIGITAL", "PAPER_IF_HZ", "PAPER_SAMPLE_RATE_HZ",
           "PAPER_SWEEP_RATE_HZ_PER_S", "SweepJammer", "WIDEBAND", "js_for_jn_db", "simulate"]
"""The simulator's public names (the front end and emitters are defined in if_scene)."""


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
        return db_to_linear(s.power_dbm) if s.power_dbm is not None else self.front_end.signal_power_mw

    def jammer_power_mw(self, j: Jammer) -> float:
        """Jammer power J = S * 10^(J/S / 10), mW."""
        return self.front_end.signal_power_mw * db_to_linear(j.js_db)

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
        x = self._signal_and_noise(n_idx, t, add_to)
        nj = len(self.jammers)
        f_true = np.full((nj, n_samples), np.nan)
        starts: list[np.ndarray] = []
        periods = np.full(nj, np.nan)
        shapes: list[str] = []
        band = np.full((nj, 2), np.nan)
        p_in_band = np.zeros(nj)      # mean power over its in-band samples, mW
        in_band_frac = np.zeros(nj)
        active = np.zeros(nj, dtype=bool)
        jam_power_t: list[np.ndarray] = []  # per-sample power of each jammer (for the AGC share)
        for i, j in enumerate(self.jammers):
            on = t >= j.on_time_s
            y, f_rel, gain, st, periods[i], shape, band[i] = self._jammer_samples(i, j, t, n_idx)
            starts.append(st)
            shapes.append(shape)
            if f_rel is not None:
                f_true[i] = f_rel
            if not bool(on.all()):
                y = y * on
            x = x + y
            inb = on & (gain >= 1 / math.sqrt(2.0))
            if f_rel is not None:
                inb &= fe.in_sampled_band(f_rel)
            pw = self.jammer_power_mw(j) * gain ** 2 * on
            jam_power_t.append(pw)
            active[i] = bool(on.any())
            if n_samples:
                in_band_frac[i] = float(np.mean(inb))
                p_in_band[i] = float(np.mean(pw[inb])) if inb.any() else 0.0
        x, g_amp = self._apply_gain(x)
        c, clipped = self._quantised(x)
        jn = np.array([self.jn_db(j) for j in self.jammers])
        live = [i for i in range(nj) if active[i]]
        if live:
            strongest = self.jammers[max(live, key=lambda i: jn[i])]
            jtype = CW if isinstance(strongest, CwJammer) else WIDEBAND if isinstance(strongest, NoiseJammer) \
                else CHIRP
        else:
            jtype = NONE
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

    def _signal_and_noise(self, n_idx: np.ndarray, t: np.ndarray, add_to: np.ndarray | None) -> np.ndarray:
        """The GPS signals and thermal noise of the samples n_idx (times t), or the recording add_to (volts)."""
        fe = self.front_end
        n_samples = n_idx.size
        if add_to is not None:
            x = np.asarray(add_to)
            if x.shape != (n_samples,):
                raise ValueError("add_to must have shape (n_samples,)")
            return x.astype(np.complex128 if fe.is_complex else np.float64)
        x = self._gps(n_idx, t)
        sig = math.sqrt(fe.noise_power_mw)
        if fe.is_complex:
            g = self._rng_noise.standard_normal(2 * n_samples)
            return x + sig / math.sqrt(2.0) * (g[0::2] + 1j * g[1::2])
        return x + sig * self._rng_noise.standard_normal(n_samples)

    def _jammer_samples(self, i: int, j: Jammer, t: np.ndarray, n_idx: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, float, str,
                                   tuple[float, float]]:
        """Jammer i's samples before its switch-on is applied: (samples through the front end's filter, frequency
        relative to the RF centre per sample (None: a noise jammer), filter gain per sample, sweep start indices,
        sweep period (NaN: none), shape name, swept band (low, high), Hz)."""
        fe = self.front_end
        n_samples = t.size
        none = np.zeros(0, dtype=np.int64)
        if isinstance(j, NoiseJammer):
            lo_hi = (j.center_frequency_hz - j.bandwidth_hz / 2, j.center_frequency_hz + j.bandwidth_hz / 2)
            return self._noise_jammer(i, j, t), None, np.ones(n_samples), none, math.nan, "noise", lo_hi
        amp = math.sqrt(self.jammer_power_mw(j))
        period = math.nan
        if isinstance(j, CwJammer):
            phase = 2 * np.pi * self._signed(j.frequency_hz) * t + j.phase_rad
            f_rel = np.full(n_samples, j.frequency_hz)
            shape, lo_hi, st = "cw", (j.frequency_hz, j.frequency_hz), none
        elif isinstance(j, ChirpJammer):
            phase, f_rel, st = self._chirp(j, t, n_idx)
            period = j.sweep_period_s
            shape = "saw_up" if j.sweep_rate_hz_per_s >= 0 else "saw_down"
            f_end = j.start_frequency_hz + j.sweep_rate_hz_per_s * j.sweep_period_s
            lo_hi = (min(j.start_frequency_hz, f_end), max(j.start_frequency_hz, f_end))
        else:
            phase, f_rel, st = self._sweep(i, j, t, n_idx)
            period, shape, lo_hi = j.sweep_period_s, j.shape, j.swept_band_hz
        y = self._phase_to_signal(amp, phase)
        gain = fe.filter_gain(f_rel)
        if fe.filter_low_hz is not None:
            y = y * gain
        return y, f_rel, gain, st, period, shape, lo_hi

    def _quantised(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """(counts: int8 up to 8 bits, else int16; I, Q interleaved for a complex front end, share of them at either
        end of the quantiser's range)."""
        fe = self.front_end
        dtype = np.int8 if fe.bits <= 8 else np.int16
        if fe.is_complex:
            c = np.empty(2 * x.size, dtype=dtype)
            c[0::2] = _quantise(x.real, fe.bits, self.step)
            c[1::2] = _quantise(x.imag, fe.bits, self.step)
        else:
            c = _quantise(x, fe.bits, self.step).astype(dtype)
        if fe.bits <= 3:
            top = 2 ** fe.bits - 1
            lo_code, hi_code = -top, top
        else:
            lo_code, hi_code = -(2 ** (fe.bits - 1)), 2 ** (fe.bits - 1) - 1
        clipped = float(np.mean((c == lo_code) | (c == hi_code))) if c.size else 0.0
        return c, clipped


def js_for_jn_db(front_end: FrontEndConfig, jn_db: float) -> float:
    """J/S (dB) that gives a jammer the nominal J/N ``jn_db`` (dB) on ``front_end``: J/N + N - S."""
    return jn_db + 10 * math.log10(front_end.noise_power_mw / front_end.signal_power_mw)


def simulate(n_samples: int, front_end: FrontEndConfig = FrontEndConfig(), jammers: tuple[Jammer, ...] = (),
             satellites: tuple[GpsSatellite, ...] = (GpsSatellite(prn=1, doppler_hz=1000.0),),
             seed: int = 0) -> IfBlock:
    """One-shot convenience wrapper: ``IfSimulator(...).generate(n_samples)``."""
    return IfSimulator(front_end, jammers, satellites, seed).generate(n_samples)

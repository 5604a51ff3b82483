"""What the IF simulator (if_signal module) simulates: the front end (sample rate, IF, bits, filter, gain, link
budget) and the emitters (GPS satellites, CW, chirp and noise jammers; SweepJammer lives in jammer_waveforms), with
Kang et al.'s front end as the defaults (Sec. 2.1, 4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rfi_sim.jammer_waveforms import SweepJammer

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


def db_to_linear(db: float) -> float:
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
        return db_to_linear(self.noise_density_dbm_per_mhz) * bw / 1e6

    @property
    def signal_power_mw(self) -> float:
        """Nominal GPS signal power S, mW."""
        return db_to_linear(self.signal_power_dbm)

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



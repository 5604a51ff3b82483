"""GPS L1 C/A acquisition: parallel code-phase search by FFT, with a stated false-alarm probability.

For each PRN and each trial Doppler ``f_d`` of a grid, the samples are wiped off by the carrier
``exp(-j 2 pi f_c(f_d) n / fs)`` (continuous phase over the whole window), cut into consecutive
1-ms code periods, and each period is circularly correlated with the sampled code replica by FFT
(the parallel code-phase search of Borre et al., "A Software-Defined GPS and Galileo Receiver", 2007):

    Y_k(tau, f_d) = IFFT( FFT(x_k e^{-j 2 pi f_c n / fs}) conj(FFT(c)) )[tau],

``M`` consecutive periods are summed coherently (in the frequency domain, before the inverse FFT)
and ``K`` such coherent sums are added non-coherently:

    S(tau, f_d) = sum_{k=1..K} | sum_{m=1..M} Y_{(k-1)M+m}(tau, f_d) |^2.

Detection statistic (the metric)
--------------------------------
Under H0 (the PRN absent) and white noise, each coherent sum is circular complex Gaussian of power
``sigma^2`` per cell, so ``S / sigma^2`` is Gamma(K, 1) distributed (a chi-square with 2K degrees of
freedom, halved). ``sigma^2`` is estimated from the search grid itself: the mean of ``S / K`` over
every cell more than 1.5 chips from the peak's code delay (all Dopplers): tens of thousands of cells.
The metric is the grid's peak over that noise floor, ``max S / sigma^2`` (H0 mean: K).

Real captures are not white noise alone: the other satellites' signals leave cross-correlation
terms that repeat from one code period to the next in a fixed cell (a non-central component), and
the cells of the grid spread more than Gamma(K) (on the PocketSDR captures var/mean of
``S / sigma^2`` is 1.10-1.19 at K = 10 and grows with K, where Gamma(K, 1) has 1). The null
distribution is therefore fitted to the grid's own first two moments (over the same cells as the
noise floor): ``S / sigma^2 ~ Gamma(k_eff, theta)`` with ``k_eff = mean^2 / var``, ``theta = var / mean``
(method of moments; on white noise ``k_eff = K``, ``theta = 1``: the plain model).

Threshold: the PRN is declared present when the metric exceeds ``eta``, where

    eta = theta Q^{-1}(k_eff, P_fa / N_cells),   Q(k, x) = Gamma(k, x) / Gamma(k) (upper regularised),

``N_cells`` is the number of cells of the grid (code delays x Dopplers) and ``P_fa`` the stated
false-alarm probability per satellite search. By the union bound P(max over the grid > eta) <=
N_cells Q(k_eff, eta / theta) = P_fa whatever the correlation between cells (neighbouring delays and
Dopplers are correlated), so on noise the stated P_fa is an upper bound, derived and not tuned; the
rates measured (white noise, and the PRNs 33-37 that no satellite transmits on the real captures)
are in docs/gnss_correlator/README.md. The estimation error of the floor and moments (thousands of
independent cells) is neglected.

Fine estimates of a detected PRN
--------------------------------
* Code delay: the triangle (the code's autocorrelation) through the signal amplitudes
  ``sqrt(S - K sigma^2)`` at the peak and its two neighbours.
* Doppler: from the 1-ms prompts ``z_j`` aligned on the code epochs, wiped at the coarse Doppler,
  ``delta_f = arg(sum_j z_{j+1} conj(z_j)) / (2 pi 1 ms)`` (the argument of the lag-one
  autocorrelation, the unweighted form of Kay's phase-difference estimator; a data bit flip between
  two prompts negates one product of ~20 and leaves the argument unbiased).
  Unambiguous for |delta_f| < 500 Hz, i.e. for any coarse step up to 1 kHz.
* C/N0: the prompts recomputed at the fine Doppler and code delay give the coherent power per
  1-ms prompt ``mean |z_j|^2 = |A|^2 + sigma_1^2`` with ``sigma_1^2 = sigma^2 / M`` from the grid's
  floor, and ``C/N0 = (|A|^2 / sigma_1^2) / T`` with T = 1 ms (post-correlation SNR over the
  coherent time; same formula for real and complex samples). It is the C/N0 the receiver sees,
  front-end filtering and quantisation losses included.

Conventions
-----------
* ``code_delay_samples``: samples from the first input sample to the start of the first code period
  in the input (chip 0 of the code), in [0, samples per code period); ``code_delay_chips`` the same
  in chips, [0, 1023). rfi_sim's ``GpsSatellite.code_phase_chips`` (the chip at the first sample)
  is ``(1023 - code_delay_chips) % 1023``.
* ``doppler_hz``: the carrier Doppler (RF, positive when the satellite approaches), so the sampled
  carrier is at ``IF + doppler`` (complex samples, or real samples with IF > 0) or at
  ``|IF| - doppler`` (real samples with IF < 0: spectral inversion), as the monitor's convention.

Example
-------
>>> import numpy as np
>>> from gnss_correlator.acquisition import AcquisitionConfig, acquire
>>> x = np.random.default_rng(0).normal(size=8000) + 1j * np.random.default_rng(1).normal(size=8000)
>>> res = acquire(x, 4e6, 0.0, AcquisitionConfig(prns=(1,), noncoherent_count=2, doppler_max_hz=1000))
>>> res[0].detected
False
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cache

import numpy as np
import scipy.fft
from scipy.special import gammainccinv

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ, GPS_CA_CODE_LENGTH_CHIPS, GPS_L1_FREQUENCY_HZ
from gnss_common.gps_ca import G2_DELAY_CHIPS, ca_code

CODE_PERIOD_S = GPS_CA_CODE_LENGTH_CHIPS / GPS_CA_CHIP_RATE_HZ
"""GPS C/A code period, s (1 ms; IS-GPS-200, 3.3.2.3)."""

MIN_SAMPLE_RATE_HZ = 2.0e6
"""Lowest sample rate accepted, Hz: about the C/A main lobe (2.046 MHz null to null)."""

NOISE_EXCLUSION_CHIPS = 1.5
"""Code delays within this many chips of the peak are left out of the noise floor, chips."""

_MAX_CHUNK_VALUES = 2_000_000
"""Complex values of the mixed samples held at once (Doppler bins are processed in chunks)."""


@dataclass(frozen=True)
class AcquisitionConfig:
    """What to search and how long to integrate.

    Attributes:
        prns: the PRNs searched, each in 1..37.
        coherent_ms: M, code periods (ms) summed coherently, 1..10. A data bit edge (every 20 ms)
            inside a coherent sum costs signal; 1 is safe.
        noncoherent_count: K, coherent sums added non-coherently, >= 1. The search uses
            M K ms of samples, the fine Doppler up to all of the input.
        doppler_max_hz: the search covers [-doppler_max_hz, +doppler_max_hz], Hz, > 0
            (satellite motion about +-5 kHz, plus the oscillator's offset).
        doppler_step_hz: grid step, Hz; None: 1 / (2 M ms) = 500 Hz / M (worst-case loss
            sinc^2(1/4) = -0.9 dB). Any value in (0, 1000 / M] Hz.
        false_alarm_probability: P_fa, the probability that a search for an absent PRN declares
            it present, in (0, 0.5).
    """

    prns: tuple[int, ...] = tuple(range(1, 33))
    coherent_ms: int = 1
    noncoherent_count: int = 10
    doppler_max_hz: float = 10_000.0
    doppler_step_hz: float | None = None
    false_alarm_probability: float = 1e-3

    def __post_init__(self) -> None:
        if not self.prns or any(int(p) not in G2_DELAY_CHIPS for p in self.prns):
            raise ValueError(f'prns must be a non-empty tuple of PRNs in 1..37, got {self.prns}')
        if not 1 <= self.coherent_ms <= 10:
            raise ValueError(f'coherent_ms must be in 1..10, got {self.coherent_ms}')
        if self.noncoherent_count < 1:
            raise ValueError(f'noncoherent_count must be >= 1, got {self.noncoherent_count}')
        if not (math.isfinite(self.doppler_max_hz) and self.doppler_max_hz > 0):
            raise ValueError(f'doppler_max_hz must be finite and > 0, got {self.doppler_max_hz}')
        if self.doppler_step_hz is not None and not 0 < self.doppler_step_hz <= 1000.0 / self.coherent_ms:
            raise ValueError(f'doppler_step_hz must be in (0, {1000.0 / self.coherent_ms}] Hz, '
                             f'got {self.doppler_step_hz}')
        if not 0 < self.false_alarm_probability < 0.5:
            raise ValueError(f'false_alarm_probability must be in (0, 0.5), got {self.false_alarm_probability}')

    @property
    def step_hz(self) -> float:
        """The Doppler step used, Hz."""
        return self.doppler_step_hz if self.doppler_step_hz is not None else 500.0 / self.coherent_ms

    def doppler_grid_hz(self) -> np.ndarray:
        """Trial Dopplers, Hz, symmetric about 0, spanning at least +-doppler_max_hz."""
        n = math.ceil(self.doppler_max_hz / self.step_hz - 1e-9)
        return np.arange(-n, n + 1) * self.step_hz

    @property
    def search_ms(self) -> int:
        """Code periods (ms) of samples the grid search uses: M K."""
        return self.coherent_ms * self.noncoherent_count


@dataclass(frozen=True)
class AcquisitionResult:
    """The search of one PRN.

    Attributes:
        prn: the PRN.
        detected: metric > threshold.
        code_delay_samples: samples from the first input sample to the first code start, in
            [0, samples per code period) (fractional: interpolated); the grid peak's even when not
            detected.
        code_delay_chips: the same in chips, [0, 1023).
        doppler_hz: carrier Doppler, Hz: fine estimate when detected, else the grid peak's.
        coarse_doppler_hz: the grid peak's Doppler, Hz.
        cn0_dbhz: C/N0 estimate, dB-Hz; NaN when not detected (or no signal power above the floor).
        metric: grid peak over the noise floor, ``max S / sigma^2`` (H0 mean: K).
        threshold: eta, the metric's threshold for the configured P_fa (from the fitted null).
        null_shape: k_eff of the null distribution fitted on the grid (K on white noise).
        null_scale: theta of that fit (1 on white noise).
        noise_floor: sigma^2, the noise power per coherent cell, (input units)^2.
        prompts_used: 1-ms prompts of the fine Doppler and C/N0 estimates (0 when not detected).
    """

    prn: int
    detected: bool
    code_delay_samples: float
    code_delay_chips: float
    doppler_hz: float
    coarse_doppler_hz: float
    cn0_dbhz: float
    metric: float
    threshold: float
    noise_floor: float
    null_shape: float
    null_scale: float
    prompts_used: int = 0


@dataclass(frozen=True)
class SearchGrid:
    """The search grid of one PRN (for tests and figures).

    Attributes:
        power: S, shape (n_doppler, samples per code period).
        doppler_hz: the grid's Dopplers, Hz, shape (n_doppler,).
    """

    power: np.ndarray = field(repr=False)
    doppler_hz: np.ndarray = field(repr=False)


def detection_threshold(shape: float, n_cells: int, false_alarm_probability: float, scale: float = 1.0) -> float:
    """eta such that P(max of n_cells Gamma(shape, scale) cells > eta) <= P_fa (union bound).

    Args:
        shape: the null distribution's shape (K for white noise, k_eff fitted on a grid).
        n_cells: cells of the search grid.
        false_alarm_probability: P_fa per satellite search.
        scale: the null distribution's scale (1 for white noise, theta fitted on a grid).

    Returns:
        eta, in units of the noise power per coherent cell.
    """
    return float(scale * gammainccinv(shape, false_alarm_probability / n_cells))


def null_fit(normalised: np.ndarray) -> tuple[float, float]:
    """Method-of-moments Gamma fit (shape k_eff, scale theta) of noise cells ``S / sigma^2``."""
    mean = float(np.mean(normalised))
    var = float(np.var(normalised))
    return mean * mean / var, var / mean


def carrier_frequency_hz(doppler_hz: np.ndarray | float, intermediate_frequency_hz: float,
                         is_complex: bool) -> np.ndarray | float:
    """Frequency at which the sampled stream carries a signal of a given Doppler, Hz.

    Args:
        doppler_hz: carrier Doppler, Hz.
        intermediate_frequency_hz: IF, Hz (< 0 for real samples: spectral inversion).
        is_complex: complex (I/Q) samples.
    """
    if not is_complex and intermediate_frequency_hz < 0:
        return -intermediate_frequency_hz - np.asarray(doppler_hz)
    return intermediate_frequency_hz + np.asarray(doppler_hz)


@cache
def _replica(prn: int, sample_rate_hz: float, n: int) -> np.ndarray:
    """The code of one period sampled at fs from chip 0, shape (n,), float64 +-1."""
    chips = np.floor(np.arange(n) * (GPS_CA_CHIP_RATE_HZ / sample_rate_hz)).astype(np.int64)
    return ca_code(prn).astype(np.float64)[chips % GPS_CA_CODE_LENGTH_CHIPS]


@cache
def _replica_spectrum(prn: int, sample_rate_hz: float, n: int) -> np.ndarray:
    """conj(FFT(code replica)), shape (n,), complex64."""
    return np.conj(scipy.fft.fft(_replica(prn, sample_rate_hz, n))).astype(np.complex64)


def _check_input(samples: np.ndarray, sample_rate_hz: float, intermediate_frequency_hz: float,
                 config: AcquisitionConfig) -> tuple[np.ndarray, bool]:
    x = np.asarray(samples)
    if x.ndim != 1:
        raise ValueError(f'samples must be one-dimensional, got shape {x.shape}')
    is_complex = bool(np.iscomplexobj(x))
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz >= MIN_SAMPLE_RATE_HZ):
        raise ValueError(f'sample_rate_hz must be >= {MIN_SAMPLE_RATE_HZ:g}, got {sample_rate_hz}')
    if not math.isfinite(intermediate_frequency_hz):
        raise ValueError(f'intermediate_frequency_hz must be finite, got {intermediate_frequency_hz}')
    if is_complex and abs(intermediate_frequency_hz) + config.doppler_max_hz >= sample_rate_hz / 2:
        raise ValueError(f'complex samples need |IF| + doppler_max_hz < fs/2: IF {intermediate_frequency_hz} Hz, '
                         f'fs {sample_rate_hz} Hz')
    if not is_complex:
        lo = abs(intermediate_frequency_hz) - config.doppler_max_hz
        hi = abs(intermediate_frequency_hz) + config.doppler_max_hz
        if lo <= 0 or hi >= sample_rate_hz / 2:
            raise ValueError(f'real samples need |IF| -+ doppler_max_hz inside (0, fs/2): IF '
                             f'{intermediate_frequency_hz} Hz, fs {sample_rate_hz} Hz')
    need = math.ceil(config.search_ms * CODE_PERIOD_S * sample_rate_hz)
    if x.size < need:
        raise ValueError(f'{config.search_ms} ms of samples needed ({need}), got {x.size}')
    if not np.all(np.isfinite(x)):
        raise ValueError('samples hold NaN or infinity')
    x = x.astype(np.complex128 if is_complex else np.float64)
    return x - x.mean(), is_complex


def search_grids(samples: np.ndarray, sample_rate_hz: float, intermediate_frequency_hz: float,
                 config: AcquisitionConfig) -> dict[int, SearchGrid]:
    """The non-coherent search grid S(tau, f_d) of every configured PRN.

    Args:
        samples: real (float, int) or complex front-end samples, shape (n,), n >= M K ms.
        sample_rate_hz: fs, Hz (complex: I/Q pairs per second), >= 2 MHz.
        intermediate_frequency_hz: IF, Hz (0 for complex baseband).
        config: the search.

    Returns:
        PRN -> its grid.
    """
    x, is_complex = _check_input(samples, sample_rate_hz, intermediate_frequency_hz, config)
    return _grids(x, is_complex, sample_rate_hz, intermediate_frequency_hz, config)


def _grids(x: np.ndarray, is_complex: bool, fs: float, if_hz: float,
           config: AcquisitionConfig) -> dict[int, SearchGrid]:
    n_code = round(fs * CODE_PERIOD_S)  # samples per replica (the FFT length)
    n_ms = config.search_ms
    starts = np.round(np.arange(n_ms) * fs * CODE_PERIOD_S).astype(np.int64)
    starts = np.minimum(starts, x.size - n_code)
    idx = starts[:, None] + np.arange(n_code)[None, :]  # (n_ms, n_code) absolute sample indices
    block = x[idx]
    dopplers = config.doppler_grid_hz()
    f_carrier = np.asarray(carrier_frequency_hz(dopplers, if_hz, is_complex), dtype=np.float64)
    chunk = max(1, _MAX_CHUNK_VALUES // (n_ms * n_code))
    power = {prn: np.empty((dopplers.size, n_code), dtype=np.float64) for prn in config.prns}
    t_s = idx / fs
    for lo in range(0, dopplers.size, chunk):
        f = f_carrier[lo:lo + chunk]
        # phase reduced in cycles before the multiplication by 2 pi keeps float64 exact enough
        cycles = np.mod(f[:, None, None] * t_s[None, :, :], 1.0)
        mixed = (block[None, :, :] * np.exp(-2j * np.pi * cycles)).astype(np.complex64)
        spec = scipy.fft.fft(mixed, axis=-1)
        spec = spec.reshape(f.size, config.noncoherent_count, config.coherent_ms, n_code).sum(axis=2)
        for prn in config.prns:
            corr = scipy.fft.ifft(spec * _replica_spectrum(int(prn), fs, n_code), axis=-1, overwrite_x=True)
            power[prn][lo:lo + f.size] = np.sum(corr.real ** 2 + corr.imag ** 2, axis=1, dtype=np.float64)
    return {prn: SearchGrid(power=power[prn], doppler_hz=dopplers) for prn in config.prns}


def _noise_cells(power: np.ndarray, peak_delay: int, samples_per_chip: float) -> np.ndarray:
    """The cells of S more than NOISE_EXCLUSION_CHIPS from the peak's code delay, flattened."""
    n_code = power.shape[1]
    dist = np.abs((np.arange(n_code) - peak_delay + n_code // 2) % n_code - n_code // 2)
    return power[:, dist > NOISE_EXCLUSION_CHIPS * samples_per_chip].ravel()


def _triangle_offset(left: float, centre: float, right: float) -> float:
    """Peak offset, in samples, of a triangle (the code's correlation) through three equally spaced
    amplitudes, the centre one the largest: ``(right - left) / (2 (centre - min(left, right)))``,
    exact while the samples are less than a chip apart; clipped to [-0.5, 0.5]."""
    den = 2.0 * (centre - min(left, right))
    if den <= 0:
        return 0.0
    return float(np.clip((right - left) / den, -0.5, 0.5))


def prompts(x: np.ndarray, is_complex: bool, fs: float, if_hz: float, prn: int, code_delay_samples: float,
            doppler_hz: float) -> np.ndarray:
    """1-ms prompt correlations on the code epochs that fit in the input, from the first code start.

    Args:
        x: samples (mean removed), shape (n,).
        is_complex: complex samples.
        fs: sample rate, Hz.
        if_hz: IF, Hz.
        prn: the PRN.
        code_delay_samples: first code start, samples (fractional).
        doppler_hz: carrier Doppler of the replica, Hz (the code rate is scaled by 1 + f_d / f_L1).

    Returns:
        complex prompts, shape (n_epochs,), in the input's units times samples.
    """
    chip_rate = GPS_CA_CHIP_RATE_HZ * (1.0 + doppler_hz / GPS_L1_FREQUENCY_HZ)
    period = GPS_CA_CODE_LENGTH_CHIPS / chip_rate * fs  # samples per code period
    first = math.ceil(code_delay_samples)
    n_epochs = int((x.size - code_delay_samples) // period)
    if n_epochs < 1:
        return np.zeros(0, dtype=np.complex128)
    end = code_delay_samples + n_epochs * period
    n = np.arange(first, min(x.size, math.ceil(end)))
    chips = (n - code_delay_samples) * (chip_rate / fs)
    code = ca_code(prn).astype(np.float64)[np.floor(chips).astype(np.int64) % GPS_CA_CODE_LENGTH_CHIPS]
    f_c = float(carrier_frequency_hz(doppler_hz, if_hz, is_complex))
    wiped = x[n] * code * np.exp(-2j * np.pi * np.mod(f_c * n / fs, 1.0))
    epoch = np.floor(chips / GPS_CA_CODE_LENGTH_CHIPS).astype(np.int64)
    return np.bincount(epoch, weights=wiped.real, minlength=n_epochs)[:n_epochs] \
        + 1j * np.bincount(epoch, weights=wiped.imag, minlength=n_epochs)[:n_epochs]


def acquire(samples: np.ndarray, sample_rate_hz: float, intermediate_frequency_hz: float,
            config: AcquisitionConfig = AcquisitionConfig()) -> list[AcquisitionResult]:
    """Search every configured PRN in a snapshot of front-end samples.

    Args:
        samples: real (float or int) or complex front-end samples, shape (n,); the search uses the
            first M K ms, the fine estimates every whole code period after the first code start.
        sample_rate_hz: fs, Hz (complex: I/Q pairs per second), >= 2 MHz (2-40 MHz tested).
        intermediate_frequency_hz: IF, Hz; 0 for complex baseband; < 0 for a spectrally inverted
            real IF.
        config: the search.

    Returns:
        One result per configured PRN, in the configured order.

    Raises:
        ValueError: too few samples, a sample rate below 2 MHz, real samples whose IF band does not
            fit in (0, fs/2), non-finite samples.
    """
    x, is_complex = _check_input(samples, sample_rate_hz, intermediate_frequency_hz, config)
    fs = float(sample_rate_hz)
    grids = _grids(x, is_complex, fs, intermediate_frequency_hz, config)
    k = config.noncoherent_count
    n_code = round(fs * CODE_PERIOD_S)
    samples_per_chip = fs / GPS_CA_CHIP_RATE_HZ
    out = []
    for prn in config.prns:
        grid = grids[prn]
        power = grid.power
        i_dopp, i_delay = np.unravel_index(int(np.argmax(power)), power.shape)
        noise = _noise_cells(power, int(i_delay), samples_per_chip)
        sigma2 = float(noise.mean() / k)
        if not sigma2 > 0:
            raise ValueError('the samples carry no power (all equal)')
        k_eff, theta = null_fit(noise / sigma2)
        eta = detection_threshold(k_eff, power.size, config.false_alarm_probability, theta)
        metric = float(power[i_dopp, i_delay] / sigma2)
        three = power[i_dopp, [(i_delay - 1) % n_code, i_delay, (i_delay + 1) % n_code]]
        amp = np.sqrt(np.maximum(three - k * sigma2, 0.0))
        delay = (i_delay + _triangle_offset(*amp)) % n_code
        coarse = float(grid.doppler_hz[i_dopp])
        detected = metric > eta
        doppler, cn0, used = coarse, math.nan, 0
        if detected:
            doppler, cn0, used = _refine(x, is_complex, fs, intermediate_frequency_hz, int(prn),
                                         (float(i_delay) - 0.5, float(delay)), coarse, sigma2 / config.coherent_ms)
        out.append(AcquisitionResult(
            prn=int(prn), detected=bool(detected), code_delay_samples=float(delay),
            code_delay_chips=float(delay / samples_per_chip) % GPS_CA_CODE_LENGTH_CHIPS,
            doppler_hz=doppler, coarse_doppler_hz=coarse, cn0_dbhz=cn0, metric=metric, threshold=eta,
            noise_floor=sigma2, null_shape=k_eff, null_scale=theta, prompts_used=used))
    return out


def _refine(x: np.ndarray, is_complex: bool, fs: float, if_hz: float, prn: int, delays: tuple[float, float],
            coarse_hz: float, sigma1_2: float) -> tuple[float, float, int]:
    """Fine Doppler (lag-one autocorrelation of the prompts) and C/N0 from the 1-ms prompts (module notes).

    The prompts are taken at whichever of two delays gives the more power: the interpolated one, and
    half a sample before the grid's peak. Where the rate is a multiple of the chip rate (2.046 MHz),
    chip edges fall on samples: a fractional delay is not observable, and a replica whose edges sit
    exactly on samples slips a whole sample by the code Doppler's rounding; half a sample before the
    peak is the middle of the delays that give the grid peak's sampled replica.
    """
    best: np.ndarray | None = None
    for delay in delays:
        z = prompts(x, is_complex, fs, if_hz, prn, delay, coarse_hz)
        if best is None or (z.size and np.mean(np.abs(z) ** 2) > np.mean(np.abs(best) ** 2)):
            best, chosen = z, delay
    assert best is not None
    if best.size < 2:
        return coarse_hz, math.nan, int(best.size)
    dphi = float(np.angle(np.sum(best[1:] * np.conj(best[:-1]))))
    delta_hz = dphi / (2.0 * np.pi * CODE_PERIOD_S)
    inverted = (not is_complex) and if_hz < 0
    fine = coarse_hz - delta_hz if inverted else coarse_hz + delta_hz
    z = prompts(x, is_complex, fs, if_hz, prn, chosen, fine)
    signal = float(np.mean(np.abs(z) ** 2)) - sigma1_2
    cn0 = 10.0 * math.log10(signal / sigma1_2 / CODE_PERIOD_S) if signal > 0 else math.nan
    return fine, cn0, int(z.size)

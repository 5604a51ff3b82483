"""Quality of a tracked channel: C/N0 and lock that know a jammer is there (issue 29), computed by the
tracking kernel (``tracking``) at each code period's end over the last periods.

* **noise reference**: per channel a fourth correlator, the same code ``noise_offset_chips(prn)`` (>= 300)
  chips away from the prompt, same carrier wipe-off: it holds no signal (the code's autocorrelation there is
  -1/1023) but the same noise and, for interference, the same despread residue in expectation (a periodic
  code's spectral lines have the same magnitudes at every offset); a jammer raises it as it raises the
  prompt's noise;
* **C/N0** over the last W = ``cn0_window_ms`` periods: ``P_n = mean |N|^2`` (the noise reference),
  ``P_s = mean |P|^2 - P_n``, ``C/N0 = P_s / (P_n T)``, i.e. the C/N0 *effective* under interference
  (C / (N0 + J_eff)); insensitive to the carrier phase and to the data bits; ``P_s`` is floored at
  CN0_FLOOR_SIGMAS x sqrt(2 / W) P_n (the estimate's spread on noise alone: 26 dB-Hz at W = 50, 1 ms). The
  moments (M2M4) estimator of Pauluzzi & Beaulieu (IEEE Trans. Commun. 48(10), 2000, eq. 14) is kept beside
  it for comparison: it measures the prompt's constant-envelope part, and a jammer's despread residue
  (a chirp's or a CW's lines leak through the code's lines as a tone) is constant-envelope too, so it reads
  the residue as signal (on the real capture with a chirp at J/S 40 dB it *rose* to 48 dB-Hz);
* **lock rule** over the last ``lock_window_ms`` periods (the issue's "phase error std and no half-cycle
  slip over the last 100 ms"): locked iff the Costas discriminator ``e_p``'s std is at most
  ``lock_phase_std_max_rad`` and no **half-cycle wrap** occurred: the Costas angle atan(Q/I) of a block of
  ``wrap_block_ms`` summed prompts changed by more than pi / 2 (WRAP_THRESHOLD_RAD) from the previous block's
  (1: consecutive 1-ms discriminators; a data bit flip inside a block leaves its angle modulo pi unchanged).
  A half-cycle slip of the loop means its phase error crosses +-pi/2, where atan(Q/I) steps by about pi:
  every slip makes a wrap (so no wrap in the window means no slip in it); a wrap without a slip (the error
  crossing back, or noise) is a false alarm, rare above 38 dB-Hz with 1-ms blocks (measured against the
  simulator's truth: docs/gnss_correlator/lock_rule.md). The wraps counted are the slip detector's output.
* the lock indicator ``cos(2 e_p)`` estimated as ``(I^2 - Q^2) / (I^2 + Q^2)`` over the C/N0 window
  (Van Dierendonck, in Parkinson & Spilker, vol. I, ch. 8) is reported too, 1 when locked, ~0 when not.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gnss_common.constants import GPS_CA_CODE_LENGTH_CHIPS
from gnss_common.gps_ca import ca_code
from gnss_common.moments import m2m4_powers

WRAP_THRESHOLD_RAD = 0.5 * math.pi
"""A change of the Costas discriminator atan(Q/I) by more than this from one period to the next is a half-cycle
wrap (the phase error crossed +-pi/2: a half-cycle slip candidate), rad. A true crossing steps by about pi."""
CN0_FLOOR_SIGMAS = 2.0
"""The noise-reference C/N0 reports a signal power of at least this many standard deviations of its estimate on
noise alone (sqrt(2 / W) P_n over W periods): a reading at the floor means 'not above it'."""
NOISE_MIN_OFFSET_CHIPS = 300
"""The noise-reference correlator sits at least this many chips from the prompt (and from the early and late)."""


def noise_offset_chips(prn: int) -> int:
    """Code offset of the noise-reference correlator of ``prn``, chips: the first offset from
    NOISE_MIN_OFFSET_CHIPS at which the code's periodic autocorrelation is -1 (of 1023: the Gold code's
    smallest side lobe, IS-GPS-200 codes take -1, -65 and 63) at the offset and at its neighbours +-1 and +-2
    chips, so that the satellite's own signal leaks into it 60 dB below the prompt even with a code error of a
    chip."""
    code = ca_code(int(prn)).astype(np.float64)
    spec = np.fft.fft(code)
    acf = np.rint(np.fft.ifft(spec * np.conj(spec)).real).astype(np.int64)
    n = GPS_CA_CODE_LENGTH_CHIPS
    for k in range(NOISE_MIN_OFFSET_CHIPS, n - NOISE_MIN_OFFSET_CHIPS):
        if all(acf[(k + j) % n] == -1 for j in range(-2, 3)):
            return k
    raise ValueError(f'no quiet code offset for PRN {prn}')  # never for the 37 C/A codes (tested)


@njit(cache=True, nogil=True)
def window_quality(ring: np.ndarray, noise_ring: np.ndarray, t_s: float) -> tuple[float, float, float, float]:
    """Of a window of prompts and of the noise-reference correlators of the same periods: C/N0 of the
    noise-reference estimator (dB-Hz, floored), C/N0 of the moments estimator (dB-Hz, NaN without signal power),
    the lock indicator mean(I^2 - Q^2) / mean(I^2 + Q^2), and the noise power per prompt (the noise reference's
    mean power). The estimators: the module docstring."""
    m2 = 0.0
    m4 = 0.0
    d = 0.0
    mn = 0.0
    for k in range(ring.shape[0]):
        z = ring[k]
        p2 = z.real * z.real + z.imag * z.imag
        m2 += p2
        m4 += p2 * p2
        d += z.real * z.real - z.imag * z.imag
        zn = noise_ring[k]
        mn += zn.real * zn.real + zn.imag * zn.imag
    w = ring.shape[0]
    m2 /= w
    m4 /= w
    mn /= w
    lock = d / w / m2 if m2 > 0 else math.nan
    cn0_m2m4 = moments_cn0_dbhz(m2, m4, t_s)
    if not mn > 0:
        return math.nan, cn0_m2m4, lock, math.nan
    ps_ref = max(m2 - mn, CN0_FLOOR_SIGMAS * math.sqrt(2.0 / w) * mn)
    return 10.0 * math.log10(ps_ref / mn / t_s), cn0_m2m4, lock, mn


@njit(cache=True, nogil=True)
def moments_cn0_dbhz(m2: float, m4: float, t_s: float) -> float:
    """C/N0 (dB-Hz) of the moments estimator from the prompts' M2 = mean |P|^2 and M4 = mean |P|^4 over a window
    of prompts of T = ``t_s`` each: ``P_s / P_n / T`` with ``(P_s, P_n)`` of ``gnss_common.moments.m2m4_powers``;
    NaN when the moments give no signal power (2 M2^2 <= M4) or no noise power."""
    ps, pn = m2m4_powers(m2, m4)
    if ps > 0.0 and pn > 0.0:
        return 10.0 * math.log10(ps / pn / t_s)
    return math.nan


@njit(cache=True, nogil=True)
def lock_window(err_ring: np.ndarray) -> tuple[float, float]:
    """Std (rad) of the PLL discriminator (column 0) and the half-cycle wraps (column 1) over the ring."""
    w = err_ring.shape[0]
    s1 = 0.0
    s2 = 0.0
    wraps = 0.0
    for j in range(w):
        e = err_ring[j, 0]
        s1 += e
        s2 += e * e
        wraps += err_ring[j, 1]
    mean = s1 / w
    return math.sqrt(max(s2 / w - mean * mean, 0.0)), wraps


def m2m4_cn0_dbhz(prompts: np.ndarray, integration_time_s: float) -> float:
    """C/N0 from coherent prompts by the moments estimator (Pauluzzi & Beaulieu 2000, eq. 14 for
    complex samples; ``gnss_common.moments``): ``P_s = sqrt(2 M2^2 - M4)``, ``P_n = M2 - P_s``,
    ``C/N0 = P_s / P_n / T`` (:func:`moments_cn0_dbhz`, the tracking kernel's too).

    Args:
        prompts: complex prompts, shape (n,), n >= 2.
        integration_time_s: T of each prompt, s.

    Returns:
        dB-Hz; NaN when the moments give no signal power (2 M2^2 <= M4) or no noise power.
    """
    p2 = np.abs(prompts) ** 2
    return moments_cn0_dbhz(float(np.mean(p2)), float(np.mean(p2 * p2)), float(integration_time_s))

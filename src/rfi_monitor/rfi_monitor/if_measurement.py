"""Three-sample instantaneous-frequency (IF) measurement of a strong tone or chirp.

Real samples (Kang et al., eq. 7-10): for ``r_n = A cos(theta_n)`` with ``theta_{n+-1} = theta_n
+- w_n + pi df`` (a linear chirp of instantaneous angular frequency ``w_n = 2 pi f_n`` and sweep
``df`` cycles/sample^2), the sum and difference of the outer samples are

    S = (r_{n+1} + r_{n-1}) / 2 = A cos(theta_n + pi df) cos(w_n)
    D = (r_{n+1} - r_{n-1}) / 2 = -A sin(theta_n + pi df) sin(w_n)

so ``S / r_n = cos(w_n) [cos(pi df) - tan(theta_n) sin(pi df)]``. With df = 0 this is eq. 8,
``f_n = arccos(S / r_n) / (2 pi)``; with df != 0 it is eq. 10 (the paper's garbled eq. 9 is
re-derived here; its "2 pi df/2" is pi df). The phase term ``tan(theta_n)`` is not known to the
receiver; we take it from the same three samples, ``tan(theta_n) ~= -D / (r_n sin(w0))`` with w0
from eq. 8 (first order in pi df), and apply eq. 10 once. The measurement is in [0, 0.5]
cycles/sample (a real signal carries no frequency sign).

Complex samples (derivation in docs/rfi_monitor/complex_baseband.md): for ``x_n = A exp(j theta_n)``
the same recurrence gives ``x_{n+1} + x_{n-1} = 2 cos(w_n) x_n e^{j pi df}`` and
``x_{n+1} - x_{n-1} = 2 j sin(w_n) x_n e^{j pi df}``; combining both,

    f_n = arg(x_{n+1} x_n^* + x_n x_{n-1}^*) / (2 pi)        in (-0.5, 0.5]

which is exact for a linear chirp (the two lag products have phases 2 pi (f_n +- df/2) and
equal moduli), needs no division by a sample and has no arccos domain.

arccos: ``acos_fast`` (Abramowitz & Stegun 4.4.46, |error| <= 2e-8 rad, i.e. 3e-9 cycles/sample,
far below any measurement noise) replaces libm's acos, which alone cost ~19 ns per sample on the
benchmark machine (the real-time budget at 38.192 MS/s is 26 ns per sample for the whole chain).

Noise compensation (beyond the paper, real samples only): with white noise of power N on a tone of
power J, the ratio S / r_n is compressed towards 0 by about ``kappa = J / (J + N)`` (the noise
adds to the denominator's power, not to the numerator's correlation), so eq. 8 is biased towards
fs/4: at J/N 11.2 dB (kappa 0.93) a chirp sweeping 0.18..0.32 cycles/sample is measured with a
bias of +0.004 at its start and -0.003 at its end, which the tracker turns into a too shallow
sweep and a late reset value (docs/rfi_monitor/paper_results.md). ``inv_kappa = 1 / kappa``
multiplies the ratio before the domain test and arccos; the monitor takes kappa from its running
power and calibrated noise floor, ``kappa = 1 - N / P``. Measured on a tone (median bias,
cycles/sample, uncompensated -> compensated): J/N 11.2 dB, f = 0.15: +0.0098 -> +0.0035; f = 0.2:
+0.0032 -> -0.0002; f = 0.3: -0.0033 -> +0.0002; near 0 and fs/2 the arccos domain clipping
dominates and remains (f = 0.05: +0.059 -> +0.054). The complex measurement is unbiased (measured
below 1e-4 at J/N 5 and 11 dB) and needs none.

Guards (the paper's Fig. 2 errors): a sample with |r_n| (or |x_n|) below ``min_abs`` is rejected
(near-zero divisor); a real ratio outside [-1 - margin, 1 + margin] is rejected (arccos domain),
inside the margin it is clipped to [-1, 1]; a chirp correction whose factor falls below 0.5 is
rejected; non-finite samples are rejected. Status codes are the ``STATUS_*`` constants.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

STATUS_OK = 0
STATUS_NEAR_ZERO = 1
STATUS_DOMAIN = 2
STATUS_NON_FINITE = 3
STATUS_CORRECTION = 4
N_STATUS = 5

_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def acos_fast(x: float) -> float:
    """arccos(x) for x in [-1, 1], rad, |error| <= 2e-8 (Abramowitz & Stegun 4.4.46).

    Args:
        x: cosine, in [-1, 1] (the caller clips).

    Returns:
        angle in [0, pi], rad.
    """
    a = abs(x)
    p = -0.0012624911
    p = p * a + 0.0066700901
    p = p * a - 0.0170881256
    p = p * a + 0.0308918810
    p = p * a - 0.0501743046
    p = p * a + 0.0889789874
    p = p * a - 0.2145988016
    p = p * a + 1.5707963050
    r = math.sqrt(1.0 - a) * p
    return r if x >= 0.0 else math.pi - r


_TAN_PI_8 = math.tan(math.pi / 8.0)


@njit(cache=True, inline="always", error_model="numpy")
def atan2_fast(y: float, x: float) -> float:
    """atan2(y, x), rad, in [-pi, pi], |error| <= 1e-12 rad, without data-dependent branches.

    Args:
        y, x: any finite values, not both zero (the result is then NaN; the caller masks it).

    Returns:
        angle, rad (y = -0.0 with x < 0 gives +pi, where libm gives -pi).

    Notes:
        atan of ``t = min(|x|, |y|) / max(|x|, |y|)`` in [0, 1]; above tan(pi/8) by
        ``atan t = pi/4 + atan((t - 1) / (t + 1))`` (one division either way), so that the
        polynomial only covers |t| <= tan(pi/8) = 0.414: ``t P(t^2)`` of degree 15, coefficients a
        least-squares fit (ours) to atan on that interval, max error 3e-13 rad; then the octant
        by selects. Replaces libm's atan2 (a call per sample, not vectorised) in the complex path.
    """
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    mn = min(ax, ay)
    big = mn > _TAN_PI_8 * mx
    t = (mn - mx if big else mn) / (mn + mx if big else mx)
    t2 = t * t
    p = -0.03689059557509951
    p = p * t2 + 0.06923569875384492
    p = p * t2 - 0.08979132378181513
    p = p * t2 + 0.1110164377047397
    p = p * t2 - 0.14285255261811863
    p = p * t2 + 0.19999988169691182
    p = p * t2 - 0.3333333319680412
    p = p * t2 + 0.9999999999954501
    a = t * p + (0.25 * math.pi if big else 0.0)
    a = 0.5 * math.pi - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    return -a if y < 0.0 else a


@njit(cache=True, inline="always")
def sincos_small(e: float) -> tuple[float, float]:
    """(sin e, cos e) by Taylor polynomials for |e| <= 0.07 rad (|error| < 1e-10).

    The chirp correction needs them for ``e = pi df`` with |df| <= MAX_ABS_RATE = 0.02
    cycles/sample^2 (|e| <= 0.063); libm's sin and cos cost ~20 ns each per sample.
    """
    e2 = e * e
    return (e * (1.0 - e2 * (1.0 / 6.0 - e2 * (1.0 / 120.0))),
            1.0 - e2 * (0.5 - e2 * (1.0 / 24.0 - e2 * (1.0 / 720.0))))


@njit(cache=True, inline="always", error_model="numpy")
def measure_real(r_prev: float, r_0: float, r_next: float, delta_f: float, chirp_correction: bool,
                 min_abs: float, domain_margin: float) -> tuple[float, int]:
    """Digital frequency of a real tone/chirp from three consecutive samples (``measure_real_sq``
    with the near-zero threshold given as |r_n| <= min_abs)."""
    return measure_real_sq(r_prev, r_0, r_next, delta_f, chirp_correction, min_abs * min_abs, domain_margin, 1.0)


@njit(cache=True, inline="always", error_model="numpy")
def measure_real_sq(r_prev: float, r_0: float, r_next: float, delta_f: float, chirp_correction: bool,
                    min_abs_sq: float, domain_margin: float, inv_kappa: float) -> tuple[float, int]:
    """Digital frequency of a real tone/chirp from three consecutive samples.

    Args:
        r_prev, r_0, r_next: samples r_{n-1}, r_n, r_{n+1}, any consistent unit.
        delta_f: sweep, cycles/sample^2 (Kang's Delta f), used by the chirp correction,
            |delta_f| <= 0.02 (the polynomial sin/cos of ``sincos_small``).
        chirp_correction: apply eq. 10 (else eq. 8).
        min_abs_sq: reject when r_n^2 <= min_abs_sq (sample unit squared).
        domain_margin: tolerated excess of |S / r_n| over 1 before rejection, >= 0.
        inv_kappa: noise compensation 1 / kappa >= 1 (module docstring), 1: none (the paper).

    Returns:
        (f_n in cycles/sample in [0, 0.5], status code). f_n is NaN unless status == STATUS_OK.

    Notes:
        Kang et al., eq. 8 and eq. 10 (see the module docstring for the derivation). Written
        without data-dependent branches and with one division (speed): with ``Q = sqrt(r_n^2 -
        S^2) = |r_n| sin(w0)``, eq. 10's ratio ``S / (r_n [cos(e) - tan(theta) sin(e)])`` with
        ``tan(theta) = -D / (r_n sin(w0))`` is ``S Q / (r_n Q cos(e) + D |r_n| sin(e))``, e = pi df;
        its factor is below 0.5 when ``den r_n < r_n^2 Q / 2``. Without correction (or sin(w0) <
        1e-6) the ratio is S / r_n (eq. 8). Checks in order: non-finite, near zero, domain of S /
        r_n, correction factor, domain of the corrected ratio.
    """
    s = 0.5 * inv_kappa * (r_next + r_prev)       # S / kappa (noise compensation; 1: eq. 8 / 10)
    d = 0.5 * (r_next - r_prev)
    r0sq = r_0 * r_0
    abs_r0 = abs(r_0)
    lim = 1.0 + domain_margin
    q = math.sqrt(max(r0sq - s * s, 0.0))
    sn, cs = sincos_small(math.pi * delta_f)
    den_c = r_0 * q * cs + d * abs_r0 * sn
    use_corr = chirp_correction and delta_f != 0.0 and q >= 1e-6 * abs_r0
    num = s * q if use_corr else s
    den = den_c if use_corr else r_0
    ratio = num / den
    bad_corr = use_corr and den_c * r_0 < 0.5 * r0sq * q
    finite = math.isfinite(r_prev + r_0 + r_next)
    st = STATUS_DOMAIN if abs(ratio) > lim else STATUS_OK
    st = STATUS_CORRECTION if bad_corr else st
    st = STATUS_DOMAIN if s * s > lim * lim * r0sq else st
    st = STATUS_NEAR_ZERO if r0sq <= min_abs_sq else st
    st = STATUS_NON_FINITE if not finite else st
    w = acos_fast(min(1.0, max(-1.0, ratio)))
    return (w * (1.0 / _TWO_PI) if st == STATUS_OK else math.nan), st


@njit(cache=True, inline="always", error_model="numpy")
def measure_complex(re_prev: float, im_prev: float, re_0: float, im_0: float, re_next: float,
                    im_next: float, min_abs: float) -> tuple[float, int]:
    """Signed digital frequency of a complex tone/chirp from three consecutive I/Q samples
    (``measure_complex_sq`` with the near-zero threshold given as |x_n| <= min_abs)."""
    return measure_complex_sq(re_prev, im_prev, re_0, im_0, re_next, im_next, min_abs * min_abs)


@njit(cache=True, inline="always", error_model="numpy")
def measure_complex_sq(re_prev: float, im_prev: float, re_0: float, im_0: float, re_next: float,
                       im_next: float, min_abs_sq: float) -> tuple[float, int]:
    """Signed digital frequency of a complex tone/chirp from three consecutive I/Q samples.

    Args:
        re_*, im_*: I and Q of x_{n-1}, x_n, x_{n+1}.
        min_abs_sq: reject when |x_n|^2 <= min_abs_sq.

    Returns:
        (f_n in cycles/sample in (-0.5, 0.5], status code); NaN unless STATUS_OK.

    Notes:
        Complex counterpart of Kang et al., eq. 8/10: arg(x_{n+1} x_n^* + x_n x_{n-1}^*) / 2 pi,
        derived in docs/rfi_monitor/complex_baseband.md. Written without data-dependent branches
        (``atan2_fast``, selects for the checks: non-finite, then near zero, then a zero sum), so
        that the compiled loop vectorises.
    """
    finite = math.isfinite(re_prev + im_prev + re_0 + im_0 + re_next + im_next)
    # x_{n+1} conj(x_n) + x_n conj(x_{n-1})
    a_re = re_next * re_0 + im_next * im_0 + re_0 * re_prev + im_0 * im_prev
    a_im = im_next * re_0 - re_next * im_0 + im_0 * re_prev - re_0 * im_prev
    st = STATUS_NEAR_ZERO if (a_re == 0.0 and a_im == 0.0) else STATUS_OK
    st = STATUS_NEAR_ZERO if re_0 * re_0 + im_0 * im_0 <= min_abs_sq else st
    st = STATUS_NON_FINITE if not finite else st
    w = atan2_fast(a_im, a_re)
    return (w * (1.0 / _TWO_PI) if st == STATUS_OK else math.nan), st


@njit(cache=True, error_model="numpy")
def _measure_block_real(x: np.ndarray, delta_f: np.ndarray, chirp_correction: bool, min_abs: float,
                        domain_margin: float, inv_kappa: float) -> tuple[np.ndarray, np.ndarray]:
    n = x.size
    z = np.full(max(n - 2, 0), np.nan)
    st = np.zeros(max(n - 2, 0), dtype=np.int8)
    for k in range(1, n - 1):
        z[k - 1], st[k - 1] = measure_real_sq(x[k - 1], x[k], x[k + 1], delta_f[k - 1], chirp_correction,
                                              min_abs * min_abs, domain_margin, inv_kappa)
    return z, st


@njit(cache=True, error_model="numpy")
def _measure_block_complex(xr: np.ndarray, xi: np.ndarray, min_abs: float) -> tuple[np.ndarray, np.ndarray]:
    n = xr.size
    z = np.full(max(n - 2, 0), np.nan)
    st = np.zeros(max(n - 2, 0), dtype=np.int8)
    for k in range(1, n - 1):
        z[k - 1], st[k - 1] = measure_complex(xr[k - 1], xi[k - 1], xr[k], xi[k], xr[k + 1], xi[k + 1],
                                              min_abs)
    return z, st


def measure_if(x: np.ndarray, delta_f: float | np.ndarray = 0.0, chirp_correction: bool = False,
               min_abs: float = 0.0, domain_margin: float = 0.05,
               tone_power_fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample IF measurements of a whole array (stand-alone; the monitor fuses this in its loop).

    Args:
        x: samples, shape (n,), real (float/int) or complex.
        delta_f: sweep per sample, cycles/sample^2, scalar or shape (n - 2,) (real chirp correction).
        chirp_correction: use eq. 10 instead of eq. 8 (real samples only).
        min_abs: near-zero guard on |x_n|, sample units, >= 0.
        domain_margin: arccos domain margin (real samples), >= 0.
        tone_power_fraction: kappa = J / (J + N) of the noise compensation (real samples, module
            docstring), in (0, 1]; 1: none (eq. 8 / 10 as in the paper).

    Returns:
        (z, status): z shape (n - 2,), cycles/sample, measurement for samples 1..n-2 (NaN where
        rejected); status shape (n - 2,) int8 codes.

    Raises:
        ValueError: x not 1-D, negative guards, or tone_power_fraction outside (0, 1].
    """
    x = np.asarray(x)
    if x.ndim != 1:
        raise ValueError("x must be 1-D")
    if min_abs < 0 or domain_margin < 0:
        raise ValueError("min_abs and domain_margin must be >= 0")
    if not 0.0 < tone_power_fraction <= 1.0:
        raise ValueError(f"tone_power_fraction must be in (0, 1], got {tone_power_fraction}")
    if np.iscomplexobj(x):
        xc = x.astype(np.complex128)
        return _measure_block_complex(np.ascontiguousarray(xc.real), np.ascontiguousarray(xc.imag),
                                      float(min_abs))
    xr = x.astype(np.float64)
    df = np.broadcast_to(np.asarray(delta_f, dtype=np.float64), (max(xr.size - 2, 0),))
    return _measure_block_real(xr, np.ascontiguousarray(df), bool(chirp_correction), float(min_abs),
                               float(domain_margin), 1.0 / float(tone_power_fraction))

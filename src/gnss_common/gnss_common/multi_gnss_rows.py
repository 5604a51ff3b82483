"""Per-satellite row arithmetic of the multi-constellation snapshot (:mod:`gnss_common.multi_gnss_fix`).

Pure core (no rclpy, no state). Compiled kernels for the element-wise work of one fix: screening, Sagnac
rotation, variances, the rows of the normal equations, residuals and rate variances. A 20 Hz
multi-GNSS stream made that work, tens of numpy calls on 40-element arrays per Gauss-Newton
iteration, the larger part of the fix's cost (docs/gnss_integrity/speed.md).

The kernels do the same IEEE operations in the same order, element by element, as the numpy
expressions they replace (each quoted in its docstring), so their results are bit-identical: the
fix's residuals are differences of 2e7 m ranges, where a changed last bit would move a chi-square
statistic by 1e-9. What has no order-preserving element-wise form stays a numpy call in the fix:
the transcendental functions, the 3-term dot products (``einsum``, BLAS) and the matrix algebra.
:func:`warm_up` compiles (or loads from numba's cache) every kernel.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from gnss_common.constants import EARTH_ROTATION_RATE_RADPS, SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation_scalar


@njit(cache=True)
def _floor(x: float, low: float) -> float:
    """``np.maximum(x, low)`` of one element (NaN propagates)."""
    return x if (x != x or x >= low) else low


@njit(cache=True)
def screen_flags(s: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per observation: finite, physically plausible, usable rate.

    ``s`` columns: pseudorange, satellite clock bias, ionosphere, troposphere, rate, satellite clock drift
    (m, m/s); ``pos``, ``vel`` (n, 3). Finite: the first four and the position; physical: pseudorange in
    [1e7, 5e7] m, ``sqrt(sum(pos * pos))`` in [2e7, 5e7] m, ``|clock| < 3e6`` m, ionosphere in [0, 200],
    troposphere in [0, 100] m; rate: rate, drift and velocity finite, ``|rate| < 1e5`` m/s.
    """
    n = s.shape[0]
    finite = np.zeros(n, dtype=np.bool_)
    physical = np.zeros(n, dtype=np.bool_)
    rate_ok = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        finite[i] = (math.isfinite(s[i, 0]) and math.isfinite(s[i, 1]) and math.isfinite(s[i, 2])
                     and math.isfinite(s[i, 3]) and math.isfinite(pos[i, 0]) and math.isfinite(pos[i, 1])
                     and math.isfinite(pos[i, 2]))
        r = math.sqrt(pos[i, 0] * pos[i, 0] + pos[i, 1] * pos[i, 1] + pos[i, 2] * pos[i, 2])
        physical[i] = (1.0e7 <= s[i, 0] <= 5.0e7 and 2.0e7 <= r <= 5.0e7 and abs(s[i, 1]) < 3.0e6
                       and 0.0 <= s[i, 2] <= 200.0 and 0.0 <= s[i, 3] <= 100.0)
        rate_ok[i] = (math.isfinite(s[i, 4]) and math.isfinite(s[i, 5]) and math.isfinite(vel[i, 0])
                      and math.isfinite(vel[i, 1]) and math.isfinite(vel[i, 2]) and abs(s[i, 4]) < 1.0e5)
    return finite, physical, rate_ok


@njit(cache=True)
def sagnac_rotate(sat: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Satellite positions rotated by the Earth's rotation during the travel time, minus ``pos``, and
    the rotation's cos and sin (``earth_rotation.sagnac_rotate``, one iteration): angle
    ``w_E * (sqrt(np.sum((sat - pos) ** 2, axis=1)) / c)``, then :func:`rotate_z`."""
    n = sat.shape[0]
    c = np.empty(n)
    s = np.empty(n)
    for i in range(n):
        d0, d1, d2 = sat[i, 0] - pos[0], sat[i, 1] - pos[1], sat[i, 2] - pos[2]
        ang = EARTH_ROTATION_RATE_RADPS * (math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / SPEED_OF_LIGHT_MPS)
        c[i] = math.cos(ang)
        s[i] = math.sin(ang)
    return rotate_z(sat, c, s, pos), c, s


@njit(cache=True)
def screened(s: np.ndarray, idx: np.ndarray, rate_ok: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows ``idx`` of the observations ``s`` (columns as :func:`screen_flags`, then C/N0, pseudorange std,
    rate std): ``y = P + c dt_s - I - T``, ``rate + c ddt_s`` (NaN where not ``rate_ok``), the stated
    pseudorange variance (NaN where the std is not finite and > 0)."""
    m = idx.size
    y, rate, stated2 = np.empty(m), np.empty(m), np.empty(m)
    for j in range(m):
        i = idx[j]
        y[j] = s[i, 0] + s[i, 1] - s[i, 2] - s[i, 3]
        rate[j] = s[i, 4] + s[i, 5] if rate_ok[i] else math.nan
        sd = s[i, 7]
        stated2[j] = sd**2 if (math.isfinite(sd) and sd > 0.0) else math.nan
    return y, rate, stated2


@njit(cache=True)
def design(los: np.ndarray, clock: np.ndarray, k: int) -> np.ndarray:
    """``[-u_i, one-hot clock_i]`` of every row (no clock column where ``clock_i < 0``), (n, 3 + k)."""
    h = np.zeros((los.shape[0], 3 + k))
    for i in range(los.shape[0]):
        for a in range(3):
            h[i, a] = -los[i, a]
        if clock[i] >= 0:
            h[i, 3 + clock[i]] = 1.0
    return h


@njit(cache=True)
def rotate_z(vec: np.ndarray, c: np.ndarray, s: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """``earth_rotation.rotate_about_z(vec, c, s) - pos``: ``(c v0 + s v1, -s v0 + c v1, v2) - pos``, (n, 3)."""
    out = np.empty_like(vec)
    for i in range(vec.shape[0]):
        out[i, 0] = (c[i] * vec[i, 0] + s[i] * vec[i, 1]) - pos[0]
        out[i, 1] = (-s[i] * vec[i, 0] + c[i] * vec[i, 1]) - pos[1]
        out[i, 2] = vec[i, 2] - pos[2]
    return out


@njit(cache=True)
def row_variances(sin_el: np.ndarray, k_cn0: np.ndarray, iono: np.ndarray, sisre: np.ndarray, stated2: np.ndarray,
                  a2: float, b: float, f_iono: float, s_tropo: float, white_only: bool) -> np.ndarray:
    """:func:`gnss_common.spp.code_variance_m2` (``white_only``: ``code_noise_variance_m2``) of every row, a stated
    variance (``stated2`` not NaN) overriding; ``a2`` is ``sigma_code_a_m**2``."""
    out = np.empty(sin_el.size)
    for i in range(sin_el.size):
        s_el = _floor(sin_el[i], 0.05)
        v = (a2 + (b / s_el) ** 2) * k_cn0[i]
        if not white_only:
            v = v + (f_iono * iono[i]) ** 2 + (s_tropo / (s_el + 0.1)) ** 2 + sisre[i] ** 2
        out[i] = v if stated2[i] != stated2[i] else stated2[i]
    return out


@njit(cache=True)
def normal_rows(var: np.ndarray, los: np.ndarray, rng: np.ndarray, y: np.ndarray, x: np.ndarray,
                clock: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows ``idx`` of the linearised system: ``h = [-u_i, one-hot clock]``, ``w = 1 / var``,
    ``r = y - (rng + x[3 + clock_i])`` (``cols @ x[3:]`` of a one-hot row is exactly that clock)."""
    m, k = idx.size, x.size
    h = np.zeros((m, k))
    w = np.empty(m)
    r = np.empty(m)
    for j in range(m):
        i = idx[j]
        w[j] = 1.0 / var[i]
        for a in range(3):
            h[j, a] = -los[i, a]
        h[j, 3 + clock[i]] = 1.0
        r[j] = y[i] - (rng[i] + x[3 + clock[i]])
    return h, w, r


@njit(cache=True)
def residuals(y: np.ndarray, rng: np.ndarray, x: np.ndarray, clock: np.ndarray) -> np.ndarray:
    """``(y - rng) - x[3 + clock_i]``, NaN where the row's constellation has no clock (``clock_i < 0``)."""
    out = np.empty(y.size)
    for i in range(y.size):
        out[i] = (y[i] - rng[i]) - x[3 + clock[i]] if clock[i] >= 0 else math.nan
    return out


@njit(cache=True)
def rate_variances(k_cn0: np.ndarray, sin_el: np.ndarray, rate_std: np.ndarray, sigma_rate: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``scales = sqrt(k_cn0) / max(sin el, 0.05)`` and the rate variances: the stated std where finite
    and > 0, else ``sigma_rate * scales``, squared."""
    n = k_cn0.size
    scales = np.empty(n)
    var = np.empty(n)
    for i in range(n):
        scales[i] = math.sqrt(k_cn0[i]) / _floor(sin_el[i], 0.05)
        sd = rate_std[i] if (math.isfinite(rate_std[i]) and rate_std[i] > 0.0) else sigma_rate * scales[i]
        var[i] = sd**2
    return scales, var


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel of this module on throwaway inputs."""
    s, v3, v1 = np.full((2, 6), 1.0), np.ones((2, 3)), np.ones(2)
    screen_flags(s, v3, v3)
    screened(np.ones((2, 9)), np.arange(2), np.ones(2, dtype=np.bool_))
    sagnac_rotate(v3, np.zeros(3))
    ecef_to_enu_rotation_scalar(0.5, 0.5)  # coordinates' kernel, which the fix calls
    design(v3, np.zeros(2, dtype=np.int64), 1)
    row_variances(v1, v1, v1, v1, np.full(2, math.nan), 0.09, 0.3, 0.5, 0.3, False)
    clock = np.zeros(2, dtype=np.int64)
    normal_rows(v1, v3, v1, v1, np.zeros(4), clock, np.arange(2))
    residuals(v1, v1, np.zeros(4), clock)
    rate_variances(v1, v1, v1, 0.1)

"""Compiled kernels and exact small helpers that keep the monitor within its per-epoch budget.

Pure core (no rclpy). Issue 25 asks the node to keep up with a 20 Hz multi-GNSS receiver at under
5 % of one core (2.5 ms per epoch for everything); the tests' arithmetic on 2-40 element arrays was
almost all numpy call overhead (docs/gnss_integrity/speed.md). What is here does the same arithmetic:

* :class:`RunningMedian`: the median of the last ``maxlen`` values, equal to ``np.median`` of them
  (a sorted list kept beside the FIFO instead of sorting 600 values every epoch);
* :func:`chi2_form`: ``d^T (U diag(a) U^T + diag(o))^-1 d``, compiled (LAPACK ``gesv``, as ``np.linalg.solve``);
  :func:`lagged_chi2`: it for every lag of :class:`.kinematics_test.LaggedDisplacement`;
  :func:`quad_solve`: ``v^T A^-1 v``;
* :func:`agreement_blocks`, :func:`block_difference`, :func:`agreement_differences`,
  :func:`agreement_track`: the per-constellation normal equations of :mod:`.consistency`
  (``constellation_agreement``), the position differences they give (every constellation in one
  call) and each constellation's average, level and change;
* :func:`clock_kalman_step`: one predict / update of the two-state clock filter of :mod:`.clock_test`;
* :func:`cn0_reference_rows`: the per-satellite references of :meth:`.cn0_model.Cn0Models.reference`;
* :func:`doppler_add_pairs`: the per-satellite running sums of ``doppler_vs_pseudorange``.

Compiled results agree with the numpy forms to rounding (the summation order of a 3-term dot
product may differ); ``benchmarks/integrity_speed.py --check`` compares every report field of
representative runs within 1e-9 relative. :func:`warm_up` compiles (or loads from numba's cache)
every kernel: a node calls it before it subscribes, so that its first epoch does not pay it.
"""

from __future__ import annotations

import math
from bisect import bisect_left, insort
from collections import deque

import numpy as np
from numba import njit

from gnss_common import multi_gnss_rows, multilateration


class RunningMedian:
    """Median of the last ``maxlen`` values appended, exactly ``np.median`` of them.

    ``np.median`` of n values is the middle one (n odd) or the mean of the two middle ones (n even),
    NaN if any is NaN; the same comes from a sorted copy kept up to date by bisection (O(n) memmove
    in C instead of an O(n log n) sort and array conversion per call).
    """

    def __init__(self, maxlen: int) -> None:
        self._fifo: deque[float] = deque()
        self._sorted: list[float] = []
        self._nans = 0
        self.maxlen = int(maxlen)

    def __len__(self) -> int:
        return len(self._fifo)

    def append(self, value: float) -> None:
        """Add a value; the oldest leaves once ``maxlen`` are held."""
        v = float(value)
        if len(self._fifo) >= self.maxlen:
            old = self._fifo.popleft()
            if old != old:
                self._nans -= 1
            else:
                del self._sorted[bisect_left(self._sorted, old)]
        self._fifo.append(v)
        if v != v:
            self._nans += 1
        else:
            insort(self._sorted, v)

    def median(self) -> float:
        """``float(np.median(values))`` (NaN when empty or when a NaN is held)."""
        s = self._sorted
        n = len(s)
        if self._nans or n == 0:
            return math.nan
        if n % 2:
            return s[n // 2]
        return (s[n // 2 - 1] + s[n // 2]) / 2.0


@njit(cache=True)
def chi2_form(u: np.ndarray, axes: np.ndarray, own: np.ndarray, d: np.ndarray) -> float:
    """``d^T C^-1 d`` with ``C = U diag(axes) U^T + diag(own)``; U (k, 3), axes (3,), own and d (k,)."""
    k = d.size
    c = np.empty((k, k))
    for i in range(k):
        for j in range(k):
            s = 0.0
            for m in range(3):
                s += u[i, m] * axes[m] * u[j, m]
            c[i, j] = s
        c[i, i] += own[i]
    x = np.linalg.solve(c, d)
    out = 0.0
    for i in range(k):
        out += d[i] * x[i]
    return out


@njit(cache=True)
def lagged_chi2(u: np.ndarray, d: np.ndarray, own: np.ndarray, g: np.ndarray, n_eff: np.ndarray, lag_s: np.ndarray,
                cov_axes: np.ndarray, white_axes: np.ndarray, lag_var: float) -> np.ndarray:
    """:func:`chi2_form` of each lag l of ``kinematics_test.LaggedDisplacement`` with the same components:
    ``axes_l = g_l cov_axes + (white_axes / n_eff_l + lag_var lag_l)``; U (k, 3), d and own (L, k)."""
    out = np.empty(d.shape[0])
    axes = np.empty(3)
    for m in range(d.shape[0]):
        for a in range(3):
            axes[a] = g[m] * cov_axes[a] + (white_axes[a] / n_eff[m] + lag_var * lag_s[m])
        out[m] = chi2_form(u, axes, own[m], d[m])
    return out


@njit(cache=True)
def quad_solve(a: np.ndarray, v: np.ndarray) -> float:
    """``v^T A^-1 v`` (``v @ np.linalg.solve(a, v)``), A (k, k), v (k,)."""
    x = np.linalg.solve(a, v)
    out = 0.0
    for i in range(v.size):
        out += v[i] * x[i]
    return out


@njit(cache=True)
def agreement_blocks(design: np.ndarray, w: np.ndarray, r: np.ndarray, noise: np.ndarray, group: np.ndarray,
                     n_groups: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each group's position normal equations with its own clock eliminated (``consistency._blocks``).

    Args:
        design: the fix's design matrix (its first three columns ``-u_i``), (n, >= 3). w: weights, 1/m^2.
        r: residuals, m. noise: white (code noise) variances, m^2. group: group of each row (< 0: not
        used), (n,). n_groups: number of groups.

    Returns:
        ``(M (G, 3, 3), g (G, 3), Q (G, 3, 3), spread (G,), rows (G,))``: with ``h_i = u_bar - u_i``
        (``u_bar`` the group's weighted mean line of sight), ``M = H^T W H``, ``g = H^T W r``,
        ``Q = H^T W diag(noise) W H``, ``spread = sum w (r - r_bar)^2``.
    """
    n = w.size
    sw = np.zeros(n_groups)
    swu = np.zeros((n_groups, 3))
    swr = np.zeros(n_groups)
    rows = np.zeros(n_groups, dtype=np.int64)
    for i in range(n):
        k = group[i]
        if k < 0:
            continue
        sw[k] += w[i]
        swr[k] += w[i] * r[i]
        rows[k] += 1
        for a in range(3):
            swu[k, a] += w[i] * -design[i, a]
    m = np.zeros((n_groups, 3, 3))
    g = np.zeros((n_groups, 3))
    q = np.zeros((n_groups, 3, 3))
    spread = np.zeros(n_groups)
    h = np.empty(3)
    wh = np.empty(3)
    for i in range(n):
        k = group[i]
        if k < 0:
            continue
        spread[k] += w[i] * (r[i] - swr[k] / sw[k]) ** 2
        for a in range(3):
            h[a] = swu[k, a] / sw[k] - -design[i, a]
            wh[a] = w[i] * h[a]
        for a in range(3):
            g[k, a] += wh[a] * r[i]
            for b in range(3):
                m[k, a, b] += h[a] * wh[b]
                q[k, a, b] += wh[a] * noise[i] * wh[b]
    return m, g, q, spread, rows


@njit(cache=True)
def _solution(m: np.ndarray, g: np.ndarray, q: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """``(ok, x = M^-1 g, W = M^-1 Q M^-1, P = M^-1)``; ok False when M is singular or a variance is not > 0."""
    try:
        cov = np.linalg.inv(m)
    except Exception:  # numba catches only the generic form
        return False, g, q, q
    for a in range(3):
        if not (math.isfinite(cov[a, a]) and cov[a, a] > 0.0):
            return False, g, q, q
    return True, cov @ g, cov @ q @ cov, cov


@njit(cache=True)
def block_difference(ma: np.ndarray, ga: np.ndarray, qa: np.ndarray, mb: np.ndarray, gb: np.ndarray,
                     qb: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """Position of block sums ``a`` minus that of ``b`` (ECEF), its white and correlated covariances
    (``(ok, x_a - x_b, W_a + W_b, P_a + P_b - W_a - W_b)``; ok False: a block cannot be solved)."""
    ok_a, xa, wa, pa = _solution(ma, ga, qa)
    if not ok_a:
        return False, ga, qa, qa
    ok_b, xb, wb, pb = _solution(mb, gb, qb)
    if not ok_b:
        return False, ga, qa, qa
    return True, xa - xb, wa + wb, pa + pb - wa - wb


@njit(cache=True)
def agreement_differences(m: np.ndarray, g: np.ndarray, q: np.ndarray, tested: np.ndarray, rot: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each tested group's position minus that of all the other groups, in ENU (``rot``: ECEF -> ENU).

    Returns:
        ``(ok (T,), d (T, 3), white (T, 3, 3), correlated (T, 3, 3))``.
    """
    n_t = tested.size
    tm, tg, tq = m.sum(axis=0), g.sum(axis=0), q.sum(axis=0)
    ok = np.zeros(n_t, dtype=np.bool_)
    d = np.zeros((n_t, 3))
    white = np.zeros((n_t, 3, 3))
    corr = np.zeros((n_t, 3, 3))
    for t in range(n_t):
        k = tested[t]
        good, x, w, c = block_difference(m[k], g[k], q[k], tm - m[k], tg - g[k], tq - q[k])
        if good:
            ok[t] = True
            d[t] = rot @ x
            white[t] = rot @ w @ rot.T
            corr[t] = rot @ c @ rot.T
    return ok, d, white, corr


@njit(cache=True)
def agreement_track(mean: np.ndarray, white: np.ndarray, d: np.ndarray, white_new: np.ndarray, corr: np.ndarray,
                    a: float, an: float, mean0: np.ndarray, white0: np.ndarray, corr0: np.ndarray, f_white: float,
                    f_corr: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """One epoch of a constellation's average (``consistency.ConstellationAgreementTest``).

    ``mean = a mean + (1 - a) d``, ``white = an^2 white + (1 - an)^2 white_new`` (a < 0: restart at
    ``d``, ``white_new``); level ``mean^T (white + corr)^-1 mean``; with ``f_white`` finite, the change
    against the lagged state, ``delta^T V^-1 delta`` with ``delta = mean - mean0``,
    ``V = white + f_white white0 + f_corr (corr + corr0)`` (NaN otherwise).

    Returns:
        ``(mean, white, level, change)``.
    """
    if a < 0.0:
        mean, white = d.copy(), white_new.copy()
    else:
        mean = a * mean + (1.0 - a) * d
        white = an * an * white + (1.0 - an) ** 2 * white_new
    level = quad_solve(white + corr, mean)
    change = math.nan
    if math.isfinite(f_white):
        change = quad_solve(white + f_white * white0 + f_corr * (corr + corr0), mean - mean0)
    return mean, white, level, change


@njit(cache=True)
def clock_kalman_step(x: np.ndarray, p: np.ndarray, phi: np.ndarray, q: np.ndarray, r: np.ndarray, z: np.ndarray,
                      millisecond_m: float, tolerance_m: float) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Predict ``x = Phi x``, ``P = Phi P Phi^T + Q``; recognise a receiver millisecond step in the bias
    innovation (re-align, no alarm); update with ``z`` (covariance ``R``).

    Returns:
        ``(x, P, NIS nu^T S^-1 nu, whole milliseconds re-aligned)``.
    """
    xp = phi @ x
    pp = phi @ p @ phi.T + q
    nu = z - xp
    steps = int(np.round(nu[0] / millisecond_m))
    if steps != 0 and abs(nu[0] - steps * millisecond_m) < tolerance_m:
        xp[0] += steps * millisecond_m
        nu = z - xp
    else:
        steps = 0
    s = pp + r
    nis = 0.0
    sol = np.linalg.solve(s, nu)
    for i in range(2):
        nis += nu[i] * sol[i]
    k = pp @ np.linalg.inv(s)
    xn = xp + k @ nu
    pn = (np.eye(2) - k) @ pp
    return xn, 0.5 * (pn + pn.T), nis, steps


@njit(cache=True)
def cn0_reference_rows(cn0: np.ndarray, el: np.ndarray, slots: np.ndarray, slot_base: np.ndarray,
                       pub_ready: np.ndarray, std_ready: np.ndarray, off: np.ndarray, off_w: np.ndarray,
                       lv_t: np.ndarray, lv_ready: np.ndarray, lv_std: np.ndarray, t: float, min_cn0: float,
                       max_cn0: float, nodes_per_rad: float, n_nodes: int, prior: float, max_age: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                  np.ndarray, np.ndarray]:
    """Per row of ``cn0_model.Cn0Models.reference``: valid C/N0, tent nodes (lower, upper, upper's weight),
    elevation-model reference and 1-sigma, satellite-level reference and 1-sigma (NaN: none).

    The node arrays are NaN where a node is unusable; the interpolation uses both nodes, else the usable
    one in whose half the row lies (``cn0_model._interp``); the satellite offset is shrunk by
    ``w / (w + prior)``; a level is used when refreshed within ``max_age`` s of ``t``.
    """
    n = cn0.size
    valid = np.zeros(n, dtype=np.bool_)
    n0 = np.empty(n, dtype=np.int64)
    frac = np.empty(n)
    el_exp, el_std, lv_exp, lv_sd = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    half_pi = 0.5 * math.pi
    for i in range(n):
        valid[i] = min_cn0 <= cn0[i] <= max_cn0
        e = el[i]
        pos = min(max(e, 0.0), half_pi) * nodes_per_rad if e == e else 0.0
        k0 = min(int(pos), n_nodes - 2)
        frac[i] = pos - k0
        sl = slots[i]
        n0[i] = slot_base[sl] + k0
        est = _tent(pub_ready, n0[i], frac[i]) + off[sl] * off_w[sl] / (off_w[sl] + prior)
        el_exp[i] = est if (valid[i] and e == e) else math.nan
        el_std[i] = _tent(std_ready, n0[i], frac[i]) if el_exp[i] == el_exp[i] else math.nan
        lv_exp[i] = lv_ready[sl] if (valid[i] and t - lv_t[sl] <= max_age) else math.nan
        lv_sd[i] = lv_std[sl] if lv_exp[i] == lv_exp[i] else math.nan
    return valid, n0, n0 + 1, frac, el_exp, el_std, lv_exp, lv_sd


@njit(cache=True)
def _tent(values: np.ndarray, n0: int, frac: float) -> float:
    v0, v1 = values[n0], values[n0 + 1]
    both = v0 + frac * (v1 - v0)
    return both if both == both else (v0 if frac <= 0.5 else v1)


@njit(cache=True)
def doppler_add_pairs(slots: np.ndarray, e: np.ndarray, pair_var: np.ndarray, start_var: np.ndarray,
                      end_var: np.ndarray, los: np.ndarray, stamp_ns: int, start_ns: int, limit_ns: int, seq: int,
                      head: int, active: np.ndarray, last: np.ndarray, count: np.ndarray, first: np.ndarray,
                      sum_e: np.ndarray, sum_var: np.ndarray, chain_end_var: np.ndarray, chain_los: np.ndarray,
                      ring_stamp: np.ndarray, ring_e: np.ndarray, ring_var: np.ndarray, ring_start_var: np.ndarray,
                      ring_in: np.ndarray) -> int:
    """One epoch pair of ``doppler_pseudorange.DopplerPseudorangeTest``, in place: entry ``seq`` (start
    ``start_ns``) gets each slot's value, variance and start code variance; a slot without a chain starts
    one (sums 0, first entry ``seq``); each chain adds its pair, then removes its pairs that start before
    ``limit_ns``, oldest first (a chain left empty has its sums reset to 0).

    Returns:
        The oldest entry still held.
    """
    cap = ring_stamp.size
    q = seq % cap
    ring_stamp[q] = start_ns
    ring_in[q, :] = False
    for j in range(slots.size):
        s = slots[j]
        if not active[s]:
            active[s] = True
            sum_e[s] = 0.0
            sum_var[s] = 0.0
            count[s] = 0
            first[s] = seq
        ring_in[q, s] = True
        ring_e[q, s], ring_var[q, s], ring_start_var[q, s] = e[j], pair_var[j], start_var[j]
        sum_e[s] += e[j]
        sum_var[s] += pair_var[j]
        count[s] += 1
        last[s] = stamp_ns
        chain_end_var[s] = end_var[j]
        for a in range(3):
            chain_los[s, a] = los[j, a]
    while head <= seq and ring_stamp[head % cap] < limit_ns:
        q = head % cap
        for s in range(ring_in.shape[1]):
            if ring_in[q, s] and active[s] and first[s] == head:
                sum_e[s] -= ring_e[q, s]
                sum_var[s] -= ring_var[q, s]
                count[s] -= 1
                first[s] += 1
                if count[s] == 0:
                    sum_e[s] = 0.0
                    sum_var[s] = 0.0
        head += 1
    return head


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel of this module and of
    ``gnss_common.multi_gnss_rows`` (the fix's) and ``gnss_common.multilateration`` on throwaway inputs."""
    multi_gnss_rows.warm_up()
    multilateration.warm_up()
    chi2_form(np.eye(3), np.ones(3), np.ones(3), np.ones(3))
    lagged_chi2(np.eye(3), np.ones((2, 3)), np.ones((2, 3)), np.ones(2), np.ones(2), np.ones(2), np.ones(3),
                np.ones(3), 0.0)
    quad_solve(np.eye(3), np.ones(3))
    rng = np.random.default_rng(0)
    design = np.hstack([rng.standard_normal((8, 3)), np.ones((8, 1))])
    blocks = agreement_blocks(design, np.ones(8), np.ones(8), np.ones(8), np.arange(8) % 2, 2)
    agreement_differences(blocks[0], blocks[1], blocks[2], np.array([0, 1]), np.eye(3))
    clock_kalman_step(np.zeros(2), np.eye(2), np.eye(2), np.eye(2), np.eye(2), np.ones(2), 3.0e5, 1.0e3)
    z3, e3 = np.ones(3), np.eye(3)
    agreement_track(z3, e3, z3, e3, e3, 0.5, 0.5, z3, e3, e3, 0.5, 0.5)
    i1 = np.zeros(1, dtype=np.int64)
    cn0_reference_rows(np.ones(1), np.ones(1), i1, i1, z3, z3, z3, z3, z3, z3, z3, 0.0, 0.0, 99.0, 1.0, 3, 1.0,
                       1.0)

    def ints() -> np.ndarray:
        return np.zeros(1, dtype=np.int64)

    def floats(*shape: int) -> np.ndarray:
        return np.zeros(shape)

    doppler_add_pairs(np.zeros(1, dtype=np.intp), floats(1), floats(1), floats(1), floats(1), floats(1, 3), 1, 0, 0,
                      0, 0, np.zeros(1, dtype=np.bool_), ints(), ints(), ints(), floats(1), floats(1), floats(1),
                      floats(1, 3), ints(), floats(1, 1), floats(1, 1), floats(1, 1), np.zeros((1, 1), dtype=np.bool_))

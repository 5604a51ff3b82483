"""Consistency tests of spoofing (issue 25, item 3): constellations, Doppler and residuals disagree.

Pure (no rclpy; time only from the stamps passed in, ns). Each test is a small class with
``update(stamp_ns, epoch, fix) -> TestOutcome`` and ``reset()``; ``fix`` is the epoch's
:class:`gnss_common.multi_gnss_fix.MultiGnssFix`, solved once by the caller; :class:`ConsistencyTests`
runs the three. Category CONSISTENCY; SUSPECT and ALARM thresholds from a false-alarm probability per
evaluation under each test's clean-data model:

``constellation_agreement``: per constellation c, its own position minus that of all the others
(disjoint satellites, own clocks), ``d_c = b_c + w_c``: correlated errors b (orbits, clocks,
atmosphere: Gauss-Markov, correlation time tau, covariance ``S_c`` from those terms of the weight
model) plus white code noise w (``S_w``, the code-noise term). On an exponential average ``d_bar``
(time constant T, white variance ``U``), two 3-dof chi-squares: level ``d_bar^T (U + S_c)^-1 d_bar``
and change over a lag L >= ``agreement_lag_s``, ``D = d_bar(t) - d_bar(t - L)`` against
``V = U_t + (1 - 2 e^(-L/T)) U_(t-L) + (1 - e^(-L/tau)) (S_c,t + S_c,t-L)`` (a drag faster than the
correlated errors wander). Statistic: the largest over the K constellations tested; thresholds at
p / (2 K) (Bonferroni). A change of satellites restarts that constellation's average. With >= 3
constellations it names the largest if its own solution is self-consistent (chi-square) and the
others agree without it (scope CONSTELLATIONS); else (and always with 2: one difference, either
may lie) it names none, scope ALL.

``doppler_vs_pseudorange``: per satellite and epoch pair, the code's change minus the trapezoid
integral of its Doppler, ``e_i = P_i(t_k) - P_i(t_k-1) - dt (r_i(t_k-1) + r_i(t_k)) / 2`` (satellite
motion and clocks cancel: no ephemeris needed), minus the weighted mean over satellites (the receiver
clock's bias change against its drift, e.g. millisecond steps: the clock test's business), summed
over a window. The code terms telescope to the window's ends: ``V_i = s_P^2(start) + s_P^2(end) +
sum dt^2 (s_r^2(t_k-1) + s_r^2(t_k)) / 2 + sum (dt |dv| / 4)^2 + (r_c span)^2`` (code noise, Doppler
noise, trapezoid error from the receiver's velocity change, slow code-error drift). Chi-square
``sum (E_i - M)^2 / V_i``, n - 1 dof. A simple spoofer moving pseudoranges without the matching
Doppler diverges. If a position push explains the divergence (``e_i = -u_i . delta + m``) scope ALL;
else satellites by iterative exclusion (a whole constellation: CONSTELLATIONS). UNKNOWN without Doppler.

``raim_subset``: the all-in-view weighted residual sum of squares (chi-square, n - 3 - k dof); on
SUSPECT the largest w-test ``r_i / sqrt(Qr_ii)`` is excluded and the subset re-solved until it passes:
the excluded satellites are implicated. Blind spot: a spoof consistent on every satellite passes.

Notes
-----
Baarda (1968) w-test; Brown (1992), "A baseline GPS RAIM scheme"; Kaplan & Hegarty, 3rd ed., sec. 11.5;
Gauss-Markov increments: Brown & Hwang, 4th ed., sec. 2.9.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gnss_common.constants import NS_PER_S
from gnss_common.multi_gnss_fix import MultiGnssFix, subset_solution
from gnss_common.observations import GnssEpoch

from .consistency_common import (
    ConsistencyParams,
    Sat,
    consistency_outcome,
    implicated_scope,
)
from .doppler_pseudorange import WARMUP_EVALUATIONS, DopplerPseudorangeTest
from .kernels import agreement_blocks, agreement_differences, agreement_track, block_difference, quad_solve
from .outcome import CATEGORY_CONSISTENCY, SCOPE_CONSTELLATIONS, TestOutcome, chi2_threshold, unknown

__all__ = ["WARMUP_EVALUATIONS", "ConsistencyParams", "ConsistencyTests", "ConstellationAgreementTest",
           "DopplerPseudorangeTest", "RaimSubsetTest", "Sat"]


# ------------------------------------------------------------------------------------------------
@dataclass
class _Track:
    """Running state of one constellation's position difference."""

    stamp_ns: int
    members: frozenset
    mean: np.ndarray  # d_bar, ENU, m
    white: np.ndarray  # U, m^2
    history: deque = field(default_factory=deque)  # (stamp_ns, d_bar, U, S_c)


class ConstellationAgreementTest:
    """``constellation_agreement``: each constellation's own position against the others' (see module)."""

    name = "constellation_agreement"

    def __init__(self, params: ConsistencyParams | None = None) -> None:
        self.params = params if params is not None else ConsistencyParams()
        self._tracks: dict[int, _Track] = {}
        self.last_statistics: dict[int, tuple[float, float]] = {}  # this epoch's (level, change) per constellation

    def reset(self) -> None:
        """Forget every average and history."""
        self._tracks.clear()
        self.last_statistics = {}

    def update(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix) -> TestOutcome:
        """One epoch (``epoch`` unused: everything is in ``fix``). UNKNOWN with < 2 constellations tested."""
        p = self.params
        pfa = p.agreement_false_alarm_probability
        self.last_statistics = {}
        if not fix.valid:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        system = fix.constellation_of_row
        used = system[fix.used].tolist()
        n_used = {c: used.count(c) for c in fix.clock_constellations}
        present = tuple(c for c in fix.clock_constellations if n_used[c] >= 2)
        tested = [c for c in present if n_used[c] >= p.agreement_min_satellites]
        if len(tested) < 2:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        # Per constellation, its used rows' position normal equations with its own clock eliminated
        # (Schur complement: rows h_i = u_bar - u_i, u_bar the weighted mean line of sight): with a
        # clock per constellation, the position step of a union of constellations is (sum M)^-1 sum g,
        # its covariance (sum M)^-1, the white noise's share (sum M)^-1 (sum Q) (sum M)^-1; a
        # constellation's own SSE is spread - g^T M^-1 g (chi-square, rows - 4 dof).
        slot = {c: k for k, c in enumerate(present)}
        group = np.array([slot.get(c, -1) if u else -1 for c, u in zip(system.tolist(), fix.used.tolist(),
                                                                          strict=True)], dtype=np.int64)
        m, g, q, spread, rows = agreement_blocks(fix.design_matrix, fix.weights, fix.residuals_m,
                                                 fix.noise_variances_m2, group, len(present))
        members = frozenset(s for s, u in zip(fix.satellites, fix.used, strict=True) if u and s[0] in present)
        chosen = tested[:1] if len(tested) == 2 else tested  # with two, the two differences are one
        ok, d, white, corr = agreement_differences(m, g, q, np.array([slot[c] for c in chosen], dtype=np.int64),
                                                   np.ascontiguousarray(fix.enu_rotation, dtype=float))
        stats: dict[int, float] = {}
        for j, c in enumerate(chosen):
            if ok[j]:
                stats[c] = self._track(c, stamp_ns, members, d[j], white[j], corr[j])
        for c in [c for c, t in self._tracks.items() if c not in stats and stamp_ns - t.stamp_ns > p.max_gap_s * 1e9]:
            del self._tracks[c]
        if not stats:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        k = len(stats)
        suspect = chi2_threshold(pfa / (2 * k), 3)
        alarm = chi2_threshold(p.alarm_false_alarm_probability / (2 * k), 3)
        worst = max(stats, key=lambda c: stats[c])
        statistic = stats[worst]
        if statistic < suspect or len(stats) < 3:
            return consistency_outcome(self.name, statistic, suspect, alarm, pfa)
        w = slot[worst]
        if rows[w] > 4 and spread[w] - g[w] @ np.linalg.solve(m[w], g[w]) >= chi2_threshold(pfa, int(rows[w]) - 4):
            return consistency_outcome(self.name, statistic, suspect, alarm, pfa)  # not self-consistent
        for c in (c for c in stats if c != worst):  # name it only if the others agree without it
            rest = [slot[o] for o in present if o not in (c, worst)]
            good, x, wv, cv = block_difference(m[slot[c]], g[slot[c]], q[slot[c]], m[rest].sum(axis=0),
                                               g[rest].sum(axis=0), q[rest].sum(axis=0))
            if good and quad_solve(wv + cv, x) >= suspect:
                return consistency_outcome(self.name, statistic, suspect, alarm, pfa)
        return consistency_outcome(self.name, statistic, suspect, alarm, pfa, SCOPE_CONSTELLATIONS, (worst,))

    def _track(self, c: int, stamp_ns: int, members: frozenset, d: np.ndarray, white: np.ndarray,
               corr: np.ndarray) -> float:
        """Update constellation c's average and history (reset when ``members`` change); its larger
        chi-square (level, change)."""
        p = self.params
        t = self._tracks.get(c)
        dt = (stamp_ns - t.stamp_ns) / NS_PER_S if t is not None else math.inf
        a = an = -1.0  # a restart
        if t is None or not 0.0 < dt <= p.max_gap_s or t.members != members:
            t = self._tracks[c] = _Track(stamp_ns, members, d, white)
        else:
            a = math.exp(-dt / p.agreement_smoothing_s)
            an = math.exp(-max(dt, p.noise_correlation_time_s) / p.agreement_smoothing_s)
            t.stamp_ns = stamp_ns
        lag_ns = p.agreement_lag_s * NS_PER_S
        while len(t.history) >= 2 and t.history[1][0] <= stamp_ns - lag_ns:
            t.history.popleft()
        mean0, white0, corr0, f_white, f_corr = d, white, corr, math.nan, math.nan
        if t.history and t.history[0][0] <= stamp_ns - lag_ns:
            t0, mean0, white0, corr0 = t.history[0]
            lag = (stamp_ns - t0) / NS_PER_S
            f_white = 1.0 - 2.0 * math.exp(-lag / p.agreement_smoothing_s)
            f_corr = 1.0 - math.exp(-lag / p.agreement_correlation_time_s)
        # the average (a, an: weights of the old value), its level and its change over the lag
        t.mean, t.white, level, change = agreement_track(t.mean, t.white, d, white, corr, a, an, mean0, white0,
                                                         corr0, f_white, f_corr)
        t.history.append((stamp_ns, t.mean, t.white, corr))  # never changed in place
        self.last_statistics[c] = (level, change)
        return max(level, change) if math.isfinite(change) else level


# ------------------------------------------------------------------------------------------------
class RaimSubsetTest:
    """``raim_subset``: the residual chi-square of the all-in-view fix; the failing subset by exclusion."""

    name = "raim_subset"

    def __init__(self, params: ConsistencyParams | None = None) -> None:
        self.params = params if params is not None else ConsistencyParams()

    def reset(self) -> None:
        """Stateless (kept for the common interface)."""

    def update(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix) -> TestOutcome:
        """One epoch. UNKNOWN without a fix or without redundancy (dof < 1)."""
        p = self.params
        pfa = p.raim_false_alarm_probability
        if not fix.valid or fix.dof < 1 or not math.isfinite(fix.sse):
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        suspect = chi2_threshold(pfa, fix.dof)
        alarm = chi2_threshold(p.alarm_false_alarm_probability, fix.dof)
        if fix.sse < suspect:
            return consistency_outcome(self.name, fix.sse, suspect, alarm, pfa)
        used = fix.used.copy()
        wstd = fix.standardised_residuals
        excluded: list[int] = []
        passed = False
        while len(excluded) < p.raim_max_exclusions:
            finite = used & np.isfinite(wstd)
            if not np.any(finite):
                break
            worst = int(np.flatnonzero(finite)[int(np.argmax(np.abs(wstd[finite])))])
            used[worst] = False
            excluded.append(worst)
            sub = subset_solution(fix, used)
            if not sub.valid or sub.dof < 1:
                break
            if sub.sse < chi2_threshold(pfa, sub.dof):
                passed = True
                break
            wstd = sub.standardised_residuals
        tested = [s for s, u in zip(fix.satellites, fix.used, strict=True) if u]
        scope, cons, implicated = implicated_scope([fix.satellites[i] for i in excluded], passed, tested)
        return consistency_outcome(self.name, fix.sse, suspect, alarm, pfa, scope, cons, implicated)


class ConsistencyTests:
    """The three consistency tests together: one ``update`` per epoch, three outcomes.

    The caller solves the epoch once (``gnss_common.multi_gnss_fix.solve_multi_gnss``, seeded with the
    previous fix's position) and passes the epoch and the fix.
    """

    def __init__(self, params: ConsistencyParams | None = None) -> None:
        self.params = params if params is not None else ConsistencyParams()
        self.agreement = ConstellationAgreementTest(self.params)
        self.doppler = DopplerPseudorangeTest(self.params)
        self.raim = RaimSubsetTest(self.params)

    def reset(self) -> None:
        """Reset every test."""
        for test in (self.agreement, self.doppler, self.raim):
            test.reset()

    def update(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix
               ) -> tuple[TestOutcome, TestOutcome, TestOutcome]:
        """(``constellation_agreement``, ``doppler_vs_pseudorange``, ``raim_subset``) of one epoch."""
        return (self.agreement.update(stamp_ns, epoch, fix), self.doppler.update(stamp_ns, epoch, fix),
                self.raim.update(stamp_ns, epoch, fix))

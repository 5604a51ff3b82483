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

from gnss_common.multi_gnss_fix import MultiGnssFix, subset_solution
from gnss_common.observations import GnssEpoch

from .outcome import (
    CATEGORY_CONSISTENCY,
    DECISION_SUSPECT,
    SCOPE_ALL,
    SCOPE_CONSTELLATIONS,
    SCOPE_SATELLITES,
    TestOutcome,
    chi2_threshold,
    decide,
    unknown,
)

NS_PER_S = 1_000_000_000
Sat = tuple[int, int]


@dataclass(frozen=True)
class ConsistencyParams:
    """Parameters of the consistency tests (validated).

    Attributes:
        agreement_false_alarm_probability, doppler_false_alarm_probability, raim_false_alarm_probability:
            per-evaluation probability of a clean SUSPECT of each test; alarm_false_alarm_probability:
            of a clean ALARM (every test), <= the suspect ones.
        agreement_min_satellites: satellites a constellation needs to be tested (its own fix: 4).
        agreement_smoothing_s: time constant T of the average of the position difference, s.
        agreement_lag_s: lag of the change statistic, s (>= 2 T).
        agreement_correlation_time_s: correlation time tau of the correlated errors, s.
        noise_correlation_time_s: code noise is taken as independent only between epochs this far
            apart (tracking loops, smoothing), s.
        doppler_window_s: window of the code-minus-Doppler sums, s.
        doppler_sigma_mps: the receiver's Doppler noise (orbit errors cancel) as a rate 1-sigma at zenith
            and reference C/N0, m/s, scaled by ``fix.sigma_scales``; a stated rate std overrides it.
        doppler_code_drift_mps: 1-sigma rate of change of the code's slowly varying errors over a window
            (ionospheric code-carrier divergence 2 dI/dt, slow multipath), m/s; adds ``(rate span)^2``.
        doppler_min_satellites: satellites needed for a Doppler test (one dof goes to the clock).
        raim_max_exclusions: satellites ``raim_subset`` (and the Doppler test) exclude at most.
        max_gap_s: a longer gap between epochs restarts every average and window, s.
    """

    agreement_false_alarm_probability: float = 1e-6
    doppler_false_alarm_probability: float = 1e-6
    raim_false_alarm_probability: float = 1e-6
    alarm_false_alarm_probability: float = 1e-9
    agreement_min_satellites: int = 5
    agreement_smoothing_s: float = 5.0
    agreement_lag_s: float = 30.0
    agreement_correlation_time_s: float = 600.0
    noise_correlation_time_s: float = 1.0
    doppler_window_s: float = 30.0
    doppler_sigma_mps: float = 0.05
    doppler_code_drift_mps: float = 0.01
    doppler_min_satellites: int = 4
    raim_max_exclusions: int = 4
    max_gap_s: float = 60.0

    def __post_init__(self) -> None:
        probabilities = [f"{t}_false_alarm_probability" for t in ("agreement", "doppler", "raim", "alarm")]
        positive = ("agreement_smoothing_s", "agreement_lag_s", "agreement_correlation_time_s",
                    "noise_correlation_time_s", "doppler_window_s", "doppler_sigma_mps", "max_gap_s")
        for name in (*probabilities, *positive, "doppler_code_drift_mps"):
            v = getattr(self, name)
            low_ok = v >= 0.0 if name == "doppler_code_drift_mps" else v > 0.0
            if not (isinstance(v, (int, float)) and math.isfinite(v) and low_ok and (name not in probabilities
                                                                                  or v < 0.5)):
                raise ValueError(f"ConsistencyParams.{name} out of range: {v!r}")
        if self.alarm_false_alarm_probability > min(getattr(self, n) for n in probabilities[:3]):
            raise ValueError("ConsistencyParams.alarm_false_alarm_probability must not exceed the suspect ones")
        if self.agreement_lag_s < 2.0 * self.agreement_smoothing_s:
            raise ValueError("ConsistencyParams.agreement_lag_s must be >= 2 agreement_smoothing_s")
        for name, low in (("agreement_min_satellites", 4), ("doppler_min_satellites", 3), ("raim_max_exclusions", 0)):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= low):
                raise ValueError(f"ConsistencyParams.{name} must be an int >= {low}, got {getattr(self, name)!r}")


def _outcome(name: str, statistic: float, suspect: float, alarm: float, pfa: float, scope: int = SCOPE_ALL,
             constellations: tuple[int, ...] = (), satellites: tuple[Sat, ...] = ()) -> TestOutcome:
    decision = decide(statistic, suspect, alarm)
    if decision < DECISION_SUSPECT:
        scope, constellations, satellites = SCOPE_ALL, (), ()
    return TestOutcome(name, CATEGORY_CONSISTENCY, decision, statistic, suspect, alarm, pfa, "1", scope,
                       constellations, satellites)


# ------------------------------------------------------------------------------------------------
@dataclass
class _Track:
    """Running state of one constellation's position difference."""

    stamp_ns: int
    members: frozenset
    mean: np.ndarray  # d_bar, ENU, m
    white: np.ndarray  # U, m^2
    history: deque = field(default_factory=deque)  # (stamp_ns, d_bar, U, S_c)


def _blocks(fix: MultiGnssFix, constellations: tuple[int, ...], system: np.ndarray) -> dict[int, tuple]:
    """Per constellation, its used rows' position normal equations with its own clock eliminated.

    Returns constellation -> (M (3, 3), g (3,), Q (3, 3), weighted residual spread, rows), ECEF: with a
    clock per constellation, the position step of a union of constellations is ``(sum M)^-1 sum g``,
    its covariance ``(sum M)^-1``, the white noise's share ``(sum M)^-1 (sum Q) (sum M)^-1``; the own
    solution's SSE is ``spread - g^T M^-1 g`` (chi-square, rows - 4 dof).

    Notes
    -----
    Schur complement of the clock: rows ``h_i = u_bar - u_i`` (``u_bar`` the weighted mean line of
    sight of the constellation); ``M = H^T W H``, ``g = H^T W r``, ``Q = H^T W diag(s_w^2) W H``.
    """
    out = {}
    los = -fix.design_matrix[:, :3]
    for c in constellations:
        rows = fix.used & (system == c)
        w, u, r = fix.weights[rows], los[rows], fix.residuals_m[rows]
        h = (w @ u) / np.sum(w) - u
        wh = w[:, None] * h
        spread = float(w @ (r - (w @ r) / np.sum(w)) ** 2)
        out[c] = (h.T @ wh, wh.T @ r, (wh * fix.noise_variances_m2[rows, None]).T @ wh, spread, int(np.sum(rows)))
    return out


def _difference(a: tuple, b: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Position of block sums ``a`` minus that of ``b`` (ECEF), its white and correlated covariances."""
    parts = []
    for m, g, q in (a[:3], b[:3]):
        try:
            cov = np.linalg.inv(m)
        except np.linalg.LinAlgError:
            return None
        if not (np.all(np.isfinite(np.diag(cov))) and np.all(np.diag(cov) > 0.0)):
            return None
        parts.append((cov @ g, cov, cov @ q @ cov))
    (xa, pa, wa), (xb, pb, wb) = parts
    return xa - xb, wa + wb, pa + pb - wa - wb


def _sum(blocks: dict, group) -> tuple:
    return tuple(sum(blocks[c][i] for c in group) for i in range(3))


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
        n_used = {c: int(np.sum(system[fix.used] == c)) for c in fix.clock_constellations}
        present = tuple(c for c in fix.clock_constellations if n_used[c] >= 2)
        tested = [c for c in present if n_used[c] >= p.agreement_min_satellites]
        if len(tested) < 2:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        blocks = _blocks(fix, present, system)
        total = _sum(blocks, present)
        members = frozenset(s for s, u in zip(fix.satellites, fix.used, strict=True) if u and s[0] in present)
        r = fix.enu_rotation
        stats: dict[int, float] = {}
        for c in tested[:1] if len(tested) == 2 else tested:  # with two, the two differences are one
            diff = _difference(blocks[c], tuple(t - b for t, b in zip(total, blocks[c], strict=False)))
            if diff is not None:
                stats[c] = self._track(c, stamp_ns, members, r @ diff[0], r @ diff[1] @ r.T, r @ diff[2] @ r.T)
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
            return _outcome(self.name, statistic, suspect, alarm, pfa)
        m, g, _, spread, rows = blocks[worst]
        if rows > 4 and spread - g @ np.linalg.solve(m, g) >= chi2_threshold(pfa, rows - 4):
            return _outcome(self.name, statistic, suspect, alarm, pfa)  # not self-consistent: satellites, not it
        for c in (c for c in stats if c != worst):  # name it only if the others agree without it
            diff = _difference(blocks[c], _sum(blocks, [o for o in present if o not in (c, worst)]))
            if diff is not None and float(diff[0] @ np.linalg.solve(diff[1] + diff[2], diff[0])) >= suspect:
                return _outcome(self.name, statistic, suspect, alarm, pfa)
        return _outcome(self.name, statistic, suspect, alarm, pfa, SCOPE_CONSTELLATIONS, (worst,))

    def _track(self, c: int, stamp_ns: int, members: frozenset, d: np.ndarray, white: np.ndarray,
               corr: np.ndarray) -> float:
        """Update constellation c's average and history (reset when ``members`` change); its larger
        chi-square (level, change)."""
        p = self.params
        t = self._tracks.get(c)
        dt = (stamp_ns - t.stamp_ns) / NS_PER_S if t is not None else math.inf
        if t is None or not 0.0 < dt <= p.max_gap_s or t.members != members:
            t = self._tracks[c] = _Track(stamp_ns, members, d.copy(), white.copy())
        else:
            a = math.exp(-dt / p.agreement_smoothing_s)
            an = math.exp(-max(dt, p.noise_correlation_time_s) / p.agreement_smoothing_s)
            t.mean = a * t.mean + (1.0 - a) * d
            t.white = an * an * t.white + (1.0 - an) ** 2 * white
            t.stamp_ns = stamp_ns
        level = float(t.mean @ np.linalg.solve(t.white + corr, t.mean))
        change = math.nan
        lag_ns = p.agreement_lag_s * NS_PER_S
        while len(t.history) >= 2 and t.history[1][0] <= stamp_ns - lag_ns:
            t.history.popleft()
        if t.history and t.history[0][0] <= stamp_ns - lag_ns:
            t0, mean0, white0, corr0 = t.history[0]
            lag = (stamp_ns - t0) / NS_PER_S
            v = (t.white + (1.0 - 2.0 * math.exp(-lag / p.agreement_smoothing_s)) * white0
                 + (1.0 - math.exp(-lag / p.agreement_correlation_time_s)) * (corr + corr0))
            delta = t.mean - mean0
            change = float(delta @ np.linalg.solve(v, delta))
        t.history.append((stamp_ns, t.mean.copy(), t.white.copy(), corr))
        self.last_statistics[c] = (level, change)
        return max(level, change) if math.isfinite(change) else level


# ------------------------------------------------------------------------------------------------
@dataclass
class _Chain:
    """One satellite's unbroken run of code-minus-Doppler pairs inside the window."""

    last_stamp_ns: int
    pairs: deque = field(default_factory=deque)  # (start stamp ns, e_i - m, pair variance, start code var)
    sum_e: float = 0.0
    sum_var: float = 0.0
    end_code_var: float = math.nan
    los: np.ndarray = field(default_factory=lambda: np.full(3, math.nan))  # unit vector to the satellite


def _exclude(e: np.ndarray, v: np.ndarray, dof_lost: int, threshold_of, max_exclusions: int,
             min_left: int) -> tuple[float, list[int], bool]:
    """Chi-square of weighted-mean-removed values; iteratively exclude the largest until it passes.

    Returns (statistic of all, excluded indices, passes after exclusion).
    """
    keep = np.ones(e.size, dtype=bool)
    excluded: list[int] = []
    first = math.nan
    while True:
        w = 1.0 / v[keep]
        z = (e[keep] - np.sum(w * e[keep]) / np.sum(w)) * np.sqrt(w)
        q = float(np.sum(z * z))
        if not excluded:
            first = q
        if q < threshold_of(int(keep.sum()) - dof_lost):
            return first, excluded, True
        if len(excluded) >= max_exclusions or keep.sum() - 1 < min_left:
            return first, excluded, False
        worst = int(np.flatnonzero(keep)[int(np.argmax(np.abs(z)))])
        keep[worst] = False
        excluded.append(worst)


def _scope(implicated: list[Sat], passed: bool, tested: list[Sat]) -> tuple[int, tuple[int, ...], tuple[Sat, ...]]:
    """Scope of a set of implicated satellites: whole constellations, satellites, or ALL."""
    if not passed or not implicated or 2 * len(implicated) > len(tested):
        return SCOPE_ALL, (), tuple(sorted(implicated))
    whole = tuple(sorted({c for c, _ in implicated if sum(1 for s in tested if s[0] == c) >= 2
                          and all(s in implicated for s in tested if s[0] == c)}))
    if whole and all(s[0] in whole for s in implicated):
        return SCOPE_CONSTELLATIONS, whole, tuple(sorted(implicated))
    return SCOPE_SATELLITES, (), tuple(sorted(implicated))


WARMUP_EVALUATIONS = 20
"""``doppler_vs_pseudorange`` evaluations that only teach its noise scale (UNKNOWN) after a start."""


class DopplerPseudorangeTest:
    """``doppler_vs_pseudorange``: each satellite's code change against its integrated Doppler (see module)."""

    name = "doppler_vs_pseudorange"

    def __init__(self, params: ConsistencyParams | None = None) -> None:
        self.params = params if params is not None else ConsistencyParams()
        self.reset()

    def reset(self) -> None:
        """Forget the previous epoch and every window."""
        self._prev: tuple[int, dict[Sat, tuple[float, float, float, float]], np.ndarray] | None = None
        self._chains: dict[Sat, _Chain] = {}
        self.common_mode_m = math.nan  # the last pair's weighted mean (receiver clock change minus drift), m
        self.implied_displacement_m = np.full(3, math.nan)  # position push that explains a failure, ECEF m
        self._los: dict[Sat, np.ndarray] = {}
        if not hasattr(self, "_clean_ratios"):
            # the learned noise scale survives a reset: it describes the receiver, not the window
            self._clean_ratios: deque[float] = deque(maxlen=600)
            self.noise_scale = 1.0

    def _current(self, epoch: GnssEpoch, fix: MultiGnssFix) -> dict[Sat, tuple[float, float, float, float]]:
        """Satellite -> (pseudorange m, rate m/s, code noise variance m^2, rate variance) of the used rows."""
        self._los = {fix.satellites[i]: -fix.design_matrix[i, :3] for i in np.flatnonzero(fix.rate_used)}
        obs = {(int(o.constellation), int(o.svid)): o for o in epoch.observations}
        out = {}
        for i in np.flatnonzero(fix.rate_used):
            o = obs.get(fix.satellites[i])
            if o is not None:
                stated = o.pseudorange_rate_std_mps
                sigma = stated if stated > 0.0 else self.params.doppler_sigma_mps * float(fix.sigma_scales[i])
                out[fix.satellites[i]] = (o.pseudorange_m, o.pseudorange_rate_mps, float(fix.noise_variances_m2[i]),
                                          sigma * sigma)
        return out

    def update(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix) -> TestOutcome:
        """One epoch. UNKNOWN without rates, before the first pair, or with too few satellites."""
        p = self.params
        pfa = p.doppler_false_alarm_probability
        cur = self._current(epoch, fix) if fix.valid and fix.velocity_valid else {}
        if not cur:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        prev = self._prev
        self._prev = (stamp_ns, cur, fix.velocity_ecef_mps.copy())
        dt = (stamp_ns - prev[0]) / NS_PER_S if prev is not None else math.inf
        if not 0.0 < dt <= p.max_gap_s:
            self._chains.clear()
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        assert prev is not None
        common = [s for s in cur if s in prev[1]]
        allowance = (dt * float(np.linalg.norm(fix.velocity_ecef_mps - prev[2])) / 4.0) ** 2
        e = np.array([cur[s][0] - prev[1][s][0] - 0.5 * dt * (cur[s][1] + prev[1][s][1]) for s in common])
        v = np.array([0.5 * dt * dt * (cur[s][3] + prev[1][s][3]) + allowance + cur[s][2] + prev[1][s][2]
                      for s in common])
        if len(common) >= 2:
            self.common_mode_m = float(np.sum(e / v) / np.sum(1.0 / v))
            e = e - self.common_mode_m
        window_ns = p.doppler_window_s * NS_PER_S
        for s in [s for s, ch in self._chains.items() if ch.last_stamp_ns != prev[0] or s not in cur]:
            del self._chains[s]  # broken run: start again
        if len(common) >= 2:
            for s, ei, vi in zip(common, e, v, strict=True):
                ch = self._chains.setdefault(s, _Chain(prev[0]))
                pair_var = vi - cur[s][2] - prev[1][s][2]
                ch.pairs.append((prev[0], float(ei), pair_var, prev[1][s][2]))
                ch.sum_e += float(ei)
                ch.sum_var += pair_var
                ch.last_stamp_ns, ch.end_code_var, ch.los = stamp_ns, cur[s][2], self._los[s]
                while ch.pairs and ch.pairs[0][0] < stamp_ns - window_ns:
                    old = ch.pairs.popleft()
                    ch.sum_e -= old[1]
                    ch.sum_var -= old[2]
                    if not ch.pairs:
                        ch.sum_e = ch.sum_var = 0.0
        return self._evaluate()

    def _evaluate(self) -> TestOutcome:
        p = self.params
        pfa = p.doppler_false_alarm_probability
        self.implied_displacement_m = np.full(3, math.nan)
        sats = sorted(s for s, ch in self._chains.items() if ch.pairs)
        if len(sats) < p.doppler_min_satellites:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        chains = [self._chains[s] for s in sats]
        e = np.array([ch.sum_e for ch in chains])
        span = np.array([(ch.last_stamp_ns - ch.pairs[0][0]) / NS_PER_S for ch in chains])
        v = np.array([ch.sum_var + ch.pairs[0][3] + ch.end_code_var for ch in chains]) + (p.doppler_code_drift_mps
                                                                                         * span) ** 2
        # A receiver noisier than the weight model (tracking loops, multipath) would alarm on clean
        # data: the variances are scaled by the median ratio of passing statistics to the
        # chi-square median over the last 600 evaluations, never below 1 (learned only from passing
        # epochs, so an attack cannot raise it quickly).
        v = v * self.noise_scale
        suspect = chi2_threshold(pfa, len(sats) - 1)
        alarm = chi2_threshold(p.alarm_false_alarm_probability, len(sats) - 1)
        first, excluded, passed = _exclude(e, v, 1, lambda dof: chi2_threshold(pfa, dof) if dof >= 1 else math.inf,
                                           p.raim_max_exclusions, p.doppler_min_satellites)
        warming_up = len(self._clean_ratios) < WARMUP_EVALUATIONS
        if first < suspect or warming_up:
            self._clean_ratios.append(first * self.noise_scale / chi2_threshold(0.5, len(sats) - 1))
            if len(self._clean_ratios) >= WARMUP_EVALUATIONS:
                self.noise_scale = min(10.0, max(1.0, float(np.median(self._clean_ratios))))
        if warming_up:  # the noise scale is not known yet: the first evaluations only teach it
            return unknown(self.name, CATEGORY_CONSISTENCY, suspect, alarm, pfa)
        if first >= suspect and len(sats) >= 5:
            # a position-shaped divergence e_i = -u_i . delta + m: the receiver's whole position pushed
            h = np.hstack([-np.array([ch.los for ch in chains]), np.ones((len(sats), 1))])
            fit = np.linalg.lstsq(h / np.sqrt(v)[:, None], e / np.sqrt(v), rcond=None)[0]
            self.implied_displacement_m = fit[:3]
            if float(np.sum((e - h @ fit) ** 2 / v)) < chi2_threshold(pfa, len(sats) - 4):
                return _outcome(self.name, first, suspect, alarm, pfa)
        scope, cons, implicated = _scope([sats[i] for i in excluded], passed, sats)
        return _outcome(self.name, first, suspect, alarm, pfa, scope, cons, implicated)


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
            return _outcome(self.name, fix.sse, suspect, alarm, pfa)
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
        scope, cons, implicated = _scope([fix.satellites[i] for i in excluded], passed, tested)
        return _outcome(self.name, fix.sse, suspect, alarm, pfa, scope, cons, implicated)


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

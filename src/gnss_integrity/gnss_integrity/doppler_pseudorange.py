"""``doppler_vs_pseudorange``: each satellite's code change against its integrated Doppler.

Pure (no rclpy; time only from the stamps passed in, ns). The statistic, its clean-data model and its
scope are in the docstring of :mod:`.consistency`, which re-exports :class:`DopplerPseudorangeTest`.

Each satellite's unbroken run of epoch pairs inside the window (its *chain*) keeps the running sums of
its code-minus-Doppler values and of their variances. Every chain gets a pair at the same epochs, so
the pairs are held once per epoch for all satellites (an *entry* of a ring buffer: the pair's start
stamp and, per satellite slot, its value, its variance and the code variance at its start) and each
chain keeps the number of its first entry; :func:`.kernels.doppler_add_pairs` updates every chain in
one compiled call, each satellite's sums in the order of the per-satellite form (add the new pair,
then remove the pairs that left the window, oldest first): the arithmetic of one running sum each.
"""

from __future__ import annotations

import math
from operator import attrgetter
from typing import NamedTuple

import numpy as np

from gnss_common.constants import NS_PER_S
from gnss_common.multi_gnss_fix import MultiGnssFix
from gnss_common.observations import GnssEpoch

from .consistency_common import ConsistencyParams, Sat, consistency_outcome, exclude_largest, implicated_scope
from .kernels import RunningMedian, doppler_add_pairs
from .outcome import CATEGORY_CONSISTENCY, TestOutcome, chi2_threshold, unknown

WARMUP_EVALUATIONS = 20
"""``doppler_vs_pseudorange`` evaluations that only teach its noise scale (UNKNOWN) after a start."""

_OBS_FIELDS = attrgetter("pseudorange_m", "pseudorange_rate_mps", "pseudorange_rate_std_mps")
_KEY = attrgetter("constellation", "svid")


class _Epoch(NamedTuple):
    """The used rows of one epoch: satellites, their slots and position in the list, pseudorange m, rate
    m/s, code noise variance m^2, rate variance (m/s)^2, line of sight (n, 3), receiver velocity m/s."""

    stamp_ns: int
    sats: list[Sat]
    slots: np.ndarray
    position: dict[Sat, int]
    pr: np.ndarray
    rate: np.ndarray
    code_var: np.ndarray
    rate_var: np.ndarray
    los: np.ndarray
    velocity: np.ndarray


class DopplerPseudorangeTest:
    """``doppler_vs_pseudorange``: each satellite's code change against its integrated Doppler (see module)."""

    name = "doppler_vs_pseudorange"

    def __init__(self, params: ConsistencyParams | None = None) -> None:
        self.params = params if params is not None else ConsistencyParams()
        self._slot: dict[Sat, int] = {}
        self._keys: list[Sat] = []
        # per satellite slot: chain exists, last stamp ns, pairs held, number of its first entry, running
        # sums of values and of variances, code variance at its last epoch, line of sight
        self._active = np.zeros(0, dtype=bool)
        self._last = self._count = self._start = np.zeros(0, dtype=np.int64)
        self._sum_e = self._sum_var = self._end_var = np.zeros(0)
        self._los = np.zeros((0, 3))
        # ring buffer of entries (position seq % capacity): start stamp, and per slot value, variance,
        # code variance at the start and membership
        self._ring_stamp = np.zeros(0, dtype=np.int64)
        self._ring_e = self._ring_var = self._ring_start_var = np.zeros((0, 0))
        self._ring_in = np.zeros((0, 0), dtype=bool)
        self._grow(64)
        self.reset()

    def _grow(self, size: int) -> None:
        """Per-slot chain state to ``size`` slots (existing slots kept)."""

        def fit(a: np.ndarray, fill: float) -> np.ndarray:
            out = np.full((size, *a.shape[1:]), fill, dtype=a.dtype)
            out[: a.shape[0]] = a
            return out

        self._active = fit(self._active, False)
        self._last, self._count, self._start = fit(self._last, 0), fit(self._count, 0), fit(self._start, 0)
        self._sum_e, self._sum_var = fit(self._sum_e, 0.0), fit(self._sum_var, 0.0)
        self._end_var, self._los = fit(self._end_var, math.nan), fit(self._los, math.nan)
        self._grow_ring(max(self._ring_stamp.size, 64))

    def _grow_ring(self, capacity: int) -> None:
        """The ring to ``capacity`` entries and the current slot count, live entries kept at their seq."""
        n_slots = self._active.size
        old_cap = self._ring_stamp.size
        live = range(getattr(self, "_head", 0), getattr(self, "_seq", 0)) if old_cap else range(0)
        stamp = np.zeros(capacity, dtype=np.int64)
        arrays = [np.full((capacity, n_slots), math.nan) for _ in range(3)]
        member = np.zeros((capacity, n_slots), dtype=bool)
        for q in live:
            a, b = q % old_cap, q % capacity
            stamp[b] = self._ring_stamp[a]
            for new, old in zip(arrays, (self._ring_e, self._ring_var, self._ring_start_var), strict=True):
                new[b, : old.shape[1]] = old[a]
            member[b, : self._ring_in.shape[1]] = self._ring_in[a]
        self._ring_stamp, (self._ring_e, self._ring_var, self._ring_start_var), self._ring_in = stamp, arrays, member

    def reset(self) -> None:
        """Forget the previous epoch and every window."""
        self._prev: _Epoch | None = None
        self._head = self._seq = 0  # oldest entry held, next entry
        self._active[:] = False
        self.common_mode_m = math.nan  # the last pair's weighted mean (receiver clock change minus drift), m
        self.implied_displacement_m = np.full(3, math.nan)  # position push that explains a failure, ECEF m
        if not hasattr(self, "_clean_ratios"):
            # the learned noise scale survives a reset: it describes the receiver, not the window
            self._clean_ratios = RunningMedian(600)
            self.noise_scale = 1.0

    def _slots_of(self, sats: list[Sat]) -> np.ndarray:
        for s in sats:
            if s not in self._slot:
                self._slot[s] = len(self._keys)
                self._keys.append(s)
        if len(self._keys) > self._active.size:
            self._grow(2 * len(self._keys))
        return np.array([self._slot[s] for s in sats], dtype=np.intp)

    def _current(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix) -> _Epoch | None:
        """The rows in the velocity fix with their observation: (pseudorange, rate, code noise variance,
        rate variance) and line of sight; None when there is none."""
        rows = np.flatnonzero(fix.rate_used).tolist()
        where = {key: j for j, key in enumerate(map(_KEY, epoch.observations))}  # the last of a key wins
        found = [(i, where[fix.satellites[i]]) for i in rows if fix.satellites[i] in where]
        if not found:
            return None
        obs = epoch.observations
        vals = np.array([_OBS_FIELDS(obs[j]) for _, j in found], dtype=float).reshape(-1, 3)
        idx = np.array([i for i, _ in found], dtype=np.intp)
        stated = vals[:, 2]
        with np.errstate(invalid="ignore"):
            sigma = np.where(stated > 0.0, stated, self.params.doppler_sigma_mps * fix.sigma_scales[idx])
        sats = [fix.satellites[i] for i in idx.tolist()]
        return _Epoch(stamp_ns, sats, self._slots_of(sats), {s: k for k, s in enumerate(sats)}, vals[:, 0],
                      vals[:, 1], fix.noise_variances_m2[idx], sigma * sigma, -fix.design_matrix[idx, :3],
                      fix.velocity_ecef_mps.copy())

    def update(self, stamp_ns: int, epoch: GnssEpoch, fix: MultiGnssFix) -> TestOutcome:
        """One epoch. UNKNOWN without rates, before the first pair, or with too few satellites."""
        p = self.params
        pfa = p.doppler_false_alarm_probability
        cur = self._current(stamp_ns, epoch, fix) if fix.valid and fix.velocity_valid else None
        if cur is None:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        prev = self._prev
        self._prev = cur
        dt = (stamp_ns - prev.stamp_ns) / NS_PER_S if prev is not None else math.inf
        if not 0.0 < dt <= p.max_gap_s:
            self._active[:] = False
            self._head = self._seq
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        assert prev is not None
        common = [k for k, s in enumerate(cur.sats) if s in prev.position]
        ic = np.array(common, dtype=np.intp)
        ip = np.array([prev.position[cur.sats[k]] for k in common], dtype=np.intp)
        allowance = (dt * float(np.linalg.norm(cur.velocity - prev.velocity)) / 4.0) ** 2
        e = cur.pr[ic] - prev.pr[ip] - 0.5 * dt * (cur.rate[ic] + prev.rate[ip])
        v = 0.5 * dt * dt * (cur.rate_var[ic] + prev.rate_var[ip]) + allowance + cur.code_var[ic] + prev.code_var[ip]
        if len(ic) >= 2:
            self.common_mode_m = float(np.sum(e / v) / np.sum(1.0 / v))
            e = e - self.common_mode_m
        in_cur = np.zeros(self._active.size, dtype=bool)
        in_cur[cur.slots] = True
        self._active &= (self._last == prev.stamp_ns) & in_cur  # a broken run starts again
        if len(ic) >= 2:
            self._add_pairs(stamp_ns, prev, cur, ic, e, v - cur.code_var[ic] - prev.code_var[ip], prev.code_var[ip])
        return self._evaluate()

    def _add_pairs(self, stamp_ns: int, prev: _Epoch, cur: _Epoch, ic: np.ndarray, e: np.ndarray,
                   pair_var: np.ndarray, start_var: np.ndarray) -> None:
        """Append this pair to every chain (a new chain for a satellite without one), then drop from
        each chain its pairs older than the window, oldest first (the per-chain running sums)."""
        if self._seq - self._head >= self._ring_stamp.size:
            self._grow_ring(2 * self._ring_stamp.size)
        # Python compares the int stamps with the float limit exactly; the limit is a whole number
        limit = stamp_ns - self.params.doppler_window_s * NS_PER_S
        self._head = doppler_add_pairs(
            cur.slots[ic], e, pair_var, start_var, cur.code_var[ic], cur.los[ic], stamp_ns, prev.stamp_ns,
            math.ceil(limit), self._seq, self._head, self._active, self._last, self._count, self._start,
            self._sum_e, self._sum_var, self._end_var, self._los, self._ring_stamp, self._ring_e, self._ring_var,
            self._ring_start_var, self._ring_in)
        self._seq += 1

    def _evaluate(self) -> TestOutcome:
        p = self.params
        pfa = p.doppler_false_alarm_probability
        self.implied_displacement_m = np.full(3, math.nan)
        live = np.flatnonzero(self._active & (self._count > 0)).tolist()
        if len(live) < p.doppler_min_satellites:
            return unknown(self.name, CATEGORY_CONSISTENCY, false_alarm_probability=pfa)
        keys = self._keys
        slots = np.array(sorted(live, key=keys.__getitem__), dtype=np.intp)
        sats = [keys[k] for k in slots.tolist()]
        e = self._sum_e[slots]
        at = self._start[slots] % self._ring_stamp.size  # each chain's first entry
        first, first_var = self._ring_stamp[at], self._ring_start_var[at, slots]
        span = (self._last[slots] - first) / NS_PER_S
        v = self._sum_var[slots] + first_var + self._end_var[slots] + (p.doppler_code_drift_mps * span) ** 2
        # A receiver noisier than the weight model (tracking loops, multipath) would alarm on clean
        # data: the variances are scaled by the median ratio of passing statistics to the
        # chi-square median over the last 600 evaluations, never below 1 (learned only from passing
        # epochs, so an attack cannot raise it quickly).
        v = v * self.noise_scale
        n = len(sats)
        suspect = chi2_threshold(pfa, n - 1)
        alarm = chi2_threshold(p.alarm_false_alarm_probability, n - 1)
        first_stat, excluded, passed = exclude_largest(
            e, v, 1, lambda dof: chi2_threshold(pfa, dof) if dof >= 1 else math.inf, p.raim_max_exclusions,
            p.doppler_min_satellites)
        warming_up = len(self._clean_ratios) < WARMUP_EVALUATIONS
        if first_stat < suspect or warming_up:
            self._clean_ratios.append(first_stat * self.noise_scale / chi2_threshold(0.5, n - 1))
            if len(self._clean_ratios) >= WARMUP_EVALUATIONS:
                self.noise_scale = min(10.0, max(1.0, self._clean_ratios.median()))
        if warming_up:  # the noise scale is not known yet: the first evaluations only teach it
            return unknown(self.name, CATEGORY_CONSISTENCY, suspect, alarm, pfa)
        if first_stat >= suspect and n >= 5:
            # a position-shaped divergence e_i = -u_i . delta + m: the receiver's whole position pushed
            h = np.hstack([-self._los[slots], np.ones((n, 1))])
            fit = np.linalg.lstsq(h / np.sqrt(v)[:, None], e / np.sqrt(v), rcond=None)[0]
            self.implied_displacement_m = fit[:3]
            if float(np.sum((e - h @ fit) ** 2 / v)) < chi2_threshold(pfa, n - 4):
                return consistency_outcome(self.name, first_stat, suspect, alarm, pfa)
        scope, cons, implicated = implicated_scope([sats[i] for i in excluded], passed, sats)
        return consistency_outcome(self.name, first_stat, suspect, alarm, pfa, scope, cons, implicated)

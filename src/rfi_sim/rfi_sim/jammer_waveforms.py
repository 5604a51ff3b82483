"""Frequency laws of real chirp jammers: saw-tooth up/down, triangular, hooked saw-tooth, non-linear rate.

Cheap in-car chirp jammers drive a VCO with a saw-tooth or triangular voltage from an RC oscillator,
so their sweeps are neither the paper's constant-rate saw-tooth nor confined to the receiver's band
(Mitch et al., "Signal characteristics of civil GPS jammers", ION GNSS 2011, Fig. 4-8: saw-tooth,
triangular and "hooked" saw-tooth sweeps, non-constant rates). This module describes one period of
such a sweep as a list of segments whose frequency is quadratic in time (the sweep rate changes
linearly inside a segment), so the phase is an exact cubic and the instantaneous frequency of a
generated signal is known in closed form.

Frequencies are relative to the RF centre, Hz; times in s. ``tau`` is the time inside the current
sweep period, ``0 <= tau < sweep_period_s``; a period starts at ``low_frequency_hz`` (saw-tooth up,
triangle, hooked saw-tooth) or ``high_frequency_hz`` (saw-tooth down).

Example
-------
>>> j = SweepJammer(shape="triangle", low_frequency_hz=-12e6, high_frequency_hz=12e6,
...                 sweep_period_s=9.09e-6)
>>> law = sweep_law(j)
>>> float(law.frequency_hz(np.array([0.0, 4.545e-6]))[1]) / 1e6   # top of the triangle, MHz
12.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SHAPES = ("saw_up", "saw_down", "triangle", "hooked_saw")
"""Sweep shapes of :class:`SweepJammer`."""


@dataclass(frozen=True)
class SweepJammer:
    """Swept (chirp) jammer with a real jammer's sweep shape.

    One period (``sweep_period_s``) is made of segments in which the frequency moves between
    ``low_frequency_hz`` and ``high_frequency_hz``:

    - ``saw_up``: low -> high over the whole period, then an instantaneous return (phase continuous);
    - ``saw_down``: high -> low, then an instantaneous return;
    - ``triangle``: low -> high over ``up_fraction`` of the period, high -> low over the rest;
    - ``hooked_saw``: low -> high over ``1 - hook_fraction`` of the period, then a fast return
      that overshoots to ``low - hook_overshoot_hz`` in the first half of the hook and relaxes back
      to ``low`` in the second half (the "hook").

    Non-linear rate: in every sweeping segment the rate changes linearly in time from ``r0`` at the
    segment start to ``rate_ratio * r0`` at its end, with ``r0`` such that the segment covers its
    band exactly (``r0 = 2 * delta_f / (duration * (1 + rate_ratio))``). ``rate_ratio = 1`` is a
    constant-rate (linear) sweep; 1.54 / 1.35 is the saw-tooth of the issue's first recording.
    The hook's two parts are always linear.

    The band may be wider than the sampled band (set ``FrontEndConfig.filter_*`` to model the
    front end's band-limiting filter; without one the sweep aliases, as an unfiltered ADC would).

    Attributes:
        shape: one of ``SHAPES``.
        low_frequency_hz: lowest frequency of the sweep (hook excluded), relative to the RF centre, Hz.
        high_frequency_hz: highest frequency of the sweep, Hz, > low_frequency_hz.
        sweep_period_s: period of the sweep, s, > 0.
        js_db: jammer-to-signal ratio (power at the antenna, before any front-end filter), dB.
        rate_ratio: rate at the end of each sweeping segment over the rate at its start, > 0.
        up_fraction: triangle only: fraction of the period spent sweeping up, (0, 1).
        hook_fraction: hooked_saw only: fraction of the period taken by the return, (0, 1).
        hook_overshoot_hz: hooked_saw only: how far below low_frequency_hz the return goes, Hz, >= 0.
        phase_rad: phase at the start of the stream, rad.
        time_offset_s: position inside the sweep at sample 0, s.
        on_time_s: time at which the jammer is switched on, s since sample 0 of the stream; 0: on from
            the first sample. Before it the jammer is absent.
    """

    shape: str = "saw_up"
    low_frequency_hz: float = -4.0e6
    high_frequency_hz: float = 4.0e6
    sweep_period_s: float = 10e-6
    js_db: float = 30.0
    rate_ratio: float = 1.0
    up_fraction: float = 0.5
    hook_fraction: float = 0.1
    hook_overshoot_hz: float = 1.0e6
    phase_rad: float = 0.0
    time_offset_s: float = 0.0
    on_time_s: float = 0.0

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"shape must be one of {SHAPES}, got {self.shape!r}")
        vals = (self.low_frequency_hz, self.high_frequency_hz, self.sweep_period_s, self.js_db,
                self.rate_ratio, self.up_fraction, self.hook_fraction, self.hook_overshoot_hz,
                self.phase_rad, self.time_offset_s, self.on_time_s)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("SweepJammer fields must be finite")
        if not self.high_frequency_hz > self.low_frequency_hz:
            raise ValueError("high_frequency_hz must be > low_frequency_hz")
        if not self.sweep_period_s > 0:
            raise ValueError("sweep_period_s must be > 0")
        if not self.rate_ratio > 0:
            raise ValueError("rate_ratio must be > 0")
        if not 0 < self.up_fraction < 1 or not 0 < self.hook_fraction < 1:
            raise ValueError("up_fraction and hook_fraction must be in (0, 1)")
        if self.hook_overshoot_hz < 0:
            raise ValueError("hook_overshoot_hz must be >= 0")

    @property
    def swept_band_hz(self) -> tuple[float, float]:
        """(lowest, highest) frequency the sweep reaches, Hz (the hook's overshoot included)."""
        lo = self.low_frequency_hz - (self.hook_overshoot_hz if self.shape == "hooked_saw" else 0.0)
        return lo, self.high_frequency_hz

    @property
    def mean_rate_hz_per_s(self) -> float:
        """Mean |rate| of the main sweeping segment, Hz/s (band over its duration)."""
        span = self.high_frequency_hz - self.low_frequency_hz
        if self.shape == "triangle":
            return span / (self.up_fraction * self.sweep_period_s)
        if self.shape == "hooked_saw":
            return span / ((1 - self.hook_fraction) * self.sweep_period_s)
        return span / self.sweep_period_s


@dataclass(frozen=True)
class SweepLaw:
    """Piecewise-quadratic frequency law of one sweep period.

    Segment ``i`` starts at ``start_s[i]`` (s into the period) with frequency ``f0_hz[i]``, rate
    ``r0_hz_per_s[i]`` and rate change ``a_hz_per_s2[i]``:
    ``f(tau) = f0 + r0 s + a s^2 / 2`` and phase ``cycles(tau) = C_i + f0 s + r0 s^2 / 2 + a s^3 / 6``
    with ``s = tau - start_s[i]`` and ``C_i`` the cycles accumulated by the earlier segments.

    Attributes:
        period_s: sweep period, s.
        start_s, f0_hz, r0_hz_per_s, a_hz_per_s2, cycles_at_start: per segment, shape (n_seg,).
        cycles_per_period: cycles accumulated over one whole period.
    """

    period_s: float
    start_s: np.ndarray
    f0_hz: np.ndarray
    r0_hz_per_s: np.ndarray
    a_hz_per_s2: np.ndarray
    cycles_at_start: np.ndarray
    cycles_per_period: float

    def _segment(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.clip(np.searchsorted(self.start_s, tau, side="right") - 1, 0, self.start_s.size - 1)
        return i, tau - self.start_s[i]

    def frequency_hz(self, tau: np.ndarray) -> np.ndarray:
        """Instantaneous frequency at ``tau`` (s into the period, [0, period)), Hz."""
        i, s = self._segment(np.asarray(tau, dtype=np.float64))
        return self.f0_hz[i] + self.r0_hz_per_s[i] * s + 0.5 * self.a_hz_per_s2[i] * s * s

    def rate_hz_per_s(self, tau: np.ndarray) -> np.ndarray:
        """Instantaneous sweep rate df/dt at ``tau``, Hz/s."""
        i, s = self._segment(np.asarray(tau, dtype=np.float64))
        return self.r0_hz_per_s[i] + self.a_hz_per_s2[i] * s

    def cycles(self, tau: np.ndarray) -> np.ndarray:
        """Phase accumulated from the period start to ``tau``, cycles (integral of frequency_hz)."""
        i, s = self._segment(np.asarray(tau, dtype=np.float64))
        return (self.cycles_at_start[i] + self.f0_hz[i] * s + 0.5 * self.r0_hz_per_s[i] * s * s
                + self.a_hz_per_s2[i] * s * s * s / 6.0)


def _segments(j: SweepJammer) -> list[tuple[float, float, float, float]]:
    """(duration s, f start Hz, f end Hz, rate ratio) of each segment of one period."""
    T, lo, hi, q = j.sweep_period_s, j.low_frequency_hz, j.high_frequency_hz, j.rate_ratio
    if j.shape == "saw_up":
        return [(T, lo, hi, q)]
    if j.shape == "saw_down":
        return [(T, hi, lo, q)]
    if j.shape == "triangle":
        u = j.up_fraction
        return [(u * T, lo, hi, q), ((1 - u) * T, hi, lo, q)]
    h = j.hook_fraction
    bottom = lo - j.hook_overshoot_hz
    return [((1 - h) * T, lo, hi, q), (0.5 * h * T, hi, bottom, 1.0), (0.5 * h * T, bottom, lo, 1.0)]


def sweep_law(j: SweepJammer) -> SweepLaw:
    """The frequency law of one period of ``j`` (see :class:`SweepLaw`)."""
    starts, f0s, r0s, accs, cyc = [], [], [], [], []
    t = 0.0
    c = 0.0
    for dur, fa, fb, q in _segments(j):
        r0 = 2.0 * (fb - fa) / (dur * (1.0 + q))
        a = (q * r0 - r0) / dur
        starts.append(t)
        f0s.append(fa)
        r0s.append(r0)
        accs.append(a)
        cyc.append(c)
        c += fa * dur + 0.5 * r0 * dur * dur + a * dur ** 3 / 6.0
        t += dur
    return SweepLaw(period_s=j.sweep_period_s, start_s=np.array(starts), f0_hz=np.array(f0s),
                    r0_hz_per_s=np.array(r0s), a_hz_per_s2=np.array(accs),
                    cycles_at_start=np.array(cyc), cycles_per_period=c)


def sweep_cycles(law: SweepLaw, t: np.ndarray, time_offset_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase (cycles, relative to sample 0), frequency (Hz) and sweep counter at stream times ``t``.

    Args:
        law: SweepLaw.
        t: stream times, s, shape (n,).
        time_offset_s: position inside the sweep at t = 0, s.

    Returns:
        (cycles mod an integer, shape (n,); f_rel_hz, shape (n,); k, the sweep counter, shape (n,)).
        Whole periods are reduced modulo 1 cycle before they are added, so the phase stays exact
        over long streams.
    """
    T = law.period_s
    u = t + time_offset_s
    k = np.floor(u / T)
    tau = u - k * T
    frac = law.cycles_per_period - math.floor(law.cycles_per_period)
    k0 = math.floor(time_offset_s / T)
    tau0 = np.array([time_offset_s - k0 * T])
    cyc0 = float(law.cycles(tau0)[0])
    cycles = np.mod((k - k0) * frac, 1.0) + law.cycles(tau) - cyc0
    return cycles, law.frequency_hz(tau), k

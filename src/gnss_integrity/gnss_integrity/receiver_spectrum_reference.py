"""The learned clean reference of one RF block of a receiver spectrum, and its noise model (pure).

Used by :class:`gnss_integrity.receiver_spectrum.ReceiverSpectrumMonitor` (see its module
docstring for the test): the per-bin median shape of the last clean reports (each without its
median level), their input-referred levels and PGA gains, and from the out-of-sample differences
of each newly learned report against the reference before it, the per-bin noise std and the
noise of window sums.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from scipy.special import ndtri

TRIM_KEEP = 0.9
"""Share of the smallest |values| a trimmed std keeps."""
_Q = float(ndtri(0.5 + TRIM_KEEP / 2.0))
TRIM_VARIANCE = (TRIM_KEEP - 2.0 * _Q * math.exp(-0.5 * _Q * _Q) / math.sqrt(2.0 * math.pi)) / TRIM_KEEP
"""E[Z^2 | |Z| below its TRIM_KEEP quantile] of a standard normal Z (0.623)."""


REFRESH_FROM, REFRESH_EVERY = 20, 10
"""The noise model is recomputed with each learned report until it rests on REFRESH_FROM
differences, then with every REFRESH_EVERY-th (it changes slowly; this keeps a report < 2 ms)."""


def trimmed_std(values: np.ndarray, axis: int | None = None) -> np.ndarray:
    """Std of zero-mean normal data from the smallest ``TRIM_KEEP`` of ``|values|``: robust to a
    tenth of outliers, and not 0 on data quantised more coarsely than its spread (as a MAD is).

    Examples:
        >>> round(float(trimmed_std(np.random.default_rng(1).normal(0.0, 2.0, 100_000))), 1)
        2.0
        >>> round(float(trimmed_std(np.array([0.0, 0.0, 0.0, 0.25, -0.25, 0.0]))), 2)  # its MAD is 0
        0.18
    """
    v = np.asarray(values, dtype=float)
    if axis is None:
        v, axis = v.ravel(), 0
    v = v * v
    keep = max(1, int(math.ceil(TRIM_KEEP * v.shape[axis])))
    if keep < v.shape[axis]:
        v = np.take(np.partition(v, keep - 1, axis=axis), np.arange(keep), axis=axis)
    return np.sqrt(np.mean(v, axis=axis) / TRIM_VARIANCE)


def window_sums(values: np.ndarray, w: int, axis: int = -1) -> np.ndarray:
    """Sums of ``w`` consecutive values along ``axis``, for every start (length n - w + 1)."""
    c = np.cumsum(values, axis=axis)
    c = np.concatenate((np.zeros_like(np.take(c, [0], axis=axis)), c), axis=axis)
    n = c.shape[axis]
    return np.take(c, np.arange(w, n), axis=axis) - np.take(c, np.arange(0, n - w), axis=axis)


class BlockReference:
    """Clean reference and noise model of one RF block.

    Args:
        geometry: what the reference is valid for (bin count, centre, span, PGA reported); a
            report with another geometry needs a new reference.
        max_reports: clean reports kept (older ones are forgotten).
        window_bins: window widths whose noise scale is learned, bins.
        noise_floor_db: smallest per-bin noise std, dB.

    Attributes:
        shape: per-bin median of the kept clean shapes, dB, (bins,) (None before 3 reports).
        sigma: per-bin noise std of a new report's shape difference, dB (None before 3
            differences): the larger of the per-bin and the global trimmed std, >= noise_floor_db
            (refreshed as :data:`REFRESH_FROM` and :data:`REFRESH_EVERY` say).
        window_scale: width -> ``c_w >= 1``, trimmed std of the window sums of the normalised
            differences over ``sqrt(w)`` (1 for white noise; larger when neighbouring bins correlate).
        streak, last_bins: reports in a row with a finding, and the bins of the last one.
    """

    def __init__(self, geometry: tuple[float, ...], max_reports: int, window_bins: tuple[int, ...],
                 noise_floor_db: float) -> None:
        self.geometry = geometry
        self._max = int(max_reports)
        self._widths = tuple(window_bins)
        self._floor = float(noise_floor_db)
        self._shapes: deque[np.ndarray] = deque()
        self._levels: deque[float] = deque()
        self._pgas: deque[float] = deque()
        self._innovations: deque[np.ndarray] = deque()
        self._level_innovations: deque[float] = deque()
        self.shape: np.ndarray | None = None
        self.sigma: np.ndarray | None = None
        self.window_scale: dict[int, float] = {}
        self.streak = 0
        self.last_bins: tuple[int, int] | None = None
        self._learned = 0

    @property
    def count(self) -> int:
        """Clean reports kept."""
        return len(self._shapes)

    @property
    def level_db(self) -> float:
        """Median input-referred level of the kept reports, dB (NaN: none)."""
        return float(np.median(self._levels)) if self._levels else math.nan

    @property
    def pga_gain_db(self) -> float:
        """Median PGA gain of the kept reports that reported one, dB (NaN: none)."""
        finite = [v for v in self._pgas if math.isfinite(v)]
        return float(np.median(finite)) if finite else math.nan

    def level_std_db(self, floor_db: float) -> float:
        """Trimmed std of the clean level changes, at least ``floor_db``, dB."""
        if not self._level_innovations:
            return floor_db
        return max(floor_db, float(trimmed_std(np.asarray(self._level_innovations))))

    def learn(self, power_db: np.ndarray, level_db: float, pga_gain_db: float) -> None:
        """Add a clean report: its bins (dB), input-referred level (dB) and PGA gain (dB, NaN)."""
        shape = power_db - np.median(power_db)
        if self.shape is not None:
            r = shape - self.shape
            self._innovations.append(r - np.median(r))
            self._level_innovations.append(level_db - self.level_db)
        self._shapes.append(shape)
        self._levels.append(float(level_db))
        self._pgas.append(float(pga_gain_db))
        for history in (self._shapes, self._levels, self._pgas, self._innovations, self._level_innovations):
            while len(history) > self._max:
                history.popleft()
        if len(self._shapes) >= 3:
            self.shape = np.median(np.asarray(self._shapes), axis=0)
        self._learned += 1
        n = len(self._innovations)
        if n >= 3 and (n < REFRESH_FROM or self._learned % REFRESH_EVERY == 0):
            innovations = np.asarray(self._innovations)
            per_bin = trimmed_std(innovations, axis=0)
            self.sigma = np.maximum(per_bin, max(float(trimmed_std(innovations)), self._floor))
            z = innovations / self.sigma
            self.window_scale = {w: max(1.0, float(trimmed_std(window_sums(z, w, axis=1))) / math.sqrt(w))
                                 for w in self._widths}

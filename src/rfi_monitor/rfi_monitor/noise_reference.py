"""The noise power a block's J/N is measured against, for the "stft" estimator (pure module, no ROS).

The reference is, in this order (``NoiseReference.reference``): the configured floor (``noise_floor_power``, or
``noise_floor_dbfs`` of the quantiser's full scale), the floor learned from the last ``calibration_blocks`` blocks
that passed as noise (their median power, and the median of their normalised spectra, smoothed across frequency, as
the front end's shape), else the noise level measured inside the block itself (ridge analysis, step 2). The codes
``REF_*`` say which (``estimate`` module; rfi_msgs/JammerState).
"""

from __future__ import annotations

import math

import numpy as np

from rfi_monitor.classifier import smooth_template
from rfi_monitor.estimate import REF_FIXED, REF_IN_BLOCK, REF_LEARNED
from rfi_monitor.params import RfiMonitorParams


class NoiseReference:
    """The learned noise floor and shape of the "stft" estimator, and the reference J/N is measured against."""

    def __init__(self, params: RfiMonitorParams) -> None:
        self.params = params
        self.forget()

    def forget(self) -> None:
        """Learn the floor and shape again from the next blocks that pass as noise."""
        self._learn_pow: list[float] = []
        self._learn_psd: list[np.ndarray] = []
        self.floor = math.nan
        """The learned floor, sample units^2 (NaN until ``calibration_blocks`` blocks were learned)."""
        self.template: np.ndarray | None = None
        """The learned normalised noise shape (None until learned)."""
        self._learn_since_tpl = 0

    def reference(self, fs: float, cplx: bool, full_scale: float | None, inblock: float) -> tuple[float, int]:
        """(noise power, REF_* code) J/N is measured against (module docstring)."""
        p = self.params
        if p.noise_floor_power > 0:
            return p.noise_floor_power, REF_FIXED
        if p.noise_floor_dbfs < 0 and full_scale is not None:
            return (2.0 if cplx else 1.0) * full_scale ** 2 * 10 ** (p.noise_floor_dbfs / 10), REF_FIXED
        if math.isfinite(self.floor):
            return self.floor, REF_LEARNED
        return inblock, REF_IN_BLOCK

    def learn(self, power: float, norm_psd: np.ndarray) -> None:
        """Add a block that passed as noise to the learned floor and shape (the last calibration_blocks).

        The floor (a median of k numbers) follows every such block; the shape (a median of k spectra, then a
        running median across bins: ~0.15 ms, more than the rest of a quiet block's bookkeeping) is formed again
        once every k blocks learned, from the last k (the front end's shape drifts over seconds, not blocks)."""
        k = int(self.params.calibration_blocks)
        self._learn_pow.append(power)
        self._learn_psd.append(norm_psd)
        if len(self._learn_pow) > k:
            del self._learn_pow[:-k], self._learn_psd[:-k]
        self._learn_since_tpl += 1
        if len(self._learn_pow) >= k:
            self.floor = _median(self._learn_pow)
            if self.template is None or self._learn_since_tpl >= k:
                med = _median_rows(np.stack(self._learn_psd))
                self.template = smooth_template(med, self.params.classifier.template_smooth_bins)
                self._learn_since_tpl = 0


def _median(values: list[float]) -> float:
    """``float(np.median(values))`` of a few finite numbers, to the bit (the middle one, or the mean of the two
    middle ones as (a + b) / 2), without numpy's per-call overhead (~12 us; this runs on every quiet block)."""
    s = sorted(values)
    h = len(s) // 2
    return float(s[h]) if len(s) % 2 else (s[h - 1] + s[h]) / 2


def _median_rows(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=0)`` of finite values, to the bit (each column sorted: its middle value, or the mean of
    the two middle ones), at a fraction of its cost on a few rows."""
    s = np.sort(a, axis=0)
    h = s.shape[0] // 2
    return s[h].copy() if s.shape[0] % 2 else (s[h - 1] + s[h]) / 2

"""The CW statistic of the evidence over blocks (orchestrated by ``rfi_monitor.integration.Integrator``; issue 14
item 5).

A tone of at least ``min_cw_jn_db`` over the whole band's noise (front-end spurs, -11 to -20 dB in the real clean
captures, are significant but no jammer), significant in the Welch PSD (the classifier's Welch PSD of the block at
``nfft``, all frames) summed over blocks. Under Gaussian noise each bin of the sum over ``K`` independent Hann frames is
``N_b chi2(2K) / 2K`` (real input: the DC and Nyquist bins ``chi2(K) / K``). The reference ``N_b`` is the summed PSD's
own running median over ``smooth_bins`` bins (a tone never enters it). A bin is a tone when ``P_b / N_b`` exceeds the
``1 - alpha / B`` quantile of ``Gamma(K, 1/K)`` (Bonferroni over the ``B`` bins: a false alarm per block of at most
``alpha``; the median's own scatter, ~1.25 / sqrt(K smooth_bins), taken at 4 sigma, multiplies the threshold).
The running median and the scores are compiled (:func:`_cw_scores`; issue 26 item 2: scipy's median filter and ten
numpy calls per tested sum before, the same values).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy import special

from rfi_monitor.numpy_kernels import MEDIAN_REFLECT, MEDIAN_WRAP, pairwise_sum, running_median


class CwStatistic:
    """The CW test of a summed Welch PSD (module docstring); keeps its thresholds and the Gamma medians cached.

    Args:
        smooth_bins: width of the running median that is the noise reference, odd >= 5.
    """

    def __init__(self, smooth_bins: int) -> None:
        self.smooth_bins = int(smooth_bins)
        self._cw_thr: dict[tuple[int, int, bool, float], np.ndarray] = {}
        self._med: dict[int, float] = {}

    def test(self, P: np.ndarray, K: int, cplx: bool, alpha: float) -> tuple[float, float, float]:
        """(score, frequency, excess) of the PSD P summed over K frames, at false-alarm probability alpha: the largest
        normalised bin over its threshold (> 1: a tone), its bin centre (cycles/sample: fftshift order for complex
        input, -0.5..0.5; real 0..0.5), and the tone's power there over the noise of the whole band (linear)."""
        Pm = P
        if not cplx and P.size > 3:
            Pm = P.copy()
            Pm[0], Pm[-1] = P[1], P[-2]      # DC and Nyquist (one degree of freedom) do not enter the median
        B = P.size
        thr = self._threshold(K, B, cplx, alpha)
        # the running median of a Gamma(K, 1/K) variable is its median, not its mean (ln 2 at K = 1): corrected; the
        # score and the tone's excess in one compiled pass (:func:`_cw_scores`)
        cw_score, j, excess = _cw_scores(np.ascontiguousarray(P, dtype=np.float64),
                                         np.ascontiguousarray(Pm, dtype=np.float64), thr, self._median_ratio(K),
                                         self.smooth_bins, bool(cplx))
        cw_f = (j - B // 2) / B if cplx else j / (2 * (B - 1))
        return cw_score, float(cw_f), excess

    def _median_ratio(self, K: int) -> float:
        """Median over mean of Gamma(K, 1/K) (cached)."""
        v = self._med.get(int(K))
        if v is None:
            v = float(special.gammaincinv(float(K), 0.5)) / float(K)   # scipy.stats.gamma.median, without its overhead
            if len(self._med) > 256:
                self._med.clear()
            self._med[int(K)] = v
        return v

    def _threshold(self, K: int, B: int, cplx: bool, alpha: float) -> np.ndarray:
        """Per-bin threshold of P_b / N_b (module docstring) at false-alarm probability alpha, cached per
        (K, B, kind, alpha)."""
        key = (int(K), int(B), bool(cplx), float(alpha))
        thr = self._cw_thr.get(key)
        if thr is None:
            # the upper alpha / B quantile of Gamma(dof, 1 / dof): dof K, and K / 2 at DC and Nyquist of a real IF
            # (scipy.special directly: scipy.stats.gamma.isf gives the same numbers at ~0.3 ms a call, per decision)
            q = alpha / B
            thr_g = np.full(B, float(special.gammainccinv(float(K), q)) / float(K))
            if not cplx:
                thr_g[0] = thr_g[-1] = float(special.gammainccinv(0.5 * K, q)) / (0.5 * K)
            # the reference's own scatter (a median of smooth_bins bins of the same chi-square: 1.2533 / sqrt(K w)
            # relative, 1 sigma), taken at 4 sigma as a relative error of the reference
            rel_ref = 1.2533 / math.sqrt(K * self.smooth_bins)
            thr = thr_g * (1.0 + 4.0 * rel_ref)
            if len(self._cw_thr) > 64:
                self._cw_thr.clear()
            self._cw_thr[key] = thr
        return thr


@njit(cache=True, nogil=True)
def _cw_scores(P: np.ndarray, Pm: np.ndarray, thr: np.ndarray, median_ratio: float, width: int, cplx: bool
               ) -> tuple[float, int, float]:
    """(largest score, its bin, the tone's excess) of ``CwStatistic.test``: the reference N_b, Pm's running median over
    width bins (``numpy_kernels.running_median``, wrapped for complex samples, mirrored for real) over median_ratio,
    floored at 1e-300; the score (P / N_b) / thr (0 at DC and Nyquist of a real IF: outside any front end's pass
    band), its first largest bin j; the excess over the reference
    of bins j - 2 .. j + 2 (a Hann window puts 0.4-0.67 of a tone in its strongest bin) over the reference's sum
    (the noise of the whole band). The numpy expressions it replaced, element by element, numpy's pairwise sums."""
    B = P.size
    ref = running_median(Pm, width, MEDIAN_WRAP if cplx else MEDIAN_REFLECT)
    for i in range(B):
        ref[i] = max(ref[i] / median_ratio, 1e-300)
    j = 0
    best = -math.inf
    for i in range(B):
        sc = P[i] / ref[i] / thr[i]
        if not cplx and (i == 0 or i == B - 1):
            sc = 0.0
        if sc > best or i == 0:
            best = sc
            j = i
    lo_j, hi_j = max(j - 2, 0), min(j + 3, B)
    ex = np.empty(hi_j - lo_j)
    for i in range(lo_j, hi_j):
        ex[i - lo_j] = P[i] - ref[i]
    excess = pairwise_sum(ex, 0.0) / max(pairwise_sum(ref, 0.0), 1e-300)
    return best, j, excess

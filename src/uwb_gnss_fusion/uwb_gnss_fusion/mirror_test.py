"""The UWB mirror ambiguity and the GNSS likelihood-ratio test that resolves it (ours, not Cao et al.).

Pure core (no rclpy).

Ranges to anchors that lie in one plane (three anchors always do) are unchanged when the tag is
reflected across that plane: the range model of Cao et al. eq. 7 has two solutions, the tag and
its mirror image. A tag close to the plane of its anchors (the usual installation: anchors around
the work area at about the tag's height) has its mirror a few decimetres to a metre away, and the
UWB ranges cannot tell the two apart, so the filter settles on whichever side its first metres of
GNSS vertical error favour (docs/uwb_gnss_fusion/fusion_never_worse.md: 3 anchors, the mirror
about 1.2 m above the truth). The pseudoranges (eq. 5) do tell them apart, weakly at every epoch
and better on their time average.

:class:`MirrorTest` accumulates, epoch after epoch, the GNSS log-likelihood ratio of the mirror
against the current estimate (both have the same UWB likelihood) and the filter jumps to the
mirror when the ratio exceeds a threshold:

``Lambda_t = 0.5 (chi2(x) - chi2(x_m))``, ``chi2(x) = r_c^T W r_c``, ``r_c`` the pseudorange
residuals at ``x`` with their weighted mean removed (the receiver clock re-solved for each
hypothesis), ``W = diag(1 / sigma_pr^2)`` (Cao et al. eq. 4, 12).

``L = sum_t Lambda_t * min(1, dt_t / (2 tau)) / s0^2``: the per-epoch increments are scaled
(a) by ``dt / (2 tau)``, the number of independent samples an epoch adds when the pseudorange
errors are correlated over ``tau`` (for a first-order Gauss-Markov error the variance of a long sum
of ``N`` samples is ``N (2 tau / dt)`` times that of independent ones; Brown & Hwang, 4th ed.,
sec. 2.9), only when the filter models such errors (``pseudorange_correlated_std_m`` > 0; otherwise
the test assumes white errors as the filter does: ``tau = 0``, factor 1), and (b) by the
a-posteriori variance factor ``s0^2 = chi2 / (k - 4)`` of the residuals (exponentially averaged
over ``tau`` or :data:`VARIANCE_FACTOR_MEMORY_S`, floored at 1), which rescales ``W`` when the
stated pseudorange 1-sigmas are too small for the errors actually seen. ``L`` is then an
approximate log-likelihood ratio of the two sides with no prior preference (the side the filter
first chose holds no information beyond the same early epochs). The filter jumps when ``L`` exceeds
the threshold, and ``L`` changes sign (the hypotheses swap).
"""

from __future__ import annotations

import math

import numpy as np

MIRROR_MIN_PLANE_SPREAD_M = 0.5
"""The anchors must span a plane: the second singular value of their centred positions (about
their spread across the smallest in-plane direction) at least this, m."""

MIRROR_MAX_RANGE_CHANGE_SIGMA = 1.0
"""The reflection is a UWB ambiguity only if every anchor's predicted range changes by less than
this many range 1-sigmas (exactly 0 for three anchors; four or more anchors must be nearly coplanar)."""


VARIANCE_FACTOR_MEMORY_S = 60.0
"""Averaging time of the a-posteriori variance factor when the pseudorange errors are white, s."""


def anchor_plane(anchors_m: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Best-fit plane of the anchors: ``(centroid (3,), unit normal (3,))``, or None when there are
    fewer than three anchors or they are (nearly) collinear (``MIRROR_MIN_PLANE_SPREAD_M``)."""
    a = np.asarray(anchors_m, dtype=float)
    if a.ndim != 2 or a.shape[0] < 3 or a.shape[1] != 3:
        return None
    c = a.mean(axis=0)
    _, s, vt = np.linalg.svd(a - c)
    if s[1] < MIRROR_MIN_PLANE_SPREAD_M:
        return None
    return c, vt[2]


def reflect(points_m: np.ndarray, centroid_m: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Reflection of points (..., 3) across the plane through ``centroid_m`` with unit ``normal``."""
    p = np.asarray(points_m, dtype=float)
    return p - 2.0 * ((p - centroid_m) @ normal)[..., None] * normal


def householder(normal: np.ndarray) -> np.ndarray:
    """The reflection matrix ``I - 2 n n^T`` (3, 3) (linear part of :func:`reflect`)."""
    n = np.asarray(normal, dtype=float)
    return np.eye(3) - 2.0 * np.outer(n, n)


def is_range_ambiguous(tag_m: np.ndarray, mirror_m: np.ndarray, anchors_m: np.ndarray, range_std_m: float) -> bool:
    """True if the ranges from ``tag_m`` and ``mirror_m`` to every anchor differ by less than
    ``MIRROR_MAX_RANGE_CHANGE_SIGMA * range_std_m``."""
    a = np.asarray(anchors_m, dtype=float)
    d0 = np.linalg.norm(a - tag_m, axis=1)
    d1 = np.linalg.norm(a - mirror_m, axis=1)
    return bool(np.max(np.abs(d0 - d1)) < MIRROR_MAX_RANGE_CHANGE_SIGMA * range_std_m)


def clock_free_chi2(residuals_m: np.ndarray, sigma_m: np.ndarray) -> np.ndarray:
    """Weighted sum of squares of residuals with their weighted mean (the clock) removed.

    Args:
        residuals_m: (h, k) pseudorange residuals of ``h`` hypotheses at ``k`` satellites, m.
        sigma_m: (k,) pseudorange 1-sigmas, m.

    Returns:
        (h,) chi-square values.
    """
    w = 1.0 / np.asarray(sigma_m, dtype=float) ** 2
    r = np.atleast_2d(residuals_m)
    clock = (r * w).sum(axis=1, keepdims=True) / w.sum()
    return ((r - clock) ** 2 * w).sum(axis=1)


def mirror_wrong_side_probability(separation_m: float, gnss_std_m: float | None) -> float:
    """Probability that an estimate that settled on one side of the anchors' plane is on the mirror.

    The estimate sits at one of two points ``d`` apart along the plane's normal ``n``, on the wrong
    one with this probability ``p``: its mean squared error along ``n`` is ``p d^2``, which a
    covariance from the ranges leaves out (``uwb_mirror_covariance`` publishes it).

    With GNSS the side is the one the GNSS position was nearer to when the ranges took over: wrong
    when the GNSS error along the plane's normal exceeds half the separation ``d`` of the tag and
    its mirror, ``p = Phi(-d / (2 sigma))`` for a GNSS error of 1-sigma ``sigma`` along the normal
    (``docs/uwb_gnss_fusion/fusion_mirror_bound.md`` measures how often that happens). Without GNSS
    (``gnss_std_m`` None) nothing picks the side: ``p = 0.5``.

    Example:
        >>> round(mirror_wrong_side_probability(1.28, 2.0), 3)
        0.374
    """
    if gnss_std_m is None:
        return 0.5
    if not gnss_std_m > 0.0:
        return 0.0
    return 0.5 * math.erfc(separation_m / (2.0 * math.sqrt(2.0) * gnss_std_m))


class MirrorTest:
    """Accumulated GNSS log-likelihood ratio of the mirror solution against the current one.

    Args:
        tau_s: correlation time of the pseudorange errors, s (>= 0; 0: white errors, every epoch
            independent evidence).
        switch_log_lr: jump to the mirror when the ratio exceeds this (> 0).

    Example:
        >>> t = MirrorTest(tau_s=60.0, switch_log_lr=1.0)
        >>> t.add(np.array([10.0, 2.0]), 8, 120.0)  # chi2 current 10, mirror 2, 8 satellites
        True
        >>> round(t.log_lr, 3)  # 0.5 (10 - 2) / s0^2 = 2.5, swapped after the jump
        -1.6
    """

    def __init__(self, tau_s: float, switch_log_lr: float) -> None:
        if not (math.isfinite(tau_s) and tau_s >= 0.0 and math.isfinite(switch_log_lr) and switch_log_lr > 0.0):
            raise ValueError("tau_s must be finite and >= 0, switch_log_lr finite and > 0")
        self.tau_s = float(tau_s)
        self.switch_log_lr = float(switch_log_lr)
        self.reset()

    def reset(self, key: object = None) -> None:
        """Forget the evidence (new anchor set ``key``, reinitialisation)."""
        self.key = key
        self.log_lr = 0.0
        self.variance_factor = 1.0
        self._vf_weight = 0.0

    def add(self, chi2_pair: np.ndarray, n_satellites: int, dt_s: float) -> bool:
        """Add one epoch: ``chi2_pair = (chi2 current, chi2 mirror)`` over ``n_satellites``
        pseudoranges, ``dt_s`` since the previous epoch. Returns True when the filter should jump
        to the mirror (the ratio is then already swapped)."""
        c0, c1 = float(chi2_pair[0]), float(chi2_pair[1])
        if not (math.isfinite(c0) and math.isfinite(c1)) or n_satellites < 4:
            return False
        dt = max(dt_s, 0.0)
        frac = 1.0 if self.tau_s == 0.0 else min(1.0, dt / (2.0 * self.tau_s))
        if n_satellites > 4:
            # a-posteriori variance factor, exponentially averaged over about tau (white errors:
            # VARIANCE_FACTOR_MEMORY_S; the first epoch of a test sets it)
            memory = self.tau_s if self.tau_s > 0.0 else VARIANCE_FACTOR_MEMORY_S
            a = min(1.0, dt / memory) if self._vf_weight > 0.0 else 1.0
            self._vf_weight = (1.0 - a) * self._vf_weight + a
            s0 = c0 / (n_satellites - 4)
            self.variance_factor += (a / self._vf_weight) * (s0 - self.variance_factor)
        self.log_lr += 0.5 * (c0 - c1) * frac / max(1.0, self.variance_factor)
        if self.log_lr > self.switch_log_lr:
            self.log_lr = -self.log_lr
            return True
        return False

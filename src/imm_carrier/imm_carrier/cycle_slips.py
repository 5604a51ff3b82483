"""Cycle-slip counting of a carrier tracker against truth (for benchmarks and integration tests)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CycleSlipCount:
    """Result of :func:`count_cycle_slips`.

    Attributes:
        count: number of slips (sum of |ambiguity changes|).
        slip_indices: sample indices where the ambiguity changed, shape (m,).
        ambiguity: integer ambiguity per sample (in slip periods, relative to the reference), shape (n,).
        phase_error_rad: estimate - truth - reference offset - ambiguity * period, rad, shape (n,);
            the residual tracking error.
        reference_offset_rad: the constant offset removed (initial ambiguity and phase offset), rad.
    """

    count: int
    slip_indices: np.ndarray
    ambiguity: np.ndarray
    phase_error_rad: np.ndarray
    reference_offset_rad: float


def count_cycle_slips(
    estimated_phase_rad: np.ndarray,
    true_phase_rad: np.ndarray,
    slip_period_rad: float = math.pi,
    hysteresis: float = 0.25,
    reference_samples: int = 50,
) -> CycleSlipCount:
    """Count the slips of an estimated carrier phase against the true phase.

    The error e_k = estimate - truth is referred to its circular mean (modulo the slip period) over
    the first ``reference_samples`` samples. The integer ambiguity m changes only when the error is
    more than (0.5 + hysteresis) periods away from m * period, so noise around a half-period does
    not count; each change adds |Delta m| slips.

    Args:
        estimated_phase_rad: tracker phase, rad, unwrapped, shape (n,). Non-finite samples are skipped.
        true_phase_rad: truth, rad, unwrapped, shape (n,).
        slip_period_rad: pi for half-cycle slips (Costas PLL, and the IMM with unknown bits), 2 pi for
            full cycles.
        hysteresis: fraction of a period, in [0, 0.5).
        reference_samples: samples used for the initial offset, >= 1.

    Returns:
        CycleSlipCount.
    """
    est = np.asarray(estimated_phase_rad, dtype=float)
    tru = np.asarray(true_phase_rad, dtype=float)
    if est.shape != tru.shape or est.ndim != 1 or est.size == 0:
        raise ValueError(
            "estimated_phase_rad and true_phase_rad must be non-empty 1-D arrays of the same shape"
        )
    if not (math.isfinite(slip_period_rad) and slip_period_rad > 0):
        raise ValueError("slip_period_rad must be finite and > 0")
    if not 0.0 <= hysteresis < 0.5:
        raise ValueError("hysteresis must be in [0, 0.5)")
    if reference_samples < 1:
        raise ValueError("reference_samples must be >= 1")
    err = est - tru
    ok = np.isfinite(err)
    if not np.any(ok):
        raise ValueError("no finite phase error")
    first = err[ok][:reference_samples]
    ang = first * (2.0 * math.pi / slip_period_rad)
    ref = (
        math.atan2(float(np.mean(np.sin(ang))), float(np.mean(np.cos(ang))))
        * slip_period_rad
        / (2.0 * math.pi)
    )
    ref += slip_period_rad * round((float(first[0]) - ref) / slip_period_rad)
    x = (err - ref) / slip_period_rad
    amb = np.zeros(err.size, dtype=np.int64)
    m = 0
    slips = []
    count = 0
    limit = 0.5 + hysteresis
    for k in range(err.size):
        if ok[k] and abs(x[k] - m) > limit:
            new = int(round(x[k]))
            count += abs(new - m)
            m = new
            slips.append(k)
        amb[k] = m
    residual = err - ref - amb * slip_period_rad
    return CycleSlipCount(
        count=count,
        slip_indices=np.asarray(slips, dtype=np.int64),
        ambiguity=amb,
        phase_error_rad=residual,
        reference_offset_rad=ref,
    )

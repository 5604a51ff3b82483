"""Receiver clock steps: finding them in an epoch's pseudoranges and moving the filter's clock by them.

Pure core (no rclpy); beyond Cao et al., whose clock model (eq. 2, 8-10) is a random walk of bias and
drift. Many receivers hold their clock within a millisecond by stepping it; a restart or re-steering
steps it by other amounts. :func:`receiver_clock_step` finds a step as the consensus of the clock-free
pseudorange innovations (:func:`clock_free_innovations`, shared with the common-mode screen of
:func:`.gnss_update.screen_common_mode`, which finds the step from the same innovations), and
:func:`apply_clock_step` moves the filter's clock bias by it before the GNSS update
(``receiver_clock_steps``).
"""

from __future__ import annotations

import math

import numpy as np

from gnss_common.constants import SPEED_OF_LIGHT_MPS

from .ckf import CubatureKalmanFilter
from .input_checks import Count, PreparedEpoch
from .measurement_models import pseudorange_model
from .robust_screen import common_mode_screen, projected_variance

CLOCK_STEP_MIN_SATELLITES = 5
"""Satellites that must agree on a common pseudorange step before it is taken for a receiver
clock step (:func:`receiver_clock_step`): the fault-detection minimum of RAIM, one more than the
unknowns. With four, coincident outliers were taken for steps under 30 dB J/S (simulated runs of
Cao et al.: four of seven satellites in bursts of 32-48 m while the predicted clock was within
0.3 m), and the 3D RMS of GNSS alone rose from 2.00 to 2.14 m on that run."""

MS_OF_LIGHT_M = SPEED_OF_LIGHT_MPS * 1.0e-3
"""The pseudorange step of a 1 ms receiver clock adjustment, m."""

CLOCK_STEP_MS_TOLERANCE_M = 1000.0
"""A clock step within this of a whole number of milliseconds (and within 3 sigma of it: the
predicted clock's and the consensus's) is taken as exactly that many (the usual receiver clock
adjustment), m."""

NO_CLOCK_STEP = (0.0, False, 0.0)
"""What :func:`receiver_clock_step` returns when it finds no step."""


def clock_free_innovations(
    prep: PreparedEpoch, nominal: np.ndarray, p: np.ndarray,
    bias_column: np.ndarray | None, error_column: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pseudorange innovations at the predicted state (eq. 5), their clock-free variances
    ``R_i + e_i^T P e_i`` (plus the inter-system bias and correlated-error variances of each
    satellite's states) and the unit lines of sight (:mod:`.robust_screen`)."""
    d = prep.sat_pos - nominal[None, 0:3]
    los = d / np.linalg.norm(d, axis=1)[:, None]
    hx = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column, error_column)
    nu = prep.pr - hx(nominal[None, :])[0]
    var = prep.sigma_pr**2 + projected_variance(los, p[0:3, 0:3])
    if error_column is not None:
        var = var + np.where(error_column >= 0, np.diag(p)[np.maximum(error_column, 0)], 0.0)
    if bias_column is not None:
        has = bias_column >= 0
        if has.any():
            var = var + np.where(has, np.diag(p)[np.where(has, bias_column, 0)], 0.0)
    return nu, var, los


def receiver_clock_step(
    prep: PreparedEpoch, nominal: np.ndarray, p: np.ndarray, gate_nis: float,
    bias_column: np.ndarray | None = None, error_column: np.ndarray | None = None,
) -> tuple[float, bool, float]:
    """A step of the receiver clock since the last epoch: every pseudorange moved by one amount
    that the predicted clock cannot explain (beyond the paper, whose clock model is eq. 2's random
    walk).

    Many receivers let their clock drift and hold it within a millisecond by stepping it, and
    the pseudoranges of every satellite jump by ``c`` x 1 ms (299,792.458 m) together; a receiver
    restart or re-steering steps it by other amounts. To the filter the step is an innovation
    common to all satellites and far outside the clock's predicted variance, so the gate rejects
    every pseudorange, divergence is declared and the position is rebuilt from scratch (measured
    on the real ESBC hour with a 1 ms step: 3D error up to 6.2 m for 10 epochs).

    Test: the consensus of the clock-free innovations (:func:`.robust_screen.common_mode_screen`,
    the same sets the screen keeps) holds at least :data:`CLOCK_STEP_MIN_SATELLITES` satellites and
    more than half of them, and its inverse-variance mean ``c`` fails the gate against the predicted
    clock: ``c^2 > g (P_cc + V_c + median R_i)`` (``P_cc`` the predicted clock variance, ``V_c = 1 /
    sum(1 / V_i)`` the variance of ``c`` from the clock-free variances ``V_i``, ``R_i`` the pseudorange
    variances of the consensus). The position's uncertainty is not in the test: it moves the
    innovations along each line of sight, not all of them by one amount. The ``median R_i`` term keeps
    the test from taking the ordinary wander of a clock whose variance is too small (white
    pseudorange errors that are in fact correlated make it so) for a step; the update follows that
    wander. Independent outliers do not agree with each other, so they cannot form such a
    consensus.

    Returns:
        ``(step_m, whole_ms, variance_m2)``: the step (0.0 when there is none), whether it is a whole number
        of milliseconds of light travel (within ``3 sqrt(P_cc + V_c)`` + 1 m and at most
        :data:`CLOCK_STEP_MS_TOLERANCE_M`), in which case ``step_m`` is that exact multiple and its
        variance 0, and otherwise the variance of ``c`` as the step, ``V_c + median R_i``.
    """
    nu, var, _ = clock_free_innovations(prep, nominal, p, bias_column, error_column)
    if nu.size < CLOCK_STEP_MIN_SATELLITES:
        return NO_CLOCK_STEP
    return clock_step_of_consensus(nu, var, common_mode_screen(nu, var, gate_nis), prep.sigma_pr, float(p[6, 6]),
                                    gate_nis)


def clock_step_of_consensus(nu: np.ndarray, var: np.ndarray, keep: np.ndarray, sigma_pr: np.ndarray,
                             p_cc: float, gate_nis: float) -> tuple[float, bool, float]:
    """:func:`receiver_clock_step` from the screen's innovations ``nu``, clock-free variances ``var``
    and consensus ``keep`` (shared with :func:`screen_common_mode`, which computes them anyway)."""
    k = int(np.count_nonzero(keep))
    if k < CLOCK_STEP_MIN_SATELLITES or 2 * k <= nu.size:
        return NO_CLOCK_STEP
    w = 1.0 / var[keep]
    w_sum = float(w.sum())
    v_c = 1.0 / w_sum
    c = float(w @ nu[keep]) * v_c
    if not math.isfinite(c) or c * c <= gate_nis * (p_cc + v_c):  # the common case, before the median
        return NO_CLOCK_STEP
    r_med = float(np.median(sigma_pr[keep] ** 2))
    if c * c <= gate_nis * (p_cc + v_c + r_med):
        return NO_CLOCK_STEP
    ms = round(c / MS_OF_LIGHT_M)
    tolerance_m = min(CLOCK_STEP_MS_TOLERANCE_M, 3.0 * math.sqrt(p_cc + v_c) + 1.0)
    if ms != 0 and abs(c - ms * MS_OF_LIGHT_M) <= tolerance_m:
        return ms * MS_OF_LIGHT_M, True, 0.0
    return c, False, v_c + r_med


def apply_clock_step(nominal: np.ndarray, ckf: CubatureKalmanFilter, step: tuple[float, bool, float],
                     count: Count) -> None:
    """``receiver_clock_steps``: move the clock bias ``nominal[6]`` by a step of the receiver clock
    (:func:`receiver_clock_step`, found with the common-mode screen) before the update. A whole number
    of milliseconds is a known adjustment: the clock keeps its variance (counted as
    ``receiver_clock_step_ms``); any other step moves it by the consensus's common innovation and adds
    that estimate's variance to the clock's (``receiver_clock_step``; resetting the clock block instead,
    as after a divergence, gave the same errors on the real stations of
    ``benchmarks/fusion_clock_steps.py``). Beyond the paper."""
    step_m, whole_ms, step_var = step
    if step_m == 0.0:
        return
    nominal[6] += step_m
    if whole_ms:
        count("receiver_clock_step_ms", 1)
        return
    count("receiver_clock_step", 1)
    ckf.p[6, 6] += step_var

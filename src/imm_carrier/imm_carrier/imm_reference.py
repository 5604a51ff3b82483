"""Generic N-mode IMM step with mode-matched EKFs: the readable numpy reference (test oracle).

The compiled two-mode filter of :mod:`imm_carrier.imm` must equal it to rounding (test_imm.py); it
is not used at run time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

MeasurementFunction = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""A mode's measurement model: x (n,) -> (predicted z (m,), Jacobian H (m, n))."""


def imm_step_reference(
    means: Sequence[np.ndarray],
    covariances: Sequence[np.ndarray],
    mode_probabilities: np.ndarray,
    transition: np.ndarray,
    f_matrix: np.ndarray,
    q_matrix: np.ndarray,
    measurement_models: Sequence[MeasurementFunction],
    r_matrix: np.ndarray,
    z: np.ndarray | None,
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Generic N-mode IMM step with mode-matched EKFs (numpy reference implementation).

    Args:
        means: per-mode posterior means at k-1, each shape (n,).
        covariances: per-mode posterior covariances, each shape (n, n).
        mode_probabilities: mu_{k-1}, shape (N,).
        transition: Markov matrix Pi[i, j] = P(mode j at k | mode i at k-1), shape (N, N).
        f_matrix: state transition F, shape (n, n) (shared by the modes).
        q_matrix: process noise W, shape (n, n).
        measurement_models: per-mode callables x -> (h(x) (m,), H (m, n)).
        r_matrix: measurement noise covariance, shape (m, m).
        z: measurement, shape (m,), or None for prediction only.

    Returns:
        (means, covariances, mode_probabilities, combined mean (n,), combined covariance (n, n)).

    Notes:
        Bar-Shalom, Li & Kirubarajan (2001), Section 11.6.6; Zhao et al., Fig. 2. Written for
        clarity (numpy matrix calls); the compiled filter must equal it.
    """
    n_modes = len(means)
    mu = np.asarray(mode_probabilities, dtype=float)
    pi = np.asarray(transition, dtype=float)
    c = pi.T @ mu
    mix = (pi * mu[:, None]) / c[None, :]  # mix[i, j] = mu_{i|j}
    new_means, new_covs, lik = [], [], np.zeros(n_modes)
    for j in range(n_modes):
        x0 = sum(mix[i, j] * means[i] for i in range(n_modes))
        p0 = sum(
            mix[i, j] * (covariances[i] + np.outer(means[i] - x0, means[i] - x0)) for i in range(n_modes)
        )
        x = f_matrix @ x0
        p = f_matrix @ p0 @ f_matrix.T + q_matrix
        if z is not None:
            zp, h = measurement_models[j](x)
            s = h @ p @ h.T + r_matrix
            k = p @ h.T @ np.linalg.inv(s)
            r = z - zp
            x = x + k @ r
            p = p - k @ s @ k.T
            lik[j] = math.exp(-0.5 * r @ np.linalg.solve(s, r)) / math.sqrt(np.linalg.det(2 * math.pi * s))
        else:
            lik[j] = 1.0
        new_means.append(x)
        new_covs.append(p)
    mu_new = lik * c / np.sum(lik * c)
    xc = sum(mu_new[j] * new_means[j] for j in range(n_modes))
    pc = sum(
        mu_new[j] * (new_covs[j] + np.outer(new_means[j] - xc, new_means[j] - xc)) for j in range(n_modes)
    )
    return new_means, new_covs, mu_new, xc, pc

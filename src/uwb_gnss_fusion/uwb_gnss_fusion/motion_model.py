"""Which motion model the GNSS filter runs: a stationarity detector with hysteresis (beyond the paper).

Pure core (no ROS, no clock: every decision is made on header-stamp times passed in).

The constant-velocity model of Cao et al. (eq. 8-10) is driven by a white acceleration of PSD
``accel_psd_m2ps3`` (0.1 m^2/s^3 by default, a slowly moving robot). On a static antenna that
model forgets the past at every epoch (900 m^2 of position variance per 30 s step), so the filter
gains little over single-point positioning. :class:`StationarityDetector` finds out from the data
whether the receiver stands still and switches the filter between two models:

* **moving**: the constant-velocity model with ``accel_psd_m2ps3``;
* **static**: the same transition with ``static_accel_psd_m2ps3``, entered with a zero-velocity
  pseudo-measurement ``v = 0`` of 1-sigma ``static_velocity_std_mps`` per axis
  (:func:`zero_velocity_update`; a ZUPT). The position then averages the epochs since the antenna
  was found static; the small acceleration noise lets the velocity (hence the position) wander by
  ``sqrt(q t)``, i.e. a memory of some tens of minutes, the correlation time of the broadcast
  models' residual errors (a memory of the whole static period averaged the errors of the first
  epochs into the last ones: 0.47 m instead of 0.41 m horizontal RMS on GEONET 0759).

Moving -> static (entry test, after every GNSS update in the moving model), two statistics:

* the positions ``p_i`` (covariances ``C_i``) of the current run of epochs, against a common
  position: ``D = sum_i (p_i - p_w)^T C_i^-1 (p_i - p_w)`` with ``p_w`` their weighted mean,
  chi-square with ``3 (N - 1)`` degrees of freedom for a static receiver and independent
  estimates (the moving model at 30 s forgets almost everything between epochs, so they nearly
  are; at high rates they are correlated, which makes ``D`` smaller, but a displacement of a few
  position sigmas over the run still shows). It sees motion without Doppler, where the moving
  model's velocity is not observed (a velocity 1-sigma near 1 m/s at 30 s epochs);
* where the velocity is observed (Doppler: ``sqrt(max eig P_v) <= STATIC_SPEED_STD_MAX_MPS``),
  also ``s = v^T P_v^-1 v``, chi-square with 3 degrees of freedom for a static receiver.

An epoch *passes* when ``D <= chi2_{3(N-1)}(1 - ENTRY_TEST_ALPHA)`` and, where it applies,
``s <= chi2_3(1 - ENTRY_TEST_ALPHA)``; a failing epoch starts a new run from itself. The model
becomes static when a run has lasted at least ``static_enter_s`` and :data:`ENTRY_MIN_EPOCHS`
epochs.

Static -> moving (exit test, at every GNSS epoch in the static model, on the *predicted*
innovations before the update): a generalised likelihood-ratio test of a displacement. The
pseudorange innovations ``nu = -L d + A b + e`` (``L`` the lines of sight, ``d`` the displacement
since the prediction, ``b`` one free common mode per system: the receiver clock and inter-system
biases, ``e ~ N(0, S)``, ``S = L P L^T + R`` with the predicted position covariance ``P`` and the
measurement variances ``R``), with ``M = W - W A (A^T W A)^-1 A^T W``, ``W = S^-1``, give the
displacement statistic ``T_d = nu^T M L (L^T M L)^-1 L^T M nu`` (chi-square, 3 dof, when the
receiver did not move) and the residual ``T_r = nu^T M nu - T_d`` (chi-square, ``n - k - 3`` dof);
the pseudorange-rate innovations likewise for a velocity change (the clock drift the only common
mode) (:func:`static_exit_statistic`). An epoch *fails* when, for the pseudoranges or the rates,
``T_d`` exceeds its ``1 - EXIT_TEST_ALPHA`` chi-square quantile *and* the F ratio
``(T_d / 3) / (T_r / dof_r)`` its F(3, dof_r) quantile: the displacement must stand out against
the residual, which makes the test blind to the scale of the measurement noise (under jamming the
noise exceeds the stated sigmas on every satellite and the chi-squares grow together). With a large
``T_r`` the worst measurement is left out once and both are recomputed (:func:`displacement_test`).
Testing the innovations' whole chi-square instead left the static model 28 times in 6 minutes on
every simulated 30 dB J/S run (benchmarks/fusion_never_worse.py, GNSS alone: 3.73 m 3D RMS against
2.39 m); the displacement chi-square alone, 20 times. A
failing epoch gets the moving model's process noise for its interval (the adaptive process noise:
the covariance is opened by ``Q_moving(dt) - Q_static(dt)`` before the update), so a receiver that
starts to move is followed from its first inconsistent epoch; :data:`EXIT_EPOCHS` consecutive
failing epochs switch to the moving model, with the position and velocity variances raised (on the
diagonal) to at least those of the moving model when the static one was entered. (Raising the
velocity's to ``init_velocity_std_mps^2`` as well followed a simulated start from rest at 1 m/s
better, 1.3 m instead of 3.1 m peak 3D error, but made every false exit under 30 dB J/S expensive:
2.9 m instead of 2.2 m 3D RMS, GNSS alone, 8 seeds; raising it to the velocity change the rates
fit diverged there, Doppler outliers of several m/s.) A UWB range ends a static period too (the detector watches GNSS
epochs only; with ranges at 10-50 Hz the moving model costs little).

False decisions, under the tests' own models (independent epochs):

* static declared while moving: with Doppler, each epoch passes with the probability that a
  non-central chi-square (3 dof, non-centrality ``u^2 / sigma_v^2`` for speed ``u`` along a
  direction of velocity 1-sigma ``sigma_v``) stays below ``chi2_3(0.999)`` = 16.3: 0.13 for
  ``u = 3 sigma_v``, 6e-4 for ``u = 5 sigma_v``. Without Doppler, three epochs 30 s apart along a
  straight line at speed ``u`` with 1 m position sigmas give ``D`` non-central with
  ``(30 u)^2 2 / 1 m^2``; 6 dof, ``chi2_6(0.999)`` = 22.5: ``u = 0.15 m/s`` passes with
  probability 0.2, ``u = 0.25 m/s`` with 1e-3. A slow mover declared static is caught by the exit
  test once its displacement shows in the pseudoranges.
* moving declared while static: ``EXIT_TEST_ALPHA^EXIT_EPOCHS`` = 1e-6 per epoch; a single
  failing epoch (probability 1e-3) costs one epoch of the moving model's process noise.

Real pseudorange errors are not white (slowly varying residual ionosphere, troposphere, orbit and
multipath), so the measured rates differ: benchmarks/fusion_real_gnss.py and fusion_multignss.py count
the decisions on real stations (``motion_static_entered``, ``motion_static_left``,
``motion_epoch_opened``): ARL1, GEONET 0759 and 3040 (one hour each) and ESBC00DNK (a whole day,
GPS alone to every system) are each found static once, early (ARL1 and GEONET at the fifth epoch),
and never left: no false exit, nor a single opened epoch, in about 3 x 116 + 4 x 2875 static epochs
at 30 s. The exit test's power is shown on simulated receivers instead
(benchmarks/fusion_motion_model.py: a receiver starting at 1 m/s after 120 s at rest leaves the
static model within two 5 Hz epochs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2
from scipy.stats import f as f_dist

from .input_checks import PreparedEpoch
from .measurement_models import pseudorange_model, pseudorange_rate_model

ENTRY_TEST_ALPHA = 1.0e-3
"""Per-epoch probability that the entry test fails on a static receiver (a run of passes restarts)."""
ENTRY_MIN_EPOCHS = 3
"""Consecutive passing GNSS epochs needed, besides ``static_enter_s``, to declare the receiver static."""
STATIC_SPEED_STD_MAX_MPS = 0.2
"""Largest velocity 1-sigma (any direction) with which the entry test may pass, m/s: below it a
speed of 1 m/s is a 5-sigma departure, rejected with probability 1 - 6e-4 per epoch."""
EXIT_TEST_ALPHA = 1.0e-3
"""Per-epoch probability that the exit test fails on a static receiver (white errors)."""
EXIT_EPOCHS = 2
"""Consecutive failing GNSS epochs that switch a static model back to the moving one."""
LEAVE_ONE_OUT_MIN_DOF = 3
"""Degrees of freedom the exit statistic must keep after its most inconsistent measurement is left out."""

_ENTRY_LIMIT = float(chi2.ppf(1.0 - ENTRY_TEST_ALPHA, 3))
_EXIT_LIMIT_3 = float(chi2.ppf(1.0 - EXIT_TEST_ALPHA, 3))


def entry_statistic(velocity_mps: np.ndarray, velocity_cov_m2ps2: np.ndarray) -> tuple[float, float]:
    """The entry test's ``(s, sigma_max)``: ``s = v^T P_v^-1 v`` (chi-square, 3 dof, for a static
    receiver) and the largest velocity 1-sigma ``sqrt(max eig P_v)``, m/s (``(inf, inf)`` when
    ``P_v`` is singular or not finite)."""
    v = np.asarray(velocity_mps, dtype=float)
    c = np.asarray(velocity_cov_m2ps2, dtype=float)
    try:
        lam = np.linalg.eigvalsh(0.5 * (c + c.T))
        if not (np.all(np.isfinite(lam)) and lam[0] > 0.0):
            return math.inf, math.inf
        return float(v @ np.linalg.solve(c, v)), math.sqrt(float(lam[-1]))
    except np.linalg.LinAlgError:
        return math.inf, math.inf


def _glrt(nu: np.ndarray, los: np.ndarray, s: np.ndarray, groups: np.ndarray
          ) -> tuple[float, float, int, np.ndarray, np.ndarray]:
    """Generalised likelihood ratio of a displacement: ``nu = L d + A b + e``, ``e ~ N(0, s)``, ``b``
    one free common mode per group. Returns (``T_d``: chi-square 3 dof of the fitted displacement,
    ``T_r``: the residual after it, its dof, the standardised post-fit residuals, the fitted ``L d``
    displacement (3,) along the lines of sight' sign: the receiver's is its negative)."""
    w = np.linalg.inv(s)
    values = np.unique(groups)
    a = (groups[:, None] == values[None, :]).astype(float)
    wa = w @ a
    m = w - wa @ np.linalg.solve(a.T @ wa, wa.T)  # common modes projected out
    ml = m @ los
    info = los.T @ ml  # information of the displacement
    g = ml.T @ nu
    d = np.linalg.solve(info, g)
    t_d = float(g @ d)
    t_all = float(nu @ m @ nu)
    dof_r = int(nu.size - values.size - 3)
    # post-fit residuals r = nu - L d (common modes free): M r standardised by the diagonal of M
    r = nu - los @ d
    mr = m @ r
    return t_d, max(t_all - t_d, 0.0), dof_r, mr / np.sqrt(np.maximum(np.diag(m), 1e-300)), d


def displacement_test(
    innovations: np.ndarray, lines_of_sight: np.ndarray, state_cov: np.ndarray, variances: np.ndarray,
    groups: np.ndarray,
) -> tuple[float, float, int, np.ndarray]:
    """Whether innovations whose common mode per group is unknown (clock, inter-system bias) show a
    displacement (of position, or of velocity for rates): the fitted displacement's chi-square (3 dof
    when static) and the residual chi-square after it, leaving out the measurement with the largest
    post-fit residual when at least ``LEAVE_ONE_OUT_MIN_DOF`` residual degrees remain.

    Args:
        innovations: (k,) innovations at the predicted state (m or m/s; NaN: not available).
        lines_of_sight: (k, 3) unit lines of sight.
        state_cov: (3, 3) predicted covariance of the state they see (position or velocity).
        variances: (k,) measurement variances (plus any per-measurement state variance).
        groups: (k,) integer group of each measurement (one unknown common mode per group).

    Returns:
        (displacement chi2 (3 dof), residual chi2, residual dof, the receiver's fitted displacement (3,),
        in the units of the innovations); (0.0, 0.0, -1, zeros) when the displacement is not determined
        (fewer than groups + 3 measurements).
    """
    nu = np.asarray(innovations, dtype=float)
    g = np.asarray(groups)
    keep = np.isfinite(nu)
    nu, los, var, g = nu[keep], np.asarray(lines_of_sight)[keep], np.asarray(variances, float)[keep], g[keep]
    if nu.size - np.unique(g).size < 3:
        return 0.0, 0.0, -1, np.zeros(3)
    s = los @ state_cov @ los.T + np.diag(var)
    try:
        t_d, t_r, dof_r, std_res, d = _glrt(nu, los, s, g)
        if dof_r - 1 >= LEAVE_ONE_OUT_MIN_DOF and t_r > float(chi2.ppf(1.0 - EXIT_TEST_ALPHA, dof_r)):
            rest = np.ones(nu.size, dtype=bool)
            rest[int(np.argmax(np.abs(std_res)))] = False
            if nu.size - 1 - np.unique(g[rest]).size - 3 >= LEAVE_ONE_OUT_MIN_DOF:
                t_d, t_r, dof_r, _, d = _glrt(nu[rest], los[rest], s[np.ix_(rest, rest)], g[rest])
    except np.linalg.LinAlgError:
        return 0.0, 0.0, -1, np.zeros(3)
    # nu = rho_measured - rho_predicted; a receiver displaced by x shortens each range by e . x
    return t_d, t_r, dof_r, -d


def static_exit_statistic(
    prep: PreparedEpoch, nominal: np.ndarray, p: np.ndarray,
    bias_column: np.ndarray | None, error_column: np.ndarray | None,
) -> list[tuple[float, float, int, np.ndarray]]:
    """The exit test's statistics on an epoch at the predicted state: :func:`displacement_test` of the
    pseudorange innovations (common mode per system removed; a position displacement) and of the
    pseudorange-rate innovations (clock drift removed; a velocity), one ``(T_d, T_r, dof_r, displacement)``
    each (position in m, velocity in m/s).

    Args:
        prep: the epoch's satellites (rates NaN where not applied).
        nominal: predicted nominal state, (n,).
        p: predicted error covariance, (n, n).
        bias_column / error_column: the inter-system bias and correlated-error columns of each
            satellite (as :func:`.measurement_models.pseudorange_model`), or None.

    Returns:
        the testable parts (empty: nothing testable), pseudoranges first.

    Notes:
        Cao et al., eq. 5 and 6 for the predicted measurements.
    """
    x = nominal[None, :]
    d = prep.sat_pos - nominal[None, 0:3]
    los = d / np.linalg.norm(d, axis=1)[:, None]
    nu = prep.pr - pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column,
                                     error_column)(x)[0]
    var = prep.sigma_pr**2
    if error_column is not None:
        var = var + np.where(error_column >= 0, np.diag(p)[np.maximum(error_column, 0)], 0.0)
    groups = np.zeros(nu.size, dtype=np.int64) if bias_column is None else np.asarray(bias_column)
    out = []
    parts = [(nu, p[0:3, 0:3], var, groups)]
    if np.isfinite(prep.rate).sum() >= 4:
        rate_hat = pseudorange_rate_model(prep.sat_pos, prep.sat_vel, prep.sat_drift)(x)[0]
        parts.append((prep.rate - rate_hat, p[3:6, 3:6], prep.sigma_rate**2, np.zeros(nu.size, dtype=np.int64)))
    for innov, cov, v, grp in parts:
        a, b, k, disp = displacement_test(innov, los, cov, v, grp)
        if k >= 0:
            out.append((a, b, k, disp))
    return out


def zero_velocity_update(p: np.ndarray, velocity_mps: np.ndarray, std_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """A zero-velocity pseudo-measurement ``0 = v + w``, ``w ~ N(0, std^2 I3)``, on an error state
    whose velocity block is columns 3:6.

    Args:
        p: error covariance, (n, n).
        velocity_mps: the nominal velocity, (3,), m/s.
        std_mps: 1-sigma of the pseudo-measurement per axis, m/s, > 0.

    Returns:
        (error-state correction dx (n,), updated covariance (n, n), Joseph form).

    Notes:
        A linear Kalman update (Brown & Hwang, 4th ed., eq. 4.2.8-4.2.11); the CKF of Cao et al.
        (eq. 17-24) gives the same on a linear measurement.
    """
    n = p.shape[0]
    h = np.zeros((3, n))
    h[:, 3:6] = np.eye(3)
    r = np.eye(3) * std_mps**2
    s = p[3:6, 3:6] + r
    k = np.linalg.solve(s, p[3:6, :]).T  # P H^T S^-1 (S symmetric)
    dx = k @ (-np.asarray(velocity_mps, dtype=float))
    ikh = np.eye(n) - k @ h
    p_new = ikh @ p @ ikh.T + k @ r @ k.T
    return dx, 0.5 * (p_new + p_new.T)


@dataclass
class MotionDecision:
    """What the filter does at a GNSS epoch in the static model: ``open_covariance``: add the moving
    model's process noise for this interval before the update (the epoch failed the exit test);
    ``left_static``: the model is moving from this epoch on."""

    open_covariance: bool
    left_static: bool


class StationarityDetector:
    """The moving/static decision with hysteresis (module docstring).

    Args:
        enter_s: ``static_enter_s``, how long every GNSS epoch must pass the entry test, s (>= 0).

    Example:
        >>> d = StationarityDetector(enter_s=10.0)
        >>> for k in range(4):
        ...     _ = d.observe_moving(k * 5_000_000_000, np.zeros(3), np.eye(3), np.zeros(3), np.eye(3) * 0.01)
        >>> d.static
        True
    """

    def __init__(self, enter_s: float) -> None:
        if not (math.isfinite(enter_s) and enter_s >= 0.0):
            raise ValueError(f"enter_s must be finite and >= 0, got {enter_s!r}")
        self._enter_ns = int(round(enter_s * 1e9))
        self.reset()

    def reset(self) -> None:
        """Back to the moving model, no evidence (a (re)initialisation, a time gap, a UWB range)."""
        self.static = False
        self._new_run()
        self._fails = 0
        self.last_statistic = math.nan
        self.last_dof = 0

    def _new_run(self) -> None:
        self._run_since_ns: int | None = None
        self._run_epochs = 0
        self._origin = np.zeros(3)
        self._sum_w = np.zeros((3, 3))
        self._sum_wp = np.zeros(3)
        self._sum_pwp = 0.0

    def _add_to_run(self, stamp_ns: int, position_m: np.ndarray, position_cov_m2: np.ndarray) -> float:
        """Add an epoch to the run; return the run's ``D`` (chi-square with 3 (N - 1) dof)."""
        if self._run_since_ns is None:
            self._run_since_ns = int(stamp_ns)
            self._origin = np.asarray(position_m, dtype=float).copy()
        d = np.asarray(position_m, dtype=float) - self._origin  # metres from the run's first epoch
        w = np.linalg.inv(position_cov_m2)
        self._sum_w += w
        self._sum_wp += w @ d
        self._sum_pwp += float(d @ w @ d)
        self._run_epochs += 1
        return max(self._sum_pwp - float(self._sum_wp @ np.linalg.solve(self._sum_w, self._sum_wp)), 0.0)

    def observe_moving(self, stamp_ns: int, position_m: np.ndarray, position_cov_m2: np.ndarray,
                       velocity_mps: np.ndarray, velocity_cov_m2ps2: np.ndarray) -> bool:
        """Entry test after a GNSS update in the moving model (ECEF or any Cartesian frame, m, m/s, with
        their (3, 3) covariances); True when the model becomes static."""
        try:
            dev = self._add_to_run(stamp_ns, position_m, position_cov_m2)
        except np.linalg.LinAlgError:
            self._new_run()
            return False
        dof = 3 * (self._run_epochs - 1)
        ok = dof == 0 or dev <= float(chi2.ppf(1.0 - ENTRY_TEST_ALPHA, dof))
        s, sigma = entry_statistic(velocity_mps, velocity_cov_m2ps2)
        if sigma <= STATIC_SPEED_STD_MAX_MPS:
            ok = ok and s <= _ENTRY_LIMIT
        self.last_statistic, self.last_dof = dev, dof
        if not ok:
            self._new_run()
            self._add_to_run(stamp_ns, position_m, position_cov_m2)
            return False
        assert self._run_since_ns is not None
        if self._run_epochs >= ENTRY_MIN_EPOCHS and stamp_ns - self._run_since_ns >= self._enter_ns:
            self.static = True
            self._fails = 0
            self._new_run()
            return True
        return False

    def observe_static(self, parts: list[tuple[float, float, int, np.ndarray]]) -> MotionDecision:
        """Exit test on a GNSS epoch's predicted innovations in the static model: ``parts`` as
        :func:`static_exit_statistic` returns them. The epoch fails when in some part the fitted
        displacement is significant (``T_d`` above the 3-dof chi-square quantile) and large against the
        residual (``(T_d / 3) / (T_r / dof_r)`` above the F(3, dof_r) quantile; the chi-square quantile of
        ``T_r`` with ``dof_r`` 0): a displacement that explains the innovations, whatever the scale of the
        measurement noise."""
        moved = False
        for t_d, t_r, dof_r, _ in parts:
            self.last_statistic, self.last_dof = t_d, 3
            if t_d <= _EXIT_LIMIT_3:
                continue
            limit = float(f_dist.ppf(1.0 - EXIT_TEST_ALPHA, 3, dof_r)) if dof_r > 0 else 0.0
            if dof_r <= 0 or (t_d / 3.0) / max(t_r / dof_r, 1e-300) > limit:
                moved = True
        if not moved:
            self._fails = 0
            return MotionDecision(False, False)
        self._fails += 1
        if self._fails >= EXIT_EPOCHS:
            self.reset()
            return MotionDecision(True, True)
        return MotionDecision(True, False)

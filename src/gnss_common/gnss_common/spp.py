"""Single-point positioning (SPP): weighted least squares per epoch with RAIM-like FDE.

Pure core (no rclpy): :class:`SinglePointPositioner.process` takes a
:class:`gnss_common.observations.GnssEpoch` (time from ``epoch.stamp_ns``, integer ns, ROS (UTC)
time; GPS week / time of week in the epoch) and returns a frozen :class:`SppResult`. It is the
GNSS-only baseline of Cao et al. (sec. IV, "GNSS SPP") and the initialiser of their tightly coupled filter.

Model (Cao et al., eq. 5 and 6), GPS satellites only, one receiver clock::

    P_i + c dt_i - I_i - T_i = |R3(w tau_i) p_i - p_r| + c dt_r + e_i
    rate_i + c ddt_i - (R3(w tau_i) v_i) . u_i = -v_r . u_i + c ddt_r + e'_i

with u_i the receiver-to-satellite unit vector and R3(w tau) the Earth-rotation (Sagnac)
correction over the signal travel time tau (IS-GPS-200, 20.3.3.4.3.3.2).

Weights: sigma_i^2 = [a^2 + b^2 / sin^2(el_i)] k_cn0 + (f_I I_i)^2 + (s_T / (sin el_i + 0.1))^2
+ sigma_eph^2, with k_cn0 = max(1, 10^((cn0_ref - cn0_i) / 10)) when C/N0 is known -- the
RTKLIB ``varerr`` model (Takasu, RTKLIB 2.4.2 manual, E.6) extended with the C/N0 factor of
the sigma-epsilon family (Hartinger & Brunner 1999). A finite ``pseudorange_std_m`` in the
measurement overrides the model.

Fault detection and exclusion: chi-square test of the weighted residual sum of squares with
n - 4 degrees of freedom at false-alarm probability p_fa; on failure the satellite with the
largest standardised residual |r_i| / sqrt((R - H (H^T W H)^-1 H^T)_ii) (Baarda's w-test) is
excluded and the fix recomputed, while at least 5 satellites remain (Kaplan & Hegarty, 3rd ed.,
sec. 11.5; Brown 1992 "A baseline GPS RAIM scheme").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from gnss_common.constants import WGS84_ECCENTRICITY_SQUARED, WGS84_SEMI_MAJOR_AXIS_M
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic_scalar
from gnss_common.earth_rotation import rotate_about_z, sagnac_rotate
from gnss_common.observations import GnssEpoch
from gnss_common.positioning import CONVERGED, SINGULAR, least_squares_position, weighted_least_squares
from gnss_common.spp_screening import ScreenedEpoch, screen_epoch

STATUS_OK = "ok"
STATUS_OK_WITH_EXCLUSIONS = "ok_with_exclusions"
STATUS_TOO_FEW = "too_few_satellites"
STATUS_SINGULAR = "singular_geometry"
STATUS_NOT_CONVERGED = "not_converged"
STATUS_RAIM_FAILED = "raim_failed"

REJECTION_REASONS = (
    "unsupported_constellation",
    "invalid_input",
    "non_physical",
    "duplicate_svid",
    "below_elevation_mask",
    "outlier",
)
"""Keys of :attr:`SppResult.rejection_counts`."""

_MAX_DOF_TABLE = 64
_NEAR_SURFACE_R_M = 0.9 * WGS84_SEMI_MAJOR_AXIS_M * math.sqrt(1.0 - WGS84_ECCENTRICITY_SQUARED)


@dataclass(frozen=True)
class SppParams:
    """Validated SPP parameters.

    Attributes:
        elevation_mask_deg: satellites below this elevation are rejected, deg, in [-10, 60).
        max_iterations: Gauss-Newton iteration cap, >= 2.
        convergence_m: stop when the position/clock step is below this, m, > 0.
        sigma_code_a_m: elevation-independent code sigma a, m, >= 0.
        sigma_code_b_m: elevation-dependent code sigma b (b / sin el), m, >= 0.
        cn0_reference_dbhz: C/N0 at or above which no C/N0 inflation applies, dB-Hz.
        use_cn0_weighting: apply the C/N0 factor when C/N0 is finite.
        iono_error_fraction: 1-sigma Klobuchar residual as a fraction of the delay (0.5: RTKLIB).
        sigma_tropo_zenith_m: zenith troposphere model error, m (0.3: RTKLIB).
        sigma_broadcast_m: broadcast orbit+clock error (SISRE), m.
        sigma_rate_mps: pseudorange-rate sigma at zenith and reference C/N0, m/s, > 0.
        raim_false_alarm_probability: chi-square test p_fa in (0, 0.5).
        max_exclusions: maximum satellites excluded per epoch by FDE, >= 0.
        min_satellites_for_exclusion: FDE excludes only while at least this many remain
            after exclusion, >= 5 (5 keeps detection possible).
    """

    elevation_mask_deg: float = 10.0
    max_iterations: int = 10
    convergence_m: float = 1.0e-4
    sigma_code_a_m: float = 0.3
    sigma_code_b_m: float = 0.3
    cn0_reference_dbhz: float = 45.0
    use_cn0_weighting: bool = True
    iono_error_fraction: float = 0.5
    sigma_tropo_zenith_m: float = 0.3
    sigma_broadcast_m: float = 1.0
    sigma_rate_mps: float = 0.1
    raim_false_alarm_probability: float = 1.0e-3
    max_exclusions: int = 3
    min_satellites_for_exclusion: int = 5

    def __post_init__(self) -> None:
        def finite(name: str) -> float:
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"SppParams.{name} must be a finite number, got {v!r}")
            return float(v)

        if not -10.0 <= finite("elevation_mask_deg") < 60.0:
            raise ValueError(
                f"SppParams.elevation_mask_deg must be in [-10, 60), got {self.elevation_mask_deg}"
            )
        if not isinstance(self.max_iterations, int) or self.max_iterations < 2:
            raise ValueError(f"SppParams.max_iterations must be an int >= 2, got {self.max_iterations!r}")
        if finite("convergence_m") <= 0.0:
            raise ValueError(f"SppParams.convergence_m must be > 0, got {self.convergence_m}")
        for name in (
            "sigma_code_a_m",
            "sigma_code_b_m",
            "iono_error_fraction",
            "sigma_tropo_zenith_m",
            "sigma_broadcast_m",
        ):
            if finite(name) < 0.0:
                raise ValueError(f"SppParams.{name} must be >= 0, got {getattr(self, name)}")
        if self.sigma_code_a_m + self.sigma_code_b_m + self.sigma_broadcast_m <= 0.0:
            raise ValueError(
                "SppParams: at least one of sigma_code_a_m, sigma_code_b_m, sigma_broadcast_m must be > 0"
            )
        if finite("sigma_rate_mps") <= 0.0:
            raise ValueError(f"SppParams.sigma_rate_mps must be > 0, got {self.sigma_rate_mps}")
        if not 0.0 <= finite("cn0_reference_dbhz") <= 70.0:
            raise ValueError(
                f"SppParams.cn0_reference_dbhz must be in [0, 70], got {self.cn0_reference_dbhz}"
            )
        if not 0.0 < finite("raim_false_alarm_probability") < 0.5:
            raise ValueError(
                "SppParams.raim_false_alarm_probability must be in (0, 0.5), got "
                f"{self.raim_false_alarm_probability}"
            )
        if not isinstance(self.max_exclusions, int) or self.max_exclusions < 0:
            raise ValueError(f"SppParams.max_exclusions must be an int >= 0, got {self.max_exclusions!r}")
        if not isinstance(self.min_satellites_for_exclusion, int) or self.min_satellites_for_exclusion < 5:
            raise ValueError(
                "SppParams.min_satellites_for_exclusion must be an int >= 5, got "
                f"{self.min_satellites_for_exclusion!r}"
            )


@dataclass(frozen=True)
class Dop:
    """Dilution of precision (unweighted geometry, ENU at the solution). NaN when undefined."""

    gdop: float
    pdop: float
    hdop: float
    vdop: float
    tdop: float


_NAN_DOP = Dop(math.nan, math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class SppResult:
    """One epoch's SPP output.

    Attributes:
        stamp_ns: the epoch's stamp, ns (copied from the input).
        valid: True only for a converged, RAIM-consistent fix; then position, clock and
            covariance are finite. When False, ``position_ecef_m`` may hold the last iterate
            (``raim_failed``, ``not_converged``) or NaN (``too_few_satellites``,
            ``singular_geometry``) and must not be used as a fix.
        status: one of ``ok``, ``ok_with_exclusions``, ``too_few_satellites``,
            ``singular_geometry``, ``not_converged``, ``raim_failed``.
        position_ecef_m: receiver ECEF position, m, (3,).
        clock_bias_m: receiver clock bias c dt_r, m.
        velocity_valid: True when a velocity was estimated from >= 4 pseudorange rates.
        velocity_ecef_mps: receiver ECEF velocity, m/s, (3,) (NaN if not velocity_valid).
        clock_drift_mps: receiver clock drift c ddt_r, m/s (NaN if not velocity_valid).
        covariance: (4, 4) covariance of [x, y, z, c dt_r], m^2, row-major, ECEF axes.
        covariance_enu_m2: (3, 3) position covariance rotated to local ENU, m^2.
        velocity_covariance: (4, 4) covariance of [vx, vy, vz, c ddt_r], (m/s)^2.
        dop: :class:`Dop` of the used satellites.
        used_svids: GPS PRNs in the fix, ascending.
        rejected: ``(svid, reason)`` pairs, reasons from ``REJECTION_REASONS``.
        rejection_counts: reason -> count for this epoch (every key present).
        residuals_m: post-fit pseudorange residuals of ``used_svids``, m.
        elevations_rad: elevations of ``used_svids`` at the solution, rad.
        iterations: Gauss-Newton iterations of the final fix.
        test_statistic: weighted SSE of the final fix (chi-square with n - 4 dof), NaN if n = 4.
        test_threshold: chi-square threshold used, NaN if n = 4.
    """

    stamp_ns: int
    valid: bool
    status: str
    position_ecef_m: np.ndarray
    clock_bias_m: float
    velocity_valid: bool
    velocity_ecef_mps: np.ndarray
    clock_drift_mps: float
    covariance: np.ndarray
    covariance_enu_m2: np.ndarray
    velocity_covariance: np.ndarray
    dop: Dop
    used_svids: tuple[int, ...]
    rejected: tuple[tuple[int, str], ...]
    rejection_counts: dict[str, int]
    residuals_m: np.ndarray
    elevations_rad: np.ndarray
    iterations: int
    test_statistic: float
    test_threshold: float
    extra: dict[str, float] = field(default_factory=dict)


def code_variance_m2(params: SppParams, sin_el: np.ndarray, cn0_dbhz: np.ndarray | None, iono_m: np.ndarray,
                     sigma_broadcast_m: np.ndarray | float, k_cn0: np.ndarray | None = None) -> np.ndarray:
    """Pseudorange error variance of the RTKLIB ``varerr`` model with the C/N0 factor, m^2, (n,).

    ``[a^2 + b^2 / sin^2 el] k_cn0 + (f_I I)^2 + (s_T / (sin el + 0.1))^2 + s_eph^2`` with the fields of
    ``params``, sin el floored at 0.05, the modelled ionospheric delay ``iono_m`` (m) and the SISRE
    ``sigma_broadcast_m`` (m, scalar or (n,)); the weights of this module's fix and of ``multi_gnss_fix``
    (Takasu, RTKLIB 2.4.2 manual, E.6; ``k_cn0 = max(1, 10^((cn0_ref - cn0) / 10))``, Hartinger &
    Brunner 1999; ``k_cn0`` when already computed, :func:`cn0_factor` of ``cn0_dbhz``).
    """
    s_el = np.maximum(sin_el, 0.05)
    return (code_noise_variance_m2(params, sin_el, cn0_dbhz, k_cn0) + (params.iono_error_fraction * iono_m) ** 2
            + (params.sigma_tropo_zenith_m / (s_el + 0.1)) ** 2 + np.asarray(sigma_broadcast_m, dtype=float) ** 2)


def code_noise_variance_m2(params: SppParams, sin_el: np.ndarray, cn0_dbhz: np.ndarray | None,
                           k_cn0: np.ndarray | None = None) -> np.ndarray:
    """The white (code noise, fast multipath) term ``[a^2 + b^2 / sin^2 el] k_cn0`` of
    :func:`code_variance_m2`, m^2, (n,) (``k_cn0``: :func:`cn0_factor` of ``cn0_dbhz`` if already computed)."""
    k = cn0_factor(params, np.asarray(cn0_dbhz, dtype=float)) if k_cn0 is None else k_cn0
    return (params.sigma_code_a_m**2 + (params.sigma_code_b_m / np.maximum(sin_el, 0.05)) ** 2) * k


def cn0_factor(params: SppParams, cn0_dbhz: np.ndarray) -> np.ndarray:
    """C/N0 variance factor ``max(1, 10^((cn0_ref - cn0) / 10))`` (1 where C/N0 is NaN or unused), (n,)."""
    cn0 = np.asarray(cn0_dbhz, dtype=float)
    if not params.use_cn0_weighting:
        return np.ones(cn0.shape)
    with np.errstate(invalid="ignore"):
        f = np.maximum(1.0, 10.0 ** ((params.cn0_reference_dbhz - cn0) / 10.0))
    return np.where(np.isfinite(f), f, 1.0)


def _geodetic_up_and_rotation(pos: np.ndarray) -> np.ndarray:
    """ECEF->ENU rotation at a near-surface ECEF point (row 2: the local up)."""
    lat, lon, _ = ecef_to_geodetic_scalar(float(pos[0]), float(pos[1]), float(pos[2]))
    return ecef_to_enu_rotation(lat, lon)


@dataclass(frozen=True)
class _PositionFix:
    """One weighted least-squares position solution of :meth:`SinglePointPositioner._solve_position`.

    Attributes:
        status: ``ok``, ``not_converged``, ``too_few_satellites`` or ``singular_geometry``; the
            arrays below are empty (shape 0) unless ``ok`` or ``not_converged``.
        below_mask: satellites (all N, not only the active ones) below the elevation mask at a
            converged solution, bool (N,).
        iterations: Gauss-Newton iterations.
        x: ``[x, y, z, c dt]``, m, (4,).
        covariance: ``(H^T W H)^-1``, m^2, (4, 4).
        h: design matrix at the solution, (n_active, 4).
        residuals_m: post-fit residuals of the active satellites, m.
        sse: weighted sum of squared residuals (chi-square with n - 4 dof).
        standardised_residuals: ``r_i / sqrt(Qr_ii)`` (Baarda's w-test statistics).
        enu_rotation: ECEF->ENU rotation at the solution, (3, 3); None far from the surface.
        el_all: elevations, rad, (N,) (NaN for inactive satellites).
        los_all: receiver-to-satellite unit vectors, (N, 3) (NaN for inactive satellites).
        scale_all: C/N0 and elevation factor of the sigmas, (N,) (NaN for inactive satellites).
    """

    status: str
    below_mask: np.ndarray
    iterations: int
    x: np.ndarray = field(default_factory=lambda: np.full(4, math.nan))
    covariance: np.ndarray = field(default_factory=lambda: np.full((4, 4), math.nan))
    h: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    residuals_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sse: float = math.nan
    standardised_residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    enu_rotation: np.ndarray | None = None
    el_all: np.ndarray = field(default_factory=lambda: np.zeros(0))
    los_all: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    scale_all: np.ndarray = field(default_factory=lambda: np.zeros(0))


class SinglePointPositioner:
    """Epoch-by-epoch GPS single-point positioning (stateless except for the initial guess).

    The last valid position seeds the next epoch's iteration (this changes only the number of
    iterations, not the fix beyond ``convergence_m``). ``totals`` accumulates rejection counts.
    """

    def __init__(self, params: SppParams | None = None) -> None:
        """Args: params: :class:`SppParams` (defaults if None)."""
        self.params = params if params is not None else SppParams()
        dof = np.arange(1, _MAX_DOF_TABLE + 1)
        self._chi2_threshold = chi2.isf(self.params.raim_false_alarm_probability, dof)
        self._last_position: np.ndarray | None = None
        self.totals: dict[str, int] = dict.fromkeys(REJECTION_REASONS, 0)
        self.totals["epochs"] = 0
        self.totals["valid_epochs"] = 0

    def reset(self) -> None:
        """Forget the initial guess and the totals."""
        self._last_position = None
        self.totals = dict.fromkeys(self.totals, 0)

    def _threshold(self, dof: int) -> float:
        if dof <= 0:
            return math.nan
        if dof <= _MAX_DOF_TABLE:
            return float(self._chi2_threshold[dof - 1])
        return float(chi2.isf(self.params.raim_false_alarm_probability, dof))

    # ------------------------------------------------------------------------------------------
    def process(self, epoch: GnssEpoch, initial_position_ecef_m: np.ndarray | None = None) -> SppResult:
        """Solve one epoch.

        Args:
            epoch: measurements of one receive epoch (GPS satellites are used; others rejected).
            initial_position_ecef_m: optional starting point, m, (3,); default: last valid fix,
                else the Earth's centre.

        Returns:
            :class:`SppResult` (never raises on bad measurement content; see ``status``).

        Raises:
            TypeError: ``epoch`` is not a GnssEpoch.

        Notes
        -----
        Cao et al., eq. 5 (position/clock) and eq. 6 (velocity/drift), linearised and solved by
        iterated weighted least squares; see the module docstring for weights and FDE.
        """
        if not isinstance(epoch, GnssEpoch):
            raise TypeError(f"epoch must be a GnssEpoch, got {type(epoch).__name__}")
        p = self.params
        counts = dict.fromkeys(REJECTION_REASONS, 0)
        rejected: list[tuple[int, str]] = []

        def reject(svid: int, reason: str) -> None:
            counts[reason] += 1
            rejected.append((int(svid), reason))

        m = screen_epoch(epoch, reject)
        extra = {"missing_corrections": float(m.missing_corrections)}
        svids, sat_pos, sat_vel, rate_corr, rate_std = m.svids, m.sat_pos, m.sat_vel, m.rate_corr, m.rate_std

        if initial_position_ecef_m is not None:
            x0 = np.asarray(initial_position_ecef_m, dtype=float).reshape(3)
            if not np.all(np.isfinite(x0)):
                raise ValueError("initial_position_ecef_m must be finite")
        elif self._last_position is not None:
            x0 = self._last_position
        else:
            x0 = np.zeros(3)

        sol, status, active, exclusions = self._solve_with_fde(m, x0, reject)
        used = np.flatnonzero(active)
        self.totals["epochs"] += 1
        for reason, count in counts.items():
            self.totals[reason] += count
        if status in (STATUS_TOO_FEW, STATUS_SINGULAR):
            return _no_solution(epoch.stamp_ns, status, svids[used], tuple(rejected), counts, sol.iterations, extra)

        x = sol.x
        valid = status == STATUS_OK
        if valid and exclusions > 0:
            status = STATUS_OK_WITH_EXCLUSIONS
        if valid:
            self._last_position = x[:3].copy()
            self.totals["valid_epochs"] += 1
        dof = used.size - 4
        rot = sol.enu_rotation
        cov = sol.covariance
        cov_enu = rot @ cov[:3, :3] @ rot.T if rot is not None else np.full((3, 3), math.nan)
        dop = _dop(sol.h, rot)

        # ---- velocity and clock drift (eq. 6) -----------------------------------------------
        vel_valid = False
        v = np.full(3, math.nan)
        drift = math.nan
        vcov = np.full((4, 4), math.nan)
        if valid:
            solved = _velocity(sol, used, x[:3], sat_pos, sat_vel, rate_corr, rate_std, p.sigma_rate_mps)
            if solved is not None:
                v, drift, vcov = solved
                vel_valid = True

        return SppResult(
            stamp_ns=epoch.stamp_ns,
            valid=valid,
            status=status,
            position_ecef_m=x[:3].copy(),
            clock_bias_m=float(x[3]),
            velocity_valid=vel_valid,
            velocity_ecef_mps=np.asarray(v, dtype=float),
            clock_drift_mps=drift,
            covariance=cov,
            covariance_enu_m2=cov_enu,
            velocity_covariance=vcov,
            dop=dop,
            used_svids=tuple(int(s) for s in svids[used]),
            rejected=tuple(rejected),
            rejection_counts=counts,
            residuals_m=sol.residuals_m,
            elevations_rad=sol.el_all[used],
            iterations=sol.iterations,
            test_statistic=float(sol.sse) if dof > 0 else math.nan,
            test_threshold=self._threshold(dof) if dof > 0 else math.nan,
            extra=extra,
        )

    def _solve_with_fde(self, m: ScreenedEpoch, x0: np.ndarray, reject: Callable[[int, str], None]):
        """The position solution with the elevation mask and fault detection and exclusion (module docstring):
        (the last solution, its status, the satellites used, the number excluded as outliers)."""
        p = self.params
        n, svids, sat_pos = m.n, m.svids, m.sat_pos
        active = np.ones(n, dtype=bool)
        exclusions = 0
        mask_rad = math.radians(p.elevation_mask_deg)
        if n > 0 and float(np.linalg.norm(x0)) > _NEAR_SURFACE_R_M:
            # Elevation mask from the starting point (the previous fix); re-checked at convergence.
            rs = sagnac_rotate(sat_pos, x0)[0]
            d = rs - x0
            sin_el0 = (d @ _geodetic_up_and_rotation(x0)[2]) / np.sqrt(np.sum(d * d, axis=1))
            below0 = sin_el0 < math.sin(mask_rad)
            for i in np.flatnonzero(below0):
                reject(int(svids[i]), "below_elevation_mask")
            active &= ~below0
        while True:
            sol = self._solve_position(sat_pos, m.y_corr, m.cn0, m.iono_m, m.pr_std, active, x0, mask_rad)
            status = sol.status
            below = sol.below_mask
            if np.any(below):
                for i in np.flatnonzero(below):
                    reject(int(svids[i]), "below_elevation_mask")
                active &= ~below
                if status == STATUS_OK:
                    # re-solve without the masked satellites (the mask can only shrink the set)
                    continue
            if status != STATUS_OK:
                break
            used = np.flatnonzero(active)
            dof = used.size - 4
            if dof <= 0:
                break
            t = sol.sse
            thr = self._threshold(dof)
            if t <= thr:
                break
            # FDE: exclude the largest standardised residual while enough satellites remain
            if exclusions >= p.max_exclusions or used.size - 1 < p.min_satellites_for_exclusion:
                status = STATUS_RAIM_FAILED
                break
            worst = used[int(np.argmax(np.abs(sol.standardised_residuals)))]
            reject(int(svids[worst]), "outlier")
            active[worst] = False
            exclusions += 1
            x0 = sol.x[:3]

        return sol, status, active, exclusions

    # ------------------------------------------------------------------------------------------
    def _solve_position(
        self,
        sat_pos: np.ndarray,
        y_corr: np.ndarray,
        cn0: np.ndarray,
        iono_m: np.ndarray,
        pr_std: np.ndarray,
        active: np.ndarray,
        x0: np.ndarray,
        mask_rad: float,
    ) -> _PositionFix:
        """Iterated WLS for [x, y, z, c dt] on the active satellites (see module docstring).

        Notes
        -----
        Cao et al., eq. 5 linearised, solved by :func:`gnss_common.positioning.least_squares_position`
        with the range rotated by :func:`gnss_common.earth_rotation.sagnac_rotate`.
        """
        p = self.params
        n = sat_pos.shape[0]
        idx = np.flatnonzero(active)
        if idx.size < 4:
            return _PositionFix(STATUS_TOO_FEW, np.zeros(n, dtype=bool), 0)
        sp, yc = sat_pos[idx], y_corr[idx]
        k_cn0 = cn0_factor(p, cn0[idx])
        given = np.isfinite(pr_std[idx]) & (pr_std[idx] > 0)
        sin_el = np.ones(idx.size)

        def model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            nonlocal sin_el
            rs = sagnac_rotate(sp, x[:3])[0]
            diff = rs - x[:3]
            rng = np.sqrt(np.sum(diff * diff, axis=1))
            los = diff / rng[:, None]
            if np.linalg.norm(x[:3]) > _NEAR_SURFACE_R_M:
                sin_el = np.clip(los @ _geodetic_up_and_rotation(x[:3])[2], -1.0, 1.0)
            else:
                sin_el = np.ones(idx.size)
            var = code_variance_m2(p, sin_el, None, iono_m[idx], p.sigma_broadcast_m, k_cn0)
            return rng + x[3], los, 1.0 / np.where(given, pr_std[idx] ** 2, var)

        start = np.zeros(4)
        start[:3] = x0
        ls = least_squares_position(model, yc, start, p.max_iterations, p.convergence_m)
        if ls.status == SINGULAR:
            return _PositionFix(STATUS_SINGULAR, np.zeros(n, dtype=bool), ls.iterations)
        converged = ls.status == CONVERGED
        x, cov, h, w = ls.x, ls.covariance, ls.h, ls.weights
        # final linearisation at the converged point
        rs = sagnac_rotate(sp, x[:3])[0]
        diff = rs - x[:3]
        rng = np.sqrt(np.sum(diff * diff, axis=1))
        los = diff / rng[:, None]
        resid = yc - (rng + x[3])
        h[:, :3] = -los
        rot = _geodetic_up_and_rotation(x[:3]) if np.linalg.norm(x[:3]) > _NEAR_SURFACE_R_M else None
        el_all = np.full(n, math.nan)
        los_all = np.full((n, 3), math.nan)
        scale_all = np.full(n, math.nan)
        if rot is not None:
            sin_el = np.clip(los @ rot[2], -1.0, 1.0)
            el_all[idx] = np.arcsin(sin_el)
        los_all[idx] = los
        scale_all[idx] = np.sqrt(k_cn0) / np.maximum(sin_el, 0.05)
        below = np.zeros(n, dtype=bool)
        if rot is not None and converged:
            below[idx] = el_all[idx] < mask_rad
        # standardised residuals: r_i / sqrt(Qr_ii), Qr = W^-1 - H cov H^T
        qr_diag = 1.0 / w - np.einsum("ij,jk,ik->i", h, cov, h)
        # converged far from the Earth's surface (rot None): not a fix
        return _PositionFix(
            status=STATUS_OK if converged and rot is not None else STATUS_NOT_CONVERGED,
            below_mask=below,
            iterations=ls.iterations,
            x=x,
            covariance=cov,
            h=h,
            residuals_m=resid,
            sse=float(np.sum(w * resid**2)),
            standardised_residuals=resid / np.sqrt(np.maximum(qr_diag, 1e-12)),
            enu_rotation=rot,
            el_all=el_all,
            los_all=los_all,
            scale_all=scale_all,
        )


def _dop(h: np.ndarray, rot: np.ndarray | None) -> Dop:
    """Dilutions of precision of the position solution's geometry h (ECEF columns) in local ENU (rot); NaN when
    there is no rotation or the geometry is singular."""
    if rot is None:
        return _NAN_DOP
    g = h.copy()
    g[:, :3] = g[:, :3] @ rot.T
    try:
        q = np.linalg.inv(g.T @ g)
    except np.linalg.LinAlgError:
        return _NAN_DOP
    return Dop(
        float(np.sqrt(np.trace(q))),
        float(np.sqrt(q[0, 0] + q[1, 1] + q[2, 2])),
        float(np.sqrt(q[0, 0] + q[1, 1])),
        float(np.sqrt(q[2, 2])),
        float(np.sqrt(q[3, 3])),
    )


def _velocity(sol, used: np.ndarray, position: np.ndarray, sat_pos: np.ndarray, sat_vel: np.ndarray,
              rate_corr: np.ndarray, rate_std: np.ndarray, sigma_rate_mps: float
              ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """Velocity and clock drift (Cao et al., eq. 6) from the used satellites with a rate, by weighted least squares
    on the position solution's lines of sight: (velocity, drift, covariance), or None (fewer than 4, or not finite)."""
    rv = used[np.isfinite(rate_corr[used])]
    if rv.size < 4:
        return None
    los = sol.los_all[rv]
    _, c, s, _ = sagnac_rotate(sat_pos[rv], position)
    vs = rotate_about_z(sat_vel[rv], c, s)
    yv = rate_corr[rv] - np.sum(vs * los, axis=1)
    hv = np.hstack([-los, np.ones((rv.size, 1))])
    sig_v = sigma_rate_mps * sol.scale_all[rv]
    sig_v = np.where(np.isfinite(rate_std[rv]) & (rate_std[rv] > 0), rate_std[rv], sig_v)
    solved = weighted_least_squares(hv, yv, 1.0 / sig_v**2)
    if solved is None or not np.all(np.isfinite(solved[0])):
        return None
    return solved[0][:3], float(solved[0][3]), solved[1]


def _no_solution(stamp_ns: int, status: str, used_svids: np.ndarray, rejected: tuple, counts: dict[str, int],
                 iterations: int, extra: dict[str, float]) -> SppResult:
    """The result of an epoch with too few satellites or a singular geometry: invalid, NaN estimates."""
    nan3 = np.full(3, math.nan)
    nan4 = np.full((4, 4), math.nan)
    k = used_svids.size
    return SppResult(stamp_ns, False, status, nan3, math.nan, False, nan3.copy(), math.nan, nan4,
                     np.full((3, 3), math.nan), nan4.copy(), _NAN_DOP, tuple(int(s) for s in used_svids), rejected,
                     counts, np.full(k, math.nan), np.full(k, math.nan), iterations, math.nan, math.nan, extra)

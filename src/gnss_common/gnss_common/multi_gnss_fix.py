"""Multi-constellation snapshot solution: position with one receiver clock per constellation, velocity
with one common drift, and the per-satellite residuals that residual and consistency tests read.

Pure core (no rclpy, no state): :func:`solve_multi_gnss` (GnssEpoch -> frozen :class:`MultiGnssFix`).
Unlike ``gnss_common.spp`` it uses every constellation, excludes nothing (fault detection is the
caller's, e.g. ``gnss_integrity.consistency``) and keeps its design matrix and weights: the solution
of any subset of its satellites is one linear step (:func:`subset_solution`). Satellite i of
constellation k(i) (Cao et al., eq. 5, 6)::

    P_i + c dt_i - I_i - T_i = |R3(w tau_i) p_i - p_r| + c dt_r,k(i) + e_i
    rate_i + c ddt_i - (R3(w tau_i) v_i) . u_i = -v_r . u_i + c ddt_r + e'_i

A clock bias per constellation (receiver clock, system time offset, hardware delay) but ONE drift:
every signal comes from one oscillator, whose frequency error df / f shifts every rate ``-lambda D``
by ``c df / f`` whatever the carrier; system time offsets drift by < 1e-13 (< 1 mm/s). On ESBC00DNK
the per-constellation mean rate residual against the common drift is < 1 mm/s (``test_real_common_drift``).
Weights: RTKLIB ``varerr`` of ``gnss_common.spp`` (``code_variance_m2``), SISRE per constellation.

Notes
-----
Kaplan & Hegarty 3rd ed., sec. 11.2.1, eq. 11.40-11.45 (iterated WLS); Baarda's w-test
``r_i / sqrt((W^-1 - H (H^T W H)^-1 H^T)_ii)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import chain
from operator import attrgetter
from typing import NamedTuple

import numpy as np

from gnss_common.constants import WGS84_ECCENTRICITY_SQUARED, WGS84_SEMI_MAJOR_AXIS_M
from gnss_common.coordinates import ecef_to_enu_rotation_scalar, ecef_to_geodetic_scalar
from gnss_common.multi_gnss_rows import (
    design,
    normal_rows,
    rate_variances,
    residuals,
    rotate_z,
    row_variances,
    sagnac_rotate,
    screen_flags,
    screened,
)
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, GnssEpoch
from gnss_common.spp import SppParams, cn0_factor

STATUS_OK = "ok"
STATUS_TOO_FEW = "too_few_satellites"
STATUS_SINGULAR = "singular_geometry"
STATUS_NOT_CONVERGED = "not_converged"

REJECTION_REASONS = ("unsupported_constellation", "not_selected", "invalid_input", "non_physical", "duplicate_svid",
                     "below_elevation_mask")
"""Keys of :attr:`MultiGnssFix.rejection_counts` (``not_selected``: left out by the caller's
``use`` mask or ``constellations``; ``invalid_input``: a NaN pseudorange or satellite state)."""

_NEAR_SURFACE_R_M = 0.9 * WGS84_SEMI_MAJOR_AXIS_M * math.sqrt(1.0 - WGS84_ECCENTRICITY_SQUARED)
_MAX_VARIANCE_M2 = 1.0e10


@dataclass(frozen=True)
class MultiGnssFixParams:
    """Validated parameters of :func:`solve_multi_gnss`.

    Attributes:
        weights: elevation mask, iterations, convergence and the ``varerr`` model (``SppParams``;
            its RAIM fields unused). constellations: codes solved (others ``unsupported_constellation``).
        sigma_broadcast_m: ``((constellation, SISRE 1-sigma m), ...)``; others ``weights.sigma_broadcast_m``.
    """

    weights: SppParams = field(default_factory=SppParams)
    constellations: tuple[int, ...] = (GPS, GLONASS, GALILEO, BEIDOU, QZSS)
    sigma_broadcast_m: tuple[tuple[int, float], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.weights, SppParams):
            raise ValueError(f"MultiGnssFixParams.weights must be SppParams, got {type(self.weights).__name__}")
        if not self.constellations or any(not isinstance(c, int) or c < 1 for c in self.constellations):
            raise ValueError(f"MultiGnssFixParams.constellations must be codes >= 1, got {self.constellations!r}")
        if any(len(e) != 2 or not (math.isfinite(e[1]) and e[1] >= 0.0) for e in self.sigma_broadcast_m):
            raise ValueError(f"MultiGnssFixParams.sigma_broadcast_m: (code, sigma >= 0), got {self.sigma_broadcast_m}")


@dataclass(frozen=True)
class MultiGnssFix:
    """One epoch's multi-constellation snapshot solution.

    Per-satellite arrays (n,) have one row per satellite with a usable state (``satellites``, sorted by
    (constellation, svid)), used in the fix or not (``used``); rows not used keep their elevation,
    azimuth and predicted residual where their constellation's clock is solved (else NaN). ``sse`` is
    chi-square with ``dof`` degrees of freedom under the weight model (NaN when dof < 1).
    """

    stamp_ns: int  # the epoch's stamp, ns
    valid: bool  # status ok: >= 3 + k satellites, converged near the Earth's surface
    status: str  # ok, too_few_satellites, singular_geometry, not_converged
    position_ecef_m: np.ndarray  # receiver position, ECEF m, (3,)
    clock_constellations: tuple[int, ...]  # the constellation of each clock, ascending codes, (k,)
    clock_biases_m: np.ndarray  # c dt_r,k of each, m, (k,)
    covariance: np.ndarray  # of [x, y, z, c dt_1 .. c dt_k], m^2, ECEF
    covariance_enu_m2: np.ndarray  # of the position in local ENU, m^2, (3, 3)
    enu_rotation: np.ndarray  # ECEF -> ENU at the solution, (3, 3)
    velocity_valid: bool  # solved from >= 4 rates of used rows
    velocity_ecef_mps: np.ndarray  # receiver velocity, ECEF m/s, (3,)
    clock_drift_mps: float  # the one receiver clock drift c ddt_r, m/s
    velocity_covariance: np.ndarray  # of [vx, vy, vz, c ddt_r], (m/s)^2, (4, 4)
    satellites: tuple[tuple[int, int], ...]  # (constellation, svid) of each row
    used: np.ndarray  # row in the position fix, bool
    elevations_rad: np.ndarray  # at the solution, rad
    azimuths_rad: np.ndarray  # from north, clockwise, rad
    residuals_m: np.ndarray  # corrected pseudorange minus the model at the solution, m
    standardised_residuals: np.ndarray  # w-test r / sqrt(Qr_ii) of used rows (NaN without redundancy)
    rate_used: np.ndarray  # row in the velocity fix, bool
    rate_residuals_mps: np.ndarray  # corrected rate minus the model, m/s
    rate_standardised_residuals: np.ndarray  # their w-test values
    design_matrix: np.ndarray  # rows [-u_i, one-hot clock of k(i)] at the solution, (n, 3 + k)
    weights: np.ndarray  # 1 / sigma^2 of the pseudoranges, 1/m^2
    noise_variances_m2: np.ndarray  # the white part (code noise) of each variance, m^2; the rest is
    # atmosphere, orbit and clock, correlated over tens of minutes (code_noise_variance_m2, or a stated std^2)
    rate_weights: np.ndarray  # 1 / sigma^2 of the rates, (m/s)^-2
    sigma_scales: np.ndarray  # the weight model's sqrt(k_cn0) / max(sin el, 0.05) (rate sigma: sigma_rate_mps x it)
    sse: float  # weighted residual sum of squares of the used rows
    dof: int  # n_used - 3 - k
    rate_sse: float  # the same for the rates
    rate_dof: int  # n_rate_used - 4
    iterations: int  # Gauss-Newton linearisations
    rejected: tuple[tuple[tuple[int, int], str], ...]  # ((constellation, svid), reason) not in the rows or unused
    rejection_counts: dict[str, int]  # reason -> count, every key of REJECTION_REASONS

    @property
    def constellation_of_row(self) -> np.ndarray:
        """Constellation code of each row, (n,)."""
        return np.array([c for c, _ in self.satellites], dtype=int)

    def clock_bias_m(self, constellation: int) -> float:
        """The clock bias of one constellation, m (NaN when not solved)."""
        if constellation in self.clock_constellations:
            return float(self.clock_biases_m[self.clock_constellations.index(constellation)])
        return math.nan


def _invert(nmat: np.ndarray, max_variance: float = math.inf) -> np.ndarray | None:
    """Inverse of a normal matrix, or None when singular or with a variance <= 0 or above the bound."""
    try:
        cov = np.linalg.inv(nmat)
    except np.linalg.LinAlgError:
        return None
    return cov if all(0.0 < v < max_variance and math.isfinite(v) for v in cov.diagonal().tolist()) else None


def _w_test(resid: np.ndarray, var: np.ndarray, h: np.ndarray, cov: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Standardised residuals ``r_i / sqrt((R - H cov H^T)_ii)`` of ``rows`` (else and without redundancy NaN)."""
    qr = var - np.sum((h @ cov) * h, axis=1)
    with np.errstate(invalid="ignore"):
        return np.where(rows & (qr > 1e-9 * var), resid / np.sqrt(np.maximum(qr, 1e-300)), math.nan)


class _Rows(NamedTuple):
    """Screened satellites, one row each, by (constellation, svid): ``y = P + c dt_s - I - T`` (m), ``rate +
    c ddt_s`` (m/s, NaN if unusable), ``selected`` by the caller's mask and constellations; the weight model's
    inputs once per epoch (``cn0_factor``; stated pseudorange std^2, NaN where none)."""

    sats: tuple[tuple[int, int], ...]
    system: np.ndarray
    sat_pos: np.ndarray
    sat_vel: np.ndarray
    y: np.ndarray
    rate: np.ndarray
    rate_std: np.ndarray
    selected: np.ndarray
    k_cn0: np.ndarray
    iono: np.ndarray
    sisre: np.ndarray
    stated2: np.ndarray


_FIELDS = attrgetter("pseudorange_m", "satellite_clock_bias_m", "ionosphere_delay_m", "troposphere_delay_m",
                     "pseudorange_rate_mps", "satellite_clock_drift_mps", "cn0_dbhz", "pseudorange_std_m",
                     "pseudorange_rate_std_mps")


def _stack3(values: list, n: int) -> np.ndarray:
    """Stack per-observation 3-vectors into (n, 3); a malformed one becomes a NaN row."""
    try:
        out = np.array(values, dtype=float)
    except (ValueError, TypeError):
        out = np.zeros(0)
    return out if out.shape == (n, 3) else np.array([a if (a := np.asarray(v, dtype=float).reshape(-1)).shape == (3,)
                                                     else np.full(3, math.nan) for v in values]).reshape(n, 3)


def _screen(epoch: GnssEpoch, params: MultiGnssFixParams, use: np.ndarray | None,
            constellations: tuple[int, ...] | None,
            reject: dict[str, int], rejected: list[tuple[tuple[int, int], str]]) -> _Rows:
    """Screen the observations of an epoch into rows (counts every rejection), vectorised."""
    obs, n_obs = epoch.observations, len(epoch.observations)
    selected = np.ones(n_obs, dtype=bool) if use is None else np.asarray(use, dtype=bool).reshape(-1)
    if selected.shape != (n_obs,):
        raise ValueError(f"use must have one entry per observation ({n_obs}), got shape {selected.shape}")
    keys = [(int(o.constellation), int(o.svid)) for o in obs]
    s = np.fromiter(chain.from_iterable(map(_FIELDS, obs)), float, 9 * n_obs).reshape(n_obs, 9)
    pos = _stack3([o.satellite_position_ecef_m for o in obs], n_obs)
    vel = _stack3([o.satellite_velocity_ecef_mps for o in obs], n_obs)
    system = np.array([k[0] for k in keys], dtype=int)
    unique = np.ones(n_obs, dtype=bool) if len(set(keys)) == n_obs else np.array([keys.count(k) == 1 for k in keys])
    supported = np.array([k[0] in params.constellations for k in keys], dtype=bool)
    finite, physical, rate_ok = screen_flags(s, pos, vel)
    ok = supported & unique & finite & physical
    for j in np.flatnonzero(~ok).tolist():
        reason = ("unsupported_constellation" if not supported[j] else "duplicate_svid" if not unique[j]
                  else "invalid_input" if not finite[j] else "non_physical")
        reject[reason] += 1
        rejected.append((keys[j], reason))
    if constellations is not None:
        selected = selected & np.isin(system, constellations)
    idx = np.array(sorted(np.flatnonzero(ok).tolist(), key=keys.__getitem__), dtype=np.intp)
    sel = selected[idx]
    for j in idx[~sel].tolist():
        reject["not_selected"] += 1
        rejected.append((keys[j], "not_selected"))
    sv, wp, table = s[idx], params.weights, dict(params.sigma_broadcast_m)
    sisre = np.array([table.get(c, wp.sigma_broadcast_m) for c in system[idx].tolist()], dtype=float)
    y, rate, stated2 = screened(s, idx, rate_ok)
    return _Rows(tuple([keys[j] for j in idx.tolist()]), system[idx], pos[idx], vel[idx], y, rate, sv[:, 8], sel,
                 cn0_factor(wp, sv[:, 6]), sv[:, 2], sisre, stated2)


class _Geometry(NamedTuple):
    """Ranges, unit vectors, Sagnac rotation and elevation sines of every row at one position."""

    rng: np.ndarray
    los: np.ndarray
    cos_s: np.ndarray
    sin_s: np.ndarray
    rot: np.ndarray | None
    sin_el: np.ndarray


def _geometry(rows: _Rows, pos: np.ndarray) -> _Geometry:
    """The geometry of every row seen from ``pos`` (ECEF m): ``gnss_common.earth_rotation.sagnac_rotate``
    (one travel-time iteration) without its unused second travel time; the ENU rotation (row 2: the local
    up) where ``pos`` is near the surface, else None."""
    diff, c, s = sagnac_rotate(rows.sat_pos, pos)
    rng = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    los = diff / rng[:, None]
    x, y, z = pos.tolist()
    near = all(map(math.isfinite, (x, y, z))) and math.sqrt(x * x + y * y + z * z) > _NEAR_SURFACE_R_M
    rot = ecef_to_enu_rotation_scalar(*ecef_to_geodetic_scalar(x, y, z)[:2]) if near else None
    sin_el = np.clip(los @ rot[2], -1.0, 1.0) if rot is not None else np.ones(rng.size)
    return _Geometry(rng, los, c, s, rot, sin_el)


def _variance(geo: _Geometry, params: SppParams, rows: _Rows, white_only: bool = False) -> np.ndarray:
    """Pseudorange variance (or its white part) of every row at a geometry, a stated std overriding, m^2."""
    return row_variances(geo.sin_el, rows.k_cn0, rows.iono, rows.sisre, rows.stated2, params.sigma_code_a_m**2,
                         params.sigma_code_b_m, params.iono_error_fraction, params.sigma_tropo_zenith_m, white_only)


def _gauss_newton(rows: _Rows, idx: np.ndarray, clock: np.ndarray, x0: np.ndarray, geo: _Geometry,
                  params: SppParams) -> tuple[str, np.ndarray, np.ndarray | None, int, _Geometry, np.ndarray]:
    """Iterated WLS for ``[x, y, z, c dt_1 .. c dt_k]`` on rows ``idx`` (clock ``clock`` of each row) from
    ``x0`` (geometry ``geo``): (status, x, covariance or None, iterations, geometry at x, row variances)."""
    x = x0.copy()
    var = np.full(len(rows.sats), math.nan)
    for it in range(1, params.max_iterations + 1):
        var = _variance(geo, params, rows)
        h, w, r = normal_rows(var, geo.los, geo.rng, rows.y, x, clock, idx)
        cov = _invert(h.T @ (h * w[:, None]), _MAX_VARIANCE_M2)
        if cov is None:
            return STATUS_SINGULAR, x, None, it, geo, var
        dx = cov @ (h.T @ (w * r))
        x = x + dx
        geo = _geometry(rows, x[:3])
        if math.sqrt(float(dx @ dx)) < params.convergence_m:  # np.linalg.norm's arithmetic
            return (STATUS_OK if geo.rot is not None else STATUS_NOT_CONVERGED), x, cov, it, geo, var
    return STATUS_NOT_CONVERGED, x, cov, params.max_iterations, geo, var


def _clock_columns(system: np.ndarray, idx: np.ndarray) -> tuple[tuple[int, ...], np.ndarray]:
    """Clocks of the constellations among rows ``idx`` and their one-hot columns, (idx.size, k)."""
    clocks = tuple(sorted(set(system[idx].tolist())))
    return clocks, (system[idx][:, None] == np.array(clocks, dtype=int)[None, :]).astype(float)


def solve_multi_gnss(epoch: GnssEpoch, params: MultiGnssFixParams | None = None, *,
                     use: np.ndarray | None = None, constellations: tuple[int, ...] | None = None,
                     initial_position_ecef_m: np.ndarray | None = None) -> MultiGnssFix:
    """Solve one epoch: position and a clock per constellation, then velocity and one drift.

    Args:
        epoch: one receive epoch, any constellations (satellite states at transmit time in the ECEF
            frame of transmission; delays as the message gives them).
        params: :class:`MultiGnssFixParams` (defaults if None).
        use: optional bool mask, one per ``epoch.observations`` (False: ``not_selected``; the row
            still gets its elevation and predicted residual).
        constellations: optional subset of codes to solve with (per-constellation solutions).
        initial_position_ecef_m: starting point, m, (3,) (default the Earth's centre; the previous
            fix saves iterations and applies the elevation mask from the start).

    Returns:
        :class:`MultiGnssFix`; never raises on measurement content (see ``status``).

    Raises:
        ValueError: ``use`` of the wrong length, or a non-finite initial position.

    Notes
    -----
    Cao et al., eq. 5 (a clock per constellation) and eq. 6 (one drift), iterated WLS (Kaplan &
    Hegarty, eq. 11.40-11.45); the elevation mask is applied at convergence and the fix recomputed.
    """
    p = params if params is not None else MultiGnssFixParams()
    wp = p.weights
    counts = dict.fromkeys(REJECTION_REASONS, 0)
    rejected: list[tuple[tuple[int, int], str]] = []
    rows = _screen(epoch, p, use, constellations, counts, rejected)
    x_start = np.zeros(3) if initial_position_ecef_m is None else np.asarray(initial_position_ecef_m, float).reshape(3)
    if not np.all(np.isfinite(x_start)):
        raise ValueError("initial_position_ecef_m must be finite")
    active = rows.selected.copy()
    sin_mask = math.sin(math.radians(wp.elevation_mask_deg))
    geo = _geometry(rows, x_start)
    below = active & (geo.sin_el < sin_mask) if geo.rot is not None else np.zeros(active.size, dtype=bool)
    status, iterations, cov, x, var = STATUS_TOO_FEW, 0, None, np.zeros(3), np.full(active.size, math.nan)
    clocks: tuple[int, ...] = ()
    while True:  # the elevation mask only removes rows: re-solve from the last fix until none is below
        for i in np.flatnonzero(below):
            counts["below_elevation_mask"] += 1
            rejected.append((rows.sats[i], "below_elevation_mask"))
        active &= ~below
        idx = np.flatnonzero(active)
        clocks, cols = _clock_columns(rows.system, idx)
        clock = np.array([clocks.index(c) if c in clocks else -1 for c in rows.system.tolist()], dtype=np.int64)
        if idx.size == 0 or idx.size < 3 + len(clocks):
            status = STATUS_TOO_FEW
            break
        x0 = np.concatenate([x_start, np.zeros(len(clocks))])
        if geo.rot is not None:  # start near the surface: each clock at its rows' mean offset
            x0[3:] = ((rows.y[idx] - geo.rng[idx]) @ cols) / np.sum(cols, axis=0)
        status, x, cov, its, geo, var = _gauss_newton(rows, idx, clock, x0, geo, wp)
        iterations += its
        below = active & (geo.sin_el < sin_mask)
        if status != STATUS_OK or not np.any(below):
            break
        x_start = x[:3].copy()
    return _assemble(epoch.stamp_ns, status, rows, active, clocks, clock, x, cov, geo, var, iterations, wp, counts,
                     rejected)


def _velocity(rows: _Rows, geo: _Geometry, active: np.ndarray, wp: SppParams) -> dict:
    """Velocity and one clock drift from the rates of the active rows (Cao et al., eq. 6)."""
    n = len(rows.sats)
    scales, var_v = rate_variances(rows.k_cn0, geo.sin_el, rows.rate_std, wp.sigma_rate_mps)
    out: dict = {"sigma_scales": scales, "rate_weights": 1.0 / var_v}
    yv = rows.rate - np.einsum("ij,ij->i", rotate_z(rows.sat_vel, geo.cos_s, geo.sin_s, np.zeros(3)), geo.los)
    hv = design(geo.los, np.zeros(n, dtype=np.int64), 1)  # [-u_i, 1]
    rv = np.flatnonzero(used := active & np.isfinite(yv))
    wv, hr = 1.0 / var_v[rv], hv[rv]
    vcov = _invert(hr.T @ (hr * wv[:, None])) if rv.size >= 4 else None
    if vcov is None:
        return out | {"velocity_valid": False, "velocity_ecef_mps": np.full(3, math.nan), "clock_drift_mps": math.nan,
                      "velocity_covariance": np.full((4, 4), math.nan), "rate_used": np.zeros(n, dtype=bool),
                      "rate_residuals_mps": np.full(n, math.nan), "rate_standardised_residuals": np.full(n, math.nan),
                      "rate_sse": math.nan, "rate_dof": 0}
    xv = vcov @ (hr.T @ (wv * yv[rv]))
    res = yv - hv @ xv
    return out | {"velocity_valid": True, "velocity_ecef_mps": xv[:3].copy(), "clock_drift_mps": float(xv[3]),
                  "velocity_covariance": vcov, "rate_used": used, "rate_residuals_mps": res, "rate_dof": rv.size - 4,
                  "rate_standardised_residuals": _w_test(res, var_v, hv, vcov, used),
                  "rate_sse": float(np.sum(wv * res[rv] ** 2)) if rv.size > 4 else math.nan}


def _assemble(stamp_ns: int, status: str, rows: _Rows, active: np.ndarray, clocks: tuple[int, ...],
              clock: np.ndarray, x: np.ndarray, cov: np.ndarray | None, geo: _Geometry, var: np.ndarray,
              iterations: int, wp: SppParams, counts: dict[str, int], rejected: list[tuple[tuple[int, int], str]]
              ) -> MultiGnssFix:
    """Residuals, weights, w-tests, azimuth/elevation and the velocity at the final solution (``clock``: each
    row's index in ``clocks``, -1 without one)."""
    n, k = len(rows.sats), len(clocks)
    h = design(geo.los, clock, k)
    nan = np.full(n, math.nan)
    el, az, resid, wstd, w, noise, sse = nan, nan, nan, nan, nan, nan, math.nan
    rot = geo.rot if status in (STATUS_OK, STATUS_NOT_CONVERGED) and cov is not None and n else None
    dof = int(active.sum()) - 3 - k
    if rot is not None and cov is not None:
        resid = residuals(rows.y, geo.rng, x, clock)
        w = 1.0 / var
        noise = _variance(geo, wp, rows, white_only=True)
        wstd = _w_test(resid, var, h, cov, active)
        sse = float(np.sum(w[active] * resid[active] ** 2)) if dof >= 1 else math.nan
        enu = geo.los @ rot.T
        el = np.arcsin(np.clip(enu[:, 2], -1.0, 1.0))
        az = np.mod(np.arctan2(enu[:, 0], enu[:, 1]), 2.0 * math.pi)
        vel = _velocity(rows, geo, active, wp)
    else:
        x, cov = np.full(3 + k, math.nan), np.full((3 + k, 3 + k), math.nan)
        vel = _velocity(rows, geo, np.zeros(n, dtype=bool), wp)
        vel["rate_weights"] = nan
    nan33 = np.full((3, 3), math.nan)
    return MultiGnssFix(
        stamp_ns=int(stamp_ns), valid=status == STATUS_OK and rot is not None, status=status,
        position_ecef_m=np.asarray(x[:3], dtype=float).copy(), clock_constellations=clocks,
        clock_biases_m=np.asarray(x[3:], dtype=float).copy(), covariance=cov,
        covariance_enu_m2=rot @ cov[:3, :3] @ rot.T if rot is not None else nan33,
        enu_rotation=rot if rot is not None else nan33, satellites=rows.sats, used=active.copy(),
        elevations_rad=el, azimuths_rad=az, residuals_m=resid, standardised_residuals=wstd, design_matrix=h,
        weights=w, noise_variances_m2=noise, sse=sse, dof=max(dof, 0), iterations=iterations,
        rejected=tuple(rejected), rejection_counts=counts, **vel)


@dataclass(frozen=True)
class SubsetSolution:
    """A linearised solution from a subset of a fix's rows (:func:`subset_solution`)."""

    valid: bool  # enough rows (>= 3 + clocks), invertible normal matrix
    position_ecef_m: np.ndarray  # ECEF m, (3,)
    clock_constellations: tuple[int, ...]  # its clocks
    clock_biases_m: np.ndarray  # m
    covariance: np.ndarray  # of [x, y, z, clocks], m^2
    noise_covariance: np.ndarray  # its part from the rows' white noise (fix.noise_variances_m2), m^2
    standardised_residuals: np.ndarray  # w-test of the subset's rows after the step, NaN elsewhere, (n,)
    sse: float  # weighted residual sum of squares of the subset (NaN when dof < 1)
    dof: int


def subset_solution(fix: MultiGnssFix, rows: np.ndarray) -> SubsetSolution:
    """The solution of the rows ``rows`` (bool over ``fix.satellites``; NaN residuals ignored) alone.

    One Gauss-Newton step from ``fix``: ``dx = (H_S^T W_S H_S)^-1 H_S^T W_S r_S`` with a clock column
    per constellation of the subset and ``r_S`` the residuals at ``fix`` (Kaplan & Hegarty, eq.
    11.40-11.45). The neglected second-order term is ``|dx|^2 / (2 range)``: 25 mm 1 km away.
    """
    sel = np.flatnonzero(np.asarray(rows, dtype=bool) & np.isfinite(fix.residuals_m) & np.isfinite(fix.weights))
    system = fix.constellation_of_row
    clocks, cols = _clock_columns(system, sel)
    k = len(clocks)
    h = np.hstack([fix.design_matrix[sel, :3], cols])
    w = fix.weights[sel]
    cov = _invert(h.T @ (h * w[:, None])) if sel.size >= max(3 + k, 1) else None
    wstd = np.full(len(fix.satellites), math.nan)
    if cov is None:
        nan_cov = np.full((3 + k, 3 + k), math.nan)
        return SubsetSolution(False, np.full(3, math.nan), clocks, np.full(k, math.nan), nan_cov, nan_cov, wstd,
                              math.nan, 0)
    r = fix.residuals_m[sel]
    gain = cov @ (h.T * w)
    dx = gain @ r
    post = r - h @ dx
    dof = sel.size - 3 - k
    wstd[sel] = _w_test(post, 1.0 / w, h, cov, np.ones(sel.size, dtype=bool))
    return SubsetSolution(True, fix.position_ecef_m + dx[:3], clocks,
                          np.array([fix.clock_bias_m(c) for c in clocks]) + dx[3:], cov,
                          (gain * fix.noise_variances_m2[sel]) @ gain.T, wstd,
                          float(np.sum(w * post**2)) if dof >= 1 else math.nan, dof)

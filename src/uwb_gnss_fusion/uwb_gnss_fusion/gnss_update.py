"""The GNSS update of the fusion filter: satellite weights, the common-mode screen, the CKF update.

Pure core (no rclpy).

* :func:`prepare_epoch`: the satellites the filter may apply (:mod:`.input_checks`, elevation
  mask) with their 1-sigmas from C/N0 and the jammer-to-signal ratio (Cao et al., eq. 4 and 12,
  :mod:`gnss_common.jamming_weights`);
* :func:`screen_common_mode`: drop pseudoranges (and rates) whose innovation departs from the
  epoch's common-mode (clock) innovation (:mod:`.robust_screen`; beyond the paper);
* :func:`update_gnss`: pseudoranges and pseudorange rates in one gated cubature update
  (Cao et al., eq. 5, 6 and 17-24);
* :func:`clock_offset_from_residuals`: the receiver clock from the pseudorange residuals.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gnss_common.coordinates import azimuth_elevation
from gnss_common.jamming_weights import measurement_sigmas
from gnss_common.observations import GnssEpoch

from .ckf import CubatureKalmanFilter, UpdateResult
from .fusion_params import FusionParams
from .input_checks import Count, PreparedEpoch, gps_observations, validate_satellites
from .measurement_models import MeasurementModel, pseudorange_model, pseudorange_rate_model, stack_models
from .robust_screen import common_mode_screen, projected_variance

MIN_SIN_ELEVATION = math.sin(math.radians(5.0))
"""Floor of sin(elevation) in the elevation weighting of satellites without C/N0 (caps the factor at 11.5)."""


def prepare_epoch(
    epoch: GnssEpoch, receiver_m: np.ndarray | None, js_db: float, params: FusionParams, count: Count
) -> PreparedEpoch | None:
    """Validate the satellites of an epoch (counting rejections per reason) and compute their weights.

    Args:
        epoch: the receive epoch.
        receiver_m: predicted receiver position, ECEF, m, (3,), for the elevation mask and weights
            (None before initialisation: no mask).
        js_db: the current jammer-to-signal ratio, dB (NaN: none).
        params: filter parameters.
        count: the rejection counter.

    Returns:
        The usable satellites, or None when none is left.

    Notes:
        Cao et al., eq. 4 (effective C/N0 under a jammer) and eq. 12 (measurement noise from the
        DLL/FLL jitter), :func:`gnss_common.jamming_weights.measurement_sigmas`.
    """
    p = params
    rows = validate_satellites(gps_observations(epoch.observations, count), p, count)
    sin_el = None
    if rows and receiver_m is not None:
        _, el = azimuth_elevation(receiver_m, np.array([r[1] for r in rows]))
        el = np.atleast_1d(el)
        above = np.degrees(el) >= p.elevation_mask_deg
        count("below_elevation_mask", int(above.size - above.sum()))
        rows = [r for r, a in zip(rows, above, strict=True) if a]
        sin_el = np.sin(el[above])
    if not rows:
        return None
    n = len(rows)
    has_cn0 = np.array([math.isfinite(r[0].cn0_dbhz) for r in rows])
    cn0 = np.array([r[0].cn0_dbhz if ok else p.nominal_cn0_dbhz for r, ok in zip(rows, has_cn0, strict=True)])
    s_pr, s_rate, _ = measurement_sigmas(cn0, math.nan, p.loop, p.jammer_quality_factor)
    if sin_el is not None and not has_cn0.all():
        # No C/N0 reported (e.g. RINEX without S1): the nominal C/N0 holds at zenith and the
        # sigma grows as 1/sin(el), the usual elevation weighting when the signal strength is
        # unknown (Euler & Goad 1991; RTKLIB's b/sin(el) term). Without it every satellite had
        # the same weight, and low satellites (larger troposphere/multipath error) pulled the
        # solution (docs/uwb_gnss_fusion/fusion_real_gnss.md).
        scale = np.where(has_cn0, 1.0, 1.0 / np.maximum(sin_el, MIN_SIN_ELEVATION))
        s_pr = s_pr * scale
        s_rate = s_rate * scale
    if math.isfinite(js_db):
        # eq. 4 on the nominal jammer-free C/N0; the weaker of (reported, predicted) is used so
        # that a receiver that already reports the degraded C/N0 is not penalised twice.
        s_pr_j, s_rate_j, _ = measurement_sigmas(np.full(n, p.nominal_cn0_dbhz), js_db, p.loop, p.jammer_quality_factor)
        s_pr = np.maximum(s_pr, s_pr_j)
        s_rate = np.maximum(s_rate, s_rate_j)
    given_pr = np.array([r[0].pseudorange_std_m for r in rows])
    given_rate = np.array([r[0].pseudorange_rate_std_mps for r in rows])
    ok_pr = np.isfinite(given_pr) & (given_pr > 0.0)
    ok_rate = np.isfinite(given_rate) & (given_rate > 0.0)
    s_pr = np.where(ok_pr, np.maximum(given_pr, s_pr) if math.isfinite(js_db) else given_pr, s_pr)
    s_rate = np.where(ok_rate, np.maximum(given_rate, s_rate) if math.isfinite(js_db) else given_rate, s_rate)
    rate = np.array([r[0].pseudorange_rate_mps if r[3] else math.nan for r in rows])
    return PreparedEpoch(
        sat_pos=np.array([r[1] for r in rows]),
        sat_vel=np.array([r[2] if r[3] else np.zeros(3) for r in rows]),
        sat_clk=np.array([r[0].satellite_clock_bias_m for r in rows]),
        sat_drift=np.array([r[0].satellite_clock_drift_mps if r[3] else 0.0 for r in rows]),
        iono=np.array([r[0].ionosphere_delay_m for r in rows]),
        tropo=np.array([r[0].troposphere_delay_m for r in rows]),
        pr=np.array([r[0].pseudorange_m for r in rows]),
        rate=rate,
        sigma_pr=s_pr,
        sigma_rate=s_rate,
    )


def clock_offset_from_residuals(prep: PreparedEpoch, nominal: np.ndarray) -> float:
    """Median pseudorange residual at the nominal state, m: the receiver clock correction when the
    position is trusted (a UWB start, or a GNSS-declared divergence that UWB does not confirm).

    Notes:
        Cao et al., eq. 5 with the position fixed; the median ignores the jammed outliers.
    """
    hx0 = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)
    return float(np.median(prep.pr - hx0(nominal[None, :])[0]))


def screen_common_mode(
    prep: PreparedEpoch, nominal: np.ndarray, p: np.ndarray, gate_nis: float, count: Count
) -> tuple[PreparedEpoch, int]:
    """Drop the pseudoranges (and mark the rates) that fail the common-mode innovation screen.

    Args:
        prep: the epoch's satellites.
        nominal: predicted nominal state, (8,).
        p: predicted error covariance, (8, 8) (read only).
        gate_nis: the per-measurement gate.
        count: the rejection counter (``common_mode_pseudorange``, ``common_mode_doppler``).

    Returns:
        (the epoch without the dropped pseudoranges, how many were dropped).

    Notes:
        :mod:`.robust_screen`: innovations at the predicted state, the median removed, tested
        with ``R_i + e_i^T P e_i`` (position covariance for pseudoranges, velocity covariance
        for rates).
    """
    x = nominal[None, :]
    d = prep.sat_pos - nominal[None, 0:3]
    los = d / np.linalg.norm(d, axis=1)[:, None]
    nu = prep.pr - pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)(x)[0]
    keep = common_mode_screen(nu, prep.sigma_pr**2 + projected_variance(los, p[0:3, 0:3]), gate_nis)
    rate = prep.rate
    ridx = np.flatnonzero(np.isfinite(rate))
    if ridx.size >= 3:
        h_rate = pseudorange_rate_model(prep.sat_pos[ridx], prep.sat_vel[ridx], prep.sat_drift[ridx])
        nu_r = rate[ridx] - h_rate(x)[0]
        ok_r = common_mode_screen(
            nu_r, prep.sigma_rate[ridx] ** 2 + projected_variance(los[ridx], p[3:6, 3:6]), gate_nis
        )
        if not ok_r.all():
            rate = rate.copy()
            rate[ridx[~ok_r]] = math.nan
            count("common_mode_doppler", int(ridx.size - ok_r.sum()))
    n_drop = int(keep.size - keep.sum())
    if n_drop == 0:
        return (prep if rate is prep.rate else replace(prep, rate=rate)), 0
    count("common_mode_pseudorange", n_drop)
    return prep.subset(keep, rate), n_drop


def update_gnss(
    ckf: CubatureKalmanFilter, nominal: np.ndarray, prep: PreparedEpoch, gate_nis: float, params: FusionParams
) -> UpdateResult:
    """One gated cubature update with the epoch's pseudoranges and usable pseudorange rates.

    Args:
        ckf: the error-state filter (error mean zero; the caller folds the correction in).
        nominal: the nominal state the error state is relative to, (8,).
        prep: the satellites (k pseudoranges, then the finite rates, in that order).
        gate_nis: the per-measurement gate.
        params: ``max_update_iterations``, ``nonlinearity_threshold``.

    Returns:
        The CKF's :class:`.ckf.UpdateResult` (``accepted[:k]``: pseudoranges).

    Raises:
        CholeskyError: the covariance could not be factored.

    Notes:
        Cao et al., eq. 5 and 6 (models), 17-24 (cubature update).
    """
    models = [pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo)]
    z = [prep.pr]
    var = [prep.sigma_pr**2]
    ridx = np.flatnonzero(np.isfinite(prep.rate))
    if ridx.size:
        models.append(pseudorange_rate_model(prep.sat_pos[ridx], prep.sat_vel[ridx], prep.sat_drift[ridx]))
        z.append(prep.rate[ridx])
        var.append(prep.sigma_rate[ridx] ** 2)
    return ckf.update(
        np.concatenate(z),
        np.concatenate(var),
        _shifted(stack_models(models), nominal),
        gate_nis,
        max_iterations=params.max_update_iterations,
        nonlinearity_threshold=params.nonlinearity_threshold,
    )


def _shifted(hx: MeasurementModel, nominal: np.ndarray) -> MeasurementModel:
    """The model of the error state: ``hx(points + nominal)``."""

    def h(points: np.ndarray) -> np.ndarray:
        return hx(points + nominal)

    return h

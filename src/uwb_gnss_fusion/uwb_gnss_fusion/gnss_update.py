"""The GNSS update of the fusion filter: satellite weights, the common-mode screen, the CKF update.

Pure core (no rclpy).

* :func:`prepare_epoch`: the satellites the filter may apply (:mod:`.input_checks`, elevation
  mask) with their 1-sigmas from C/N0 and the jammer-to-signal ratio (Cao et al., eq. 4 and 12,
  :mod:`gnss_common.jamming_weights`), per signal (chip rate and wavelength of each carrier);
* :func:`screen_common_mode`: drop pseudoranges (and rates) whose innovation departs from the
  epoch's common-mode (clock) innovation (:mod:`.robust_screen`; beyond the paper);
  with ``find_clock_step``, a step of the receiver clock found from the same consensus
  (:mod:`.clock_steps`; beyond the paper);
* :func:`update_gnss`: pseudoranges and pseudorange rates in one gated cubature update
  (Cao et al., eq. 5, 6 and 17-24);
* :func:`clock_offset_from_residuals`: the receiver clock from the pseudorange residuals.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ, GPS_L1_FREQUENCY_HZ
from gnss_common.coordinates import azimuth_elevation
from gnss_common.jamming_weights import dll_jitter_m, effective_cn0_dbhz, fll_jitter_mps, measurement_sigmas
from gnss_common.observations import BEIDOU, GLONASS, GPS, GnssEpoch

from .ckf import CubatureKalmanFilter, UpdateResult
from .clock_steps import CLOCK_STEP_MIN_SATELLITES, NO_CLOCK_STEP, clock_free_innovations, clock_step_of_consensus
from .fusion_params import FusionParams
from .input_checks import Count, PreparedEpoch, usable_observations, validate_satellites
from .measurement_models import MeasurementModel, pseudorange_model, pseudorange_rate_model, stack_models
from .robust_screen import common_mode_screen, projected_variance

MIN_SIN_ELEVATION = math.sin(math.radians(5.0))
"""Floor of sin(elevation) in the elevation weighting of satellites without C/N0 (caps the factor at 11.5)."""

_BANDS_HZ = (
    # (lowest carrier, highest carrier, chip rate of the open signal; BeiDou's own where it differs)
    (1_573.0e6, 1_578.0e6, 1.023e6, 1.023e6),  # GPS/QZSS L1 C/A, Galileo E1 OS, BeiDou B1C
    (1_559.0e6, 1_563.0e6, 2.046e6, 2.046e6),  # BeiDou B1I
    (1_592.0e6, 1_610.0e6, 0.511e6, 0.511e6),  # GLONASS G1 FDMA (channels -7..+13)
    (1_225.0e6, 1_230.0e6, 1.023e6, 1.023e6),  # GPS/QZSS L2C (two 511.5 kchip/s codes multiplexed)
    (1_237.0e6, 1_254.0e6, 0.511e6, 0.511e6),  # GLONASS G2 FDMA
    (1_174.0e6, 1_179.0e6, 10.23e6, 10.23e6),  # GPS/QZSS L5, Galileo E5a, BeiDou B2a
    (1_189.0e6, 1_195.0e6, 10.23e6, 10.23e6),  # Galileo E5 AltBOC
    (1_200.0e6, 1_204.0e6, 10.23e6, 10.23e6),  # GLONASS G3 CDMA
    (1_205.0e6, 1_209.0e6, 10.23e6, 2.046e6),  # Galileo E5b, BeiDou B2I / B2b
    (1_266.0e6, 1_271.0e6, 10.23e6, 10.23e6),  # BeiDou B3I
    (1_276.0e6, 1_281.0e6, 5.115e6, 5.115e6),  # Galileo E6, QZSS L6
)


def signal_scales(system: np.ndarray, carrier_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chip rate and wavelength factor of each satellite's signal, from its system and carrier.

    Args:
        system: constellation codes, (k,).
        carrier_hz: carrier frequencies, Hz, (k,) (NaN, 0 or an unlisted band: GPS L1 C/A assumed,
            as ``rfi_msgs/GnssMeasurement`` says; GLONASS without a channel: G1 at channel 0).

    Returns:
        ``(chip_rate_hz (k,), wavelength / GPS L1 wavelength (k,))``. BOC signals (Galileo E1,
        BeiDou B1C) get the chip rate of their code, i.e. the BPSK jitter formula, a conservative
        bound (their split spectrum tracks better).
    """
    f = np.asarray(carrier_hz, dtype=float)
    sysc = np.asarray(system)
    f = np.where(np.isfinite(f) & (f > 0.0), f, np.where(sysc == GLONASS, 1_602.0e6, GPS_L1_FREQUENCY_HZ))
    chip = np.full(f.shape, GPS_CA_CHIP_RATE_HZ)
    for lo, hi, rate, rate_bds in _BANDS_HZ:
        inside = (f >= lo) & (f <= hi)
        if inside.any():
            chip = np.where(inside, np.where(sysc == BEIDOU, rate_bds, rate), chip)
    return chip, GPS_L1_FREQUENCY_HZ / f


def signal_sigmas(
    cn0_dbhz: np.ndarray, js_db: float, params: FusionParams, chip_rate_hz: np.ndarray | None,
    wavelength_scale: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pseudorange and pseudorange-rate 1-sigmas of each signal for C/N0 and J/S (Cao et al., eq. 4, 12).

    Args:
        cn0_dbhz: jammer-free C/N0 per satellite, dB-Hz, (k,).
        js_db: J/S, dB (NaN: none).
        params: ``loop``, ``jammer_quality_factor``.
        chip_rate_hz / wavelength_scale: of each signal (:func:`signal_scales`); None: all GPS
            L1 C/A, exactly :func:`gnss_common.jamming_weights.measurement_sigmas`.

    Returns:
        ``(sigma_pr_m (k,), sigma_rate_mps (k,))``.

    Notes:
        Per signal: eq. 4 with the signal's chip rate ``f_c`` (the spectral separation of a
        jammer from a faster code is larger), the DLL jitter of Kaplan & Hegarty eq. 8.53 in chips
        times the signal's chip length, and the FLL jitter (eq. 8.47) in Hz times the signal's
        wavelength (Cao et al., eq. 6: GLONASS per channel). The one J/S reported by the monitor is
        applied to every signal (conservative where the jammer does not cover another band).
    """
    if chip_rate_hz is None or wavelength_scale is None:
        s_pr, s_rate, _ = measurement_sigmas(cn0_dbhz, js_db, params.loop, params.jammer_quality_factor)
        return s_pr, s_rate
    js = -math.inf if math.isnan(js_db) else js_db
    cn0_eff = np.empty(np.shape(cn0_dbhz))
    for rate in np.unique(chip_rate_hz):
        sel = chip_rate_hz == rate
        cn0_eff[sel] = effective_cn0_dbhz(np.asarray(cn0_dbhz)[sel], js, params.jammer_quality_factor, float(rate))
    loop = params.loop
    s_pr = np.hypot(dll_jitter_m(cn0_eff, loop) * (GPS_CA_CHIP_RATE_HZ / chip_rate_hz), loop.code_floor_m)
    s_rate = np.hypot(fll_jitter_mps(cn0_eff, loop) * wavelength_scale, loop.rate_floor_mps)
    return s_pr, s_rate


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
    rows = validate_satellites(usable_observations(epoch.observations, count, p.multi_gnss), p, count)
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
    systems = [r[0].constellation for r in rows]
    # None: all GPS (the single-clock model; no per-satellite system array needed)
    system = None if all(sc == GPS for sc in systems) else np.array(systems, dtype=np.int64)
    carriers = [r[0].carrier_frequency_hz for r in rows]
    chip: np.ndarray | None = None
    lam: np.ndarray | None = None
    # all on L1 at 1.023 Mchip/s (or unknown carriers: GPS L1 C/A assumed): the paper's weights
    # exactly, without the band look-up (the common GPS-only case, checked on Python lists)
    if not (all(sc != GLONASS for sc in systems) and all(not c > 0.0 or c == GPS_L1_FREQUENCY_HZ for c in carriers)):
        chip_all, lam_all = signal_scales(np.array(systems), np.array(carriers, dtype=float))
        if not ((chip_all == GPS_CA_CHIP_RATE_HZ).all() and (lam_all == 1.0).all()):
            chip, lam = chip_all, lam_all
    has_cn0 = np.array([math.isfinite(r[0].cn0_dbhz) for r in rows])
    cn0 = np.array([r[0].cn0_dbhz if ok else p.nominal_cn0_dbhz for r, ok in zip(rows, has_cn0, strict=True)])
    s_pr, s_rate = signal_sigmas(cn0, math.nan, p, chip, lam)
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
        s_pr_j, s_rate_j = signal_sigmas(np.full(n, p.nominal_cn0_dbhz), js_db, p, chip, lam)
        s_pr = np.maximum(s_pr, s_pr_j)
        s_rate = np.maximum(s_rate, s_rate_j)
    if p.pseudorange_broadcast_std_m > 0.0:
        # The C/N0 (eq. 12) gives the tracking noise only; each satellite's broadcast orbit and clock
        # error (SISRE) is independent of it and of the elevation: added in quadrature, as the
        # project's SPP does (gnss_common.spp.code_variance_m2, ``sigma_broadcast_m``).
        s_pr = np.hypot(s_pr, p.pseudorange_broadcast_std_m)
    given_pr = np.array([r[0].pseudorange_std_m for r in rows])
    given_rate = np.array([r[0].pseudorange_rate_std_mps for r in rows])
    ok_pr = np.isfinite(given_pr) & (given_pr > 0.0)
    ok_rate = np.isfinite(given_rate) & (given_rate > 0.0)
    s_pr = np.where(ok_pr, np.maximum(given_pr, s_pr) if math.isfinite(js_db) else given_pr, s_pr)
    s_rate = np.where(ok_rate, np.maximum(given_rate, s_rate) if math.isfinite(js_db) else given_rate, s_rate)
    if system is not None and p.glonass_pseudorange_error_factor != 1.0:
        # GLONASS code carries what its sigma from C/N0 does not: each FDMA channel's receiver
        # inter-frequency code bias and a poorer broadcast orbit/clock (ESBC00DNK: spread of the
        # per-satellite means 1.26 m against GPS's 0.63 m). RTKLIB's convention (EFACT_GLO 1.5,
        # pntpos.c varerr) scales the sigma (the model's, the jammer's or the receiver's).
        s_pr = np.where(system == GLONASS, s_pr * p.glonass_pseudorange_error_factor, s_pr)
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
        system=system,
        sat_id=np.array([r[0].constellation * 1000 + r[0].svid for r in rows], dtype=np.int64),
    )


def clock_offset_from_residuals(
    prep: PreparedEpoch, nominal: np.ndarray, bias_column: np.ndarray | None = None, rows: np.ndarray | None = None,
    error_column: np.ndarray | None = None,
) -> float:
    """Median pseudorange residual at the nominal state, m: the receiver clock correction when the
    position is trusted (a UWB start, or a GNSS-declared divergence that UWB does not confirm), or
    with ``rows`` one system's satellites and no bias column, that system's inter-system bias.

    Args:
        prep: the epoch's satellites.
        nominal: the nominal state, (n,).
        bias_column: inter-system bias column of each satellite (-1: none), as
            :func:`.measurement_models.pseudorange_model`; None: no bias applied.
        rows: bool mask of the satellites to take the median over (None: all).
        error_column: correlated-error state column of each satellite (None: none).

    Notes:
        Cao et al., eq. 5 with the position fixed; the median ignores the jammed outliers.
    """
    hx0 = pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column, error_column)
    res = prep.pr - hx0(nominal[None, :])[0]
    return float(np.median(res if rows is None else res[rows]))


def screen_common_mode(
    prep: PreparedEpoch, nominal: np.ndarray, p: np.ndarray, gate_nis: float, count: Count,
    bias_column: np.ndarray | None = None, error_column: np.ndarray | None = None, find_clock_step: bool = False,
) -> tuple[PreparedEpoch, int, tuple[float, bool, float]]:
    """Drop the pseudoranges (and mark the rates) that fail the common-mode innovation screen.

    Args:
        prep: the epoch's satellites.
        nominal: predicted nominal state, (n,).
        p: predicted error covariance, (n, n) (read only).
        gate_nis: the per-measurement gate.
        count: the rejection counter (``common_mode_pseudorange``, ``common_mode_doppler``).
        bias_column: inter-system bias column of each satellite (-1: GPS); None: all GPS.
        error_column: correlated-error state column of each satellite (None: none); its
            estimate is removed from the innovation and its variance added.
        find_clock_step: also test the consensus for a receiver clock step (:func:`.clock_steps.receiver_clock_step`,
            from the same innovations: no second computation).

    Returns:
        (the epoch without the dropped pseudoranges, how many were dropped, the clock step as
        :func:`.clock_steps.receiver_clock_step` returns it, :data:`NO_CLOCK_STEP` unless ``find_clock_step``).
        The screen does not depend on the clock (it removes the consensus's common innovation), so
        its result holds after the clock is moved by the step.

    Notes:
        :mod:`.robust_screen`: innovations at the predicted state, the median removed, tested
        with ``R_i + e_i^T P e_i`` (position covariance for pseudoranges, velocity covariance
        for rates). With several systems the innovations have each system's bias estimate removed
        (the model's), and its variance ``P_bb`` is added to the variance of that system's
        satellites: one consensus over all systems, so that a system with one or two satellites is
        screened as well. The rates carry no inter-system bias.
    """
    x = nominal[None, :]
    nu, var, los = clock_free_innovations(prep, nominal, p, bias_column, error_column)
    keep = common_mode_screen(nu, var, gate_nis)
    step = NO_CLOCK_STEP
    if find_clock_step and nu.size >= CLOCK_STEP_MIN_SATELLITES:
        step = clock_step_of_consensus(nu, var, keep, prep.sigma_pr, float(p[6, 6]), gate_nis)
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
        return (prep if rate is prep.rate else replace(prep, rate=rate)), 0, step
    count("common_mode_pseudorange", n_drop)
    return prep.subset(keep, rate), n_drop, step


def update_gnss(
    ckf: CubatureKalmanFilter, nominal: np.ndarray, prep: PreparedEpoch, gate_nis: float, params: FusionParams,
    bias_column: np.ndarray | None = None, error_column: np.ndarray | None = None,
) -> UpdateResult:
    """One gated cubature update with the epoch's pseudoranges and usable pseudorange rates.

    Args:
        ckf: the error-state filter (error mean zero; the caller folds the correction in).
        nominal: the nominal state the error state is relative to, (n,).
        prep: the satellites (k pseudoranges, then the finite rates, in that order).
        gate_nis: the per-measurement gate.
        params: ``max_update_iterations``, ``nonlinearity_threshold``.
        bias_column: inter-system bias column of each satellite (-1: GPS); None: all GPS.
        error_column: correlated-error state column of each satellite (None: none).

    Returns:
        The CKF's :class:`.ckf.UpdateResult` (``accepted[:k]``: pseudoranges).

    Raises:
        CholeskyError: the covariance could not be factored.

    Notes:
        Cao et al., eq. 5 and 6 (models), 17-24 (cubature update).
    """
    models = [pseudorange_model(prep.sat_pos, prep.sat_clk, prep.iono, prep.tropo, bias_column, error_column)]
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

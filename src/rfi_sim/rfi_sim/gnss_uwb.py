"""Half-simulated GNSS + UWB measurements of a receiver under chirp jamming (Cao et al.).

Satellite geometry comes from a pluggable source (``rfi_sim.satellite_geometry``; by default a
real GPS broadcast ephemeris read with ``gnss_common.rinex`` / ``gnss_common.ephemeris``); the
receiver is static at a known ECEF position (or moves from it on a straight line at a constant
velocity, the UWB tag with it) with a clock drawn from an h-coefficient model
(``gnss_common.clock_model``); GPS L1 pseudoranges and pseudorange rates come at 5 Hz; three UWB
anchors around the tag (the paper's reference ranges 11.71, 13.00 and 11.26 m) range at 20 Hz each
with centimetre noise; jamming at a given J/S lowers each satellite's C/N0 by Cao et al. eq. 4,
which sets the code (DLL) and frequency (FLL) tracking jitter (Kaplan & Hegarty), drops satellites
below a loss-of-lock threshold, and adds bursts of gross pseudorange outliers (tens to hundreds of
metres) from 6 dB J/S on, as the paper observed (Sec. IV-2, Fig. 4).
Everything is seeded; the output is deterministic for a given :class:`GnssUwbScenario`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gnss_common.clock_model import ClockHCoefficients, simulate_clock
from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import azimuth_elevation, ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.earth_rotation import flight_rotation, rotate_about_z
from gnss_common.gps_time import gps_ns_to_ros_stamp_ns, gps_to_gps_ns, gps_to_ros_stamp_ns
from gnss_common.jamming_weights import TrackingLoopParams, measurement_sigmas
from gnss_common.observations import GPS, GnssEpoch, SatelliteObservation, UwbRangeMeasurement

# The geometry sources live in rfi_sim.satellite_geometry; imported from here by the scenario streams,
# benchmarks and tests, hence the re-export.
from rfi_sim.satellite_geometry import BroadcastGeometry, GeometrySource, SatelliteSnapshot  # noqa: F401

JSR_SCENARIOS_DB = (None, -10.0, -2.0, 6.0, 14.0, 22.0, 30.0)
"""The paper's scenarios: no jamming, then J/S in dB (Cao et al., Table 1)."""

ARL1_ECEF_M = (-740289.918, -5457071.734, 3207245.542)
"""Static receiver: ARL1 (NGA station 85408, Austin TX) RINEX header position, ECEF, m."""

PAPER_ANCHOR_RANGES_M = (11.71, 13.00, 11.26)
"""Reference tag-anchor ranges of the paper's three UWB anchors, m (Cao et al., Sec. IV-1)."""


@dataclass(frozen=True)
class JammingEffect:
    """How a J/S degrades tracking in the simulator.

    Attributes:
        quality_factor: Q of Cao et al. eq. 4 (1: narrowband/swept jammer).
        loss_of_lock_dbhz: satellites whose measured effective C/N0 is below are not tracked, dB-Hz.
        cn0_estimate_std_db: 1-sigma of the receiver's C/N0 estimate, dB.
        outlier_onset_jsr_db: no gross outliers below this J/S, dB (paper: from 6 dB on).
        outlier_burst_rate_per_s: burst starts per satellite per second, at the onset J/S.
        outlier_rate_growth_per_db: the burst rate multiplies by ``10**(growth * (jsr - onset) / 10)``.
        outlier_burst_duration_s: (min, max) burst length, s (uniform).
        outlier_magnitude_m: (min, max) |pseudorange error| during a burst, m (log-uniform).
        doppler_outlier_mps: (min, max) |pseudorange-rate error| during a burst, m/s (log-uniform).
    """

    quality_factor: float = 1.0
    loss_of_lock_dbhz: float = 30.0
    cn0_estimate_std_db: float = 0.7
    outlier_onset_jsr_db: float = 6.0
    outlier_burst_rate_per_s: float = 0.002
    outlier_rate_growth_per_db: float = 1.0
    outlier_burst_duration_s: tuple[float, float] = (0.2, 2.0)
    outlier_magnitude_m: tuple[float, float] = (20.0, 300.0)
    doppler_outlier_mps: tuple[float, float] = (0.5, 10.0)


@dataclass(frozen=True)
class GnssUwbScenario:
    """One simulated run.

    Attributes:
        jsr_db: jammer-to-signal ratio at the antenna, dB (None: no jammer).
        duration_s: length, s.
        seed: seed of every random draw.
        start_week: continuous GPS week of the first epoch.
        start_tow_s: GPS time of week of the first epoch, s.
        receiver_ecef_m: antenna (and tag) position at the first epoch, ECEF, m.
        receiver_velocity_enu_mps: constant antenna (and tag) velocity, m/s, east-north-up at
            ``receiver_ecef_m``: the receiver moves on the straight ECEF line
            ``receiver_ecef_m + v_ecef t`` (``v_ecef = R^T v_enu``, R the ENU rotation there,
            t the time since the first epoch). (0, 0, 0): static, and the output is that of the
            static simulator draw for draw.
        anchor_origin_ecef_m: point the anchors are placed around, ECEF, m (None:
            ``receiver_ecef_m``). A run that continues another one (the scenario stream's
            phases) gives the first run's start, so the anchors stay where they are.
        gnss_rate_hz: GNSS epoch rate, Hz.
        uwb_rate_hz: ranging rate per anchor, Hz.
        anchor_ranges_m: true tag-anchor distances, m (one anchor each).
        anchor_azimuths_deg: anchor azimuths around the tag, deg from north.
        anchor_up_m: anchor heights above the tag, m.
        uwb_noise_std_m: UWB range noise 1-sigma, m.
        uwb_reported_std_m: range_std_m written in the messages, m (NaN: let the filter decide).
        elevation_mask_deg: satellites below are not tracked, deg.
        cn0_zenith_dbhz, cn0_horizon_dbhz: jammer-free C/N0 at 90 and 0 deg elevation, dB-Hz
            (linear in sin(elevation) between).
        correlated_error_std_m: 1-sigma of a per-satellite first-order Gauss-Markov pseudorange
            error (residual atmosphere, multipath, orbit), m.
        correlated_error_tau_s: its correlation time, s.
        clock: receiver clock h-coefficients (default: compensated crystal, Brown & Hwang).
        clock_bias0_s, clock_drift0: initial receiver clock offset (s) and frequency offset (s/s).
        loop: tracking-loop parameters of the jitter model.
        jamming: :class:`JammingEffect`.
        report_sigmas: write pseudorange_std_m / pseudorange_rate_std_mps from the receiver's
            own C/N0 into the messages (False: NaN, the filter decides).
    """

    jsr_db: float | None = None
    duration_s: float = 360.0
    seed: int = 0
    start_week: int = 1854
    start_tow_s: float = 3600.0
    receiver_ecef_m: tuple[float, float, float] = ARL1_ECEF_M
    receiver_velocity_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    anchor_origin_ecef_m: tuple[float, float, float] | None = None
    gnss_rate_hz: float = 5.0
    uwb_rate_hz: float = 20.0
    anchor_ranges_m: tuple[float, ...] = PAPER_ANCHOR_RANGES_M
    anchor_azimuths_deg: tuple[float, ...] = (20.0, 140.0, 260.0)
    anchor_up_m: tuple[float, ...] = (1.5, -0.5, 0.8)
    uwb_noise_std_m: float = 0.03
    uwb_reported_std_m: float = math.nan
    elevation_mask_deg: float = 10.0
    cn0_zenith_dbhz: float = 49.0
    cn0_horizon_dbhz: float = 34.0
    correlated_error_std_m: float = 0.7
    correlated_error_tau_s: float = 60.0
    clock: ClockHCoefficients = field(default_factory=lambda: ClockHCoefficients(h0=2e-19, h_minus2=2e-20))
    clock_bias0_s: float = 1.0e-6
    clock_drift0: float = 5.0e-8
    loop: TrackingLoopParams = field(default_factory=TrackingLoopParams)
    jamming: JammingEffect = field(default_factory=JammingEffect)
    report_sigmas: bool = False

    def __post_init__(self) -> None:
        if not (self.duration_s > 0 and self.gnss_rate_hz > 0 and self.uwb_rate_hz > 0):
            raise ValueError("duration_s, gnss_rate_hz and uwb_rate_hz must be > 0")
        n = len(self.anchor_ranges_m)
        if len(self.anchor_azimuths_deg) != n or len(self.anchor_up_m) != n:
            raise ValueError("anchor_ranges_m, anchor_azimuths_deg and anchor_up_m must have equal length")
        for r, u in zip(self.anchor_ranges_m, self.anchor_up_m, strict=True):
            if not (r > abs(u)):
                raise ValueError(f"anchor range {r} must exceed its height offset {u}")
        if self.jsr_db is not None and not math.isfinite(self.jsr_db):
            raise ValueError("jsr_db must be finite or None")
        if not (
            self.uwb_noise_std_m >= 0 and self.correlated_error_std_m >= 0 and self.correlated_error_tau_s > 0
        ):
            raise ValueError("noise standard deviations must be >= 0 and tau > 0")
        vel = np.asarray(self.receiver_velocity_enu_mps, dtype=float)
        if vel.shape != (3,) or not np.all(np.isfinite(vel)):
            raise ValueError(f"receiver_velocity_enu_mps must be 3 finite numbers, m/s, got {vel.tolist()}")
        origin = self.anchor_origin_ecef_m
        if origin is not None and (np.shape(origin) != (3,) or not np.all(np.isfinite(origin))):
            raise ValueError(f"anchor_origin_ecef_m must be None or 3 finite numbers, m, got {origin!r}")


@dataclass(frozen=True)
class GnssUwbTruth:
    """Truth of a run.

    Attributes:
        receiver_ecef_m: antenna position at the first epoch, ECEF, m, shape (3,).
        anchor_ecef_m: anchor positions, ECEF, m, shape (k, 3), row j is anchor id ``f"A{j+1}"``.
        gnss_stamps_ns: stamps of the GNSS epochs, ns, shape (n,).
        clock_bias_m: true receiver c*dt at the GNSS epochs, m, shape (n,).
        clock_drift_mps: true receiver c*ddt at the GNSS epochs, m/s, shape (n,).
        outlier_mask: per GNSS epoch, number of satellites inside an outlier burst, shape (n,).
        satellites_tracked: per GNSS epoch, satellites in the epoch, shape (n,).
        receiver_velocity_ecef_mps: constant antenna velocity, ECEF, m/s, shape (3,) (zeros: static).
        receiver_ecef_m_per_epoch: antenna position at each GNSS epoch's receive time, ECEF, m,
            shape (n, 3) (every row ``receiver_ecef_m`` when static).
    """

    receiver_ecef_m: np.ndarray
    anchor_ecef_m: np.ndarray
    gnss_stamps_ns: np.ndarray
    clock_bias_m: np.ndarray
    clock_drift_mps: np.ndarray
    outlier_mask: np.ndarray
    satellites_tracked: np.ndarray
    receiver_velocity_ecef_mps: np.ndarray
    receiver_ecef_m_per_epoch: np.ndarray


@dataclass(frozen=True)
class GnssUwbRun:
    """Output of :func:`simulate`: time-ordered GNSS epochs, UWB ranges and the truth."""

    scenario: GnssUwbScenario
    gnss_epochs: tuple[GnssEpoch, ...]
    uwb_ranges: tuple[UwbRangeMeasurement, ...]
    truth: GnssUwbTruth

    def messages(
        self, anchor_ids: tuple[str, ...] | None = None, gnss: bool = True
    ) -> list[GnssEpoch | UwbRangeMeasurement]:
        """All messages merged in stamp order (a GNSS epoch before a UWB range at the same stamp).

        Args:
            anchor_ids: keep only these anchors (None: all).
            gnss: include the GNSS epochs.
        """
        items: list[tuple[int, int, GnssEpoch | UwbRangeMeasurement]] = []
        if gnss:
            items += [(e.stamp_ns, 0, e) for e in self.gnss_epochs]
        items += [
            (u.stamp_ns, 1, u) for u in self.uwb_ranges if anchor_ids is None or u.anchor_id in anchor_ids
        ]
        items.sort(key=lambda t: (t[0], t[1]))
        return [t[2] for t in items]


def anchor_positions_ecef(receiver_ecef_m: np.ndarray, ranges_m, azimuths_deg, up_m) -> np.ndarray:
    """Anchors placed around the tag at given ranges, azimuths and heights.

    Args:
        receiver_ecef_m: tag position, ECEF, m, shape (3,).
        ranges_m, azimuths_deg, up_m: per anchor, m, deg, m.

    Returns:
        Anchor ECEF positions, m, shape (k, 3).
    """
    lat, lon, _ = ecef_to_geodetic(np.asarray(receiver_ecef_m, float))
    rot = ecef_to_enu_rotation(lat, lon)
    out = []
    for r, az, u in zip(ranges_m, azimuths_deg, up_m, strict=True):
        horiz = math.sqrt(r * r - u * u)
        enu = np.array([horiz * math.sin(math.radians(az)), horiz * math.cos(math.radians(az)), u])
        out.append(np.asarray(receiver_ecef_m, float) + rot.T @ enu)
    return np.array(out)


def receiver_velocity_ecef(receiver_ecef_m: np.ndarray, velocity_enu_mps) -> np.ndarray:
    """ECEF velocity ``R^T v_enu`` of an ENU velocity at a point, m/s, shape (3,) (R: ENU rotation)."""
    lat, lon, _ = ecef_to_geodetic(np.asarray(receiver_ecef_m, float))
    return ecef_to_enu_rotation(lat, lon).T @ np.asarray(velocity_enu_mps, dtype=float)


@dataclass(frozen=True)
class _EpochSky:
    """What every satellite of one epoch looks like from the receiver (rows = the geometry's satellites).

    Attributes: ``snap`` the geometry's states; ``p_tx`` positions at transmission in the ECEF
    frame of transmission, m; ``v_rot`` velocities rotated into the frame of reception, m/s;
    ``geom`` ranges, m; ``los`` receiver-to-satellite unit vectors; ``el`` elevations, rad;
    ``sat_clk_m``, ``sat_drift_mps`` satellite clock c dt_s (m) and c ddt_s (m/s); ``iono``,
    ``tropo`` delays, m; ``cn0_clean`` jammer-free C/N0, dB-Hz.
    """

    snap: SatelliteSnapshot
    p_tx: np.ndarray
    v_rot: np.ndarray
    geom: np.ndarray
    los: np.ndarray
    el: np.ndarray
    sat_clk_m: np.ndarray
    sat_drift_mps: np.ndarray
    iono: np.ndarray
    tropo: np.ndarray
    cn0_clean: np.ndarray


def _epoch_sky(sc: GnssUwbScenario, geometry: GeometrySource, week: int, tow: float, rx: np.ndarray,
               iono_alpha: np.ndarray | None, iono_beta: np.ndarray | None) -> _EpochSky:
    """The satellites seen at receive time ``(week, tow)`` from ``rx`` (ECEF, m): light-time
    iteration with the Earth rotating during the flight, transmit-time ECEF positions."""
    from gnss_common.corrections import klobuchar_delay_s, troposphere_delay_m

    lat, lon, h = ecef_to_geodetic(rx)
    snap = geometry(week, tow - 0.075)
    tau = np.full(snap.prn.size, 0.075)
    for _ in range(3):
        p_tx = snap.position_ecef_m + snap.velocity_ecef_mps * (0.075 - tau)[:, None]
        p_rot = rotate_about_z(p_tx, *flight_rotation(tau))
        tau = np.linalg.norm(p_rot - rx, axis=1) / SPEED_OF_LIGHT_MPS
    p_tx = snap.position_ecef_m + snap.velocity_ecef_mps * (0.075 - tau)[:, None]
    cos_a, sin_a = flight_rotation(tau)
    p_rot = rotate_about_z(p_tx, cos_a, sin_a)
    v_rot = rotate_about_z(snap.velocity_ecef_mps, cos_a, sin_a)
    geom = np.linalg.norm(p_rot - rx, axis=1)
    los = (p_rot - rx) / geom[:, None]
    az, el = azimuth_elevation(rx, p_rot)
    az = np.atleast_1d(az)
    el = np.atleast_1d(el)
    sat_clk_m = SPEED_OF_LIGHT_MPS * (snap.clock_bias_s + snap.clock_drift_s_per_s * (0.075 - tau))
    if iono_alpha is not None and iono_beta is not None:
        iono = SPEED_OF_LIGHT_MPS * klobuchar_delay_s(iono_alpha, iono_beta, lat, lon, az, el, tow)
    else:
        iono = np.zeros_like(geom)
    cn0_clean = sc.cn0_horizon_dbhz + (sc.cn0_zenith_dbhz - sc.cn0_horizon_dbhz) * np.sin(np.clip(el, 0.0, None))
    return _EpochSky(snap, p_tx, v_rot, geom, los, el, sat_clk_m, SPEED_OF_LIGHT_MPS * snap.clock_drift_s_per_s,
                     iono, troposphere_delay_m(lat, h, el), cn0_clean)


class _OutlierBursts:
    """Bursts of gross pseudorange and rate outliers per satellite (:class:`JammingEffect`).

    A burst starts at an epoch with probability ``rate dt`` (rate grown with the J/S above the
    onset), lasts a uniform time and carries a log-uniform error of one sign for code and rate.
    """

    def __init__(self, jam: JammingEffect, jsr_db: float | None, dt_s: float) -> None:
        self.jam = jam
        self.dt_s = dt_s
        self.rate_per_s = 0.0
        if jsr_db is not None and jsr_db >= jam.outlier_onset_jsr_db:
            self.rate_per_s = jam.outlier_burst_rate_per_s * 10.0 ** (
                jam.outlier_rate_growth_per_db * (jsr_db - jam.outlier_onset_jsr_db) / 10.0
            )
        self.until_s: dict[int, float] = {}
        self.error: dict[int, tuple[float, float]] = {}

    def __call__(self, prn: int, t_s: float, u: np.ndarray) -> tuple[float, float] | None:
        """The (pseudorange m, rate m/s) error of ``prn`` at ``t_s`` (None: no burst); ``u``: 5 uniforms."""
        if self.rate_per_s <= 0.0:
            return None
        jam = self.jam
        if t_s >= self.until_s.get(prn, -1.0) and u[0] < self.rate_per_s * self.dt_s:
            lo, hi = jam.outlier_burst_duration_s
            self.until_s[prn] = t_s + lo + (hi - lo) * u[1]
            mlo, mhi = jam.outlier_magnitude_m
            dlo, dhi = jam.doppler_outlier_mps
            sign = 1.0 if u[2] < 0.5 else -1.0
            self.error[prn] = (sign * mlo * (mhi / mlo) ** u[3], sign * dlo * (dhi / dlo) ** u[4])
        return self.error[prn] if t_s < self.until_s.get(prn, -1.0) else None


def _uwb_ranges(sc: GnssUwbScenario, anchors: np.ndarray, rx: np.ndarray, v_ecef: np.ndarray,
                rng: np.random.Generator) -> list[UwbRangeMeasurement]:
    """The UWB ranges of the run: each anchor at ``uwb_rate_hz``, interleaved, to the tag at
    ``rx + v_ecef t`` (t from the first epoch, s); Gaussian noise drawn from ``rng``."""
    n_u = int(round(sc.duration_s * sc.uwb_rate_hz))
    k_a = anchors.shape[0]
    offsets_ns = [int(round(j / (k_a * sc.uwb_rate_hz) * 1e9)) for j in range(k_a)]
    # UWB times are stepped on the GPS-scale axis (as the GNSS epochs) and stamped in ROS time by
    # the same conversion, so both line up even across a leap second.
    t0_gps_ns = gps_to_gps_ns(sc.start_week, sc.start_tow_s)
    noise = sc.uwb_noise_std_m * rng.standard_normal((n_u, k_a))
    if np.any(v_ecef != 0.0):
        t_s = (np.round(np.arange(n_u) / sc.uwb_rate_hz * 1e9)[:, None] + np.array(offsets_ns)[None, :]) * 1e-9
        true_r = np.linalg.norm(anchors[None, :, :] - (rx + v_ecef * t_s[:, :, None]), axis=2)
    else:
        true_r = np.broadcast_to(np.linalg.norm(anchors - rx, axis=1), (n_u, k_a))
    uwb = []
    for m in range(n_u):
        base = t0_gps_ns + int(round(m / sc.uwb_rate_hz * 1e9))
        for j in range(k_a):
            uwb.append(
                UwbRangeMeasurement(
                    stamp_ns=gps_ns_to_ros_stamp_ns(base + offsets_ns[j]),
                    anchor_id=f"A{j + 1}",
                    anchor_position_m=anchors[j].copy(),
                    frame_id="earth",
                    range_m=float(true_r[m, j] + noise[m, j]),
                    range_std_m=sc.uwb_reported_std_m,
                )
            )
    return uwb


def simulate(
    scenario: GnssUwbScenario,
    geometry: GeometrySource,
    iono_alpha: np.ndarray | None = None,
    iono_beta: np.ndarray | None = None,
) -> GnssUwbRun:
    """Simulate one run.

    Args:
        scenario: :class:`GnssUwbScenario`.
        geometry: satellite states source, e.g. :class:`BroadcastGeometry`.
        iono_alpha, iono_beta: Klobuchar coefficients (shape (4,)); None: no ionosphere (and
            ``ionosphere_delay_m`` = 0 in the messages).

    Returns:
        :class:`GnssUwbRun`.

    Notes:
        Pseudorange (Cao et al., eq. 5): ``|R(w tau) p_s(t - tau) - p_r(t)| + c dt_r - c dt_s + I + T
        + e_corr + e_DLL (+ outlier)``, with the exact light-time iteration and Earth rotation, the
        DLL jitter of the effective C/N0 (eq. 4; Kaplan & Hegarty 8.53), a Gauss-Markov correlated
        error; the messages report the same I, T (from ``gnss_common.corrections``) so the only
        unmodelled errors are e_corr, the jitter and the outliers. Pseudorange rate (eq. 6),
        ``e . (v_s - v_r) + c ddt_r - c ddt_s`` (e the receiver-to-satellite unit vector, v_r the
        receiver's velocity), with FLL jitter (Kaplan & Hegarty 8.47). UWB (eq. 7) with Gaussian
        noise, to the tag at ``p_r(t) = p_r(0) + v_r t`` at each range's own time.
    """
    sc = scenario
    rng = np.random.default_rng(sc.seed)
    rx0 = np.asarray(sc.receiver_ecef_m, dtype=float)
    v_ecef = receiver_velocity_ecef(rx0, sc.receiver_velocity_enu_mps)
    dt_g = 1.0 / sc.gnss_rate_hz
    n_ep = int(round(sc.duration_s * sc.gnss_rate_hz))
    x_s, y = simulate_clock(sc.clock, dt_g, n_ep - 1 if n_ep > 1 else 1, seed=sc.seed + 1, x0_s=sc.clock_bias0_s,
                            y0=sc.clock_drift0)
    clk_m = SPEED_OF_LIGHT_MPS * x_s[:n_ep]
    drift_mps = SPEED_OF_LIGHT_MPS * y[:n_ep]
    jam = sc.jamming
    bursts = _OutlierBursts(jam, sc.jsr_db, dt_g)
    phi_gm = math.exp(-dt_g / sc.correlated_error_tau_s)
    q_gm = sc.correlated_error_std_m * math.sqrt(1.0 - phi_gm**2)
    gm_state: dict[int, float] = {}
    epochs: list[GnssEpoch] = []
    stamps = np.zeros(n_ep, dtype=np.int64)
    n_out = np.zeros(n_ep, dtype=int)
    n_trk = np.zeros(n_ep, dtype=int)
    rx_per_epoch = np.tile(rx0, (n_ep, 1))  # receiver at each receive time (bit-exact rx0 when static)
    if np.any(v_ecef != 0.0):
        rx_per_epoch = rx0 + v_ecef * (np.arange(n_ep) * dt_g)[:, None]
    for k in range(n_ep):
        t_rel = k * dt_g
        week = sc.start_week
        tow = sc.start_tow_s + t_rel
        stamp = gps_to_ros_stamp_ns(week, tow)  # header stamp: ROS (UTC) time of the GPS week/tow
        stamps[k] = stamp
        sky = _epoch_sky(sc, geometry, week, tow, rx_per_epoch[k], iono_alpha, iono_beta)
        js = -np.inf if sc.jsr_db is None else sc.jsr_db
        s_pr, s_rate, cn0_eff = measurement_sigmas(sky.cn0_clean, js, sc.loop, jam.quality_factor)
        cn0_meas = cn0_eff + jam.cn0_estimate_std_db * rng.standard_normal(sky.geom.size)
        # Draw all random numbers for every visible satellite, tracked or not, so the sequence of
        # one satellite does not depend on another's lock state.
        n_pr = rng.standard_normal(sky.geom.size)
        n_rate = rng.standard_normal(sky.geom.size)
        n_gm = rng.standard_normal(sky.geom.size)
        u_burst = rng.random((sky.geom.size, 5))
        obs = []
        for i, prn in enumerate(sky.snap.prn.tolist()):
            if math.degrees(sky.el[i]) < sc.elevation_mask_deg:
                gm_state.pop(prn, None)
                continue
            gm = gm_state.get(prn)
            gm = sc.correlated_error_std_m * n_gm[i] if gm is None else phi_gm * gm + q_gm * n_gm[i]
            gm_state[prn] = gm
            if cn0_meas[i] < jam.loss_of_lock_dbhz:
                continue
            err_pr = gm + s_pr[i] * n_pr[i]
            err_rate = s_rate[i] * n_rate[i]
            burst = bursts(prn, t_rel, u_burst[i])
            if burst is not None:
                err_pr += burst[0]
                err_rate += burst[1]
                n_out[k] += 1
            pr = sky.geom[i] + clk_m[k] - sky.sat_clk_m[i] + sky.iono[i] + sky.tropo[i] + err_pr
            rate = float(sky.los[i] @ (sky.v_rot[i] - v_ecef)) + drift_mps[k] - sky.sat_drift_mps[i] + err_rate
            obs.append(SatelliteObservation(
                constellation=GPS, svid=int(prn), pseudorange_m=float(pr), pseudorange_rate_mps=rate,
                cn0_dbhz=float(cn0_meas[i]), satellite_position_ecef_m=sky.p_tx[i].copy(),
                satellite_velocity_ecef_mps=sky.snap.velocity_ecef_mps[i].copy(),
                satellite_clock_bias_m=float(sky.sat_clk_m[i]), satellite_clock_drift_mps=float(sky.sat_drift_mps[i]),
                ionosphere_delay_m=float(sky.iono[i]), troposphere_delay_m=float(sky.tropo[i]),
                pseudorange_std_m=float(s_pr[i]) if sc.report_sigmas else math.nan,
                pseudorange_rate_std_mps=float(s_rate[i]) if sc.report_sigmas else math.nan))
        n_trk[k] = len(obs)
        epochs.append(
            GnssEpoch(stamp_ns=int(stamp), gps_week=week, gps_time_of_week_s=tow, observations=tuple(obs))
        )

    origin = rx0 if sc.anchor_origin_ecef_m is None else np.asarray(sc.anchor_origin_ecef_m, dtype=float)
    anchors = anchor_positions_ecef(origin, sc.anchor_ranges_m, sc.anchor_azimuths_deg, sc.anchor_up_m)
    uwb = _uwb_ranges(sc, anchors, rx0, v_ecef, rng)
    truth = GnssUwbTruth(
        receiver_ecef_m=rx0.copy(),
        anchor_ecef_m=anchors,
        gnss_stamps_ns=stamps,
        clock_bias_m=clk_m,
        clock_drift_mps=drift_mps,
        outlier_mask=n_out,
        satellites_tracked=n_trk,
        receiver_velocity_ecef_mps=v_ecef,
        receiver_ecef_m_per_epoch=rx_per_epoch,
    )
    return GnssUwbRun(scenario=sc, gnss_epochs=tuple(epochs), uwb_ranges=tuple(uwb), truth=truth)

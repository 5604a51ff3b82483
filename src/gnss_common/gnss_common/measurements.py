"""Build :class:`gnss_common.observations.GnssEpoch` objects from RINEX observations and navigation.

For every satellite of an epoch whose system has a broadcast orbit model here (GPS, Galileo,
BeiDou, QZSS: Keplerian, :mod:`gnss_common.ephemeris`; GLONASS: integrated,
:mod:`gnss_common.glonass`), on one signal per system
(:data:`gnss_common.observation_codes.DEFAULT_SIGNALS`: GPS L1, QZSS L1, Galileo E1, BeiDou B1I,
GLONASS G1), on one tracking attribute picked per satellite and epoch by the priority there (GPS:
``C1C`` first, then ``C1X``, ..., ``C1W``; RINEX 2 ``C1``): the code pseudorange, the
pseudorange rate from the Doppler of the same attribute with the sign of
rfi_msgs/GnssMeasurement.msg (``-wavelength * doppler_hz``, positive when the range grows, the
wavelength that of the signal's carrier, per channel for GLONASS), C/N0 of the same attribute
(NaN when absent; never another attribute's), the
satellite state at transmit time from the broadcast ephemeris, and Klobuchar / Saastamoinen
delays (the Klobuchar L1 delay scaled to the signal's carrier) evaluated at a receiver reference
position:
the header APPROX POSITION when present, else a coarse per-epoch single-point fix computed here
(unweighted Gauss-Newton on the raw pseudoranges with Earth-rotation correction).

Satellites that cannot be modelled are skipped and counted by reason in the result, in total and
per constellation (SBAS and NavIC, and systems left out of ``constellations``:
``unsupported_constellation``; no pseudorange on any attribute of the signal's band:
``missing_pseudorange``). The code used for each built satellite is in
:attr:`EpochBuildResult.signal_codes`.

Notes
-----
Cao et al., eq. 5 (pseudorange) and eq. 6 (pseudorange rate = lambda * Doppler, with the sign
convention of the message: rate = -lambda * D for a RINEX Doppler that is positive for an
approaching satellite, RINEX 2.11 sec. 6.4 / RINEX 3.04 sec. 5.2.6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import azimuth_elevation, ecef_to_geodetic
from gnss_common.corrections import (
    ionosphere_free_pseudorange_m,
    ionosphere_frequency_scale,
    klobuchar_delay_s,
    troposphere_delay_m,
)
from gnss_common.ephemeris import (
    EphemerisStore,
    GpsEphemeris,
    earth_rotation_correction,
    pack_ephemerides,
    satellite_states_at_transmit,
)
from gnss_common.glonass import DEFAULT_MAX_AGE_S as GLONASS_DEFAULT_MAX_AGE_S
from gnss_common.glonass import (
    GlonassEphemeris,
    GlonassStore,
    glonass_g1_frequency_hz,
    glonass_states_at_transmit,
    pack_glonass,
)
from gnss_common.gps_time import gps_to_ros_stamp_ns
from gnss_common.observation_codes import DEFAULT_SIGNALS, SignalPreference, select_signal
from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, SBAS, GnssEpoch, SatelliteObservation
from gnss_common.positioning import CONVERGED, least_squares_position
from gnss_common.rinex import SYSTEM_NAMES, RinexNav, RinexObs, RinexObsEpoch

SKIP_REASONS = (
    "unsupported_constellation",
    "missing_pseudorange",
    "pseudorange_out_of_range",
    "no_ephemeris",
    "unhealthy",
    "stale_ephemeris",
    "missing_dual_frequency",
)
"""Keys of :attr:`EpochBuildResult.skipped` (always all present, zero when nothing skipped)."""

GPS_DUAL_FREQUENCY_CODES = {2: ("P1", "P2"), 3: ("C1W", "C2W"), 4: ("C1W", "C2W")}
"""RINEX major version -> the GPS L1 and L2 P(Y) codes of the ionosphere-free combination
(:attr:`MeasurementBuilderParams.ionosphere_free`). Only the P(Y) pair: the broadcast T_GD and the
clock polynomial refer to P1/P2, so C/A (``C1``, ``C1C``) with P2 would carry each satellite's
P1-C1 code bias times 2.55, which no broadcast message gives (measured:
docs/uwb_gnss_fusion/fusion_real_gnss.md, section 4)."""

CONSTELLATION_CODES = {"G": GPS, "R": GLONASS, "E": GALILEO, "C": BEIDOU, "J": QZSS, "S": SBAS}
"""RINEX system letter -> constellation code of rfi_msgs/GnssMeasurement."""

SUPPORTED_SYSTEMS = ("G", "E", "C", "R", "J")
"""Systems whose satellite state can be computed from a broadcast ephemeris here."""


@dataclass(frozen=True)
class MeasurementBuilderParams:
    """Parameters of :class:`GnssEpochBuilder`.

    Attributes:
        min_pseudorange_m: smallest plausible pseudorange, m (GPS ranges are 20000-26000 km plus
            the receiver clock offset).
        max_pseudorange_m: largest plausible pseudorange, m.
        max_pseudorange_high_orbit_m: largest plausible BeiDou and QZSS pseudorange, m (their GEO,
            IGSO and QZO satellites are 36 000-42 000 km away, plus the receiver clock offset).
        max_ephemeris_age_s: |t - t_oe| limit of the Keplerian records (GPS, Galileo, BeiDou,
            QZSS), s; None uses half of each record's fit interval.
        max_glonass_age_s: |t - t_b| limit of GLONASS records, s (records every 30 min; the
            integrated orbit degrades by metres per extra quarter hour).
        apply_ionosphere: compute the Klobuchar delay (else 0).
        apply_troposphere: compute the Saastamoinen delay (else 0).
        constellations: RINEX system letters to build (of :data:`SUPPORTED_SYSTEMS`); satellites
            of other systems are skipped as ``unsupported_constellation``.
        signals: the signal of each system and its tracking attributes in priority order
            (:data:`gnss_common.observation_codes.DEFAULT_SIGNALS`).
        ionosphere_free: GPS pseudoranges as the ionosphere-free combination of the L1 and L2
            P(Y) codes (:data:`GPS_DUAL_FREQUENCY_CODES`,
            :func:`gnss_common.corrections.ionosphere_free_pseudorange_m`), with no ionospheric
            delay (``ionosphere_delay_m`` 0) and the broadcast clock without T_GD; a GPS satellite
            without both codes is skipped as ``missing_dual_frequency``. Doppler, C/N0 and the
            carrier stay those of the L1 signal. The other systems are unchanged (single
            frequency, Klobuchar). False (the default): every system single frequency.
    """

    min_pseudorange_m: float = 1.0e7
    max_pseudorange_m: float = 4.0e7
    max_pseudorange_high_orbit_m: float = 4.8e7
    max_ephemeris_age_s: float | None = None
    max_glonass_age_s: float = GLONASS_DEFAULT_MAX_AGE_S
    apply_ionosphere: bool = True
    apply_troposphere: bool = True
    constellations: tuple[str, ...] = SUPPORTED_SYSTEMS
    signals: dict[str, SignalPreference] = field(default_factory=lambda: dict(DEFAULT_SIGNALS), hash=False)
    ionosphere_free: bool = False

    def __post_init__(self) -> None:
        unknown = [c for c in self.constellations if c not in SUPPORTED_SYSTEMS]
        if unknown:
            raise ValueError(f"constellations must be among {SUPPORTED_SYSTEMS}, got {unknown}")
        if not (math.isfinite(self.max_glonass_age_s) and self.max_glonass_age_s > 0.0):
            raise ValueError(f"max_glonass_age_s must be finite and > 0, got {self.max_glonass_age_s}")
        missing = [c for c in self.constellations if c not in self.signals]
        if missing:
            raise ValueError(f"no signal given for constellation(s) {missing}")
        if not (
            math.isfinite(self.min_pseudorange_m)
            and math.isfinite(self.max_pseudorange_m)
            and 0.0 < self.min_pseudorange_m < self.max_pseudorange_m
        ):
            raise ValueError(
                "need 0 < min_pseudorange_m < max_pseudorange_m, both finite; got "
                f"{self.min_pseudorange_m}, {self.max_pseudorange_m}"
            )
        high = self.max_pseudorange_high_orbit_m
        if not (math.isfinite(high) and high > self.min_pseudorange_m):
            raise ValueError(f"max_pseudorange_high_orbit_m must be finite and > min_pseudorange_m, got {high}")
        if self.max_ephemeris_age_s is not None and not (
            math.isfinite(self.max_ephemeris_age_s) and self.max_ephemeris_age_s > 0.0
        ):
            raise ValueError(
                f"max_ephemeris_age_s must be None or finite > 0, got {self.max_ephemeris_age_s}"
            )


@dataclass(frozen=True)
class EpochBuildResult:
    """Output of :meth:`GnssEpochBuilder.build`.

    Attributes:
        epoch: the GnssEpoch (observations sorted by svid).
        skipped: reason -> number of satellites skipped in this epoch (keys: ``SKIP_REASONS``).
        skipped_satellites: ``(satellite id, reason)`` for every skipped satellite.
        reference_position_ecef_m: receiver position used for the delays, m, (3,); NaN if none.
        reference_source: ``"given"``, ``"coarse_fix"`` or ``"none"`` (delays are NaN then).
        extra: other counts (``ionosphere_unavailable``).
        skipped_by_constellation: constellation name (:data:`gnss_common.rinex.SYSTEM_NAMES`,
            e.g. ``"galileo"``) -> reason -> satellites skipped in this epoch (only nonzero entries).
        signal_codes: satellite id (``"C05"``) -> pseudorange observable its measurement was made
            from (``"C2X"``, ``"C1"``; Doppler, C/N0 of the same attribute), for every satellite
            of ``epoch``.
    """

    epoch: GnssEpoch
    skipped: dict[str, int]
    skipped_satellites: tuple[tuple[str, str], ...]
    reference_position_ecef_m: np.ndarray
    reference_source: str
    extra: dict[str, float] = field(default_factory=dict)
    skipped_by_constellation: dict[str, dict[str, int]] = field(default_factory=dict)
    signal_codes: dict[str, str] = field(default_factory=dict)


def coarse_position_fix(
    satellite_ecef_m: np.ndarray, pseudorange_m: np.ndarray, max_iterations: int = 12
) -> np.ndarray | None:
    """Unweighted Gauss-Newton position fix from the Earth's centre, no atmosphere corrections.

    Args:
        satellite_ecef_m: satellite positions at transmit time (transmit-time ECEF), m, (N, 3).
        pseudorange_m: pseudoranges with the satellite clock already added back, m, (N,).
        max_iterations: iteration cap.

    Returns:
        Receiver ECEF position, m, (3,), or None with fewer than 4 satellites, a singular
        geometry, or no convergence (< 1 mm step) within the cap.

    Notes
    -----
    Linearised Cao et al., eq. 5 with T = I = 0, solved by
    :func:`gnss_common.positioning.least_squares_position`; range with the Earth-rotation correction
    (:func:`gnss_common.ephemeris.earth_rotation_correction`). Used only to place the receiver
    for the atmosphere models (tens of metres suffice there).
    """
    sat = np.asarray(satellite_ecef_m, dtype=float)
    rho = np.asarray(pseudorange_m, dtype=float)
    if sat.shape[0] < 4:
        return None
    unit_weights = np.ones(sat.shape[0])

    def model(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        diff = earth_rotation_correction(sat, x[:3])[0] - x[:3]
        rng = np.linalg.norm(diff, axis=1)
        return rng + x[3], diff / rng[:, None], unit_weights

    sol = least_squares_position(model, rho, np.zeros(4), max_iterations, 1.0e-3, max_variance_m2=np.inf)
    if sol.status != CONVERGED or np.linalg.norm(sol.x[:3]) < 6.0e6:
        return None
    return sol.x[:3].copy()


class GnssEpochBuilder:
    """Turns RINEX observation epochs into GnssEpoch objects (GPS, Galileo, BeiDou, GLONASS, QZSS).

    Usage::

        nav = read_rinex_nav(nav_path); obs = read_rinex_obs(obs_path)
        builder = GnssEpochBuilder(nav.ephemerides, nav.header.iono_alpha, nav.header.iono_beta,
                                   obs.header.approx_position_ecef_m)
        results = [builder.build(e) for e in obs.epochs]
    """

    def __init__(
        self,
        ephemerides: Sequence[GpsEphemeris | GlonassEphemeris],
        iono_alpha: np.ndarray | None,
        iono_beta: np.ndarray | None,
        reference_position_ecef_m: np.ndarray | None = None,
        params: MeasurementBuilderParams | None = None,
        rinex_version: float | None = None,
    ) -> None:
        """Args:
        ephemerides: broadcast records of any systems (Keplerian :class:`GpsEphemeris` of GPS,
            Galileo, BeiDou, QZSS and :class:`GlonassEphemeris`), any order.
        iono_alpha: Klobuchar alpha (4,), or None / NaN-filled (ionosphere then 0 and counted
            in ``extra["ionosphere_unavailable"]``).
        iono_beta: Klobuchar beta (4,), idem.
        reference_position_ecef_m: receiver position for the delays, m, (3,); None for a
            per-epoch coarse fix.
        params: builder parameters (defaults if None).
        rinex_version: version of the observation files the epochs come from (BeiDou band
            numbers changed in 3.02); None for 3.02 or later.
        """
        self.params = params if params is not None else MeasurementBuilderParams()
        self.rinex_version = rinex_version
        kepler = [e for e in ephemerides if isinstance(e, GpsEphemeris)]
        glonass = [e for e in ephemerides if isinstance(e, GlonassEphemeris)]
        self._store = EphemerisStore(kepler, self.params.max_ephemeris_age_s)
        self._glonass = GlonassStore(glonass, self.params.max_glonass_age_s)
        alpha = None if iono_alpha is None else np.asarray(iono_alpha, dtype=float).reshape(-1)
        beta = None if iono_beta is None else np.asarray(iono_beta, dtype=float).reshape(-1)
        ok = (
            alpha is not None
            and beta is not None
            and alpha.shape == (4,)
            and beta.shape == (4,)
            and bool(np.all(np.isfinite(alpha)))
            and bool(np.all(np.isfinite(beta)))
        )
        self._alpha = alpha if ok else None
        self._beta = beta if ok else None
        if reference_position_ecef_m is not None:
            ref = np.asarray(reference_position_ecef_m, dtype=float).reshape(-1)
            if ref.shape != (3,) or not np.all(np.isfinite(ref)) or not 6.0e6 < np.linalg.norm(ref) < 7.0e6:
                raise ValueError(
                    f"reference_position_ecef_m must be a finite near-surface ECEF point, got {ref}"
                )
            self._ref: np.ndarray | None = ref
        else:
            self._ref = None

    @classmethod
    def from_rinex(
        cls, obs: RinexObs, nav: RinexNav, params: MeasurementBuilderParams | None = None
    ) -> GnssEpochBuilder:
        """Builder using the nav file's records of every system, its Klobuchar parameters, the
        obs header APPROX POSITION and the obs file's RINEX version."""
        return cls(
            (*nav.keplerian_ephemerides, *nav.glonass_ephemerides),
            nav.header.iono_alpha,
            nav.header.iono_beta,
            obs.header.approx_position_ecef_m,
            params,
            obs.header.version,
        )

    def build(self, obs_epoch: RinexObsEpoch) -> EpochBuildResult:
        """Build the GnssEpoch of one RINEX observation epoch.

        Args:
            obs_epoch: one epoch from :func:`gnss_common.rinex.read_rinex_obs`.

        Returns:
            :class:`EpochBuildResult`; ``epoch.stamp_ns`` is the receiver time tag as a ROS
            (UTC) stamp; the exact GPS week / time of week are in the epoch (see
            :mod:`gnss_common.gps_time`).
        """
        p = self.params
        week, tow = obs_epoch.gps_week, obs_epoch.tow_s
        skipped = dict.fromkeys(SKIP_REASONS, 0)
        skipped_sats: list[tuple[str, str]] = []
        by_system: dict[str, dict[str, int]] = {}

        def skip(sat_id: str, reason: str) -> None:
            skipped[reason] += 1
            skipped_sats.append((sat_id, reason))
            name = SYSTEM_NAMES.get(sat_id[0], sat_id[0].lower())
            counts = by_system.setdefault(name, {})
            counts[reason] = counts.get(reason, 0) + 1

        systems: list[str] = []
        prns: list[int] = []
        ephs: list[GpsEphemeris | GlonassEphemeris] = []
        prs: list[float] = []
        dops: list[float] = []
        cn0s: list[float] = []
        freqs: list[float] = []
        dual: list[bool] = []
        codes_used: dict[str, str] = {}
        version_pair = (GPS_DUAL_FREQUENCY_CODES.get(int(self.rinex_version))
                        if p.ionosphere_free and self.rinex_version is not None else None)
        for sat_id in sorted(obs_epoch.observations):
            values = obs_epoch.observations[sat_id]
            sys_char = sat_id[0]
            if sys_char not in p.constellations:
                skip(sat_id, "unsupported_constellation")
                continue
            signal = p.signals[sys_char]
            selected = select_signal(values, signal, self.rinex_version)
            if selected is None:
                skip(sat_id, "missing_pseudorange")
                continue
            pr = selected.pseudorange_m
            code = selected.pseudorange_observable
            if p.ionosphere_free and sys_char == "G":
                combined = _ionosphere_free_pair(values, version_pair)
                if combined is None:
                    skip(sat_id, "missing_dual_frequency")
                    continue
                pr, code = combined
            max_pr = p.max_pseudorange_high_orbit_m if sys_char in ("C", "J") else p.max_pseudorange_m
            if not p.min_pseudorange_m <= pr <= max_pr:
                skip(sat_id, "pseudorange_out_of_range")
                continue
            prn = int(sat_id[1:])
            eph: GpsEphemeris | GlonassEphemeris | None
            if sys_char == "R":
                eph, reason = self._glonass.select(prn, week, tow)
                freq = glonass_g1_frequency_hz(eph.frequency_channel) if eph is not None else math.nan
            else:
                eph, reason = self._store.select(prn, week, tow, sys_char)
                freq = signal.carrier_frequency_hz
            if eph is None:
                skip(sat_id, reason)
                continue
            cn0 = selected.cn0_dbhz
            codes_used[sat_id] = code
            dual.append(p.ionosphere_free and sys_char == "G")
            systems.append(sys_char)
            prns.append(prn)
            ephs.append(eph)
            prs.append(pr)
            dops.append(selected.doppler_hz)
            cn0s.append(cn0 if 0.0 < cn0 < 100.0 else math.nan)
            freqs.append(freq)

        extra: dict[str, float] = {"ionosphere_unavailable": 0.0}
        ref = np.full(3, math.nan)
        source = "none"
        if not ephs:
            epoch = GnssEpoch(
                stamp_ns=gps_to_ros_stamp_ns(week, tow), gps_week=week, gps_time_of_week_s=tow, observations=()
            )
            return EpochBuildResult(epoch, skipped, tuple(skipped_sats), ref, source, extra, by_system, codes_used)

        pr_arr = np.asarray(prs)
        n = len(ephs)
        pos, vel, clk_s, drift_s = _states_at_transmit(ephs, week, tow, pr_arr)
        clk_m = SPEED_OF_LIGHT_MPS * clk_s
        drift_mps = SPEED_OF_LIGHT_MPS * drift_s
        freq_arr = np.asarray(freqs, dtype=float)

        ref, source = self._reference_position(systems, pos, pr_arr, clk_m)
        iono, tropo = self._atmosphere(ref, source, pos, freq_arr, tow, extra)
        if any(dual):
            clk_m, iono = _ionosphere_free_user(np.asarray(dual), ephs, clk_m, iono)

        rates = -(SPEED_OF_LIGHT_MPS / freq_arr) * np.asarray(dops)
        observations = tuple(
            SatelliteObservation(constellation=CONSTELLATION_CODES[systems[i]], svid=prns[i],
                                 pseudorange_m=float(pr_arr[i]), pseudorange_rate_mps=float(rates[i]),
                                 cn0_dbhz=float(cn0s[i]), satellite_position_ecef_m=pos[i].copy(),
                                 satellite_velocity_ecef_mps=vel[i].copy(), satellite_clock_bias_m=float(clk_m[i]),
                                 satellite_clock_drift_mps=float(drift_mps[i]), ionosphere_delay_m=float(iono[i]),
                                 troposphere_delay_m=float(tropo[i]), carrier_frequency_hz=float(freq_arr[i]))
            for i in range(n)
        )
        epoch = GnssEpoch(
            stamp_ns=gps_to_ros_stamp_ns(week, tow),
            gps_week=week,
            gps_time_of_week_s=tow,
            observations=observations,
        )
        return EpochBuildResult(
            epoch, skipped, tuple(skipped_sats), np.array(ref, dtype=float), source, extra, by_system, codes_used
        )

    def _reference_position(self, systems: list[str], pos: np.ndarray, pr: np.ndarray, clk_m: np.ndarray
                            ) -> tuple[np.ndarray, str]:
        """(position the atmospheric delays are computed at, its source: "given", "coarse_fix" or "none")."""
        if self._ref is not None:
            return self._ref, "given"
        # One receiver clock for all systems: fix on GPS alone when it has 4 satellites (the
        # inter-system biases are tens of ns), else on everything (tens of metres suffice here).
        gps_rows = np.array([s == "G" for s in systems])
        rows = gps_rows if int(np.sum(gps_rows)) >= 4 else np.ones(len(systems), dtype=bool)
        fix = coarse_position_fix(pos[rows], pr[rows] + clk_m[rows])
        if fix is not None:
            return fix, "coarse_fix"
        return np.full(3, math.nan), "none"

    def _atmosphere(self, ref: np.ndarray, source: str, pos: np.ndarray, freq: np.ndarray, tow: float,
                    extra: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(ionosphere, troposphere) delays of each satellite at ref, m (Klobuchar scaled to each carrier; NaN with
        no reference position; 0 when not applied; a missing Klobuchar model counted in extra)."""
        p = self.params
        n = pos.shape[0]
        if source == "none":
            return np.full(n, math.nan), np.full(n, math.nan)
        iono = np.zeros(n)
        tropo = np.zeros(n)
        lat, lon, h = ecef_to_geodetic(ref)
        rot_pos, _, _ = earth_rotation_correction(pos, ref)
        az, el = azimuth_elevation(ref, rot_pos)
        if p.apply_ionosphere:
            if self._alpha is not None and self._beta is not None:
                iono = SPEED_OF_LIGHT_MPS * klobuchar_delay_s(self._alpha, self._beta, lat, lon, az, el, tow) * (
                    ionosphere_frequency_scale(freq)
                )
            else:
                extra["ionosphere_unavailable"] = float(n)
        if p.apply_troposphere:
            tropo = troposphere_delay_m(lat, h, el)
        return iono, tropo


def _states_at_transmit(
    ephs: Sequence[GpsEphemeris | GlonassEphemeris], week: int, tow: float, pr: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Position (N, 3) m, velocity (N, 3) m/s, clock s, drift s/s of each record at transmit time:
    Keplerian records by :func:`satellite_states_at_transmit`, GLONASS by
    :func:`gnss_common.glonass.glonass_states_at_transmit`, rows in input order."""
    n = len(ephs)
    pos = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    clk = np.zeros(n)
    drift = np.zeros(n)
    kep = np.array([isinstance(e, GpsEphemeris) for e in ephs], dtype=bool)
    if np.any(kep):
        k_ephs = [e for e in ephs if isinstance(e, GpsEphemeris)]
        st, _ = satellite_states_at_transmit(pack_ephemerides(k_ephs), week, tow, pr[kep])
        pos[kep], vel[kep], clk[kep], drift[kep] = (
            st.position_ecef_m, st.velocity_ecef_mps, st.clock_bias_s, st.clock_drift_s_per_s
        )
    if not np.all(kep):
        g_ephs = [e for e in ephs if isinstance(e, GlonassEphemeris)]
        st, _ = glonass_states_at_transmit(pack_glonass(g_ephs), week, tow, pr[~kep])
        pos[~kep], vel[~kep], clk[~kep], drift[~kep] = (
            st.position_ecef_m, st.velocity_ecef_mps, st.clock_bias_s, st.clock_drift_s_per_s
        )
    return pos, vel, clk, drift


def build_epochs(
    obs: RinexObs, nav: RinexNav, params: MeasurementBuilderParams | None = None
) -> list[EpochBuildResult]:
    """Build every epoch of an observation file (header APPROX POSITION as reference when present)."""
    builder = GnssEpochBuilder.from_rinex(obs, nav, params)
    return [builder.build(e) for e in obs.epochs]


def _ionosphere_free_pair(values: dict[str, float], version_pair: tuple[str, str] | None) -> tuple[float, str] | None:
    """(the GPS ionosphere-free pseudorange of one satellite's P(Y) pair, m; its code, e.g. "P1+P2") or None when
    the satellite lacks either code (``MeasurementBuilderParams.ionosphere_free``). ``version_pair``: the pair of
    the file's RINEX version; None (version unknown): the RINEX 2 names if the satellite has one, else the RINEX 3
    ones."""
    pair = version_pair or (GPS_DUAL_FREQUENCY_CODES[2] if ("P1" in values or "P2" in values)
                            else GPS_DUAL_FREQUENCY_CODES[3])
    pr1 = values.get(pair[0], math.nan)
    pr2 = values.get(pair[1], math.nan)
    if not (math.isfinite(pr1) and math.isfinite(pr2) and pr1 > 0.0 and pr2 > 0.0):
        return None
    return (float(ionosphere_free_pseudorange_m(pr1, pr2, GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ)),
            f"{pair[0]}+{pair[1]}")


def _ionosphere_free_user(is_dual: np.ndarray, ephs: list, clk_m: np.ndarray, iono: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """(satellite clocks, ionospheric delays), m, of an epoch whose ``is_dual`` satellites carry ionosphere-free
    pseudoranges: no ionospheric model, the clock polynomial without T_GD (IS-GPS-200, 20.3.3.3.3.2-3;
    ``_states_at_transmit`` subtracted T_GD, as for an L1 user)."""
    tgd_m = np.array([SPEED_OF_LIGHT_MPS * getattr(e, "tgd_s", 0.0) for e in ephs])
    return np.where(is_dual, clk_m + tgd_m, clk_m), np.where(is_dual & np.isfinite(iono), 0.0, iono)

"""Scenario stream ``gnss_uwb``: GNSS measurements and UWB ranges of Cao et al. under a jamming schedule.

Section keys (all optional; the defaults are the simulator's defaults, i.e. the paper's static
rooftop set-up moved to the ARL1 station, Cao et al., Sec. IV-1 and Table 1)::

    gnss_uwb:
      start_gps_week: 1854            # continuous GPS week of the first epoch (the ARL1 nav file's week)
      start_gps_tow_s: 3600.0         # GPS time of week of the first epoch, s
      receiver_ecef_m: [-740289.918, -5457071.734, 3207245.542]   # antenna = tag at the start, ECEF, m
      receiver_velocity_enu_mps: [0.0, 0.0, 0.0]   # constant velocity, m/s, ENU at the start (straight
                                      # line; the anchors stay around the start position)
      gnss_rate_hz: 5.0               # GNSS epoch rate, Hz
      uwb_rate_hz: 20.0               # ranging rate per anchor, Hz (anchors interleaved)
      anchors:                        # one entry per anchor, ids A1, A2, ... in this order
        - {range_m: 11.71, azimuth_deg: 20.0, up_m: 1.5}
        - {range_m: 13.00, azimuth_deg: 140.0, up_m: -0.5}
        - {range_m: 11.26, azimuth_deg: 260.0, up_m: 0.8}
      uwb_noise_std_m: 0.03           # UWB range noise 1-sigma, m
      uwb_reported_std_m: .nan        # range_std_m written in /uwb/ranges, m (.nan or null: the filter decides)
      elevation_mask_deg: 10.0        # satellites below are not tracked, deg
      cn0_zenith_dbhz: 49.0           # jammer-free C/N0 at 90 deg elevation, dB-Hz
      cn0_horizon_dbhz: 34.0          # jammer-free C/N0 at 0 deg elevation, dB-Hz
      correlated_error_std_m: 0.7     # per-satellite Gauss-Markov pseudorange error 1-sigma, m
      correlated_error_tau_s: 60.0    # its correlation time, s
      report_sigmas: false            # write pseudorange_std_m / pseudorange_rate_std_mps (else NaN)
      ionosphere: true                # Klobuchar delay from the nav file header (false: none)
      nav_file: null                  # RINEX GPS nav file (null: the installed ARL1 copy, see below)
      truth_jammer_state: true        # also write /truth/jammer_state
      jamming:                        # the schedule: consecutive phases from the start
        - {jsr_db: null, duration_s: 30.0}   # null: no jammer
        - {jsr_db: 22.0}                     # the last phase may omit duration_s: it runs to the end
      spoofing:                       # optional: attacks on the GNSS measurements (rfi_experiments.attacks)
        - {kind: position_push, start_s: 60.0, push_velocity_enu_mps: [1.0, 0.0, 0.0],
           doppler_consistent: true, power_advantage_db: 3.0}

Each phase's ``duration_s`` must be a whole number of GNSS and UWB periods, and the phases must
cover the scenario's ``duration_s`` exactly.

Simulation. :func:`rfi_sim.gnss_uwb.simulate` takes one J/S per run, so the builder
simulates each phase as its own run (seeded from ``seed`` and the phase index) and joins them:
the stamps continue on the same GNSS/UWB grid, the receiver clock of a phase starts where the
previous one ended (bias extrapolated by one GNSS period with the last drift), the geometry and
anchors are the same, and a moving receiver starts a phase where its straight line puts it. Not
continuous across a phase boundary: the per-satellite Gauss-Markov errors (re-drawn from their
stationary distribution, so their statistics are unchanged), the state of outlier bursts (a burst
ends at a boundary) and the random number streams. The spoofing attacks run across the phases
without a break (one injector per attack for the whole stream).

Output, in stamp order, per GNSS epoch k (stamp = receive time as a ROS (UTC) stamp,
gnss_common.gps_time.gps_to_ros_stamp_ns of the message's gps_week / gps_time_of_week_s; UWB
ranges stamped by the same conversion; at equal stamps in this order):

* ``/gnss/measurements`` (rfi_msgs/GnssMeasurementArray, frame "earth");
* ``/truth/position`` (geometry_msgs/PointStamped, frame "earth"): the true antenna (= tag)
  position, ECEF, m, at every GNSS epoch (at its receive time for a moving receiver);
* ``/truth/jammer_state`` (rfi_msgs/JammerState, only with ``truth_jammer_state``) at the start of
  each phase and then once per second: ``type`` CHIRP (the paper's linear chirp) or NONE,
  ``jammer_to_signal_db`` the phase's J/S (NaN without a jammer), ``confidence`` 1, every other
  float NaN. It has the layout of the RFI monitor's output, so remapping it to /rfi/jammer_state
  gives the fusion node an ideal monitor;
* with a ``spoofing`` list: the measurements are those under the attacks
  (:mod:`rfi_sim.spoofing`, injected epoch by epoch with the true receiver state), and
  ``/truth/integrity``, ``/truth/spoofed_position``, ``/truth/spoofed_time`` (see
  :mod:`rfi_experiments.attacks`);

and the UWB ranges ``/uwb/ranges`` (rfi_msgs/UwbRange, frame "earth", anchor ids A1...), each
anchor at ``uwb_rate_hz``, interleaved. Nothing else of the simulator's truth (clock, outlier
masks) is written: it stays available from the simulator itself.

Ephemeris: ``nav_file: null`` resolves ``share/rfi_experiments/data/arlm2000.15n`` through the
ament index (ARL1, 2015-07-19, SGL-UT/gnsstk commit 028fdaae, LGPL-3.0; see data/README.md); in a
source checkout where the package is not installed it falls back to ``src/rfi_experiments/data``.

Notes
-----
Measurement models: Cao et al., eq. 4 (effective C/N0 under J/S), eq. 5-7, as implemented by the
simulator (see its module docstring).

In a scenario file with a top-level timeline (``start``, ``jamming``), ``start_gps_week``,
``start_gps_tow_s`` and ``jamming`` are derived from it by
:func:`rfi_experiments.scenario.resolve_streams`; a key written in this section overrides the
derived one.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.gps_time import gps_to_ros_stamp_ns
from rfi_experiments.attacks import StreamSpoofer, parse_spoofing
from rfi_experiments.scenario import Scenario, data_path
from rfi_experiments.schema import (
    JsrPhases,
    ScenarioError,
    anchors,
    boolean,
    integer,
    jsr_phases,
    number,
    optional_std,
    reject_unknown_keys,
)
from rfi_sim.gnss_uwb import (
    ARL1_ECEF_M,
    PAPER_ANCHOR_RANGES_M,
    BroadcastGeometry,
    GnssUwbScenario,
    receiver_velocity_ecef,
    simulate,
)

GNSS_TOPIC = '/gnss/measurements'
UWB_TOPIC = '/uwb/ranges'
TRUTH_POSITION_TOPIC = '/truth/position'
TRUTH_JAMMER_TOPIC = '/truth/jammer_state'
EARTH_FRAME = 'earth'
TRUTH_JAMMER_PERIOD_S = 1.0
"""Period of /truth/jammer_state within a phase, s."""

NAV_FILE_NAME = 'arlm2000.15n'
"""Default ephemeris: ARL1 broadcast navigation file of 2015-07-19 (GPS week 1854)."""

_DEFAULT_SIM = GnssUwbScenario()

PAPER_ANCHORS = tuple({'range_m': r, 'azimuth_deg': a, 'up_m': u} for r, a, u in zip(
    PAPER_ANCHOR_RANGES_M, _DEFAULT_SIM.anchor_azimuths_deg, _DEFAULT_SIM.anchor_up_m, strict=True))
"""Default ``anchors`` of the gnss_uwb and rinex_jammed sections: the paper's three reference ranges."""


@dataclass(frozen=True)
class UwbSkyKeys:
    """The keys the ``gnss_uwb`` and ``rinex_jammed`` sections share (module docstrings): the UWB ranging and
    the sky's elevation mask and C/N0 model, with the simulator's defaults. A section checks them first
    (:meth:`_check_uwb_sky_keys`; the messages name the key under :attr:`SECTION`).

    After the check ``anchors`` is ``(ranges m, azimuths deg, ups m)`` and ``uwb_reported_std_m`` NaN when
    not given.
    """

    SECTION: ClassVar[str] = ''
    uwb_rate_hz: float = _DEFAULT_SIM.uwb_rate_hz
    anchors: Any = PAPER_ANCHORS
    uwb_noise_std_m: float = _DEFAULT_SIM.uwb_noise_std_m
    uwb_reported_std_m: float | None = None
    elevation_mask_deg: float = _DEFAULT_SIM.elevation_mask_deg
    cn0_zenith_dbhz: float = _DEFAULT_SIM.cn0_zenith_dbhz
    cn0_horizon_dbhz: float = _DEFAULT_SIM.cn0_horizon_dbhz

    def _check_uwb_sky_keys(self) -> None:
        """Validate and convert the shared keys (frozen: set through ``object.__setattr__``).

        Raises:
            ScenarioError: wrong type or non-physical value (the message names the key).
        """
        at = self.SECTION
        for key, value in (
            ('uwb_rate_hz', number(self.uwb_rate_hz, f'{at}.uwb_rate_hz', 0.0, 1000.0, low_open=True)),
            ('anchors', anchors(self.anchors, f'{at}.anchors')),
            ('uwb_noise_std_m', number(self.uwb_noise_std_m, f'{at}.uwb_noise_std_m', 0.0, 100.0)),
            ('uwb_reported_std_m', optional_std(self.uwb_reported_std_m, f'{at}.uwb_reported_std_m')),
            ('elevation_mask_deg', number(self.elevation_mask_deg, f'{at}.elevation_mask_deg', -10.0, 60.0)),
            ('cn0_zenith_dbhz', number(self.cn0_zenith_dbhz, f'{at}.cn0_zenith_dbhz', 0.0, 70.0)),
            ('cn0_horizon_dbhz', number(self.cn0_horizon_dbhz, f'{at}.cn0_horizon_dbhz', 0.0, 70.0)),
        ):
            object.__setattr__(self, key, value)


@dataclass(frozen=True)
class GnssUwbSection(UwbSkyKeys):
    """The ``gnss_uwb`` section: every key with its default (the simulator's; no jamming), validated
    and converted on construction (module docstring for each key).

    After construction ``anchors`` is ``(ranges m, azimuths deg, ups m)``, ``receiver_ecef_m`` and
    ``receiver_velocity_enu_mps`` tuples of 3 floats, ``uwb_reported_std_m`` NaN when not given and
    ``spoofing`` a tuple of :class:`rfi_sim.spoofing.SpoofingAttack` (checked against the
    scenario's duration by :func:`parse_section`); ``jamming`` and ``nav_file``
    stay as written (they depend on the scenario: :func:`parse_section` resolves them).

    Raises:
        ScenarioError: wrong type or non-physical value (the message names the key).
    """

    SECTION: ClassVar[str] = 'gnss_uwb'
    start_gps_week: int = _DEFAULT_SIM.start_week
    start_gps_tow_s: float = _DEFAULT_SIM.start_tow_s
    receiver_ecef_m: Any = ARL1_ECEF_M
    receiver_velocity_enu_mps: Any = (0.0, 0.0, 0.0)
    gnss_rate_hz: float = _DEFAULT_SIM.gnss_rate_hz
    correlated_error_std_m: float = _DEFAULT_SIM.correlated_error_std_m
    correlated_error_tau_s: float = _DEFAULT_SIM.correlated_error_tau_s
    report_sigmas: bool = _DEFAULT_SIM.report_sigmas
    ionosphere: bool = True
    nav_file: str | None = None
    truth_jammer_state: bool = True
    jamming: Any = ({'jsr_db': None},)
    spoofing: Any = None

    def __post_init__(self) -> None:
        def put(key: str, value: Any) -> None:
            object.__setattr__(self, key, value)

        put('start_gps_week', integer(self.start_gps_week, 'gnss_uwb.start_gps_week', 0, 10_000))
        put('start_gps_tow_s', number(self.start_gps_tow_s, 'gnss_uwb.start_gps_tow_s', 0.0, 604800.0))
        rx = self.receiver_ecef_m
        if not isinstance(rx, (list, tuple)) or len(rx) != 3:
            raise ScenarioError(f'gnss_uwb.receiver_ecef_m must be a list of 3 numbers, m, got {rx!r}')
        rx = tuple(number(v, 'gnss_uwb.receiver_ecef_m', -1e7, 1e7) for v in rx)
        if not 6.0e6 < math.hypot(*rx) < 6.5e6:
            raise ScenarioError(f'gnss_uwb.receiver_ecef_m {rx} is not near the Earth surface')
        put('receiver_ecef_m', rx)
        vel = self.receiver_velocity_enu_mps
        if not isinstance(vel, (list, tuple)) or len(vel) != 3:
            raise ScenarioError(f'gnss_uwb.receiver_velocity_enu_mps must be a list of 3 numbers, m/s, got {vel!r}')
        put('receiver_velocity_enu_mps',
            tuple(number(v, 'gnss_uwb.receiver_velocity_enu_mps', -1000.0, 1000.0) for v in vel))
        put('spoofing', parse_spoofing(self.spoofing, math.inf, 'gnss_uwb.spoofing'))
        put('gnss_rate_hz', number(self.gnss_rate_hz, 'gnss_uwb.gnss_rate_hz', 0.0, 100.0, low_open=True))
        self._check_uwb_sky_keys()
        put('correlated_error_std_m',
            number(self.correlated_error_std_m, 'gnss_uwb.correlated_error_std_m', 0.0, 100.0))
        put('correlated_error_tau_s',
            number(self.correlated_error_tau_s, 'gnss_uwb.correlated_error_tau_s', 0.0, 1e6, low_open=True))
        for key in ('report_sigmas', 'ionosphere', 'truth_jammer_state'):
            boolean(getattr(self, key), f'gnss_uwb.{key}')
        if self.nav_file is not None and not isinstance(self.nav_file, str):
            raise ScenarioError(f'gnss_uwb.nav_file must be a path or null, got {self.nav_file!r}')

    @classmethod
    def from_mapping(cls, section: Mapping[str, Any]) -> GnssUwbSection:
        """The section as written in the scenario (unknown keys rejected), defaults for the rest."""
        reject_unknown_keys(section, [f.name for f in fields(cls)], 'gnss_uwb')
        return cls(**section)


def default_nav_path() -> Path:
    """The installed ARL1 nav file (ament index), else the source checkout's copy.

    Raises:
        ScenarioError: neither exists.
    """
    return data_path(NAV_FILE_NAME)


def parse_section(scenario: Scenario, section: Mapping[str, Any]) -> tuple[GnssUwbSection, JsrPhases, Path]:
    """Validate the section.

    Returns:
        ``(settings, phases, nav_path)``: the validated settings, the phases
        ``((jsr_db or None, duration_s), ...)`` and the nav file.

    Raises:
        ScenarioError: unknown key, wrong type, non-physical value (the message names the key).
    """
    s = GnssUwbSection.from_mapping(section)
    if s.nav_file is None:
        nav = default_nav_path()
    else:
        nav = Path(s.nav_file)
        if not nav.is_absolute() and scenario.source is not None:
            nav = scenario.source.parent / nav
        if not nav.is_file():
            raise ScenarioError(f'gnss_uwb.nav_file {nav} does not exist')
    phases = jsr_phases(s.jamming, scenario.duration_s, 'gnss_uwb.jamming',
                        {'GNSS': s.gnss_rate_hz, 'UWB': s.uwb_rate_hz})
    for i, attack in enumerate(s.spoofing):
        if attack.start_s >= scenario.duration_s:
            raise ScenarioError(f'gnss_uwb.spoofing[{i}].start_s {attack.start_s} is not before the end of the '
                                f'scenario ({scenario.duration_s} s)')
    end_tow = s.start_gps_tow_s + scenario.duration_s
    if end_tow >= 604800.0:
        raise ScenarioError(f'gnss_uwb: the scenario runs past the end of GPS week {s.start_gps_week} '
                            f'(start_gps_tow_s + duration_s = {end_tow} s)')
    return s, phases, nav


def _jammer_truth(stamp_ns: int, jsr_db: float | None):
    from rfi_msgs.msg import JammerState
    from rfi_node_common.stamps import ns_to_stamp

    msg = JammerState()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = 'truth'
    msg.type = JammerState.NONE if jsr_db is None else JammerState.CHIRP
    msg.confidence = 1.0
    for name in ('jammer_to_noise_db', 'frequency_hz', 'frequency_std_hz', 'sweep_rate_hz_per_s', 'sweep_period_s',
                 'sweep_start_frequency_hz', 'sweep_bandwidth_hz', 'center_frequency_hz', 'sample_rate_hz'):
        setattr(msg, name, math.nan)
    msg.jammer_to_signal_db = math.nan if jsr_db is None else float(jsr_db)
    return msg


def build(scenario: Scenario, section: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    """Validate ``section`` and yield ``(stamp_ns, topic, message)`` in stamp order.

    Args:
        scenario: the scenario (its ``duration_s`` is the length, s).
        section: the ``gnss_uwb`` section (see the module docstring).
        seed: seed of this stream; phase i is simulated with a seed drawn from
            ``np.random.default_rng(seed)``.

    Raises:
        ScenarioError: invalid section, or a nav file that gives fewer than 4 satellites at the
            start or the end of the scenario (raised before anything is yielded).
    """
    s, phases, nav = parse_section(scenario, section)
    try:
        geometry = BroadcastGeometry(nav)
    except (OSError, ValueError) as err:
        raise ScenarioError(f'gnss_uwb.nav_file {nav}: cannot read ({err})') from None
    week, tow0 = s.start_gps_week, s.start_gps_tow_s
    for t in (tow0, tow0 + scenario.duration_s):
        if geometry(week, t).prn.size < 4:
            raise ScenarioError(f'gnss_uwb: {nav.name} has fewer than 4 valid ephemerides at GPS week {week}, '
                                f'tow {t} s: choose start_gps_week/start_gps_tow_s within the file')
    return _generate(s, phases, geometry, seed)


def _enu_velocity(rx_ecef_m: np.ndarray, v_ecef_mps: np.ndarray) -> tuple[float, float, float]:
    """An ECEF velocity (m/s) in ENU at ``rx_ecef_m``, m/s."""
    from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic

    lat, lon, _ = ecef_to_geodetic(np.asarray(rx_ecef_m, dtype=float))
    east, north, up = (float(v) for v in ecef_to_enu_rotation(lat, lon) @ v_ecef_mps)
    return east, north, up


def _generate(s: GnssUwbSection, phases: JsrPhases, geometry: BroadcastGeometry, seed: int
              ) -> Iterator[tuple[int, str, Any]]:
    from rfi_node_common.conversions import epoch_to_msg, point_to_msg, uwb_to_msg

    week, tow0 = s.start_gps_week, s.start_gps_tow_s
    alpha = geometry.iono_alpha if s.ionosphere else None
    beta = geometry.iono_beta if s.ionosphere else None
    phase_seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=len(phases))
    ranges, azimuths, ups = s.anchors
    bias0_s, drift0 = _DEFAULT_SIM.clock_bias0_s, _DEFAULT_SIM.clock_drift0
    dt_g = 1.0 / s.gnss_rate_hz
    n_jam = max(1, round(TRUTH_JAMMER_PERIOD_S * s.gnss_rate_hz))
    rx0 = np.asarray(s.receiver_ecef_m, dtype=float)
    v_ecef = receiver_velocity_ecef(rx0, s.receiver_velocity_enu_mps)
    moving = bool(np.any(v_ecef != 0.0))
    spoofer = StreamSpoofer(s.spoofing, gps_to_ros_stamp_ns(week, tow0), seed) if s.spoofing else None
    t_start = 0.0
    for (jsr, dur), phase_seed in zip(phases, phase_seeds, strict=True):
        # A moving receiver starts the phase on its straight line, with the same ECEF velocity
        # (expressed in ENU at the phase's start) and the anchors around the first start.
        rx = rx0 + v_ecef * t_start if moving else rx0
        vel_enu = _enu_velocity(rx, v_ecef) if moving else (0.0, 0.0, 0.0)
        sim = GnssUwbScenario(
            jsr_db=jsr, duration_s=dur, seed=int(phase_seed), start_week=week, start_tow_s=tow0 + t_start,
            receiver_ecef_m=tuple(rx), receiver_velocity_enu_mps=vel_enu,
            anchor_origin_ecef_m=tuple(rx0) if moving else None, gnss_rate_hz=s.gnss_rate_hz,
            uwb_rate_hz=s.uwb_rate_hz, anchor_ranges_m=ranges, anchor_azimuths_deg=azimuths, anchor_up_m=ups,
            uwb_noise_std_m=s.uwb_noise_std_m, uwb_reported_std_m=s.uwb_reported_std_m,
            elevation_mask_deg=s.elevation_mask_deg, cn0_zenith_dbhz=s.cn0_zenith_dbhz,
            cn0_horizon_dbhz=s.cn0_horizon_dbhz, correlated_error_std_m=s.correlated_error_std_m,
            correlated_error_tau_s=s.correlated_error_tau_s, clock_bias0_s=bias0_s, clock_drift0=drift0,
            report_sigmas=s.report_sigmas)
        run = simulate(sim, geometry, alpha, beta)
        # The next phase's clock starts where this one ends (one GNSS period later).
        drift0 = float(run.truth.clock_drift_mps[-1]) / SPEED_OF_LIGHT_MPS
        bias0_s = float(run.truth.clock_bias_m[-1]) / SPEED_OF_LIGHT_MPS + drift0 * dt_g
        items: list[tuple[int, int, str, Any]] = []
        for k, epoch in enumerate(run.gnss_epochs):
            rx_k = run.truth.receiver_ecef_m_per_epoch[k]
            truth_items: list[tuple[str, Any]] = []
            if spoofer is not None:
                epoch, truth_items = spoofer.apply(epoch, rx_k, v_ecef, jsr)
            items.append((epoch.stamp_ns, 0, GNSS_TOPIC, epoch_to_msg(epoch)))
            items.append((epoch.stamp_ns, 1, TRUTH_POSITION_TOPIC, point_to_msg(epoch.stamp_ns, rx_k, EARTH_FRAME)))
            if s.truth_jammer_state and k % n_jam == 0:
                items.append((epoch.stamp_ns, 2, TRUTH_JAMMER_TOPIC, _jammer_truth(epoch.stamp_ns, jsr)))
            items += [(epoch.stamp_ns, 3 + j, topic, msg) for j, (topic, msg) in enumerate(truth_items)]
        items += [(u.stamp_ns, 9, UWB_TOPIC, uwb_to_msg(u)) for u in run.uwb_ranges]
        items.sort(key=lambda item: (item[0], item[1]))
        for stamp_ns, _, topic, msg in items:
            yield stamp_ns, topic, msg
        t_start += dur


def start_stamp_ns(section: Mapping[str, Any]) -> int:
    """ROS (UTC) stamp of the first GNSS epoch of a section (defaults applied), ns."""
    s = GnssUwbSection.from_mapping(section)
    return gps_to_ros_stamp_ns(s.start_gps_week, s.start_gps_tow_s)

"""Scenario stream ``correlators``: prompt correlators of the Zhao et al. scenario, and their truth.

Section keys (all optional; defaults are the paper's scenario, Zhao, Khanafseh & Pervan, Section VI-A)::

    correlators:
      start_gps_week: 2300            # GPS week of the start (continuous, not modulo 1024)
      start_gps_tow_s: 345600.0       # GPS time of week of the start, s; a multiple of 20 ms so that
                                      # the 50 bit/s data bits start on the GPS bit grid
      integration_time_s: 0.02        # coherent integration time T, s; must divide 20 ms (0.02, 0.01, 0.001)
      constellation: 1               # rfi_msgs GnssMeasurement constellation code (1 = GPS)
      frame_id: gnss_receiver         # header frame_id of /gnss/correlators
      clock: rubidium                 # a preset of gnss_common.clock_model.PRESETS, or a mapping of
                                      # h-coefficients {h0: 5.0e-25, h_minus2: 1.0e-30}
      clock_initial_frequency_hz: 0.0 # receiver clock frequency error at the start, Hz at the carrier
      nominal_cn0_dbhz: 51.0          # C/N0 of every satellite before the interference, dB-Hz
      onset_s: 120.0                  # interference onset, s after the start
      cn0_transition_s: 0.0           # the C/N0 drop is a linear ramp over this time, s (0: a step)
      doppler_range_hz: 3000.0        # initial Doppler drawn uniformly in +- this, Hz
      doppler_rate_range_hzps: 0.8    # Doppler rate drawn uniformly in +- this, Hz/s
      iq_scaling: unit_amplitude      # unit_amplitude (A = 1, eq. 5) or unit_noise (sigma = 1)
      satellites:                     # one entry per satellite: PRN and C/N0 drop at the onset, dB
        - {svid: 1, cn0_drop_db: 0.0}
        - {svid: 30, cn0_drop_db: 6.0}
        - {svid: 7, cn0_drop_db: 16.0}
        - {svid: 11, cn0_drop_db: 26.0}
        - {svid: 28, cn0_drop_db: 36.0}

In a scenario file with a top-level ``start`` and ``jamming`` schedule, ``start_gps_week`` and
``start_gps_tow_s`` come from ``start``, and ``onset_phase: {type: chirp, jsr_db: 22.0}`` (instead
of ``onset_s``) puts the onset at the start of the first phase of that type and J/S
(rfi_experiments.scenario resolves it); a key written here overrides the shared one.

The duration is the scenario's ``duration_s``. The builder runs
:func:`rfi_sim.correlators.simulate_correlators` (one receiver clock shared by all
satellites) and yields, for each interval k (stamp = end of the interval as a ROS (UTC) stamp,
converted from GPS time by gnss_common.gps_time.gps_ns_to_ros_stamp_ns),
``(stamp_ns, '/gnss/correlators', CorrelatorArray)`` and then
``(stamp_ns, '/truth/carrier', CarrierPhaseArray)``.

Truth (/truth/carrier): one CarrierPhase per satellite with ``method = 0`` (TRUTH_METHOD, none of
IMM/PLL/KF), ``phase_rad`` the true residual phase (receiver clock phase plus the channel's constant
initial phase, rad, unwrapped; a tracker's estimate equals it up to a constant multiple of pi, see
imm_carrier.cycle_slips), ``frequency_hz`` the true clock frequency error at the carrier, Hz,
``data_bit`` the true navigation bit, both standard deviations 0, ``data_bit_probability`` 1,
``locked`` true and ``cycle_slips`` 0.

The simulation is held in memory: about 100 bytes per satellite and interval (240 s of 32 satellites
at T = 1 ms is about 0.8 GB; split long 1 kHz runs).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

from gnss_common.clock_model import PRESETS, ClockHCoefficients
from gnss_common.constants import GPS_NAV_BIT_RATE_HZ
from gnss_common.gps_time import gps_ns_to_ros_stamp_ns, gps_to_gps_ns
from rfi_experiments.scenario import Scenario
from rfi_experiments.schema import ScenarioError, integer, number, reject_unknown_keys
from rfi_sim.correlators import CorrelatorScenario, simulate_correlators

CORRELATORS_TOPIC = '/gnss/correlators'
TRUTH_TOPIC = '/truth/carrier'
TRUTH_METHOD = 0
"""CarrierPhase.method of the truth messages (IMM = 1, PLL = 2, KF = 3 are trackers)."""

PAPER_SATELLITES = ({'svid': 1, 'cn0_drop_db': 0.0}, {'svid': 30, 'cn0_drop_db': 6.0},
                    {'svid': 7, 'cn0_drop_db': 16.0}, {'svid': 11, 'cn0_drop_db': 26.0},
                    {'svid': 28, 'cn0_drop_db': 36.0})
"""Zhao et al., Section VI-A: five satellites at 51 dB-Hz, drops of 0, 6, 16, 26 and 36 dB at the onset."""

DEFAULTS: dict[str, Any] = {
    'start_gps_week': 2300,
    'start_gps_tow_s': 345600.0,
    'integration_time_s': 0.02,
    'constellation': 1,
    'frame_id': 'gnss_receiver',
    'clock': 'rubidium',
    'clock_initial_frequency_hz': 0.0,
    'nominal_cn0_dbhz': 51.0,
    'onset_s': 120.0,
    'cn0_transition_s': 0.0,
    'doppler_range_hz': 3000.0,
    'doppler_rate_range_hzps': 0.8,
    'iq_scaling': 'unit_amplitude',
    'satellites': PAPER_SATELLITES,
}
"""Every section key and its default (the paper's scenario)."""

_CLOCK_KEYS = ('h0', 'h_minus2', 'h_minus1', 'h1', 'h2')


def _number(section: Mapping[str, Any], key: str) -> float:
    return number(section[key], f'correlators.{key}')


def _integer(section: Mapping[str, Any], key: str, low: int, high: int) -> int:
    return integer(section[key], f'correlators.{key}', low, high)


def _clock(value: Any) -> ClockHCoefficients:
    if isinstance(value, str):
        if value not in PRESETS:
            raise ScenarioError(f'correlators.clock: unknown preset {value!r} (known: {", ".join(PRESETS)})')
        return PRESETS[value]
    if isinstance(value, Mapping):
        unknown = set(value) - set(_CLOCK_KEYS)
        if unknown or not {'h0', 'h_minus2'} <= set(value):
            raise ScenarioError(f'correlators.clock: a mapping needs h0 and h_minus2 (optional h_minus1, h1, h2), '
                                f'got keys {", ".join(sorted(map(str, value)))}')
        try:
            return ClockHCoefficients(**{k: float(v) for k, v in value.items()}, name='scenario')
        except (TypeError, ValueError) as err:
            raise ScenarioError(f'correlators.clock: {err}') from None
    raise ScenarioError(f'correlators.clock must be a preset name or a mapping of h-coefficients, got {value!r}')


def _satellites(value: Any) -> tuple[tuple[int, ...], tuple[float, ...]]:
    if not isinstance(value, (list, tuple)) or not value:
        raise ScenarioError('correlators.satellites must be a non-empty list of {svid, cn0_drop_db}')
    svids, drops = [], []
    for i, sat in enumerate(value):
        if not isinstance(sat, Mapping) or set(sat) != {'svid', 'cn0_drop_db'}:
            raise ScenarioError(f'correlators.satellites[{i}] must be a mapping with exactly svid and cn0_drop_db, '
                                f'got {sat!r}')
        svids.append(_integer(sat, 'svid', 1, 255))
        drops.append(_number(sat, 'cn0_drop_db'))
    if len(set(svids)) != len(svids):
        raise ScenarioError(f'correlators.satellites: svids must be distinct, got {svids}')
    return tuple(svids), tuple(drops)


def parse_section(scenario: Scenario, section: Mapping[str, Any]) -> tuple[CorrelatorScenario, dict[str, Any]]:
    """Validate the section; return the simulator scenario and the resolved settings.

    Raises:
        ScenarioError: unknown key, wrong type or non-physical value (the message names the key).
    """
    reject_unknown_keys(section, tuple(DEFAULTS), 'correlators')
    s = {**DEFAULTS, **section}
    week = _integer(s, 'start_gps_week', 0, 10_000)
    tow_s = _number(s, 'start_gps_tow_s')
    t_s = _number(s, 'integration_time_s')
    if not 0.0 <= tow_s < 604800.0:
        raise ScenarioError(f'correlators.start_gps_tow_s must be in [0, 604800) s, got {tow_s}')
    bit_s = 1.0 / GPS_NAV_BIT_RATE_HZ
    if abs(tow_s / bit_s - round(tow_s / bit_s)) > 1e-6:
        raise ScenarioError(f'correlators.start_gps_tow_s must be a multiple of {bit_s} s so that data bits '
                            f'start on the GPS bit grid, got {tow_s}')
    s['start_gps_ns'] = gps_to_gps_ns(week, tow_s)  # GPS-scale ns of the start (gnss_common.gps_time)
    s['start_stamp_ns'] = gps_ns_to_ros_stamp_ns(s['start_gps_ns'])  # its ROS (UTC) header stamp
    s['constellation'] = _integer(s, 'constellation', 1, 255)
    if not isinstance(s['frame_id'], str):
        raise ScenarioError(f'correlators.frame_id must be a string, got {s["frame_id"]!r}')
    svids, drops = _satellites(s['satellites'])
    try:
        sim = CorrelatorScenario(
            svids=svids, cn0_drops_db=drops, nominal_cn0_dbhz=_number(s, 'nominal_cn0_dbhz'),
            onset_s=_number(s, 'onset_s'), duration_s=float(scenario.duration_s), integration_time_s=t_s,
            clock=_clock(s['clock']), clock_initial_frequency_hz=_number(s, 'clock_initial_frequency_hz'),
            doppler_range_hz=_number(s, 'doppler_range_hz'),
            doppler_rate_range_hzps=_number(s, 'doppler_rate_range_hzps'),
            iq_scaling=str(s['iq_scaling']), cn0_transition_s=_number(s, 'cn0_transition_s'))
    except ValueError as err:
        raise ScenarioError(f'correlators: {err}') from None
    if sim.n_steps < 1:
        raise ScenarioError(f'correlators: duration_s {scenario.duration_s} is shorter than one integration time')
    return sim, s


def build(scenario: Scenario, section: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    """Yield (stamp_ns, topic, message) of /gnss/correlators and /truth/carrier in stamp order.

    Args:
        scenario: the loaded scenario (its duration_s is the simulated span, s).
        section: the ``correlators`` section (keys: see the module docstring).
        seed: seed of the simulation (np.random.default_rng inside the simulator).

    Raises:
        ScenarioError: invalid section, raised by this call (before anything is simulated).

    Notes:
        Zhao, Khanafseh & Pervan, eq. 2-5 (I/Q model), eq. 6-8 (clock), Section VI-A (scenario).
    """
    sim_scenario, s = parse_section(scenario, section)
    return _generate(sim_scenario, s, int(seed))


def _generate(sim_scenario: CorrelatorScenario, s: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    from rfi_msgs.msg import CarrierPhase, CarrierPhaseArray, Correlator, CorrelatorArray
    from rfi_node_common.stamps import ns_to_stamp

    sim = simulate_correlators(sim_scenario, seed)
    start_gps_ns = s['start_gps_ns']
    constellation = s['constellation']
    t_s = sim_scenario.integration_time_s
    sats = [(sat.svid, sat.in_phase.tolist(), sat.quadrature.tolist(), sat.cn0_dbhz.tolist(),
             sat.predicted_phase_change_rad.tolist(), sat.truth_phase_rad.tolist(),
             sat.truth_frequency_hz.tolist(), sat.truth_bits.tolist()) for sat in sim.satellites]
    # Interval ends on the GPS-scale axis, stamped in ROS time by the one conversion (whole leap
    # seconds: the 20 ms bit grid of GPS time is also a 20 ms grid of the stamps).
    stamps = [gps_ns_to_ros_stamp_ns(t) for t in (sim.satellites[0].stamps_ns + start_gps_ns).tolist()]
    for k, stamp_ns in enumerate(stamps):
        stamp = ns_to_stamp(stamp_ns)
        arr = CorrelatorArray()
        arr.header.stamp = stamp
        arr.header.frame_id = s['frame_id']
        truth = CarrierPhaseArray()
        truth.header.stamp = stamp
        truth.header.frame_id = s['frame_id']
        for svid, zi, zq, cn0, dphi, phase, freq, bits in sats:
            arr.correlators.append(Correlator(
                constellation=constellation, svid=svid, integration_time_s=t_s, in_phase=zi[k], quadrature=zq[k],
                cn0_dbhz=cn0[k], predicted_phase_change_rad=dphi[k],
                carrier_lock=Correlator.CARRIER_LOCK_UNKNOWN))  # open-loop replica: no carrier loop, no lock
            truth.estimates.append(CarrierPhase(
                constellation=constellation, svid=svid, method=TRUTH_METHOD, phase_rad=phase[k], phase_std_rad=0.0,
                frequency_hz=freq[k], frequency_std_hz=0.0, data_bit=int(bits[k]), data_bit_probability=1.0,
                locked=True, cycle_slips=0))
        yield stamp_ns, CORRELATORS_TOPIC, arr
        yield stamp_ns, TRUTH_TOPIC, truth

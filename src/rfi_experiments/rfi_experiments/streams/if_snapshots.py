"""Scenario stream ``if_snapshots``: IF sample snapshots of a GNSS front end under a jamming schedule.

A snapshot monitor does not take the whole 38 MS/s stream: every ``period_s`` it takes one block of
``block_duration_s`` (1 ms is realistic). This builder yields exactly those blocks, each with the
``first_sample_index`` it has in the continuous stream (``round(t * sample_rate_hz)``), so a monitor
sees the gap between two snapshots as it would on the real front end, and the truth of each block.

Section keys (all optional; defaults: Kang et al.'s front end, Sec. 2.1 and 4, no jammer)::

    if_snapshots:
      start_stamp_ns: 1700000000000000000  # ROS (UTC) stamp of sample 0 of the stream, ns (int)
      frame_id: front_end                  # header frame_id of both topics
      center_frequency_hz: 1575420000.0    # RF centre the blocks are referenced to, Hz (GPS L1)
      sample_rate_hz: 38192000.0           # samples (complex: I/Q pairs) per second, Hz
      intermediate_frequency_hz: 9548000.0 # IF, Hz; 0 complex baseband; < 0 spectral inversion
      is_complex: false                    # I/Q samples (interleaved) instead of real ones
      bits: 8                              # quantisation, bits per real value, 1..16 (> 8: INT16 storage)
      clip_sigma: null                     # AGC full scale in input RMS units (null: 2 for <= 3 bits, else 4)
      noise_density_dbm_per_mhz: -114.0    # thermal noise density, dBm/MHz
      noise_bandwidth_hz: null             # band the noise power is counted over, Hz (null: the sampled band)
      signal_power_dbm: -130.0             # power of each GPS signal, dBm
      satellites: [{prn: 1, doppler_hz: 1000.0}]   # GPS C/A signals in the samples
      period_s: 1.0                        # one snapshot every period_s, s
      block_duration_s: 0.001              # length of each snapshot, s (<= period_s)
      phases:                              # jamming schedule; times in s from the stream start
        - {start_s: 0.0, end_s: 8.0, type: none}
        - {start_s: 8.0, end_s: 14.0, type: cw, jsr_db: 30.0, frequency_hz: 1.0e+6}
        - {start_s: 14.0, end_s: 20.0, type: chirp, jsr_db: 30.0, sweep_rate_hz_per_s: 1.0e+12}
        - {start_s: 20.0, end_s: 24.0, type: wideband, jsr_db: 30.0, bandwidth_hz: 2.0e+6}

Phase keys: those of a jamming phase (:mod:`rfi_experiments.schema`, the same as the scenario's
top-level ``jamming``; where no phase applies there is no jammer), sweeps starting at ``start_s``.
Every tone frequency must lie inside the sampled band. A snapshot belongs to the phase that contains
its first sample; put phase boundaries between snapshots.

Each snapshot is simulated by a fresh :class:`rfi_sim.if_signal.IfSimulator` (seeded
from ``(seed, k)``) whose jammers and satellites are shifted to the snapshot's time: the chirp's
position inside its sweep, the CW's and the satellites' carrier and code phases are those of the
continuous stream. Noise is independent between snapshots (as it is over a one-second gap). The
quantiser step is fixed by the configured powers of the current phase (an ideal AGC).

Yields, per snapshot k (stamp = stamp of its first sample, ``start_stamp_ns + round(index / fs)``):
``(stamp_ns, '/rfi/if_samples', IfSamples)`` then ``(stamp_ns, '/truth/jammer', JammerState)``.
Truth: ``type`` the phase's type, ``confidence`` 1, J/N (the simulator's, over the noise bandwidth)
and J/S, ``frequency_hz`` the true instantaneous frequency at the block's last sample (CW, chirp),
``frequency_std_hz`` 0, ``sweep_rate_hz_per_s`` (chirp; 0 for CW), ``sweep_period_s``,
``sweep_start_frequency_hz``, ``sweep_bandwidth_hz`` (chirp). NaN wherever a field does not apply
(every jammer field of a NONE block; the frequency fields of a wideband jammer).

Size: the bag holds ``sample_rate_hz * block_duration_s * (2 if complex) * (1 if bits <= 8 else 2)``
bytes per snapshot (plus about 250 bytes of headers and truth), i.e. per second of scenario that
divided by ``period_s``: 38.4 kB/s for the paper's front end (real, 8 bit, 1 ms every second), 20 s
about 0.8 MB.

In a scenario file with a top-level timeline (``start``, ``jamming``), ``start_stamp_ns`` and ``phases``
are derived from it by :func:`rfi_experiments.scenario.resolve_streams`; a key written in this
section overrides the derived one.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ, GPS_CA_CODE_LENGTH_CHIPS, GPS_L1_FREQUENCY_HZ
from gnss_common.gps_ca import G2_DELAY_CHIPS
from rfi_experiments.scenario import Scenario
from rfi_experiments.schema import Phase, ScenarioError, number, parse_phases, reject_unknown_keys
from rfi_sim.if_signal import (
    CHIRP,
    CW,
    NONE,
    PAPER_IF_HZ,
    PAPER_SAMPLE_RATE_HZ,
    WIDEBAND,
    ChirpJammer,
    CwJammer,
    FrontEndConfig,
    GpsSatellite,
    IfSimulator,
    Jammer,
    NoiseJammer,
)

IF_TOPIC = '/rfi/if_samples'
TRUTH_TOPIC = '/truth/jammer'

TYPES = {'none': NONE, 'cw': CW, 'chirp': CHIRP, 'wideband': WIDEBAND}
"""Phase type name -> rfi_msgs/JammerState type code."""

DEFAULTS: dict[str, Any] = {
    'start_stamp_ns': 1_700_000_000_000_000_000,
    'frame_id': 'front_end',
    'center_frequency_hz': GPS_L1_FREQUENCY_HZ,
    'sample_rate_hz': PAPER_SAMPLE_RATE_HZ,
    'intermediate_frequency_hz': PAPER_IF_HZ,
    'is_complex': False,
    'bits': 8,
    'clip_sigma': None,
    'noise_density_dbm_per_mhz': -114.0,
    'noise_bandwidth_hz': None,
    'signal_power_dbm': -130.0,
    'satellites': ({'prn': 1, 'doppler_hz': 1000.0},),
    'period_s': 1.0,
    'block_duration_s': 0.001,
    'phases': (),
}
"""Every section key and its default."""


def _number(where: str, value: Any) -> float:
    return number(value, f'if_snapshots.{where}')


def _phases(value: Any, duration_s: float, fe: FrontEndConfig) -> tuple[Phase, ...]:
    phases = parse_phases(value, duration_s, 'if_snapshots.phases', non_empty=False)
    for i, phase in enumerate(phases):
        _check_band(phase, f'phases[{i}]', fe)
    return phases


def _check_band(phase: Phase, where: str, fe: FrontEndConfig) -> None:
    """Raise if a tone of ``phase`` leaves the sampled band or its parameters are not physical."""
    s = phase.settings
    low, high = (-0.5, 0.5) if fe.is_complex else (0.0, 0.5)
    tones: list[float] = []
    if phase.type == 'cw':
        tones = [s['frequency_hz']]
    elif phase.type == 'chirp':
        if not s['sweep_period_s'] > 0 or s['sweep_rate_hz_per_s'] == 0:
            raise ScenarioError(f'if_snapshots.{where}: sweep_period_s must be > 0 and sweep_rate_hz_per_s != 0')
        tones = [s['start_frequency_hz'], s['start_frequency_hz'] + s['sweep_rate_hz_per_s'] * s['sweep_period_s']]
    elif phase.type == 'wideband':
        if not 0 < s['bandwidth_hz'] <= fe.sample_rate_hz:
            raise ScenarioError(f'if_snapshots.{where}.bandwidth_hz must be in (0, sample_rate_hz], '
                                f'got {s["bandwidth_hz"]}')
        tones = [s['center_frequency_hz']]
    for f_hz in tones:
        digital = float(fe.digital_frequency(f_hz))
        if not low < digital < high:
            raise ScenarioError(f'if_snapshots.{where}: frequency {f_hz} Hz (digital {digital:.4f} cycles/sample) '
                                f'is outside the sampled band ({low}, {high}) cycles/sample')


def _satellites(value: Any) -> tuple[GpsSatellite, ...]:
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(f'if_snapshots.satellites must be a list of {{prn, doppler_hz}}, got {value!r}')
    sats = []
    for i, sat in enumerate(value):
        if not isinstance(sat, Mapping) or not set(sat) <= {'prn', 'doppler_hz', 'code_phase_chips'} \
                or 'prn' not in sat:
            raise ScenarioError(f'if_snapshots.satellites[{i}] must be a mapping with prn and optional doppler_hz, '
                                f'code_phase_chips; got {sat!r}')
        prn = sat['prn']
        if isinstance(prn, bool) or not isinstance(prn, int) or prn not in G2_DELAY_CHIPS:
            raise ScenarioError(f'if_snapshots.satellites[{i}].prn must be a GPS PRN 1..37, got {prn!r}')
        sats.append(GpsSatellite(prn=prn, doppler_hz=_number(f'satellites[{i}].doppler_hz', sat.get('doppler_hz', 0.0)),
                                 code_phase_chips=_number(f'satellites[{i}].code_phase_chips',
                                                          sat.get('code_phase_chips', 0.0))))
    return tuple(sats)


def parse_section(scenario: Scenario, section: Mapping[str, Any]) -> dict[str, Any]:
    """Validate the section; return the resolved settings (front_end, satellites, phases, ...).

    Raises:
        ScenarioError: unknown key, wrong type or non-physical value (the message names the key).
    """
    reject_unknown_keys(section, tuple(DEFAULTS), 'if_snapshots')
    s = {**DEFAULTS, **section}
    start = s['start_stamp_ns']
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        raise ScenarioError(f'if_snapshots.start_stamp_ns must be an integer >= 0, got {start!r}')
    if not isinstance(s['frame_id'], str):
        raise ScenarioError(f'if_snapshots.frame_id must be a string, got {s["frame_id"]!r}')
    if not isinstance(s['is_complex'], bool):
        raise ScenarioError(f'if_snapshots.is_complex must be true or false, got {s["is_complex"]!r}')
    bits = s['bits']
    if isinstance(bits, bool) or not isinstance(bits, int) or not 1 <= bits <= 16:
        raise ScenarioError(f'if_snapshots.bits must be an integer in 1..16, got {bits!r}')
    try:
        fe = FrontEndConfig(
            sample_rate_hz=_number('sample_rate_hz', s['sample_rate_hz']),
            intermediate_frequency_hz=_number('intermediate_frequency_hz', s['intermediate_frequency_hz']),
            is_complex=s['is_complex'], bits=bits,
            clip_sigma=None if s['clip_sigma'] is None else _number('clip_sigma', s['clip_sigma']),
            noise_density_dbm_per_mhz=_number('noise_density_dbm_per_mhz', s['noise_density_dbm_per_mhz']),
            noise_bandwidth_hz=None if s['noise_bandwidth_hz'] is None
            else _number('noise_bandwidth_hz', s['noise_bandwidth_hz']),
            signal_power_dbm=_number('signal_power_dbm', s['signal_power_dbm']))
    except ValueError as err:
        raise ScenarioError(f'if_snapshots: {err}') from None
    center = _number('center_frequency_hz', s['center_frequency_hz'])
    period_s = _number('period_s', s['period_s'])
    block_s = _number('block_duration_s', s['block_duration_s'])
    n = round(block_s * fe.sample_rate_hz)
    if not (period_s > 0 and 0 < block_s <= period_s and n >= 1):
        raise ScenarioError(f'if_snapshots: need period_s > 0 and 0 < block_duration_s <= period_s with at least '
                            f'one sample per block, got period_s {period_s}, block_duration_s {block_s}')
    n_blocks = math.floor((scenario.duration_s - block_s) / period_s + 1e-9) + 1
    if n_blocks < 1:
        raise ScenarioError(f'if_snapshots: duration_s {scenario.duration_s} is shorter than one block')
    return {'start_stamp_ns': start, 'frame_id': s['frame_id'], 'center_frequency_hz': center,
            'front_end': fe, 'satellites': _satellites(s['satellites']),
            'phases': _phases(s['phases'], scenario.duration_s, fe),
            'period_s': period_s, 'block_samples': n, 'n_blocks': n_blocks}


def bytes_per_second(settings: Mapping[str, Any]) -> float:
    """Sample bytes per second of scenario of resolved ``settings`` (from :func:`parse_section`)."""
    fe = settings['front_end']
    per_block = settings['block_samples'] * (2 if fe.is_complex else 1) * (1 if fe.bits <= 8 else 2)
    return per_block / settings['period_s']


def build(scenario: Scenario, section: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    """Yield (stamp_ns, topic, message) of /rfi/if_samples and /truth/jammer in stamp order.

    Args:
        scenario: the loaded scenario (its duration_s is the simulated span, s).
        section: the ``if_snapshots`` section (keys: see the module docstring).
        seed: seed of the simulation; snapshot k uses ``SeedSequence([seed, k])``.

    Raises:
        ScenarioError: invalid section, raised by this call (before anything is simulated).

    Notes:
        Kang et al., Sec. 2.1 (front end, chirp eq. 2-5, CW eq. 6) and Sec. 4 (J/S 30 dB, 1e12 Hz/s).
    """
    settings = parse_section(scenario, section)
    return _generate(settings, int(seed))


def _phase_at(phases: tuple[Phase, ...], t_s: float) -> Phase | None:
    for p in phases:
        if p.start_s <= t_s < p.end_s:
            return p
    return None


def _jammer(phase: Phase, t_s: float, first_index: int, fe: FrontEndConfig) -> Jammer:
    """The phase's jammer, shifted so that the simulator's sample 0 is stream sample ``first_index``."""
    s = phase.settings
    if phase.type == 'cw':
        cycles = float(fe.digital_frequency(s['frequency_hz'])) * first_index
        return CwJammer(frequency_hz=s['frequency_hz'], js_db=phase.jsr_db,
                        phase_rad=2 * math.pi * (cycles - math.floor(cycles)))
    if phase.type == 'chirp':
        offset_s = math.fmod(t_s - phase.start_s, s['sweep_period_s'])
        return ChirpJammer(start_frequency_hz=s['start_frequency_hz'], sweep_rate_hz_per_s=s['sweep_rate_hz_per_s'],
                           sweep_period_s=s['sweep_period_s'], js_db=phase.jsr_db, time_offset_s=offset_s)
    return NoiseJammer(center_frequency_hz=s['center_frequency_hz'], bandwidth_hz=s['bandwidth_hz'],
                       js_db=phase.jsr_db)


def _shifted_satellite(sat: GpsSatellite, t_s: float, fe: FrontEndConfig) -> GpsSatellite:
    rate = GPS_CA_CHIP_RATE_HZ * (1.0 + sat.doppler_hz / GPS_L1_FREQUENCY_HZ)
    chips = math.fmod(sat.code_phase_chips + rate * t_s, GPS_CA_CODE_LENGTH_CHIPS)
    cycles = float(fe.digital_frequency(sat.doppler_hz)) * t_s * fe.sample_rate_hz
    return GpsSatellite(prn=sat.prn, doppler_hz=sat.doppler_hz, code_phase_chips=chips,
                        carrier_phase_rad=sat.carrier_phase_rad + 2 * math.pi * (cycles - math.floor(cycles)),
                        power_dbm=sat.power_dbm)


def _truth(phase: Phase | None, sim: IfSimulator, f_end_hz: float) -> dict[str, float]:
    nan = math.nan
    t = dict(type=NONE, jammer_to_noise_db=nan, jammer_to_signal_db=nan, frequency_hz=nan, frequency_std_hz=nan,
             sweep_rate_hz_per_s=nan, sweep_period_s=nan, sweep_start_frequency_hz=nan, sweep_bandwidth_hz=nan)
    if phase is None or phase.type == 'none':
        return t
    t.update(type=TYPES[phase.type], jammer_to_noise_db=sim.jn_db(sim.jammers[0]), jammer_to_signal_db=phase.jsr_db)
    s = phase.settings
    if phase.type == 'cw':
        t.update(frequency_hz=f_end_hz, frequency_std_hz=0.0, sweep_rate_hz_per_s=0.0)
    elif phase.type == 'chirp':
        t.update(frequency_hz=f_end_hz, frequency_std_hz=0.0, sweep_rate_hz_per_s=s['sweep_rate_hz_per_s'],
                 sweep_period_s=s['sweep_period_s'], sweep_start_frequency_hz=s['start_frequency_hz'],
                 sweep_bandwidth_hz=abs(s['sweep_rate_hz_per_s']) * s['sweep_period_s'])
    return t


def _generate(settings: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    from rfi_msgs.msg import IfSamples, JammerState
    from rfi_node_common.stamps import ns_to_stamp

    fe: FrontEndConfig = settings['front_end']
    fs = fe.sample_rate_hz
    n = settings['block_samples']
    storage = (IfSamples.INT8, '<i1') if fe.bits <= 8 else (IfSamples.INT16, '<i2')
    for k in range(settings['n_blocks']):
        first_index = round(k * settings['period_s'] * fs)
        t_s = first_index / fs
        stamp_ns = settings['start_stamp_ns'] + round(first_index * 1e9 / fs)
        phase = _phase_at(settings['phases'], t_s)
        jammers = () if phase is None or phase.type == 'none' else (_jammer(phase, t_s, first_index, fe),)
        sats = tuple(_shifted_satellite(s, t_s, fe) for s in settings['satellites'])
        block_seed = int(np.random.SeedSequence([seed, k]).generate_state(1)[0])
        sim = IfSimulator(fe, jammers, sats, seed=block_seed)
        blk = sim.generate(n)
        header_stamp = ns_to_stamp(stamp_ns)
        msg = IfSamples(sample_rate_hz=fs, intermediate_frequency_hz=fe.intermediate_frequency_hz,
                        center_frequency_hz=settings['center_frequency_hz'], is_complex=fe.is_complex,
                        first_sample_index=first_index, scale=float(blk.scale), bits_per_sample=fe.bits,
                        sample_format=storage[0])
        msg.header.stamp = header_stamp
        msg.header.frame_id = settings['frame_id']
        msg.samples = blk.counts.astype(storage[1]).tobytes()
        f_end = float(blk.truth.frequency_hz[0, -1]) if jammers else math.nan
        truth = JammerState(confidence=1.0, center_frequency_hz=settings['center_frequency_hz'], sample_rate_hz=fs,
                            **_truth(phase, sim, f_end))
        truth.header.stamp = header_stamp
        truth.header.frame_id = settings['frame_id']
        yield stamp_ns, IF_TOPIC, msg
        yield stamp_ns, TRUTH_TOPIC, truth

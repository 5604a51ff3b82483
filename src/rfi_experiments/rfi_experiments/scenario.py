"""Scenario files: load, validate, and turn into a bag.

A scenario is YAML::

    name: default
    description: one line
    seed: 7                 # every random stream derives from it
    duration_s: 180.0
    start: {gps_week: 1854, tow_s: 3600.0}   # optional: the start of every stream (GPS time)
    jamming:                # optional: the one jamming schedule every stream follows
      - {start_s: 0.0, end_s: 30.0, type: none}
      - {start_s: 30.0, end_s: 50.0, type: cw, jsr_db: 22.0, frequency_hz: 1.2e+6}
      - {start_s: 60.0, end_s: 180.0, type: chirp, jsr_db: 6.0, sweep_rate_hz_per_s: 1.0e+12}
    streams:                # one section per input stream; each maps to a builder below
      if_snapshots: {...}
      gnss_uwb: {...}
      correlators: {...}

The timeline. ``start`` (GPS week and time of week, s) and ``jamming`` (phases in s from the start:
``start_s``, ``end_s``, ``type`` none / cw / chirp / wideband, ``jsr_db`` (J/S at the antenna, dB;
not for none) and the type's waveform keys: cw ``frequency_hz``; chirp ``start_frequency_hz``,
``sweep_rate_hz_per_s``, ``sweep_period_s``; wideband ``center_frequency_hz``, ``bandwidth_hz``;
see streams/if_snapshots.py) are written once and every stream derives its own keys from them
(:func:`resolve_streams`):

- ``if_snapshots``: ``start_stamp_ns`` (the ROS (UTC) stamp of ``start``,
  :func:`gnss_common.gps_time.gps_to_ros_stamp_ns`) and ``phases`` (the phases as they are);
- ``gnss_uwb``: ``start_gps_week``, ``start_gps_tow_s`` and ``jamming`` (one ``{jsr_db, duration_s}``
  per phase, ``jsr_db: null`` for none and for the gaps between phases; the simulator models the
  J/S, whatever the waveform);
- ``rinex_jammed``: ``jamming`` as gnss_uwb (its start is the RINEX file's; a top-level ``start``
  is an error there);
- ``correlators``: ``start_gps_week``, ``start_gps_tow_s``, and ``onset_s`` (the C/N0 drops) from
  the section's ``onset_phase: {type, jsr_db}``: the start of the first phase of that type and J/S.

A key written in a stream section overrides the derived one (e.g. a stream that starts later);
a section may not give both ``onset_s`` and ``onset_phase``.

Each stream has a builder module in :mod:`rfi_experiments.streams` with a function
``build(scenario, section, seed)`` that validates its section (raising :class:`ScenarioError`)
and yields ``(stamp_ns, topic, message)`` in stamp order, truth topics included; the streams
are merged by stamp and written with :class:`rfi_experiments.bag_io.BagWriter`.
"""

from __future__ import annotations

import heapq
import importlib
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rfi_experiments.bag_io import BagWriter
from rfi_experiments.progress import ProgressLine
from rfi_experiments.schema import JAMMING_TYPES, ScenarioError, number, parse_phases


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario; ``streams`` holds each stream's section with the shared timeline resolved."""

    name: str
    description: str
    seed: int
    duration_s: float
    streams: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    source: Path | None = None
    start: tuple[int, float] | None = None  # (GPS week, time of week s) of the top-level ``start``
    jamming: tuple[Mapping[str, Any], ...] | None = None  # the top-level phases, validated


Builder = Callable[[Scenario, Mapping[str, Any], int], Iterator[tuple[int, str, Any]]]

STREAMS = {
    'if_snapshots': 'rfi_experiments.streams.if_snapshots',
    'gnss_uwb': 'rfi_experiments.streams.gnss_uwb',
    'correlators': 'rfi_experiments.streams.correlators',
    'rinex_jammed': 'rfi_experiments.streams.rinex_jammed',
}
"""Stream name -> module whose ``build(scenario, section, seed)`` yields (stamp_ns, topic, message)."""


def stream_builder(name: str) -> Builder:
    """The ``build`` function of stream ``name``."""
    if name not in STREAMS:
        raise ScenarioError(f'unknown stream {name!r} (known: {", ".join(sorted(STREAMS))})')
    return importlib.import_module(STREAMS[name]).build


def data_path(name: str) -> Path:
    """A file shipped in rfi_experiments/data (ephemerides, RINEX): the installed copy (ament
    index), else the source checkout's copy.

    Raises:
        ScenarioError: neither exists.
    """
    candidates = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            candidates.append(Path(get_package_share_directory('rfi_experiments')) / 'data' / name)
        except PackageNotFoundError:
            pass
    except ImportError:
        pass
    candidates.append(Path(__file__).resolve().parents[1] / 'data' / name)
    for path in candidates:
        if path.is_file():
            return path
    raise ScenarioError(f'no data file {name} (looked in {", ".join(map(str, candidates))}); install '
                        'rfi_experiments or give the file\'s path in the scenario section')


def scenarios_dir() -> Path:
    """The installed scenarios directory (share/rfi_experiments/scenarios)."""
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('rfi_experiments')) / 'scenarios'


def scenario_path(name_or_path: str) -> Path:
    """A scenario file: an existing path, or the name of a shipped scenario."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    shipped = scenarios_dir() / f'{name_or_path}.yaml'
    if shipped.is_file():
        return shipped
    known = ', '.join(sorted(p.stem for p in scenarios_dir().glob('*.yaml'))) or 'none'
    raise ScenarioError(f'no scenario file {name_or_path!r} (shipped scenarios: {known})')


def parse_start(value: Any, where: str = 'start') -> tuple[int, float]:
    """Validate ``start: {gps_week, tow_s}``; return (week, time of week s).

    Raises:
        ScenarioError: not a mapping of exactly those keys, week not an integer >= 0, or tow_s outside
            [0, 604800) s.
    """
    if not isinstance(value, Mapping) or set(value) != {'gps_week', 'tow_s'}:
        raise ScenarioError(f'{where} must be a mapping with exactly gps_week and tow_s, got {value!r}')
    week = value['gps_week']
    if isinstance(week, bool) or not isinstance(week, int) or not 0 <= week <= 10_000:
        raise ScenarioError(f'{where}.gps_week must be an integer in [0, 10000], got {week!r}')
    tow_s = number(value['tow_s'], f'{where}.tow_s')
    if not 0.0 <= tow_s < 604800.0:
        raise ScenarioError(f'{where}.tow_s must be in [0, 604800) s, got {tow_s}')
    return week, tow_s


def parse_jamming(value: Any, duration_s: float, where: str = 'jamming') -> tuple[dict[str, Any], ...]:
    """Validate the top-level jamming schedule (phases sorted, not overlapping, inside the scenario).

    Raises:
        ScenarioError: the message names the phase and the key.
    """
    return tuple(dict(p.given) for p in parse_phases(value, duration_s, where, non_empty=True))


def _jsr_schedule(jamming: Sequence[Mapping[str, Any]], duration_s: float) -> list[dict[str, Any]]:
    """The schedule as consecutive ``{jsr_db, duration_s}`` phases (gnss_uwb, rinex_jammed): one per
    phase, ``jsr_db`` None for none and for a gap before, between or after the phases."""
    out: list[dict[str, Any]] = []
    t = 0.0
    for p in jamming:
        if p['start_s'] > t:
            out.append({'jsr_db': None, 'duration_s': p['start_s'] - t})
        out.append({'jsr_db': None if p['type'] == 'none' else p['jsr_db'], 'duration_s': p['end_s'] - p['start_s']})
        t = p['end_s']
    if t < duration_s:
        out.append({'jsr_db': None, 'duration_s': duration_s - t})
    return out


def _onset_s(jamming: Sequence[Mapping[str, Any]] | None, value: Any, stream: str) -> float:
    """Start of the first phase with the type and J/S of ``onset_phase: {type, jsr_db}``, s."""
    where = f'{stream}.onset_phase'
    if not isinstance(value, Mapping) or set(value) != {'type', 'jsr_db'} or value['type'] not in JAMMING_TYPES[1:]:
        raise ScenarioError(f'{where} must be a mapping {{type: cw|chirp|wideband, jsr_db: J/S dB}}, got {value!r}')
    jsr_db = number(value['jsr_db'], f'{where}.jsr_db')
    if jamming is None:
        raise ScenarioError(f'{where} needs the top-level jamming schedule (or give onset_s)')
    for p in jamming:
        if p['type'] == value['type'] and float(p['jsr_db']) == jsr_db:
            return float(p['start_s'])
    raise ScenarioError(f'{where}: no {value["type"]} phase at {jsr_db} dB J/S in the jamming schedule')


def resolve_streams(streams: Mapping[str, Mapping[str, Any]], duration_s: float, start: tuple[int, float] | None,
                    jamming: Sequence[Mapping[str, Any]] | None) -> dict[str, dict[str, Any]]:
    """Each stream's section with the keys it derives from the shared ``start`` and ``jamming``
    (module docstring); keys already in a section are kept (per-stream overrides).

    Raises:
        ScenarioError: ``onset_s`` and ``onset_phase`` together, ``onset_phase`` without a schedule
            or matching no phase, or a top-level ``start`` with rinex_jammed.
    """
    from gnss_common.gps_time import gps_to_ros_stamp_ns

    out: dict[str, dict[str, Any]] = {}
    for name, section in streams.items():
        s = dict(section)
        if name == 'if_snapshots':
            if start is not None:
                s.setdefault('start_stamp_ns', gps_to_ros_stamp_ns(*start))
            if jamming is not None:
                s.setdefault('phases', [dict(p) for p in jamming])
        elif name in ('gnss_uwb', 'correlators'):
            if start is not None:
                s.setdefault('start_gps_week', start[0])
                s.setdefault('start_gps_tow_s', start[1])
            if name == 'gnss_uwb' and jamming is not None:
                s.setdefault('jamming', _jsr_schedule(jamming, duration_s))
            if name == 'correlators' and 'onset_phase' in s:
                if 'onset_s' in s:
                    raise ScenarioError('correlators: give onset_s or onset_phase, not both')
                s['onset_s'] = _onset_s(jamming, s.pop('onset_phase'), name)
        elif name == 'rinex_jammed':
            if start is not None:
                raise ScenarioError('rinex_jammed starts at the RINEX file\'s first epoch (its start_offset_s): '
                                    'remove the top-level start')
            if jamming is not None:
                s.setdefault('jamming', _jsr_schedule(jamming, duration_s))
        out[name] = s
    return out


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file; resolve the shared timeline into each stream's section."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ScenarioError(f'{path}: cannot read ({err})') from None
    if not isinstance(data, dict):
        raise ScenarioError(f'{path}: expected a mapping at the top level')
    unknown = set(data) - {'name', 'description', 'seed', 'duration_s', 'start', 'jamming', 'streams'}
    if unknown:
        raise ScenarioError(f'{path}: unknown key(s) {", ".join(sorted(unknown))}')
    try:
        seed = int(data['seed'])
        duration_s = float(data['duration_s'])
    except (KeyError, TypeError, ValueError) as err:
        raise ScenarioError(f'{path}: seed (int) and duration_s (float) are required ({err})') from None
    if not duration_s > 0:
        raise ScenarioError(f'{path}: duration_s must be > 0, got {duration_s}')
    streams = data.get('streams') or {}
    if not isinstance(streams, dict) or not streams:
        raise ScenarioError(f'{path}: streams must map stream names to their settings')
    for name, section in streams.items():
        if name not in STREAMS:
            raise ScenarioError(f'{path}: unknown stream {name!r} (known: {", ".join(sorted(STREAMS))})')
        if section is not None and not isinstance(section, dict):
            raise ScenarioError(f'{path}: stream {name} must be a mapping of settings')
    try:
        start = parse_start(data['start']) if 'start' in data else None
        jamming = parse_jamming(data['jamming'], duration_s) if 'jamming' in data else None
        resolved = resolve_streams({k: dict(v or {}) for k, v in streams.items()}, duration_s, start, jamming)
    except ScenarioError as err:
        raise ScenarioError(f'{path}: {err}') from None
    return Scenario(name=str(data.get('name', path.stem)), description=str(data.get('description', '')),
                    seed=seed, duration_s=duration_s, streams=resolved, source=path, start=start, jamming=jamming)


def scenario_messages(scenario: Scenario) -> Iterator[tuple[int, str, Any]]:
    """Every stream of ``scenario`` merged by stamp: ``(stamp_ns, topic, message)``, what the bag holds.

    Lazy: a caller that stops early (a window at the start) does not simulate the rest of the
    streams that simulate as they go (IF snapshots, GNSS/UWB phases). Stream i (sorted by name) is
    seeded ``seed + 1000 i``; at equal stamps the streams come in that order.

    Raises:
        ScenarioError: a section is invalid (raised by this call, before anything is simulated).
    """
    iterators = [stream_builder(name)(scenario, section, scenario.seed + 1000 * i)
                 for i, (name, section) in enumerate(sorted(scenario.streams.items()))]
    return heapq.merge(*iterators, key=lambda item: item[0])


def write_scenario_bag(scenario: Scenario, out: Path, *, overwrite: bool = False,
                       progress: ProgressLine | None = None) -> dict[str, int]:
    """Simulate every stream of ``scenario`` and write them, merged by stamp, to the bag ``out``.

    ``progress``, if given, gets the scenario's whole seconds as its total, is moved to the seconds of data
    written, and is closed at the end.
    """
    messages = scenario_messages(scenario)
    if progress is not None:
        progress.total = round(scenario.duration_s)
    try:
        with BagWriter(out, overwrite=overwrite) as bag:
            first = None
            for stamp_ns, topic, message in messages:
                bag.write(topic, message, stamp_ns)
                if progress is not None:
                    first = stamp_ns if first is None else first
                    progress.set_done(max(progress.done, round((stamp_ns - first) * 1e-9)))
            counts = dict(bag.counts)
    finally:
        if progress is not None:
            progress.close()
    return counts

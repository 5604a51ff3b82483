"""Scenario files: load, validate, and turn into a bag.

A scenario is YAML::

    name: default
    description: one line
    seed: 7                 # every random stream derives from it
    duration_s: 180.0
    streams:                # one section per input stream; each maps to a builder below
      if_snapshots: {...}
      gnss_uwb: {...}
      correlators: {...}

Each stream has a builder module in :mod:`rfi_experiments.streams` with a function
``build(scenario, section, seed)`` that validates its section (raising :class:`ScenarioError`)
and yields ``(stamp_ns, topic, message)`` in stamp order, truth topics included; the streams
are merged by stamp and written with :class:`rfi_experiments.bag_io.BagWriter`.
"""

from __future__ import annotations

import heapq
import importlib
import os
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rfi_experiments.bag_io import BagWriter


class ScenarioError(Exception):
    """A scenario file is missing or invalid; the message says which key and why."""


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    seed: int
    duration_s: float
    streams: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    source: Path | None = None


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


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ScenarioError(f'{path}: cannot read ({err})') from None
    if not isinstance(data, dict):
        raise ScenarioError(f'{path}: expected a mapping at the top level')
    unknown = set(data) - {'name', 'description', 'seed', 'duration_s', 'streams'}
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
    return Scenario(name=str(data.get('name', path.stem)), description=str(data.get('description', '')),
                    seed=seed, duration_s=duration_s, streams={k: dict(v or {}) for k, v in streams.items()},
                    source=path)


def write_scenario_bag(scenario: Scenario, out: Path, *, overwrite: bool = False,
                       progress: bool = False) -> dict[str, int]:
    """Simulate every stream of ``scenario`` and write them, merged by stamp, to the bag ``out``."""
    iterators = [stream_builder(name)(scenario, section, scenario.seed + 1000 * i)
                 for i, (name, section) in enumerate(sorted(scenario.streams.items()))]
    bar = None
    if progress:
        import sys

        from tqdm import tqdm
        bar = tqdm(total=round(scenario.duration_s), unit='s', desc=f'simulate {scenario.name}', file=sys.stderr)
    with BagWriter(out, overwrite=overwrite) as bag:
        first = None
        for stamp_ns, topic, message in heapq.merge(*iterators, key=lambda item: item[0]):
            bag.write(topic, message, stamp_ns)
            if bar is not None:
                first = stamp_ns if first is None else first
                bar.update(max(0, round((stamp_ns - first) * 1e-9) - bar.n))
        counts = dict(bag.counts)
    if bar is not None:
        bar.close()
    return counts

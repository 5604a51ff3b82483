"""Validation of scenario files: the error type, one checker per value kind, and the jamming phase schema.

Everything a scenario section is checked with lives here, below :mod:`rfi_experiments.scenario`
and the stream builders (:mod:`rfi_experiments.streams`), so that both use the same rules and the
same messages without importing each other:

* :class:`ScenarioError`, raised with a message that names the key (``where``) and why;
* :func:`number`, :func:`integer`, :func:`boolean`: a value of the YAML, checked and converted;
* the jamming phase: :data:`JAMMING_TYPES`, :data:`PHASE_KEYS` (each type's waveform keys and their
  defaults), :class:`Phase` and :func:`parse_phases`, used by the top-level ``jamming`` schedule of
  a scenario and by the ``phases`` of the ``if_snapshots`` stream.

Phase keys: ``start_s``, ``end_s`` (required, s from the start, 0 <= start_s < end_s <= duration_s,
phases sorted and not overlapping), ``type`` (none, cw, chirp, wideband), ``jsr_db`` (J/S at the
antenna, dB; required except for none), and per type: cw ``frequency_hz`` (relative to the RF
centre, default 0); chirp ``start_frequency_hz`` (default: digital 0.1832 at the paper's fs and IF),
``sweep_rate_hz_per_s`` (default 1e12, may be negative) and ``sweep_period_s`` (default: the
symmetric sweep about the IF, 5.10 us); wideband ``center_frequency_hz`` (default 0) and
``bandwidth_hz`` (default 2 MHz).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rfi_sim.if_signal import PAPER_SWEEP_RATE_HZ_PER_S, ChirpJammer


class ScenarioError(Exception):
    """A scenario file is missing or invalid; the message says which key and why."""


_YAML_EXPONENT_HINT = ' (YAML reads 1.0e12 as a string: write the exponent sign, 1.0e+12)'


def reject_unknown_keys(section: Mapping[str, Any], known: Sequence[str], where: str) -> None:
    """Raise :class:`ScenarioError` naming the keys of ``section`` that are not in ``known`` (and the known ones).

    Args:
        section: the mapping as written in the scenario.
        known: the accepted keys, in the order the message lists them.
        where: the section's name, the message's prefix.
    """
    unknown = set(section) - set(known)
    if unknown:
        raise ScenarioError(f'{where}: unknown key(s) {", ".join(sorted(map(str, unknown)))} '
                            f'(known: {", ".join(known)})')


def number(value: Any, where: str, low: float = -math.inf, high: float = math.inf, *,
           low_open: bool = False) -> float:
    """``value`` as a float: finite and in ``[low, high]`` (``(low, high]`` with ``low_open``).

    Raises:
        ScenarioError: ``{where} must be a finite number, got ...`` or ``{where} must be in [...]``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        hint = _YAML_EXPONENT_HINT if isinstance(value, str) and 'e' in value.lower() else ''
        raise ScenarioError(f'{where} must be a finite number, got {value!r}{hint}')
    value = float(value)
    if value < low or value > high or (low_open and value == low):
        raise ScenarioError(f'{where} must be in {"(" if low_open else "["}{low}, {high}], got {value}')
    return value


def integer(value: Any, where: str, low: int, high: int) -> int:
    """``value`` as an int in ``[low, high]`` (a bool is not an integer here).

    Raises:
        ScenarioError: ``{where} must be an integer in [low, high], got ...``.
    """
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ScenarioError(f'{where} must be an integer in [{low}, {high}], got {value!r}')
    return value


def boolean(value: Any, where: str) -> bool:
    """``value``, which must be true or false.

    Raises:
        ScenarioError: ``{where} must be true or false, got ...``.
    """
    if not isinstance(value, bool):
        raise ScenarioError(f'{where} must be true or false, got {value!r}')
    return value


JAMMING_TYPES = ('none', 'cw', 'chirp', 'wideband')
"""Phase types, in the order of the messages."""

_CHIRP_DEFAULT = ChirpJammer()

PHASE_KEYS: dict[str, dict[str, float]] = {
    'none': {},
    'cw': {'frequency_hz': 0.0},
    'chirp': {'start_frequency_hz': _CHIRP_DEFAULT.start_frequency_hz,
              'sweep_rate_hz_per_s': PAPER_SWEEP_RATE_HZ_PER_S,
              'sweep_period_s': _CHIRP_DEFAULT.sweep_period_s},
    'wideband': {'center_frequency_hz': 0.0, 'bandwidth_hz': 2.0e6},
}
"""Phase type -> its optional keys and their defaults (besides start_s, end_s, type, jsr_db)."""


@dataclass(frozen=True)
class Phase:
    """One validated phase of a jamming schedule (module docstring for the keys).

    Attributes:
        start_s, end_s: the phase's span from the start of the scenario, s.
        type: one of :data:`JAMMING_TYPES`.
        jsr_db: J/S at the antenna, dB (NaN for none).
        settings: the type's waveform keys (:data:`PHASE_KEYS`), defaults filled in.
        given: the phase as written (validated), e.g. to hand on to a stream's section.
    """

    start_s: float
    end_s: float
    type: str
    jsr_db: float
    settings: Mapping[str, float]
    given: Mapping[str, Any]


def parse_phases(value: Any, duration_s: float, where: str, *, non_empty: bool) -> tuple[Phase, ...]:
    """Validate a jamming schedule: a list of phases, sorted, not overlapping, inside ``[0, duration_s]``.

    Args:
        value: the list as read from YAML.
        duration_s: length of the scenario, s.
        where: the key of the list in messages (``jamming``, ``if_snapshots.phases``).
        non_empty: an empty list is an error.

    Raises:
        ScenarioError: the message names the phase (``{where}[i]``) and the key.
    """
    if not isinstance(value, (list, tuple)) or (non_empty and not value):
        what = 'a non-empty list' if non_empty else 'a list'
        raise ScenarioError(f'{where} must be {what} of phases {{start_s, end_s, type, jsr_db, ...}}, got {value!r}')
    phases: list[Phase] = []
    for i, p in enumerate(value):
        at = f'{where}[{i}]'
        if not isinstance(p, Mapping):
            raise ScenarioError(f'{at} must be a mapping, got {p!r}')
        kind = p.get('type')
        if kind not in JAMMING_TYPES:
            raise ScenarioError(f'{at}.type must be one of {", ".join(JAMMING_TYPES)}, got {kind!r}')
        allowed = {'start_s', 'end_s', 'type'} | set(PHASE_KEYS[kind]) | ({'jsr_db'} if kind != 'none' else set())
        unknown = set(p) - allowed
        if unknown:
            raise ScenarioError(f'{at}: unknown key(s) {", ".join(sorted(map(str, unknown)))} for type {kind} '
                                f'(known: {", ".join(sorted(allowed))})')
        for key in ('start_s', 'end_s') + (('jsr_db',) if kind != 'none' else ()):
            if key not in p:
                raise ScenarioError(f'{at}.{key} is required')
        start_s, end_s = number(p['start_s'], f'{at}.start_s'), number(p['end_s'], f'{at}.end_s')
        if not 0.0 <= start_s < end_s <= duration_s:
            raise ScenarioError(f'{at}: need 0 <= start_s < end_s <= duration_s ({duration_s}), got {start_s}, '
                                f'{end_s}')
        if phases and start_s < phases[-1].end_s:
            raise ScenarioError(f'{at}: phases must be sorted and not overlap (starts at {start_s} s, the previous '
                                f'one ends at {phases[-1].end_s} s)')
        jsr_db = number(p['jsr_db'], f'{at}.jsr_db') if kind != 'none' else math.nan
        settings = {k: number(p.get(k, d), f'{at}.{k}') for k, d in PHASE_KEYS[kind].items()}
        phases.append(Phase(start_s, end_s, kind, jsr_db, settings, dict(p)))
    return tuple(phases)


def optional_std(value: Any, where: str, high: float = 100.0) -> float:
    """A reported 1-sigma, m: null or .nan -> NaN (the consumer decides), else a number in (0, high].

    Raises:
        ScenarioError: not null, NaN or a number in (0, high].
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return math.nan
    return number(value, where, 0.0, high, low_open=True)


Anchors = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
"""UWB anchors as (ranges m, azimuths deg, heights above the tag m), one entry per anchor."""


def anchors(value: Any, where: str) -> Anchors:
    """UWB anchors around the tag: a non-empty list of ``{range_m, azimuth_deg, up_m}``.

    Raises:
        ScenarioError: not such a list, a value out of range, or an anchor whose range does not
            exceed its height.
    """
    if not isinstance(value, (list, tuple)) or not value:
        raise ScenarioError(f'{where} must be a non-empty list of {{range_m, azimuth_deg, up_m}}')
    ranges, azimuths, ups = [], [], []
    for i, a in enumerate(value):
        if not isinstance(a, Mapping) or set(a) != {'range_m', 'azimuth_deg', 'up_m'}:
            raise ScenarioError(f'{where}[{i}] must be a mapping with exactly range_m, azimuth_deg, up_m, got {a!r}')
        r = number(a['range_m'], f'{where}[{i}].range_m', 0.0, 1000.0, low_open=True)
        u = number(a['up_m'], f'{where}[{i}].up_m', -1000.0, 1000.0)
        if not r > abs(u):
            raise ScenarioError(f'{where}[{i}]: range_m {r} must exceed |up_m| {abs(u)}')
        ranges.append(r)
        azimuths.append(number(a['azimuth_deg'], f'{where}[{i}].azimuth_deg', -360.0, 360.0))
        ups.append(u)
    return tuple(ranges), tuple(azimuths), tuple(ups)


JSR_RANGE_DB = (-60.0, 80.0)
"""Accepted J/S of a phase, dB (beyond: certainly a typo)."""

JsrPhases = tuple[tuple[float | None, float], ...]
"""Consecutive phases ``(jsr_db or None for no jammer, duration_s)`` from the start of a stream."""


def jsr_phases(value: Any, duration_s: float, where: str, periods: Mapping[str, float]) -> JsrPhases:
    """A J/S schedule of consecutive ``{jsr_db, duration_s}`` phases covering ``duration_s`` exactly.

    Args:
        value: the list as read from YAML (``duration_s`` may be omitted on the last phase).
        duration_s: length of the scenario, s.
        where: the key of the list in messages (``gnss_uwb.jamming``).
        periods: measurement name -> rate, Hz: each phase lasts a whole number of periods of each.

    Raises:
        ScenarioError: the message names the phase and the key.
    """
    if not isinstance(value, (list, tuple)) or not value:
        raise ScenarioError(f'{where} must be a non-empty list of phases {{jsr_db, duration_s}}')
    phases: list[tuple[float | None, float]] = []
    elapsed = 0.0
    for i, ph in enumerate(value):
        at = f'{where}[{i}]'
        if not isinstance(ph, Mapping) or 'jsr_db' not in ph or not set(ph) <= {'jsr_db', 'duration_s'}:
            raise ScenarioError(f'{at} must be a mapping with jsr_db (null: no jammer) and duration_s (optional on '
                                f'the last phase), got {ph!r}')
        jsr = None if ph['jsr_db'] is None else number(ph['jsr_db'], f'{at}.jsr_db', *JSR_RANGE_DB)
        if 'duration_s' in ph:
            dur = number(ph['duration_s'], f'{at}.duration_s', 0.0, 1e6, low_open=True)
        elif i == len(value) - 1:
            dur = duration_s - elapsed
            if dur <= 1e-9:
                raise ScenarioError(f'{at}: the earlier phases already fill duration_s {duration_s}')
        else:
            raise ScenarioError(f'{at}.duration_s is required (only the last phase may omit it)')
        for rate_hz in periods.values():
            n = dur * rate_hz
            if abs(n - round(n)) > 1e-6 or round(n) < 1:
                whole = ' and '.join(f'{name} (1/{rate} s)' for name, rate in periods.items())
                raise ScenarioError(f'{at}.duration_s {dur} must be a whole number of {whole} periods')
        phases.append((jsr, dur))
        elapsed += dur
    if abs(elapsed - duration_s) > 1e-6:
        raise ScenarioError(f'{where}: the phases last {elapsed} s but the scenario lasts {duration_s} s')
    return tuple(phases)

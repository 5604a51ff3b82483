"""Spoofing attacks in scenario streams: the ``spoofing:`` list of a section, its injection into the
stream's GNSS epochs, and the truth topics that score a detector.

A section's ``spoofing`` is a list of attacks, each a mapping of the keys of
:class:`rfi_sim.spoofing.SpoofingAttack` (parsed by :func:`rfi_sim.spoofing.attack_from_dict`)::

    spoofing:
      - kind: position_push            # time_push | position_push | takeover | meaconing
        start_s: 60.0                  # from the stream's first epoch, s
        end_s: null                    # null: to the end
        push_velocity_enu_mps: [1.0, 0.0, 0.0]
        doppler_consistent: true       # false: the rates of the authentic signals (a simple spoofer)
        power_advantage_db: 3.0        # takeover power over the authentic signals, dB
        cn0_mode: single_transmitter   # or matched
        constellations: null           # e.g. [galileo]: only that constellation spoofed

The attacks are applied in turn to each epoch (each seeded from the stream's seed and its index);
their spans must be sorted and must not overlap (every attack but the last needs ``end_s``).

Truth topics (only in a stream with a ``spoofing`` list), per GNSS epoch at its stamp:

* ``/truth/integrity`` (rfi_msgs/GnssIntegrity, frame "truth"), every epoch: the output an ideal
  ``gnss_integrity`` would give (remapped to /gnss/integrity it is an ideal monitor for the
  fusion): ``spoofing_state`` DETECTED while an attack is on, else NONE; ``spoofing_scope`` ALL
  (an attack on every constellation) or CONSTELLATIONS; the affected constellations and
  satellites; ``first_alarm_stamp`` = ``first_detection_stamp`` = the attack's first epoch (0
  outside an attack); the jamming part from the stream's J/S (``jamming_state`` DETECTED with
  ``jammer_to_signal_db`` and std 0 in a jammed phase, else NONE with NaN, ``jammer_type``
  CHIRP / NONE as /truth/jammer_state); every other float NaN, no tests;
* ``/truth/spoofed_position`` (geometry_msgs/PointStamped, frame "earth"), while an attack is on:
  q, the position the spoofed satellites give (ECEF, m; against /truth/position: the push);
* ``/truth/spoofed_time`` (sensor_msgs/TimeReference), while an attack is on: ``time_ref`` =
  stamp + the clock offset the spoofed satellites add (time push; meaconing: the delay plus the
  meacon-to-receiver path), ns resolution; ``source`` the attack's kind.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from gnss_common.observations import GnssEpoch
from rfi_experiments.schema import ScenarioError
from rfi_sim.spoofing import AttackInjector, EpochAttackTruth, SpoofingAttack, attack_from_dict

TRUTH_INTEGRITY_TOPIC = '/truth/integrity'
TRUTH_SPOOFED_POSITION_TOPIC = '/truth/spoofed_position'
TRUTH_SPOOFED_TIME_TOPIC = '/truth/spoofed_time'
TRUTH_FRAME = 'truth'


def parse_spoofing(value: Any, duration_s: float, where: str) -> tuple[SpoofingAttack, ...]:
    """Validate a ``spoofing`` list (module docstring).

    Args:
        value: the list as read from YAML (None or empty: no attack); items already parsed pass.
        duration_s: length of the scenario, s: every attack starts before it.
        where: the key in messages (``gnss_uwb.spoofing``).

    Raises:
        ScenarioError: the message names the attack (``{where}[i]``) and the key.
    """
    if value is None:
        return ()
    if not isinstance(value, (list, tuple)):
        raise ScenarioError(f'{where} must be a list of attacks {{kind, start_s, ...}}, got {value!r}')
    attacks: list[SpoofingAttack] = []
    for i, item in enumerate(value):
        try:
            attack = item if isinstance(item, SpoofingAttack) else attack_from_dict(item)
        except ValueError as err:
            raise ScenarioError(f'{where}[{i}]: {err}') from None
        if attack.start_s >= duration_s:
            raise ScenarioError(f'{where}[{i}].start_s {attack.start_s} is not before the end of the scenario '
                                f'({duration_s} s)')
        if attacks:
            prev = attacks[-1]
            if prev.end_s is None or prev.end_s > attack.start_s:
                raise ScenarioError(f'{where}[{i}]: attacks must be sorted and not overlap (starts at '
                                    f'{attack.start_s} s, the previous one ends at '
                                    f'{"the end" if prev.end_s is None else f"{prev.end_s} s"})')
        attacks.append(attack)
    return tuple(attacks)


class StreamSpoofer:
    """The attacks of one stream applied in turn to its epochs, with their truth messages.

    Args:
        attacks: validated attacks (:func:`parse_spoofing`).
        first_stamp_ns: stamp of the stream's first epoch (t = 0 of the attacks), ns.
        seed: the stream's seed; attack i draws its C/N0 from a seed derived from it and i.
    """

    def __init__(self, attacks: Sequence[SpoofingAttack], first_stamp_ns: int, seed: int) -> None:
        seeds = np.random.default_rng([int(seed), 0x5F00F]).integers(0, 2**31 - 1, size=len(attacks))
        self.injectors = [AttackInjector(a, first_stamp_ns, int(s)) for a, s in zip(attacks, seeds, strict=True)]
        self._first_attacked_ns: dict[int, int] = {}

    def apply(self, epoch: GnssEpoch, receiver_ecef_m: np.ndarray, receiver_velocity_ecef_mps: np.ndarray,
              jsr_db: float | None) -> tuple[GnssEpoch, list[tuple[str, Any]]]:
        """The epoch under the attacks and its truth messages ``(topic, message)`` (module docstring).

        Args:
            epoch: the clean epoch.
            receiver_ecef_m, receiver_velocity_ecef_mps: true receiver state, ECEF, m and m/s, (3,).
            jsr_db: the stream's J/S at this epoch, dB (None: no jammer).
        """
        row: EpochAttackTruth | None = None
        index = -1
        for i, injector in enumerate(self.injectors):
            epoch, r = injector.apply(epoch, receiver_ecef_m, receiver_velocity_ecef_mps)
            if r.attacked:
                row, index = r, i
                self._first_attacked_ns.setdefault(i, epoch.stamp_ns)
        stamp = epoch.stamp_ns
        attack = None if row is None else self.injectors[index].attack
        items: list[tuple[str, Any]] = [(TRUTH_INTEGRITY_TOPIC, integrity_truth_msg(
            stamp, row, attack, self._first_attacked_ns.get(index, 0), jsr_db))]
        if row is not None and attack is not None:
            from rfi_node_common.conversions import point_to_msg
            items.append((TRUTH_SPOOFED_POSITION_TOPIC, point_to_msg(stamp, row.spoofed_position_ecef_m, 'earth')))
            items.append((TRUTH_SPOOFED_TIME_TOPIC, _time_truth(stamp, row.time_offset_s, attack.kind)))
        return epoch, items


def integrity_truth_msg(stamp_ns: int, row: EpochAttackTruth | None, attack: SpoofingAttack | None,
                        first_attacked_ns: int, jsr_db: float | None):
    """The rfi_msgs/GnssIntegrity an ideal monitor publishes for one epoch (module docstring).

    Args:
        stamp_ns: the epoch's stamp, ns.
        row: the epoch's attack truth (None: no attack on).
        attack: the attack that is on (None: none).
        first_attacked_ns: stamp of that attack's first epoch, ns.
        jsr_db: J/S at the antenna, dB (None: no jammer).
    """
    from rfi_msgs.msg import GnssIntegrity, JammerState
    from rfi_node_common.stamps import ns_to_stamp

    msg = GnssIntegrity()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = TRUTH_FRAME
    jammed = jsr_db is not None
    msg.jamming_state = GnssIntegrity.STATE_DETECTED if jammed else GnssIntegrity.STATE_NONE
    msg.jammer_to_signal_db = float(jsr_db) if jsr_db is not None else math.nan
    msg.jammer_to_signal_std_db = 0.0 if jammed else math.nan
    msg.jammer_type = JammerState.CHIRP if jammed else JammerState.NONE
    for name in ('cn0_drop_db', 'jammer_frequency_hz', 'jammer_bandwidth_hz'):
        setattr(msg, name, math.nan)
    if row is None or attack is None:
        msg.spoofing_state = GnssIntegrity.STATE_NONE
        msg.spoofing_scope = GnssIntegrity.SCOPE_NONE
        return msg
    msg.spoofing_state = GnssIntegrity.STATE_DETECTED
    every = attack.constellations is None
    msg.spoofing_scope = GnssIntegrity.SCOPE_ALL if every else GnssIntegrity.SCOPE_CONSTELLATIONS
    pairs = sorted(row.affected)
    msg.affected_constellations = sorted(attack.constellations or {c for c, _ in pairs})
    msg.affected_satellite_constellations = [c for c, _ in pairs]
    msg.affected_svids = [s for _, s in pairs]
    msg.first_alarm_stamp = ns_to_stamp(first_attacked_ns)
    msg.first_detection_stamp = ns_to_stamp(first_attacked_ns)
    return msg


def _time_truth(stamp_ns: int, time_offset_s: float, kind: str):
    from sensor_msgs.msg import TimeReference

    from rfi_node_common.stamps import ns_to_stamp

    msg = TimeReference()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = TRUTH_FRAME
    msg.time_ref = ns_to_stamp(stamp_ns + round(time_offset_s * 1e9))
    msg.source = kind
    return msg


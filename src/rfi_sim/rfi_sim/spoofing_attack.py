"""The definition of a spoofing attack: :class:`SpoofingAttack`, validated, and its parser from a plain
mapping (:func:`attack_from_dict`, for scenario files). The physics and the injection are in
:mod:`rfi_sim.spoofing`, which re-exports both.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from gnss_common.observations import BEIDOU, GALILEO, GLONASS, GPS, QZSS, SBAS

ATTACK_KINDS = ("time_push", "position_push", "takeover", "meaconing")
"""The attack kinds (module docstring)."""
CN0_MODES = ("single_transmitter", "matched")
"""How the spoofed C/N0 is made (module docstring)."""
CONSTELLATION_CODES = {"gps": GPS, "glonass": GLONASS, "galileo": GALILEO, "beidou": BEIDOU, "qzss": QZSS,
                       "sbas": SBAS}
"""Constellation names accepted in an attack dict -> rfi_msgs/GnssMeasurement codes."""
DEFAULT_MEACONING_DELAY_S = 2.0e-6
"""Delay of a meacon (reception, amplification, cables, retransmission) when none is given, s."""
MAX_TIME_PUSH_NS_PER_S = 1.0e4
"""Largest accepted |time push|, ns/s (3 km/s of pseudorange rate)."""
MAX_PUSH_SPEED_MPS = 1000.0
"""Largest accepted |push velocity|, m/s."""


@dataclass(frozen=True)
class SpoofingAttack:
    """One attack (module docstring for the physics).

    Attributes:
        kind: one of :data:`ATTACK_KINDS`.
        start_s: attack start from the run's first epoch, s (>= 0).
        end_s: attack end, s (> start_s; None: to the end of the run).
        doppler_consistent: True: rates follow the pseudorange change (eq. 2, a careful spoofer);
            False: rates of the authentic signals (eq. 3). Meaconing: always True.
        constellations: codes of the spoofed constellations (None: all).
        time_push_ns_per_s: clock push rate r, ns/s (time_push: non-zero; takeover: optional).
        push_velocity_enu_mps: position push velocity, m/s, ENU at p(t0) (position_push: non-zero;
            takeover: optional).
        power_advantage_db: A, spoofed over authentic power, dB.
        cn0_mode: one of :data:`CN0_MODES`.
        cn0_satellite_std_db: std of the fixed per-satellite offset b_i (single transmitter), dB.
        cn0_common_std_db: std of the common fluctuation f(t), dB.
        cn0_common_tau_s: correlation time of f(t), s.
        cn0_noise_std_db: std of the per-epoch estimation noise n_ik (single transmitter), dB.
        meaconing_delay_s: meacon delay d, s (meaconing only; None: :data:`DEFAULT_MEACONING_DELAY_S`).
        meacon_offset_enu_m: meacon antenna minus p(t0), m, ENU (meaconing only; None: zero).

    Raises:
        ValueError: a value out of range or a field the kind does not take (the message names it).
    """

    kind: str
    start_s: float
    end_s: float | None = None
    doppler_consistent: bool = True
    constellations: tuple[int, ...] | None = None
    time_push_ns_per_s: float = 0.0
    push_velocity_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    power_advantage_db: float = 3.0
    cn0_mode: str = "single_transmitter"
    cn0_satellite_std_db: float = 0.5
    cn0_common_std_db: float = 1.0
    cn0_common_tau_s: float = 2.0
    cn0_noise_std_db: float = 0.3
    meaconing_delay_s: float | None = None
    meacon_offset_enu_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        def bad(key: str, why: str) -> ValueError:
            return ValueError(f"spoofing attack {key}: {why}, got {getattr(self, key)!r}")

        if self.kind not in ATTACK_KINDS:
            raise bad("kind", f"must be one of {', '.join(ATTACK_KINDS)}")
        if not (math.isfinite(self.start_s) and self.start_s >= 0.0):
            raise bad("start_s", "must be a finite time >= 0 s")
        if self.end_s is not None and not (math.isfinite(self.end_s) and self.end_s > self.start_s):
            raise bad("end_s", "must be None or a finite time after start_s")
        if self.cn0_mode not in CN0_MODES:
            raise bad("cn0_mode", f"must be one of {', '.join(CN0_MODES)}")
        if self.constellations is not None:
            codes = tuple(self.constellations)
            if not codes or len(set(codes)) != len(codes) or not set(codes) <= set(CONSTELLATION_CODES.values()):
                raise bad("constellations", "must be None or distinct constellation codes "
                          f"{sorted(CONSTELLATION_CODES.values())}")
            object.__setattr__(self, "constellations", codes)
        for key, low, high in (("power_advantage_db", -20.0, 30.0), ("cn0_satellite_std_db", 0.0, 10.0),
                               ("cn0_common_std_db", 0.0, 10.0), ("cn0_noise_std_db", 0.0, 10.0)):
            if not low <= getattr(self, key) <= high:
                raise bad(key, f"must be in [{low}, {high}] dB")
        if not 0.0 < self.cn0_common_tau_s <= 1e4:
            raise bad("cn0_common_tau_s", "must be in (0, 1e4] s")
        if not abs(self.time_push_ns_per_s) <= MAX_TIME_PUSH_NS_PER_S:
            raise bad("time_push_ns_per_s", f"must be within +-{MAX_TIME_PUSH_NS_PER_S} ns/s")
        push = np.asarray(self.push_velocity_enu_mps, dtype=float)
        if push.shape != (3,) or not np.linalg.norm(push) <= MAX_PUSH_SPEED_MPS:
            raise bad("push_velocity_enu_mps", f"must be 3 numbers (east, north, up), at most {MAX_PUSH_SPEED_MPS} m/s")
        object.__setattr__(self, "push_velocity_enu_mps", tuple(float(v) for v in push))
        self._check_kind(push)

    def _check_kind(self, push: np.ndarray) -> None:
        """The fields each kind needs and refuses."""
        moving, timing = bool(np.any(push != 0.0)), self.time_push_ns_per_s != 0.0
        if self.kind != "meaconing":
            for key in ("meaconing_delay_s", "meacon_offset_enu_m"):
                if getattr(self, key) is not None:
                    raise ValueError(f"spoofing attack {key}: only for kind meaconing (this is {self.kind})")
        if self.kind == "time_push" and (not timing or moving):
            raise ValueError("spoofing attack time_push_ns_per_s: kind time_push needs a non-zero time push and "
                             "no push_velocity_enu_mps (use kind takeover for both)")
        if self.kind == "position_push" and (not moving or timing):
            raise ValueError("spoofing attack push_velocity_enu_mps: kind position_push needs a non-zero push "
                             "velocity and no time_push_ns_per_s (use kind takeover for both)")
        if self.kind != "meaconing":
            return
        if moving or timing:
            raise ValueError("spoofing attack push_velocity_enu_mps / time_push_ns_per_s: a meacon replays, it "
                             "does not push (give meacon_offset_enu_m and meaconing_delay_s)")
        if not self.doppler_consistent:
            raise ValueError("spoofing attack doppler_consistent: a meacon's replay is consistent by construction")
        delay = DEFAULT_MEACONING_DELAY_S if self.meaconing_delay_s is None else float(self.meaconing_delay_s)
        if not 0.0 < delay <= 1e-3:
            raise ValueError(f"spoofing attack meaconing_delay_s: must be in (0, 1e-3] s, got {delay!r}")
        offset = np.zeros(3) if self.meacon_offset_enu_m is None else np.asarray(self.meacon_offset_enu_m, float)
        if offset.shape != (3,) or not np.linalg.norm(offset) <= 1e5:
            raise ValueError("spoofing attack meacon_offset_enu_m: must be 3 numbers (east, north, up) within "
                             f"100 km, m, got {self.meacon_offset_enu_m!r}")
        object.__setattr__(self, "meaconing_delay_s", delay)
        object.__setattr__(self, "meacon_offset_enu_m", tuple(float(v) for v in offset))

    def spoofs(self, constellation: int) -> bool:
        """True when satellites of ``constellation`` are spoofed."""
        return self.constellations is None or constellation in self.constellations


def attack_from_dict(value: Any) -> SpoofingAttack:
    """A :class:`SpoofingAttack` from a plain mapping (one item of a scenario's ``spoofing:`` list).

    Keys are the attribute names of :class:`SpoofingAttack`; ``kind`` and ``start_s`` are
    required. ``constellations`` is a list of names (:data:`CONSTELLATION_CODES`, any case) or
    codes; vectors are lists of 3 numbers.

    Raises:
        ValueError: not a mapping, an unknown or missing key, or a bad value (the message names the key).
    """
    if not isinstance(value, Mapping):
        raise ValueError(f"spoofing attack must be a mapping of keys {{kind, start_s, ...}}, got {value!r}")
    known = [f.name for f in fields(SpoofingAttack)]
    unknown = sorted(map(str, set(value) - set(known)))
    if unknown:
        raise ValueError(f"spoofing attack: unknown key(s) {', '.join(unknown)} (known: {', '.join(known)})")
    for key in ("kind", "start_s"):
        if key not in value:
            raise ValueError(f"spoofing attack {key}: required")
    out: dict[str, Any] = {}
    for key, v in value.items():
        if key in ("kind", "cn0_mode"):
            if not isinstance(v, str):
                raise ValueError(f"spoofing attack {key}: must be a string, got {v!r}")
            out[key] = v
        elif key == "doppler_consistent":
            if not isinstance(v, bool):
                raise ValueError(f"spoofing attack {key}: must be true or false, got {v!r}")
            out[key] = v
        elif key == "constellations":
            out[key] = None if v is None else _constellations(v)
        elif key in ("push_velocity_enu_mps", "meacon_offset_enu_m"):
            if v is None and key == "meacon_offset_enu_m":
                out[key] = None
                continue
            if not isinstance(v, (list, tuple)) or len(v) != 3:
                raise ValueError(f"spoofing attack {key}: must be a list of 3 numbers (east, north, up), got {v!r}")
            out[key] = tuple(_number(x, key) for x in v)
        elif v is None and key in ("end_s", "meaconing_delay_s"):
            out[key] = None
        else:
            out[key] = _number(v, key)
    return SpoofingAttack(**out)


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"spoofing attack {key}: must be a finite number, got {value!r}")
    return float(value)


def _constellations(value: Any) -> tuple[int, ...]:
    if not isinstance(value, (list, tuple)) or not value:
        raise ValueError(f"spoofing attack constellations: must be a non-empty list of names "
                         f"({', '.join(CONSTELLATION_CODES)}) or codes, got {value!r}")
    out = []
    for item in value:
        if isinstance(item, str) and item.lower() in CONSTELLATION_CODES:
            out.append(CONSTELLATION_CODES[item.lower()])
        elif isinstance(item, int) and not isinstance(item, bool) and item in CONSTELLATION_CODES.values():
            out.append(item)
        else:
            raise ValueError(f"spoofing attack constellations: unknown constellation {item!r} "
                             f"(names: {', '.join(CONSTELLATION_CODES)}; codes: 1-6)")
    return tuple(out)

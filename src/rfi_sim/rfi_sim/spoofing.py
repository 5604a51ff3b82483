"""Spoofing and meaconing attacks injected into GNSS measurement epochs (issue 25, item 5).

Pure numpy, seeded. :func:`apply_attack` turns a clean sequence of :class:`GnssEpoch` (from the
GNSS/UWB simulator or a real RINEX day built with ``gnss_common.measurements.build_epochs``) into
the epochs a receiver would output under one :class:`SpoofingAttack`, with an :class:`AttackTruth`
to score detectors against; :class:`AttackInjector` does the same epoch by epoch (for streams).
Stamps, satellites and every field but pseudorange, pseudorange rate and C/N0 stay as they are;
satellites outside the attacked constellations, and every epoch outside the attack, are the input
objects themselves (bit-identical). The attack's definition and its parser from a plain mapping
(scenario files) are in :mod:`rfi_sim.spoofing_attack`, re-exported here.

Physics. The victim is at the true position p(t) (ECEF, m) with velocity v_r(t) (m/s). Satellite
i is at ``s_i`` in the ECEF frame of transmission with velocity ``sdot_i`` (the epoch's fields).
The geometric range from a point x and its rate for a receiver velocity v are (Cao et al., eq. 5-6,
with the Earth's rotation during the flight, ``gnss_common.earth_rotation.sagnac_rotate``)::

    rho_i(x)       = |R3(w tau_i) s_i - x|
    rhodot_i(x, v) = e_i(x) . (R3(w tau_i) sdot_i - v),   e_i(x) = (R3(w tau_i) s_i - x) / rho_i(x)

A spoofer that wants the receiver to compute the position q(t) and a clock offset grown by
dt_s(t) (s) sends, for every spoofed satellite, signals whose pseudorange and rate are::

    pr_i'   = pr_i   + rho_i(q) - rho_i(p) + c dt_s                                      (1)
    rate_i' = rate_i + rhodot_i(q, qdot) - rhodot_i(p, v_r) + c d(dt_s)/dt   (consistent)   (2)
    rate_i' = rate_i                                                          (simple)     (3)

(everything else of the authentic signal, satellite clocks and atmosphere included, reproduced).
A careful spoofer keeps the Doppler consistent with its code (2); a simple one shifts only the
code, and the Doppler the receiver measures is still that of the authentic signals (3). Attacks,
with t0 = ``start_s``, R0 the ENU rotation at p(t0) and tau = t - t0:

* ``time_push``: q = p, dt_s = r tau (r = ``time_push_ns_per_s`` 1e-9): every spoofed pseudorange
  grows by ``c r tau``, every rate by ``c r`` (consistent);
* ``position_push``: q = p + R0^T v_push tau (v_push = ``push_velocity_enu_mps``), dt_s = 0: the
  spoofer drags the victim's true trajectory (for a static receiver p0 + v tau), qdot = v_r +
  R0^T v_push;
* ``takeover``: the spoofer captures the tracking loops at t0 with its power advantage, then drags
  with the optional push velocity and time push (either, both or none);
* ``meaconing``: a delayed replay of all signals received by an antenna at m = p(t0) + R0^T o
  (o = ``meacon_offset_enu_m``, static): q = m, and every pseudorange also carries the meacon's
  delay d (``meaconing_delay_s``) and the meacon-to-victim path: ``c dt_s = c d + |m - p(t)|``;
  the Doppler is the meacon antenna's plus the victim's motion along that path
  (``rate_i' = rate_i + rhodot_i(m, 0) - rhodot_i(p, v_r) + u . v_r``, u = (p - m) / |p - m|):
  consistent by construction, as a replay is.

C/N0 (dB-Hz) of the spoofed satellites, with L = median clean C/N0 of the attacked constellations
in the last epoch before the attack, A = ``power_advantage_db``, f(t) a common first-order
Gauss-Markov fluctuation shared by all spoofed satellites (std ``cn0_common_std_db``, correlation
time ``cn0_common_tau_s``: ``f_k = phi f_{k-1} + std sqrt(1 - phi^2) w_k``, phi = exp(-dt / tau)):

* ``single_transmitter`` (one antenna sends every signal): ``L + A + b_i + f(t) + n_ik``, b_i a
  per-satellite offset (std ``cn0_satellite_std_db``, fixed per satellite: the spoofer's channel
  gains) and n_ik the receiver's estimation noise (std ``cn0_noise_std_db``). The elevation
  dependence of the authentic signals is lost and the satellites rise and fall together;
* ``matched`` (a careful spoofer that copies each satellite's authentic power): ``C/N0_i + A +
  f(t)``.

A C/N0 that is NaN (a file without C/N0) stays NaN. After ``end_s`` the spoofer is off and the
receiver tracks the authentic signals again (the epochs pass through).

Not modelled: the transient of the capture itself (the loops are assumed pulled off smoothly at
t0), the spoofer's own clock and antenna errors, and the satellite states a receiver decodes from a
spoofed signal (kept as in the epoch; decoding the spoofed transmit time would move a satellite by
``|sdot| Delta pr / c`` along its orbit, 1.3 mm per 100 m of pseudorange change). The measurements
are exactly consistent with the satellite states given, so a snapshot solver finds exactly q and
the pushed clock (tests: ``test/test_spoofing.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from gnss_common.constants import SPEED_OF_LIGHT_MPS
from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.earth_rotation import rotate_about_z, sagnac_rotate
from gnss_common.observations import GnssEpoch
from rfi_sim.spoofing_attack import (  # noqa: F401  (re-exported: the attack's definition and parser)
    ATTACK_KINDS,
    CN0_MODES,
    CONSTELLATION_CODES,
    DEFAULT_MEACONING_DELAY_S,
    SpoofingAttack,
    attack_from_dict,
)


@dataclass(frozen=True)
class EpochAttackTruth:
    """What an attack did to one epoch.

    Attributes:
        attacked: the spoofer was on (start_s <= t < end_s).
        position_offset_enu_m: q - p, m, ENU at p(t0), shape (3,) (zeros when not attacked).
        spoofed_position_ecef_m: q, the position the spoofed satellites give, ECEF, m, shape (3,)
            (the true position when not attacked).
        time_offset_s: dt_s, the clock offset the spoofed satellites add, s.
        affected: ``(constellation, svid)`` of every spoofed satellite in the epoch.
    """

    attacked: bool
    position_offset_enu_m: np.ndarray
    spoofed_position_ecef_m: np.ndarray
    time_offset_s: float
    affected: frozenset[tuple[int, int]]


@dataclass(frozen=True)
class AttackTruth:
    """Per-epoch truth of :func:`apply_attack` (n epochs): the fields of :class:`EpochAttackTruth`
    stacked (``attacked`` (n,) bool, ``position_offset_enu_m`` (n, 3), ``spoofed_position_ecef_m``
    (n, 3), ``time_offset_s`` (n,), ``affected`` n frozensets), plus ``stamps_ns`` (n,), the
    ``attack`` and ``reference_cn0_dbhz`` (L of the module docstring, NaN if none was found).
    """

    attack: SpoofingAttack
    stamps_ns: np.ndarray
    attacked: np.ndarray
    position_offset_enu_m: np.ndarray
    spoofed_position_ecef_m: np.ndarray
    time_offset_s: np.ndarray
    affected: tuple[frozenset[tuple[int, int]], ...]
    reference_cn0_dbhz: float


def _ranges(sat_ecef_m: np.ndarray, sat_vel_ecef_mps: np.ndarray, rx_ecef_m: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``rho_i(x)`` (m, (n,)), ``e_i(x)`` ((n, 3)) and the rotated satellite velocities (m/s, (n, 3))."""
    rotated, cos_a, sin_a, _ = sagnac_rotate(sat_ecef_m, rx_ecef_m, iterations=2)
    diff = rotated - rx_ecef_m
    rho = np.sqrt(np.sum(diff * diff, axis=1))
    return rho, diff / rho[:, None], rotate_about_z(sat_vel_ecef_mps, cos_a, sin_a)


class AttackInjector:
    """One attack applied epoch by epoch, in stamp order (the state: the C/N0 reference, the
    attack's ENU origin, the common C/N0 fluctuation).

    Args:
        attack: the :class:`SpoofingAttack`.
        first_stamp_ns: stamp of the run's first epoch (t = 0 of ``start_s`` / ``end_s``), ns.
        seed: seed of the C/N0 draws (offsets per satellite, common fluctuation, noise).
    """

    def __init__(self, attack: SpoofingAttack, first_stamp_ns: int, seed: int = 0) -> None:
        self.attack = attack
        self.first_stamp_ns = int(first_stamp_ns)
        self.seed = int(seed)
        self._start_ns = round(attack.start_s * 1e9)
        self._end_ns = None if attack.end_s is None else round(attack.end_s * 1e9)
        self.reference_cn0_dbhz = math.nan
        self._origin: np.ndarray | None = None  # p(t0), ECEF, m
        self._rot = np.eye(3)  # ENU rotation at p(t0)
        self._common_db = 0.0
        self._last_ns: int | None = None  # stamp of the previous attacked epoch
        self._prev_stamp_ns: int | None = None
        self._rng_common = np.random.default_rng([self.seed, 1])
        self._rng_noise = np.random.default_rng([self.seed, 2])
        self._offsets_db: dict[tuple[int, int], float] = {}

    def _active(self, stamp_ns: int) -> bool:
        t_ns = stamp_ns - self.first_stamp_ns
        return t_ns >= self._start_ns and (self._end_ns is None or t_ns < self._end_ns)

    def apply(self, epoch: GnssEpoch, receiver_ecef_m: np.ndarray,
              receiver_velocity_ecef_mps: np.ndarray | None = None) -> tuple[GnssEpoch, EpochAttackTruth]:
        """The epoch as the receiver outputs it under the attack, and its truth.

        Args:
            epoch: the clean epoch (stamps non-decreasing from call to call).
            receiver_ecef_m: true (or approximate: the changes depend on it only through the line
                of sight) receiver position at the epoch, ECEF, m, shape (3,).
            receiver_velocity_ecef_mps: its velocity, ECEF, m/s, shape (3,) (None: static).

        Raises:
            ValueError: a stamp earlier than the previous one, a geometry-dependent attack
                (position push, meaconing) on a satellite without a finite position, or a consistent
                rate without a finite satellite velocity.
        """
        if self._prev_stamp_ns is not None and epoch.stamp_ns < self._prev_stamp_ns:
            raise ValueError(f"epoch stamp {epoch.stamp_ns} ns is earlier than the previous {self._prev_stamp_ns} ns")
        self._prev_stamp_ns = epoch.stamp_ns
        p = np.asarray(receiver_ecef_m, dtype=float).reshape(3)
        v_r = np.zeros(3) if receiver_velocity_ecef_mps is None else np.asarray(receiver_velocity_ecef_mps, float)
        a = self.attack
        if not self._active(epoch.stamp_ns):
            if self._origin is None:  # before the attack: the reference is the newest clean median
                ref = self._clean_median(epoch)
                self.reference_cn0_dbhz = ref if math.isfinite(ref) else self.reference_cn0_dbhz
            return epoch, EpochAttackTruth(False, np.zeros(3), p.copy(), 0.0, frozenset())
        if self._origin is None:
            self._origin = p.copy()
            lat, lon, _ = ecef_to_geodetic(p)
            self._rot = ecef_to_enu_rotation(lat, lon)
            if not math.isfinite(self.reference_cn0_dbhz):
                self.reference_cn0_dbhz = self._clean_median(epoch)
        tau_s = (epoch.stamp_ns - self.first_stamp_ns - self._start_ns) * 1e-9
        idx = [i for i, o in enumerate(epoch.observations) if a.spoofs(o.constellation)]
        q, q_dot, time_s, dpr_common_m, drate_common_mps = self._spoofed_state(p, v_r, tau_s)
        obs = list(epoch.observations)
        if idx:
            sel = [obs[i] for i in idx]
            dpr, drate = self._changes(epoch, sel, p, v_r, q, q_dot)
            cn0 = self._cn0(epoch, sel)
            for j, i in enumerate(idx):
                rate = obs[i].pseudorange_rate_mps
                if a.doppler_consistent:
                    rate = rate + drate[j] + drate_common_mps
                obs[i] = replace(obs[i], pseudorange_m=obs[i].pseudorange_m + dpr[j] + dpr_common_m,
                                 pseudorange_rate_mps=rate, cn0_dbhz=cn0[j])
        affected = frozenset((int(o.constellation), int(o.svid)) for o in (epoch.observations[i] for i in idx))
        truth = EpochAttackTruth(True, self._rot @ (q - p), q, time_s, affected)
        return replace(epoch, observations=tuple(obs)), truth

    def _spoofed_state(self, p: np.ndarray, v_r: np.ndarray, tau_s: float
                       ) -> tuple[np.ndarray, np.ndarray, float, float, float]:
        """``(q, qdot, dt_s, c dt_s, c d(dt_s)/dt)`` at ``tau_s`` into the attack (module docstring)."""
        a = self.attack
        assert self._origin is not None
        if a.kind == "meaconing":
            assert a.meacon_offset_enu_m is not None and a.meaconing_delay_s is not None
            m = self._origin + self._rot.T @ np.asarray(a.meacon_offset_enu_m)
            path_m = float(np.linalg.norm(m - p))
            path_rate = float((p - m) @ v_r) / path_m if path_m > 0.0 else 0.0
            return (m, np.zeros(3), a.meaconing_delay_s + path_m / SPEED_OF_LIGHT_MPS,
                    SPEED_OF_LIGHT_MPS * a.meaconing_delay_s + path_m, path_rate)
        push = self._rot.T @ np.asarray(a.push_velocity_enu_mps)
        r_s_per_s = a.time_push_ns_per_s * 1e-9
        return (p + push * tau_s, v_r + push, r_s_per_s * tau_s, SPEED_OF_LIGHT_MPS * r_s_per_s * tau_s,
                SPEED_OF_LIGHT_MPS * r_s_per_s)

    def _changes(self, epoch: GnssEpoch, sel: Sequence, p: np.ndarray, v_r: np.ndarray, q: np.ndarray,
                 q_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Geometric parts of eq. (1) and (2): ``rho_i(q) - rho_i(p)`` (m) and
        ``rhodot_i(q, qdot) - rhodot_i(p, v_r)`` (m/s) of the spoofed satellites."""
        n = len(sel)
        if np.array_equal(q, p) and np.array_equal(q_dot, v_r):
            return np.zeros(n), np.zeros(n)
        sats = np.array([o.satellite_position_ecef_m for o in sel], dtype=float).reshape(n, 3)
        vels = np.array([o.satellite_velocity_ecef_mps for o in sel], dtype=float).reshape(n, 3)
        bad = [o for o, s in zip(sel, sats, strict=True) if not np.all(np.isfinite(s))]
        if bad:
            raise ValueError(f"{self.attack.kind} at stamp {epoch.stamp_ns} ns needs satellite positions: "
                             f"(constellation, svid) {(bad[0].constellation, bad[0].svid)} has none")
        rho_p, e_p, vrot_p = _ranges(sats, vels, p)
        rho_q, e_q, vrot_q = _ranges(sats, vels, q)
        drate = np.zeros(n)
        if self.attack.doppler_consistent:
            finite = np.array([math.isfinite(o.pseudorange_rate_mps) for o in sel])
            if not np.all(np.isfinite(vels[finite])):
                raise ValueError(f"{self.attack.kind} with consistent Doppler at stamp {epoch.stamp_ns} ns needs "
                                 "satellite velocities")
            drate = np.sum(e_q * (vrot_q - q_dot), axis=1) - np.sum(e_p * (vrot_p - v_r), axis=1)
        return rho_q - rho_p, drate

    def _clean_median(self, epoch: GnssEpoch) -> float:
        """Median C/N0 of the attacked constellations' satellites in ``epoch``, dB-Hz (NaN: none)."""
        values = [o.cn0_dbhz for o in epoch.observations
                  if self.attack.spoofs(o.constellation) and math.isfinite(o.cn0_dbhz)]
        return float(np.median(values)) if values else math.nan

    def _cn0(self, epoch: GnssEpoch, sel: Sequence) -> list[float]:
        """Spoofed C/N0 of the selected satellites, dB-Hz (module docstring)."""
        a = self.attack
        dt_s = 0.0 if self._last_ns is None else (epoch.stamp_ns - self._last_ns) * 1e-9
        if self._last_ns is None:
            self._common_db = a.cn0_common_std_db * float(self._rng_common.standard_normal())
        else:
            phi = math.exp(-dt_s / a.cn0_common_tau_s)
            w = float(self._rng_common.standard_normal())
            self._common_db = phi * self._common_db + a.cn0_common_std_db * math.sqrt(1.0 - phi * phi) * w
        self._last_ns = epoch.stamp_ns
        noise = self._rng_noise.standard_normal(len(sel))
        out = []
        for o, w in zip(sel, noise, strict=True):
            if not math.isfinite(o.cn0_dbhz):
                out.append(o.cn0_dbhz)
            elif a.cn0_mode == "matched":
                out.append(o.cn0_dbhz + a.power_advantage_db + self._common_db)
            else:
                out.append(self.reference_cn0_dbhz + a.power_advantage_db + self._satellite_offset_db(o)
                           + self._common_db + a.cn0_noise_std_db * float(w))
        return out

    def _satellite_offset_db(self, o) -> float:
        key = (int(o.constellation), int(o.svid))
        if key not in self._offsets_db:  # seeded per satellite: independent of the order they appear in
            rng = np.random.default_rng([self.seed, 3, key[0], key[1]])
            self._offsets_db[key] = self.attack.cn0_satellite_std_db * float(rng.standard_normal())
        return self._offsets_db[key]


def apply_attack(
    epochs: Sequence[GnssEpoch],
    attack: SpoofingAttack,
    receiver_ecef_m: np.ndarray,
    receiver_velocity_ecef_mps: np.ndarray | None = None,
    seed: int = 0,
    first_stamp_ns: int | None = None,
) -> tuple[tuple[GnssEpoch, ...], AttackTruth]:
    """Inject ``attack`` into a run of clean epochs.

    Args:
        epochs: the clean epochs, stamps non-decreasing.
        attack: :class:`SpoofingAttack`.
        receiver_ecef_m: true (or approximate) receiver position, ECEF, m: shape (3,) for a static
            receiver, (n, 3) one per epoch for a moving one.
        receiver_velocity_ecef_mps: ECEF, m/s, (3,) or (n, 3); None: zero for a (3,) position, the
            stamp-wise finite difference (``np.gradient``) of an (n, 3) one.
        seed: seed of the C/N0 draws.
        first_stamp_ns: t = 0 of the attack's times, ns (None: the first epoch's stamp).

    Returns:
        ``(spoofed epochs, AttackTruth)``; the epochs have the input's stamps and satellites.

    Raises:
        ValueError: positions or velocities of the wrong shape, or see :meth:`AttackInjector.apply`.

    Examples:
        >>> from gnss_common.synthetic_sky import synthetic_epoch, RECEIVER_ECEF_M
        >>> push = SpoofingAttack("position_push", start_s=0.0, push_velocity_enu_mps=(1.0, 0.0, 0.0))
        >>> out, truth = apply_attack([synthetic_epoch()], push, RECEIVER_ECEF_M)
        >>> bool(truth.attacked[0]), len(out[0].observations)
        (True, 9)
    """
    n = len(epochs)
    pos = np.asarray(receiver_ecef_m, dtype=float)
    if pos.shape not in ((3,), (n, 3)):
        raise ValueError(f"receiver_ecef_m must have shape (3,) or ({n}, 3), got {pos.shape}")
    if receiver_velocity_ecef_mps is not None:
        vel = np.asarray(receiver_velocity_ecef_mps, dtype=float)
    elif pos.ndim == 2 and n >= 2:
        vel = np.gradient(pos, np.array([e.stamp_ns for e in epochs], dtype=float) * 1e-9, axis=0)
    else:
        vel = np.zeros(3)
    if vel.shape not in ((3,), (n, 3)):
        raise ValueError(f"receiver_velocity_ecef_mps must have shape (3,) or ({n}, 3), got {vel.shape}")
    first = (epochs[0].stamp_ns if epochs else 0) if first_stamp_ns is None else int(first_stamp_ns)
    injector = AttackInjector(attack, first, seed)
    out, rows = [], []
    for k, epoch in enumerate(epochs):
        spoofed, row = injector.apply(epoch, pos if pos.ndim == 1 else pos[k], vel if vel.ndim == 1 else vel[k])
        out.append(spoofed)
        rows.append(row)
    truth = AttackTruth(
        attack=attack,
        stamps_ns=np.array([e.stamp_ns for e in epochs], dtype=np.int64),
        attacked=np.array([r.attacked for r in rows], dtype=bool),
        position_offset_enu_m=np.array([r.position_offset_enu_m for r in rows]).reshape(n, 3),
        spoofed_position_ecef_m=np.array([r.spoofed_position_ecef_m for r in rows]).reshape(n, 3),
        time_offset_s=np.array([r.time_offset_s for r in rows], dtype=float),
        affected=tuple(r.affected for r in rows),
        reference_cn0_dbhz=injector.reference_cn0_dbhz,
    )
    return tuple(out), truth

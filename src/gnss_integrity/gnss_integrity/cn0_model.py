"""Clean C/N0 models the integrity node learns by itself: C/N0 versus elevation, and per satellite.

Pure (no rclpy, no rfi_msgs). Two references of a satellite's clean C/N0:

* **Elevation model**, per constellation and signal band (``cn0_epoch.signal_band``): piecewise
  linear in elevation with nodes every ``bin_width_deg`` (default 5 deg), plus a per-satellite offset
  (satellites differ by a few dB: block type, antenna pattern, multipath at the site) learned from
  the satellite's residual less the epoch's median residual (relative to the others only). Each clean
  sample is shared between its two neighbouring nodes with linear ("tent") weights, so each node holds
  the weighted running mean, mean squared deviation and effective sample count of the samples near
  it; the prediction interpolates the same nodes. Needs elevations (satellite states and a receiver
  position).
* **Satellite levels**, per satellite and band: the recent clean C/N0 (exponentially weighted with
  time constant ``level_time_constant_s``), for a stream without ephemeris (NaN satellite states:
  elevation unknown).

How it avoids learning from a jammed (or spoofed) start (see :meth:`Cn0Models.learn`):

1. **Physical ceiling.** A clean open-sky receiver sees 45-52 dB-Hz near zenith (ARL1 46, ESBC
   GPS 51, GLONASS 50, BeiDou MEO 52 dB-Hz at 70-90 deg). An epoch whose satellites above
   ``ceiling_min_elevation_deg`` are, in the median, below the floor line ``ceiling_horizon_dbhz +
   (ceiling_zenith_dbhz - ceiling_horizon_dbhz) sin(el)`` (default 32 -> 44 dB-Hz) is not learned;
   without elevations, an epoch whose ``ceiling_top_rank``-th strongest satellite is below
   ``ceiling_top_dbhz`` is not learned. On the simulator's C/N0 law (34 -> 49 dB-Hz) a start jammed
   at J/S >= ~18 dB is refused (the model stays empty, the tests UNKNOWN, state ``MODEL_BLOCKED``);
   a weaker jammer at start biases the model low by its drop (<= 4 dB at zenith for 15 dB J/S)
   until clean data lifts it. A receiver with a poor (chip) antenna may need lower floors.
2. **Only clean epochs.** The caller passes ``clean``: the receiver's AGC at its learned level and
   no receiver jamming flag (:mod:`gnss_integrity.receiver_agc`), no C/N0 drop
   (:mod:`gnss_integrity.cn0_jamming`) and no C/N0 spoofing test at its threshold.
3. **Up fast, down slowly.** Each node's published level follows its running mean up at once but
   falls at most ``max_fall_db_per_s`` (default 1 dB per minute), so a jammer that slips through the
   gates drags the model down by at most that rate. Samples beyond ``huber_k`` sigma of the
   prediction are clipped before they are learned.
4. **Minimum weight.** A node is used once it holds ``min_node_weight`` effective samples; a
   satellite contributes at most one effective sample per ``decorrelation_s`` (C/N0 estimates
   at 5-20 Hz are correlated over about a second).

A stored elevation model may be loaded (:meth:`Cn0Models.load`): JSON with a format name and version,
validated on load. Satellite levels are recent by nature and are not stored.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gnss_integrity.cn0_epoch import (
    BAND_NAMES,
    BANDS,
    N_BANDS,
    N_CONSTELLATION_CODES,
    Cn0Epoch,
    Cn0Reference,
    signal_band,
)
from gnss_integrity.kernels import cn0_reference_rows
from rfi_node_common.params import check_positive_finite

MODEL_FORMAT = "gnss_integrity.cn0_model"
MODEL_FORMAT_VERSION = 1

MODEL_EMPTY = 0     # no clean data learned yet
MODEL_LEARNING = 1  # learning, no node or level usable yet
MODEL_BLOCKED = 2   # the last epochs failed the physical ceiling: not learning (jammed start?)
MODEL_READY = 3     # learned: some node or satellite level has been usable


@dataclass(frozen=True)
class Cn0ModelParams:
    """Parameters of :class:`Cn0Models` (see the module docstring for the learning gates).

    Attributes:
        bin_width_deg: spacing of the elevation nodes, deg (90 / width must be an integer).
        min_node_weight: effective samples a node needs before it is used.
        memory_samples: a node's running mean becomes exponentially weighted after this many
            effective samples (its memory).
        decorrelation_s: a satellite adds at most one effective sample per this time, s.
        learn_interval_s: epochs closer than this to the last learned one are not learned (a 20 Hz
            receiver adds nothing in between but cost), s.
        max_fall_db_per_s: fastest fall of a published node level or satellite level, dB/s.
        huber_k: samples are clipped to the prediction +- huber_k sigma before learning.
        min_std_db: floor of every residual standard deviation, dB.
        offset_memory_samples: memory of a satellite's offset, effective samples.
        offset_prior_samples: a satellite's offset is shrunk by w / (w + this) towards 0.
        level_time_constant_s: time constant of a satellite's recent clean level, s.
        level_min_weight: effective samples before a satellite level is used.
        level_max_age_s: a satellite level not refreshed by clean data for this long is unused, s.
        ceiling_zenith_dbhz, ceiling_horizon_dbhz: floor line of clean C/N0 (ends at 90 and 0 deg), dB-Hz.
        ceiling_min_elevation_deg: satellites above this elevation take part in the ceiling check, deg.
        ceiling_min_satellites: fewer such satellites: the ceiling check falls back to the top rank.
        ceiling_top_rank, ceiling_top_dbhz: without elevations the ``rank``-th strongest satellite
            must reach this, dB-Hz (fewer satellites: the weakest of them).
        min_cn0_dbhz, max_cn0_dbhz: C/N0 outside this range is ignored as invalid, dB-Hz.
    """

    bin_width_deg: float = 5.0
    min_node_weight: float = 20.0
    memory_samples: float = 600.0
    decorrelation_s: float = 1.0
    learn_interval_s: float = 0.2
    max_fall_db_per_s: float = 1.0 / 60.0
    huber_k: float = 3.0
    min_std_db: float = 0.5
    offset_memory_samples: float = 300.0
    offset_prior_samples: float = 10.0
    level_time_constant_s: float = 60.0
    level_min_weight: float = 5.0
    level_max_age_s: float = 600.0
    ceiling_zenith_dbhz: float = 44.0
    ceiling_horizon_dbhz: float = 32.0
    ceiling_min_elevation_deg: float = 30.0
    ceiling_min_satellites: int = 3
    ceiling_top_rank: int = 3
    ceiling_top_dbhz: float = 42.0
    min_cn0_dbhz: float = 5.0
    max_cn0_dbhz: float = 70.0

    def __post_init__(self) -> None:
        n = 90.0 / self.bin_width_deg if self.bin_width_deg > 0 else math.nan
        if not (math.isfinite(n) and abs(n - round(n)) < 1e-9 and n >= 1):
            raise ValueError(f"bin_width_deg must divide 90, got {self.bin_width_deg}")
        check_positive_finite(self, ("min_node_weight", "memory_samples", "decorrelation_s", "huber_k", "min_std_db",
                                     "offset_memory_samples", "level_time_constant_s", "level_min_weight",
                                     "level_max_age_s"))
        if not (self.max_fall_db_per_s >= 0 and self.offset_prior_samples >= 0 and self.learn_interval_s >= 0):
            raise ValueError("max_fall_db_per_s, offset_prior_samples and learn_interval_s must be >= 0")
        if not self.min_node_weight <= self.memory_samples:
            raise ValueError("min_node_weight must be <= memory_samples")
        if not (self.ceiling_min_satellites >= 1 and self.ceiling_top_rank >= 1):
            raise ValueError("ceiling_min_satellites and ceiling_top_rank must be >= 1")
        if not (0 <= self.min_cn0_dbhz < self.max_cn0_dbhz):
            raise ValueError("need 0 <= min_cn0_dbhz < max_cn0_dbhz")

    @property
    def n_nodes(self) -> int:
        return int(round(90.0 / self.bin_width_deg)) + 1


_SLOT_FIELDS = ("off", "off_w", "lv", "lv_pub", "lv_ready", "lv_var", "lv_std", "lv_w", "lv_t", "learn_t", "clean_t",
                "clean_cn0", "clean_el")
_SLOT_INIT = (0.0, 0.0, math.nan, math.nan, math.nan, 0.0, math.nan, 0.0, -math.inf, -math.inf, -math.inf, math.nan,
              math.nan)
_NODE_FIELDS = ("w", "mean", "pub", "var_tot", "w_res", "var_res")  # stored; "t", and the NaN-masked views below
_NODE_VIEWS = ("pub_ready", "std_ready", "mean_any", "var_any")


def _interp(values: np.ndarray, n0: np.ndarray, n1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Tent interpolation of a node array that is NaN where a node is unusable: both nodes, else
    the usable one if the row is in its half, else NaN."""
    v0, v1 = values[n0], values[n1]
    both = v0 + frac * (v1 - v0)
    return np.where(both == both, both, np.where(frac <= 0.5, v0, v1))


class Cn0Models:
    """The elevation model and the satellite levels (see the module docstring).

    Per epoch (the node, in stamp order)::

        ref = models.reference(Cn0Epoch.from_arrays(stamp_ns, constellation, svid, cn0_dbhz,
                                                    elevation_rad, carrier_frequency_hz))
        jam = jamming.evaluate(ref)                # cn0_jamming.Cn0JammingDetector
        spoof = spoofing.evaluate(ref, jam)        # cn0_spoofing.Cn0SpoofingTests
        models.learn(ref, clean=agc.looks_clean and jam.epoch_clean and spoof.epoch_clean)

    Args:
        params: :class:`Cn0ModelParams`.
        lost_memory_s: a satellite missing now counts as lost when it was in a clean epoch within this
            time before the last clean epoch, s.
        lost_max_age_s: and its last clean sighting is at most this old, s.
    """

    def __init__(self, params: Cn0ModelParams | None = None, lost_memory_s: float = 10.0,
                 lost_max_age_s: float = 300.0) -> None:
        self.params = params or Cn0ModelParams()
        self.lost_memory_s = float(lost_memory_s)
        self.lost_max_age_s = float(lost_max_age_s)
        size = N_CONSTELLATION_CODES * N_BANDS * self.params.n_nodes
        self._n = {f: np.zeros(size) for f in _NODE_FIELDS}
        self._n["t"] = np.full(size, -math.inf)
        self._n.update({f: np.full(size, np.nan) for f in _NODE_VIEWS})
        self._slot_of: dict[tuple[int, int, int], int] = {}  # (constellation, svid, band) -> slot
        self._slot_cache: dict[tuple[int, int, int], int] = {}  # (constellation, svid, carrier kHz) -> slot
        self._slot_key = np.zeros((0, 3), dtype=np.int64)
        self._slot_base = np.zeros(0, dtype=np.int64)  # first node of the slot's (constellation, band)
        self._s = {f: np.full(0, v) for f, v in zip(_SLOT_FIELDS, _SLOT_INIT, strict=True)}
        self._last_clean_s = -math.inf
        self._last_ceiling_ok: bool | None = None
        self._ready = False  # some node or satellite level usable
        self.epochs_learned = 0
        self.epochs_blocked = 0

    # ------------------------------------------------------------------ slots
    def _slots(self, constellation: np.ndarray, svid: np.ndarray, carrier_hz: np.ndarray) -> np.ndarray:
        fk = np.where(carrier_hz == carrier_hz, carrier_hz * 1e-3, -1.0).astype(np.int64).tolist()
        keys = list(zip(constellation.tolist(), svid.tolist(), fk, strict=True))
        get = self._slot_cache.get
        slots = [get(k, -1) for k in keys]
        if min(slots, default=0) < 0:
            band = signal_band(constellation, carrier_hz).tolist()
            for i, k in enumerate(keys):
                if slots[i] < 0:
                    sk = (k[0], k[1], band[i])
                    slots[i] = self._slot_cache[k] = self._slot_of.setdefault(sk, len(self._slot_of))
            new = sorted(self._slot_of.items(), key=lambda kv: kv[1])[self._slot_key.shape[0]:]
            keys_new = np.array([k for k, _ in new], dtype=np.int64).reshape(-1, 3)
            self._slot_key = np.vstack([self._slot_key, keys_new])
            c = np.minimum(np.maximum(keys_new[:, 0], 0), N_CONSTELLATION_CODES - 1)
            self._slot_base = np.concatenate([self._slot_base, (c * N_BANDS + keys_new[:, 2]) * self.params.n_nodes])
            for f, v in zip(_SLOT_FIELDS, _SLOT_INIT, strict=True):
                self._s[f] = np.concatenate([self._s[f], np.full(len(new), v)])
        return np.array(slots, dtype=np.int64)

    # ------------------------------------------------------------------ reference
    def reference(self, epoch: Cn0Epoch) -> Cn0Reference:
        """The clean references of this epoch's satellites (no learning; new satellites get a slot)."""
        p = self.params
        slots = self._slots(epoch.constellation, epoch.svid, epoch.carrier_frequency_hz)
        s = self._s
        t = epoch.stamp_ns * 1e-9
        # valid C/N0 (False for NaN), tent nodes, elevation model + offset, satellite level (compiled)
        valid, n0, n1, frac, el_exp, el_std, lv_exp, lv_std = cn0_reference_rows(
            epoch.cn0_dbhz, epoch.elevation_rad, slots, self._slot_base, self._n["pub_ready"], self._n["std_ready"],
            s["off"], s["off_w"], s["lv_t"], s["lv_ready"], s["lv_std"], t, p.min_cn0_dbhz, p.max_cn0_dbhz,
            180.0 / math.pi / p.bin_width_deg, p.n_nodes, p.offset_prior_samples, p.level_max_age_s)
        n_el = int(np.count_nonzero(el_exp == el_exp))
        n_lv = int(np.count_nonzero(lv_exp == lv_exp))
        use_el = n_el >= max(1, n_lv // 2)
        exp, std = (el_exp, el_std) if use_el else (lv_exp, lv_std)
        # Lost: in a clean epoch shortly before the last clean epoch, not in this one.
        lost = (s["clean_t"] >= self._last_clean_s - self.lost_memory_s) & (s["clean_t"] >= t - self.lost_max_age_s)
        lost[slots] = False
        if use_el or n_lv or self._ready:
            state = MODEL_READY
        elif self._last_ceiling_ok is False:
            state = MODEL_BLOCKED
        else:
            state = MODEL_LEARNING if self.epochs_learned else MODEL_EMPTY
        return Cn0Reference(epoch, slots, valid, el_exp, el_std, lv_exp, lv_std, use_el, exp, std,
                            self._slot_key[lost, 0], self._slot_key[lost, 1], s["clean_cn0"][lost],
                            s["clean_el"][lost], state, (n0, n1, frac))

    def _offsets(self, slots: np.ndarray) -> np.ndarray:
        w = self._s["off_w"][slots]
        return self._s["off"][slots] * w / (w + self.params.offset_prior_samples)

    def ceiling_ok(self, epoch: Cn0Epoch, valid: np.ndarray) -> bool | None:
        """Physical ceiling check of the module docstring (None: no satellite to judge by)."""
        p = self.params
        cn0 = epoch.cn0_dbhz[valid]
        el = epoch.elevation_rad[valid]
        high = el >= math.radians(p.ceiling_min_elevation_deg)  # False for NaN
        n_high = int(np.count_nonzero(high))
        if n_high >= p.ceiling_min_satellites:
            floor = p.ceiling_horizon_dbhz + (p.ceiling_zenith_dbhz - p.ceiling_horizon_dbhz) * np.sin(el[high])
            margin = np.sort(cn0[high] - floor)
            return bool(margin[(n_high - 1) // 2] + margin[n_high // 2] >= 0.0)
        if cn0.size == 0:
            return None
        k = cn0.size - min(p.ceiling_top_rank, cn0.size)
        return bool(np.partition(cn0, k)[k] >= p.ceiling_top_dbhz)

    @property
    def ceiling_passed(self) -> bool | None:
        """Whether the last epoch offered to :meth:`learn` as clean passed the ceiling (None: none yet)."""
        return self._last_ceiling_ok

    # ------------------------------------------------------------------ learning
    def learn(self, ref: Cn0Reference, clean: bool) -> bool:
        """Learn the epoch of ``ref`` if ``clean`` and it passes the physical ceiling.

        Args:
            ref: this epoch's :meth:`reference` (the tests ran on it).
            clean: the other evidence calls this epoch clean (AGC, receiver flag, no C/N0 test at
                its threshold).

        Returns:
            True if the epoch was learned (False: not clean, below the ceiling, or within
            ``learn_interval_s`` of the last learned epoch).
        """
        t = ref.epoch.stamp_ns * 1e-9
        if not clean or not ref.valid.any() or t - self._last_clean_s < self.params.learn_interval_s - 1e-3:
            return False
        ok = self.ceiling_ok(ref.epoch, ref.valid)
        if ok is not None:
            self._last_ceiling_ok = ok
        if ok is False:
            self.epochs_blocked += 1
            return False
        p = self.params
        epoch = ref.epoch
        rows = np.flatnonzero(ref.valid)
        slots = ref.slots[rows]
        x = epoch.cn0_dbhz[rows]
        s = self._s
        dt = t - s["learn_t"][slots]  # inf for a new satellite
        w = np.minimum(np.maximum(dt / p.decorrelation_s, 0.0), 1.0)
        s["learn_t"][slots] = np.where(w > 0, t, s["learn_t"][slots])
        s["clean_t"][slots] = t
        s["clean_cn0"][slots] = x
        s["clean_el"][slots] = epoch.elevation_rad[rows]
        self._last_clean_s = t
        self._learn_levels(slots, x, w, dt, t)
        has_el = epoch.elevation_rad[rows] == epoch.elevation_rad[rows]
        if has_el.any():
            self._learn_elevation(ref, rows[has_el], w[has_el], t)
        self.epochs_learned += 1
        return True

    def _learn_levels(self, slots: np.ndarray, x: np.ndarray, w: np.ndarray, dt: np.ndarray, t: float) -> None:
        p = self.params
        s = self._s
        lw = s["lv_w"][slots] + w
        gain = np.where(w > 0, np.maximum(w / np.maximum(lw, 1e-12), 1.0 - np.exp(-dt / p.level_time_constant_s)), 0.0)
        old = s["lv"][slots]
        fresh = old != old
        mature = s["lv_w"][slots] >= p.level_min_weight
        k_scale = p.huber_k * np.maximum(np.sqrt(s["lv_var"][slots]), p.min_std_db)
        xc = np.where(mature, np.minimum(np.maximum(x, old - k_scale), old + k_scale), x)
        err = np.where(fresh, 0.0, xc - old)
        new = np.where(fresh, x, old + gain * err)
        var = np.where(fresh, p.min_std_db**2, s["lv_var"][slots] + gain * (err**2 - s["lv_var"][slots]))
        pub = s["lv_pub"][slots]
        floor = pub - p.max_fall_db_per_s * np.maximum(t - s["lv_t"][slots], 0.0)
        pub = np.where(fresh | ~mature | (new >= pub), new, np.maximum(new, floor))
        ready = lw >= p.level_min_weight
        s["lv_pub"][slots] = pub
        s["lv_ready"][slots] = np.where(ready, pub, np.nan)
        self._ready = self._ready or bool(ready.any())
        s["lv_std"][slots] = np.maximum(np.sqrt(var), p.min_std_db)
        s["lv_var"][slots] = var
        s["lv"][slots] = new
        s["lv_w"][slots] = lw
        s["lv_t"][slots] = np.where(w > 0, t, s["lv_t"][slots])

    def _learn_elevation(self, ref: Cn0Reference, rows: np.ndarray, w: np.ndarray, t: float) -> None:
        """Tent-weighted running means of the nodes near each sample, and the satellite offsets."""
        p = self.params
        nd = self._n
        n0, n1, frac = (a[rows] for a in ref.node_index)
        slots = ref.slots[rows]
        x = ref.epoch.cn0_dbhz[rows]
        pred = _interp(nd["pub_ready"], n0, n1, frac)
        raw = _interp(nd["mean_any"], n0, n1, frac)
        k_scale = p.huber_k * np.maximum(np.sqrt(_interp(nd["var_any"], n0, n1, frac)), p.min_std_db)
        ready = pred == pred
        xc = np.where(ready, np.minimum(np.maximum(x, pred - k_scale), pred + k_scale), x)
        e_tot = np.where(raw == raw, xc - raw, 0.0)
        e_res = np.where(ready, xc - pred - self._offsets(slots), 0.0)
        nodes, inv = np.unique(np.concatenate([n0, n1]), return_inverse=True)
        a = np.concatenate([w * (1.0 - frac), w * frac])
        a_r = a * np.concatenate([ready, ready])
        m = nodes.size

        def wsum(values: np.ndarray, weights: np.ndarray = a) -> np.ndarray:
            return np.bincount(inv, weights=weights * np.concatenate([values, values]), minlength=m)

        acc, acc_r = wsum(np.ones_like(x)), wsum(np.ones_like(x), a_r)
        sums = [wsum(xc), wsum(e_tot**2), wsum(e_res**2, a_r)]
        sel = acc > 0  # a sample exactly on a node gives its neighbour no weight
        nodes, acc, acc_r = nodes[sel], acc[sel], acc_r[sel]
        s_x, s_tot, s_res = (v[sel] for v in sums)
        w_old = nd["w"][nodes]
        w_new = np.minimum(w_old + acc, p.memory_samples)
        mean = nd["mean"][nodes]
        new_mean = mean + (s_x - acc * mean) / w_new
        var_tot = nd["var_tot"][nodes] + (s_tot - acc * nd["var_tot"][nodes]) / w_new
        wr = np.minimum(nd["w_res"][nodes] + acc_r, p.memory_samples)
        var_res = nd["var_res"][nodes]
        var_res = var_res + np.where(acc_r > 0, (s_res - acc_r * var_res) / np.maximum(wr, 1e-12), 0.0)
        pub = nd["pub"][nodes]
        floor = pub - p.max_fall_db_per_s * np.minimum(np.maximum(t - nd["t"][nodes], 0.0), 1e9)
        pub = np.where((w_old < p.min_node_weight) | (new_mean >= pub), new_mean, np.maximum(new_mean, floor))
        for f, v in (("w", w_new), ("mean", new_mean), ("var_tot", var_tot), ("w_res", wr), ("var_res", var_res),
                     ("pub", pub)):
            nd[f][nodes] = v
        nd["t"][nodes] = t
        self._refresh_views(nodes)
        # Satellite offsets: each satellite's residual less the epoch's median residual, so a change
        # common to all satellites (a jammer that slipped through) moves the rate-limited nodes only.
        n_ready = int(np.count_nonzero(ready))
        if n_ready < 3:
            return
        r = xc - pred
        r_ready = np.sort(r[ready])
        r_rel = r - 0.5 * (r_ready[(n_ready - 1) // 2] + r_ready[n_ready // 2])
        off, off_w = self._s["off"], self._s["off_w"]
        ow = np.minimum(off_w[slots] + w * ready, p.offset_memory_samples)
        go = np.where(ready & (ow > 0), w / np.maximum(ow, 1e-12), 0.0)
        off[slots] += go * (np.where(ready, r_rel, 0.0) - off[slots])
        off_w[slots] = ow

    def _refresh_views(self, nodes: np.ndarray) -> None:
        """The NaN-masked node views the predictions read: usable levels and 1-sigma, any data."""
        p, nd = self.params, self._n
        w = nd["w"][nodes]
        ready, seen = w >= p.min_node_weight, w > 0
        var_use = np.where(nd["w_res"][nodes] >= 0.5 * p.min_node_weight, nd["var_res"][nodes], nd["var_tot"][nodes])
        nd["pub_ready"][nodes] = np.where(ready, nd["pub"][nodes], np.nan)
        nd["std_ready"][nodes] = np.where(ready, np.maximum(np.sqrt(var_use), p.min_std_db), np.nan)
        nd["mean_any"][nodes] = np.where(seen, nd["mean"][nodes], np.nan)
        nd["var_any"][nodes] = np.where(seen, nd["var_tot"][nodes], np.nan)

    # ------------------------------------------------------------------ persistence
    def to_json(self) -> dict:
        """The elevation model and satellite offsets as a JSON-able dict (format versioned)."""
        shape = (N_CONSTELLATION_CODES * N_BANDS, self.params.n_nodes)
        w = self._n["w"].reshape(shape)
        nodes = {f"{key // N_BANDS}:{BAND_NAMES[key % N_BANDS]}":
                 {f: self._n[f].reshape(shape)[key].tolist() for f in _NODE_FIELDS}
                 for key in np.flatnonzero(w.sum(axis=1) > 0).tolist()}
        offsets = {f"{c}:{sv}:{BAND_NAMES[b]}": [float(self._s["off"][i]), float(self._s["off_w"][i])]
                   for (c, sv, b), i in self._slot_of.items() if self._s["off_w"][i] > 0}
        return {"format": MODEL_FORMAT, "version": MODEL_FORMAT_VERSION,
                "bin_width_deg": self.params.bin_width_deg, "nodes": nodes, "offsets": offsets}

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1))

    @classmethod
    def from_json(cls, data: dict, params: Cn0ModelParams | None = None, **kwargs) -> Cn0Models:
        """A model from :meth:`to_json` output; ValueError naming what is wrong."""
        models = cls(params, **kwargs)
        p = models.params
        if not isinstance(data, dict) or data.get("format") != MODEL_FORMAT:
            raise ValueError(f"not a {MODEL_FORMAT} file")
        if data.get("version") != MODEL_FORMAT_VERSION:
            raise ValueError(f"unsupported version {data.get('version')!r} (expected {MODEL_FORMAT_VERSION})")
        if data.get("bin_width_deg") != p.bin_width_deg:
            raise ValueError(f"bin_width_deg {data.get('bin_width_deg')!r} is not the parameter's {p.bin_width_deg}")
        nd = models._n
        for name, fields in dict(data.get("nodes", {})).items():
            c, b = cls._parse_key(name, 2)
            sl = slice((c * N_BANDS + b) * p.n_nodes, (c * N_BANDS + b + 1) * p.n_nodes)
            for f in _NODE_FIELDS:
                v = np.asarray(fields.get(f) if isinstance(fields, dict) else None, dtype=float)
                hi = p.max_cn0_dbhz if f in ("mean", "pub") else math.inf
                if v.shape != (p.n_nodes,) or not np.all(np.isfinite(v) & (v >= 0) & (v <= hi)):
                    raise ValueError(f"node field {name}/{f}: {p.n_nodes} finite values in range expected")
                nd[f][sl] = np.minimum(v, p.memory_samples) if f in ("w", "w_res") else v
            models._refresh_views(np.arange(sl.start, sl.stop))
        for name, value in dict(data.get("offsets", {})).items():
            c, sv, b = cls._parse_key(name, 3)
            off, w = (float(v) for v in value)
            if not (math.isfinite(off) and abs(off) < 30 and math.isfinite(w) and w >= 0):
                raise ValueError(f"offset {name}: {off}, {w} out of range")
            carrier = np.array([BANDS[b][1] if b < len(BANDS) else 1.0e9])  # 1 GHz: band "other"
            slot = models._slots(np.array([c]), np.array([sv]), carrier)[0]
            models._s["off"][slot], models._s["off_w"][slot] = off, min(w, p.offset_memory_samples)
        return models

    @staticmethod
    def _parse_key(name: str, n: int) -> tuple[int, ...]:
        parts = str(name).split(":")
        if len(parts) != n or parts[-1] not in BAND_NAMES or not all(x.isdigit() for x in parts[:-1]):
            raise ValueError(f"bad key {name!r}")
        nums = [int(x) for x in parts[:-1]]
        if nums[0] >= N_CONSTELLATION_CODES or (n == 3 and nums[1] > 65535):
            raise ValueError(f"bad key {name!r}")
        return (*nums, BAND_NAMES.index(parts[-1]))

    @classmethod
    def load(cls, path: str | Path, params: Cn0ModelParams | None = None, **kwargs) -> Cn0Models:
        """:meth:`from_json` of a file written by :meth:`save`."""
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: cannot read a model ({exc})") from exc
        return cls.from_json(data, params, **kwargs)

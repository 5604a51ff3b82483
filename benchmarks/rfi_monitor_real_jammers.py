"""The rows of issue 14's table, on simulations of those jammers and on real clean captures with jammers added.

Each row is a stream of consecutive 1 ms IF blocks made by ``rfi_sim.if_signal.IfSimulator`` (real-jammer
waveforms of ``rfi_sim.jammer_waveforms``, front-end filter, AGC, clipping, quantisation) or by adding a
simulated jammer onto a real clean capture (PocketSDR, GNSS-SDR; ``../shared/data`` when present, else
the 10 ms / 4 ms copies in ``src/rfi_monitor/test/data``). The blocks are decoded and handed to
``rfi_monitor.monitor.RfiMonitor`` exactly as ``rfi_monitor_node`` does it (``counts * scale``, the node's
full-scale rule when ``check_saturation`` is on), with the settings the node ships with
(``src/rfi_monitor/config/rfi_monitor.yaml``, read through ``MonitorNodeParams.monitor_params()``).
One fresh monitor per row: the node starts with the stream, so for a jammer "on from the first
sample" the monitor never sees a clean block.

The truth comes from the simulator (``IfTruth``): type, J/N over the block (what a block-power J/N
measures; the AGC and the front-end filter included), J/N while in band, in-band fraction, period,
swept band, sweep shape, clipped fraction. The recordings' facts used (issue 14): recording 1:
10 MS/s complex int8, saw-tooth up seen from -4.16 to +4.08 MHz, period 8.972 us, rate 1.35-1.54e12
Hz/s, J/N 9-10 dB, on from sample 0; recording 2: same front end, triangle much wider than the
band, in band 34-38 % of each 9.09 us period, 10-15 % of samples at full scale, J/N ~13 dB in the
block, ~17 dB in band. The stated band, period and rate of recording 1 do not fit one saw-tooth
that stays inside the band (8.24 MHz in 8.972 us is 0.92e12 Hz/s), so it is simulated twice:
"1a" keeps band and period (rate non-linear by the stated ratio 1.54/1.35, mean 0.92e12 Hz/s);
"1b" keeps rate and period (1.35 -> 1.54e12 Hz/s: a 12.96 MHz sweep) and lets the front end's
filter (pass band -4.16..+4.08 MHz) cut what lies outside.

Rows: 1a, 1b, 2: the recordings; 3: the issue's independent generator's saw-tooth chirps, CW and
clean cases at three front ends (jammer on before the node starts; the AGC settled on it); 4: the
same chirps switched on after 6 clean blocks, with an AGC that has to settle and with the gain fixed
by the configured powers (as the issue's generator likely had it); S: item 3's sweep shapes (saw-tooth
down, triangles, hooked saw-tooth, non-linear rate) at the recordings' front end; D: ``make demo``'s
chirp phases as its scenario makes them (``scenarios/default.yaml``: 1 ms snapshots 1 s apart, each
from a fresh simulator, the paper's front end and chirp); R: the real clean captures alone and with
jammers added (bands scaled to each capture's IF filter, re-quantised to its bits).

Verdicts per row (the issue's "right"): type right in >= 95 % of the blocks after the switch-on
block; J/N within 3 dB of the truth (median; a J/N flagged as a lower bound, as the node flags it for clipped
blocks and for 1-3 bit front ends, counts as right when below the truth + 3 dB: on the 2-bit captures that is the
only J/N statement the monitor makes, and it reads 2-6 dB under the truth there); every published frequency finite
and inside the sampled band, or NaN ("not tracked"); sweep period within 1 % of the truth (median of the blocks that
report one, and reported in >= 50 % of the CHIRP blocks); shape as the truth (when the monitor
reports one). The row "met" when all that apply are.

Run (about a minute; ``--rows`` picks rows by substring, ``--blocks`` sets the stream length):

    PYTHONPATH=src/rfi_sim:src/rfi_monitor:src/rfi_node_common:src/gnss_common \\
        python benchmarks/rfi_monitor_real_jammers.py [--out docs/rfi_monitor/real_jammers.md]

The monitor measured is whichever ``rfi_monitor`` the path resolves (its folder, without the machine's
prefix, and the git commit are printed in the output).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import platform
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from bench_progress import CaseLog, add_quiet_argument, case_log
from doc_paths import portable_path

from rfi_sim.if_signal import (
    CHIRP,
    CW,
    NONE,
    WIDEBAND,
    ChirpJammer,
    CwJammer,
    FrontEndConfig,
    IfSimulator,
    Jammer,
    js_for_jn_db,
)
from rfi_sim.jammer_waveforms import SweepJammer

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
TEST_DATA = ROOT / "src" / "rfi_monitor" / "test" / "data"
CONFIG = ROOT / "src" / "rfi_monitor" / "config" / "rfi_monitor.yaml"
TYPE_NAMES = {NONE: "NONE", CW: "CW", CHIRP: "CHIRP", WIDEBAND: "WIDEBAND", 4: "UNKNOWN"}
SIM_SHAPE_TO_MONITOR = {"saw_up": "sawtooth_up", "saw_down": "sawtooth_down", "triangle": "triangle",
                        "hooked_saw": "hooked_sawtooth"}
BLOCK_S = 1e-3
"""Block length, s (the issue's live stream: 1 ms blocks)."""


# ---------------------------------------------------------------------------------------------
# The monitor as the node drives it
# ---------------------------------------------------------------------------------------------
def shipped_node_params() -> tuple[object, list[str]]:
    """MonitorNodeParams from the shipped YAML (values the dataclass does not know are listed, not used).

    The YAML beside the measured package's source (``<pkg>/../config``) when there is one, else the tree's."""
    import yaml

    import rfi_monitor
    from rfi_monitor.rfi_monitor_node import MonitorNodeParams
    beside = Path(rfi_monitor.__file__).resolve().parents[1] / "config" / "rfi_monitor.yaml"
    doc = yaml.safe_load((beside if beside.exists() else CONFIG).read_text())
    values = doc["rfi_monitor"]["ros__parameters"]
    known = {f.name for f in dataclasses.fields(MonitorNodeParams)}
    use = {k: v for k, v in values.items() if k in known}
    return MonitorNodeParams(**use), sorted(set(values) - known)


class NodeLikeMonitor:
    """RfiMonitor fed as rfi_monitor_node feeds it (decode, full-scale rule), shipped settings.

    Args:
        method: None or "ours": the shipped settings; "paper": the same with Kang et al.'s method
            (``Method.paper()`` switches and the per-sample "kalman" estimator, as
            ``RfiMonitorParams.paper_method()`` selects it).
    """

    def __init__(self, method: str | None = None) -> None:
        from rfi_monitor.monitor import RfiMonitor
        node_params, self.unknown = shipped_node_params()
        params = node_params.monitor_params()  # type: ignore[attr-defined]
        if method == "paper":  # Kang et al.'s method, as RfiMonitorParams.paper_method() selects it
            from rfi_monitor.params import Method
            params = Method.paper().apply(params)
            if hasattr(params, "estimator"):
                params = dataclasses.replace(params, estimator="kalman")
        elif method is not None and method != "ours":
            raise ValueError(f"method must be None, 'paper' or 'ours', got {method!r}")
        self.params = params
        self.check_saturation = bool(node_params.check_saturation)  # type: ignore[attr-defined]
        self.monitor = RfiMonitor(params)

    def process(self, counts: np.ndarray, scale: float, fs: float, fif: float, cplx: bool, bits: int,
                first: int, stamp_ns: int, light: bool = False):
        full = (2 ** (bits - 1) - 1) * scale if (bits >= 4 and self.check_saturation) else None
        # bits as the node passes them (IfSamples.bits_per_sample): with 1-3 bits the J/N is flagged a lower bound
        extra = {"light": True} if light else {}    # (a monitor older than session 11 has no light analysis)
        return self.monitor.process(counts.astype(np.float64) * scale, fs, fif, first, stamp_ns,
                                    is_complex=cplx, full_scale=full, bits=int(bits), **extra)


# ---------------------------------------------------------------------------------------------
# Real clean captures
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Capture:
    """A clean real capture as int counts (real (n,) or interleaved I, Q (2n,)).

    Pass bands: PocketSDR's BW_IF (2.5 MHz I/Q, 4.2 MHz real; its readme), the GNSS-SDR capture's
    USRP1 + DBSRX at 4 MS/s taken as +-1.8 MHz (our assumption)."""

    name: str
    counts: np.ndarray
    scale: float
    sample_rate_hz: float
    intermediate_frequency_hz: float
    is_complex: bool
    bits: int
    source: str
    filter_hz: tuple[float, float]
    """Pass band of the capture's front end relative to the RF centre, Hz (its IF filter)."""

    @property
    def n_samples(self) -> int:
        return self.counts.size // 2 if self.is_complex else self.counts.size

    def values(self) -> np.ndarray:
        v = self.counts.astype(np.float64) * self.scale
        return v[0::2] + 1j * v[1::2] if self.is_complex else v


def load_captures() -> list[Capture]:
    """The clean captures: the whole files in ../shared/data when present, else the project's copies."""
    out = []
    p_iq = SHARED / "iq_clean_pocketsdr" / "L1_20211202_084700_4MHz_IQ.bin"
    p_re = SHARED / "iq_clean_pocketsdr" / "L1_20211125_004000_12MHz_I.bin"
    p_gs = SHARED / "iq_clean_gnsssdr" / "GSoC_CTTC_capture_2012_07_26_4Msps_4ms.dat"
    if not p_iq.exists():
        p_iq = TEST_DATA / "pocketsdr_L1_4MHz_IQ_10ms.bin"
        p_re = TEST_DATA / "pocketsdr_L1_12MHz_I_10ms.bin"
        p_gs = TEST_DATA / "gnsssdr_cttc_4Msps_4ms.dat"
    iq = np.fromfile(p_iq, dtype=np.int8)
    out.append(Capture("PocketSDR 4 MS/s I/Q 2-bit", iq, 1.0, 4e6, 0.0, True, 2, p_iq.name, (-1.25e6, 1.25e6)))
    re_ = np.fromfile(p_re, dtype=np.int8)
    out.append(Capture("PocketSDR 12 MS/s real 2-bit", re_, 1.0, 12e6, 3.0e6, False, 2, p_re.name, (-2.1e6, 2.1e6)))
    g = np.fromfile(p_gs, dtype=np.float32).astype(np.float64)
    rms = float(np.sqrt(np.mean(g ** 2)))
    scale = rms / 2 ** 12  # int16 counts with the RMS at 4096 counts (1/8 of full scale)
    gi = np.clip(np.round(g / scale), -32768, 32767).astype(np.int16)
    out.append(Capture("GNSS-SDR 4 MS/s I/Q (int16)", gi, scale, 4e6, 0.0, True, 16, p_gs.name, (-1.8e6, 1.8e6)))
    return out


# ---------------------------------------------------------------------------------------------
# Rows
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    """One stream: front end, jammers, how many blocks; optionally on a real capture.

    ``jammer_jn_db`` gives each jammer's J/N *over a block once on* (filter and in-band fraction
    included): the simulator's nominal J/S is set so that the block J/N hits it.
    """

    name: str
    front_end: FrontEndConfig
    jammers: tuple[Jammer, ...]
    jammer_jn_db: tuple[float, ...] = ()
    n_blocks: int = 45
    capture: str | None = None
    capture_jammers: Callable[[float, float, float], tuple[Jammer, ...]] | None = None
    """Real-capture rows: jammers from (filter low Hz, filter high Hz, switch-on time s)."""
    settle_agc: bool = True
    snapshot_period_s: float = 0.0
    """> 0: one 1 ms block every this many seconds, each from a fresh simulator (the demo's IF snapshots)."""
    seed: int = 1
    note: str = ""


FE_REC = dict(sample_rate_hz=10e6, intermediate_frequency_hz=0.0, is_complex=True, bits=8)


def _with_js(row_fe: FrontEndConfig, jams: Sequence[Jammer], targets: Sequence[float]) -> tuple[Jammer, ...]:
    """Set each jammer's J/S so that its J/N over a block (filter, band and AGC included) is the target
    (no targets: the jammers as given)."""
    if not targets:
        return tuple(jams)
    out = []
    for j, target in zip(jams, targets, strict=True):
        probe_j = dataclasses.replace(j, js_db=js_for_jn_db(row_fe, 0.0), on_time_s=0.0)
        fe_probe = dataclasses.replace(row_fe, gain_mode="ideal")
        tr = IfSimulator(fe_probe, (probe_j,), satellites=(), seed=0).generate(
            int(row_fe.sample_rate_hz * 2e-3)).truth
        out.append(dataclasses.replace(j, js_db=js_for_jn_db(row_fe, 0.0) + target - float(tr.jn_block_db[0])))
    return tuple(out)


def rows() -> list[Row]:
    """The issue's table as streams (see the module docstring)."""
    r: list[Row] = []
    fe1a = FrontEndConfig(**FE_REC, gain_mode="agc")
    r.append(Row("1a rec. 1: saw-tooth up -4.16..+4.08 MHz, 8.972 us, rate x1.14 over a sweep, on at 0", fe1a,
                 (SweepJammer("saw_up", -4.16e6, 4.08e6, 8.972e-6, rate_ratio=1.54 / 1.35, time_offset_s=3.1e-6),),
                 (9.5,)))
    lo = -4.16e6 - 1.35e12 * 1.3e-6
    span = 0.5 * (1.35e12 + 1.54e12) * 8.972e-6
    fe1b = FrontEndConfig(**FE_REC, gain_mode="agc", filter_low_hz=-4.16e6, filter_high_hz=4.08e6)
    r.append(Row("1b rec. 1: saw-tooth up 1.35->1.54e12 Hz/s, 8.972 us, filter -4.16..+4.08 MHz, on at 0", fe1b,
                 (SweepJammer("saw_up", lo, lo + span, 8.972e-6, rate_ratio=1.54 / 1.35, time_offset_s=0.7e-6),),
                 (9.5,)))
    fe2 = FrontEndConfig(**FE_REC, gain_mode="agc", filter_low_hz=-4.9e6, filter_high_hz=4.9e6, clip_sigma=1.9)
    r.append(Row("2 rec. 2: triangle -13.5..+13.5 MHz, 9.09 us, in band ~36 %, clipped, on at 0", fe2,
                 (SweepJammer("triangle", -13.5e6, 13.5e6, 9.09e-6, time_offset_s=2.0e-6),), (13.0,)))
    fronts = [("16.368 MS/s real int8", FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=4.092e6,
                                                          bits=8, gain_mode="agc"), (-3e6, 6e6, 12e-6), 25.0),
              ("10 MS/s complex int8", FrontEndConfig(**FE_REC, gain_mode="agc"), (-4e6, 8e6, 20e-6), 30.0),
              ("38.192 MS/s real int16", FrontEndConfig(bits=16, gain_mode="agc"), (-5e6, 10e6, 10e-6), 27.0)]
    for label, fe, (f0, bw, T), jn in fronts:
        r.append(Row(f"3 saw-tooth {bw / 1e6:.0f} MHz in {T * 1e6:.0f} us, J/N {jn:.0f} dB, on before start, {label}",
                     fe, (ChirpJammer(start_frequency_hz=f0, sweep_rate_hz_per_s=bw / T, sweep_period_s=T,
                                      time_offset_s=0.37 * T),), (jn,), n_blocks=20))
        r.append(Row(f"3 CW +1.1 MHz, J/N {jn:.0f} dB, on before start, {label}", fe,
                     (CwJammer(frequency_hz=1.1e6),), (jn,), n_blocks=12))
        r.append(Row(f"3 clean, {label}", fe, (), (), n_blocks=20))
    for label, fe, (f0, bw, T), jn in fronts[:2]:
        r.append(Row(f"4 saw-tooth {bw / 1e6:.0f} MHz in {T * 1e6:.0f} us switched on after 6 clean blocks, "
                     f"J/N {jn:.0f} dB, {label}", fe,
                     (ChirpJammer(start_frequency_hz=f0, sweep_rate_hz_per_s=bw / T, sweep_period_s=T,
                                  on_time_s=6 * BLOCK_S),), (jn,), n_blocks=20, settle_agc=False))
    # item 3's sweep shapes, inside the band of the recordings' front end (10 MS/s complex int8, AGC)
    fe_s = FrontEndConfig(**FE_REC, gain_mode="agc")
    for j in (SweepJammer("saw_down", -4e6, 4e6, 10e-6),
              SweepJammer("triangle", -4e6, 4e6, 20e-6, up_fraction=0.5),
              SweepJammer("triangle", -3e6, 4e6, 15e-6, up_fraction=0.7, rate_ratio=1.3),
              SweepJammer("hooked_saw", -3.5e6, 4e6, 12e-6, hook_fraction=0.15, hook_overshoot_hz=0.8e6),
              SweepJammer("saw_up", -4e6, 4e6, 9e-6, rate_ratio=1.5)):
        extra = ""
        if j.shape == "triangle":
            extra = f", up {j.up_fraction:.0%}"
        elif j.shape == "hooked_saw":
            extra = f", hook {j.hook_fraction:.0%} / {j.hook_overshoot_hz / 1e6:.1f} MHz"
        r.append(Row(f"S {j.shape} {j.low_frequency_hz / 1e6:+.1f}..{j.high_frequency_hz / 1e6:+.1f} MHz, "
                     f"{j.sweep_period_s * 1e6:.0f} us, rate ratio {j.rate_ratio:.2f}{extra}, J/N 10 dB, on at 0",
                     fe_s, (dataclasses.replace(j, time_offset_s=0.3 * j.sweep_period_s),), (10.0,), n_blocks=12))
    # the demo's chirp phases (scenarios/default.yaml: paper front end, noise counted over 2 MHz, the
    # paper's chirp, 1 ms snapshots every second from a fresh simulator)
    fe_demo = FrontEndConfig(noise_bandwidth_hz=2e6)
    for js in (-10.0, -2.0, 6.0, 14.0):
        r.append(Row(f"D demo chirp phase J/S {js:+.0f} dB (paper front end, 1 ms every 1 s)", fe_demo,
                     (ChirpJammer(js_db=js),), (), n_blocks=20, snapshot_period_s=1.0))
    # the generator had no AGC to speak of: the same switch-on rows with the gain fixed by the
    # configured powers (gain_mode "ideal": the noise before switch-on sits at 1-2 counts)
    for label, fe, (f0, bw, T), jn in fronts[:2]:
        r.append(Row(f"4 the same, gain fixed for the jammer ({label})", dataclasses.replace(fe, gain_mode="ideal"),
                     (ChirpJammer(start_frequency_hz=f0, sweep_rate_hz_per_s=bw / T, sweep_period_s=T,
                                  on_time_s=6 * BLOCK_S),), (jn,), n_blocks=20, settle_agc=False))
    # real clean captures, and the same with simulated jammers added (bands scaled to the capture's filter)
    r.append(Row("R clean", FrontEndConfig(), (), (), n_blocks=0, capture="*"))
    r.append(Row("R + saw-tooth up over 80 % of the IF band, 8.972 us, rate x1.14, J/N 10 dB, on at 0",
                 FrontEndConfig(), (), (10.0,), capture="*",
                 capture_jammers=lambda lo, hi, on: (SweepJammer("saw_up", 0.8 * lo, 0.8 * hi, 8.972e-6,
                                                                 rate_ratio=1.54 / 1.35),)))
    r.append(Row("R + triangle over 4x the IF band, 9.09 us, J/N 13 dB in block, on at 0", FrontEndConfig(), (),
                 (13.0,), capture="*",
                 capture_jammers=lambda lo, hi, on: (SweepJammer("triangle", 4 * lo, 4 * hi, 9.09e-6),)))
    r.append(Row("R + saw-tooth over 60 % of the IF band in 12 us, switched on mid-capture, J/N 25 dB",
                 FrontEndConfig(), (), (25.0,), capture="*", settle_agc=False,
                 capture_jammers=lambda lo, hi, on: (ChirpJammer(start_frequency_hz=0.6 * lo,
                                                                 sweep_rate_hz_per_s=0.6 * (hi - lo) / 12e-6,
                                                                 sweep_period_s=12e-6, on_time_s=on),)))
    r.append(Row("R + CW at 40 % of the upper band edge, J/N 10 dB, on at 0", FrontEndConfig(), (), (10.0,),
                 capture="*", capture_jammers=lambda lo, hi, on: (CwJammer(frequency_hz=0.4 * hi),)))
    return r


# ---------------------------------------------------------------------------------------------
# Streams
# ---------------------------------------------------------------------------------------------
@dataclass
class Block:
    """One block as the node receives it, with its truth."""

    counts: np.ndarray
    scale: float
    fs: float
    fif: float
    cplx: bool
    bits: int
    first: int
    truth_type: int
    truth_jn_db: float        # J/N over the block of the strongest active jammer (-inf: none)
    truth_jn_in_band_db: float
    truth_in_band: float
    truth_period_s: float
    truth_band_hz: tuple[float, float]
    truth_shape: str
    truth_clipped: float
    truth_freq_hz: float      # truth frequency at the block end (CW/chirp), Hz

    @property
    def clipped_pairs(self) -> float:
        """Share of samples (complex: I/Q pairs with I or Q) at the extreme codes."""
        top = 2 ** self.bits - 1 if self.bits <= 3 else 2 ** (self.bits - 1) - 1
        low = -top if self.bits <= 3 else -top - 1
        ext = (self.counts == top) | (self.counts == low)
        return float(np.mean(ext[0::2] | ext[1::2])) if self.cplx else float(np.mean(ext))


def _settled_fe(fe: FrontEndConfig, jams: tuple[Jammer, ...]) -> FrontEndConfig:
    """An AGC that had settled on the jammer before the stream starts (the recording started later)."""
    if fe.gain_mode != "agc" or not jams:
        return fe
    probe = IfSimulator(dataclasses.replace(fe, gain_mode="ideal"), tuple(dataclasses.replace(j, on_time_s=0.0)
                                                                          for j in jams), satellites=(), seed=0)
    jn = float(np.sum(10 ** (probe.generate(int(fe.sample_rate_hz * 2e-3)).truth.jn_block_db / 10)))
    return dataclasses.replace(fe, agc_initial_gain_db=-10 * math.log10(1 + jn))


def _block_from_truth(counts: np.ndarray, scale: float, fe: FrontEndConfig, first: int, tr) -> Block:
    act = [i for i in range(len(tr.jn_db)) if tr.active[i]]
    if act:
        i = max(act, key=lambda k: tr.jn_block_db[k])
        per = float(tr.sweep_period_s[i])
        return Block(counts, scale, fe.sample_rate_hz, fe.intermediate_frequency_hz, fe.is_complex, fe.bits, first,
                     tr.jammer_type, float(tr.jn_block_db[i]), float(tr.jn_in_band_db[i]),
                     float(tr.in_band_fraction[i]), per, (float(tr.swept_band_hz[i][0]), float(tr.swept_band_hz[i][1])),
                     tr.shape[i], tr.clipped_fraction, float(tr.frequency_hz[i][-1]))
    return Block(counts, scale, fe.sample_rate_hz, fe.intermediate_frequency_hz, fe.is_complex, fe.bits, first, NONE,
                 -math.inf, -math.inf, 0.0, math.nan, (math.nan, math.nan), "", tr.clipped_fraction, math.nan)


def sim_stream(row: Row) -> tuple[FrontEndConfig, list[Block]]:
    """The row's blocks from the simulator alone."""
    jams = _with_js(row.front_end, row.jammers, row.jammer_jn_db)
    fe = _settled_fe(row.front_end, jams) if row.settle_agc else row.front_end
    sim = IfSimulator(fe, jams, seed=row.seed)
    n = int(round(fe.sample_rate_hz * BLOCK_S))
    out = []
    if row.snapshot_period_s > 0:
        step = int(round(fe.sample_rate_hz * row.snapshot_period_s))
        for k in range(row.n_blocks):
            t = k * row.snapshot_period_s
            shifted = tuple(dataclasses.replace(j, time_offset_s=math.fmod(t, j.sweep_period_s))
                            if isinstance(j, ChirpJammer) else j for j in jams)
            b = IfSimulator(fe, shifted, seed=row.seed * 100_000 + k).generate(n)
            out.append(_block_from_truth(b.counts, b.scale, fe, k * step, b.truth))
        return fe, out
    for _ in range(row.n_blocks):
        b = sim.generate(n)
        out.append(_block_from_truth(b.counts, b.scale, fe, b.first_sample_index, b.truth))
    return fe, out


def capture_stream(row: Row, cap: Capture, max_blocks: int) -> tuple[FrontEndConfig, list[Block]]:
    """The capture in 1 ms blocks, with the row's jammers added (re-quantised to the capture's bits,
    the gain settled on the total power as the front end's AGC would have it)."""
    n = int(round(cap.sample_rate_hz * BLOCK_S))
    nb = min(max_blocks, cap.n_samples // n)
    if row.capture_jammers is None:
        fe = FrontEndConfig(sample_rate_hz=cap.sample_rate_hz, intermediate_frequency_hz=cap.intermediate_frequency_hz,
                            is_complex=cap.is_complex, bits=cap.bits)
        out = []
        for k in range(nb):
            c = cap.counts[(2 if cap.is_complex else 1) * k * n:(2 if cap.is_complex else 1) * (k + 1) * n]
            tr_clip = float(np.mean(np.abs(c) == (3 if cap.bits == 2 else 2 ** (cap.bits - 1) - 1)))
            out.append(Block(c, cap.scale, cap.sample_rate_hz, cap.intermediate_frequency_hz, cap.is_complex, cap.bits,
                             k * n, NONE, -math.inf, -math.inf, 0.0, math.nan, (math.nan, math.nan), "", tr_clip,
                             math.nan))
        return fe, out
    fe = FrontEndConfig(sample_rate_hz=cap.sample_rate_hz, intermediate_frequency_hz=cap.intermediate_frequency_hz,
                        is_complex=cap.is_complex, bits=cap.bits, filter_low_hz=cap.filter_hz[0],
                        filter_high_hz=cap.filter_hz[1])
    assert row.capture_jammers is not None
    on_s = min(6, nb // 2) * BLOCK_S  # switch-on rows: after 6 blocks, or half-way through a short capture
    x = cap.values()
    x = x * math.sqrt(fe.noise_power_mw / float(np.mean(np.abs(x) ** 2)))  # the capture's power is N
    jams = _with_js(fe, row.capture_jammers(cap.filter_hz[0], cap.filter_hz[1], on_s), row.jammer_jn_db)
    sim = IfSimulator(fe, jams, satellites=(), seed=row.seed)
    out = []
    for k in range(nb):
        b = sim.generate(n, add_to=x[k * n:(k + 1) * n])
        out.append(_block_from_truth(b.counts, b.scale, fe, b.first_sample_index, b.truth))
    return fe, out


# ---------------------------------------------------------------------------------------------
# Scoring
# ---------------------------------------------------------------------------------------------
def _shape_name(code: int) -> str:
    try:
        from rfi_monitor.ridge import SHAPE_NAMES
        return SHAPE_NAMES.get(int(code), str(code))
    except ImportError:
        return str(code)


@dataclass
class RowResult:
    """Truth and what the monitor reported for one stream."""

    name: str
    blocks: list[Block]
    ests: list
    seconds: float
    verdicts: dict[str, bool | None] = field(default_factory=dict)
    cells: dict[str, str] = field(default_factory=dict)


def _fmt_range(v: np.ndarray, unit_fmt: Callable[[float], str]) -> str:
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "-"
    return f"{unit_fmt(float(np.median(v)))} [{unit_fmt(float(v.min()))}, {unit_fmt(float(v.max()))}]"


def score(name: str, fe: FrontEndConfig, blocks: list[Block], ests: list, seconds: float) -> RowResult:
    res = RowResult(name, blocks, ests, seconds)
    on = [k for k, b in enumerate(blocks) if b.truth_type != NONE]
    first_on = on[0] if on else 0
    # blocks scored: from the block after the switch-on block (the whole stream if on from the start)
    sc = [k for k in range(len(blocks)) if (k > first_on if (on and first_on > 0) else True)]
    truth_t = Counter(blocks[k].truth_type for k in sc)
    want = truth_t.most_common(1)[0][0]
    types = [int(ests[k].type) if ests[k].valid else -1 for k in sc]
    got = Counter(TYPE_NAMES.get(t, "rejected") for t in types)
    right = sum(t == want for t in types)
    res.verdicts["type"] = right >= 0.95 * len(sc)
    first_right = next((k for k in range(first_on, len(blocks)) if ests[k].valid and int(ests[k].type) == want), None)
    lat = "-" if first_right is None else f"block {first_right - first_on + 1}"
    res.cells["type"] = (", ".join(f"{k} {v}" for k, v in got.most_common()) + f" of {len(sc)}; first right: {lat}")
    # J/N
    tj = np.array([blocks[k].truth_jn_db for k in sc])
    rj = np.array([ests[k].jammer_to_noise_db if ests[k].valid else math.nan for k in sc])
    lb = np.array([bool(getattr(ests[k], "jammer_to_noise_is_lower_bound", False)) for k in sc])
    if want != NONE:
        err = rj - tj
        ok = np.isfinite(err) & ((np.abs(err) <= 3.0) | (lb & (err <= 3.0)))
        res.verdicts["J/N"] = bool(np.median(ok.astype(float)) >= 0.5) if ok.size else False
        jn_in = float(np.median([blocks[k].truth_jn_in_band_db for k in sc]))
        frac = float(np.median([blocks[k].truth_in_band for k in sc]))
        res.cells["truth J/N"] = f"{np.median(tj):.1f} (in band {jn_in:.1f}, {100 * frac:.0f} % in band)"
        res.cells["J/N"] = _fmt_range(rj, lambda v: f"{v:.1f}") + (f"; lower bound in {int(lb.sum())}"
                                                                   if lb.any() else "")
    else:
        res.cells["truth J/N"] = "-"
        res.cells["J/N"] = _fmt_range(rj, lambda v: f"{v:.1f}")
    # frequency in band (never a wrong frequency published as valid)
    nyq_lo, nyq_hi = (-fe.sample_rate_hz / 2, fe.sample_rate_hz / 2) if fe.is_complex else \
        (-abs(fe.intermediate_frequency_hz), fe.sample_rate_hz / 2 - abs(fe.intermediate_frequency_hz))
    pub = [k for k in sc if ests[k].valid and int(ests[k].type) in (CW, CHIRP)]
    fr = np.array([ests[k].frequency_hz for k in pub])
    n_nan = int(np.sum(~np.isfinite(fr)))
    inside = int(np.sum(np.isfinite(fr) & (fr >= nyq_lo) & (fr <= nyq_hi)))
    outside = len(pub) - n_nan - inside
    res.verdicts["frequency"] = outside == 0 if pub else None
    if want == CW and pub:
        ferr = np.abs(fr - np.array([blocks[k].truth_freq_hz for k in pub]))
        res.cells["freq"] = f"{inside} in band, {n_nan} NaN, {outside} outside; median err {np.nanmedian(ferr):.0f} Hz"
    else:
        res.cells["freq"] = f"{inside} in band, {n_nan} NaN, {outside} outside" if pub else "-"
    if want == CHIRP:
        res.cells["freq"] += "; " + chirp_frequency_summary(blocks, ests, sc, nyq_lo, nyq_hi)
    # period
    if want == CHIRP:
        tp = float(np.nanmedian([blocks[k].truth_period_s for k in sc]))
        chirp_blocks = [k for k in sc if ests[k].valid and int(ests[k].type) == CHIRP]
        rp = np.array([ests[k].sweep_period_s for k in chirp_blocks])
        have = np.isfinite(rp)
        if have.any():
            med = float(np.median(rp[have]))
            rel = abs(med - tp) / tp
            res.verdicts["period"] = bool(rel <= 0.01 and have.sum() >= 0.5 * max(1, len(chirp_blocks)))
            res.cells["period"] = (f"{med * 1e6:.3f} us ({100 * rel:.2f} % off) in {int(have.sum())}/"
                                   f"{len(chirp_blocks)}")
        else:
            res.verdicts["period"] = False
            res.cells["period"] = f"none in {len(chirp_blocks)} CHIRP blocks"
        res.cells["truth period"] = f"{tp * 1e6:.3f} us"
        tshape = Counter(blocks[k].truth_shape for k in sc).most_common(1)[0][0]
        res.cells["truth shape"] = SIM_SHAPE_TO_MONITOR.get(tshape, tshape)
        shapes = Counter(_shape_name(getattr(ests[k], "sweep_shape", 0)) for k in chirp_blocks)
        res.cells["shape"] = ", ".join(f"{k} {v}" for k, v in shapes.most_common(2)) if shapes else "-"
        known = {k: v for k, v in shapes.items() if k not in ("unknown", "0")}
        res.verdicts["shape"] = (max(known, key=known.get) == res.cells["truth shape"]) if known else False
        lo, hi = blocks[sc[0]].truth_band_hz
        res.cells["truth band"] = f"{lo / 1e6:+.2f}..{hi / 1e6:+.2f} MHz"
    else:
        res.cells["truth period"] = res.cells["period"] = res.cells["truth shape"] = res.cells["shape"] = "-"
        res.cells["truth band"] = "-"
    tc = np.median([b.truth_clipped for b in blocks])
    tp = np.median([b.clipped_pairs for b in blocks])
    rc = np.array([getattr(e, "clipped_fraction", math.nan) for e in ests], dtype=float)
    truth_clip = (f"{100 * tc:.1f} % ({100 * tp:.1f} % of pairs)" if fe.is_complex else f"{100 * tc:.1f} %")
    if fe.bits <= 3:
        truth_clip = "2-bit: n/a"
    res.cells["clip"] = truth_clip + (f" / {100 * np.nanmedian(rc):.1f} %" if np.isfinite(rc).any() else " / -")
    res.cells["truth type"] = TYPE_NAMES[want]
    return res


CHIRP_FREQ_TOLERANCE_HZ = 100e3
"""Issue 26 item 3: a chirp's published frequency within this of the truth at the block end, Hz."""


def chirp_frequency_summary(blocks: list[Block], ests: list, scored: list[int], lo_hz: float, hi_hz: float) -> str:
    """Issue 26 item 3, per stream: of the scored blocks whose jammer is inside the sampled band [lo_hz, hi_hz] at the
    block end (truth), how many published a finite frequency, the median |error|, how many within
    CHIRP_FREQ_TOLERANCE_HZ, and the share of |error| <= the published 1-sigma std (about 68 % if the std is right);
    and how many of the blocks whose jammer is outside the band published one (should be none)."""
    inb = [k for k in scored if math.isfinite(blocks[k].truth_freq_hz) and lo_hz <= blocks[k].truth_freq_hz <= hi_hz]
    out = [k for k in scored if k not in inb and ests[k].valid and math.isfinite(ests[k].frequency_hz)]
    pubd = [k for k in inb if ests[k].valid and math.isfinite(ests[k].frequency_hz)]
    if not inb:
        return f"in band at block end: 0 blocks; published while out of band {len(out)}"
    if not pubd:
        return f"in band at block end: 0 of {len(inb)} published; published while out of band {len(out)}"
    err = np.array([ests[k].frequency_hz - blocks[k].truth_freq_hz for k in pubd])
    std = np.array([ests[k].frequency_std_hz for k in pubd])
    cover = float(np.mean(np.abs(err) <= std)) if np.isfinite(std).all() else math.nan
    return (f"in band at block end: {len(pubd)} of {len(inb)} published, abs. error median "
            f"{np.median(np.abs(err)) / 1e3:.0f} kHz, <= 100 kHz in "
            f"{int(np.sum(np.abs(err) <= CHIRP_FREQ_TOLERANCE_HZ))}, within 1 sigma {100 * cover:.0f} %; "
            f"published while out of band {len(out)}")


def run_stream(fe: FrontEndConfig, blocks: list[Block], method: str | None = None) -> tuple[list, float]:
    """Feed the blocks to a fresh node-like monitor; (estimates, CPU seconds)."""
    mon = NodeLikeMonitor(method)
    t0 = time.process_time()
    ests = []
    for k, b in enumerate(blocks):
        ests.append(mon.process(b.counts, b.scale, b.fs, b.fif, b.cplx, b.bits, b.first,
                                stamp_ns=1_000_000_000 + int(round(k * BLOCK_S * 1e9))))
    return ests, time.process_time() - t0


def verdict(res: RowResult) -> str:
    bad = [k for k, v in res.verdicts.items() if v is False]
    return "**met**" if not bad else "not met: " + ", ".join(bad)


def run(selected: Sequence[str], n_blocks: int | None, capture_blocks: int,
        log: CaseLog | None = None) -> tuple[list[RowResult], list[str]]:
    """Every selected row scored; ``log`` gets a line per row (its verdict and time), default: a case log."""
    log = log if log is not None else case_log(__file__)
    caps = load_captures()
    results = []
    sources = [f"{c.name}: {c.source}, {c.n_samples / c.sample_rate_hz * 1e3:.0f} ms" for c in caps]
    for row in rows():
        if selected and not any(s in row.name for s in selected):
            continue
        if row.capture is None:
            if n_blocks is not None:
                row = dataclasses.replace(row, n_blocks=min(row.n_blocks, n_blocks))
            fe, blocks = sim_stream(row)
            ests, secs = run_stream(fe, blocks)
            results.append(score(row.name, fe, blocks, ests, secs))
        else:
            for cap in caps:
                fe, blocks = capture_stream(row, cap, capture_blocks)
                ests, secs = run_stream(fe, blocks)
                results.append(score(f"{row.name} ({cap.name})", fe, blocks, ests, secs))
                r = results[-1]
                log.done(f"{verdict(r):40s} {r.name}: {r.cells['type']}")
            continue
        r = results[-1]
        log.done(f"{verdict(r):40s} {r.name}: {r.cells['type']}")
    return results, sources


def git_describe(path: Path) -> str:
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", str(path)], cwd=ROOT, capture_output=True,
                               text=True, timeout=10).stdout.strip()
        return head + (" + uncommitted changes under " + str(path.relative_to(ROOT)) if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def markdown(results: list[RowResult], sources: list[str], unknown: list[str], wall_s: float,
             monitor_from: str = "") -> str:
    import rfi_monitor
    mod = portable_path(Path(rfi_monitor.__file__).resolve().parent)
    n_met = sum(verdict(r) == "**met**" for r in results)
    lines = [
        "# rfi_monitor on issue 14's jammers (simulated, and real clean captures with jammers added)",
        "",
        "Made by `benchmarks/rfi_monitor_real_jammers.py` (its docstring says how each row is simulated, which",
        "facts of the real recordings are used and what \"right\" means). The monitor is driven as",
        "`rfi_monitor_node` drives it,",
        "with the shipped `config/rfi_monitor.yaml`; one fresh monitor per row, 1 ms blocks.",
        "",
        f"- monitor measured: {monitor_from or f'`{mod}` at ' + git_describe(ROOT / 'src' / 'rfi_monitor')}",
        f"- rows met: **{n_met} of {len(results)}**; run time {wall_s:.0f} s on {cpu_model()}",
        f"- clean captures: {'; '.join(sources)}",
    ]
    if unknown:
        lines.append(f"- YAML keys the node's parameter class does not know (ignored): {', '.join(unknown)}")
    lines += [
        "",
        "Columns: truth from the simulator (J/N over the block, in band, and the share of samples in band;",
        "clip = share of values at full scale (complex: and of I/Q pairs with I or Q there), truth / reported);",
        "reported = the monitor's `JammerState` fields over",
        "the scored blocks (median [min, max]); blocks are scored from the one after the switch-on block.",
        "\"freq\" counts the published CW/CHIRP frequencies inside the sampled band, NaN (not tracked), outside;",
        "for a chirp (issue 26 item 3) also: of the scored blocks whose jammer is inside the sampled band at the block",
        "end (truth), how many published a frequency, the median absolute error, how many within 100 kHz, and the",
        "share within the published 1-sigma std (about 68 % if the std is right).",
        "",
        "| row | truth type | truth J/N dB | truth period | truth band | truth shape | reported type (blocks) "
        "| reported J/N dB | freq | reported period | reported shape | clip truth / reported | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        c = r.cells
        lines.append(f"| {r.name} | {c['truth type']} | {c['truth J/N']} | {c['truth period']} | {c['truth band']} "
                     f"| {c['truth shape']} | {c['type']} | {c['J/N']} | {c['freq']} | {c['period']} | {c['shape']} "
                     f"| {c['clip']} | {verdict(r)} |")
    lines += [
        "",
        "Rows D simulate `make demo`'s chirp phases as the demo makes them (1 ms snapshots, 1 s apart, each from a",
        "fresh simulator; J/N over the block is J/S - 19 dB there). The issue's goal for them: CHIRP from J/S 6 dB on",
        "(the J/S -10 and -2 dB phases, J/N -29 and -21 dB, are scored against CHIRP too, and are not expected",
        "to be met).",
        "",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="write the markdown table here")
    ap.add_argument("--rows", nargs="*", default=[], help="run only rows whose name contains one of these")
    ap.add_argument("--blocks", type=int, default=None, help="at most this many blocks per simulated row")
    ap.add_argument("--capture-blocks", type=int, default=45, help="blocks per real capture row")
    ap.add_argument("--monitor-from", default="", help="say where the measured rfi_monitor came from (e.g. a "
                    "`git archive` export of a commit), instead of its path and the tree's git state")
    add_quiet_argument(ap)
    a = ap.parse_args(argv)
    t0 = time.time()
    log = case_log(__file__, quiet=a.quiet)
    results, sources = run(a.rows, a.blocks, a.capture_blocks, log)
    _, unknown = shipped_node_params()
    md = markdown(results, sources, unknown, time.time() - t0, a.monitor_from)
    log.say(md)
    if a.out is not None:
        a.out.write_text(md)
    log.finish(f"wrote {a.out}" if a.out is not None else "no --out: nothing written")
    return 0


if __name__ == "__main__":
    sys.exit(main())

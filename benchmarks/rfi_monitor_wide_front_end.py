"""Wider front ends with both cores (issue 26 item 4), measured as a user would run them: rfi_experiments'
if_source (pace real_time, reliable, 1 ms blocks: rclpy delivers about 1,000 messages a second, so the block length
stays 1 ms and a wider band makes bigger messages, not more of them) into separate processes at 1x over DDS.

(a) The transport alone: one if_source publishing an 8-bit complex stream (81 MS/s: the front end of the public 2025
    Jammertest recordings, and lower rates to find the limit) into a subscriber that only counts (raw bytes, no
    deserialisation, the stamp peeked for the latency): the MS/s carried, blocks lost, the CPU of the source and of
    the subscriber per second of stream.
(b) Three bands (L1, L2, L5 centre frequencies), each its own if_source and its own rfi_monitor_node in a namespace
    (/wide_l1, /wide_l2, /wide_l5; shipped parameters), at a ladder of rates per band; a saw-tooth chirp (J/N 10 dB,
    sweeping 75 % of the band in 20 us) switches on in L1 after 25 % of the stream and in L5 after 50 %; L2 stays
    clean. Per node, from its own /diagnostics and its /<ns>/rfi/jammer_state: blocks received, fully analysed, light,
    shed, lost before the node, the answer latency (arrival here minus the end of the block's samples), and the node's
    CPU seconds per stream second (/proc/<pid>/stat, over the stream), apart from its source's.

Writes docs/rfi_monitor/wide_front_end.md. Run (workspace sourced; other domains are other users):

    ROS_DOMAIN_ID=77 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python benchmarks/rfi_monitor_wide_front_end.py
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from bench_progress import add_quiet_argument, case_log
from rfi_monitor_live_stream import JN_DB, PAUSE_S, ROOT

BLOCK_S = 1e-3
"""Block duration, s (if_source's default; rclpy's delivery rate, about 1,000 messages a second, sets it)."""
TRANSPORT_RATES_HZ = (2.5e6, 20e6, 40e6, 81e6)
"""Complex sample rates of the transport-alone runs, Hz (the first: the cost of 1,000 messages a second nearly without
their bytes; the last: the 2025 Jammertest front end)."""
BAND_RATES_HZ = (2.5e6, 5e6, 10e6, 20e6)
"""Complex sample rates per band of the three-band ladder, Hz."""
QUICK_TRANSPORT_RATES_HZ = (81e6,)
QUICK_BAND_RATES_HZ = (2.5e6, 10e6)
STREAM_S = 2.0
"""Stream length, s (--quick: 1 s)."""
LATENCY_GOAL_MS = 100.0
"""The issue's bound on how far behind an answer may be, ms."""
NOISE_SEED = 26
CHIRP_PERIOD_S = 20e-6
CHIRP_BAND_FRACTION = 0.75
"""The chirp sweeps this share of each band (centred), up, in CHIRP_PERIOD_S (complex 4-10 MS/s cases of
src/rfi_monitor/test/test_stft_estimator.py sweep 75-80 % of the band in 10-30 us)."""
SETTLE_TIMEOUT_S = 15.0
"""After the sources end, the nodes' last reports (sent once the input has been silent for input_timeout_s) are
awaited this long at most, s."""
NODE_ARGS = ("-p", "diagnostics_period_s:=0.1", "-p", "input_timeout_s:=0.5")
"""As rfi_monitor_live_stream.py runs the node: everything else as shipped."""


@dataclass(frozen=True)
class Band:
    """One band of the three-band case: namespace, RF centre (Hz) and when its chirp switches on (share of the
    stream, None: clean)."""

    name: str
    center_frequency_hz: float
    chirp_on_fraction: float | None


BANDS = (Band("l1", 1575.42e6, 0.25), Band("l2", 1227.60e6, None), Band("l5", 1176.45e6, 0.5))


# ----------------------------------------------------------------------------------------------------- bookkeeping
def cpu_between(samples: Sequence[tuple[float, float]], t0: float, t1: float) -> float:
    """CPU seconds a process spent between wall times t0 and t1, s, from its (wall time, CPU seconds) samples (linear
    between samples; a time after the last sample, e.g. once the process ended, takes the last sample's value)."""
    if len(samples) < 2 or not t1 > t0:
        return math.nan
    t = np.array([s[0] for s in samples])
    c = np.array([s[1] for s in samples])
    return float(np.interp(t1, t, c) - np.interp(t0, t, c))


def latency_stats_ms(latencies_ms: Sequence[float]) -> tuple[float, float, float]:
    """(median, 95th percentile, max) of the answer latencies, ms; NaNs when there is none."""
    if not latencies_ms:
        return math.nan, math.nan, math.nan
    a = np.asarray(latencies_ms, dtype=float)
    return float(np.median(a)), float(np.percentile(a, 95)), float(np.max(a))


@dataclass
class BandResult:
    """What one node did with one band's stream (counts from its last /diagnostics report)."""

    band: str
    blocks: int
    received: int
    processed: int
    light: int
    shed: int
    lost: int
    rejected: int
    latencies_ms: list[float] = field(default_factory=list)
    node_cpu_per_s: float = math.nan
    source_cpu_per_s: float = math.nan
    chirp_answers: int = 0
    chirp_blocks_answered: int = 0

    @property
    def full(self) -> int:
        """Blocks that got the full analysis (published, not light)."""
        return self.processed - self.light

    @property
    def latency_ms(self) -> tuple[float, float, float]:
        return latency_stats_ms(self.latencies_ms)

    def in_full_on_time(self, bound_ms: float = LATENCY_GOAL_MS) -> bool:
        """Every block of the stream got the full analysis and every answer came less than ``bound_ms`` behind."""
        return (self.full == self.blocks and self.light == 0 and self.shed == 0 and self.lost == 0
                and len(self.latencies_ms) == self.blocks and self.latency_ms[2] < bound_ms)


def band_result(band: str, blocks: int, diag: dict[str, str]) -> BandResult:
    """A BandResult from a node's last /diagnostics values (strings, as DiagnosticStatus carries them)."""
    def num(key: str) -> int:
        return int(diag.get(key, 0))
    lost = sum(int(v) for k, v in diag.items() if k.startswith("input.") and k.endswith(".lost"))
    rejected = sum(int(v) for k, v in diag.items() if k.startswith("rejected_"))
    return BandResult(band, blocks, num("blocks_received"), num("blocks_processed"), num("blocks_light"),
                      num("blocks_shed"), lost, rejected)


def highest_rate_in_full(rows: Sequence[tuple[float, Sequence[BandResult]]]) -> float | None:
    """The highest rate (Hz) at which every band of every run was analysed in full on time, provided every lower
    rate of the ladder was too; None if the lowest was not."""
    ok: dict[float, bool] = {}
    for rate, results in rows:
        ok[rate] = ok.get(rate, True) and bool(results) and all(r.in_full_on_time() for r in results)
    best = None
    for rate in sorted(ok):
        if not ok[rate]:
            break
        best = rate
    return best


# ---------------------------------------------------------------------------------------------------- processes
def proc_cpu_s(pid: int) -> float | None:
    """user + system CPU seconds of a process (its threads included), or None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


MACHINE = "machine"
"""CpuSampler's key of the whole machine's busy CPU seconds (all cores, every process: ours and the other workers')."""


def machine_busy_s() -> float:
    """Busy CPU seconds of the whole machine since boot, all cores (/proc/stat: user, nice, system, irq, softirq)."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    return sum(values[i] for i in (0, 1, 2, 5, 6)) / os.sysconf("SC_CLK_TCK")


class CpuSampler:
    """Samples the CPU seconds of some processes every ``period_s`` on a thread: (wall time, CPU s) per pid."""

    def __init__(self, pids: dict[str, int], period_s: float = 0.02) -> None:
        self.pids = pids
        self.samples: dict[str, list[tuple[float, float]]] = {k: [] for k in pids}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(period_s,), daemon=True)
        self._thread.start()

    def _run(self, period_s: float) -> None:
        self.samples[MACHINE] = []
        while not self._stop.is_set():
            now = time.time()
            for key, pid in self.pids.items():
                c = proc_cpu_s(pid)
                if c is not None:
                    self.samples[key].append((now, c))
            self.samples[MACHINE].append((now, machine_busy_s()))
            self._stop.wait(period_s)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def ros2_run(pkg: str, exe: str, args: Sequence[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([str(ROOT / "tools" / "ros2_run"), pkg, exe, "--ros-args", *args],
                            stdout=subprocess.DEVNULL, stderr=open(log, "w"))


def source_args(data: Path, rate_hz: float, namespace: str, center_hz: float) -> list[str]:
    """if_source's arguments: an int8 I/Q file at ``rate_hz`` paced in real time, reliable, 1 ms blocks, held until
    one subscriber has matched (the node, or the counter)."""
    return ["-r", f"__ns:=/{namespace}", "-p", f"input:={data}", "-p", "item_type:=ibyte",
            "-p", f"sampling_frequency_hz:={rate_hz}", "-p", "intermediate_frequency_hz:=0.0",
            "-p", f"center_frequency_hz:={center_hz}", "-p", "bits_per_sample:=8",
            "-p", f"block_duration_s:={BLOCK_S}", "-p", "pace:=real_time", "-p", "reliability:=reliable",
            "-p", "wait_for_subscribers:=1", "-p", "wait_timeout_s:=600.0", "-p", f"hardware_id:=source_{namespace}"]


WARM_UP = ("from rfi_monitor.node_params import MonitorNodeParams; from rfi_monitor.warm_up import warm_up; "
           "warm_up(MonitorNodeParams().monitor_params())")
"""Run once before the ladder, in a process of its own: numba's cache filled, so that three nodes starting together do
not each compile the kernels (minutes on a fresh install of a loaded machine; a node stopped before it finished
leaves no cache)."""


def stop(proc: subprocess.Popen, timeout_s: float = 20.0) -> None:
    """SIGINT, then kill after ``timeout_s``."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


# -------------------------------------------------------------------------------------------------------- data
def write_noise(path: Path, rate_hz: float, seconds: float) -> int:
    """int8 I/Q noise (the transport does not look at it); returns the number of blocks."""
    rng = np.random.default_rng(NOISE_SEED)
    n = int(round(rate_hz * seconds)) * 2
    with open(path, "wb") as fh:
        for start in range(0, n, 1 << 24):
            rng.integers(-40, 41, size=min(1 << 24, n - start), dtype=np.int8).tofile(fh)
    return int(round(seconds / BLOCK_S))


def band_simulator(band: Band, rate_hz: float, seconds: float, seed: int):
    """rfi_sim's 8-bit I/Q front end for one band (noise and GPS PRN 1; the chirp from its switch-on, if any)."""
    from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator, js_for_jn_db
    fe = FrontEndConfig(sample_rate_hz=rate_hz, intermediate_frequency_hz=0.0, is_complex=True, bits=8)
    jammers: tuple = ()
    if band.chirp_on_fraction is not None:
        width = CHIRP_BAND_FRACTION * rate_hz
        jammers = (ChirpJammer(start_frequency_hz=-width / 2, sweep_rate_hz_per_s=width / CHIRP_PERIOD_S,
                               sweep_period_s=CHIRP_PERIOD_S, js_db=js_for_jn_db(fe, JN_DB),
                               on_time_s=band.chirp_on_fraction * seconds),)
    return IfSimulator(fe, jammers, seed=seed)


def write_band(path: Path, band: Band, rate_hz: float, seconds: float, seed: int) -> int:
    """One band's int8 I/Q stream (:func:`band_simulator`) to a file; returns the number of blocks."""
    sim = band_simulator(band, rate_hz, seconds, seed)
    n = int(round(rate_hz * seconds))
    chunk = int(round(rate_hz * BLOCK_S)) * 100
    with open(path, "wb") as fh:
        for start in range(0, n, chunk):
            sim.generate(min(chunk, n - start)).counts.astype(np.int8).tofile(fh)
    return int(round(seconds / BLOCK_S))


# ------------------------------------------------------------------------------------------ the analysis alone
ANALYSIS_BLOCKS = 120
"""Blocks per case of the in-process measurement (the first ANALYSIS_SKIP not counted: calibration, the switch-on)."""
ANALYSIS_SKIP = 20


def analysis_cost_ms(rate_hz: float, chirp: bool) -> tuple[float, float]:
    """(full, light) mean thread CPU ms per 1 ms block of ``RfiMonitor.process`` in this process, fed as the node
    feeds it (rfi_monitor_real_jammers.NodeLikeMonitor, shipped settings), at ``rate_hz`` complex: noise, or the
    chirp from the first block. No transport, no rclpy: what the analysis alone costs a node."""
    from rfi_monitor_real_jammers import NodeLikeMonitor
    band = Band("x", 0.0, 0.0 if chirp else None)
    n = int(round(rate_hz * BLOCK_S))
    out = []
    for light in (False, True):
        sim, mon = band_simulator(band, rate_hz, 1.0, seed=NOISE_SEED), NodeLikeMonitor(None)
        cpu = []
        for k in range(ANALYSIS_BLOCKS):
            blk = sim.generate(n)
            t0 = time.thread_time()
            mon.process(blk.counts, float(blk.scale), rate_hz, 0.0, True, 8, k * n, 10**9 + k * 10**6,
                        light=light and k >= ANALYSIS_SKIP)
            cpu.append(time.thread_time() - t0)
        out.append(float(np.mean(cpu[ANALYSIS_SKIP:])) * 1e3)
    return out[0], out[1]


# --------------------------------------------------------------------------------------------------- transport
def count_subscriber(namespace: str, blocks: int, timeout_s: float) -> None:
    """The counting subscriber (its own process, ``--count-subscriber``): raw blocks of /<ns>/rfi/if_samples counted,
    their stamps peeked; one JSON line on stdout at the end: received, bytes, first / last arrival (wall time),
    its own CPU seconds between them, the latencies (arrival minus the end of the block's samples, ms)."""
    import rclpy

    from rfi_msgs.msg import IfSamples
    from rfi_node_common.qos import DATA_QOS
    from rfi_node_common.stamps import peek_header_stamp_ns
    rclpy.init()
    node = rclpy.create_node("wide_transport_counter")
    got: dict = {"received": 0, "bytes": 0, "first": None, "last": None, "cpu0": 0.0, "cpu1": 0.0, "lat": []}

    def on_raw(raw: bytes) -> None:
        now = time.time()
        if got["first"] is None:
            got["first"], got["cpu0"] = now, time.process_time()
        got["received"] += 1
        got["bytes"] += len(raw)
        got["last"], got["cpu1"] = now, time.process_time()
        stamp = peek_header_stamp_ns(raw)
        if stamp is not None:
            got["lat"].append((now - stamp / 1e9 - BLOCK_S) * 1e3)

    node.create_subscription(IfSamples, f"/{namespace}/rfi/if_samples", on_raw, DATA_QOS, raw=True)
    end = time.time() + timeout_s
    while time.time() < end and got["received"] < blocks:
        rclpy.spin_once(node, timeout_sec=0.1)
        if got["last"] is not None and time.time() - got["last"] > 3.0:
            break
    node.destroy_node()
    rclpy.try_shutdown()
    print(json.dumps({"received": got["received"], "bytes": got["bytes"], "first": got["first"], "last": got["last"],
                      "cpu_s": got["cpu1"] - got["cpu0"], "latency_ms": latency_stats_ms(got["lat"])}), flush=True)


@dataclass
class TransportResult:
    rate_hz: float
    blocks: int
    received: int
    carried_hz: float
    source_cpu_per_s: float
    subscriber_cpu_per_s: float
    latency_ms: tuple[float, float, float]
    machine_cores_busy: float
    """Cores the whole machine kept busy over the stream (all processes, the other workers' too), of 2."""


def run_transport(rate_hz: float, seconds: float, tmp: Path) -> TransportResult:
    """One if_source into the counting subscriber at ``rate_hz`` complex."""
    time.sleep(PAUSE_S)
    data = tmp / f"transport_{rate_hz / 1e6:g}.i8"
    blocks = write_noise(data, rate_hz, seconds)
    counter = subprocess.Popen([sys.executable, __file__, "--count-subscriber", "wide_transport", "--blocks",
                                str(blocks)], stdout=subprocess.PIPE, stderr=open(tmp / "counter.log", "w"), text=True)
    source = ros2_run("rfi_experiments", "if_source", source_args(data, rate_hz, "wide_transport", 1575.42e6),
                      tmp / "transport_source.log")
    sampler = CpuSampler({"source": source.pid})
    out, _ = counter.communicate(timeout=180)
    sampler.stop()
    stop(source)
    data.unlink()
    r = json.loads(out.strip().splitlines()[-1])
    span = (r["last"] - r["first"] + BLOCK_S) if r["first"] is not None else math.nan
    stream_s = blocks * BLOCK_S
    samples = r["received"] * int(round(rate_hz * BLOCK_S))
    t0 = (r["first"] or 0.0) - BLOCK_S
    return TransportResult(rate_hz, blocks, r["received"], samples / span,
                           cpu_between(sampler.samples["source"], t0, t0 + span) / stream_s,
                           r["cpu_s"] / stream_s, tuple(r["latency_ms"]),
                           cpu_between(sampler.samples[MACHINE], t0, t0 + span) / span)


# ----------------------------------------------------------------------------------------------------- 3 bands
@dataclass
class BandRun:
    """One run of the three bands at one rate."""

    rate_hz: float
    results: list[BandResult]
    machine_cores_busy: float
    """Cores the whole machine kept busy over the stream (all processes, the other workers' too), of 2."""
    probe_cpu_per_s: float
    """This process's CPU seconds per stream second (the probe: answers and reports received)."""


def run_bands(rate_hz: float, seconds: float, tmp: Path) -> BandRun:
    """The three bands at ``rate_hz`` each: three if_sources, three monitors, this process as the probe."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.experimental import EventsExecutor

    from rfi_msgs.msg import JammerState
    from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
    time.sleep(PAUSE_S)
    files = {b.name: tmp / f"band_{b.name}_{rate_hz / 1e6:g}.i8" for b in BANDS}
    blocks = {b.name: write_band(files[b.name], b, rate_hz, seconds, seed=NOISE_SEED + i) for i, b in enumerate(BANDS)}
    monitors = {b.name: ros2_run("rfi_monitor", "rfi_monitor_node", ["-r", f"__ns:=/wide_{b.name}", "-p",
                                 f"hardware_id:=wide_{b.name}", *NODE_ARGS], tmp / f"monitor_{b.name}.log")
                for b in BANDS}
    rclpy.init()
    node = rclpy.create_node("wide_front_end_probe")
    arrivals: dict[str, list[tuple[float, int, int]]] = {b.name: [] for b in BANDS}
    diags: dict[str, list[tuple[int, dict[str, str]]]] = {b.name: [] for b in BANDS}

    def on_state(name: str):
        def cb(m: JammerState) -> None:
            arrivals[name].append((time.time(), m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, m.type))
        return cb

    def on_diag(m: DiagnosticArray) -> None:
        for st in m.status:
            if st.name == "rfi_monitor" and st.hardware_id.startswith("wide_"):
                diags[st.hardware_id[5:]].append((int(st.level[0]) if isinstance(st.level, bytes) else int(st.level),
                                                  {kv.key: kv.value for kv in st.values}))

    for b in BANDS:
        node.create_subscription(JammerState, f"/wide_{b.name}/rfi/jammer_state", on_state(b.name), DATA_QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DIAGNOSTICS_QOS)
    ex = EventsExecutor()   # the probe's own cost per message kept low: it shares the cores with what it measures
    ex.add_node(node)
    sources = {b.name: ros2_run("rfi_experiments", "if_source", source_args(files[b.name], rate_hz, f"wide_{b.name}",
                                                                           b.center_frequency_hz),
                                tmp / f"source_{b.name}.log") for b in BANDS}
    pids = {f"node_{k}": p.pid for k, p in monitors.items()} | {f"source_{k}": p.pid for k, p in sources.items()}
    sampler = CpuSampler(pids | {"probe": os.getpid()}, period_s=0.05)
    deadline = time.time() + 240
    while any(s.poll() is None for s in sources.values()) and time.time() < deadline:
        ex.spin_once(timeout_sec=0.05)
    settle = time.time() + SETTLE_TIMEOUT_S

    def settled(name: str) -> bool:   # the STALE report (level 3) after the stream holds the whole count
        return any(level == 3 and int(d.get("blocks_received", 0)) > 0 for level, d in diags[name][-3:])
    while time.time() < settle and not all(settled(b.name) for b in BANDS):
        ex.spin_once(timeout_sec=0.05)
    sampler.stop()
    for p in monitors.values():
        stop(p)
    for p in sources.values():
        stop(p)
    node.destroy_node()
    rclpy.shutdown()
    for f in files.values():
        f.unlink()
    results = [band_summary(b, blocks[b.name], seconds, arrivals[b.name], diags[b.name], sampler.samples)
               for b in BANDS]
    stamps = [s for a in arrivals.values() for _, s, _ in a]
    t0 = min(stamps) / 1e9 if stamps else math.nan
    t1 = max([t0 + seconds] + [t for a in arrivals.values() for t, _, _ in a])
    return BandRun(rate_hz, results, cpu_between(sampler.samples[MACHINE], t0, t1) / (t1 - t0),
                   cpu_between(sampler.samples["probe"], t0, t1) / seconds)


def band_summary(band: Band, blocks: int, seconds: float, arrivals: list[tuple[float, int, int]],
                 diags: list[tuple[int, dict[str, str]]], samples: dict[str, list[tuple[float, float]]]) -> BandResult:
    """One band's BandResult: the node's last report, the answers received here, the CPU over the stream (from the
    first block's stamp to the last answer's arrival or the last block's end, whichever is later)."""
    last = max((d for _, d in diags), key=lambda d: int(d.get("blocks_received", 0)), default={})
    r = band_result(band.name, blocks, last)
    r.latencies_ms = [(t - s / 1e9 - BLOCK_S) * 1e3 for t, s, _ in arrivals]
    if arrivals:
        t0 = min(s for _, s, _ in arrivals) / 1e9
        t1 = max(max(t for t, _, _ in arrivals), t0 + seconds)
        r.node_cpu_per_s = cpu_between(samples[f"node_{band.name}"], t0, t1) / seconds
        r.source_cpu_per_s = cpu_between(samples[f"source_{band.name}"], t0, t1) / seconds
        if band.chirp_on_fraction is not None:
            on_ns = int(round((band.chirp_on_fraction * seconds + 0.01) * 1e9)) + min(s for _, s, _ in arrivals)
            phase = [ty for _, s, ty in arrivals if s >= on_ns]
            r.chirp_blocks_answered, r.chirp_answers = len(phase), phase.count(2)
    return r


# ------------------------------------------------------------------------------------------------------- report
def fmt_rate(hz: float) -> str:
    return f"{hz / 1e6:g} MS/s"


def transport_table(rows: Sequence[TransportResult]) -> str:
    head = ("| complex 8-bit stream | blocks published | received | lost | carried MS/s (ratio) | source CPU s per "
            "stream s (share of a core while streaming) | counter CPU s per stream s | "
            "latency median / 95 % / max, ms | machine cores busy |\n|---|---|---|---|---|---|---|---|---|")
    lines = [f"| {fmt_rate(r.rate_hz)} ({2 * r.rate_hz / 1e6:g} MB/s) | {r.blocks} | {r.received} | "
             f"{r.blocks - r.received} | {r.carried_hz / 1e6:.1f} ({r.carried_hz / r.rate_hz:.2f}) | "
             f"{r.source_cpu_per_s:.2f} ({r.source_cpu_per_s * r.carried_hz / r.rate_hz:.2f}) | "
             f"{r.subscriber_cpu_per_s:.2f} | " + " / ".join(f"{v:.1f}" for v in r.latency_ms)
             + f" | {r.machine_cores_busy:.2f} |" for r in rows]
    return "\n".join([head, *lines])


def bands_table(rows: Sequence[tuple[float, Sequence[BandResult]]]) -> str:
    head = ("| rate per band | band | blocks | received | fully analysed | light | shed | lost | rejected | "
            "latency median / 95 % / max, ms | node CPU s per stream s | its source's | chirp-phase answers CHIRP | "
            "in full, < 100 ms |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    lines = []
    for rate, results in rows:
        for r in results:
            chirp = f"{r.chirp_answers} of {r.chirp_blocks_answered}" if r.band != "l2" else "(clean)"
            lines.append(f"| {fmt_rate(rate)} | {r.band.upper()} | {r.blocks} | {r.received} | {r.full} | {r.light} | "
                         f"{r.shed} | {r.lost} | {r.rejected} | " + " / ".join(f"{v:.1f}" for v in r.latency_ms)
                         + f" | {r.node_cpu_per_s:.2f} | {r.source_cpu_per_s:.2f} | {chirp} | "
                         f"{'yes' if r.in_full_on_time() else 'no'} |")
    return "\n".join([head, *lines])


def analysis_table(costs: dict[float, tuple[tuple[float, float], tuple[float, float]]],
                   transport: Sequence[TransportResult]) -> str:
    """The analysis alone per rate, and what three bands need on idle cores: 3 x (the full analysis of a block, the
    dearer of noise and chirp, per 1 ms) + 3 x (source + a Python subscriber) of the transport, interpolated in rate
    between the measured transport rates."""
    head = ("| rate per band | full analysis ms per 1 ms block: noise / chirp | light: noise / chirp | three bands' "
            "full analysis alone, cores | + three transports (source + subscriber, median, interpolated), cores | "
            "fits 2 cores |\n|---|---|---|---|---|---|")
    by_rate: dict[float, list[float]] = {}
    for t in transport:
        by_rate.setdefault(t.rate_hz, []).append(t.source_cpu_per_s + t.subscriber_cpu_per_s)
    rates = sorted(by_rate)
    per_transport = [float(np.median(by_rate[r])) for r in rates]
    lines = []
    for rate, ((full_q, light_q), (full_c, light_c)) in sorted(costs.items()):
        analysis = 3 * max(full_q, full_c) / (BLOCK_S * 1e3)
        moving = 3 * float(np.interp(rate, rates, per_transport)) if rates else math.nan
        lines.append(f"| {fmt_rate(rate)} | {full_q:.2f} / {full_c:.2f} | {light_q:.2f} / {light_c:.2f} | "
                     f"{analysis:.2f} | {analysis + moving:.2f} | {'yes' if analysis + moving < 2.0 else 'no'} |")
    return "\n".join([head, *lines])


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def extrapolated_full_ms(costs: dict[float, tuple[tuple[float, float], tuple[float, float]]],
                         rate_hz: float) -> float:
    """The full analysis of a 1 ms block at ``rate_hz``, ms of CPU, on the straight line (fixed cost + cost per MS/s)
    through the dearer case (noise or chirp) at the lowest and the highest measured rates; NaN with fewer than two."""
    if len(costs) < 2:
        return math.nan
    lo, hi = min(costs), max(costs)
    y0, y1 = max(costs[lo][0][0], costs[lo][1][0]), max(costs[hi][0][0], costs[hi][1][0])
    return y0 + (y1 - y0) * (rate_hz - lo) / (hi - lo)


def findings(transport: Sequence[TransportResult], runs: Sequence[BandRun], costs: dict) -> str:
    """The page's conclusions, from the numbers: which goal is met and which is not."""
    out = []
    for t in transport:
        kept = t.received == t.blocks and t.carried_hz >= 0.98 * t.rate_hz
        cost = t.source_cpu_per_s + t.subscriber_cpu_per_s
        out.append(f"- Transport alone at {fmt_rate(t.rate_hz)}: {'carried' if kept else '**fell behind**'} "
                   f"({t.carried_hz / 1e6:.1f} MS/s, {t.received} of {t.blocks} blocks, latency max "
                   f"{t.latency_ms[2]:.0f} ms); it cost the source {t.source_cpu_per_s:.2f} and the counter "
                   f"{t.subscriber_cpu_per_s:.2f} CPU s per stream s ({cost:.2f} of the 2 cores), while the whole "
                   f"machine was {t.machine_cores_busy:.2f} of 2 cores busy.")
    best = highest_rate_in_full([(r.rate_hz, r.results) for r in runs])
    if best is None:
        out.append("- Three bands: **at no rate of the ladder** did every node analyse every block in full with every "
                   "answer under 100 ms.")
    else:
        out.append(f"- Three bands: the highest rate per band at which every node analysed every block in full, every "
                   f"answer under 100 ms behind: **{fmt_rate(best)}** (3 x {best / 1e6:g} = {3 * best / 1e6:g} MS/s "
                   "in all).")
    goal_met = best is not None and best >= 20e6
    out.append(f"- Issue 26 item 4's goal, 3 bands at 20-40 MS/s each (or 81 MS/s) answered in full: "
               f"{'met' if goal_met else '**not met**'}.")
    for r in runs:
        node = sum(b.node_cpu_per_s for b in r.results)
        src = sum(b.source_cpu_per_s for b in r.results)
        full = sum(b.full for b in r.results)
        blocks = sum(b.blocks for b in r.results)
        ours = node + src + r.probe_cpu_per_s
        out.append(f"- {fmt_rate(r.rate_hz)} per band: {full} of {blocks} blocks in full; CPU s per stream s: the "
                   f"three nodes {node:.2f}, the three sources {src:.2f}, the probe {r.probe_cpu_per_s:.2f} (together "
                   f"{ours:.2f} of 2 cores); the whole machine {r.machine_cores_busy:.2f} of 2 cores busy over the "
                   "stream, the other workers included.")
    for rate, ((full_q, _), (full_c, _)) in sorted(costs.items()):
        need = 3 * max(full_q, full_c) / (BLOCK_S * 1e3)
        out.append(f"- The analysis alone (c), {fmt_rate(rate)} per band: {max(full_q, full_c):.2f} ms of CPU per 1 ms "
                   f"block, so three bands need {need:.2f} cores for it "
                   f"({'within' if need < 2 else '**more than**'} the 2 cores, before any transport).")
    x81 = extrapolated_full_ms(costs, 81e6)
    if math.isfinite(x81):
        t81 = [t for t in transport if t.rate_hz == 81e6]
        ok81 = sum(t.received == t.blocks and t.carried_hz >= 0.98 * 81e6 for t in t81)
        out.append(f"- One node for the whole 81 MS/s stream: on the line through (c)'s lowest and highest rates, "
                   f"about {x81:.1f} ms of CPU per 1 ms block on the node's one analysis thread ({x81:.1f} cores' "
                   f"worth on one thread): not possible with this analysis. The transport alone carried 81 MS/s in "
                   f"{ok81} of {len(t81)} runs (a), at about "
                   f"{np.median([t.source_cpu_per_s + t.subscriber_cpu_per_s for t in t81]) if t81 else math.nan:.2f} "
                   f"of the 2 cores, where the full analysis alone of three bands at {fmt_rate(min(costs))} needs "
                   f"{3 * max(costs[min(costs)][0][0], costs[min(costs)][1][0]) / (BLOCK_S * 1e3):.2f} (c).")
    return "\n".join(out)


def write_doc(transport: Sequence[TransportResult], runs: Sequence[BandRun], costs: dict, seconds: float,
              loads: tuple[float, float], elapsed_s: float) -> None:
    OUT.write_text(
        "# Wider front ends with both cores (issue 26 item 4)\n\n"
        "From `benchmarks/rfi_monitor_wide_front_end.py` (its docstring says how). Every process is its own: "
        "if_source (pace real_time, reliable, 1 ms blocks, 8-bit complex), the counting subscriber or "
        "rfi_monitor_node (shipped parameters, one per band in its own namespace), and the probe that receives "
        f"the answers. Streams of {seconds:g} s. CPU: {cpu_model()}, 2 cores shared with the other workers of "
        f"this machine: 1-minute load average {loads[0]:.2f} at the start and {loads[1]:.2f} at the end; "
        f"the run took {elapsed_s / 60:.1f} min. CPU per stream second is from /proc over the stream (a core = 1.00); "
        "\"machine\" counts every process on the machine, ours and the other workers'.\n\n"
        "## What was found\n\n" + findings(transport, runs, costs) + "\n\n"
        "## (a) The transport alone: if_source into a subscriber that only counts\n\n"
        + transport_table(transport) + "\n\n"
        "## (b) Three bands (L1, L2, L5), one if_source and one rfi_monitor_node each\n\n"
        "L1: the chirp (J/N 10 dB, 75 % of the band in 20 us) on after 25 % of the stream; L2 clean; L5 the chirp "
        "after 50 %. Fully analysed = published and not light; latency = arrival at the probe minus the end of the "
        "block's samples (an upper bound: the probe's own lag is in it).\n\n"
        + bands_table([(r.rate_hz, r.results) for r in runs]) + "\n\n"
        "## (c) The analysis alone, in process, and what three bands would need on two idle cores\n\n"
        f"``RfiMonitor.process`` fed as the node feeds it, shipped settings, {ANALYSIS_BLOCKS} blocks of 1 ms per case "
        f"(the first {ANALYSIS_SKIP} not counted), thread CPU time, mean; noise, or the chirp of (b) from the first "
        "block; light = the light analysis after the full one of the first blocks (a block that disagrees with the "
        "last full analysis is escalated to the full one, as in the node). A node's own receiving adds about what "
        "the counting subscriber of (a) costs.\n\n"
        + analysis_table(costs, transport) + "\n\n" + NOTES)


OUT = ROOT / "docs" / "rfi_monitor" / "wide_front_end.md"
NOTES = """## Why one node per band

The full analysis of a block runs on one thread of one node (``RfiMonitor.process``); ``analysis_worker`` moves only
the ridge analysis into a child process, and on this 2-vCPU machine that made the node slower (live_stream.md).
An 81 MS/s stream in one node would need (c)'s cost on one thread, several cores' worth (the findings above). One
node per band needs no change to the node: each band is its own stream with its own centre frequency, the nodes are
separate processes that the kernel spreads over both cores, and each answers for its band on
``/<ns>/rfi/jammer_state``. It is both the simpler and the faster way; it cannot make the analysis itself cheaper,
and (c) shows that the analysis, not the transport, is what does not fit.

## Reading it

- CPU per stream second is the cost: CPU seconds spent on the stream over its length, whatever the wall time it
  took; "share of a core while streaming" is what the process got. The other workers of this shared machine kept it
  busy during every run (the machine column), so a process got less than a core when it needed one, and a node that
  fell behind took the light analysis or shed (its safety net, counted), which changes its cost.
- In (b), a node behind its stream answers late: the age limit (``max_block_age_s``, 50 ms) compares a block's stamp
  with its *reception* by the middleware (``load_policy``), so a block that arrived on time and then waited in the
  node's own input queue (depth 1000, one second of blocks) is not shed by age; it gets the light analysis (queued
  over 10 ms) and its answer comes as late as the queue is long. Blocks beyond the queue are lost before the node
  (counted by its input). What the node would need to keep its answers under 100 ms when it falls behind: the age
  judged against the time the block is handled (reception plus time queued), not only the reception.
- The probe runs rclpy's EventsExecutor (its own cost per answer low); the counting subscriber of (a) and the nodes
  run the default SingleThreadedExecutor, as a Python node does.
- (c)'s "fits 2 cores" adds what (a) measured for the transport to three bands' full analysis; it leaves out the
  node's own receiving and the probe, so it is the most favourable case.

## Running N bands

``ros2 launch rfi_experiments bands.launch.xml`` starts one monitor per band in namespaces l1, l2, l5 (and, with
``with_if_source:=true``, one if_source each with its own parameters file). By hand, each band: one source and one
monitor in the band's namespace (topics relative, so ``-r __ns:=/l1`` moves ``rfi/if_samples`` and
``rfi/jammer_state``; /diagnostics stays global, told apart by ``hardware_id``):

    ros2 run rfi_monitor rfi_monitor_node --ros-args -r __ns:=/l1 -p hardware_id:=l1
    ros2 run rfi_experiments if_source --ros-args -r __ns:=/l1 -p input:=l1.i8 -p item_type:=ibyte \\
        -p sampling_frequency_hz:=2500000.0 -p center_frequency_hz:=1575420000.0 -p wait_for_subscribers:=1

and the same with ``l2`` (1227.60 MHz) and ``l5`` (1176.45 MHz).
"""


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Writes docs/rfi_monitor/wide_front_end.md. Use ROS_DOMAIN_ID and "
                                 "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST to keep off other users' graphs.")
    ap.add_argument("--quick", action="store_true", help=f"{fmt_rate(QUICK_TRANSPORT_RATES_HZ[0])} transport only, "
                    "the ladder " + ", ".join(fmt_rate(r) for r in QUICK_BAND_RATES_HZ) + ", 1 s streams")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each rate of the three-band ladder (default 1)")
    ap.add_argument("--transport-repeat", type=int, default=2,
                    help="runs of each transport rate, alternated (default 2; --quick 1)")
    ap.add_argument("--seconds", type=float, default=None, help=f"stream length, s (default {STREAM_S:g}; --quick 1)")
    ap.add_argument("--count-subscriber", metavar="NS", help=argparse.SUPPRESS)
    ap.add_argument("--blocks", type=int, default=0, help=argparse.SUPPRESS)
    add_quiet_argument(ap)
    args = ap.parse_args(argv)
    if args.count_subscriber:
        count_subscriber(args.count_subscriber, args.blocks, timeout_s=180.0)
        return 0
    seconds = args.seconds or (1.0 if args.quick else STREAM_S)
    t_rates = [r for _ in range(1 if args.quick else max(1, args.transport_repeat))
               for r in (QUICK_TRANSPORT_RATES_HZ if args.quick else TRANSPORT_RATES_HZ)]
    b_rates = [r for _ in range(max(1, args.repeat)) for r in (QUICK_BAND_RATES_HZ if args.quick else BAND_RATES_HZ)]
    log = case_log(__file__, total=len(t_rates) + len(b_rates) + len(set(b_rates)), quiet=args.quiet)
    load0 = os.getloadavg()[0]
    tmp = Path(tempfile.mkdtemp(prefix="rfi_wide_"))
    subprocess.run([sys.executable, "-c", WARM_UP], check=True, timeout=1800)
    transport = [run_transport(r, seconds, tmp) for r in log.cases_of(t_rates, lambda r: f"transport {fmt_rate(r)}")]
    runs = [run_bands(r, seconds, tmp) for r in log.cases_of(b_rates, lambda r: f"3 bands at {fmt_rate(r)}")]
    costs = {r: (analysis_cost_ms(r, chirp=False), analysis_cost_ms(r, chirp=True))
             for r in log.cases_of(sorted(set(b_rates)), lambda r: f"analysis alone at {fmt_rate(r)}")}
    log.say(transport_table(transport) + "\n\n" + bands_table([(r.rate_hz, r.results) for r in runs]) + "\n\n"
            + analysis_table(costs, transport))
    write_doc(transport, runs, costs, seconds, (load0, os.getloadavg()[0]), log.elapsed_s)
    log.finish(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

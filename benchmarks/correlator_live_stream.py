"""Issue 29's "the node keeps up with item 3's streams over DDS at 1x, every block answered", measured as a user
would run it: gnss_correlator_node as its own process with its shipped parameters, fed at 1x by rfi_experiments'
if_source (pace real_time, reliable, the stamps from the ROS clock at the stream's start) with a continuous
simulated IF stream of item 3's two kinds: 12 GPS L1 C/A satellites at 4 MS/s complex, and 8 at 16.368 MS/s real
(IF 4.092 MHz), 2-bit samples (rfi_sim, seeded; C/N0 46 dB-Hz each).

Measures, from the node's own /diagnostics (its last report, the STALE one it sends when the stream has been silent
for input_timeout_s, counts the whole stream): blocks received, processed, rejected and lost before the node
(``input./rfi/if_samples.lost``, from the publisher's sequence numbers), the channels tracked; from its
/gnss/correlators (stamps read from the serialised header, no full decoding here): the arrays received against the
stream's 1-ms intervals, and their latency (wall time of arrival minus the stamp, the interval's end: if_source
stamps the first sample with the ROS clock when the stream starts and publishes a block when its last sample would
have arrived live, so this includes up to one block of waiting, and this probe's own lag); the node's CPU time over
the stream (/proc/<pid>/stat, all its threads, the start-up before the stream excluded) apart from the publisher's.
Writes docs/gnss_correlator/live_stream.md. Run (workspace sourced):

    ROS_DOMAIN_ID=46 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python benchmarks/correlator_live_stream.py
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shlex
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from bench_progress import add_quiet_argument, case_log
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rfi_experiments.child_processes import stop_processes
from rfi_msgs.msg import CorrelatorArray
from rfi_node_common.qos import DIAGNOSTICS_QOS
from rfi_sim.if_signal import FrontEndConfig, GpsSatellite, IfSimulator

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "gnss_correlator" / "live_stream.md"
POWER_DBM = -128.0
"""Each satellite's power: C/N0 46 dB-Hz over the front end's -114 dBm/MHz (174 - 128)."""
FINAL_REPORT_WAIT_S = 120.0
"""Longest wait for the node's report of the whole stream after the source ends, s."""
PAUSE_S = 2.0
PROBE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=20_000, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
"""This probe's subscription to the arrays: DATA_QOS with a queue of 20 s of arrays, so that the arrays the node
publishes while it catches up are not lost in this (Python) probe's queue."""
"""Pause before each run, s: the previous run's processes end."""
CLK_TCK = os.sysconf("SC_CLK_TCK")
CHILDREN: list[subprocess.Popen] = []
"""The node and source processes started: any still running when the benchmark ends (an interruption, an error)
are stopped, not left publishing into the next run or the next user of the ROS domain."""


def stop_children() -> None:
    """SIGINT to every child still running, then SIGKILL after 10 s."""
    stop_processes(CHILDREN)


@dataclass(frozen=True)
class Case:
    label: str
    channels: int
    fs_hz: float
    if_hz: float
    is_complex: bool
    item_type: str
    block_s: float


CASES = (
    Case("12 ch, 4 MS/s complex, 1-ms blocks", 12, 4.0e6, 0.0, True, "ibyte", 0.001),
    Case("8 ch, 16.368 MS/s real, IF 4.092 MHz, 1-ms blocks", 8, 16.368e6, 4.092e6, False, "byte", 0.001),
    Case("12 ch, 4 MS/s complex, 10-ms blocks", 12, 4.0e6, 0.0, True, "ibyte", 0.01),
    Case("8 ch, 16.368 MS/s real, IF 4.092 MHz, 10-ms blocks", 8, 16.368e6, 4.092e6, False, "byte", 0.01),
)
"""Item 3's two streams in if_source's default 1-ms blocks (the monitor's), and in 10-ms blocks: the same samples
(one file per stream), a tenth of the messages, and the 1000-message queues (DATA_QOS) then hold 10 s of stream
instead of 1 s while the first acquisition runs in the node's callback."""


def write_stream(case: Case, seconds: float, path: Path, seed: int = 1) -> int:
    """The int8 file of ``case`` (2-bit values), ``seconds`` long; returns its number of samples."""
    sats = tuple(GpsSatellite(prn=k + 1, doppler_hz=-4000.0 + 8000.0 * k / max(case.channels - 1, 1),
                              code_phase_chips=(97.3 * k) % 1023, carrier_phase_rad=0.7 * k, power_dbm=POWER_DBM)
                 for k in range(case.channels))
    fe = FrontEndConfig(sample_rate_hz=case.fs_hz, intermediate_frequency_hz=case.if_hz,
                        is_complex=case.is_complex, bits=2)
    sim = IfSimulator(fe, satellites=sats, seed=seed)
    n = int(round(seconds / case.block_s)) * int(round(case.fs_hz * case.block_s))
    chunk = int(case.fs_hz * 0.1)
    with open(path, "wb") as fh:
        for start in range(0, n, chunk):
            sim.generate(min(chunk, n - start)).counts.astype(np.int8).tofile(fh)
    return n


def cpu_s(pid: int) -> float:
    """User + system CPU time of a process and all its threads so far, s (nan once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def thread_cpu_s(pid: int) -> Counter[str]:
    """User + system CPU time of each thread of a process so far, summed by thread name with its digits dropped
    (``dds.rx.7411`` -> ``dds.rx.``; ``main``: the executor's; the kernel keeps 15 characters of a name:
    ``gnss_correlator``, the acquisition worker), s."""
    out: Counter[str] = Counter()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue
        name = "main" if task.name == str(pid) else stat[stat.index("(") + 1:stat.rindex(")")]
        fields = stat.rsplit(")", 1)[1].split()
        out[name.rstrip("0123456789") or name] += (int(fields[11]) + int(fields[12])) / CLK_TCK
    return out


def stamp_of(raw: bytes) -> int:
    """header.stamp of a serialised message (CDR: 4 bytes of encapsulation, then int32 sec, uint32 nanosec), ns."""
    little = raw[1] == 1
    sec, nsec = struct.unpack("<iI" if little else ">iI", raw[4:12])
    return sec * 1_000_000_000 + nsec


def status_values(status: DiagnosticStatus) -> dict[str, str]:
    """A gnss_correlator status as this probe keeps it: its values by key, and ``level`` as a decimal number
    (rclpy gives the ``byte`` field as a bytes object: ``str(status.level)`` is ``"b'\\x03'"``, never ``"3"``, which
    made every run wait out the 120-s bound for the node's final report)."""
    level = status.level
    number = int.from_bytes(level, "little") if isinstance(level, bytes) else int(level)
    return {kv.key: kv.value for kv in status.values} | {"level": str(number)}


STALE_LEVEL = str(int.from_bytes(DiagnosticStatus.STALE, "little"))


def stream_reported(last: dict[str, str], blocks: int) -> bool:
    """Whether ``last`` (:func:`status_values`) is the node's report of the whole stream: STALE (the input silent for
    input_timeout_s), every block received or counted lost, none held for a first acquisition still running."""
    return (last.get("level") == STALE_LEVEL
            and int(last.get("blocks_received", 0)) + int(last.get("input./rfi/if_samples.lost", 0)) >= blocks
            and last.get("blocks_held_for_acquisition", "0") == "0")


def run_once(case: Case, data: Path, n: int, tmp: Path, node_params: tuple[str, ...] = ()) -> dict[str, object]:
    """One run of the stream through a fresh node (its shipped parameters, then ``node_params``: ``name:=value``
    each); the row's values."""
    time.sleep(PAUSE_S)
    ros2_run = str(ROOT / "tools" / "ros2_run")
    load_start = os.getloadavg()[0]
    node_proc = subprocess.Popen([ros2_run, "gnss_correlator", "gnss_correlator_node", "--ros-args",
                                  "-p", "diagnostics_period_s:=0.5", "-p", "input_timeout_s:=1.0",
                                  *[a for v in node_params for a in ("-p", v)]],
                                 stdout=subprocess.DEVNULL, stderr=open(tmp / "node.log", "w"))
    CHILDREN.append(node_proc)
    rclpy.init()
    probe = rclpy.create_node("correlator_live_probe")
    arrivals: list[tuple[float, int]] = []
    diags: list[dict[str, str]] = []

    cpu_first: list[float] = []  # the node's CPU time when its first array arrived here

    def on_array(raw: bytes) -> None:
        if not arrivals:
            cpu_first.append(cpu_s(node_proc.pid))
        arrivals.append((time.time(), stamp_of(raw)))

    def on_diag(m: DiagnosticArray) -> None:
        for st in m.status:
            if st.name == "gnss_correlator":
                diags.append(status_values(st))

    probe.create_subscription(CorrelatorArray, "/gnss/correlators", on_array, PROBE_QOS, raw=True)
    probe.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DIAGNOSTICS_QOS)
    ex = SingleThreadedExecutor()
    ex.add_node(probe)
    # the node is up (its subscription in the graph) before the stream starts: its start-up CPU is not counted
    deadline = time.time() + 120
    while time.time() < deadline and not [i for i in probe.get_subscriptions_info_by_topic("/rfi/if_samples")
                                          if i.node_name == "gnss_correlator"]:
        ex.spin_once(timeout_sec=0.1)
    for _ in range(10):
        ex.spin_once(timeout_sec=0.1)
    node_cpu0 = cpu_s(node_proc.pid)
    threads0 = thread_cpu_s(node_proc.pid)
    source = subprocess.Popen([ros2_run, "rfi_experiments", "if_source", "--ros-args",
                               "-p", f"input:={data}", "-p", f"item_type:={case.item_type}",
                               "-p", f"sampling_frequency_hz:={case.fs_hz}",
                               "-p", f"intermediate_frequency_hz:={case.if_hz}",
                               "-p", "bits_per_sample:=2", "-p", f"block_duration_s:={case.block_s}",
                               "-p", "pace:=real_time", "-p", "wait_for_subscribers:=1",
                               "-p", "wait_timeout_s:=60.0"],
                              stdout=subprocess.DEVNULL, stderr=open(tmp / "source.log", "w"))
    CHILDREN.append(source)
    source_cpu = 0.0
    stream_s = n / case.fs_hz
    deadline = time.time() + stream_s + 180
    while source.poll() is None and time.time() < deadline:
        ex.spin_once(timeout_sec=0.05)
        c = cpu_s(source.pid)
        source_cpu = c if math.isfinite(c) else source_cpu
    blocks = n // int(round(case.fs_hz * case.block_s))
    # the node's last report: STALE after input_timeout_s of silence, once it has taken every block
    end = time.time() + FINAL_REPORT_WAIT_S
    reported = False
    while time.time() < end:
        ex.spin_once(timeout_sec=0.05)
        last = diags[-1] if diags else {}
        if stream_reported(last, blocks) and (not arrivals or time.time() - arrivals[-1][0] > 1.0):
            reported = True
            break
    node_cpu1 = cpu_s(node_proc.pid)
    threads = thread_cpu_s(node_proc.pid)
    threads.subtract(threads0)
    load_end = os.getloadavg()[0]
    node_proc.send_signal(signal.SIGINT)
    try:
        node_proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        node_proc.kill()
    if source.poll() is None:
        source.kill()
    probe.destroy_node()
    rclpy.shutdown()
    last = diags[-1] if diags else {}
    (tmp / "last_report.json").write_text(json.dumps(last, indent=1))  # the node's counters, to look into a run
    stamps = np.array([s for _, s in arrivals], dtype=np.int64)
    lat_ms = np.array([(t - s / 1e9) * 1e3 for t, s in arrivals]) if arrivals else np.array([math.nan])
    tail = lat_ms[len(lat_ms) // 2:] if len(lat_ms) > 1 else lat_ms
    first_cpu = cpu_first[0] - node_cpu0 if cpu_first else math.nan
    answered_s = (stamps.max() - stamps.min()) / 1e9 if stamps.size > 1 else math.nan
    steady = (node_cpu1 - cpu_first[0]) / answered_s if cpu_first and answered_s > 0 else math.nan
    unique = np.unique(stamps)
    steps = np.diff(unique) if unique.size > 1 else np.array([], dtype=np.int64)
    lost = last.get("input./rfi/if_samples.lost", "?")
    rejected = sum(int(v) for k, v in last.items() if k.startswith("rejected_"))
    # processed counts the blocks handed to the receiver, held ones too: the final report says none is held
    answered = (reported and last.get("blocks_processed") == str(blocks) and str(lost) == "0" and rejected == 0)
    return {
        "stream, s": f"{stream_s:g}",
        "blocks in the stream": blocks,
        "blocks received by the node": last.get("blocks_received", "?"),
        "processed": last.get("blocks_processed", "?"),
        "rejected": rejected,
        "lost before the node (input lost)": lost,
        "every block answered": "yes" if answered else "no",
        "channels tracked at the end": len(last.get("tracked_prns", "").split()),
        "blocks held during the first search (core.blocks_held) / replays at the hold's bound / waits for the search":
            f"{last.get('core.blocks_held', '?')} / {last.get('core.hold_bound_replays', '?')} / "
            f"{last.get('core.acquisition_waits', '?')}",
        "blocks the node took itself: after a block (in a row) / before a replay":
            f"{last.get('blocks_taken_in_a_row', '?')} / {last.get('blocks_taken_before_replay', '?')}",
        "arrays received here / published (arrays_published)": f"{len(arrivals)} / {last.get('arrays_published', '?')}",
        "arrays' stamps 1 ms apart, no gap": "yes" if steps.size and np.all(steps == 1_000_000) else "no",
        "latency median / 95 % / max, ms (whole stream)":
            f"{np.median(lat_ms):.0f} / {np.percentile(lat_ms, 95):.0f} / {np.max(lat_ms):.0f}",
        "latency median / 95 % / max, ms (second half)":
            f"{np.median(tail):.1f} / {np.percentile(tail, 95):.1f} / {np.max(tail):.1f}",
        "node CPU over the stream, s (ratio to stream time)":
            f"{node_cpu1 - node_cpu0:.2f} ({(node_cpu1 - node_cpu0) / stream_s:.2f})",
        "of it to the first array (first acquisition, kernel load), s": f"{first_cpu:.2f}",
        "after it, per second of stream answered (arrays' stamps)": f"{steady:.2f}",
        "executor thread CPU per second of stream (receive, check, decode, track, publish)":
            f"{threads['main'] / stream_s:.2f}",
        "node CPU by thread over the stream, s": ", ".join(
            f"{name} {v:.2f}" for name, v in threads.most_common() if v >= 0.05),
        "source (if_source) CPU, s (ratio)": f"{source_cpu:.2f} ({source_cpu / stream_s:.2f})",
        "load average at start / end": f"{load_start:.1f} / {load_end:.1f}",
        "node's report of the whole stream seen": "yes" if reported else f"no (waited {FINAL_REPORT_WAIT_S:g} s)",
        "_node_cpu_ratio": (node_cpu1 - node_cpu0) / stream_s,
        "_steady": steady,
        "_main": threads["main"] / stream_s,
        "_answered": answered,
        "_lat_tail_median": float(np.median(tail)),
        "_load": (load_start + load_end) / 2,
    }


def in_process_costs(case: Case, seconds: float = 1.5, skip_s: float = 0.5) -> dict[str, float]:
    """The node's own work per ms of stream, without the middleware: the blocks of ``case`` serialised as the
    source sends them, then as the node treats them (deserialise, check, decode, Receiver.process, build the
    CorrelatorArray, serialise it: what rclpy's publish does), gathered to batch_ms as the node does (its
    default); CPU time (this process) per ms of stream after the first ``skip_s`` (acquisition, kernel load), us
    per step. The arrays are written as the node publishes them (serialised from the interval's arrays,
    ``correlator_array_bytes``); the path it replaced (message objects built field by field, then serialised by
    rclpy) is timed beside it, outside the total (``_old``)."""
    from rclpy.serialization import deserialize_message, serialize_message

    from gnss_correlator.correlator_cdr import CorrelatorArrayWriter, correlator_array, correlator_array_bytes
    from gnss_correlator.gnss_correlator_node import block_problem
    from gnss_correlator.node_params import CorrelatorNodeParams
    from gnss_correlator.receiver import IfBlock, Receiver, ReceiverConfig
    from rfi_msgs.msg import IfSamples
    from rfi_node_common.if_blocks import decode_counts

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.i8"
        n = write_stream(case, seconds, path)
        raw = np.fromfile(path, dtype=np.int8)
    per = int(round(case.fs_hz * case.block_s))
    width = 2 if case.is_complex else 1
    messages = []
    for k in range(n // per):
        m = IfSamples()
        m.header.stamp.sec = 1_700_000_000
        m.header.stamp.nanosec = int(round(k * case.block_s * 1e9))
        m.sample_rate_hz, m.intermediate_frequency_hz, m.is_complex = case.fs_hz, case.if_hz, case.is_complex
        m.center_frequency_hz, m.first_sample_index, m.scale, m.bits_per_sample = 1575.42e6, k * per, 1.0, 2
        m.sample_format = IfSamples.INT8
        m.samples = raw[k * per * width:(k + 1) * per * width].tobytes()
        messages.append(serialize_message(m))
    # the first search in this thread (in the skipped part): held in the worker, a stream handed in faster than
    # real time would be held whole, and nothing measured
    rx = Receiver(ReceiverConfig(acquisition_hold_s=0.0))
    gather = max(1, int(round(CorrelatorNodeParams.batch_ms * 1e-3 / case.block_s)))
    writer = CorrelatorArrayWriter("gnss_receiver")
    steps = dict.fromkeys(("deserialise", "check", "decode", "receiver", "arrays as bytes (CDR codec)",
                           "_old: arrays built field by field", "_old: serialised by rclpy"), 0.0)
    pending: list[np.ndarray] = []
    for k, data in enumerate(messages):
        counted = k * case.block_s >= skip_s
        t = [time.process_time()]
        msg = deserialize_message(data, IfSamples)
        t.append(time.process_time())
        block_problem(msg, 5000.0, 40_000_000)
        t.append(time.process_time())
        c = decode_counts(msg).astype("float64") * msg.scale
        pending.append(c[0::2] + 1j * c[1::2] if msg.is_complex else c)
        t.append(time.process_time())
        arrays = []
        if len(pending) == gather:
            first = (k - gather + 1) * per
            out = rx.process(IfBlock(stamp_ns=1_700_000_000 * 10 ** 9 + int(round(first / case.fs_hz * 1e9)),
                                     sample_rate_hz=case.fs_hz, intermediate_frequency_hz=case.if_hz,
                                     is_complex=case.is_complex, first_sample_index=first,
                                     samples=np.concatenate(pending)))
            pending = []
            t.append(time.process_time())
            fast = [correlator_array_bytes(o, writer) for o in out]
            t.append(time.process_time())
            arrays = [correlator_array(o, "gnss_receiver") for o in out]
            t.append(time.process_time())
            reference = [serialize_message(a) for a in arrays]
            t.append(time.process_time())
            for a, b in zip(fast, reference, strict=True):  # the same bytes but the padding (Fast CDR's are
                x, y = np.frombuffer(a, np.uint8), np.frombuffer(b, np.uint8)  # left uninitialised, ours zero)
                if x.size != y.size or x[x != y].any():
                    raise AssertionError("the two publish paths differ")
        if counted:
            for name, t0, t1 in zip(steps, t[:-1], t[1:], strict=False):
                steps[name] += t1 - t0
    stream_ms = (n / case.fs_hz - skip_s) * 1e3
    return {name: v / stream_ms * 1e6 for name, v in steps.items()}


def write_in_process(out: Path) -> None:
    rows = [(case, in_process_costs(case)) for case in CASES]
    names = list(rows[0][1])
    table = ("| case | " + " | ".join(n.replace("_old: ", "") + (" (replaced)" if n.startswith("_") else "")
                                      for n in names)
             + " | total (the node's path), us per ms of stream |\n|---|" + "---|" * (len(names) + 1)
             + "\n" + "\n".join(f"| {c.label} | " + " | ".join(f"{v[n]:.0f}" for n in names)
                                 + f" | {sum(x for n, x in v.items() if not n.startswith('_')):.0f} |"
                                 for c, v in rows))
    out.write_text(
        "# gnss_correlator_node's own work per ms of stream, without the middleware\n\n"
        "Generated by `python benchmarks/correlator_live_stream.py --in-process`: the streams of "
        "[live_stream.md](live_stream.md) (1.5 s, the first 0.5 s left out: acquisition, kernel load), each block "
        "serialised as if_source sends it, then treated as the node does (deserialised, checked, decoded, gathered "
        "to 10 ms for Receiver.process, the CorrelatorArrays serialised from the intervals' arrays as the node "
        "publishes them; beside it, outside the total, the path this replaced: the message objects built field by "
        "field, then serialised by rclpy as its publish does, the same bytes, checked), CPU "
        f"time of one process, us per ms of stream (1000: one core). Load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} shared logical CPUs at the end.\n\n" + table + "\n\nWhat the node process spends "
        "beyond this over DDS (live_stream.md's CPU per second answered) is the middleware's: receiving the "
        "blocks, publishing the arrays.\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="stream length, s (default 5)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each case, alternated (default 3)")
    ap.add_argument("--out", type=Path, default=OUT, help=f"markdown to write (default {OUT.relative_to(ROOT)})")
    ap.add_argument("--in-process", action="store_true",
                    help="only the node's own work without the middleware, into live_stream_in_process.md")
    ap.add_argument("--cases", default=",".join(str(k) for k in range(len(CASES))),
                    help="the cases run, indices into CASES separated by commas (default all: "
                    + "; ".join(f"{k} {c.label}" for k, c in enumerate(CASES)) + ")")
    ap.add_argument("--node-param", action="append", default=[], metavar="NAME:=VALUE",
                    help="a parameter of the node beyond its shipped ones (repeatable), e.g. acquisition_hold_s:=0.0 "
                    "for the first acquisition in the callback")
    add_quiet_argument(ap)
    args = ap.parse_args()
    cases = tuple(CASES[int(k)] for k in args.cases.split(","))
    if args.in_process:
        write_in_process(OUT.with_name("live_stream_in_process.md"))
        return
    tmp = Path(tempfile.mkdtemp(prefix="corr_live_"))
    streams = []
    made: dict[tuple[int, float], tuple[Path, int]] = {}
    for case in cases:  # one file per stream, whatever the block size (a whole number of 10-ms blocks)
        key = (case.channels, case.fs_hz)
        if key not in made:
            path = tmp / f"stream{len(made)}.i8"
            made[key] = (path, write_stream(case, round(args.seconds, 2), path))
        streams.append(made[key])
    repeats = max(1, args.repeat)
    log = case_log(__file__, total=repeats * len(cases), quiet=args.quiet)
    runs: list[list[dict[str, object]]] = [[] for _ in cases]
    try:
        for _ in range(repeats):
            for i, case in enumerate(log.cases_of(cases, lambda c: c.label)):
                runs[i].append(run_once(case, *streams[i], tmp, tuple(args.node_param)))
    finally:
        stop_children()
    keys = [k for k in runs[0][0] if not k.startswith("_")]
    table = ("| quantity | " + " | ".join(c.label for c in cases) + " |\n|---|" + "---|" * len(cases) + "\n"
             + "\n".join(f"| {k} | " + " | ".join(" ; ".join(str(r[k]) for r in rs) for rs in runs) + " |"
                          for k in keys))
    medians = "\n".join(
        f"- {c.label}: node CPU / stream time median {np.median([r['_node_cpu_ratio'] for r in rs]):.2f} "
        f"(after the first array, per second answered: {np.median([r['_steady'] for r in rs]):.2f}; the executor "
        f"thread per second of stream: {np.median([r['_main'] for r in rs]):.2f}), "
        f"every block answered in {sum(bool(r['_answered']) for r in rs)} of {len(rs)} runs, latency (second "
        f"half) median of the runs' medians {np.median([r['_lat_tail_median'] for r in rs]):.1f} ms, load "
        f"average median {np.median([r['_load'] for r in rs]):.1f}"
        for c, rs in zip(cases, runs, strict=True))
    cpu = "unknown"
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    log.say(table)
    log.say(medians)
    args.out.write_text(
        "# Live stream at 1x: gnss_correlator_node as its own process over DDS (issue 29, done when)\n\n"
        f"Generated by `python benchmarks/correlator_live_stream.py {' '.join(shlex.quote(a) for a in sys.argv[1:])}`: "
        "if_source publishes a continuous simulated IF stream (rfi_sim, 2-bit, each satellite at 46 dB-Hz) at its "
        "sample rate (pace real_time, reliable, stamps from the ROS clock at the start) into the node started with "
        "its shipped parameters (32 PRNs searched, the first acquisition, of 10 ms, in its worker thread while the "
        "blocks are held), and any given with --node-param; "
        "this probe records the node's /gnss/correlators and /diagnostics. "
        f"Each case was run {repeats} times, alternated; a cell gives the runs' values separated by ' ; '.\n"
        f"CPU: {cpu} ({platform.machine()}), {os.cpu_count()} logical CPUs shared with other workers' jobs; the "
        "load average of each run is in the table (1-minute, at its start and end).\n\n"
        + table + "\n\nMedians over the runs:\n\n" + medians + "\n\n" + NOTES)
    log.finish(f"wrote {args.out}")


NOTES = """Reading it: the node's CPU time is that of its process (all threads) from the moment its subscription was in
the graph to its last report; its split by thread (/proc/<pid>/task): "main" is the executor (taking and
deserialising each block, the checks and decoding, the tracking, writing and publishing one CorrelatorArray per ms),
"gnss_correlator" the acquisition worker (Python threads keep the process's name; the first acquisition of the
stream, 32 PRNs on 10 ms), "dds.*" the middleware's own threads. The robust figure is the executor thread's CPU per
second of stream: it does not depend on when the first array arrived nor much on the load. "Every block answered":
the node's final report seen, every block received and processed (none lost before it, none rejected, none still
held for the first acquisition), and the arrays' stamps 1 ms apart without a gap from the first channel's first C/N0
to the end. The latency (arrival here minus the stamp) over the second half shows whether the node had caught up
with the stream (this Python probe's own lag included). The node's counters (its final report): blocks held during
the first search (receiver calls: 10 ms of stream each), the replays at the hold's bound (acquisition_hold_s, 4 s)
and the waits for a search still running there; the blocks the node took from its subscription itself.

**This document: the tracking kernel made 1.3-1.6 times cheaper (docs/gnss_correlator/tracking_speed.md; a rotation
table per 256-sample chunk for the carrier, one packed table entry per sample for the four code replicas). Every
block answered in 11 of 12 runs; keeping up at 1x in wall time: the 4 MS/s stream in 10-ms blocks yes, the 16.368
MS/s stream not** (load average 4.3-5.6 on 2 shared vCPUs; the previous document's runs had 8.1-9.9):

- CPU per second of stream, executor thread, against the previous document: 16.368 MS/s real 8 ch 0.57-0.59 in
  10-ms blocks (0.77-0.80 before) and 0.80-0.96 in 1-ms blocks (0.92-0.94: taking 1000 messages a second and the
  executor's turns dominate there); 4 MS/s complex 12 ch 0.49-0.54 (10-ms; 0.49-0.53) and 0.60-0.81 (1-ms;
  0.59-0.61): at 4 MS/s the tracking is a small part of the node's work, and no gain shows. The 16.368 MS/s stream
  was still 0.8-7.3 s behind over the second half (medians): its first search (1.5-1.7 s of CPU in the worker) held
  the blocks to the 4-s bound in the 1-ms runs, and a node that gets well under a core on this machine does not
  catch up from there within 5 s of stream. The 4 MS/s stream in 10-ms blocks kept up (11-15 ms behind), in 1-ms
  blocks 16 and 375 ms behind in two runs.
- The lost run: the first run of the series (4 MS/s, 1-ms blocks) lost 2,666 of 5,000 blocks before the node
  (input lost, from the publisher's sequence numbers) and spent 3.7 s of CPU to its first array against 0.8 in the
  other two: not investigated in this session (a kernel load slower than the warm cache's, then the subscription's
  queue overflowing, is the likely reading; the previous document's first run also lost 16 blocks).

From the previous document (not re-measured for this one):

- Where the 1-ms blocks were lost: after the first acquisition, the node answered the blocks held meanwhile from a
  guard condition, 100 ms of stream per callback, and rclpy's single-threaded executor takes one message per
  subscription per turn: one 1-ms block taken per ~80 ms of replay, so the subscription's queue (1000 messages, 1 s
  of 1-ms blocks) overflowed while the hold was replayed, and a hold that reached its bound was replayed whole in one
  call. Not the GIL: the search is numpy/scipy (large array operations release it) and the tracking kernel is numba
  with nogil. Now each replay callback first takes every block waiting in the subscription (they join the hold:
  "before a replay" above, up to 3,082 per run), blocks handed in after the search are held rather than answered
  (the receiver's replay_per_block 0), each block the executor hands over is followed by up to 100 waiting ones
  taken at once ("after a block", 1,593-4,426 per run in 1-ms blocks), and at the hold's bound each block handed in
  answers two held ones (10-49 times in 3 of the 6 runs at 16.368 MS/s: the backlog then waits in the
  subscription's queue). The same arrays as the synchronous path (tested, test_gnss_correlator_node.py), the bound
  and counters tested in the receiver (test_receiver.py).
- The loss left: in a first full run of this change (load 8.3-10.9; the arrays then written with hand-counted
  offsets, the same bytes) 11 of 12 runs answered every block; one 4 MS/s 1-ms run lost 16 of 5,000 (counted as
  input lost, from the publisher's sequence numbers) after its hold had emptied (342 calls held, the bound never
  reached): the node was then more than 1000 messages behind in steady state, where the subscription's queue is the
  only buffer. A node that gets less CPU than the stream needs loses blocks there; the queue's depth is the
  parameter qos_overrides./rfi/if_samples.subscription.depth (not measured here), or use 10-ms blocks (10 s per 1000
  messages).
- CPU per second of stream, executor thread: 4 MS/s complex 12 ch 0.49-0.53 (10-ms blocks; 0.58-0.63 before) and
  0.59-0.61 (1-ms; 0.77-0.82 before); 16.368 MS/s real 8 ch 0.77-0.80 (10-ms; 0.75-0.87 before) and 0.92-0.94 (1-ms;
  0.68-0.85 before, at lower load and with 158-162 blocks fewer answered). The acquisition worker took 0.28-0.33 and
  1.45-1.57 s once. So 12 channels at 4 MS/s fit in 0.6 of a core; 8 channels at 16.368 MS/s real need 0.8 of a
  core in 10-ms blocks and 0.93 in 1-ms blocks, and this probe saw the node 4.0-11.1 s behind over the second half
  (medians): with 7 workers on 2 vCPUs it got less than that (its hold reached the 4-s bound in 3 of 6 runs, and in
  one the search, 1.5 s of CPU, was still running there: more than 4 s of wall time). The 4 MS/s stream kept up in
  4 of 6 runs (12.5-300 ms behind over the second half) and was 2.6 and 5.2 s behind in the others.
- The publish path: each CorrelatorArray is now written as bytes from the interval's arrays through the suite's CDR
  codec (correlator_cdr.py on rfi_node_common.cdr; rclpy's serialisation of the message built field by field gives
  the same length and every field's value bit for bit, tested; only the padding differs, zero here, Fast CDR's
  buffer's old bytes there) and published as bytes. In one process
  ([live_stream_in_process.md](live_stream_in_process.md), load 7.3) writing the arrays takes 31-35 us per ms of
  stream against 64-76 for building the message objects (35-43) and rclpy's serialisation of them (29-34). Under the
  profiler in the node (GNSS_CORRELATOR_PROFILE, executor thread CPU time, 8 ch at 16.368 MS/s, 10-ms blocks, 3 s,
  load 9; the hand-counted writer) writing and publishing took 0.17 s per second of stream (0.13 the bytes, 0.04
  rclpy's publish_raw), against 0.32 + 0.19 in the previous document's profile (load 14). What remains is the
  tracking (360-620 us per ms of stream in one process) and, in 1-ms blocks, taking 1000 messages a second
  (deserialise, check, decode: 61-64 us per ms in one process; the executor's turns on top).

Changed for this document: the tracking kernel (above). The previous documents' changes stand (the replay of the
hold not starving the input, the arrays published serialised, the first acquisition in the worker thread, the
tracking kernel loaded at start-up, the final report recognised).
"""


if __name__ == "__main__":
    sys.exit(main())

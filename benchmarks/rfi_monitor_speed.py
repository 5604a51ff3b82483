"""Throughput of the whole RFI monitor chain on one core (samples/s, real-time factor).

Chain: three-sample IF measurement, adaptive fading KF, LPD + AR(10) sweep-period estimator,
reset scheduler and sweep-start fit (fused numba loop), periodicity detector, Welch features and
identification. Measures the median of
repeats over 1 ms blocks at the paper's 38.192 MS/s (real IF) and at 16.368 MS/s complex, and the
parts separately. Times are the CPU time of this thread (``time.thread_time``): the machine is
shared, and wall-clock time would count the time other processes hold the core. Run:

    PYTHONPATH=src/gnss_common:src/rfi_monitor:src/rfi_experiments python benchmarks/rfi_monitor_speed.py

``--quiet`` (``-q``): no progress lines (one per phase on stderr), no tables and no summary on stdout.

``--stages``: only the stage table of issue 26 item 2 (rfi_monitor_stages.py, the tree against STAGES_BASELINE),
written into its section of docs/rfi_monitor/speed.md (about 10 minutes). ``--runs N``: N runs of every (case,
version) child instead of STAGE_RUNS (1 on a machine too loaded for 36 children in the time at hand); ``--cases
A,B``: only these of STAGE_CASES (front end:phase).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_progress import case_log
from rfi_monitor_speed_notes import ISSUE26_NOTES

from rfi_monitor.classifier import ClassifierParams, block_features
from rfi_monitor.if_measurement import measure_if
from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
from rfi_monitor.sweep_analysis import SweepAnalysisParams, analyse
from rfi_monitor.sweep_period import SweepPeriodParams, estimate_sweep_period
from rfi_monitor.tracking_filters import TrackingFilterParams, run_tracking_filter
from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator

PAPER_FS = 38.192e6
NOT_KEPT = """Tracking mode (kept; monitor.RfiMonitorParams.confirm_fits, tracker module docstring):
once 4 sweep-start fits in a row succeed, the LPD / AR(10) / peak pass is suspended (only the
decimated history of the periodicity detector is kept up) and the periodicity detector is not
run (``SweepAnalysisParams.skip_while_tracking``); two failed fits in a row resume the search
(warm restart). The rows 'ours without tracking mode' (the chain without it) and 'ours,
tracking mode, detector every hop' in the table above isolate the two parts. The benchmark stream
is tracked from ~0.1 ms on, so the whole-chain rows are close to the steady state. The per-sample
frequency track is unchanged while the lattice is held (the step-fit lattice does not read the
LPD peaks then; tested): the RMSE tables of paper_results.md did not move.

Compiled per-block passes (kept; old vs new package alternately, steady-state blocks 20-59 of the
benchmark stream, CPU time per 1 ms block, medians of 5 monitors, on the quieter runs; the machine
was shared and some runs were 2-25x slower for both, those are not quoted):

* block_features: the float32 conversion and Hann window in one compiled pass, |X|^2 summed over
  frames in a compiled loop (double accumulation instead of float32: bins change by ~4e-7), and
  the ~15 small numpy calls after the Welch PSD in one compiled function
  (``classifier._spectral_features``): 151-168 -> 87-92 us per block.
* Fused loop: the running power (near-zero guard, noise compensation) updated once per aligned
  16-sample window from the deviations of its samples (the same exponential average, 1e-9
  relative at window ends, tested; the guard's threshold lags by < 16 samples of a 1024-sample
  average), so the per-sample serial recursion leaves the measurement loop; the five status
  counters as one packed integer per chunk: fused loop 803-818 -> 754-765 us per block
  (21.0 -> 19.8 ns per sample). paper_results.md unchanged to the printed digits.
* process(): non-finite and saturated samples counted in one compiled pass instead of
  np.isfinite, count_nonzero, abs, masking (17 us per block before).
* Whole chain, steady state: 998 -> 860-905 us per 1 ms block (1.00 -> 1.10-1.16x real time).

Measured and not kept (fused loop over 20 ms, best of 21, in one run; ns per sample):

* Welch features with at most 64 frames instead of all 149 of a 1 ms block: block
  features 167 -> 127 us per block in isolation (~1 ns per sample), not measurable in the whole
  chain on this machine (within the run-to-run noise); not adopted (noisier spectral J/N).
* Resuming the period search at the first failed fit instead of the second: at high
  J/N ~3 % of fits fail singly (116 resumptions in the 20 ms stream), the fused loop costs
  23.0 instead of 21.0 ns per sample (profiling run).

* AR(10) enhancement at decimation 8 for 'ours' (the AR and peak steps cost ~11 and ~5 ns per
  sample at D = 4): frequency RMSE at J/N 11.2 dB 0.0201 instead of 0.0095, 1e13 Hz/s sweeps lost.
* AR step on arrays padded to 16 so that it vectorises (AVX-512): 45 ns per step instead of 26
  (vector loads of values just stored as scalars stall on store forwarding).
* AR step and/or peak detector moved out of the interleaved filter/LPD loop into a pass after it:
  37-40 ns per sample instead of 35 (the interleaving overlaps the two serial recursions).
* Filter serial chain shortened (products with the innovation formed before the division, each
  output one fused multiply-add after it; kept, tracking_filters.kf_update_predict): the filter
  alone goes from ~11.5 to ~10 ns per sample, the fused loop does not change measurably.
"""
OUT = Path(__file__).resolve().parent.parent / "docs" / "rfi_monitor"
SECOND_ROUND = """Second round of speed work on issue 14 item 6 (kept; the live-stream rows compare it with 089111a):

* The frame length on noise: when no frame-length score is significant over its noise-only mean and scatter
  (measured once on seeded noise, ``ridge.null_peak_excess``), the longest frame is taken. The raw scores took a
  random length on noise, often the shortest: 8 samples on band-limited noise at 38.192 MS/s, 9,547 frames per
  1 ms block instead of 595 (the ridge analysis of a quiet block ~1.0 -> ~0.6 ms).
* The frame length is chosen again every 16 quiet blocks instead of 4 (~0.8 ms per choice at 38.192 MS/s).
* The evidence over blocks (integration.py): the normalised short-time amplitudes and the bin covariances in one
  compiled pass (162 -> 57 us), the comb over candidate periods compiled (the test ~0.9 -> ~0.3 ms, every 10 ms),
  and a processing budget, ``integration_max_samples_per_s`` (16.5 MS/s, deterministic along the stamps): every
  block up to 16.5 MS/s, 43 % of them at 38.192 MS/s (the others get the last decision, counted).
* The learned noise shape is formed once per ``calibration_blocks`` learned blocks instead of every block.
* Not kept: the integration in a worker thread beside the ridge analysis (the compiled parts release the GIL;
  measured 1.6-1.9 ms per block pair in series, 1.9-2.0 ms with the thread on the loaded 2-core machine: the
  numpy glue holds the GIL).

What is left: the ridge analysis is ~0.5-0.7 ms of a quiet 1 ms block and ~0.6-0.8 ms of a tracking block (its
tail of 16384 samples), many numpy calls of 10-50 us each. The same code on the same machine gave 0.76-1.23 ms
per tracking block in five back-to-back runs of one script (the host is shared with other virtual machines), so
the before / now ratio of the alternated rows is the figure to read, not one absolute number.
"""
THIRD_ROUND = """Third round of speed work on issue 14 item 6 (session 6; kept):

* Tracking blocks: the folded sweep profile, the saw-tooth law fit and the ridge-against-profile residuals and
  quantiles compiled (``ridge._profile_kernel``, ``_sawtooth_law_kernel`` with np.polyfit's scaled least squares,
  ``_fold_residuals`` with np.percentile's interpolation and numpy's pairwise mean): the same arithmetic in the same
  order, bit-identical on the equivalence cases (test_ridge_speed_equivalence.py run with a zero tolerance). A
  tracking block 0.86 -> 0.58 ms mean (three alternated runs against the commit before, loaded machine).
* In the node, not in this in-process table: a short gap in the sample index (blocks the node shed because it was
  behind) keeps the frame length and charges the unseen samples to the integration's budget
  (``monitor.FRAME_KEEP_GAP_S``, ``Integrator.skipped``). Before, every block a node behind its stream analysed
  paid for a new frame-length choice (about one block's analysis) and was integrated: the node fell further
  behind. That is where the live node gained most (live_stream.md: 733 of 2,901 blocks analysed as shipped in the
  previous session, 2,583 now).
* Quiet blocks analysed in part first (``RidgeParams.acquisition_samples`` = 16384, node parameter
  ``ridge_acquisition_samples``): while nothing is tracked the ridge takes the block's last 16384 samples and the
  whole block only when that part shows anything, so a quiet 38.192 MS/s block is analysed as a 16.4 MS/s front
  end's is (0.97 -> 0.83 ms per quiet block; slower front ends' blocks are unchanged).
* A block whose ridge locks on a multiple of the period the evidence over blocks found reports that period
  (``sweep_consistency.SUBHARMONIC_TOLERANCE``; accuracy, not speed: stft_shapes.md).
* ``warm_up`` also runs saw-tooth blocks: on a fresh install the first chirp of a live stream compiled the tracking
  path's functions (seconds), and the node lost a second of blocks there.
* Built, tested and off by default: ``analysis_worker`` (the ridge analysis in a child process). On this 2-vCPU
  virtual machine a block's analysis round trip through the child took 0.94 ms against 0.76 ms for the same
  analysis in the calling process (median of 300 blocks, nothing else running): the child reads a block another
  vCPU wrote and wakes from idle for each; the in-process rows above do not use it.

What is left: a quiet block (acquisition) costs about 0.8 ms per 1 ms block on this CPU when nothing else runs
(the ridge analysis of its last 16384 samples ~0.3 ms, the integration over blocks ~0.3 ms averaged over blocks,
the Welch PSD and the rest ~0.2 ms), more when the other core is busy: it does not keep up at 1x in one process
with a margin; the node then sheds quiet blocks on purpose (counted).
"""
LIVE_RUNS = 3
"""The live-stream rows are measured this many times in one run (the table gives the median, the runs are
listed after it)."""
RIDGE_SPEEDUP = """Ridge analysis speed-up (issue 14 item 6; kept): the per-bin noise level (module docstring
step 2) computed in one compiled pass after a numpy quantile (was: np.partition over the strided axis,
two scipy.ndimage median filters, a grey opening, four copies of a boolean mask and a masked float64 sum;
the 3 x 3 dilation of the jammer cells and the masked sums are now branch-free loops vectorised across
bins); the ridge's strongest bin, its excess and the two spectral-phasor sums in one compiled pass over
the STFT power (float32, numpy's pairwise summation order); the frame-length score's row maxima compiled;
STFT power squared in place; the period search after its autocorrelation FFT compiled (candidates,
sub-harmonic check, refinement on multiples, numpy's pairwise sum order); small medians without numpy's
per-call overhead. What is left of a tracking block (line timing on captured monitor inputs: tail of
16384 samples, frame 64, ~0.85 ms of ridge analysis when the machine was quiet): the STFT ~95 us (mostly
its FFTs), the saw-tooth law fit and its use ~95 + 95 us, the two folded profiles ~65 + 50 us, the shape
~35 us, percentiles and residuals ~85 us, the noise level ~70 us, the ridge's interpolation ~60 us, the
excess pass ~60 us, the period search ~55 us (its two FFTs): many numpy calls of 10-50 us each, no single
hot spot left. Cost: the compiled functions take ~10 s of CPU to compile on their first use after an
install (cached after that: 0.35 s; the node's warm_up does it before it subscribes). The arithmetic was kept in the
same precision and order, so the results are the same to the bit on this machine
(src/rfi_monitor/test/test_ridge_speed_equivalence.py: the shape cases of test_stft_estimator.py and
the real clean captures, ridge and whole monitor, against the frozen pre-speed-up ridge_reference.py;
stated tolerances 1e-6 relative, 1e-6 dB, integers and types exactly; bit-identical here; issue 28 replaced
that test and its frozen copy by test_ridge_stages.py and test_split_equivalence.py). Tried and not kept: the
autocorrelation FFT with scipy.fft instead of numpy.fft (the same bits, 3-5 us per block); the noise
level's quantile in the compiled pass (numba's np.partition and a hand-written quickselect were 4-7x
slower than numpy's introselect).
"""
def _steady_rate(fe, block: int, par, warm: int = 20, timed: int = 100, repeats: int = 5) -> float:
    """Samples/s of a continuous stream once acquired: ``warm`` blocks untimed, then ``timed`` blocks
    (CPU time, median of ``repeats`` fresh monitors)."""
    x = IfSimulator(fe, (ChirpJammer(start_frequency_hz=-2.5e6),), seed=2).generate((warm + timed) * block).values()
    ts = []
    for _ in range(repeats + 1):
        mon = RfiMonitor(par)
        for k in range(warm):
            mon.process(x[k * block:(k + 1) * block], fe.sample_rate_hz, fe.intermediate_frequency_hz, k * block, 0)
        t0 = time.thread_time()
        for k in range(warm, warm + timed):
            mon.process(x[k * block:(k + 1) * block], fe.sample_rate_hz, fe.intermediate_frequency_hz, k * block, 0)
        ts.append(time.thread_time() - t0)
    return timed * block / float(np.median(ts[1:]))


def _median_rate(fn, n_samples: int, repeats: int = 9) -> float:
    fn()  # warm-up / compile
    ts = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        ts.append(time.thread_time() - t0)
    return n_samples / float(np.median(ts))


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo ('unknown' elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


BASELINE_COMMIT = "089111a"
"""The project before the second round of speed work on issue 14 item 6 (the integration over blocks compiled and
budgeted, the frame length on noise, the reselection interval): its rfi_monitor is timed beside the current one."""
LIVE_BLOCKS = 300
"""Blocks of each live-stream stream (1 ms each; the first WARM_BLOCKS are not counted): long enough for the
integration window to hold hundreds of blocks, as in a long-running stream."""
WARM_BLOCKS = 20
CHILD = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[3])
from rfi_monitor_real_jammers import NodeLikeMonitor
from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator
case, nblk = sys.argv[1], int(sys.argv[2])
light = case.endswith("-light")          # the light analysis asked for on every block but the first
case = case.removesuffix("-light")
fe = FrontEndConfig(noise_bandwidth_hz=2e6)
block = int(round(fe.sample_rate_hz * 1e-3))
sim = IfSimulator(fe, () if case == "acquisition" else (ChirpJammer(js_db=40.0),), seed=3)
mon = NodeLikeMonitor(None)
ts, types = [], []
for k in range(nblk):
    blk = sim.generate(block)
    counts = np.clip(np.round(blk.values() / blk.scale), -127, 127).astype(np.int8)
    t0 = time.thread_time()
    e = mon.process(counts, blk.scale, fe.sample_rate_hz, fe.intermediate_frequency_hz, False, 8, k * block,
                    10**9 + k * 10**6, light=light and k > 0)
    ts.append(time.thread_time() - t0)
    types.append(int(e.type))
print(json.dumps({"t": ts, "types": types}))
"""
"""One stream in a child process (so that each version of the package is imported on its own): the shipped node
settings (``NodeLikeMonitor``, as rfi_monitor_node feeds the core), 1 ms blocks of 38.192 MS/s 8-bit real IF with
consecutive stamps; prints the CPU time of each block."""


def _export_baseline(tmp: Path, commit: str = BASELINE_COMMIT) -> Path | None:
    """src/rfi_monitor of ``commit`` exported under tmp (None if git or the commit is not there)."""
    root = Path(__file__).resolve().parent.parent
    try:
        arc = subprocess.run(["git", "archive", commit, "src/rfi_monitor"], cwd=root, capture_output=True,
                             timeout=60, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tmp)], input=arc, check=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    return tmp / "src" / "rfi_monitor"


def _stream_times(pkg_dir: Path, case: str) -> tuple[np.ndarray, np.ndarray]:
    """(CPU s per block, types) of one stream with the rfi_monitor package found in pkg_dir."""
    root = Path(__file__).resolve().parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(pkg_dir), str(root / "src" / "rfi_sim"),
                                         str(root / "src" / "rfi_node_common"), str(root / "src" / "gnss_common"),
                                         env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", CHILD, case, str(LIVE_BLOCKS), str(Path(__file__).resolve().parent)],
                         env=env, capture_output=True, text=True, timeout=1200, check=True).stdout
    d = json.loads(out.strip().splitlines()[-1])
    return np.asarray(d["t"]), np.asarray(d["types"])


def live_stream_rows() -> list[tuple[str, float]]:
    """The live-stream case of issue 14 item 6 with the default ("stft") estimator and the shipped node settings:
    CPU time per 1 ms block of 38.192 MS/s 8-bit real IF, blocks WARM_BLOCKS..LIVE_BLOCKS of a stream from a fresh
    monitor; acquisition (no jammer) and tracking (the paper's chirp at J/N 21 dB). The median block and the mean
    block (the throughput a live stream needs: it includes the blocks where the frame length is chosen again and
    the integration's tests). The rfi_monitor of BASELINE_COMMIT and the current one, alternately, each in a child
    process of its own. Returns (label, samples/s)."""
    block = int(round(PAPER_FS * 1e-3))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = _export_baseline(Path(tmp))
        now = Path(__file__).resolve().parent.parent / "src" / "rfi_monitor"
        versions = ([(f"before ({BASELINE_COMMIT})", base)] if base is not None else []) + [("now", now)]
        for case, label in (("acquisition", "acquisition, no jammer"), ("tracking", "tracking, chirp J/N 21 dB")):
            for vname, pkg in versions + [("now, light analysis asked on every block (a node behind its stream)",
                                           now)]:
                t, types = _stream_times(pkg, case + ("-light" if "light" in vname else ""))
                t = t[WARM_BLOCKS:]
                for stat, v in (("median block", float(np.median(t))), ("mean block", float(np.mean(t)))):
                    rows.append((f"live stream (stft, default), {label}, 38.192 MS/s 8-bit real, per 1 ms block, "
                                 f"{stat}, {vname}", block / v))
    return rows


STAGES_BASELINE = "93ea8b7"
"""The rfi_monitor before the speed work of issue 26 item 2 (its items 1 and issue 27 item 3 in, no speed change)."""
STAGE_CASES = tuple(f"{fe}:{phase}" for fe in ("real38", "cplx10", "real24")
                    for phase in ("acquisition", "tracking", "switch"))
"""Front end : phase of the stage table (rfi_monitor_stages.py)."""
STAGE_FRONT_ENDS = {"real38": "38.192 MS/s 8-bit real", "cplx10": "10 MS/s 8-bit complex",
                    "real24": "24 MS/s 8-bit real"}
STAGE_BLOCKS = 200
"""1 ms blocks per stream of the stage table (the first WARM_BLOCKS not counted; the switch-on at block 100)."""
STAGE_RUNS = 2
"""Runs of every (case, version) child, alternated; the table gives the median of their means."""
STAGES_BEGIN, STAGES_END = "<!-- stages:begin -->", "<!-- stages:end -->"


def _stage_run(pkg_dir: Path, case: str) -> dict:
    """One stream of rfi_monitor_stages.py with the rfi_monitor package found in pkg_dir."""
    root = Path(__file__).resolve().parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(pkg_dir), str(root / "src" / "rfi_sim"),
                                         str(root / "src" / "rfi_node_common"), str(root / "src" / "gnss_common"),
                                         env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, str(Path(__file__).resolve().parent / "rfi_monitor_stages.py"), case,
                          str(STAGE_BLOCKS)], env=env, capture_output=True, text=True, timeout=1200,
                         check=True).stdout
    d = json.loads(out.strip().splitlines()[-1])
    t = np.asarray(d["t"][WARM_BLOCKS:])
    stages: dict[str, float] = {}
    for row in d["stages"][WARM_BLOCKS:]:
        for k, v in row.items():
            stages[k] = stages.get(k, 0.0) + v
    stages = {k: v / t.size for k, v in stages.items()}
    stages["other"] = float(t.mean()) - sum(stages.values())
    return {"mean": float(t.mean()), "p99": float(np.percentile(t, 99)), "stft": float(np.median(d["stft"])),
            "block_s": d["n"] / {"real38": 38.192e6, "cplx10": 10e6, "real24": 24e6}[case.split(":")[0]],
            "stages": stages}


def stage_measurements(runs: int = STAGE_RUNS, cases: tuple[str, ...] = STAGE_CASES
                       ) -> dict[tuple[str, str], list[dict]]:
    """(case, version) -> the runs (STAGE_RUNS by default), the versions ("before", "now") alternated per case."""
    res: dict[tuple[str, str], list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        base = _export_baseline(Path(tmp), STAGES_BASELINE)
        now = Path(__file__).resolve().parent.parent / "src" / "rfi_monitor"
        versions = ([("before", base)] if base is not None else []) + [("now", now)]
        for _ in range(runs):
            for case in cases:
                for name, pkg in versions:
                    res.setdefault((case, name), []).append(_stage_run(pkg, case))
    return res


def stage_section(res: dict[tuple[str, str], list[dict]]) -> str:
    """The stage tables of speed.md (issue 26 item 2)."""
    def med(case: str, ver: str, key: str) -> float:
        return float(np.median([r[key] for r in res[(case, ver)]]))

    def stage(case: str, ver: str, name: str) -> float:
        return float(np.median([r["stages"].get(name, 0.0) for r in res[(case, ver)]]))

    measured = [c for c in STAGE_CASES if any(key[0] == c for key in res)]
    versions = [v for v in ("before", "now") if (measured[0], v) in res]
    lines = [STAGES_BEGIN, "## Full analysis per block, by stage, against a bare STFT (issue 26 item 2)", "",
             f"`benchmarks/rfi_monitor_speed.py` (children `benchmarks/rfi_monitor_stages.py`): the monitor fed as the "
             "node feeds it (shipped settings, compiled functions warmed up as the node does), "
             f"{STAGE_BLOCKS} blocks of 1 ms with consecutive stamps (a replay: every block analysed in full), "
             f"blocks {WARM_BLOCKS}..{STAGE_BLOCKS - 1} counted; acquisition = noise only, tracking = the paper's "
             "saw-tooth chirp at J/N 21 dB from the first block, switch = noise, the chirp switched on at block 100. "
             "CPU time of the thread, one core (the process pinned), 'before' = the rfi_monitor of "
             f"{STAGES_BASELINE} (before this speed work), 'now' = this tree, alternated, "
             f"{len(next(iter(res.values())))} run(s), medians. "
             "Bare STFT = a Hann-windowed 256-point STFT of the same block with numpy (|X|^2, non-overlapping frames), "
             "timed in the same process between the blocks: the ratio to it is the figure that holds on a shared "
             "machine. Real-time factor = block duration / mean CPU time per block (goal: >= 3, p99 <= 5 ms).", "",
             "| front end | phase | version | mean ms per block | p99 ms | bare STFT ms | mean / bare STFT | "
             "real-time factor |", "|---|---|---|---|---|---|---|---|"]
    for case in measured:
        fe, phase = case.split(":")
        for ver in versions:
            mean, p99, stft = med(case, ver, "mean"), med(case, ver, "p99"), med(case, ver, "stft")
            block_s = res[(case, ver)][0]["block_s"]
            lines.append(f"| {STAGE_FRONT_ENDS[fe]} | {phase} | {ver} | {mean * 1e3:.3f} | {p99 * 1e3:.2f} | "
                         f"{stft * 1e3:.3f} | {mean / stft:.1f} | {block_s / mean:.2f} |")
    names: list[str] = []
    for runs in res.values():
        for r in runs:
            names += [k for k in r["stages"] if k not in names]
    names = sorted(set(names), key=lambda k: (k == "other", -stage(measured[0], versions[-1], k)))
    for fe in STAGE_FRONT_ENDS:
        cases = [c for c in measured if c.startswith(fe + ":")]
        if not cases:
            continue
        cols = [(c, v) for c in cases for v in versions]
        lines += ["", f"Stages, {STAGE_FRONT_ENDS[fe]}: ms per block (share of the block's time; in units of the bare "
                  "STFT in brackets)", "",
                  "| stage | " + " | ".join(f"{c.split(':')[1]} {v}" for c, v in cols) + " |",
                  "|---|" + "---|" * len(cols)]
        for name in names:
            cells = []
            for c, v in cols:
                x, tot, stft = stage(c, v, name), med(c, v, "mean"), med(c, v, "stft")
                cells.append(f"{x * 1e3:.3f} ({100 * x / tot:.0f} %) [{x / stft:.2f}]")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        totals = [f"{med(c, v, 'mean') * 1e3:.3f} [{med(c, v, 'mean') / med(c, v, 'stft'):.1f}]" for c, v in cols]
        lines.append("| total | " + " | ".join(totals) + " |")
    return "\n".join(lines + ["", ISSUE26_NOTES, "", STAGES_END])


def write_stage_section(text: str) -> None:
    """Put the stage section at the top of speed.md (after its title), replacing an older one."""
    path = OUT / "speed.md"
    doc = path.read_text() if path.exists() else "# RFI monitor throughput\n"
    if STAGES_BEGIN in doc and STAGES_END in doc:
        a, b = doc.index(STAGES_BEGIN), doc.index(STAGES_END) + len(STAGES_END)
        doc = doc[:a] + text + doc[b:]
    else:
        head, _, rest = doc.partition("\n")
        doc = head + "\n\n" + text + "\n" + rest
    path.write_text(doc)


def main() -> None:
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=f"writes {OUT / 'speed.md'} (about 15 minutes; --stages: 10)")
    parser.add_argument("--stages", action="store_true",
                        help="only the stage table of issue 26 item 2, written into its section of speed.md")
    parser.add_argument("--runs", type=int, default=STAGE_RUNS,
                        help=f"runs of every (case, version) child of the stage table (default {STAGE_RUNS})")
    parser.add_argument("--cases", default=",".join(STAGE_CASES),
                        help="comma-separated stage cases (front end:phase), default all: " + ",".join(STAGE_CASES))
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines, tables or summary")
    a = parser.parse_args()
    stages_only = a.stages
    log = case_log(__file__, total=1 if stages_only else 3 + LIVE_RUNS, quiet=a.quiet)
    stage_runs = a.runs
    cases = tuple(a.cases.split(","))
    if not set(cases) <= set(STAGE_CASES) or stage_runs < 1:
        parser.error(f"--cases: each of {', '.join(STAGE_CASES)}; --runs >= 1")
    section = stage_section(stage_measurements(stage_runs, cases))
    log.done("stage table")
    log.say(section)
    if stages_only:
        write_stage_section(section)
        log.finish(f"wrote the stage section of {OUT / 'speed.md'}")
        return
    runs = [live_stream_rows() for _ in log.cases_of(range(LIVE_RUNS), lambda k: f"live-stream rows, run {k + 1}")]
    rows = [(runs[0][i][0], float(np.median([r[i][1] for r in runs]))) for i in range(len(runs[0]))]
    ref_rate = math.nan
    for name, fe in (("real IF 38.192 MS/s", FrontEndConfig(noise_density_dbm_per_mhz=-124.0)),
                     ("complex 16.368 MS/s", FrontEndConfig(sample_rate_hz=16.368e6, intermediate_frequency_hz=0.0,
                                                            is_complex=True, noise_density_dbm_per_mhz=-124.0))):
        block = int(round(fe.sample_rate_hz * 1e-3))
        nblk = 20
        x = IfSimulator(fe, (ChirpJammer(start_frequency_hz=-2.5e6),), seed=1).generate(nblk * block).values()
        ours = RfiMonitorParams(estimator="kalman", noise_floor_power=fe.noise_power_mw, calibration_blocks=1)
        for label, par in (("ours", ours),
                           ("ours without tracking mode", dataclasses.replace(
                               ours, confirm_fits=0, analysis=SweepAnalysisParams(skip_while_tracking=False))),
                           ("ours, tracking mode, detector every hop", dataclasses.replace(
                               ours, analysis=SweepAnalysisParams(skip_while_tracking=False))),
                           ("paper method", RfiMonitorParams.paper_method(noise_floor_power=fe.noise_power_mw,
                                                                          calibration_blocks=1))):
            def whole(x=x, fe=fe, block=block, nblk=nblk, par=par):
                mon = RfiMonitor(par)
                for k in range(nblk):
                    mon.process(x[k * block:(k + 1) * block], fe.sample_rate_hz, fe.intermediate_frequency_hz,
                                k * block, 0)

            rows.append((f"whole chain ({label}), {name}", _median_rate(whole, nblk * block, repeats=7)))
        if name.startswith("real"):
            rows.append((f"whole chain (ours), {name}, steady state (blocks 20-119 of one stream)",
                         _steady_rate(fe, block, ours)))
        if name.startswith("real"):
            z, _ = measure_if(x)
            zf = np.where(np.isfinite(z), z, 0.25)
            ref_rate = _median_rate(lambda z=z: run_tracking_filter(z, TrackingFilterParams()), z.size)
            rows.append(("reference: fading KF alone (numba)", ref_rate))
            rows.append(("IF measurement only (eq. 8)", _median_rate(lambda x=x: measure_if(x), x.size)))
            for d in (1, 2, 4):
                rows.append((f"LPD + AR(10) + peaks, decimation {d}",
                             _median_rate(lambda d=d, zf=zf: estimate_sweep_period(zf, SweepPeriodParams(decimation=d)),
                                          zf.size)))
            cp = ClassifierParams()
            rows.append(("Welch features (per 1 ms block)",
                         _median_rate(lambda x=x, block=block, cp=cp, nblk=nblk: [
                             block_features(x[k * block:(k + 1) * block], None, cp) for k in range(nblk)], x.size)))
            w = x[:4096]
            hop = SweepAnalysisParams().hop_s
            rows.append((f"periodicity detector (one analysis per {hop * 1e3:g} ms hop)",
                         _median_rate(lambda w=w: analyse(w, 4, 0.0, 0, SweepAnalysisParams()),
                                      int(hop * PAPER_FS))))
            par_o = RfiMonitorParams(estimator="kalman", noise_floor_power=fe.noise_power_mw, calibration_blocks=1)
            for label, p in (("ours", par_o), ("paper method", RfiMonitorParams.paper_method(
                    noise_floor_power=fe.noise_power_mw, calibration_blocks=1))):
                def loop(p=p, x=x):
                    from rfi_monitor.kalman_estimator import KalmanEstimator
                    est = RfiMonitor(p).estimator          # the tracker's fused loop moved into the estimator
                    assert isinstance(est, KalmanEstimator)
                    est._run_tracker(x, False, 0, False)
                rows.append((f"fused per-sample loop only ({label}, one call)", _median_rate(loop, x.size)))
        log.done(f"rows of the {name} front end")
    lines = ["| stage | MS/s | real-time factor vs 38.192 MS/s | ratio to the fading KF alone |", "|---|---|---|---|"]
    for name, r in rows:
        lines.append(f"| {name} | {r / 1e6:.1f} | {r / PAPER_FS:.2f} | {r / ref_rate:.2f} |")
    table = "\n".join(lines)
    log.say(table)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "speed.md").write_text(
        "# RFI monitor throughput (one core, median of repeats)\n\n"
        "Blocks of 1 ms; real-time factor = MS/s / 38.192 (the paper's front end). The machine is shared:\n"
        f"the 1-minute load average at the end of this run was {load:.2f} on 2 cores, so absolute MS/s vary\n"
        "between runs; the last column (ratio to a numba fading KF alone, measured in the same run) is\n"
        "the stable figure. Times are CPU time of the benchmark thread (median of 7-9 repeats; the\n"
        "whole-chain rows run 20 blocks of 1 ms from a fresh monitor, acquisition included; the\n"
        "steady-state row times blocks 20-119 of one stream, median of 5 monitors). 'ours' =\n"
        "paper method + step-fit lattice + periodicity detector (AR decimation 4) + tracking mode; the paper\n"
        "method runs the AR(10) enhancement at decimation 2 and never suspends it.\n\n"
        f"CPU: {cpu_model()} (/proc/cpuinfo), one core.\n\n"
        "The first rows are the default estimator since issue 14 (\"stft\", short-time FFT ridge analysis of\n"
        "each block, no per-sample loop); 'ours' and 'paper method' below are the per-sample \"kalman\"\n"
        "estimator. Where the live-stream real-time factor is below 1 the node sheds whole blocks on purpose\n"
        "(``max_cpu_load``, blocks_shed on /diagnostics; rfi_monitor_node module docstring). The live-stream\n"
        "rows give the median block and the mean block (the throughput a live stream needs: it includes the\n"
        "blocks where the frame length is chosen again and the integration's tests) of a 300-block stream with\n"
        "the shipped node settings, for the rfi_monitor of commit "
        f"{BASELINE_COMMIT} (before this round of speed work) and now,\n"
        "each in a child process, alternately; "
        f"{LIVE_RUNS} runs of them in this run, the table gives their median.\n\n"
        + table + "\n\n" + live_runs_table(runs) + "\n\n" + real_time_verdict(rows) + "\n\n" + THIRD_ROUND
        + "\n" + SECOND_ROUND
        + "\n" + RIDGE_SPEEDUP
        + "\n" + NOT_KEPT)
    write_stage_section(section)
    log.finish(f"wrote {OUT / 'speed.md'}")


def real_time_verdict(rows: list[tuple[str, float]]) -> str:
    """Whether the current ridge keeps up at 1x in this run (the median over its live-stream runs)."""
    out, light = [], []
    for name, r in rows:
        verdict = f"{r / PAPER_FS:.2f}x ({'keeps up' if r >= PAPER_FS else 'does NOT keep up'})"
        if name.startswith("live stream") and name.endswith(", now"):
            parts = name.split(", ")
            part = parts[2].split(" ")[0] + ", " + parts[-2]          # acquisition / tracking, median / mean
            out.append(f"{part}: {verdict}")
        elif name.startswith("live stream") and name.endswith("(a node behind its stream)"):
            parts = name.split(", ")
            light.append(f"{parts[2].split(' ')[0]}, {parts[6]}: {verdict}")
    return ("Real time at 38.192 MS/s with the current code in this run: " + "; ".join(out) + ". With the light "
            "analysis asked for on every block (what a node behind its stream does; rfi_monitor_node "
            "``light_analysis_debt_s``, live_stream.md): " + "; ".join(light) + ".")


def live_runs_table(runs: list[list[tuple[str, float]]]) -> str:
    """The live-stream rows of each run, real-time factor vs 38.192 MS/s (the spread between runs)."""
    lines = ["Live-stream rows, each of the runs (real-time factor; the table above gives their median):", "",
             "| row | " + " | ".join(f"run {i + 1}" for i in range(len(runs))) + " |",
             "|---|" + "---|" * len(runs)]
    for i, (name, _) in enumerate(runs[0]):
        lines.append(f"| {name} | " + " | ".join(f"{r[i][1] / PAPER_FS:.2f}" for r in runs) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()

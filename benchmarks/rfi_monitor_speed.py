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


ISSUE26_NOTES = """Issue 26 item 2, fourth round (2026-12-07, night: fewer calls at the small blocks, no behaviour
change): **the goal is not met, and the totals did not move beyond this machine's noise.** The run above: 1 run of all
9 cases (``--runs 1``), 8 workers sharing the 2 cores (load average 13 falling to 5 during the run, 16-18 during the
work). At 38.192 MS/s the full analysis costs 9.8 (acquisition), 8.6 (tracking) and 8.7 (switch) bare STFTs of its block
against 12.4, 9.6 and 10.1 for 93ea8b7 in the same run (goal: about 3-4), 0.70-0.87x real time; at 10 MS/s complex
18.7 / 14.2 / 17.9 (26.5 / 19.5 / 23.1 before), 0.59-0.85x; at 24 MS/s real 12.7 / 11.6 / 13.0 (16.1 / 13.3 / 14.1
before), 0.60-0.88x; p99 at most 3.6 ms. Now over before in the same run: 0.79 / 0.90 / 0.86, 0.71 / 0.73 / 0.77,
0.79 / 0.87 / 0.92, where the third round's run read 0.81 / 0.85 / 0.79, 0.71 / 0.70 / 0.90, 0.77 / 0.99 / 0.86: the
same within the +-10-15 % that one run carries. A first run of the same tree, started right after the edits, read
71.1 bare STFTs at 38.192 MS/s switch (mean 11.1 ms, p99 3.1 ms: one block of about 1.7 s, presumably numba
compiling a changed module's kernel on first use; not seen in the second run, whose table is above).

Done this round (src/rfi_monitor: stft.py, classifier.py, spectral_autocorrelation.py, constant_envelope.py;
bit-identical: split_reference.py --check, all 900 fields of its 12 streams; real_jammers.md's table unchanged):
scipy's pocketfft binding called directly (as ``stft.fft_inplace`` already did for the ridge: ``rfft_rows``,
``irfft_rows``, ``irfft_real``; no scipy.fft dispatch, 5-15 us a call) in the classifier's Welch PSD, the
integration's spectral autocorrelation (its STFT, the amplitudes' rfft and the irfft) and the envelope's Hilbert
transform; the noise level's compiled selection (``column_order_statistic``) also below 768 frames up to 32,768
cells (155 x 128 at 10 MS/s acquisition: 60 vs 110 us for np.partition of the transposed copy; 255 x 65: 57 vs 77;
numpy kept above, where it won at 255 x 129, 154 vs 310 us); the STFT's bin frequencies and the window energy of the
Parseval sum cached per frame length. In bare STFTs, this run against the third round's: welch + features 1.04 /
1.64 / 1.22 -> 0.92 / 1.55 / 1.00 (10 MS/s complex), 1.01 / 1.30 / 1.05 -> 0.77 / 1.10 / 0.90 (24 MS/s real);
integration 6.72 -> 6.02 (10 MS/s acquisition), 5.09 -> 3.73 (24 MS/s); envelope J/N 1.49 -> 1.16 (24 MS/s
tracking). In an A/B against the third round's tree (60afe7c, 2 runs alternated, load 16-18) the same stages moved
the same way (welch + features 1.71 -> 1.37, 1.19 -> 0.94, 1.20 -> 1.04; integration 6.61 -> 5.87; envelope
1.45 -> 1.14) and the totals by -7 to +4 %: noise. Measured and not done: a radix selection (histogram of the
float32 keys) and a sampled two-pivot filter for the long columns (1,249 x 16 at 10 MS/s tracking: 54 -> 46 us, the
selection proper is already ~2 ns a value; the column gather 15 us of it): not worth their code.

What remains at the small blocks (10 MS/s complex tracking, cProfile by thread time, 100 blocks, the loaded machine:
about 2.7 ms a block in all, 300 Python-level calls): the ridge 1.8 ms (its STFT of 1,249 16-point frames 0.2, the
noise levels 0.28 of which the selection 0.19, the frame ridges 0.21, the period search 0.25, the profiles, shape
and fold residuals 0.38, the block-end frequency 0.40 of which the saw-tooth law's fit and prediction interval in
sweep_law.py 0.29, another helper's file this round), the Welch PSD and features 0.44, the rest 0.5. Each stage is
already one or two compiled kernels; what is left per stage is its arithmetic on 1,249 frames x 16 bins and 5-30 us
of call overhead, so the goal needs fewer passes over the block, i.e. the behaviour changes listed below for the
third round (hop L instead of L / 2, a shared spectrum for the classifier and the CW statistic, the envelope over
fewer samples) or the ridge's own: its noise quantile, frame ridges and period phasor from one pass over a shared
spectrogram (the classifier's 256-point frames are 16 times the ridge's 16-point ones at 10 MS/s; one spectrogram
for both would change the ridge's time resolution or the classifier's frequency resolution).

Issue 26 item 2, third round (2026-12-07, evening: the stages outside the ridge; behaviour
changes allowed): **the goal is not met.** Its run (2 runs of all 9 cases, the machine otherwise running one
test process, load about 1-2 on 2 cores): at 38.192 MS/s the full analysis cost 10.0 (acquisition), 7.5 (tracking)
and 7.7 (switch) bare STFTs of its block against 12.3, 8.8 and 9.7 for 93ea8b7 in the same run (goal: about 3-4),
0.78-1.07x real time; at 10 MS/s complex 17.2 / 13.7 / 17.3 (24.2 / 19.5 / 19.3 before), 0.64-0.82x; at 24 MS/s real
13.1 / 12.5 / 12.5 (17.0 / 12.6 / 14.5 before), 0.86-0.98x; p99 at most 3.6 ms (goal <= 5 ms: met). The same tree in a
reduced run during the work (``--runs 1``, 5 of the 9 cases, load 15, the bare STFT itself 0.20-0.31 ms across the
children) read 8.5 / 6.1 / 6.3 at 38.192 MS/s against 9.6 / 8.7 / 8.2 before: the ratios carry about +-15-20 % between
runs; the ratio to 93ea8b7 in the same run (0.79-0.85 of its bare STFTs at 38.192 MS/s here) is the steadier figure.

Done this round (src/rfi_monitor: constant_envelope.py, cw_statistic.py, chirp_comb.py, integration.py):

* Constant-envelope J/N: the Hilbert transform by a real FFT and its inverse (``hilbert_transform``) instead of the
  complex inverse FFT of the doubled spectrum, the moments from x^2 + H(x)^2 in one compiled pass: per call 144-160
  -> 95 us (8,192 samples); the stage 1.41 -> 0.96 bare STFTs (38.192 MS/s tracking), 2.28 -> 1.54 (24 MS/s). The
  same J/N to 5e-13 dB (rounding; split_reference regenerated), real_jammers.md unchanged.
* The integration's decisions: the CW test's running median and scores in one kernel (per tested sum 38-87 -> 13-14
  us), the comb's coarse selection (argpartition, argsort, separation) and its fine comb with the best candidate's
  terms in two kernels (per sum 253-348 -> 185-199 us); a decision on a full window (4 sums) 1.81-1.95 -> 1.20-1.41
  ms, in one process, alternated. One change of behaviour: among equal coarse combs (flat plateaus of rounded lags)
  the shorter period is taken first, where numpy's partition left the order to its implementation; no field of
  split_reference's 12 streams moved, real_jammers.md and the integration tests unchanged.

What is left, and what the goal would need (38.192 MS/s quiet block, the reduced run, bare STFTs): ridge 2.3,
integration
2.7, the classifier's Welch PSD and features 0.9, spectral step 0.7, frame length 0.3, the rest 1.6. Without the ridge
(another round's) and the rest, the stages here would have to cost nothing to reach 4. The integration's cost is its
statistic: an added block (43 % of them at 38.192 MS/s under the 16.5 MS/s budget) pays 5-6 bare STFTs in the
spectral autocorrelation (its 2,386-frame 32-point STFT ~1, the 15 x 4,320-point FFT of the amplitudes ~1.5, the bin
covariances ~0.7, the amplitudes and lag terms the rest) and ~0.7 in the 1024-point Welch PSD. Measured and not
done, each a loss to weigh: (1) hop L instead of L / 2 halves the frames and the FFT lengths (47 instead of 96
us, 75 instead of 158 us), but Hann frames at hop L / 2 are nearly independent (complex correlation of white noise
0.19), so the comb's z for the same blocks falls by about sqrt 2: the same detection needs twice the blocks, the
trade that halving ``integration_max_samples_per_s`` already makes, at the same cost per frame;
(2) the CW statistic on the sum of the classifier's 256-point PSDs instead of its own 1024-point one would drop the
1024-point Welch PSD (~0.3 bare STFTs per 38.192 MS/s block, ~1 at 10 MS/s complex, where every block is added);
a tone at the reporting floor (the classifier's detect_jn_db, -6 dB) stays significant by orders of magnitude, but
the 31-bin running median would span a quarter of a real 256-bin band and no longer follow a 2 MHz pass band in a
19 MHz one: the smoothing width and the false alarms on the real clean captures would have to be derived again;
(3) the envelope moments over 4,096 samples instead of 8,192: ~0.5 bare STFTs per tracking block, their scatter
1.4 % instead of 1 % (the J/N column of real_jammers.md would scatter more); (4) decisions spread over blocks would
lower the p99 (a full-window decision, 1.2-1.4 ms, lands on one block), not the mean. The classifier's Welch PSD
(one 256-point Hann PSD of the block) is a bare STFT by construction: cheaper only shared with another stage's
spectrum, whose frame length and overlap differ (the ridge: L = 64-256 at hop L / 2 on the block's tail).

The second round (earlier the same day; its run, 2 runs of all 9 cases on a quieter machine, read 7.1-9.0 bare STFTs
at 38.192 MS/s, 0.82-1.01x real time; 10 MS/s complex 15.7-18.8, 0.74-0.86x; 24 MS/s real 12.1-13.7, 0.87-1.04x; at
the start of the day 9.2-10.0, 18.6-24.1 and 13.6-15.4; p99 <= 2.9 ms once the compiled functions are warmed up as
the node does; the cold first blocks of a stream cost 70-340 ms: numba loading its cache):

Where the time goes: four different spectrograms of every block, each with its own frame length, window and
overlap, and 100+ numpy calls of 2-20 us each. Quiet 38.192 MS/s block: the integration over blocks 34 % (its own
32-sample STFT at hop 16 of the whole block, 2,386 frames, about 1.5 bare STFTs; its 1024-point Welch PSD; the comb
decision every 10 ms of stamps, 1-2 ms each, which sets the p99), the ridge analysis 33 % (its STFT of the last 16,384
samples at hop L/2, noise levels, excess pass, periodicity FFT), the classifier's 256-point Welch PSD and features
11 %, the spectral-step test 6 %. Tracking block: the ridge 57 %, Welch 17 %, the constant-envelope J/N 15 % (the
analytic signal, an FFT of 8,192 samples). At 10 MS/s complex the block is small (10,000 samples) and the fixed cost
of the numpy calls dominates: 19-24 bare STFTs.

Done (bit-identical: every JammerEstimate field of 160-block streams at the three front ends, acquisition and
switch-on, equal to those of 93ea8b7; test_ridge_speed_equivalence.py passes): stft_power's framing, float32
conversion, window and |X|^2 compiled (no temporaries); the integration's fine comb summed from the candidate periods
directly (no lag and mask arrays of a few hundred candidates x 128 multiples) and its candidate separation compiled.
Gain 0-5 % of a block, within this machine's noise.

Done, the ridge analysis, second pass (bit-identical: split_reference.py --check, all 900 fields of its 12 streams;
real_jammers.md's table unchanged): the frame ridges' interpolation, presence flags and means fused into the excess
pass (two kernels and one np.log instead of ~15 numpy calls; the noise divisors, the complex phasor, the cos/sin tables
cached per bin count); phase_profiles in one kernel; scipy's pocketfft binding called directly for the STFT's FFT and
the period search's two FFTs (the same transforms to the bit, without scipy.fft's or numpy.fft's dispatch); the lower
noise quantile by a compiled selection on long columns (>= 768 frames: 1249 x 16 at 10 MS/s with 16-sample frames,
where np.partition took 115 us and the selection 48). The ridge stage in bare STFTs, the run above against the
previous one ('now' of each): 38.192 MS/s 3.3 -> 2.4 (acquisition), 5.2 -> 4.2 (tracking), 4.9 -> 4.0 (switch);
10 MS/s complex 7.4 -> 5.1, 13.1 -> 11.0, 10.1 -> 9.0; 24 MS/s real 5.0 -> 3.5, 8.7 -> 7.6, 7.8 -> 6.9. What is left
in it (thread time, a 38.192 MS/s tracking block, the last 16,384 samples at L = 64): the STFT 70 us, the noise levels
65 us (np.partition 35-45 of it: numpy's selection beats a compiled one on columns of 255-511 frames), the frame
ridges 45 us, the period search 30 us (its FFTs), the profiles, shape and residuals 40 us, the block-end frequency
30 us (numpy's linalg in the law's prediction interval, kept for its bits), and the sample-resolution hook test
(``fine_hook``): 1.5 ms on the 1 block in 20 that runs it (the analytic signal's FFTs of the block), 75-95 us a block
on average.

What the goal needs (not done): one spectrogram per block shared by the Welch features, the ridge and the
integration, and the per-block glue in compiled passes. The shared spectrogram changes the statistics (the
integration's comb and the ridge's noise-only peak excess are calibrated on their own frame lengths and overlaps), so
the thresholds and the accuracy documents (real_jammers.md, sensitivity.md, stft_shapes.md) must be measured again
with it; that did not fit in this session. The paper's "kalman" estimator is untouched.

The stages around the ridge (2026-12-07, later; bit-identical: split_reference.py --check, all 900 fields of 12
streams equal to the bit; the real-jammer table unchanged): the integration's spectral autocorrelation takes the
|X|^2, amplitudes, normalisations and FFT padding from the spectrum in one compiled pass and its noise moments in
another (per call 622 -> 523 us at 38.192 MS/s, 357 -> 245 us at 10 MS/s complex); its sums over the window and the
sub-windows are stacked (one add per statistic); the comb's fine candidates are compiled (36 -> 3 us); the complex
Welch PSD is compiled like the real one (82 -> 50 us per call at 10 MS/s); the noise template's running median is
compiled (20 -> 7 us, every block while no template is learned); interleaved I/Q become complex samples without
temporaries. In the run above, same process, alternated: integration 0.590 -> 0.448 ms (38.192 MS/s quiet), 0.888 ->
0.642 ms (10 MS/s quiet); Welch + features 0.22 -> 0.14 ms (tracking, both front ends). The ratio to the bare STFT
moved clearly only at 10 MS/s complex (27.2 -> 22.3 quiet, 19.2 -> 17.7 tracking); at 38.192 MS/s the bare STFT
itself read 0.12-0.16 ms across the children, more than these gains. What is left in these stages is FFTs and the
comb's decisions: a quiet 38.192 MS/s block added to the window costs about 4 bare STFTs (its 2,386-frame 32-point
STFT, the 15 x 4,320-point FFT of the amplitudes, the 1024-point Welch PSD), and a decision about 0.3 ms per distinct
window length (1.2 ms with the window full, every 10 ms of stamps). Cheaper only with a change of behaviour:
integrating at hop L instead of L / 2 (half the frames and FFT length; the noise model of the comb measured again),
deciding on fewer window lengths, or the constant-envelope moments over 4,096 samples instead of 8,192
(measured per call 129 -> 71 us; 1.4 bare STFTs per tracking block now; their scatter 1.4 % instead of 1 %)."""


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

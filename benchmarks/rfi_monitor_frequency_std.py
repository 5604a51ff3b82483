"""Issue 26 item 3: does a chirp's published ``frequency_std_hz`` cover its errors as a 1-sigma should?

For every block of the rows of ``benchmarks/rfi_monitor_real_jammers.py`` (rows D excepted: they publish no chirp
frequency) whose monitor answer is CHIRP with a finite ``frequency_hz``, whose truth frequency at the block end is
inside the sampled band, scored from the block after the first (as that benchmark scores), the normalised error
``|frequency_hz - truth| / frequency_std_hz``. A right 1-sigma puts the median of these near 0.67, the 68th
percentile near 1 and the 95th near 2 (a normal error; about 68 % within 1 sigma, 95 % within 2). The rows are the
same streams, seeds and shipped settings as that benchmark's (one fresh monitor per stream, 1 ms blocks).

Groups: simulated rows (``IfSimulator`` alone) and real-capture rows (real clean captures with a simulated jammer
added, re-quantised to the capture's bits); each row on its own below.

Run (about two minutes):

    PYTHONPATH=src/rfi_sim:src/rfi_monitor:src/rfi_node_common:src/gnss_common \\
        python benchmarks/rfi_monitor_frequency_std.py [--out docs/rfi_monitor/frequency_std.md]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from bench_progress import add_quiet_argument, case_log
from rfi_monitor_real_jammers import (
    CHIRP,
    ROOT,
    capture_stream,
    cpu_model,
    git_describe,
    load_captures,
    rows,
    run_stream,
    sim_stream,
)


@dataclass
class Coverage:
    """Normalised errors |error| / published 1-sigma of one row (or group)."""

    name: str
    real: bool
    z: list[float] = field(default_factory=list)
    err_hz: list[float] = field(default_factory=list)
    std_hz: list[float] = field(default_factory=list)


def in_band_limits_hz(fs: float, fif: float, cplx: bool) -> tuple[float, float]:
    """The sampled band relative to the RF centre, Hz (as the real-jammer benchmark scores it)."""
    return (-fs / 2, fs / 2) if cplx else (-abs(fif), fs / 2 - abs(fif))


def stream_coverage(name: str, real: bool, blocks: list, ests: list) -> Coverage:
    """The normalised errors of one stream's scored in-band CHIRP frequencies."""
    cov = Coverage(name, real)
    for k, (b, e) in enumerate(zip(blocks, ests, strict=True)):
        if k == 0 or not e.valid or int(e.type) != CHIRP or not math.isfinite(e.frequency_hz):
            continue
        lo, hi = in_band_limits_hz(b.fs, b.fif, b.cplx)
        if not (math.isfinite(b.truth_freq_hz) and lo <= b.truth_freq_hz <= hi):
            continue
        err = e.frequency_hz - b.truth_freq_hz
        cov.err_hz.append(err)
        cov.std_hz.append(e.frequency_std_hz)
        cov.z.append(abs(err) / e.frequency_std_hz if e.frequency_std_hz > 0 else math.inf)
    return cov


def run(capture_blocks: int, log) -> list[Coverage]:
    """Every non-D row's coverage, a row per stream (a capture row once per capture)."""
    out = []
    caps = load_captures()
    for row in rows():
        if row.name.startswith("D "):
            continue
        if row.capture is None:
            streams = [(row.name, sim_stream(row))]
        else:
            streams = [(f"{row.name} ({cap.name})", capture_stream(row, cap, capture_blocks)) for cap in caps]
        for name, (fe, blocks) in streams:
            ests, _ = run_stream(fe, blocks)
            cov = stream_coverage(name, row.capture is not None, blocks, ests)
            if cov.z:
                out.append(cov)
                log.done(f"{len(cov.z):3d} blocks  {name}")
    return out


def quantiles(z: Sequence[float]) -> str:
    """The table cells: n, median, 68th and 95th percentile, max, share within 1 and 2 sigma."""
    a = np.asarray(z, dtype=float)
    return (f"{a.size} | {np.median(a):.2f} | {np.percentile(a, 68):.2f} | {np.percentile(a, 95):.2f} | "
            f"{a.max():.1f} | {100 * np.mean(a <= 1):.0f} % | {100 * np.mean(a <= 2):.0f} %")


HEADER = ["| rows | blocks | median | p68 | p95 | max | within 1 sigma | within 2 sigma |",
          "|---|---|---|---|---|---|---|---|"]


NOTES: list[str] = [
    "## What the 1-sigma is, and what was found (issue 26 item 3)",
    "",
    "The published 1-sigma (`rfi_monitor.ridge`, stage 6; `rfi_monitor.sweep_law`): for a saw-tooth read off its",
    "sweep law, the law's prediction interval at the block end's phase (the profile bins' residual RMS about the law,",
    "with the law's own standard error there); for a frequency read off the folded profile, the RMS scatter of the",
    "frames' ridge about the profile; else the scatter about a local straight line (these two at least a bin /",
    "sqrt(12)). Since ad93017 the first two also carry, in quadrature, the bias of the profile bins' abscissa",
    "(`sweep_law.abscissa_bias`, `profile_abscissa_bias`): the law is fitted, and the profile read, with each phase",
    "bin at its centre, but when the sweep period is a whole number of frames every frame of a bin sits at the bin's",
    "start, and the frequency is read half a bin late. The bias is the one the block's own frames give (the law",
    "refitted at the mean phase of each bin's frames, or the profile interpolated there, minus what is published); the",
    "frequency itself is left as it was, so the bias enters the uncertainty, as a known correction not applied does",
    "(GUM, JCGM 100:2008, F.2.4.5).",
    "",
    "Before that change (ce21bb3, this script, the same blocks and frequencies):",
    "",
    *HEADER,
    "| simulated | 257 | 0.20 | 0.30 | 0.99 | 6.1 | 95 % | 99 % |",
    "| real captures + simulated jammer | 183 | 0.78 | 1.05 | 3.01 | 80.1 | 66 % | 90 % |",
    "| all | 440 | 0.33 | 0.65 | 1.80 | 80.1 | 83 % | 95 % |",
    "| R + saw-tooth over 60 % of the IF band in 12 us (PocketSDR 4 MS/s I/Q 2-bit) | 39 | 1.72 | 2.43 | 3.01 | 3.0 "
    "| 38 % | 67 % |",
    "| R + saw-tooth over 60 % of the IF band in 12 us (PocketSDR 12 MS/s real 2-bit) | 37 | 1.07 | 1.39 | 1.78 | 24.2 "
    "| 38 % | 95 % |",
    "",
    "The real-capture rows that the 1-sigma did not cover were these two: a 12 us period is 48 samples at 4 MS/s and",
    "144 at 12 MS/s, 6 and 18 hops of the 16-sample frame exactly; the profile read half a bin (half a hop) late is",
    "the sweep's rate times 1 us and 0.33 us, 125 and 70 kHz, and the measured median errors there were 124 kHz (the",
    "profile path) and 67 kHz (the law), 38 % within",
    "1 sigma in both. The simulated and the other real-capture rows' periods spread the frames over each bin.",
    "",
    "Studied and not adopted (figures on the same 440 blocks, ce21bb3):",
    "",
    "- The frequency corrected instead (the law refitted at the frames' mean phases; not done: issue 26 item 3's",
    "  brief kept the published frequencies as they were): the 12 MS/s 12 us row's median |error| 67 -> 5 kHz, p95",
    "  160 -> 37 kHz; the simulated law rows' median 8.9 -> 5.1 kHz. With it the bias term above is 0 by",
    "  construction. This is the next step; the 1-sigma should then be looked at again (below).",
    "- A scale calibrated on the stream (each block's law predicts the next block's frequency, the law being known",
    "  across blocks; a running median-based scale of those residuals over the last 16 blocks on the model 1-sigma,",
    "  bounded to [0.1, 10], the law's standard error as a floor): worse (simulated profile path 97 % -> 60 % within",
    "  1 sigma, real-capture law path 97 % -> 88 % within 2). The errors are shared by consecutive blocks: a bias that",
    "  depends on the phase the block end falls at, which the same profile gives again in the next block, and which a",
    "  scatter between blocks therefore does not see.",
    "- The law's standard error alone (no scatter term): simulated law rows 81 % within 1 sigma (p68 0.78), but the",
    "  real-capture law rows whose frames spread over the bins 45 % (p68 1.61).",
    "",
    "Left: the simulated rows' 1-sigma is about 3 times too large (median z about 0.2): the prediction interval's",
    "scatter term (the profile bins about the law) is not an error of the law at the block end, but the law's standard",
    "error alone is too small on the 2-bit real captures. The 4 MS/s row of that 12 us sweep (6 frames of 16 samples",
    "per period, profiles of 5 or 6 bins, frames straddling the flyback) stays under-covered. The unit test",
    "(`src/rfi_monitor/test/test_frequency_std.py`) checks the coverage on 48 seeded simulated saw-tooth streams (one",
    "scored block each, half with a period of a whole number of hops), within binomial 3-sigma bands: within 2 sigma",
    "at least 95.45 % less the band (85.8 % for 42 published), within 1 sigma 68.27 % +- the band (47-90 %). Measured:",
    "97.6 % and 76 % (median z 0.44, p95 1.58); with the 1-sigma of ce21bb3 85.7 % and 69 % (p95 3.67), which fails",
    "the first.",
]
"""The analysis below the tables (its figures measured as it says, not by this run)."""


def markdown(covs: list[Coverage], wall_s: float) -> str:
    from doc_paths import portable_path

    import rfi_monitor
    mod = portable_path(Path(rfi_monitor.__file__).resolve().parent)
    sim = [z for c in covs if not c.real for z in c.z]
    real = [z for c in covs if c.real for z in c.z]
    lines = [
        "# rfi_monitor: does a chirp's frequency_std_hz cover its errors? (issue 26 item 3)",
        "",
        "Made by `benchmarks/rfi_monitor_frequency_std.py` (its docstring says which blocks are scored). Normalised",
        "error z = |frequency_hz - truth at the block end| / frequency_std_hz over the published in-band CHIRP",
        "frequencies of the rows of `real_jammers.md` (rows D excepted). A right 1-sigma: median 0.67, p68 1, p95 2,",
        "68 % within 1 sigma, 95 % within 2.",
        "",
        f"- monitor measured: `{mod}` at {git_describe(ROOT / 'src' / 'rfi_monitor')}",
        f"- run time {wall_s:.0f} s on {cpu_model()}",
        "",
        *HEADER,
        f"| simulated | {quantiles(sim)} |",
        f"| real captures + simulated jammer | {quantiles(real)} |",
        f"| all | {quantiles(sim + real)} |",
        "",
        "Per row:",
        "",
        *HEADER,
    ]
    for c in covs:
        lines.append(f"| {c.name} | {quantiles(c.z)} |")
    lines += ["", *NOTES]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="write the markdown here")
    ap.add_argument("--capture-blocks", type=int, default=45, help="blocks per real capture row")
    add_quiet_argument(ap)
    a = ap.parse_args(argv)
    t0 = time.time()
    log = case_log(__file__, quiet=a.quiet)
    covs = run(a.capture_blocks, log)
    md = markdown(covs, time.time() - t0)
    log.say(md)
    if a.out is not None:
        a.out.write_text(md)
    log.finish(f"wrote {a.out}" if a.out is not None else "no --out: nothing written")
    return 0


if __name__ == "__main__":
    sys.exit(main())

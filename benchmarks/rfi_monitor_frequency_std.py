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


NOTES: list[str] = []
"""The analysis below the tables (filled in at the end of the module)."""


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
        lines.append(f"| {'R: ' if c.real else ''}{c.name} | {quantiles(c.z)} |")
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

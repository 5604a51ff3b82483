"""Reference outputs of the ridge analysis and of the whole monitor on simulated streams (issue 26 item 5, issue 28
item 2: ridge.py and integration.py split into their stages, behaviour unchanged).

``python split_reference.py`` writes ``data/split_reference.npz`` from the rfi_monitor package it imports (it was
generated from commit 6657d8c, the last one before the split, and regenerated after each deliberate change listed in
``test_split_equivalence.py``); ``python split_reference.py --check`` compares the
package it imports with that file and prints, per stream, how many values are bit-identical (the test,
``test_split_equivalence.py``, does the same comparison with a tolerance for other machines).

Streams: 160 consecutive 1 ms blocks (stamps 1 ms apart) of three front ends (``FRONT_ENDS``: 38.192 MS/s real IF
9.548 MHz, 10 MS/s complex, 24 MS/s real IF 6 MHz; 8-bit, noise counted over 2 MHz) in four scenarios: noise only,
the paper's saw-tooth chirp (1e12 Hz/s) at J/S 40 dB (J/N 21 dB) from the first block, the same switched on after 80
blocks, and a weak one (J/S 6 dB, J/N -13 dB: found only by the evidence over blocks, its shape by the folded
spectrum) from the first block.
Per block: every field of ``ridge.analyse(x, cplx, fs, RidgeParams())`` (the frame length chosen) and every field of
the ``JammerEstimate`` of ``RfiMonitor.process`` (default parameters, the 8-bit full scale as the node passes it),
its counters included.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REFERENCE = HERE / "data" / "split_reference.npz"

FRONT_ENDS = {
    "real38": dict(sample_rate_hz=38.192e6, intermediate_frequency_hz=9.548e6, is_complex=False),
    "cplx10": dict(sample_rate_hz=10.0e6, intermediate_frequency_hz=0.0, is_complex=True),
    "real24": dict(sample_rate_hz=24.0e6, intermediate_frequency_hz=6.0e6, is_complex=False),
}
SCENARIOS = ("noise", "chirp", "switch", "weak")
N_BLOCKS = 160
BITS = 8


def stream(front_end: str, scenario: str, n_blocks: int = N_BLOCKS):
    """(FrontEndConfig, block length, [(counts, scale)]) of one stream (as benchmarks/rfi_monitor_stages.py makes
    them; seeded)."""
    from rfi_sim.if_signal import ChirpJammer, FrontEndConfig, IfSimulator
    fe = FrontEndConfig(noise_bandwidth_hz=2e6, bits=BITS, **FRONT_ENDS[front_end])
    n = int(round(fe.sample_rate_hz * 1e-3))
    sims = {False: IfSimulator(fe, (), seed=3),
            True: IfSimulator(fe, (ChirpJammer(js_db=6.0 if scenario == "weak" else 40.0),), seed=4)}
    first_jammed = {"noise": n_blocks, "switch": n_blocks // 2}.get(scenario, 0)
    blocks = [sims[k >= first_jammed].generate(n) for k in range(n_blocks)]
    return fe, n, [(blk.counts.copy(), float(blk.scale)) for blk in blocks]


def _row(obj) -> dict[str, float | str]:
    """The fields of a dataclass as numbers (bool and int as float), strings kept, a mapping flattened."""
    row: dict[str, float | str] = {}
    for fld in dataclasses.fields(obj):
        v = getattr(obj, fld.name)
        if v is None:
            continue
        if isinstance(v, str):
            row[fld.name] = v
        elif isinstance(v, dict) or hasattr(v, "items"):
            for key, val in v.items():
                row[f"{fld.name}.{key}"] = float(val)
        else:
            row[fld.name] = float(v)
    return row


def outputs(front_end: str, scenario: str, n_blocks: int = N_BLOCKS) -> dict[str, np.ndarray]:
    """Per field an array over the blocks: ``ridge.<field>`` (analyse) and ``estimate.<field>`` (the monitor)."""
    from rfi_monitor import ridge
    from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams
    fe, n, data = stream(front_end, scenario, n_blocks)
    cplx = bool(fe.is_complex)
    mon = RfiMonitor(RfiMonitorParams())
    rows: list[dict[str, float | str]] = []
    for k, (counts, scale) in enumerate(data):
        x = counts.astype(np.float64) * scale
        z = x[0::2] + 1j * x[1::2] if cplx else x
        r = ridge.analyse(z, cplx, fe.sample_rate_hz, ridge.RidgeParams())
        e = mon.process(x, fe.sample_rate_hz, fe.intermediate_frequency_hz, k * n, 10**9 + k * 10**6,
                        is_complex=cplx, full_scale=(2 ** (BITS - 1) - 1) * scale, bits=BITS)
        row = {f"ridge.{key}": v for key, v in _row(r).items()}
        row.update({f"estimate.{key}": v for key, v in _row(e).items()})
        rows.append(row)
    keys = sorted({key for row in rows for key in row})
    out = {}
    for key in keys:
        vals = [row.get(key, np.nan) for row in rows]
        out[key] = np.asarray(vals, dtype=str if isinstance(vals[0], str) else np.float64)
    return out


def all_outputs(n_blocks: int = N_BLOCKS) -> dict[str, np.ndarray]:
    """``outputs`` of every stream, keys ``<front end>:<scenario>:<field>``."""
    out = {}
    for fe in FRONT_ENDS:
        for sc in SCENARIOS:
            for key, v in outputs(fe, sc, n_blocks).items():
                out[f"{fe}:{sc}:{key}"] = v
    return out


def compare(ref: dict[str, np.ndarray], new: dict[str, np.ndarray], rel: float = 0.0) -> list[str]:
    """Differences between two ``all_outputs`` (missing or extra fields; values beyond rel relative; NaN == NaN)."""
    bad = [f"missing {k}" for k in sorted(set(ref) - set(new))] + [f"extra {k}" for k in sorted(set(new) - set(ref))]
    for key in sorted(set(ref) & set(new)):
        a, b = ref[key], new[key]
        if a.dtype.kind in "US" or b.dtype.kind in "US":
            same = a.astype(str) == b.astype(str)
        else:
            same = (a == b) | (np.isnan(a) & np.isnan(b)) | (np.abs(a - b) <= rel * np.maximum(np.abs(a), np.abs(b)))
        if not np.all(same):
            i = int(np.flatnonzero(~same)[0])
            bad.append(f"{key}: {int(np.sum(~same))} blocks differ, first #{i}: {a[i]!r} != {b[i]!r}")
    return bad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="compare with the stored reference (bit for bit)")
    args = ap.parse_args()
    new = all_outputs()
    if args.check:
        with np.load(REFERENCE) as f:
            ref = {k: f[k] for k in f.files}
        bad = compare(ref, new)
        n_val = sum(v.size for v in ref.values())
        print(f"{len(ref)} fields, {n_val} values over {len(FRONT_ENDS) * len(SCENARIOS)} streams of {N_BLOCKS} "
              f"blocks: {'all bit-identical' if not bad else f'{len(bad)} fields differ'}")
        for line in bad:
            print(line)
        sys.exit(1 if bad else 0)
    np.savez_compressed(REFERENCE, **new)
    print(f"wrote {REFERENCE} ({len(new)} fields)")


if __name__ == "__main__":
    main()

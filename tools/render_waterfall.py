#!/usr/bin/env python3
"""Render the picture rfi_monitor publishes on /rfi/spectrum/waterfall, with the swept band, as a PNG for the docs.

The same code as the node (no ROS needed): :class:`rfi_monitor.monitor.RfiMonitor` analyses a simulated stream
(rfi_sim, seeded; 38.192 MS/s 2-bit real IF as the paper's front end: 1 s without a jammer, 1 s of a CW at -1.3 MHz,
1 s of the paper's saw-tooth chirp, all at J/S 40 dB), and :class:`rfi_monitor.spectrum_view.Waterfall` makes a row
of the spectrum the analysis computed every 20 ms of stamp time (the node defaults to 200 ms; 20 ms fills 150 rows
with 3 s). The
image is drawn as Foxglove's Image panel shows it (grey, newest row on top) with the swept band's edges in red,
and the frequency axis read back from the frame id the node would publish. Run (workspace sourced)::

    python tools/render_waterfall.py            # writes docs/guide/img/waterfall.png

Deterministic: the same PNG content from the same code (seeded simulation, no clock).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rfi_monitor.monitor import RfiMonitor, RfiMonitorParams  # noqa: E402
from rfi_monitor.spectrum_topics import band_segments  # noqa: E402
from rfi_monitor.spectrum_view import Waterfall, parse_axis_frame_id, quantiser_range  # noqa: E402
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'docs' / 'guide' / 'img' / 'waterfall.png'
ROW_S = 0.02
PHASE_S = 1.0


def render(out: Path) -> Path:
    fe = FrontEndConfig(noise_bandwidth_hz=2.0e6)
    size = round(1e-3 * fe.sample_rate_hz)
    phases = [IfSimulator(fe, (), seed=1), IfSimulator(fe, (CwJammer(frequency_hz=-1.3e6, js_db=40.0),), seed=2),
              IfSimulator(fe, (ChirpJammer(js_db=40.0),), seed=3)]
    rows = round(len(phases) * PHASE_S / ROW_S)
    mon = RfiMonitor(RfiMonitorParams(noise_bandwidth_hz=2.0e6))
    w = Waterfall(rows, -80.0, 0.0)
    blocks_per_row = round(ROW_S / 1e-3)
    index = 0
    for k in range(rows):
        sim = phases[min(k * len(phases) // rows, len(phases) - 1)]
        for _ in range(blocks_per_row):       # blocks are analysed continuously; a row takes the latest spectrum
            blk = sim.generate(size)
            est = mon.process(blk.counts.astype(np.float64) * blk.scale, blk.sample_rate_hz,
                              blk.intermediate_frequency_hz, index, round(index / blk.sample_rate_hz * 1e9),
                              bits=blk.bits)
            index += size
        spectrum = mon.last_spectrum
        assert spectrum is not None
        w.add(spectrum, quantiser_range(blk.bits, blk.scale), (est.sweep_start_frequency_hz, est.sweep_bandwidth_hz))
    _, f_lo, f_hi, d_lo, d_hi = parse_axis_frame_id(w.frame_id('rfi_spectrum'))
    img = w.image()
    fig, ax = plt.subplots(figsize=(7.0, 4.2), dpi=110)
    half_col = (f_hi - f_lo) / (w.width - 1) / 2
    extent = ((f_lo - half_col) / 1e6, (f_hi + half_col) / 1e6, rows * ROW_S, 0.0)
    im = ax.imshow(img, cmap='gray', vmin=0, vmax=255, aspect='auto', extent=extent, interpolation='nearest')
    to_mhz = (f_hi - f_lo) / (w.width - 1) / 1e6
    for x0, y0, _, y1 in band_segments(w.band_columns()):
        f = f_lo / 1e6 + x0 * to_mhz
        ax.plot([f, f], [(y0 + 0.5) * ROW_S, (y1 + 0.5) * ROW_S], color='red', lw=1.2)
    ax.set_xlabel('frequency relative to the RF centre, MHz')
    ax.set_ylabel('age of the row, s (newest on top)')
    ax.set_title('/rfi/spectrum/waterfall: noise, then a CW, then a chirp (red: swept band)', fontsize=9)
    cb = fig.colorbar(im, ax=ax, ticks=[0, 64, 128, 191, 255])
    cb.ax.set_yticklabels([f'{d_lo + (d_hi - d_lo) * t / 255:.0f}' for t in (0, 64, 128, 191, 255)])
    cb.set_label('power per bin, dBFS')
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, metadata={'Software': None})
    plt.close(fig)
    assert math.isfinite(f_lo) and math.isfinite(f_hi)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--out', default=str(OUT))
    args = ap.parse_args()
    print(f'wrote {render(Path(args.out))}')


if __name__ == '__main__':
    main()

"""imm_carrier on real correlators: the PocketSDR 4 MHz capture through gnss_correlator's receiver, then the IMM
and the PLL baseline of imm_carrier, clean and with a chirp jammer added to the real samples (issue 29 item 4).

Prints markdown and writes a figure. Usage (after ``source install/setup.bash``)::

    python benchmarks/correlator_imm_real.py [--captures ../shared/data] [--figure docs/gnss_correlator/imm_real.png]

Input: the 0.5-s capture ``iq_clean_pocketsdr/L1_20211202_084700_4MHz_IQ.bin`` under ``--captures`` when given,
else the 150-ms copy of the tests. Spectrum inverted (the receiver's ``spectrum_inverted``).

Jammer: a saw-tooth chirp of rfi_sim (``ChirpJammer``: -1 MHz to +1 MHz in 10 us, the kind of Kang et al.)
generated at 4 MHz complex, normalised to unit power and added, in float, to the 2-bit samples from
``--jam-on-s`` on, at a power ``J/S`` over a 45 dB-Hz satellite of this capture (S = N0 x 10^4.5 with N0 the
capture's noise power per Hz, the variance of its samples over fs). Added after the capture's own 2-bit
quantisation: a real front end would quantise the sum (not modelled here).

Trackers: imm_carrier's core (``CarrierTracker``) with the node's defaults and ``clock_preset`` tcxo (a
PocketSDR front end has a TCXO), IMM and PLL, fed every CorrelatorArray of the receiver. Per PRN over the
last 100 ms: the fraction of intervals with ``locked`` and the cycle slips the tracker counted, for both.

The truth for a jammed run is the clean run on the same samples: the jammed estimate minus the clean one
(each tracker against itself), aligned to its median over the 50 ms before the jammer, unwrapped modulo pi
(a half-cycle slip is a step of pi): its rms over the last 100 ms and the half cycles it ends off by.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from gnss_correlator.receiver import CorrelatorInterval, IfBlock, Receiver, ReceiverConfig
from imm_carrier.layout import BatchColumn
from imm_carrier.node_params import CarrierNodeParams
from imm_carrier.tracker import CarrierTracker
from rfi_sim.if_scene import ChirpJammer, FrontEndConfig
from rfi_sim.if_signal import IfSimulator

ROOT = Path(__file__).resolve().parents[1]
COPY = ROOT / 'src' / 'gnss_correlator' / 'test' / 'data' / 'pocketsdr_L1_4MHz_IQ_150ms.bin'
FULL = 'iq_clean_pocketsdr/L1_20211202_084700_4MHz_IQ.bin'
FS = 4.0e6
GPS = 1


def load(captures: Path | None) -> np.ndarray:
    path = captures / FULL if captures is not None else COPY
    raw = np.fromfile(path, dtype=np.int8).astype(np.float64)
    return raw[0::2] + 1j * raw[1::2]


def chirp(n: int) -> np.ndarray:
    """Unit-power saw-tooth chirp, 4 MHz complex, seeded simulator (no satellite, negligible noise)."""
    fe = FrontEndConfig(sample_rate_hz=FS, intermediate_frequency_hz=0.0, is_complex=True, bits=16,
                        noise_density_dbm_per_mhz=-250.0)
    jam = ChirpJammer(start_frequency_hz=-1.0e6, sweep_rate_hz_per_s=2.0e11, sweep_period_s=1.0e-5, js_db=40.0)
    b = IfSimulator(fe, jammers=(jam,), satellites=(), seed=5).generate(n)
    v = b.counts.astype(np.float64)
    z = v[0::2] + 1j * v[1::2]
    return z / np.sqrt(np.mean(np.abs(z) ** 2))


def correlators(x: np.ndarray) -> list[CorrelatorInterval]:
    rx = Receiver(ReceiverConfig(spectrum_inverted=True))
    out: list[CorrelatorInterval] = []
    block = 40_000
    for i in range(0, x.size, block):
        out += rx.process(IfBlock(stamp_ns=10 ** 18 + round(i / FS * 1e9), sample_rate_hz=FS,
                                  intermediate_frequency_hz=0.0, is_complex=True, first_sample_index=i,
                                  samples=x[i:i + block]))
    return out


def track(intervals: list[CorrelatorInterval], method: str) -> dict[int, np.ndarray]:
    """PRN -> rows (t_s, carrier phase rad, locked, cycle_slips, cn0) of one tracker; the carrier phase is the
    tracker's residual phase plus the accumulated predicted change (the NCO's), i.e. its estimate of the whole
    carrier phase, comparable between runs whose NCOs differ."""
    params = CarrierNodeParams(method='both', clock_preset='tcxo').tracker_params(method)
    tracker = CarrierTracker(params)
    rows: dict[int, list] = {}
    nco: dict[int, float] = {}
    for iv in intervals:
        for sv, d in zip(iv.svid.tolist(), iv.predicted_phase_change_rad.tolist(), strict=True):
            nco[sv] = nco.get(sv, 0.0) + d
        b = tracker.process_arrays(iv.stamp_ns, np.full(iv.svid.size, GPS), iv.svid, iv.integration_time_s,
                                   iv.in_phase, iv.quadrature, iv.cn0_dbhz, iv.predicted_phase_change_rad)
        cn0 = dict(zip(iv.svid.tolist(), iv.cn0_dbhz.tolist(), strict=True))
        for r in b.values:
            sv = int(r[BatchColumn.SVID])
            rows.setdefault(sv, []).append(((iv.stamp_ns - 10 ** 18) / 1e9, r[BatchColumn.PHASE_RAD] + nco[sv],
                                            r[BatchColumn.LOCKED], r[BatchColumn.CYCLE_SLIPS], cn0[sv]))
    return {sv: np.array(v) for sv, v in rows.items()}


def against_clean(r: np.ndarray, clean: np.ndarray, on_s: float, dur_s: float) -> tuple[str, str]:
    """(rms over the last 100 ms, half cycles off at the end) of a jammed run's phase against the clean run's."""
    common, ia, ib = np.intersect1d(np.round(r[:, 0] * 1e6), np.round(clean[:, 0] * 1e6), return_indices=True)
    t = common / 1e6
    d = r[ia, 1] - clean[ib, 1]
    before = (t > on_s - 0.05) & (t <= on_s)
    if not before.any():
        return '-', '-'
    d = np.unwrap(2.0 * (d - np.median(d[before]))) / 2.0  # modulo pi, unwrapped: a half-cycle slip is a step of pi
    last = t > dur_s - 0.1
    return f'{np.sqrt(np.mean(d[last] ** 2)):.2f}', f'{round(float(d[-1]) / np.pi):d}'


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--captures', type=Path, default=None)
    ap.add_argument('--js-db', type=float, nargs='+', default=[20.0, 25.0, 30.0])
    ap.add_argument('--jam-on-s', type=float, default=None, help='jammer switch-on, s (default: half the capture)')
    ap.add_argument('--figure', type=Path, default=None)
    args = ap.parse_args()
    x = load(args.captures)
    dur = x.size / FS
    on = args.jam_on_s if args.jam_on_s is not None else dur / 2
    n0 = float(np.var(x)) / FS
    s45 = n0 * 10 ** 4.5
    j = chirp(x.size)
    j[:int(on * FS)] = 0.0
    variants = [('clean', x)] + [(f'chirp J/S {js:g} dB from {on * 1e3:.0f} ms', x + np.sqrt(s45 * 10 ** (js / 10)) * j)
                                 for js in args.js_db]
    print('# imm_carrier on real correlators (gnss_correlator on the PocketSDR 4 MHz capture)\n')
    print(f'Generated by `python benchmarks/correlator_imm_real.py{" --captures DIR" if args.captures else ""} '
          f'--js-db {" ".join(f"{v:g}" for v in args.js_db)}{" --figure " + args.figure.name if args.figure else ""}`'
          f' (method and caveats: the script\'s docstring and docs/gnss_correlator/README.md).\n')
    print(f'Capture: {dur * 1e3:.0f} ms at 4 MHz; statistics over the last 100 ms.\n')
    print('| variant | PRN | C/N0 (dB-Hz) | IMM locked | IMM slips | IMM vs clean rms (rad) | IMM half cycles off '
          '| PLL locked | PLL slips | PLL vs clean rms (rad) | PLL half cycles off |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    curves: dict[str, dict[str, dict[int, np.ndarray]]] = {}
    for name, xs in variants:
        iv = correlators(xs)
        res = {m: track(iv, m) for m in ('imm', 'pll')}
        for sv in sorted(res['imm']):
            cells = []
            for m in ('imm', 'pll'):
                r = res[m].get(sv)
                if r is None or r.size == 0:
                    cells += ['-'] * 4
                    continue
                last = r[:, 0] > dur - 0.1
                slips = int(r[last, 3].max() - r[last, 3].min()) if last.any() else 0
                cells += [f'{np.mean(r[last, 2]):.2f}' if last.any() else '-', str(slips)]
                clean = curves.get('clean', {}).get(m, {}).get(sv) if name != 'clean' else None
                cells += list(against_clean(r, clean, on, dur)) if clean is not None else ['-', '-']
            r = res['imm'][sv]
            last = r[:, 0] > dur - 0.1
            cn0 = f'{np.median(r[last, 4]):.1f}' if last.any() else '-'
            print(f'| {name} | {sv} | {cn0} | ' + ' | '.join(cells) + ' |')
        curves[name] = res
    if args.figure is not None:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
        sv = 26
        fig, axes = plt.subplots(len(curves), 1, figsize=(8, 2.4 * len(curves)), sharex=True)
        for ax, (name, res) in zip(np.atleast_1d(axes), curves.items(), strict=True):
            for m, style in (('imm', '-'), ('pll', '--')):
                r, clean = res[m].get(sv), curves['clean'][m].get(sv)
                if r is None or clean is None or not r.size:
                    continue
                _, ia, ib = np.intersect1d(np.round(r[:, 0] * 1e6), np.round(clean[:, 0] * 1e6), return_indices=True)
                d = np.unwrap(2.0 * (r[ia, 1] - clean[ib, 1])) / 2.0
                ax.plot(r[ia, 0] * 1e3, d, style, label=m.upper())
            ax.axvline(on * 1e3, color='grey', lw=0.8)
            ax.set_title(f'PRN {sv}: {name}', fontsize=9)
            ax.set_ylabel('vs clean (rad)')
            ax.legend(fontsize=8)
        np.atleast_1d(axes)[-1].set_xlabel('time in capture (ms)')
        fig.tight_layout()
        fig.savefig(args.figure, dpi=110)
        print(f'\nFigure: `{args.figure.name}` (PRN {sv}: each tracker\'s carrier phase minus the clean run\'s, '
              'modulo pi, unwrapped).')


if __name__ == '__main__':
    main()

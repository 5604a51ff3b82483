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

Trackers: the correlator's own PLL (its carrier NCO), and imm_carrier's core (``CarrierTracker``) with the node's
defaults and ``clock_preset`` tcxo (a PocketSDR front end has a TCXO), IMM and PLL, fed every CorrelatorArray of the
receiver (``cn0_dbhz``: the correlator's noise-reference C/N0, which sets imm_carrier's amplitude and noise). Per PRN
over the last 100 ms: the C/N0 (noise reference, and the moments estimator M2M4 for comparison), the fraction of
intervals locked (the correlator's lock rule; imm_carrier's ``locked``) and the slips the trackers counted.

The truth for a jammed run is the clean run on the same samples: the jammed estimate minus the clean one
(each tracker against itself), aligned to its median over the 50 ms before the jammer, unwrapped modulo pi
(a half-cycle slip is a step of pi): its rms over the last 100 ms, the half cycles it ends off by, and the first
time it is half a cycle off or more ("true slip", ms after the jammer's switch-on; for the correlator its NCO's
phase, the accumulated predicted change). Against it: the first interval after the switch-on that the tracker
reports unlocked ("lock lost", ms).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from gnss_correlator.receiver import CorrelatorInterval, IfBlock, Receiver, ReceiverConfig
from gnss_correlator.tracking import TrackingConfig
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


def correlators(x: np.ndarray, coherent_ms: int = 1,
                wrap_block_ms: int = 1) -> tuple[list[CorrelatorInterval], Receiver]:
    rx = Receiver(ReceiverConfig(spectrum_inverted=True, coherent_ms=coherent_ms,
                                 tracking=TrackingConfig(wrap_block_ms=wrap_block_ms)))
    out: list[CorrelatorInterval] = []
    block = 40_000
    for i in range(0, x.size, block):
        out += rx.process(IfBlock(stamp_ns=10 ** 18 + round(i / FS * 1e9), sample_rate_hz=FS,
                                  intermediate_frequency_hz=0.0, is_complex=True, first_sample_index=i,
                                  samples=x[i:i + block]))
    return out, rx


def correlator_rows(intervals: list[CorrelatorInterval]) -> dict[int, np.ndarray]:
    """PRN -> rows (t_s, NCO carrier phase rad, locked, half-cycle wraps, cn0 noise reference, cn0 M2M4) of the
    correlator's own PLL; the NCO phase is the accumulated predicted change (from the channel's first published
    period)."""
    rows: dict[int, list] = {}
    nco: dict[int, float] = {}
    for iv in intervals:
        for k, sv in enumerate(iv.svid.tolist()):
            nco[sv] = nco.get(sv, 0.0) + float(iv.predicted_phase_change_rad[k])
            rows.setdefault(sv, []).append(((iv.stamp_ns - 10 ** 18) / 1e9, nco[sv], float(iv.locked[k]),
                                            iv.half_cycle_wraps[k], iv.cn0_dbhz[k], iv.cn0_m2m4_dbhz[k]))
    return {sv: np.array(v) for sv, v in rows.items()}


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


def against_clean(r: np.ndarray, clean: np.ndarray, on_s: float, dur_s: float) -> tuple[str, str, str, str]:
    """(rms over the last 100 ms, half cycles off at the end, first true slip and first lock loss after the
    switch-on, ms) of a jammed run's phase (column 1; column 2: locked) against the clean run's."""
    common, ia, ib = np.intersect1d(np.round(r[:, 0] * 1e6), np.round(clean[:, 0] * 1e6), return_indices=True)
    t = common / 1e6
    d = r[ia, 1] - clean[ib, 1]
    before = (t > on_s - 0.05) & (t <= on_s)
    if not before.any():
        return '-', '-', '-', '-'
    d = np.unwrap(2.0 * (d - np.median(d[before]))) / 2.0  # modulo pi, unwrapped: a half-cycle slip is a step of pi
    last = t > dur_s - 0.1
    after = t > on_s
    slipped = after & (np.abs(d) >= 0.5 * np.pi)
    unlocked = after & (r[ia, 2] < 0.5)
    first_slip = f'{(t[slipped][0] - on_s) * 1e3:.0f}' if slipped.any() else 'none'
    first_unlock = f'{(t[unlocked][0] - on_s) * 1e3:.0f}' if unlocked.any() else 'none'
    return f'{np.sqrt(np.mean(d[last] ** 2)):.2f}', f'{round(float(d[-1]) / np.pi):d}', first_slip, first_unlock


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--captures', type=Path, default=None)
    ap.add_argument('--js-db', type=float, nargs='+', default=[20.0, 25.0, 30.0])
    ap.add_argument('--jam-on-s', type=float, default=None, help='jammer switch-on, s (default: half the capture)')
    ap.add_argument('--figure', type=Path, default=None)
    ap.add_argument('--coherent-ms', type=int, default=1, choices=(1, 20),
                    help='the receiver\'s coherent_ms (20: one correlator per data bit after bit sync)')
    ap.add_argument('--wrap-block-ms', type=int, default=1, help='the slip detector\'s block (TrackingConfig)')
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
          f'--js-db {" ".join(f"{v:g}" for v in args.js_db)}{" --figure " + args.figure.name if args.figure else ""}'
          f'{" --coherent-ms 20" if args.coherent_ms == 20 else ""}'
          f'{f" --wrap-block-ms {args.wrap_block_ms}" if args.wrap_block_ms != 1 else ""}`'
          f' (method and caveats: the script\'s docstring and docs/gnss_correlator/README.md).\n')
    print(f'Capture: {dur * 1e3:.0f} ms at 4 MHz; statistics over the last 100 ms.\n')
    head_a = ['| variant | PRN | C/N0 noise ref (dB-Hz) | C/N0 M2M4 (dB-Hz) | locked | wraps | NCO vs clean rms (rad) '
              '| NCO half cycles off | first true slip (ms) | lock lost (ms) |',
              '|---|---|---|---|---|---|---|---|---|---|']
    head_b = ['| variant | PRN | ' + ' | '.join(f'{m} {c}' for m in ('IMM', 'PLL') for c in (
        'locked', 'slips', 'vs clean rms (rad)', 'half cycles off', 'first true slip (ms)', 'lock lost (ms)')) + ' |',
        '|---|---|' + '---|' * 12]
    table_a: list[str] = []
    table_b: list[str] = []
    syncs: list[str] = []
    summary: dict[str, list[tuple[str, str, str]]] = {'imm': [], 'pll': [], 'corr': []}
    curves: dict[str, dict[str, dict[int, np.ndarray]]] = {}
    for name, xs in variants:
        iv, rx = correlators(xs, args.coherent_ms, args.wrap_block_ms)
        if name == 'clean':
            syncs = []
            for sv in sorted(rx.tracked_prns):
                h = rx.bit_sync.histogram(sv)
                edge, at = rx.bit_sync.edge(sv), rx.bit_sync.decided_at(sv)
                syncs.append(f'| {sv} | {"-" if at is None else at} | {"-" if edge is None else edge} '
                             f'| {"-" if edge is None else h[edge]} | {h.sum()} |')
        res = {'corr': correlator_rows(iv), 'imm': track(iv, 'imm'), 'pll': track(iv, 'pll')}
        for sv in sorted(res['corr']):
            cells: dict[str, list[str]] = {}
            versus_of: dict[str, tuple[str, str, str, str]] = {}
            for m in ('corr', 'imm', 'pll'):
                r = res[m].get(sv)
                if r is None or r.size == 0:
                    cells[m] = ['-'] * 6
                    continue
                last = r[:, 0] > dur - 0.1
                if m == 'corr':
                    c = [f'{np.nanmedian(r[last, 4]):.1f}' if last.any() else '-',
                         f'{np.nanmedian(r[last, 5]):.1f}' if last.any() and np.isfinite(r[last, 5]).any() else '-',
                         f'{np.mean(r[last, 2]):.2f}' if last.any() else f'dropped at {r[-1, 0] * 1e3:.0f} ms',
                         f'{r[-1, 3]:.0f}' if np.isfinite(r[-1, 3]) else '-']
                else:
                    slips = int(r[last, 3].max() - r[last, 3].min()) if last.any() else 0
                    c = [f'{np.mean(r[last, 2]):.2f}' if last.any() else f'ended at {r[-1, 0] * 1e3:.0f} ms',
                         str(slips)]
                clean = curves.get('clean', {}).get(m, {}).get(sv) if name != 'clean' else None
                if clean is not None:
                    versus = versus_of[m] = against_clean(r, clean, on, dur)
                    c += list(versus)
                else:
                    c += ['-'] * 4
                cells[m] = c
            clean_corr = curves['clean']['corr'].get(sv) if name != 'clean' else None
            if 'corr' in versus_of and clean_corr is not None and clean_corr[-1, 0] > dur - 0.03 \
                    and np.all(clean_corr[clean_corr[:, 0] > dur - 0.1, 2] > 0.5):  # satellites locked when clean
                for m in versus_of:  # (first true slip, its own lock lost, the correlator's lock lost)
                    summary[m].append((versus_of[m][2], versus_of[m][3], versus_of['corr'][3]))
            table_a.append(f'| {name} | {sv} | ' + ' | '.join(cells['corr']) + ' |')
            table_b.append(f'| {name} | {sv} | ' + ' | '.join(cells['imm'] + cells['pll']) + ' |')
        curves[name] = res
    print('## Bit synchronisation (clean run)\n')
    print('Histogram of the prompt\'s sign changes on the 20-period grid (gnss_correlator/bit_sync.py): the period '
          'count of the channel at the decision (~ms since its start), the residue where bits start, the changes '
          'on it and all changes counted over the capture.\n')
    print('| PRN | decided at period | edge residue | changes on it | changes counted |')
    print('|---|---|---|---|---|')
    print('\n'.join(syncs) + '\n')
    print('## C/N0 and lock of the correlator\'s own PLL\n')
    print('C/N0: medians over the last 100 ms; locked: the fraction of those intervals locked by the lock rule '
          '(discriminator std <= 0.5 rad and no half-cycle wrap over the last 100 ms); wraps: in the last window; '
          'the NCO\'s phase against the clean run\'s.\n')
    print('\n'.join(head_a + table_a))
    print('\n## imm_carrier (IMM and PLL) on these correlators\n')
    print('\n'.join(head_b + table_b))
    print('\n## Lock lost where the tracker truly slips (jammed runs; the satellites the clean run keeps locked)\n')
    print('Per tracker, the satellite runs in which it truly slipped (half a cycle off its clean run) and those in '
          'which it did not, against two lock flags: the tracker\'s own and the correlator\'s lock rule.\n')
    print('| tracker | lock flag | runs | truly slipped | lock lost no later than the first true slip '
          '| lost within 20 ms after it | lost later or never | not slipped: lock lost | not slipped: held |')
    print('|---|---|---|---|---|---|---|---|---|')
    for m, label in (('corr', 'correlator NCO'), ('imm', 'IMM'), ('pll', 'imm_carrier PLL')):
        flags = (('correlator lock rule', 2),) if m == 'corr' else (('its own locked', 1), ('correlator lock rule', 2))
        for flag, col in flags:
            rows = summary[m]
            slipped = [(float(r[0]), r[col]) for r in rows if r[0] not in ('none', '-')]
            held = [r[col] for r in rows if r[0] == 'none']
            before = sum(1 for a, b in slipped if b != 'none' and float(b) <= a)
            within = sum(1 for a, b in slipped if b != 'none' and a < float(b) <= a + 20)
            print(f'| {label} | {flag} | {len(rows)} | {len(slipped)} | {before} | {within} '
                  f'| {len(slipped) - before - within} | {sum(1 for b in held if b != "none")} '
                  f'| {sum(1 for b in held if b == "none")} |')
    if args.figure is not None:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
        sv = 26
        fig, axes = plt.subplots(len(curves), 2, figsize=(12, 2.4 * len(curves)), sharex=True, squeeze=False)
        for (ax, ax_c), (name, res) in zip(axes, curves.items(), strict=True):
            for m, style, label in (('imm', '-', 'IMM'), ('pll', '--', 'imm_carrier PLL'),
                                    ('corr', ':', 'correlator NCO')):
                r, clean = res[m].get(sv), curves['clean'][m].get(sv)
                if r is None or clean is None or not r.size:
                    continue
                _, ia, ib = np.intersect1d(np.round(r[:, 0] * 1e6), np.round(clean[:, 0] * 1e6), return_indices=True)
                d = np.unwrap(2.0 * (r[ia, 1] - clean[ib, 1])) / 2.0
                ax.plot(r[ia, 0] * 1e3, d - d[0], style, label=label)
            cr = res['corr'].get(sv)
            if cr is not None and cr.size:
                unlocked = cr[:, 2] < 0.5
                ax.fill_between(cr[:, 0] * 1e3, 0, 1, where=unlocked, color='red', alpha=0.15, step='mid',
                                transform=ax.get_xaxis_transform(), label='correlator unlocked')
                ax_c.plot(cr[:, 0] * 1e3, cr[:, 4], label='noise reference')
                ax_c.plot(cr[:, 0] * 1e3, cr[:, 5], '--', label='M2M4')
            for a_ in (ax, ax_c):
                a_.axvline(on * 1e3, color='grey', lw=0.8)
            ax.set_title(f'PRN {sv}: {name}', fontsize=9)
            ax.set_ylabel('vs clean (rad)')
            ax.legend(fontsize=7)
            ax_c.set_ylabel('C/N0 (dB-Hz)')
            ax_c.legend(fontsize=7)
        axes[-1, 0].set_xlabel('time in capture (ms)')
        axes[-1, 1].set_xlabel('time in capture (ms)')
        fig.tight_layout()
        fig.savefig(args.figure, dpi=110)
        print(f'\nFigure: `{args.figure.name}` (PRN {sv}; left: each tracker\'s carrier phase minus the clean run\'s, '
              'modulo pi, unwrapped, red where the correlator\'s lock rule says unlocked; right: the correlator\'s two '
              'C/N0 estimates).')


if __name__ == '__main__':
    main()

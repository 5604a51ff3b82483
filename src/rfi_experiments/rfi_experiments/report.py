"""The report of a replayed jamming experiment: figures and headline figures against the papers.

:func:`write_report` takes the bag (for its truth topics and the raw inputs) and the outputs of a
replay (:class:`rfi_experiments.replay.ReplayResult`) and writes ``index.md`` with its figures
and ``summary.json`` into a folder. Each section appears when the bag and the outputs carry
what it needs:

- jammer: /rfi/jammer_state against /truth/jammer (type per block, frequency track, sweep period,
  J/S over time);
- positioning: /fusion/odometry (GNSS+UWB) against /truth/position, beside two baselines that the
  report computes itself from the same /gnss/measurements with the package cores (single-point
  positioning and the GNSS-only filter, Cao et al.'s SPP and "GNSS Filter"); errors per J/S phase;
- integrity: /gnss/integrity against /truth/integrity (time to detect a spoofer, false alarms) and
  the fusion's error over the attack (:mod:`rfi_experiments.report_integrity`);
- carrier: /carrier/estimates (IMM and PLL) against /truth/carrier: residual phase error and
  cycle slips (half-cycle for both) per satellite.

A report on a window of the bag (``window_ns``) scores every row on that window: the baselines are
computed from the window's GNSS epochs only, and every positioning method skips the same first
``CONVERGENCE_S`` of it. A figure that has no sample (a window too short for it) is written as
"not scored" with the reason, never left out silently.
"""

from __future__ import annotations

import json
import math
import os
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rfi_experiments.bag_io import BagReader
from rfi_experiments.report_html import save_figure, write_html
from rfi_experiments.report_integrity import integrity_section
from rfi_sim.evaluation import ecef_errors_enu, empirical_cdf, error_3d_m, error_stats, horizontal_error_m

NS = 1e-9
TYPE_NAMES = {0: 'NONE', 1: 'CW', 2: 'CHIRP', 3: 'WIDEBAND', 4: 'UNKNOWN'}
METHOD_NAMES = {1: 'IMM', 2: 'PLL', 3: 'KF'}

DETECTABLE_JN_DB = 6.0
"""Truth J/N from which a jammer counts as detectable, dB: below it the three-sample frequency
measurement is dominated by noise and the monitor is expected to report NONE (docs/rfi_monitor)."""

CONVERGENCE_S = 10.0
"""Time after the replay's first GNSS epoch that no positioning method is scored on (filter
convergence), s. The same for every method, so that every row covers the same span."""

FUSED = 'GNSS+UWB (fusion_node)'
"""Name of the fusion node's row in the positioning tables."""

PAPER_FIGURES = {
    'rfi_rmse': 0.0071,        # Kang et al.: proposed filter frequency RMSE at J/S 30 dB, cycles/sample
    'fusion_goal_m': 0.2,      # issue goal: 3-anchor horizontal RMS up to 22 dB J/S
    'imm_std_deg': 12.0,       # Zhao et al., Fig. 10: std of the main peak at 15 dB-Hz
}


@dataclass
class ReportSummary:
    """Headline figures of a report (also written as summary.json)."""

    rows: list[tuple[str, str, str, str]] = field(default_factory=list)  # (what, measured, paper/goal, note)
    values: dict[str, Any] = field(default_factory=dict)

    def add(self, what: str, measured: str, reference: str, note: str = '') -> None:
        self.rows.append((what, measured, reference, note))

    def table(self) -> str:
        """The rows as a Markdown table; a ``|`` in a cell (``median |error|``) is escaped."""
        lines = ['| figure | this run | paper / goal | note |', '|---|---|---|---|']
        lines += ['| ' + ' | '.join(cell.replace('|', '\\|') for cell in row) + ' |' for row in self.rows]
        return '\n'.join(lines)


def _stamp_s(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * NS


def _read_truth(bag: str | os.PathLike[str], window_ns: tuple[int | None, int | None] = (None, None),
                ) -> dict[str, list[Any]]:
    """The truth topics of the bag (whole: they are looked up by stamp) and its /gnss/measurements
    with log time in ``window_ns`` (the replayed ones: the baselines' input)."""
    truth: dict[str, list[Any]] = defaultdict(list)
    with BagReader(bag) as reader:
        for message in reader.messages([t for t in reader.topics if t.startswith('/truth/')]):
            truth[message.topic].append(message.decode())
        if '/gnss/measurements' in reader.topics:
            for message in reader.messages(['/gnss/measurements'], start_ns=window_ns[0], stop_ns=window_ns[1]):
                truth[message.topic].append(message.decode())
    return truth


def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


# -- jammer ---------------------------------------------------------------------------------------
def _jammer_section(truth: list[Any], estimates: list[Any], out: Path, summary: ReportSummary) -> list[str]:
    by_stamp = {(m.header.stamp.sec, m.header.stamp.nanosec): m for m in truth}
    pairs = [(by_stamp[k], e) for e in estimates
             if (k := (e.header.stamp.sec, e.header.stamp.nanosec)) in by_stamp]
    if not pairs:
        return ['## Jammer', '', 'No /rfi/jammer_state matched a /truth/jammer block.', '']
    t0 = min(_stamp_s(m.header) for m in truth)
    t = np.array([_stamp_s(e.header) - t0 for _, e in pairs])
    f_true = np.array([tr.frequency_hz for tr, _ in pairs])
    f_est = np.array([e.frequency_hz for _, e in pairs])
    p_true = np.array([tr.sweep_period_s for tr, _ in pairs])
    p_est = np.array([e.sweep_period_s for _, e in pairs])
    js_true = np.array([tr.jammer_to_signal_db for tr, _ in pairs])
    js_est = np.array([e.jammer_to_signal_db for _, e in pairs])
    jn_true = np.array([tr.jammer_to_noise_db for tr, _ in pairs])
    types_true = [TYPE_NAMES.get(tr.type, '?') if tr.type == 0 or jn >= DETECTABLE_JN_DB
                  else f'{TYPE_NAMES.get(tr.type, "?")} below {DETECTABLE_JN_DB:g} dB J/N'
                  for (tr, _), jn in zip(pairs, jn_true, strict=True)]
    types_est = [TYPE_NAMES.get(e.type, '?') for _, e in pairs]
    fs = pairs[0][1].sample_rate_hz or pairs[0][0].sample_rate_hz

    confusion: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for a, b in zip(types_true, types_est, strict=True):
        confusion[a][b] += 1
    columns = [c for c in TYPE_NAMES.values() if any(c in row for row in confusion.values())]
    rows = [c for c in TYPE_NAMES.values() if c in confusion]
    rows += sorted(r for r in confusion if r not in TYPE_NAMES.values())
    lines = ['## Jammer (rfi_monitor)', '',
             f'{len(pairs)} IF blocks. Rows: true type (a jammer whose true J/N is below {DETECTABLE_JN_DB:g} dB '
             'is listed apart: the monitor is expected to report NONE there); columns: reported type.', '',
             '| true \\ reported | ' + ' | '.join(columns) + ' |', '|---' * (len(columns) + 1) + '|']
    for a in rows:
        lines.append(f'| {a} | ' + ' | '.join(str(confusion[a].get(b, 0)) for b in columns) + ' |')
    scored = [a for a in confusion if a in TYPE_NAMES.values()]
    correct = sum(confusion[a].get(a, 0) for a in scored)
    n_scored = sum(sum(confusion[a].values()) for a in scored)
    false_alarms = sum(v for b, v in confusion.get('NONE', {}).items() if b not in ('NONE', 'UNKNOWN'))
    n_clean = sum(confusion.get('NONE', {}).values())
    summary.add(f'jammer type right (blocks with no jammer or J/N >= {DETECTABLE_JN_DB:g} dB)',
                f'{correct}/{n_scored}', '', 'per IF snapshot; UNKNOWN while the noise floor is learned counts wrong')
    summary.add('false alarms on jammer-free blocks', f'{false_alarms}/{n_clean}', '0', '')
    summary.values['jammer_type_correct'] = correct
    summary.values['jammer_blocks_scored'] = n_scored
    summary.values['jammer_false_alarms'] = false_alarms

    chirp = np.array([a == 'CHIRP' and b == 'CHIRP' for a, b in zip(types_true, types_est, strict=True)])
    if chirp.any():
        period_err = np.abs(p_est[chirp] / p_true[chirp] - 1.0) * 100.0
        freq_err = f_est[chirp] - f_true[chirp]
        rmse_digital = float(np.sqrt(np.nanmean(freq_err ** 2)) / fs)
        summary.add('sweep period error (median)', f'{np.nanmedian(period_err):.3f} %', '1 % (issue goal)',
                    f'{int(chirp.sum())} chirp blocks reported as chirp')
        summary.add('chirp frequency error at block end (RMS)', f'{rmse_digital:.4f} cycles/sample',
                    f'{PAPER_FIGURES["rfi_rmse"]} (Kang et al., over whole sweeps)',
                    'one value per snapshot, not the per-sample RMSE of the paper')
        summary.values['sweep_period_error_median_pct'] = float(np.nanmedian(period_err))
        summary.values['chirp_frequency_rmse_cycles_per_sample'] = rmse_digital
    jammed = np.isfinite(js_true) & np.isfinite(js_est) & np.array([a != 'NONE' for a in types_est])
    if jammed.any():
        js_err = js_est[jammed] - js_true[jammed]
        summary.add('J/S error where detected (median |error|)', f'{np.median(np.abs(js_err)):.2f} dB', '', '')
        summary.values['js_error_median_abs_db'] = float(np.median(np.abs(js_err)))

    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(10, 9), sharex=True)
    axes[0].plot(t, f_true / 1e6, 'k.', label='truth', ms=6)
    for name, marker in (('CW', 's'), ('CHIRP', 'o'), ('WIDEBAND', 'x'), ('UNKNOWN', '+'), ('NONE', '.')):
        sel = np.array([b == name for b in types_est])
        if sel.any():
            axes[0].plot(t[sel], f_est[sel] / 1e6, marker, ms=4, label=f'reported {name}', alpha=0.8)
    axes[0].set_ylabel('frequency at block end, MHz\n(relative to L1)')
    axes[0].legend(fontsize=7, ncol=3)
    axes[1].plot(t, p_true * 1e6, 'k.', label='truth')
    axes[1].plot(t, p_est * 1e6, 'o', ms=4, label='estimated')
    axes[1].set_ylabel('sweep period, us')
    axes[1].legend(fontsize=7)
    axes[2].plot(t, js_true, 'k.', label='truth')
    # a block reported NONE has no J/S (rfi_monitor publishes NaN there): only the blocks with a reported jammer are
    # drawn, so that no value of a jammer-free block is read as a measured J/S (issue 27 item 5)
    reported = np.array([b != 'NONE' for b in types_est])
    axes[2].plot(t[reported], js_est[reported], 'o', ms=4, label='estimated (blocks with a reported jammer)')
    axes[2].set_ylabel('J/S, dB')
    axes[2].set_xlabel('time, s')
    axes[2].legend(fontsize=7)
    figure = save_figure(fig, plt, out / 'jammer.png',
                         'Jammer frequency track, sweep period and J/S: rfi_monitor against truth')
    lines += ['', 'Figure: the frequency at each block end, the sweep period and the J/S, reported against the truth. '
              'A period is drawn only where the monitor published one (a period it cannot tell from a multiple of a '
              'shorter one is NaN); J/S only for blocks with a reported jammer (a NONE block carries no J/S).']
    return lines + figure


# -- positioning ----------------------------------------------------------------------------------
def _baselines(gnss_msgs: list[Any]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """SPP and the GNSS-only filter on the bag's GNSS epochs: name -> (stamps s, ECEF positions)."""
    from gnss_common.spp import SinglePointPositioner, SppParams
    from rfi_node_common.conversions import msg_to_epoch
    from uwb_gnss_fusion.fusion_filter import FusionFilter, FusionParams

    spp = SinglePointPositioner(SppParams())
    gnss_filter = FusionFilter(FusionParams(use_uwb=False))
    out: dict[str, list[tuple[float, np.ndarray]]] = {'SPP': [], 'GNSS filter': []}
    for msg in gnss_msgs:
        try:
            epoch = msg_to_epoch(msg)
        except ValueError:
            continue
        t = epoch.stamp_ns * NS
        fix = spp.process(epoch)
        if fix.valid:
            out['SPP'].append((t, np.asarray(fix.position_ecef_m, dtype=float)))
            gnss_filter.supply_reference_solution(epoch.stamp_ns, fix.position_ecef_m, 10.0, fix.clock_bias_m)
        result = gnss_filter.process_gnss(epoch)
        if result.initialized and np.all(np.isfinite(result.position_m)):
            out['GNSS filter'].append((t, np.asarray(result.position_m, dtype=float)))
    return {k: (np.array([a for a, _ in v]), np.array([b for _, b in v]).reshape(-1, 3)) for k, v in out.items()}


def _truth_at(truth_t: np.ndarray, truth_p: np.ndarray, t: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(truth_t, t, side='right') - 1, 0, len(truth_t) - 1)
    return truth_p[idx]


def _phase_labels(jammer_truth: list[Any], t: np.ndarray) -> list[str]:
    if not jammer_truth:
        return ['all'] * len(t)
    jt = np.array([_stamp_s(m.header) for m in jammer_truth])
    labels = []
    for m in jammer_truth:
        js = m.jammer_to_signal_db
        labels.append('no jammer' if m.type == 0 or not math.isfinite(js) else
                      f'{TYPE_NAMES.get(m.type, "?")} {js:+.0f} dB')
    idx = np.clip(np.searchsorted(jt, t, side='right') - 1, 0, len(jt) - 1)
    return [labels[i] for i in idx]


def _fusion_section(truth: Mapping[str, list[Any]], odometry: list[Any], out: Path,
                    summary: ReportSummary) -> list[str]:
    """Positioning errors of the fusion node and of the two baselines, over the same span.

    ``truth['/gnss/measurements']`` holds the GNSS epochs that were replayed (the run's window):
    the baselines are computed from those only, and every method is scored from the replay's
    first GNSS epoch (or first output) plus :data:`CONVERGENCE_S`. A method with no sample there
    gets a row that says so.
    """
    truth_pos = truth.get('/truth/position', [])
    if not truth_pos or truth_pos[0].header.frame_id != 'earth':
        return ['## Positioning', '', 'No ECEF /truth/position in the bag: no error figures.', '']
    truth_t = np.array([_stamp_s(m.header) for m in truth_pos])
    truth_p = np.array([[m.point.x, m.point.y, m.point.z] for m in truth_pos])
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    gnss = truth.get('/gnss/measurements', [])
    if gnss:
        series.update(_baselines(gnss))
    earth = [m for m in odometry if m.header.frame_id == 'earth']
    positions = [[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z] for m in earth]
    series[FUSED] = (np.array([_stamp_s(m.header) for m in earth]), np.array(positions).reshape(-1, 3))
    # the replay's start: its first GNSS epoch, else the node's first output
    t0 = _stamp_s(gnss[0].header) if gnss else float(series[FUSED][0][0]) if earth else float(truth_t[0])
    stops = [float(t[-1]) for t, _ in series.values() if len(t)]
    span_s = (max(stops) - t0) if stops else 0.0
    lines = ['## Positioning (uwb_gnss_fusion)', '',
             'GNSS+UWB is the node\'s /fusion/odometry. SPP and the GNSS filter are computed by the report from the '
             'same replayed /gnss/measurements with the package cores (Cao et al.\'s baselines). Every method is '
             f'scored on the same span: from {CONVERGENCE_S:g} s after the replay\'s first GNSS epoch (convergence '
             f'excluded) to its end ({span_s:.1f} s of data replayed). Horizontal RMS per jamming phase, m:', '']
    jammer_truth = truth.get('/truth/jammer', [])
    per_phase: dict[str, dict[str, float]] = {}
    errors: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    missing: dict[str, str] = {}
    order: list[str] = []
    for name, (t, p) in series.items():
        if len(t) == 0:
            missing[name] = 'no estimate in the replay' if name == FUSED else 'no valid solution in the replay'
            continue
        enu = ecef_errors_enu(p, _truth_at(truth_t, truth_p, t))
        h, e3 = horizontal_error_m(enu), error_3d_m(enu)
        keep = (t - t0 >= CONVERGENCE_S) & np.isfinite(h)
        if not keep.any():
            missing[name] = (f'no sample after the first {CONVERGENCE_S:g} s (convergence) of a {span_s:.1f} s '
                             'replay: replay a longer window')
            summary.values[f'positioning_samples[{name}]'] = 0
            continue
        errors[name] = (t[keep] - t0, h[keep], e3[keep])
        summary.values[f'positioning_samples[{name}]'] = int(keep.sum())
        labels = _phase_labels(jammer_truth, t[keep])
        for label in labels:
            if label not in order:
                order.append(label)
        for label in set(labels):
            sel = np.array([lab == label for lab in labels])
            per_phase.setdefault(name, {})[label] = error_stats(h[keep][sel]).rms_m
    summary.values['positioning_scored_from_s'] = t0 + CONVERGENCE_S
    if order:
        lines.append('| method | ' + ' | '.join(order) + ' |')
        lines.append('|---' * (len(order) + 1) + '|')
        for name in errors:
            lines.append(f'| {name} | ' + ' | '.join(
                f'{per_phase[name][lab]:.3f}' if lab in per_phase[name] else 'no sample' for lab in order) + ' |')
        lines += ['', '| method | horizontal RMS | horizontal 95 % | horizontal max | 3D RMS | 3D 95 % |',
                  '|---|---|---|---|---|---|']
    for name, (_, h, e3) in errors.items():
        sh, s3 = error_stats(h), error_stats(e3)
        lines.append(f'| {name} | {sh.rms_m:.3f} | {sh.p95_m:.3f} | {sh.max_m:.3f} | {s3.rms_m:.3f} | {s3.p95_m:.3f} |')
        summary.values[f'horizontal_rms_m[{name}]'] = sh.rms_m
    if missing:
        lines += ['', '| method | not scored |', '|---|---|']
        lines += [f'| {name} | {why} |' for name, why in missing.items()]
    if not jammer_truth:  # no jamming experiment: the jamming goal has no phase to score
        if FUSED in errors:
            summary.add('GNSS+UWB horizontal RMS (no jammer truth in the bag)',
                        f'{error_stats(errors[FUSED][1]).rms_m:.3f} m', '', 'the whole scored span')
    elif FUSED in errors:
        worst = max((v for k, v in per_phase[FUSED].items() if not k.endswith('+30 dB')), default=math.nan)
        summary.add('GNSS+UWB horizontal RMS, worst phase up to 22 dB', f'{worst:.3f} m',
                    f'< {PAPER_FIGURES["fusion_goal_m"]} m (issue goal, 3 anchors)', '')
        summary.values['fusion_worst_phase_rms_up_to_22db_m'] = worst
    else:
        summary.add('GNSS+UWB horizontal RMS, worst phase up to 22 dB', 'not scored',
                    f'< {PAPER_FIGURES["fusion_goal_m"]} m (issue goal, 3 anchors)', missing.get(FUSED, ''))
    if 'SPP' in errors:
        summary.add('SPP horizontal RMS (all phases)', f'{error_stats(errors["SPP"][1]).rms_m:.2f} m', '',
                    'the unaided baseline, same span')
    elif gnss:
        summary.add('SPP horizontal RMS (all phases)', 'not scored', '', missing.get('SPP', ''))
    if not errors:
        return lines + ['']

    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    for name, (t, h, e3) in errors.items():
        axes[0].semilogy(t, np.maximum(h, 1e-3), '.', ms=2, label=name)
        x, y = empirical_cdf(e3)
        axes[1].semilogx(np.maximum(x, 1e-3), y, label=name)
    axes[0].set_xlabel('time, s')
    axes[0].set_ylabel('horizontal error, m')
    axes[0].legend(fontsize=8, markerscale=4)
    axes[1].set_xlabel('3D error, m')
    axes[1].set_ylabel('CDF')
    axes[1].grid(True, which='both', alpha=0.3)
    axes[1].legend(fontsize=8)
    return lines + save_figure(fig, plt, out / 'positioning.png', 'Positioning error under the jamming schedule',
                               'Positioning error under the jamming schedule: horizontal error over time and CDF of '
                               'the 3D error')


# -- carrier --------------------------------------------------------------------------------------
def _carrier_section(truth_msgs: list[Any], estimates: list[Any], out: Path, summary: ReportSummary) -> list[str]:
    from imm_carrier.cycle_slips import count_cycle_slips

    truth: dict[int, dict[tuple[int, int], float]] = defaultdict(dict)
    cn0: dict[int, list[float]] = defaultdict(list)
    for msg in truth_msgs:
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        for c in msg.estimates:
            truth[c.svid][key] = c.phase_rad
    est: dict[tuple[int, int], dict[tuple[int, int], float]] = defaultdict(dict)
    locked: dict[tuple[int, int], int] = defaultdict(int)
    for msg in estimates:
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        for c in msg.estimates:
            if math.isfinite(c.phase_rad):  # judged whether or not the tracker claims lock
                est[(c.svid, c.method)][key] = c.phase_rad
                locked[(c.svid, c.method)] += bool(c.locked)
    del cn0
    if not est:
        return ['## Carrier phase (imm_carrier)', '', 'No /carrier/estimates to evaluate.', '']
    lines = ['## Carrier phase (imm_carrier)', '',
             'Residual phase error against /truth/carrier after removing the initial half-cycle ambiguity; '
             'slips counted in half cycles for both trackers (imm_carrier.cycle_slips). Every estimate with a '
             'finite phase is judged, whether or not the tracker reports lock.', '',
             '| satellite | tracker | epochs | reported locked | phase error std, deg | half-cycle slips |',
             '|---|---|---|---|---|---|']
    results = {}
    for (svid, method), series in sorted(est.items()):
        keys = [k for k in series if k in truth[svid]]
        if len(keys) < 60:
            continue
        keys.sort()
        e = np.array([series[k] for k in keys])
        tr = np.array([truth[svid][k] for k in keys])
        slips = count_cycle_slips(e, tr)
        std_deg = float(np.degrees(np.std(slips.phase_error_rad)))
        name = METHOD_NAMES.get(method, str(method))
        results[(svid, name)] = (keys, slips, std_deg)
        lines.append(f'| {svid} | {name} | {len(keys)} | {100.0 * locked[(svid, method)] / len(series):.0f} % '
                     f'| {std_deg:.1f} | {slips.count} |')
    if not results:
        return lines[:2] + ['No satellite has 60 estimates matched with /truth/carrier in this replay (1.2 s at '
                            '50 Hz): the carrier figures need a longer window.', '']
    imm = {sv: r for (sv, m), r in results.items() if m == 'IMM'}
    pll = {sv: r for (sv, m), r in results.items() if m == 'PLL'}
    if imm:
        summary.add('IMM half-cycle slips (all satellites)', str(sum(r[1].count for r in imm.values())),
                    '0 (Zhao et al.)', '')
        worst = max(r[2] for r in imm.values())
        summary.add('IMM phase error std, worst satellite', f'{worst:.1f} deg',
                    f'<= {PAPER_FIGURES["imm_std_deg"]} deg (Zhao et al., 15 dB-Hz)', '')
        summary.values['imm_slips'] = sum(r[1].count for r in imm.values())
        summary.values['imm_worst_std_deg'] = worst
    if pll:
        summary.add('PLL half-cycle slips (all satellites)', str(sum(r[1].count for r in pll.values())),
                    'slips (Zhao et al., Fig. 14)', 'the baseline')
        summary.values['pll_slips'] = sum(r[1].count for r in pll.values())

    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(10, 7))
    worst = max(pll, key=lambda sv: pll[sv][2]) if pll else (max(imm, key=lambda sv: imm[sv][2]) if imm else None)
    for (svid, name), (keys, slips, _) in sorted(results.items()):
        if svid != worst:
            continue
        t = np.array([k[0] + k[1] * NS for k in keys])
        axes[0].plot(t - t[0], np.degrees(slips.phase_error_rad + slips.ambiguity * math.pi), lw=0.6,
                     label=f'{name}: {slips.count} half-cycle slips')
    axes[0].set_xlabel('time, s')
    axes[0].set_ylabel('phase error incl. slips, deg')
    axes[0].set_title(f'PRN {worst}, the satellite where the PLL does worst (a slip is a 180 deg step)')
    axes[0].legend(fontsize=8)
    svids = sorted({sv for sv, _ in results})
    width = 0.4
    for i, name in enumerate(('IMM', 'PLL')):
        stds = [results[(sv, name)][2] if (sv, name) in results else np.nan for sv in svids]
        axes[1].bar(np.arange(len(svids)) + (i - 0.5) * width, stds, width, label=name)
    axes[1].set_xticks(np.arange(len(svids)), [f'PRN {sv}' for sv in svids])
    axes[1].set_ylabel('phase error std, deg')
    axes[1].axhline(PAPER_FIGURES['imm_std_deg'], color='k', ls=':', lw=1, label='12 deg (Zhao et al.)')
    axes[1].legend(fontsize=8)
    return lines + save_figure(fig, plt, out / 'carrier.png', 'Carrier phase: IMM against PLL on the same correlators',
                               'Carrier phase: IMM against PLL on the same correlators (phase error of the worst '
                               'satellite, error std per satellite)')


def write_report(bag: str | os.PathLike[str], outputs: Mapping[str, list[Any]], out_dir: str | os.PathLike[str],
                 *, header: str = '', window_ns: tuple[int | None, int | None] = (None, None)) -> ReportSummary:
    """Write index.md, figures and summary.json for a replay of ``bag`` into ``out_dir``.

    Args:
        bag: the replayed bag (its truth topics and /gnss/measurements are read).
        outputs: topic -> deserialised messages the nodes published (ReplayResult.messages).
        out_dir: report folder (created).
        header: Markdown put at the top (run statistics).
        window_ns: the log times [start, stop) that were replayed, ns (None: unbounded); the
            positioning baselines are computed from the GNSS epochs of that window only, so that
            every row covers what the nodes saw.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    truth = _read_truth(bag, window_ns)
    summary = ReportSummary()
    lines = [f'# Jamming experiment: {Path(bag).name}', '', header, '']
    body: list[str] = []
    if truth.get('/truth/jammer') and outputs.get('/rfi/jammer_state'):
        body += _jammer_section(truth['/truth/jammer'], list(outputs['/rfi/jammer_state']), out, summary)
    if outputs.get('/fusion/odometry') or truth.get('/gnss/measurements'):
        body += _fusion_section(truth, list(outputs.get('/fusion/odometry', [])), out, summary)
    if truth.get('/truth/integrity') and outputs.get('/gnss/integrity'):
        body += integrity_section(truth, outputs, out, summary, _plt())
    if truth.get('/truth/carrier') and outputs.get('/carrier/estimates'):
        body += _carrier_section(truth['/truth/carrier'], list(outputs['/carrier/estimates']), out, summary)
    lines += ['## Headline figures', '', summary.table(), ''] + body
    (out / 'index.md').write_text('\n'.join(lines) + '\n')
    write_html(out / 'index.md')
    (out / 'summary.json').write_text(json.dumps(summary.values, indent=2, sort_keys=True) + '\n')
    return summary

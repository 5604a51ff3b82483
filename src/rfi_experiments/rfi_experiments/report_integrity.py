"""The integrity section of a replay report: what gnss_integrity said, and what the fusion did with it.

Called by :func:`rfi_experiments.report.write_report` when the replay published /gnss/integrity and
the bag carries /truth/integrity (a spoofing scenario, rfi_experiments/attacks.py). It scores:

- the spoofing state over time against the truth: time from the attack's start to the first
  SUSPECTED and the first DETECTED epoch, and DETECTED epochs before the attack (false alarms);
- the fusion's horizontal error (/fusion/odometry against /truth/position) before the attack and
  over it, with the span where the fusion excluded GNSS (/fusion/status ``gnss_excluded``);

and draws both on one figure (``integrity.png``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from rfi_experiments.report_html import save_figure
from rfi_sim.evaluation import ecef_errors_enu, horizontal_error_m

STATE_NAMES = {0: 'unknown', 1: 'none', 2: 'suspected', 3: 'detected'}
DETECTION_GOAL_S = 10.0
"""Issue 25: a 1 m/s push detected within 10 s with at least one anchor."""
MAX_ERROR_GOAL_M = 1.0
"""Issue 25: fused horizontal error at most 1 m over the attack with three anchors."""


def _s(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def integrity_section(truth: Mapping[str, list[Any]], outputs: Mapping[str, list[Any]], out: Path,
                      summary: Any, plt: Any) -> list[str]:
    """Markdown lines of the section (``summary`` gets its headline rows); empty without its inputs."""
    reports = list(outputs.get('/gnss/integrity', []))
    truth_int = truth.get('/truth/integrity', [])
    if not reports or not truth_int:
        return []
    attacked = [m for m in truth_int if m.spoofing_state == 3]
    t0 = min(_s(m.header) for m in truth_int)
    attack_s = (_s(attacked[0].header) - t0) if attacked else math.inf
    t = np.array([_s(m.header) - t0 for m in reports])
    state = np.array([m.spoofing_state for m in reports])
    first = {name: next((float(x) for x, s in zip(t, state, strict=True) if s >= level and x >= attack_s), math.inf)
             for name, level in (('suspected', 2), ('detected', 3))}
    false_detections = int(np.count_nonzero((state == 3) & (t < attack_s)))
    lines = ['## Integrity (gnss_integrity)', '',
             f'Attack from {attack_s:.1f} s (the bag\'s /truth/integrity). The node\'s spoofing state per GNSS epoch: '
             + ', '.join(f'{STATE_NAMES[k]} {int(np.count_nonzero(state == k))}' for k in STATE_NAMES) + '.', '']
    delay = {k: v - attack_s for k, v in first.items()}
    lines += ['| what | value |', '|---|---|',
              f'| first SUSPECTED after the attack\'s start | {delay["suspected"]:.1f} s |',
              f'| first DETECTED after the attack\'s start | {delay["detected"]:.1f} s |',
              f'| DETECTED epochs before the attack | {false_detections} |']
    summary.add('spoofing detected after the attack\'s start', f'{delay["detected"]:.1f} s',
                f'<= {DETECTION_GOAL_S:g} s (issue 25, >= 1 anchor)', f'{false_detections} detections before it')
    summary.values['spoofing_detection_delay_s'] = delay['detected']
    summary.values['spoofing_false_detections'] = false_detections
    fired: dict[str, int] = {}
    for m in reports:
        if m.spoofing_state == 3:
            for test in m.tests:
                if test.decision >= 2 and test.category != 1:
                    fired[test.name] = fired.get(test.name, 0) + 1
    if fired:
        lines += ['', 'Tests at SUSPECT or ALARM in the DETECTED epochs: '
                  + ', '.join(f'{k} ({v})' for k, v in sorted(fired.items(), key=lambda kv: -kv[1])) + '.']
    err = _fusion_errors(truth, outputs, t0)
    excluded = _excluded(outputs, t0)
    if err is not None:
        te, h = err
        before = h[(te >= 10.0) & (te < attack_s)]
        during = h[te >= attack_s]
        rms = {k: float(np.sqrt(np.mean(v**2))) if v.size else math.nan for k, v in (('before', before),
                                                                                    ('during', during))}
        worst = float(during.max()) if during.size else math.nan
        lines += ['', '| fusion horizontal error | RMS | max |', '|---|---|---|',
                  f'| before the attack (from 10 s) | {rms["before"]:.3f} m | '
                  f'{float(before.max()) if before.size else math.nan:.3f} m |',
                  f'| over the attack | {rms["during"]:.3f} m | {worst:.3f} m |']
        if excluded is not None and excluded[1].any():
            tx, on = excluded
            lines.append(f'\nThe fusion excluded GNSS from {float(tx[on][0]):.1f} s '
                         f'({int(np.count_nonzero(on))} of {on.size} status messages).')
        summary.add('GNSS+UWB horizontal RMS over the attack / before it',
                    f'{rms["during"]:.3f} / {rms["before"]:.3f} m', '<= 2x the clean run (issue 25)',
                    'before-attack span as the clean reference')
        summary.add('GNSS+UWB horizontal max over the attack', f'{worst:.3f} m',
                    f'<= {MAX_ERROR_GOAL_M:g} m (issue 25, 3 anchors)', '')
        summary.values['fusion_rms_before_attack_m'] = rms['before']
        summary.values['fusion_rms_over_attack_m'] = rms['during']
        summary.values['fusion_max_over_attack_m'] = worst
    return lines + _figure(t, state, attack_s, err, excluded, out, plt)


def _fusion_errors(truth: Mapping[str, list[Any]], outputs: Mapping[str, list[Any]],
                   t0: float) -> tuple[np.ndarray, np.ndarray] | None:
    pos = truth.get('/truth/position', [])
    odo = [m for m in outputs.get('/fusion/odometry', []) if m.header.frame_id == 'earth']
    if not pos or not odo:
        return None
    tt = np.array([_s(m.header) for m in pos])
    tp = np.array([[m.point.x, m.point.y, m.point.z] for m in pos])
    t = np.array([_s(m.header) for m in odo])
    p = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z] for m in odo])
    idx = np.clip(np.searchsorted(tt, t, side='right') - 1, 0, len(tt) - 1)
    return t - t0, horizontal_error_m(ecef_errors_enu(p, tp[idx]))


def _excluded(outputs: Mapping[str, list[Any]], t0: float) -> tuple[np.ndarray, np.ndarray] | None:
    status = list(outputs.get('/fusion/status', []))
    if not status:
        return None
    return (np.array([_s(m.header) - t0 for m in status]),
            np.array([getattr(m, 'gnss_excluded', 0) != 0 for m in status]))


def _figure(t: np.ndarray, state: np.ndarray, attack_s: float, err, excluded, out: Path, plt: Any) -> list[str]:
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    axes[0].step(t, state, where='post', label='gnss_integrity spoofing state')
    axes[0].set_yticks(list(STATE_NAMES), [STATE_NAMES[k] for k in STATE_NAMES])
    if math.isfinite(attack_s):
        for ax in axes:
            ax.axvline(attack_s, color='r', ls='--', lw=1, label='attack starts' if ax is axes[0] else None)
    axes[0].legend(fontsize=8, loc='upper left')
    if err is not None:
        te, h = err
        axes[1].semilogy(te, np.maximum(h, 1e-3), '.', ms=2, label='GNSS+UWB (fusion_node)')
    if excluded is not None and excluded[1].any():
        tx, on = excluded
        axes[1].fill_between(tx, 1e-3, 1e3, where=on, color='0.85', step='post', label='GNSS excluded')
    axes[1].set_ylim(1e-3, 1e3)
    axes[1].set_xlabel('time, s')
    axes[1].set_ylabel('horizontal error, m')
    axes[1].legend(fontsize=8, loc='upper left', markerscale=4)
    title = 'Spoofing: what gnss_integrity reported and what the fusion did with it'
    return save_figure(fig, plt, out / 'integrity.png', title,
                       f'{title} (spoofing state, fusion horizontal error)')

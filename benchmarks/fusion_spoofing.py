"""Benchmark: the GNSS/UWB fusion under spoofing, with and without the integrity monitor acting on it
(issue 25, item 4 and its goals).

A closed loop in process, in stamp order, of what the nodes do (``fusion_core.FusionCore.process`` /
``_apply_integrity`` and the gnss_integrity core):

* the simulated default-like scenario (``rfi_sim.gnss_uwb.simulate``: static receiver at ARL1, GPS L1 at
  5 Hz from the ARL1 broadcast ephemeris, three UWB anchors at 20 Hz each, no jammer) with an attack
  injected into its GNSS epochs by ``rfi_sim.spoofing.apply_attack`` (+3 dB single-transmitter C/N0, the
  attack's defaults);
* ``IntegrityMonitor.process_epoch`` judges the (unfiltered) epoch; its report becomes the
  ``IntegrityVerdict`` the node's ``verdict_of`` would make of the published message. As the node's
  re-ordering buffer releases it (a verdict before the measurements of the same stamp), the verdict of
  epoch k is applied before epoch k, as ``FusionCore._apply_integrity`` applies it: with the node's own
  ``uwb_gnss_fusion.spoofing_response.SpoofingResponse`` (exclusion; at an exclusion of all GNSS the
  roll-back to before the first alarm, else the re-anchor on UWB; ``use_gnss`` false on the held side of
  the anchors' plane while all GNSS is out; the node's parameters at a readmission); the SPP cache is
  cleared at an exclusion; the report's C/N0 J/S goes to the filter;
* each GNSS epoch then goes through ``GnssExclusion.filter_epoch``; what is left goes into the SPP
  reference cache and ``FusionFilter.process_gnss`` (the filter built as the node builds it:
  ``FusionNodeParams().fusion_params()``, the SPP reference solved on demand);
* each UWB range goes to ``FusionFilter.process_uwb`` and ``IntegrityMonitor.add_uwb``.

The monitor takes no input from the fusion, so its reports are computed once per attacked run and
anchor set and replayed into every fusion variant at their place in the stamp order (the same as
calling it inside the loop).

Metrics over the attack (``start_s`` to the end of the run) against the clean run (same seed, no attack)
over the same span: the horizontal error of the position a consumer holds at each GNSS epoch (the last
output of the filter at or before the epoch: GNSS epochs and UWB ranges both produce one; none before the
first initialisation or after a reset to uninitialised: "available"), RMS and max; the time of the first
DETECTED (and SUSPECTED) after the start; the error held when the exclusion began; the time GNSS was
excluded; readmissions; re-initialisations of the filter during the attack; DETECTED / SUSPECTED epochs
before the attack (false alarms).

What-if rows (push only) measure alternatives to the shipped behaviour: the verdict applied after the epoch
of its stamp (the node before commit fe95fe1), a static platform's motion model and a near-zero velocity
(the parameter ``accel_psd_m2ps3``), and the re-anchor without the roll-back (``integrity_rollback_s`` 0).
They are measurements for a decision, not
the shipped behaviour.

Usage:
    source .venv/bin/activate && source install/setup.bash
    python benchmarks/fusion_spoofing.py [--seeds 5] [--jobs 2]

Writes the tables into docs/gnss_integrity/fusion_spoofing.md (between the ``results`` markers; the prose
around them is by hand) and fusion_spoofing_*.png next to it; prints the tables. About 20 min on two cores
(``--no-what-if``: about half).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import pickle
import platform
import subprocess
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from bench_progress import CaseLog, add_quiet_argument, case_log

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from gnss_common.integrity_codes import STATE_DETECTED, STATE_SUSPECTED
from gnss_common.observations import GnssEpoch
from gnss_common.spp import SinglePointPositioner
from gnss_integrity.monitor import IntegrityMonitor, IntegrityReport
from rfi_sim.gnss_uwb import BroadcastGeometry, GnssUwbRun, GnssUwbScenario, simulate
from rfi_sim.spoofing import apply_attack
from rfi_sim.spoofing_attack import SpoofingAttack
from uwb_gnss_fusion.fusion_filter import FRAME_EARTH, FusionFilter, FusionOutput
from uwb_gnss_fusion.fusion_node_params import FusionNodeParams
from uwb_gnss_fusion.integrity_policy import (
    IntegrityVerdict,
    integrity_jammer_to_signal,
)
from uwb_gnss_fusion.spoofing_response import SpoofingResponse
from uwb_gnss_fusion.spp_reference import SppReferenceCache

ROOT = Path(__file__).resolve().parents[1]
NAV = ROOT / "src" / "rfi_experiments" / "data" / "arlm2000.15n"
OUT = ROOT / "docs" / "gnss_integrity"
NS = 1_000_000_000
START_S = 60.0
ANCHOR_CASES = (0, 1, 3)
PUSH = "position push 1 m/s E"
ENDING = "position push 1 m/s E, 60-100 s"
BEGIN, END = "<!-- results: begin -->", "<!-- results: end -->"
"""The generated tables sit between these lines of docs/gnss_integrity/fusion_spoofing.md (the rest is prose)."""


@dataclasses.dataclass(frozen=True)
class Case:
    """An attack and the length of the run it is injected into."""

    attack: SpoofingAttack
    duration_s: float = 180.0


CASES = {
    PUSH: Case(SpoofingAttack(kind="position_push", start_s=START_S, push_velocity_enu_mps=(1.0, 0.0, 0.0))),
    "time push 100 ns/s": Case(SpoofingAttack(kind="time_push", start_s=START_S, time_push_ns_per_s=100.0)),
    "meaconing 100 m E, 2 us": Case(SpoofingAttack(kind="meaconing", start_s=START_S,
                                                   meacon_offset_enu_m=(100.0, 0.0, 0.0))),
    ENDING: Case(SpoofingAttack(kind="position_push", start_s=START_S, end_s=100.0,
                                push_velocity_enu_mps=(1.0, 0.0, 0.0)), duration_s=480.0),
}
"""The attacks (+3 dB single-transmitter C/N0, consistent Doppler: the defaults). The ending push runs 480 s so
that a readmission can be seen. A one-constellation (Galileo-only) case is skipped: the simulator is GPS-only."""


@dataclasses.dataclass(frozen=True)
class Config:
    """One fusion configuration.

    Attributes:
        name: its label in the tables.
        node_params: :class:`FusionNodeParams` overrides (empty: the node's defaults).
        verdict_after: apply the verdict of epoch k after the fusion applied epoch k (the node before commit
            fe95fe1, whose re-ordering buffer released a verdict after the measurements of its stamp); False:
            before it, as the node now does.
    """

    name: str
    node_params: tuple[tuple[str, object], ...] = ()
    verdict_after: bool = False


DEFAULTS = Config("node defaults")
STATIC = (("accel_psd_m2ps3", 0.01),)
AFTER_CONFIG = Config("verdict after its epoch (node before fe95fe1)", verdict_after=True)
STATIC_CONFIG = Config("static motion model (accel_psd 0.01)", node_params=STATIC)
NO_ROLLBACK = Config("re-anchor only, no roll-back (integrity_rollback_s 0, the node before e41252d)",
                     node_params=(("integrity_rollback_s", 0.0),))
WHAT_IF = (
    AFTER_CONFIG,
    STATIC_CONFIG,
    NO_ROLLBACK,
    Config("near-zero velocity (accel_psd 1e-4)", node_params=(("accel_psd_m2ps3", 1e-4),)),
)
"""What-if configurations, run on the push (the doc says what each one stands for). The core changes P1
(re-initialise from UWB first at a divergence), P2 (the roll-back to before the first alarm), P3 (the
filter told that all GNSS is excluded) and the verdict-first order (P4), emulated here before, are now the
shipped behaviour (node defaults: ``uwb_gnss_fusion.spoofing_response``)."""


def report_verdict(r: IntegrityReport) -> IntegrityVerdict:
    """What the node's ``verdict_of`` makes of the message the integrity node publishes from ``r``."""
    return IntegrityVerdict(r.stamp_ns, int(r.spoofing_state), int(r.spoofing_scope),
                            tuple(int(c) for c in r.affected_constellations),
                            tuple((int(c), int(s)) for c, s in r.affected_satellites),
                            int(r.jamming_state), float(r.jammer_to_signal_db), int(r.first_alarm_ns))


def run_scenario(seed: int, duration_s: float) -> GnssUwbRun:
    geo = BroadcastGeometry(NAV)
    return simulate(GnssUwbScenario(duration_s=duration_s, seed=seed), geo, geo.iono_alpha, geo.iono_beta)


def merged(epochs: Sequence[GnssEpoch], run: GnssUwbRun, anchors: int) -> list[tuple[int, int, object]]:
    """``(kind, epoch index, message)`` in stamp order: GNSS epochs (kind 0) and the ranges of the first
    ``anchors`` anchors (kind 1), an epoch before a range of the same stamp (as ``GnssUwbRun.messages``)."""
    ids = {f"A{j + 1}" for j in range(anchors)}
    items: list[tuple[int, int, int, object]] = [(e.stamp_ns, 0, k, e) for k, e in enumerate(epochs)]
    items += [(u.stamp_ns, 1, 0, u) for u in run.uwb_ranges if u.anchor_id in ids]
    items.sort(key=lambda t: (t[0], t[1]))
    return [(kind, k, m) for _, kind, k, m in items]


def monitor_reports(items: list[tuple[int, int, object]], n_epochs: int) -> list[IntegrityReport]:
    """The integrity monitor over the stream (ranges through ``add_uwb``), one report per GNSS epoch."""
    mon = IntegrityMonitor()
    reports: list[IntegrityReport | None] = [None] * n_epochs
    for kind, k, m in items:
        if kind:
            mon.add_uwb(m)  # type: ignore[arg-type]
        else:
            reports[k] = mon.process_epoch(m)  # type: ignore[arg-type]
    assert all(r is not None for r in reports)
    return reports  # type: ignore[return-value]


@dataclasses.dataclass
class FusionRun:
    """One fusion replay, per GNSS epoch: the held position (ECEF, m; NaN: none), whether GNSS was excluded,
    the cumulative re-initialisations; and the counts."""

    held_ecef_m: np.ndarray
    excluded: np.ndarray
    reinit_at: np.ndarray
    counts: dict[str, int]
    exclusion_counts: dict[str, int]
    first_exclusion_k: int | None
    readmit_ks: list[int]


def run_fusion(items: list[tuple[int, int, object]], n_epochs: int, reports: Sequence[IntegrityReport] | None,
               config: Config = DEFAULTS) -> FusionRun:
    """The fusion node's core over the stream (module docstring); ``reports`` None: no integrity input.
    What the node does with a verdict is :class:`SpoofingResponse`, the node's own implementation."""
    params = FusionNodeParams(**dict(config.node_params))
    spp_cache = SppReferenceCache(SinglePointPositioner(), params.reference_max_age_s)
    use_spp = params.use_spp_reference and params.use_gnss
    provider = spp_cache.reference if use_spp else None
    response = SpoofingResponse(params.integrity_readmit_clean_s, reports is not None and params.act_on_integrity,
                                params.integrity_rollback_s)
    exclusion = response.exclusion
    filt = FusionFilter(response.filter_params(params.fusion_params()), reference_provider=provider)
    held = np.full((n_epochs, 3), np.nan)
    excluded = np.zeros(n_epochs, dtype=bool)
    reinit_at = np.zeros(n_epochs, dtype=int)
    state: dict[str, object] = {"pos": None, "reinits": 0, "first": None}
    readmit_ks: list[int] = []

    def hold(out: FusionOutput) -> None:
        state["reinits"] = out.reinitializations
        if out.initialized and out.frame_id == FRAME_EARTH and out.is_finite():
            state["pos"] = out.position_m.copy()
        elif not out.initialized:
            state["pos"] = None

    def apply(k: int) -> None:
        """FusionCore._apply_integrity."""
        assert reports is not None
        verdict = report_verdict(reports[k])
        done = response.apply(verdict, filt, params.fusion_params())
        if done.change == "excluded":
            spp_cache.clear()  # the SPP reference must not bring the spoofed position back
            if state["first"] is None:
                state["first"] = k
        elif done.change == "readmitted":
            readmit_ks.append(k)
        if params.act_on_integrity:
            js = integrity_jammer_to_signal(verdict)
            if js is not None:  # no SDR monitor in this loop: the C/N0 J/S always applies
                filt.set_jammer_to_signal(verdict.stamp_ns, js)

    for kind, k, m in items:
        if kind:
            hold(filt.process_uwb(m))  # type: ignore[arg-type]
            response.after_message(m.stamp_ns, filt, m)  # type: ignore[attr-defined]
            continue
        if reports is not None and not config.verdict_after:
            apply(k)  # the node: a verdict is released before the measurements of its stamp
        epoch, _ = exclusion.filter_epoch(m)  # type: ignore[arg-type]
        excluded[k] = epoch is None
        if epoch is not None:
            if use_spp:
                spp_cache.add(epoch)
            hold(filt.process_gnss(epoch))
        response.after_message(m.stamp_ns, filt)  # type: ignore[attr-defined]
        if reports is not None and config.verdict_after:
            apply(k)
        if state["pos"] is not None:
            held[k] = state["pos"]
        reinit_at[k] = state["reinits"]
    first = state["first"]
    return FusionRun(held, excluded, reinit_at, dict(filt.rejection_counts), dict(exclusion.counts),
                     first if isinstance(first, int) else None, readmit_ks)


def horizontal_error(held_ecef_m: np.ndarray, truth_ecef_m: np.ndarray) -> np.ndarray:
    """Horizontal error of each held position (ENU at the first true position), m (NaN: none held)."""
    lat, lon, _ = ecef_to_geodetic(truth_ecef_m[0])
    rot = ecef_to_enu_rotation(lat, lon)
    enu = (held_ecef_m - truth_ecef_m) @ rot.T
    return np.hypot(enu[:, 0], enu[:, 1])


def span_stats(err: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """RMS and max of the finite errors in ``mask``, and the fraction that is finite ("available")."""
    e = err[mask]
    ok = np.isfinite(e)
    if not ok.any():
        return {"rms": math.nan, "max": math.nan, "avail": 0.0}
    return {"rms": float(np.sqrt(np.mean(e[ok] ** 2))), "max": float(np.max(e[ok])), "avail": float(ok.mean())}


def one_seed(seed: int, cases: Sequence[str], anchor_cases: Sequence[int], what_if: bool,
             quiet: bool = False) -> list[dict]:
    """Every (case, anchors, configuration, variant) of one seed: rows of metrics with the error series (a
    progress line per case on stderr unless ``quiet``; run in a worker process)."""
    log = CaseLog(f"{Path(__file__).stem} seed {seed}", len(cases), quiet=quiet)
    rows: list[dict] = []
    runs: dict[float, GnssUwbRun] = {}
    clean_cache: dict[tuple, tuple[np.ndarray, FusionRun]] = {}
    for name in cases:
        case = CASES[name]
        if case.duration_s not in runs:
            runs[case.duration_s] = run_scenario(seed, case.duration_s)
        run = runs[case.duration_s]
        truth = run.truth.receiver_ecef_m_per_epoch
        t_s = (run.truth.gnss_stamps_ns - run.truth.gnss_stamps_ns[0]) / NS
        span = t_s >= START_S
        end_s = case.attack.end_s
        epochs, attack_truth = apply_attack(run.gnss_epochs, case.attack, run.truth.receiver_ecef_m, seed=seed)
        offset_m = np.linalg.norm(attack_truth.position_offset_enu_m[:, :2], axis=1)
        configs = [DEFAULTS, *(WHAT_IF if what_if and name == PUSH else ())]
        for anchors in anchor_cases:
            clean_items = merged(run.gnss_epochs, run, anchors)
            items = merged(epochs, run, anchors)
            reports = monitor_reports(items, len(epochs))
            states = np.array([r.spoofing_state for r in reports])
            k_det = next((k for k in range(len(t_s)) if span[k] and states[k] >= STATE_DETECTED), None)
            k_sus = next((k for k in range(len(t_s)) if span[k] and states[k] >= STATE_SUSPECTED), None)
            base = {
                "seed": seed, "case": name, "anchors": anchors,
                "detect_s": math.inf if k_det is None else float(t_s[k_det] - START_S),
                "suspect_s": math.inf if k_sus is None else float(t_s[k_sus] - START_S),
                "offset_at_detection_m": math.nan if k_det is None else float(offset_m[k_det]),
                "false_detected": int(np.sum((states >= STATE_DETECTED) & ~span)),
                "false_suspected": int(np.sum((states == STATE_SUSPECTED) & ~span)),
                "detected_after_end_s": (float(np.sum((states >= STATE_DETECTED) & (t_s >= end_s)))
                                         / run.scenario.gnss_rate_hz) if end_s is not None else math.nan,
                "t_s": t_s,
            }
            for config in configs:
                key = (case.duration_s, anchors, config.node_params)
                if key not in clean_cache:
                    fr = run_fusion(clean_items, len(epochs), None, config=config)
                    clean_cache[key] = (horizontal_error(fr.held_ecef_m, truth), fr)
                clean_err, clean_fr = clean_cache[key]
                clean = span_stats(clean_err, span)
                variants = ["clean", "no integrity", "integrity"] if config is DEFAULTS else ["clean", "integrity"]
                for variant in variants:
                    if variant == "clean":
                        fr, err = clean_fr, clean_err
                    else:
                        rep = None if variant == "no integrity" else reports
                        fr = run_fusion(items, len(epochs), rep, config=config)
                        err = horizontal_error(fr.held_ecef_m, truth)
                    st = span_stats(err, span)
                    integ = variant.startswith("integrity")
                    k_ex = fr.first_exclusion_k
                    rows.append({
                        **base, "config": config.name, "variant": variant,
                        "rms": st["rms"], "max": st["max"], "avail": st["avail"],
                        "clean_rms": clean["rms"], "clean_max": clean["max"],
                        "err_at_exclusion": float(err[k_ex]) if integ and k_ex is not None else math.nan,
                        "excluded_s": float(np.sum(fr.excluded[span])) / run.scenario.gnss_rate_hz,
                        "excluded_before_s": float(np.sum(fr.excluded[~span])) / run.scenario.gnss_rate_hz,
                        "excluded_after_end_s": (float(np.sum(fr.excluded[t_s >= end_s])) / run.scenario.gnss_rate_hz
                                                 if end_s is not None else math.nan),
                        "readmit_s": [float(t_s[k]) for k in fr.readmit_ks],
                        "reinits": int(fr.reinit_at[-1] - fr.reinit_at[int(np.argmax(span))]),
                        "err": err, "excluded": fr.excluded,
                    })
        log.done(name)
    return rows


# ---------------------------------------------------------------------------------------------- tables
def _f(x: float, nd: int = 2) -> str:
    if math.isinf(x):
        return "never"
    if math.isnan(x):
        return "-"
    return f"{x:.{nd}f}"


def _groups(rows: list[dict], keys: tuple[str, ...]) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def main_table(rows: list[dict], config: str = DEFAULTS.name) -> str:
    """Per (case, anchors, variant): mean horizontal RMS over the seeds, the clean run's, the per-seed ratio
    (median and range), the worst max, availability, detection, exclusion, readmissions, re-initialisations."""
    head = ("| attack | anchors | fusion | horizontal RMS (m) | clean RMS (m) | RMS / clean, median (range) "
            "| max (m) | available | detected after (s) | error at exclusion (m) | GNSS excluded (s) "
            "| readmissions | re-inits |")
    lines = [head, "|" + "---|" * 13]
    for (case, anchors, variant), rs in _groups([r for r in rows if r["config"] == config],
                                                ("case", "anchors", "variant")).items():
        ratio = np.array([r["rms"] / r["clean_rms"] for r in rs])
        integ = variant.startswith("integrity")
        det = [r["detect_s"] for r in rs]
        lines.append(
            f"| {case} | {anchors} | {variant} | {_f(float(np.mean([r['rms'] for r in rs])))} "
            f"| {_f(float(np.mean([r['clean_rms'] for r in rs])))} "
            f"| {_f(float(np.median(ratio)), 1)} ({_f(float(np.min(ratio)), 1)}-{_f(float(np.max(ratio)), 1)}) "
            f"| {_f(max(r['max'] for r in rs))} | {_f(float(np.mean([r['avail'] for r in rs])))} "
            f"| {_f(min(det), 1) + '-' + _f(max(det), 1) if integ else '-'} "
            f"| {_f(float(np.nanmax([r['err_at_exclusion'] for r in rs]))) if integ else '-'} "
            f"| {_f(float(np.mean([r['excluded_s'] for r in rs])), 1) if integ else '-'} "
            f"| {sum(len(r['readmit_s']) for r in rs) if integ else '-'} | {sum(r['reinits'] for r in rs)} |")
    return "\n".join(lines)


def detection_table(rows: list[dict]) -> str:
    """The monitor alone, per (case, anchors): detection and suspicion times, the spoofer's offset then, and
    false alarms before the attack (over all seeds)."""
    head = ("| attack | anchors | first SUSPECTED after start (s) | first DETECTED after start (s) "
            "| spoofed offset at detection (m) | DETECTED before the attack (epochs) "
            "| SUSPECTED before the attack (epochs) |")
    lines = [head, "|" + "---|" * 7]
    sel = [r for r in rows if r["config"] == DEFAULTS.name and r["variant"] == "clean"]
    for (case, anchors), rs in _groups(sel, ("case", "anchors")).items():
        sus = [r["suspect_s"] for r in rs]
        det = [r["detect_s"] for r in rs]
        lines.append(f"| {case} | {anchors} | {_f(min(sus), 1)}-{_f(max(sus), 1)} "
                     f"| {_f(min(det), 1)}-{_f(max(det), 1)} "
                     f"| {_f(float(np.nanmax([r['offset_at_detection_m'] for r in rs])), 1)} "
                     f"| {sum(r['false_detected'] for r in rs)} | {sum(r['false_suspected'] for r in rs)} |")
    return "\n".join(lines)


def goal_table(rows: list[dict]) -> str:
    """Issue 25's goals on the push, seed by seed, for every configuration with the integrity monitor: with
    >= 1 anchor detected within 10 s and RMS over the attack <= 2x the clean run's, with 3 anchors max <= 1 m;
    GNSS alone (0 anchors) detected before the spoofed position is 50 m off."""
    head = ("| fusion | anchors | detected <= 10 s | offset at detection <= 50 m | RMS <= 2x clean | max <= 1 m "
            "| detected after (s) per seed | RMS / clean per seed | max (m) per seed |")
    lines = [head, "|" + "---|" * 9]
    sel = [r for r in rows if r["case"] == PUSH and r["variant"] == "integrity"]
    for (config, anchors), rs in _groups(sel, ("config", "anchors")).items():
        n = len(rs)
        det = sum(r["detect_s"] <= 10.0 for r in rs)
        off = sum(r["offset_at_detection_m"] <= 50.0 for r in rs)
        rms_ok = sum(r["rms"] <= 2.0 * r["clean_rms"] for r in rs)
        max_ok = sum(r["max"] <= 1.0 for r in rs)
        lines.append(f"| {config} | {anchors} | {det}/{n} | {off}/{n} | {rms_ok}/{n} | {max_ok}/{n} "
                     f"| {', '.join(_f(r['detect_s'], 1) for r in rs)} "
                     f"| {', '.join(_f(r['rms'] / r['clean_rms'], 1) for r in rs)} "
                     f"| {', '.join(_f(r['max']) for r in rs)} |")
    return "\n".join(lines)


def what_if_table(rows: list[dict]) -> str:
    """The push under each configuration: mean RMS, its clean RMS, worst max, availability, re-inits."""
    head = ("| fusion | anchors | run | horizontal RMS (m) | clean RMS (m) | RMS / clean, median (range) | max (m) "
            "| available | re-inits |")
    lines = [head, "|" + "---|" * 9]
    sel = [r for r in rows if r["case"] == PUSH and r["variant"] != "no integrity"]
    for (config, anchors, variant), rs in _groups(sel, ("config", "anchors", "variant")).items():
        ratio = np.array([r["rms"] / r["clean_rms"] for r in rs])
        spread = f"{_f(float(np.min(ratio)), 1)}-{_f(float(np.max(ratio)), 1)}"
        lines.append(f"| {config} | {anchors} | {variant} | {_f(float(np.mean([r['rms'] for r in rs])))} "
                     f"| {_f(float(np.mean([r['clean_rms'] for r in rs])))} "
                     f"| {_f(float(np.median(ratio)), 1)} ({spread}) "
                     f"| {_f(max(r['max'] for r in rs))} | {_f(float(np.mean([r['avail'] for r in rs])))} "
                     f"| {sum(r['reinits'] for r in rs)} |")
    return "\n".join(lines)


def ending_table(rows: list[dict]) -> str:
    """The push that stops at 100 s: what stays excluded after the spoofer left, and the readmissions."""
    head = ("| anchors | fusion | horizontal RMS 60 s-end (m) | clean RMS (m) | max (m) | monitor DETECTED after the "
            "spoofer left (s) | GNSS excluded after it left (s) | readmitted at (s) |")
    lines = [head, "|" + "---|" * 8]
    sel = [r for r in rows if r["case"] == ENDING and r["config"] == DEFAULTS.name and r["variant"] != "clean"]
    for (anchors, variant), rs in _groups(sel, ("anchors", "variant")).items():
        integ = variant.startswith("integrity")
        lines.append(
            f"| {anchors} | {variant} | {_f(float(np.mean([r['rms'] for r in rs])))} "
            f"| {_f(float(np.mean([r['clean_rms'] for r in rs])))} | {_f(max(r['max'] for r in rs))} "
            f"| {_f(float(np.mean([r['detected_after_end_s'] for r in rs])), 0)} "
            f"| {_f(float(np.mean([r['excluded_after_end_s'] for r in rs])), 0) if integ else '-'} "
            f"| {'; '.join(', '.join(f'{t:.0f}' for t in r['readmit_s']) or 'none' for r in rs) if integ else '-'} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- figures
def figures(rows: list[dict], out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []

    def pick(case, anchors, config, variant, seed):
        want = (case, anchors, config, variant, seed)
        return next((r for r in rows if (r["case"], r["anchors"], r["config"], r["variant"], r["seed"]) == want),
                    None)

    seeds = sorted({r["seed"] for r in rows})
    # 1: the push, clean / attacked / protected, per anchor count (first seed)
    anchor_list = sorted({r["anchors"] for r in rows if r["case"] == PUSH})
    if anchor_list:
        fig, axes = plt.subplots(1, len(anchor_list), figsize=(5.5 * len(anchor_list), 4.2), sharey=True,
                                 squeeze=False)
        for ax, anchors in zip(axes[0], anchor_list, strict=True):
            for variant, style in (("clean", "k-"), ("no integrity", "r-"), ("integrity", "b-")):
                r = pick(PUSH, anchors, DEFAULTS.name, variant, seeds[0])
                if r is not None:
                    ax.semilogy(r["t_s"], np.maximum(r["err"], 1e-3), style, lw=1,
                                label={"integrity": "with gnss_integrity"}.get(variant, variant))
            r = pick(PUSH, anchors, DEFAULTS.name, "clean", seeds[0])
            if r is not None and math.isfinite(r["detect_s"]):
                ax.axvline(START_S + r["detect_s"], color="g", ls=":", lw=1, label="DETECTED")
            ax.axvline(START_S, color="grey", ls="--", lw=0.8)
            ax.set_title(f"{anchors} UWB anchor{'s' if anchors != 1 else ''}")
            ax.set_xlabel("time (s); push from 60 s")
            ax.set_ylim(1e-3, 500)
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].set_ylabel("fused horizontal error (m)")
        axes[0][0].legend(loc="upper left", fontsize=8)
        fig.suptitle(f"1 m/s east push, +3 dB, consistent Doppler (seed {seeds[0]}; node defaults)")
        fig.tight_layout()
        path = out_dir / "fusion_spoofing_push.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    # 2: 3 anchors, the first seconds of the push, node defaults vs the what-ifs (the seed with the worst max)
    cand = [r for r in rows if r["case"] == PUSH and r["anchors"] == 3 and r["config"] == DEFAULTS.name
            and r["variant"] == "integrity"]
    if cand:
        seed = max(cand, key=lambda r: r["max"])["seed"]
        fig, ax = plt.subplots(figsize=(8, 4.2))
        for config, variant, style in ((DEFAULTS.name, "no integrity", "r-"),
                                       (DEFAULTS.name, "integrity", "b-"),
                                       (AFTER_CONFIG.name, "integrity", "m--"),
                                       (STATIC_CONFIG.name, "integrity", "c-"),
                                       (DEFAULTS.name, "clean", "k-")):
            r = pick(PUSH, 3, config, variant, seed)
            if r is not None:
                sel = (r["t_s"] >= 55) & (r["t_s"] <= 75)
                ax.plot(r["t_s"][sel], r["err"][sel], style, lw=1, label=f"{config}, {variant}")
        r = pick(PUSH, 3, DEFAULTS.name, "clean", seed)
        if r is not None:
            ax.axvline(START_S + r["detect_s"], color="g", ls=":", lw=1, label="DETECTED")
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.set_ylim(0, 2.0)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("fused horizontal error (m)")
        ax.set_title(f"3 anchors, push from 60 s (seed {seed}): the first seconds")
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(True, alpha=0.3)
        fig.tight_layout()
        path = out_dir / "fusion_spoofing_3_anchors.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    # 3: the ending push: error and exclusion
    end_anchors = sorted({r["anchors"] for r in rows if r["case"] == ENDING})
    if end_anchors:
        fig, axes = plt.subplots(len(end_anchors), 1, figsize=(9, 2.6 * len(end_anchors)), sharex=True,
                                 squeeze=False)
        for ax, anchors in zip(axes[:, 0], end_anchors, strict=True):
            for variant, style in (("clean", "k-"), ("no integrity", "r-"), ("integrity", "b-")):
                r = pick(ENDING, anchors, DEFAULTS.name, variant, seeds[0])
                if r is not None:
                    ax.semilogy(r["t_s"], np.maximum(r["err"], 1e-3), style, lw=1, label=variant)
            r = pick(ENDING, anchors, DEFAULTS.name, "integrity", seeds[0])
            if r is not None:
                ax.fill_between(r["t_s"], 1e-3, 500, where=r["excluded"], color="orange", alpha=0.25,
                                label="GNSS excluded")
            ax.axvspan(START_S, 100.0, color="red", alpha=0.08, label="spoofer on")
            ax.set_ylim(1e-3, 500)
            ax.set_ylabel(f"{anchors} anchors: error (m)")
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].legend(fontsize=7, loc="upper right", ncol=3)
        axes[-1][0].set_xlabel("time (s)")
        fig.suptitle(f"push 60-100 s, then authentic signals (seed {seeds[0]})")
        fig.tight_layout()
        path = out_dir / "fusion_spoofing_ending.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


LOAD_AT_START = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan


def provenance(wall_s: float, jobs: int) -> str:
    """What was measured and on what: the commit (and whether the measured sources carry uncommitted changes),
    wall and CPU time, the CPU, the host's load (other jobs share it), versions."""
    paths = ("src/uwb_gnss_fusion", "src/gnss_integrity", "src/rfi_sim", "src/gnss_common")
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", *paths], cwd=ROOT, capture_output=True,
                               text=True, timeout=10).stdout.strip()
        commit = f"commit {head}" + (" with uncommitted changes in the measured packages" if dirty else " (clean)")
    except (OSError, subprocess.SubprocessError):
        commit = "unknown commit"
    cpu = "unknown CPU"
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                   if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    used = sum(os.times()[:4])
    return (f"fusion, monitor and simulator of {commit}, as installed in the workspace; {wall_s:.0f} s wall time "
            f"with {jobs} workers, {used:.0f} s CPU, on {cpu} ({os.cpu_count()} cores, shared: 1-min load average "
            f"{LOAD_AT_START:.1f} at the start, {os.getloadavg()[0]:.1f} at the end); Python "
            f"{platform.python_version()}, numpy {np.__version__}")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds 1..n")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (one seed each)")
    ap.add_argument("--cases", nargs="*", default=list(CASES), help="attack cases (names of CASES)")
    ap.add_argument("--anchors", nargs="*", type=int, default=list(ANCHOR_CASES))
    ap.add_argument("--no-what-if", action="store_true", help="skip the what-if configurations")
    ap.add_argument("--no-write", action="store_true", help="print the tables only")
    ap.add_argument("--save", type=Path, default=None, help="pickle the rows (with error series) here")
    ap.add_argument("--load", type=Path, default=None,
                    help="tables and figures from rows saved with --save (no simulation)")
    add_quiet_argument(ap)
    args = ap.parse_args(argv)
    log = case_log(__file__, total=None if args.load is not None else args.seeds, quiet=args.quiet)
    unknown = set(args.cases) - set(CASES)
    if unknown:
        ap.error(f"unknown cases {sorted(unknown)}; known: {list(CASES)}")
    rows: list[dict] = []
    if args.load is not None:
        with open(args.load, "rb") as fh:
            saved = pickle.load(fh)
        rows, args.jobs, args.seeds, host = saved["rows"], saved["jobs"], saved["seeds"], saved["host"]
    else:
        t0 = time.perf_counter()
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futures = [pool.submit(one_seed, s, args.cases, args.anchors, not args.no_what_if, args.quiet)
                       for s in range(1, args.seeds + 1)]
            for s, f in enumerate(futures, 1):
                rows.extend(f.result())
                log.done(f"seed {s}: every case")
        host = provenance(time.perf_counter() - t0, args.jobs)
    if args.save is not None:
        with open(args.save, "wb") as fh:
            pickle.dump({"rows": rows, "host": host, "jobs": args.jobs, "seeds": args.seeds}, fh)
    sections = [
        ("Fusion, node defaults", main_table([r for r in rows if r["case"] != ENDING])),
        ("The monitor alone", detection_table(rows)),
        ("Goal (issue 25) on the push, seed by seed", goal_table(rows)),
        ("What-if configurations on the push", what_if_table([r for r in rows if r["config"] != DEFAULTS.name
                                                                or r["case"] == PUSH])),
        ("A push that stops at 100 s (run of 480 s)", ending_table(rows)),
    ]
    text = "\n\n".join(f"### {title}\n\n{table}" for title, table in sections)
    seeds = f"seeds 1-{args.seeds}"
    log.say(text)
    log.say(f"\n{seeds}; {host}")
    if not args.no_write:
        OUT.mkdir(parents=True, exist_ok=True)
        block = (f"{BEGIN}\n_Generated by `python benchmarks/fusion_spoofing.py --seeds {args.seeds}` ({seeds}; "
                 f"{host}). Do not edit between the markers: the benchmark rewrites it._\n\n{text}\n{END}")
        doc = OUT / "fusion_spoofing.md"
        old = doc.read_text() if doc.exists() else "# Fusion under spoofing\n\n"
        if BEGIN in old and END in old:
            new = old[:old.index(BEGIN)] + block + old[old.index(END) + len(END):]
        else:
            new = old.rstrip("\n") + "\n\n## Results\n\n" + block + "\n"
        doc.write_text(new)
        written = [f"wrote {path.relative_to(ROOT)}" for path in figures(rows, OUT)]
        log.finish(*written, f"wrote the tables into {doc.relative_to(ROOT)}")
    else:
        log.finish("--no-write: docs/ left unchanged")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Scenario stream ``rinex_jammed``: real RINEX GPS observations with simulated jamming on top, plus UWB.

The half-simulated set-up of Cao et al. (Sec. IV) on real data: the GPS L1 C/A pseudoranges,
Doppler and C/N0 of a real station (RINEX obs + nav, converted exactly as ``rinex_to_bag`` does)
are degraded per a J/S schedule, and three simulated UWB anchors range to the station's surveyed
position. Section keys (all optional)::

    rinex_jammed:
      obs_file: null                 # RINEX obs (null: the installed ARL1 copy arlm200a.15o, see below)
      nav_file: null                 # RINEX nav (null: the installed ARL1 copy arlm2000.15n)
      start_offset_s: 0.0            # skip this much of the file: the stream starts at the first epoch
                                     # at or after first_epoch + start_offset_s, s
      elevation_mask_deg: 10.0       # real satellites below are dropped (seen from the header position), deg
      uwb_rate_hz: 20.0              # ranging rate per anchor, Hz (anchors interleaved)
      anchors:                       # as gnss_uwb: the paper's three reference ranges around the station
        - {range_m: 11.71, azimuth_deg: 20.0, up_m: 1.5}
        - {range_m: 13.00, azimuth_deg: 140.0, up_m: -0.5}
        - {range_m: 11.26, azimuth_deg: 260.0, up_m: 0.8}
      uwb_noise_std_m: 0.03          # UWB range noise 1-sigma, m
      uwb_reported_std_m: .nan       # range_std_m written in /uwb/ranges, m (.nan or null: the filter decides)
      cn0_zenith_dbhz: 49.0          # elevation model of the jammer-free C/N0, used only for a
      cn0_horizon_dbhz: 34.0         #   satellite without S1 (e.g. GEONET files), dB-Hz
      truth_jammer_state: true       # also write /truth/jammer_state (1 s period)
      jamming:                       # consecutive phases from the start, as gnss_uwb
        - {jsr_db: null, duration_s: 600.0}
        - {jsr_db: 22.0}             # the last phase may omit duration_s

Each phase's ``duration_s`` must be a whole number of UWB periods; the phases cover the
scenario's ``duration_s``, which must fit in the file (first used epoch + duration_s <= last epoch
+ the file's epoch interval).

What is real and what is simulated, per GNSS epoch (one per RINEX epoch, at its real receive time:
nothing is resampled, so GNSS is sparse here, 30 s apart for the ARL1 file, while UWB comes at
``uwb_rate_hz`` over the same span):

* real: pseudorange, Doppler rate, satellite states, broadcast clock, Klobuchar / Saastamoinen
  delays (``rfi_experiments.rinex_to_bag.convert_rinex``) and the jammer-free C/N0 (RINEX S1; an
  elevation model ``cn0_horizon + (cn0_zenith - cn0_horizon) sin(el)`` when S1 is absent, as the
  GNSS/UWB simulator);
* simulated, only in a phase with a jammer (a phase with ``jsr_db: null`` passes the real
  observations through untouched):

  - effective C/N0 of eq. 4 (``gnss_common.jamming_weights.effective_cn0_dbhz``) from the
    real C/N0, plus the receiver's C/N0 estimation error
    (``rfi_sim.gnss_uwb.JammingEffect.cn0_estimate_std_db``); this is the C/N0 written
    (NaN stays NaN for a file without S1);
  - loss of lock: satellites whose estimated effective C/N0 is below
    ``JammingEffect.loss_of_lock_dbhz`` are dropped;
  - the *extra* tracking jitter, the real data already holding the jammer-free jitter:
    ``sqrt(sigma(C/N0_eff)^2 - sigma(C/N0)^2)`` with the DLL (code) and FLL (Doppler) formulas of
    ``gnss_common.jamming_weights`` (without their floors, which are already in the real
    errors);
  - outlier bursts from ``JammingEffect.outlier_onset_jsr_db`` (6 dB) on, with the simulator's
    rate, growth, duration and magnitudes. The simulator draws a burst start per 0.2 s epoch;
    with 30 s epochs that discrete process would be sampled far too coarsely, so here the same
    bursts are drawn in continuous time (Poisson starts at the burst rate, uniform durations,
    log-uniform magnitudes with one sign for code and Doppler, per satellite and phase), and an
    epoch carries the error of a burst that covers it. The fraction of time in a burst is the
    simulator's.

* ``/uwb/ranges``: anchors placed by ``rfi_sim.gnss_uwb.anchor_positions_ecef`` around
  the header position, Gaussian noise, anchors interleaved within each UWB period as in the
  simulator.
* ``/truth/position``: the header APPROX POSITION XYZ (the station's published coordinate) at
  every GNSS epoch; ``/truth/jammer_state`` at each phase start and every second, as gnss_uwb.

Files: ``obs_file: null`` / ``nav_file: null`` resolve ``share/rfi_experiments/data/`` through the
ament index, else the source tree's ``src/rfi_experiments/data`` (ARL1, 2015-07-19, SGL-UT/gnsstk,
LGPL-3.0; see data/README.md). A relative path is taken relative to the scenario file.

Random numbers: one generator per purpose spawned from ``seed`` (GNSS, UWB); the GNSS draws are
made for every satellite of every epoch, tracked or not, so one satellite's numbers do not depend
on another's lock state.

Notes
-----
Cao et al., eq. 4 (effective C/N0), eq. 5-7 (measurement models of the real data and UWB);
Kaplan & Hegarty, 3rd ed., eq. 8.53 (DLL) and 8.47 (FLL) via ``jamming_weights``.

In a scenario file with a top-level timeline (``start``, ``jamming``), ``jamming``
is derived from it by :func:`rfi_experiments.scenario.resolve_streams`; a key written in this
section overrides the derived one.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import InitVar, dataclass, fields, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from gnss_common.coordinates import azimuth_elevation
from gnss_common.ephemeris import earth_rotation_correction
from gnss_common.jamming_weights import (
    TrackingLoopParams,
    dll_jitter_m,
    effective_cn0_dbhz,
    fll_jitter_mps,
)
from gnss_common.observations import GnssEpoch, SatelliteObservation, UwbRangeMeasurement
from gnss_common.rinex import RinexFormatError
from rfi_experiments.scenario import Scenario, data_path
from rfi_experiments.schema import (
    JsrPhases,
    ScenarioError,
    boolean,
    jsr_phases,
    number,
    reject_unknown_keys,
)
from rfi_experiments.streams.gnss_uwb import (  # the topics and frame of the gnss_uwb stream, the same here
    EARTH_FRAME,
    GNSS_TOPIC,
    NAV_FILE_NAME,
    TRUTH_JAMMER_PERIOD_S,
    TRUTH_JAMMER_TOPIC,
    TRUTH_POSITION_TOPIC,
    UWB_TOPIC,
    UwbSkyKeys,
)
from rfi_sim.gnss_uwb import GnssUwbScenario, JammingEffect, anchor_positions_ecef

OBS_FILE_NAME = 'arlm200a.15o'
"""Default observations: ARL1 RINEX 2.11 obs, 2015-07-19 00:00-00:59 GPST, 30 s (with S1 and D1)."""

_SIM = GnssUwbScenario()


def _error(message: str) -> ScenarioError:
    return ScenarioError(f'rinex_jammed.{message}')


def _file(value: Any, key: str, default: str, scenario: Scenario) -> Path:
    if value is None:
        return data_path(default)
    if not isinstance(value, (str, Path)):
        raise _error(f'{key} must be a path or null, got {value!r}')
    path = Path(value)
    if not path.is_absolute() and scenario.source is not None:
        path = scenario.source.parent / path
    if not path.is_file():
        raise _error(f'{key} {path} does not exist')
    return path


@dataclass(frozen=True)
class Section(UwbSkyKeys):
    """The ``rinex_jammed`` section: every key with its default (the simulator's; no jamming over the
    whole scenario), validated and converted on construction (module docstring for each key; those it
    shares with gnss_uwb in :class:`~rfi_experiments.streams.gnss_uwb.UwbSkyKeys`).

    After construction ``anchors`` is ``(ranges m, azimuths deg, ups m)`` and ``uwb_reported_std_m``
    NaN when not given. Given the ``scenario`` (as :func:`parse_section` does), ``obs_file`` and
    ``nav_file`` are resolved to existing paths and ``jamming`` becomes the phases
    ``((jsr_db or None, duration_s), ...)`` covering the scenario.

    Raises:
        ScenarioError: wrong type or non-physical value (the message names the key).
    """

    SECTION: ClassVar[str] = 'rinex_jammed'
    obs_file: Any = None
    nav_file: Any = None
    start_offset_s: float = 0.0
    truth_jammer_state: bool = True
    jamming: Any = ({'jsr_db': None},)
    scenario: InitVar[Scenario | None] = None

    def __post_init__(self, scenario: Scenario | None) -> None:
        def put(key: str, value: Any) -> None:
            object.__setattr__(self, key, value)

        self._check_uwb_sky_keys()
        boolean(self.truth_jammer_state, 'rinex_jammed.truth_jammer_state')
        if scenario is not None:
            put('obs_file', _file(self.obs_file, 'obs_file', OBS_FILE_NAME, scenario))
            put('nav_file', _file(self.nav_file, 'nav_file', NAV_FILE_NAME, scenario))
        put('start_offset_s', number(self.start_offset_s, 'rinex_jammed.start_offset_s', 0.0, 1e7))
        if scenario is not None:
            put('jamming', jsr_phases(self.jamming, scenario.duration_s, 'rinex_jammed.jamming',
                                      {'UWB': self.uwb_rate_hz}))

    @property
    def phases(self) -> JsrPhases:
        """The validated J/S schedule (after :func:`parse_section`)."""
        return self.jamming


def parse_section(scenario: Scenario, section: Mapping[str, Any]) -> Section:
    """Validate the section (defaults applied, files resolved against the scenario).

    Raises:
        ScenarioError: unknown key, wrong type, non-physical value (the message names the key).
    """
    reject_unknown_keys(section, [f.name for f in fields(Section)], 'rinex_jammed')
    return Section(**section, scenario=scenario)


def burst_rate_per_s(jamming: JammingEffect, jsr_db: float | None) -> float:
    """Outlier-burst starts per satellite per second at a J/S (0 below the onset or without a jammer).

    Args:
        jamming: the simulator's jamming effect parameters.
        jsr_db: J/S, dB (None: no jammer).

    Notes:
        The rate law of :func:`rfi_sim.gnss_uwb.simulate`:
        ``rate = rate_onset * 10^(growth (J/S - onset) / 10)`` from the onset J/S on (Cao et al.,
        Sec. IV-2: outliers from 6 dB).
    """
    if jsr_db is None or jsr_db < jamming.outlier_onset_jsr_db:
        return 0.0
    return jamming.outlier_burst_rate_per_s * 10.0 ** (
        jamming.outlier_rate_growth_per_db * (jsr_db - jamming.outlier_onset_jsr_db) / 10.0)


def draw_bursts(rng: np.random.Generator, rate_per_s: float, start_s: float, stop_s: float,
                jamming: JammingEffect) -> np.ndarray:
    """Outlier bursts of one satellite over [start_s, stop_s), in continuous time.

    Args:
        rng: generator (one call draws a fixed number of arrays, so the stream stays reproducible).
        rate_per_s: burst starts per second (:func:`burst_rate_per_s`), >= 0.
        start_s, stop_s: interval, s.
        jamming: durations (uniform) and magnitudes (log-uniform, one random sign for both).

    Returns:
        Array (k, 4): start s, end s, pseudorange error m, pseudorange-rate error m/s.
    """
    n = int(rng.poisson(rate_per_s * max(stop_s - start_s, 0.0)))
    u = rng.random((n, 5))
    lo, hi = jamming.outlier_burst_duration_s
    mlo, mhi = jamming.outlier_magnitude_m
    dlo, dhi = jamming.doppler_outlier_mps
    start = start_s + (stop_s - start_s) * u[:, 0]
    sign = np.where(u[:, 2] < 0.5, 1.0, -1.0)
    return np.column_stack([start, start + lo + (hi - lo) * u[:, 1],
                            sign * mlo * (mhi / mlo) ** u[:, 3], sign * dlo * (dhi / dlo) ** u[:, 4]])


def elevations_rad(epoch: GnssEpoch, receiver_ecef_m: np.ndarray) -> np.ndarray:
    """Elevation of each satellite of ``epoch`` seen from ``receiver_ecef_m``, rad, shape (n,).

    Notes:
        Earth-rotation-corrected satellite position, as ``rinex_to_bag.apply_elevation_mask``.
    """
    if not epoch.observations:
        return np.zeros(0)
    sats = np.array([o.satellite_position_ecef_m for o in epoch.observations], dtype=float)
    rotated, _, _ = earth_rotation_correction(sats, receiver_ecef_m)
    _, el = azimuth_elevation(receiver_ecef_m, rotated)
    return np.atleast_1d(np.asarray(el, dtype=float))


@dataclass(frozen=True)
class JammedEpoch:
    """One GNSS epoch after jamming, with what happened to it (for tests and reports).

    Attributes:
        epoch: the degraded epoch (the real one in a phase without a jammer).
        jsr_db: J/S of its phase, dB (None: no jammer).
        lost_lock: svids dropped by loss of lock.
        outliers: svids inside an outlier burst.
        cn0_clean_dbhz: svid -> jammer-free C/N0 used (S1 or the elevation model), dB-Hz.
    """

    epoch: GnssEpoch
    jsr_db: float | None
    lost_lock: tuple[int, ...]
    outliers: tuple[int, ...]
    cn0_clean_dbhz: dict[int, float]


def jam_epochs(epochs: tuple[GnssEpoch, ...], receiver_ecef_m: np.ndarray, t0_ns: int, section: Section,
               rng: np.random.Generator, jamming: JammingEffect | None = None,
               loop: TrackingLoopParams | None = None) -> list[JammedEpoch]:
    """Apply the J/S schedule of ``section`` to real epochs (see the module docstring).

    Args:
        epochs: real epochs in time order (stamps >= ``t0_ns``, all within the schedule).
        receiver_ecef_m: station position, ECEF, m, shape (3,).
        t0_ns: schedule start, ns.
        section: validated section (phases, C/N0 elevation model).
        rng: generator of the GNSS draws.
        jamming, loop: the simulator's jamming effect and tracking-loop parameters (default: its defaults).

    Returns:
        One :class:`JammedEpoch` per input epoch.
    """
    jam = jamming if jamming is not None else _SIM.jamming
    lp = loop if loop is not None else _SIM.loop
    bounds = np.cumsum([0.0] + [d for _, d in section.phases])
    burst_rng = rng.spawn(1)[0]   # bursts do not shift the per-epoch noise draws
    bursts: dict[tuple[int, int], np.ndarray] = {}
    out = []
    for epoch in epochs:
        t_rel = (epoch.stamp_ns - t0_ns) * 1e-9
        k = min(int(np.searchsorted(bounds, t_rel, side='right')) - 1, len(section.phases) - 1)
        jsr = section.phases[k][0]
        obs = epoch.observations
        el = elevations_rad(epoch, receiver_ecef_m)
        reported = np.array([o.cn0_dbhz for o in obs], dtype=float)
        model = section.cn0_horizon_dbhz + (section.cn0_zenith_dbhz - section.cn0_horizon_dbhz) * np.sin(
            np.clip(el, 0.0, None))
        clean = np.where(np.isfinite(reported), reported, model)
        # Fixed number of draws per satellite and epoch, whatever the phase or lock state.
        n_cn0 = rng.standard_normal(len(obs))
        n_pr = rng.standard_normal(len(obs))
        n_rate = rng.standard_normal(len(obs))
        cn0_clean = {o.svid: float(c) for o, c in zip(obs, clean, strict=True)}
        if jsr is None:
            out.append(JammedEpoch(epoch, None, (), (), cn0_clean))
            continue
        eff = effective_cn0_dbhz(clean, jsr, jam.quality_factor)
        measured = eff + jam.cn0_estimate_std_db * n_cn0
        extra_pr = np.sqrt(np.maximum(dll_jitter_m(eff, lp) ** 2 - dll_jitter_m(clean, lp) ** 2, 0.0))
        extra_rate = np.sqrt(np.maximum(fll_jitter_mps(eff, lp) ** 2 - fll_jitter_mps(clean, lp) ** 2, 0.0))
        rate = burst_rate_per_s(jam, jsr)
        kept: list[SatelliteObservation] = []
        lost, hit = [], []
        for i, o in enumerate(obs):
            key = (k, o.svid)
            if key not in bursts:
                bursts[key] = draw_bursts(burst_rng, rate, float(bounds[k]), float(bounds[k + 1]), jam)
            if measured[i] < jam.loss_of_lock_dbhz:
                lost.append(o.svid)
                continue
            err_pr = extra_pr[i] * n_pr[i]
            err_rate = extra_rate[i] * n_rate[i]
            b = bursts[key]
            inside = b[(b[:, 0] <= t_rel) & (t_rel < b[:, 1])]
            if inside.size:
                err_pr += inside[0, 2]
                err_rate += inside[0, 3]
                hit.append(o.svid)
            kept.append(replace(
                o, pseudorange_m=o.pseudorange_m + float(err_pr),
                pseudorange_rate_mps=o.pseudorange_rate_mps + float(err_rate),
                cn0_dbhz=float(measured[i]) if math.isfinite(o.cn0_dbhz) else math.nan))
        out.append(JammedEpoch(replace(epoch, observations=tuple(kept)), jsr, tuple(lost), tuple(hit), cn0_clean))
    return out


def uwb_ranges(receiver_ecef_m: np.ndarray, t0_ns: int, duration_s: float, section: Section,
               rng: np.random.Generator) -> tuple[np.ndarray, list[UwbRangeMeasurement]]:
    """UWB ranges of the anchors around the static station over [t0, t0 + duration).

    Returns:
        ``(anchor_ecef_m (k, 3), ranges)``: anchor ``A{j+1}`` ranges at ``t0 + m / rate + j / (k rate)``.

    Notes:
        Cao et al., eq. 7 with Gaussian noise; anchor geometry of the GNSS/UWB simulator.
    """
    ranges_m, azimuths, ups = section.anchors
    anchors = anchor_positions_ecef(receiver_ecef_m, ranges_m, azimuths, ups)
    true_r = np.linalg.norm(anchors - receiver_ecef_m, axis=1)
    k_a = anchors.shape[0]
    n_u = int(round(duration_s * section.uwb_rate_hz))
    offsets_ns = [int(round(j / (k_a * section.uwb_rate_hz) * 1e9)) for j in range(k_a)]
    noise = section.uwb_noise_std_m * rng.standard_normal((n_u, k_a))
    # checked when the section is read: never None here
    reported_std_m = math.nan if section.uwb_reported_std_m is None else section.uwb_reported_std_m
    out = []
    for m in range(n_u):
        base = t0_ns + int(round(m / section.uwb_rate_hz * 1e9))
        for j in range(k_a):
            out.append(UwbRangeMeasurement(
                stamp_ns=base + offsets_ns[j], anchor_id=f'A{j + 1}', anchor_position_m=anchors[j].copy(),
                frame_id=EARTH_FRAME, range_m=float(true_r[j] + noise[m, j]),
                range_std_m=reported_std_m))
    return anchors, out


def load_epochs(scenario: Scenario, section: Section) -> tuple[tuple[GnssEpoch, ...], np.ndarray, int]:
    """Read the RINEX pair and select the epochs of the scenario.

    Returns:
        ``(epochs, truth_ecef_m (3,), t0_ns)``.

    Raises:
        ScenarioError: unreadable files, no header position, or a scenario longer than the file.
    """
    from rfi_experiments.rinex_to_bag import convert_rinex

    try:
        conv = convert_rinex(section.obs_file, section.nav_file, section.elevation_mask_deg)
    except (RinexFormatError, ValueError, OSError) as err:
        raise _error(f'cannot read {section.obs_file.name} / {section.nav_file.name} ({err})') from None
    if conv.truth_position_ecef_m is None:
        raise _error(f'obs_file {section.obs_file.name} has no APPROX POSITION XYZ: no truth for the station')
    stamps = np.array([e.stamp_ns for e in conv.epochs], dtype=np.int64)
    interval_ns = int(np.median(np.diff(stamps))) if stamps.size > 1 else 0
    first = int(np.searchsorted(stamps, stamps[0] + round(section.start_offset_s * 1e9)))
    if first >= stamps.size:
        raise _error(f'start_offset_s {section.start_offset_s} is past the last epoch of {section.obs_file.name}')
    t0 = int(stamps[first])
    end = t0 + round(scenario.duration_s * 1e9)
    available_s = (int(stamps[-1]) + interval_ns - t0) * 1e-9
    if end > int(stamps[-1]) + interval_ns:
        raise _error(f'duration_s {scenario.duration_s} exceeds the {available_s:.0f} s of {section.obs_file.name} '
                     f'from the start epoch')
    epochs = tuple(e for e in conv.epochs[first:] if e.stamp_ns < end)
    return epochs, conv.truth_position_ecef_m, t0


def build(scenario: Scenario, section: Mapping[str, Any], seed: int) -> Iterator[tuple[int, str, Any]]:
    """Validate ``section`` and yield ``(stamp_ns, topic, message)`` in stamp order.

    At equal stamps: /gnss/measurements, /truth/position, /truth/jammer_state, /uwb/ranges.

    Args:
        scenario: the scenario (its ``duration_s`` is the length, s).
        section: the ``rinex_jammed`` section (module docstring).
        seed: seed of this stream.

    Raises:
        ScenarioError: invalid section or files (raised before anything is yielded).
    """
    sec = parse_section(scenario, section)
    epochs, truth, t0 = load_epochs(scenario, sec)
    return _generate(scenario, sec, epochs, truth, t0, seed)


def _generate(scenario: Scenario, sec: Section, epochs: tuple[GnssEpoch, ...], truth: np.ndarray, t0: int,
              seed: int) -> Iterator[tuple[int, str, Any]]:
    from rfi_experiments.streams.gnss_uwb import _jammer_truth
    from rfi_node_common.conversions import epoch_to_msg, point_to_msg, uwb_to_msg

    gnss_rng, uwb_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    jammed = jam_epochs(epochs, truth, t0, sec, gnss_rng)
    _, ranges = uwb_ranges(truth, t0, scenario.duration_s, sec, uwb_rng)
    items: list[tuple[int, int, str, Any]] = []
    for j in jammed:
        stamp = j.epoch.stamp_ns
        items.append((stamp, 0, GNSS_TOPIC, epoch_to_msg(j.epoch, EARTH_FRAME)))
        items.append((stamp, 1, TRUTH_POSITION_TOPIC, point_to_msg(stamp, truth, EARTH_FRAME)))
    if sec.truth_jammer_state:
        start = 0.0
        for jsr, dur in sec.phases:
            for m in range(max(1, math.ceil(dur / TRUTH_JAMMER_PERIOD_S - 1e-9))):
                stamp = t0 + round((start + m * TRUTH_JAMMER_PERIOD_S) * 1e9)
                items.append((stamp, 2, TRUTH_JAMMER_TOPIC, _jammer_truth(stamp, jsr)))
            start += dur
    items += [(u.stamp_ns, 3, UWB_TOPIC, uwb_to_msg(u)) for u in ranges]
    items.sort(key=lambda item: (item[0], item[1]))
    for stamp_ns, _, topic, msg in items:
        yield stamp_ns, topic, msg

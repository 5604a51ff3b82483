"""ROS node of the RFI monitor: /rfi/if_samples -> /rfi/jammer_state, /diagnostics.

The node is thin: it declares the parameters (the core's :class:`rfi_monitor.monitor.RfiMonitorParams`,
flattened, plus a few of its own), checks and decodes each ``rfi_msgs/IfSamples`` block into a numpy
array (``np.frombuffer`` by ``sample_format``, little-endian, times ``scale``: volts), hands it to one
:class:`rfi_monitor.monitor.RfiMonitor` (Kang et al., eq. 8-27, plus the identification of
docs/rfi_monitor/README.md) and publishes the returned estimate as a ``rfi_msgs/JammerState``.

Input: ``/rfi/if_samples`` is subscribed with :func:`rfi_node_common.inputs.subscribe_input`: best
effort (a sensor driver's best-effort publisher and a reliable one are both accepted; rclpy's
``qos_overrides./rfi/if_samples.subscription.*`` parameters change it), every arrival and every
message lost before the node saw it (publisher sequence gaps, the middleware's lost-message event)
counted as ``input./rfi/if_samples.*``. The subscription is raw: bytes that rclpy cannot deserialise
are counted as ``rejected_malformed_message`` (:meth:`RfiMonitorNode.on_raw_block`). Nothing raises
out of :meth:`RfiMonitorNode.on_block`: every
block that reaches it is either processed or rejected under a named reason; the subscription's own
guard (``callback_errors``) is only the last net and makes the diagnostics ERROR.

Output policy (one decision, applied to every block):

* Exactly one JammerState per block that the core *analysed* (``JammerEstimate.valid``): header
  copied from the block (stamp = time of its first sample, frame_id of the front end), frequencies
  relative to the block's ``center_frequency_hz`` (the core converts from the IF), NaN where the
  core does not know a value. While the noise floor is being learned the core reports UNKNOWN
  (confidence 0.5, NaNs); that is published, since it is what the monitor knows.
* Nothing for a rejected block: malformed or physically impossible blocks (checked here before the
  core sees them) and blocks the core refuses to analyse (``valid`` False). An invalid estimate is
  therefore never on the topic, and in particular a block that carries no information (blank,
  absurd scale) never gives "NONE, confidence 1"; a consumer that needs the monitor's status reads
  /diagnostics or notices the missing state. Each rejection is counted as ``rejected_<reason>`` and
  gives one warning, throttled to ``warning_throttle_s``.

Stream continuity: the core owns it. A jump in ``first_sample_index`` resets the per-sample tracker
(the calibration is kept) and is counted as a gap; a change of sample rate, IF or complexness resets
it and the calibration and is counted as ``rate_changes``. A snapshot front end (1 ms every second)
therefore produces one gap per block; gaps are reported but are not a warning. A block rejected here
never reaches the core, so the block after it counts as a gap (also after a lost message).

Stamps: :class:`rfi_node_common.input_checks.StampGate` admits every block's stamp first (a block
whose stamp is accepted moves the time line even if its content is then rejected). A stamp
<= 0 is ``stamp_not_positive``; one that does not increase is ``stamp_not_increasing``; one more than
``max_stamp_jump_s`` from the latest accepted stamp is ``stamp_far_future`` / ``stamp_far_past`` and
does not move the node's time line, so a single bad stamp never stalls the node. A jump confirmed by
``stamp_jump_confirmations`` consecutive blocks is accepted as a new time line (``stamp_restarts``;
nothing in the monitor depends on stamp continuity, which the sample index carries). A stamp whose
nanoseconds are not below 1e9 is ``bad_stamp_nanosec`` (not a canonical ROS time).

Block checks, in this order (``rejected_<reason>``), with the physical ranges they enforce:

* ``unknown_sample_format``; ``bad_bits_per_sample`` (outside 1..16, or above 8 for INT8);
* ``bad_sample_rate``: not in [SAMPLE_RATE_MIN_HZ, SAMPLE_RATE_MAX_HZ] = [1e5, 1e11] Hz (a GNSS
  signal needs at least ~1 MS/s, direct-RF samplers stay below 100 GS/s; at a tiny rate the
  periodicity analysis, one per ``analysis_hop_s``, would run once per sample);
* ``bad_intermediate_frequency``: not finite, or |IF| at or beyond the Nyquist band (fs/2 real,
  fs complex);
* ``bad_scale``: not in [SCALE_MIN, SCALE_MAX] = [1e-12, 1e3] V/count. Every real front end fits:
  a 16-bit ADC with 1 V full scale has 3e-5 V/count, a front end reporting full-scale units 1/2^(bits-1)
  or counts 1.0. 1e-12 V/count would put a 16-bit full scale at 33 nV, below the thermal noise of any
  input stage (about 0.6 uV rms over 2 MHz at 50 ohm); no ADC has a count of 1 kV. Within the range
  the block's power (count * scale)^2 is a normal double and fits the single-precision Welch FFT;
  outside it (5e-324, 1e150, 1e308) it underflows to zero or overflows;
* ``bad_center_frequency``: not finite, negative or above CENTER_FREQUENCY_MAX_HZ = 1e11 Hz (0 is
  accepted for a stream referenced to its IF);
* ``empty_block``, ``truncated_sample`` (INT16 with an odd byte count), ``odd_length_iq``,
  ``short_block`` (fewer samples than ``min_block_samples``), ``long_block`` (more than
  ``max_block_samples``: bounds memory and the time one callback takes);
* ``bad_first_sample_index``: ``first_sample_index + samples`` beyond 2^53 (the core keeps
  absolute sample positions in float64, exact only up to 2^53: 7.5 years at 38.192 MS/s);
* ``values_exceed_bits``: a stored value outside what ``bits_per_sample`` can hold (:func:`count_range`: two's
  complement for 4-16 bits, odd levels up to +-(2**bits - 1) for 1-3 bits), e.g. an INT16 block declaring 8 bits
  with values to +-32767 (issue 27 item 3): malformed, not analysed as a clipped block;
* ``blank_block``: every sample equal (real), or every I and every Q equal (complex): a block
  with no variation (all zero, a stuck ADC) carries no information about a jammer;
* from the core (``JammerEstimate.rejection``): ``non_finite`` (more than ``max_invalid_fraction``
  of the samples not finite; clipped blocks are analysed, issue 14), ``blank_block`` (no power in the
  analysed Welch frames),
  ``power_overflow``, ``below_noise_floor`` (10 dB below the calibrated noise floor) and
  ``implausible_power`` (120 dB above it): gain or scale no longer match the calibration, see
  rfi_monitor.monitor;
* ``core_error``: the core raised on a block that passed the checks; ``node_error``: the node's own
  checks raised (both bugs, logged as errors, and the diagnostics are ERROR).

Saturation: full scale is ``(2**(bits_per_sample - 1) - 1) * scale`` for two's-complement front ends
(bits >= 4). A clipped block is analysed: its clipped fraction is in the JammerState and in /diagnostics
(``last_clipped_fraction``, ``core.clipped_blocks``, ``core.saturated_samples``), its J/N flagged as a lower
bound above ``clip_lower_bound_fraction``. For 1-3 bit sign/magnitude front ends the largest level is a
normal value (a 2-bit front end puts about a third of its samples there), so no saturation check is made.

Diagnostics (/diagnostics, every ``diagnostics_period_s`` of *stamp* time via StampTimer, driven only
by stamps the StampGate accepted, after the block of that stamp is counted): blocks_received,
blocks_processed, states_published, each rejected_* count, stamp_restarts, gaps, rate_changes, the
core's counters (``core.*``), calibrated, the last type, the subscription's ``input.*`` counters and
``accounting_ok`` (every block that reached the subscription reached the handler, and
blocks_received == blocks_processed + sum of rejected_*). Level: ERROR if the accounting does not
add up, the core or the node raised, or the subscription's guard caught an exception since the last report;
WARN (input degraded) if over the last ``diagnostics_window_s`` of stamp time more than
``warn_rejected_fraction`` of the blocks was rejected or more than ``warn_lost_fraction`` lost before
reaching the node (one rejected block among many stays OK); else OK. ``hardware_id`` of every status is
the parameter (the front end), and it, the window, the thresholds and ``warning_throttle_s`` can be set
while the node runs (rfi_node_common.params.RuntimeParameters; the core's parameters are read-only).

Load policy (issue 26 item 1; :mod:`rfi_monitor.load_policy`, pure and tested on its own, defines "live"): a
replay (a bag, ``if_to_bag`` output, ``play --max``, ``--rate 10`` or ``--rate 1``: its stamps lie in the past, more
than ``load_policy.LIVE_BOUND_S`` (1 s) from the receive clock when its first block arrives) gets the full analysis
on every block, whatever it costs: nothing is shed, nothing is light, and its answers do not depend on the replay
speed. Only a live stream (stamped with the clock: if_source ``pace: real_time``, an SDR driver) has the safety
net: over its CPU budget (``max_cpu_load`` of one core over the stream time its blocks cover, measured with the CPU
time of this thread in the callbacks, deserialising included; ``time.thread_time``, resource accounting only), or
after ``LIGHT_QUEUE_S`` in the input queue, a block gets the light analysis (estimator stft;
``RfiMonitor.process(light=True)``: its Welch spectrum, type and J/N checked against the last full analysis, whose
sweep period, band and shape it carries, a chirp's frequency NaN; a block that disagrees is analysed in full,
``core.light_escalations``), counted as ``blocks_light`` (within ``blocks_processed``); over budget by more than
``light_analysis_debt_s`` it is shed whole, judged on the stamp read from the raw bytes before they are deserialised
(``peek_stamp_ns``), counted as ``blocks_shed`` (no JammerState; the block after it is a gap for the core). A live
block stamped more than ``max_block_age_s`` behind the receive clock is shed too (``blocks_shed_stale``). The
decisions are counted as ``load.full``, ``load.light``, ``load.shed``, ``load.shed_stale`` and ``load.not_live``
(blocks of a replay) on /diagnostics, with ``live_stream``. The compiled functions are compiled (or loaded) at
start-up (:func:`warm_up`), so that a one-off cost does not shed seconds of a live stream. ``accounting_ok`` counts
shed blocks: received == processed + shed + rejected.

Second core: ``analysis_worker`` (off by default) runs each block's ridge analysis in a child process
(:mod:`rfi_monitor.analysis_worker`) while the node does the rest; the estimates are the same (tested byte for byte
on the published states); a child that fails is counted (``core.worker_failures``) and the node carries on alone.
It pays only where a core is idle: on the project's 2-vCPU machine it made the node slower
(docs/rfi_monitor/live_stream.md).

Stale input: :class:`rfi_node_common.inputs.StaleInputWatch` publishes a STALE status (stamped with
the node clock, the only wall-clock use; no estimate depends on it) while nothing has arrived for
``input_timeout_s``.
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.serialization import deserialize_message

from rfi_monitor.analysis_worker import AnalysisWorker
from rfi_monitor.classifier import ClassifierParams
from rfi_monitor.integration import IntegrationParams
from rfi_monitor.load_policy import (
    FULL,
    LIGHT,
    SHED,
    SHED_CREDIT_CAP_S,
    LoadPolicy,
    LoadPolicyParams,
)
from rfi_monitor.monitor import NON_FINITE, JammerEstimate, RfiMonitor, RfiMonitorParams
from rfi_monitor.params import ESTIMATORS
from rfi_monitor.ridge import RidgeParams
from rfi_monitor.spectral_step import SpectralStepParams
from rfi_monitor.spectral_step import warm_up as spectral_step_warm_up
from rfi_monitor.sweep_analysis import SweepAnalysisParams
from rfi_monitor.sweep_period import SweepPeriodParams
from rfi_monitor.tracker import MAX_REFINE_WINDOW
from rfi_monitor.tracking_filters import MODE_AFKF, MODE_AKF, MODE_KF, TrackingFilterParams
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common.diagnostics import (
    ERROR,
    OK,
    STALE,
    WARN,
    CountWindow,
    StampTimer,
    degraded_inputs,
    diagnostic_array,
    diagnostics_window_parameter,
    hardware_id_parameter,
    input_timeout_parameter,
    max_stamp_jump_parameter,
    stamp_jump_confirmations_parameter,
    warn_lost_fraction_parameter,
    warn_rejected_fraction_parameter,
)
from rfi_node_common.input_checks import StampGate
from rfi_node_common.inputs import InputHealth, StaleInputWatch, subscribe_input
from rfi_node_common.main import run_node
from rfi_node_common.params import RuntimeParameters, changed_names, declare, parameter, validate_ranges
from rfi_node_common.qos import DATA_QOS, DIAGNOSTICS_QOS
from rfi_node_common.stamps import NS_PER_S, stamp_to_ns

TOPICS = """topics:
  subscribes /rfi/if_samples (rfi_msgs/IfSamples)
  publishes  /rfi/jammer_state (rfi_msgs/JammerState), /diagnostics (diagnostic_msgs/DiagnosticArray)"""

IF_TOPIC = 'rfi/if_samples'
"""Input topic, relative: /rfi/if_samples without a namespace, /<ns>/rfi/if_samples with ``-r __ns:=/<ns>``."""

SAMPLE_RATE_MIN_HZ = 1.0e5
"""Lowest sample rate accepted, Hz (module docstring: a GNSS band needs >= ~1 MS/s)."""
SAMPLE_RATE_MAX_HZ = 1.0e11
"""Highest sample rate accepted, Hz (beyond any direct-RF sampler)."""
SCALE_MIN = 1.0e-12
"""Smallest volts (or full-scale units) per count accepted (module docstring)."""
SCALE_MAX = 1.0e3
"""Largest volts (or full-scale units) per count accepted (module docstring)."""
CENTER_FREQUENCY_MAX_HZ = 1.0e11
"""Highest RF reference frequency accepted, Hz (GNSS bands are 1.1-2.5 GHz; 100 GHz leaves room for any band)."""
MAX_SAMPLE_INDEX = 2 ** 53
"""first_sample_index + samples may not exceed this: the core's sample positions are float64, exact to 2^53."""

TYPE_NAMES = {JammerState.NONE: 'NONE', JammerState.CW: 'CW', JammerState.CHIRP: 'CHIRP',
              JammerState.WIDEBAND: 'WIDEBAND', JammerState.UNKNOWN: 'UNKNOWN'}
"""JammerState type code -> name (for diagnostics and logs)."""

TRACKER_MODES = {'kf': MODE_KF, 'akf': MODE_AKF, 'afkf': MODE_AFKF}
"""tracker_mode parameter -> tracking_filters mode code."""

SAMPLE_WIDTH_BYTES = {IfSamples.INT8: 1, IfSamples.INT16: 2}
"""IfSamples.sample_format -> bytes per stored value."""

SAMPLE_DTYPES = {IfSamples.INT8: np.dtype('<i1'), IfSamples.INT16: np.dtype('<i2')}
"""IfSamples.sample_format -> numpy dtype of the stored values (little-endian)."""

NESTED = (('tracker', 'tracker_', TrackingFilterParams), ('sweep', 'sweep_', SweepPeriodParams),
          ('classifier', 'classifier_', ClassifierParams), ('analysis', 'analysis_', SweepAnalysisParams),
          ('ridge', 'ridge_', RidgeParams), ('integration', 'integration_', IntegrationParams),
          ('spectral_step', 'spectral_step_', SpectralStepParams))
"""(RfiMonitorParams field, node parameter prefix, dataclass) of the core's nested parameter groups."""

_M = RfiMonitorParams()
_T = _M.tracker
_S = _M.sweep
_C = _M.classifier
_A = _M.analysis
_R = _M.ridge
_I = _M.integration
_P = _M.spectral_step


@dataclass(frozen=True)
class MonitorNodeParams:
    """Parameters of rfi_monitor_node (documented for users in config/rfi_monitor.yaml).

    The core's RfiMonitorParams, flattened: its nested groups get the prefixes ``tracker_``,
    ``sweep_``, ``analysis_`` and ``classifier_``; the defaults are the core's own. Node-only parameters:
    diagnostics_period_s, warning_throttle_s, input_timeout_s, max_stamp_jump_s, stamp_jump_confirmations,
    check_saturation, max_block_samples.

    Notes:
        Kang et al.: tracking filters eq. 11-22 (tracker_*), sweep period eq. 23-27 (sweep_*);
        Kang et al. give no values for most of them (see docs/rfi_monitor/README.md for ours). The
        identification (classifier_*) is not in the paper.
    """

    # --- node ---------------------------------------------------------------------------------
    diagnostics_period_s: float = parameter(
        1.0, 'Period of /diagnostics in message (stamp) time, s.', minimum=0.001, maximum=3600.0)
    warning_throttle_s: float = parameter(
        5.0, 'Shortest interval between two warnings about rejected blocks, s (wall time; logging only).',
        minimum=0.0, maximum=3600.0, read_only=False)
    # diagnostics levels and hardware_id (rfi_node_common.diagnostics), settable while running
    hardware_id: str = hardware_id_parameter('rf_front_end')
    diagnostics_window_s: float = diagnostics_window_parameter()
    warn_rejected_fraction: float = warn_rejected_fraction_parameter()
    warn_lost_fraction: float = warn_lost_fraction_parameter()
    input_timeout_s: float = input_timeout_parameter()
    max_stamp_jump_s: float = max_stamp_jump_parameter(10.0)
    stamp_jump_confirmations: int = stamp_jump_confirmations_parameter(3)
    check_saturation: bool = parameter(
        True, 'Count samples at full scale (two\'s-complement front ends, bits_per_sample >= 4): the block is '
        'analysed, its clipped fraction reported and its J/N flagged as a lower bound.')
    max_cpu_load: float = parameter(
        0.9, 'Live streams only (a replay is analysed in full, always): share of one core the analysis may use, over '
        'the stream time the blocks cover (a continuous stream: the block durations; snapshots: the time between '
        'them). Beyond it blocks get the light analysis '
        '(light_analysis_debt_s) and, beyond that, are shed whole on purpose (blocks_shed on /diagnostics, no '
        'JammerState for them) until it fits again; 0: never shed.',
        minimum=0.0, maximum=1000.0)
    light_analysis_debt_s: float = parameter(
        0.02, 'Estimator stft: while the node is over its max_cpu_load budget by at most this much CPU time, a block '
        'gets the light analysis instead of being shed (its Welch spectrum: type and J/N checked against the last full '
        'analysis, whose sweep period, band and shape it carries; a chirp\'s frequency NaN; blocks_light on '
        '/diagnostics), so that every block is answered while the light analysis keeps up; beyond it blocks are shed. '
        '0: no light analysis (shed at once, as before session 11).', minimum=0.0, maximum=SHED_CREDIT_CAP_S)
    max_block_age_s: float = parameter(
        0.05, 'Live streams only: a block stamped more than this many seconds behind the node clock is shed before '
        'it is deserialised (blocks_shed and blocks_shed_stale), so the answers stay within this latency when the '
        'node is short of CPU. A stream is live when its first block (after the start or a stamp restart) is '
        'stamped within 1 s of the receive clock (live_stream on /diagnostics; rfi_monitor.load_policy); a replay, '
        'whose stamps lie in the past, is never shed nor given the light analysis. 0: off.',
        minimum=0.0, maximum=3600.0)
    analysis_worker: bool = parameter(
        False, 'Run the ridge analysis of each block (estimator stft) in a child process on another core while this '
        'one does the rest of the block (rfi_monitor.analysis_worker): about half the CPU time per block in this '
        'process, the same estimates. For live streams on a machine with a core to spare; a worker that fails is '
        'counted (core.worker_failures) and the node carries on without it.')
    max_block_samples: int = parameter(
        2 ** 22, 'Longest block analysed, samples (complex: I/Q pairs); longer blocks are rejected (long_block). '
        'Bounds memory (about 40 bytes per sample) and the time of one callback.', minimum=1024, maximum=2**31 - 1)
    # --- monitor ------------------------------------------------------------------------------
    estimator: str = parameter(
        _M.estimator, 'stft: short-time FFT ridge analysis per block (ours; real sweep shapes, no clean start '
        'needed); kalman: Kang et al.\'s per-sample tracker (with the switches below).', choices=ESTIMATORS)
    noise_floor_dbfs: float = parameter(
        _M.noise_floor_dbfs, 'Thermal noise power of the front end per real component relative to full scale '
        'squared, dB; the J/N reference when set (needs bits_per_sample >= 4); 0: not documented.',
        minimum=-300.0, maximum=0.0)
    clip_lower_bound_fraction: float = parameter(
        _M.clip_lower_bound_fraction, 'Above this share of samples at full scale the J/N is flagged as a lower '
        'bound, 0..1.', minimum=0.0, maximum=1.0)
    ridge_min_frame_length: int = parameter(
        _R.min_frame_length, 'Shortest short-time FFT frame tried by the stft estimator, samples (power of two).',
        minimum=8, maximum=2**16)
    ridge_max_frame_length: int = parameter(
        _R.max_frame_length, 'Longest short-time FFT frame tried by the stft estimator, samples (power of two).',
        minimum=8, maximum=2**16)
    ridge_select_samples: int = parameter(
        _R.select_samples, 'Samples of a block used to choose the frame length (stft); 0: the whole block.',
        minimum=0, maximum=2**31 - 1)
    ridge_min_period_frames: int = parameter(
        _R.min_period_frames, 'Shortest sweep period searched (stft), frames of half the frame length.',
        minimum=3, maximum=10**6)
    ridge_presence_nats: float = parameter(
        _R.presence_nats, 'Per-frame ridge threshold above ln(bins) (stft), nats of the exponential.',
        minimum=0.1, maximum=100.0)
    ridge_noise_smooth_bins: int = parameter(
        _R.noise_smooth_bins, 'Width of the median across bins of the in-block noise level (stft), odd.',
        minimum=3, maximum=10**4)
    ridge_phase_bins: int = parameter(
        _R.phase_bins, 'Bins of the folded sweep profile (stft).', minimum=8, maximum=4096)
    ridge_hook_rate_ratio: float = parameter(
        _R.hook_rate_ratio, 'A saw-tooth whose two steps after its flyback both exceed this times its median step '
        'is hooked (stft; also hooked: a way back swept over at least two profile bins).', minimum=1.0001, maximum=1e3)
    ridge_min_present_fraction: float = parameter(
        _R.min_present_fraction, 'A non-periodic ridge must be present in at least this share of the frames '
        '(stft), (0, 1].', minimum=1e-6, maximum=1.0)
    ridge_tracking_samples: int = parameter(
        _R.tracking_samples, 'While a chirp is tracked the stft estimator analyses only the last this many '
        'samples of a block (speed; J/N and the CW test use the whole block); 0: the whole block.',
        minimum=0, maximum=2**31 - 1)
    ridge_acquisition_samples: int = parameter(
        _R.acquisition_samples, 'While nothing is tracked the stft estimator analyses only the last this many '
        'samples of a block first and the whole block when that part shows anything (speed; J/N, the CW test and '
        'the evidence over blocks use the whole block); 0: the whole block.', minimum=0, maximum=2**31 - 1)
    ridge_max_period_s: float = parameter(
        _R.max_period_s, 'Longest sweep period searched by the stft estimator, s.', minimum=1e-7, maximum=10.0)
    ridge_detect_sigma: float = parameter(
        _R.detect_sigma, 'Significance of a sweep period (stft), noise standard deviations.',
        minimum=1.0, maximum=100.0)
    ridge_min_strength: float = parameter(
        _R.min_strength, 'Smallest normalised autocorrelation peak of a periodic sweep (stft), (0, 1].',
        minimum=1e-6, maximum=1.0)
    integration_window_s: float = parameter(
        _I.window_s, 'stft: evidence of the blocks stamped within this many seconds is summed to find a weak '
        'stationary CW or chirp that no single block shows, s; 0: off.', minimum=0.0, maximum=60.0)
    integration_false_alarm_per_block: float = parameter(
        _I.false_alarm_per_block, 'stft: false-alarm probability per block of each integrated statistic under '
        'Gaussian noise (sets the thresholds), (0, 0.1].', minimum=1e-12, maximum=0.1)
    integration_frame_length_s: float = parameter(
        _I.frame_length_s, 'stft: frame of the integrated chirp statistic, s (rounded to a power of two of '
        '8..128 samples).', minimum=1e-9, maximum=1.0)
    integration_max_period_s: float = parameter(
        _I.max_period_s, 'stft: longest sweep period of the integrated chirp statistic, s.', minimum=1e-7,
        maximum=1.0)
    integration_max_multiples: int = parameter(
        _I.max_multiples, 'stft: most multiples of a candidate sweep period summed by the integrated chirp '
        'statistic.', minimum=2, maximum=4096)
    integration_nfft: int = parameter(
        _I.nfft, 'stft: Welch frame of the integrated CW statistic, samples (power of two >= 64).', minimum=64,
        maximum=2**20)
    integration_smooth_bins: int = parameter(
        _I.smooth_bins, 'stft: running median (bins, odd >= 5) that is the integrated CW statistic\'s noise '
        'reference.', minimum=5, maximum=4095)
    integration_decide_interval_s: float = parameter(
        _I.decide_interval_s, 'stft: the integrated statistics are tested at most once per this many seconds of '
        'stamps (speed); blocks in between get the last decision, s; 0: every block.', minimum=0.0, maximum=10.0)
    integration_min_chirp_strength: float = parameter(
        _I.min_chirp_strength, 'stft: a periodic sweep found over blocks is reported only when this share of the '
        'amplitudes\' variance repeats at its period (the faint periodic modulations of real front ends stay below '
        'it; a chirp at J/N -5 dB measures 0.017 or more), [0, 1).', minimum=0.0, maximum=0.999)
    integration_sub_windows: int = parameter(
        _I.sub_windows, 'stft: the integrated statistics are also tested on the newest integration_window_s / 4**k '
        'seconds, k = 1..this (a jammer that just switched on is found without the dilution of a window of clean '
        'blocks; Bonferroni over the sums tested); 0: the whole window only.', minimum=0, maximum=4)
    integration_max_samples_per_s: float = parameter(
        _I.max_samples_per_s, 'stft: processing budget of the evidence over blocks, samples per second of stamps '
        '(deterministic): beyond it blocks are left out of the sums (counted, integration_blocks_thinned); 0: no '
        'limit.', minimum=0.0, maximum=1e12)
    spectral_step_enabled: bool = parameter(
        _P.enabled, 'stft: look for a band of the spectrum that rose against the shape of the blocks that passed as '
        'noise (a noise jammer in part of the band, seen behind an AGC that hides its power): WIDEBAND with the '
        'band\'s centre in frequency_hz.')
    spectral_step_window_s: float = parameter(
        _P.window_s, 'stft: the spectral-step test sums the blocks stamped within this many seconds (1, 4, 16, ... '
        'and all of them), s.', minimum=0.0, maximum=60.0)
    spectral_step_groups: int = parameter(
        _P.groups, 'stft: groups (of >= 2 Welch bins) the band is cut into by the spectral-step test.', minimum=8,
        maximum=4096)
    spectral_step_false_alarm_per_block: float = parameter(
        _P.false_alarm_per_block, 'stft: false-alarm probability per block of the spectral-step test under Gaussian '
        'noise (Bonferroni over bands and scales), (0, 0.1].', minimum=1e-12, maximum=0.1)
    spectral_step_min_step_db: float = parameter(
        _P.min_step_db, 'stft: smallest rise of a band over the rest of the spectrum reported, dB (drift of the '
        'front end\'s shape is no jammer).', minimum=1e-3, maximum=60.0)
    spectral_step_max_band_fraction: float = parameter(
        _P.max_band_fraction, 'stft: widest band that rose reported, share of the sampled band, (0, 0.5].',
        minimum=0.01, maximum=0.5)
    spectral_step_reference_blocks: int = parameter(
        _P.reference_blocks, 'stft: memory of the spectral-step reference shape, blocks (exponential).', minimum=1,
        maximum=10**7)
    spectral_step_min_reference_blocks: int = parameter(
        _P.min_reference_blocks, 'stft: blocks in the reference shape before the spectral-step test runs.',
        minimum=1, maximum=10**7)
    spectral_step_learn_z: float = parameter(
        _P.learn_z, 'stft: a block whose spectral-step z (any scale) exceeds this does not enter the reference.',
        minimum=0.1, maximum=1e3)
    spectral_step_relearn_after_s: float = parameter(
        _P.relearn_after_s, 'stft: a spectrum that differs from the spectral-step reference (z over '
        'spectral_step_learn_z) without a break for this long makes the reference be learned again, s (a changed '
        'front end; also a partial-band noise jammer behind an AGC that stays on longer); 0: never.', minimum=0.0,
        maximum=1e6)
    spectral_step_decide_interval_s: float = parameter(
        _P.decide_interval_s, 'stft: the spectral-step sums are tested at most once per this many seconds of stamps '
        '(speed); blocks in between are added and get the last decision, s; 0: every block.', minimum=0.0,
        maximum=10.0)
    chirp_correction: bool = parameter(
        _M.chirp_correction, 'Correct the three-sample IF measurement for the sweep (Kang et al., eq. 10; '
        'real samples only).')
    reset_at_sweep_start: bool = parameter(
        _M.reset_at_sweep_start, 'Reset the tracking filter at estimated sweep starts (Kang et al., eq. 21-22).')
    min_abs_ratio: float = parameter(
        _M.min_abs_ratio, 'Near-zero guard: a sample with |x| <= this times the running RMS gives no '
        'measurement, dimensionless.', minimum=0.0, maximum=1.0)
    domain_margin: float = parameter(
        _M.domain_margin, 'arccos domain margin: a measurement ratio beyond 1 + this is rejected, dimensionless.',
        minimum=0.0, maximum=10.0)
    power_time_constant: float = parameter(
        _M.power_time_constant, 'Time constant of the running RMS used by the near-zero guard, samples.',
        minimum=1.0, maximum=1e9)
    phase_gain: float = parameter(
        _M.phase_gain, 'Gain of the sweep-start lattice phase correction, (0, 1].', minimum=1e-6, maximum=1.0)
    noise_floor_power: float = parameter(
        _M.noise_floor_power, 'Fixed noise power of the decoded samples, V^2 (counts * scale, squared); '
        '0: learn it from the first calibration_blocks blocks.', minimum=0.0, maximum=1e12)
    calibration_blocks: int = parameter(
        _M.calibration_blocks, 'Blocks used to learn the noise floor and the front-end noise shape.',
        minimum=1, maximum=100000)
    signal_power_dbm: float = parameter(
        _M.signal_power_dbm, 'Nominal GNSS signal power S for J/S, dBm (Kang et al.: -130).',
        minimum=-250.0, maximum=50.0)
    noise_density_dbm_per_mhz: float = parameter(
        _M.noise_density_dbm_per_mhz, 'Nominal noise density for J/S, dBm/MHz (Kang et al.: -114).',
        minimum=-250.0, maximum=50.0)
    noise_bandwidth_hz: float = parameter(
        _M.noise_bandwidth_hz, 'Bandwidth of the nominal noise power for J/S, Hz; 0: the sampled band.',
        minimum=0.0, maximum=1e10)
    max_invalid_fraction: float = parameter(
        _M.max_invalid_fraction, 'A block with more saturated (or non-finite) samples than this fraction is '
        'rejected, 0..1.', minimum=0.0, maximum=1.0)
    min_block_samples: int = parameter(
        _M.min_block_samples, 'Shortest block analysed, samples (complex: I/Q pairs); >= classifier_nfft.',
        minimum=32, maximum=2**31 - 1)
    refine_window: int = parameter(
        _M.refine_window, 'Half-window W of the sweep-start step fit that refines the reset lattice (ours), '
        'samples; 0 runs the paper\'s lattice (LPD peaks only).', minimum=0, maximum=MAX_REFINE_WINDOW)
    lattice_period_drift: float = parameter(
        _M.lattice_period_drift, 'Random walk of the sweep period per sweep, relative, of the step-fit lattice '
        'filter (ours), 0..0.01.', minimum=0.0, maximum=0.01)
    noise_compensation: bool = parameter(
        _M.noise_compensation, 'Divide the real three-sample ratio by kappa = 1 - N/P (removes eq. 8\'s bias '
        'towards fs/4 at moderate J/N; ours). No effect on complex samples.')
    confirm_fits: int = parameter(
        _M.confirm_fits, 'Tracking mode (ours): after this many consecutive significant sweep-start fits the '
        'LPD/AR(10)/peak search is suspended until fits fail; 0: always search (the paper).',
        minimum=0, maximum=10**6)
    reset_cross_covariance: bool = parameter(
        _M.reset_cross_covariance, 'At a sweep reset keep the exact covariance of eq. 21 instead of eq. 22 '
        '(ours).')
    # --- tracking filter (Kang et al., eq. 11-22) ----------------------------------------------
    tracker_mode: str = parameter(
        'afkf', 'Frequency tracking filter: kf (eq. 11-17), akf (adaptive gain) or afkf (adaptive fading, '
        'the proposed filter).', choices=tuple(TRACKER_MODES))
    tracker_measurement_std: float = parameter(
        _T.measurement_std, 'sigma_v of the IF measurement (eq. 20), cycles/sample.', minimum=1e-9, maximum=1.0)
    tracker_process_std: float = parameter(
        _T.process_std, 'sigma_w on the frequency (eq. 19), cycles/sample.', minimum=0.0, maximum=1.0)
    tracker_process_rate_std: float = parameter(
        _T.process_rate_std, 'Process noise on the sweep rate per sample, cycles/sample^2 (eq. 19: 0).',
        minimum=0.0, maximum=1.0)
    tracker_window: int = parameter(
        _T.window, 'Innovation window M of the adaptive filters (eq. 12), samples.', minimum=2, maximum=100000)
    tracker_initial_frequency: float = parameter(
        _T.initial_frequency, 'Frequency at start and after a reset, cycles/sample.', minimum=-1.0, maximum=1.0)
    tracker_initial_frequency_std: float = parameter(
        _T.initial_frequency_std, '1-sigma of the initial frequency, cycles/sample.', minimum=1e-12, maximum=1.0)
    tracker_initial_rate_std: float = parameter(
        _T.initial_rate_std, '1-sigma of the initial sweep rate, cycles/sample^2.', minimum=1e-12, maximum=1.0)
    # --- sweep period (Kang et al., eq. 23-27) -------------------------------------------------
    sweep_forgetting: float = parameter(
        _S.forgetting, 'Forgetting factor gamma of the LPD (eq. 23), [0, 1).', minimum=0.0, maximum=0.999999)
    sweep_beta: float = parameter(
        _S.beta, 'Normalisation beta of the LPD (eq. 23), dimensionless.', minimum=1e-12, maximum=1e6)
    sweep_beta_en: float = parameter(
        _S.beta_en, 'Enhancement rate beta_en of the peak threshold, dimensionless.', minimum=0.0, maximum=1e6)
    sweep_kappa: float = parameter(
        _S.kappa, 'Peak threshold in multiples of the running mean |zAR|, dimensionless.',
        minimum=1e-6, maximum=1e6)
    sweep_noise_time_constant: float = parameter(
        _S.noise_time_constant, 'Time constant of the running mean |zAR|, decimated steps.',
        minimum=1.0, maximum=1e9)
    sweep_decimation: int = parameter(
        _S.decimation, 'Samples averaged per AR(10) step (speed), samples.', minimum=1, maximum=1000)
    sweep_ar_process_var: float = parameter(
        _S.ar_process_var, 'Diagonal of Q_AR (eq. 25), dimensionless.', minimum=1e-12, maximum=1e12)
    sweep_ar_measurement_var: float = parameter(
        _S.ar_measurement_var, 'sigma_AR^2 (eq. 26), dimensionless.', minimum=1e-12, maximum=1e12)
    sweep_ar_transition: float = parameter(
        _S.ar_transition, 'Diagonal of the AR transition A (eq. 25; paper: 0.2), (-1, 1).',
        minimum=-0.999999, maximum=0.999999)
    sweep_delay: float = parameter(
        _S.delay, 'Samples from a sweep start to its detected peak (group delay), samples.',
        minimum=0.0, maximum=1e6)
    sweep_min_separation: int = parameter(
        _S.min_separation, 'Refractory time between two detected sweep starts, samples.', minimum=1, maximum=10**9)
    sweep_tolerance: float = parameter(
        _S.tolerance, 'Relative tolerance of a sweep interval to a multiple of the period, (0, 0.5).',
        minimum=1e-6, maximum=0.499999)
    sweep_min_consistent: int = parameter(
        _S.min_consistent, 'Peaks fitting the period lattice needed to lock, minus one.', minimum=1, maximum=100000)
    sweep_min_tolerance_samples: float = parameter(
        _S.min_tolerance_samples, 'Absolute floor of the lattice tolerance, samples.', minimum=0.0, maximum=1e6)
    sweep_max_period: float = parameter(
        _S.max_period, 'Longest sweep period considered by the lattice voting, samples (> sweep_min_separation).',
        minimum=1.0, maximum=1e9)
    sweep_lattice_voting: bool = parameter(
        _S.lattice_voting, 'Sweep period by lattice voting over all recent peaks (ours) instead of successive '
        'intervals (the paper).')
    # --- periodicity detector (ours) -----------------------------------------------------------
    analysis_enabled: bool = parameter(
        _A.enabled, 'Run the block-level periodicity detector of the frequency track (seeds the reset lattice '
        'and the identification).')
    analysis_hop_s: float = parameter(
        _A.hop_s, 'Interval between two periodicity analyses (at absolute sample indices), s.',
        minimum=1e-7, maximum=10.0)
    analysis_min_strength: float = parameter(
        _A.min_strength, 'Normalised autocorrelation peak-to-trough of a periodic track, (0, 1.5].',
        minimum=1e-6, maximum=1.5)
    analysis_min_lag: int = parameter(
        _A.min_lag, 'Shortest period detected, decimated samples.', minimum=2, maximum=10**9)
    analysis_max_period_fraction: float = parameter(
        _A.max_period_fraction, 'Longest period as a fraction of the analysed window, (0, 0.5].',
        minimum=1e-6, maximum=0.5)
    analysis_min_window: int = parameter(
        _A.min_window, 'Fewest decimated values for an analysis.', minimum=64, maximum=10**9)
    analysis_skip_while_tracking: bool = parameter(
        _A.skip_while_tracking, 'No periodicity analysis while in tracking mode (the confirmed lattice is then '
        'the periodicity evidence).')
    # --- identification (not in the paper) ----------------------------------------------------
    classifier_nfft: int = parameter(
        _C.nfft, 'Welch frame length, samples (a power of two).', minimum=32, maximum=2**20)
    classifier_max_frames: int = parameter(
        _C.max_frames, 'At most this many Welch frames per block.', minimum=8, maximum=10**7)
    classifier_sig_sigma: float = parameter(
        _C.sig_sigma, 'Significance of an occupied spectral bin, standard deviations of the Welch average.',
        minimum=1e-6, maximum=1e3)
    classifier_min_excess: float = parameter(
        _C.min_excess, 'Smallest relative excess of an occupied bin over the noise, dimensionless.',
        minimum=1e-6, maximum=1e6)
    classifier_detect_jn_db: float = parameter(
        _C.detect_jn_db, 'J/N above which a jammer is declared, dB.', minimum=-100.0, maximum=100.0)
    classifier_cw_max_occupancy: float = parameter(
        _C.cw_max_occupancy, 'Largest occupied fraction of the band of a CW, (0, 1).',
        minimum=1e-6, maximum=0.999999)
    classifier_min_chirp_rate: float = parameter(
        _C.min_chirp_rate, '|Sweep rate| that marks a chirp before the period locks, cycles/sample^2.',
        minimum=1e-12, maximum=1.0)
    classifier_template_smooth_bins: int = parameter(
        _C.template_smooth_bins, 'Width of the median filter smoothing the learned noise shape, bins.',
        minimum=1, maximum=2**20)
    classifier_sidelobe_db: float = parameter(
        _C.sidelobe_db, 'Bins more than this below the strongest excess are not occupied, dB.',
        minimum=0.0, maximum=300.0)
    classifier_confidence_slope_db: float = parameter(
        _C.confidence_slope_db, 'J/N margin that maps to a logistic confidence of 0.73, dB.',
        minimum=1e-6, maximum=100.0)

    def __post_init__(self) -> None:
        validate_ranges(self)
        if self.max_block_samples < self.min_block_samples:
            raise ValueError(f'max_block_samples {self.max_block_samples} must be >= min_block_samples '
                             f'{self.min_block_samples}')
        try:
            self.monitor_params()
        except ValueError as err:
            raise ValueError(f'invalid monitor parameters: {err}') from None

    def monitor_params(self) -> RfiMonitorParams:
        """The core's parameters. Core fields without a node parameter keep the core's default.

        Raises:
            ValueError: a combination the core rejects (e.g. min_block_samples < classifier_nfft).
        """
        own = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        nested: dict[str, Any] = {}
        for name, prefix, cls in NESTED:
            values = {f.name: own[prefix + f.name] for f in dataclasses.fields(cls) if prefix + f.name in own}
            if cls is TrackingFilterParams:
                values['mode'] = TRACKER_MODES[self.tracker_mode]
            nested[name] = dataclasses.replace(getattr(_M, name), **values)
        top = {f.name: own[f.name] for f in dataclasses.fields(RfiMonitorParams)
               if f.name in own and f.name not in nested}
        return dataclasses.replace(_M, **top, **nested)


def check_block(msg: IfSamples, min_block_samples: int, max_block_samples: int = 2 ** 31 - 1) -> str | None:
    """Why an IF block cannot be analysed (a ``rejected_<reason>`` key), or None if it is well formed.

    Checks the fields only (module docstring, in that order); :func:`is_blank` checks the values.

    Args:
        msg: rfi_msgs/IfSamples.
        min_block_samples, max_block_samples: shortest and longest block, samples (complex: I/Q pairs).
    """
    width = SAMPLE_WIDTH_BYTES.get(msg.sample_format)
    if width is None:
        return 'unknown_sample_format'
    if not 1 <= msg.bits_per_sample <= 8 * width:
        return 'bad_bits_per_sample'
    fs = msg.sample_rate_hz
    if not SAMPLE_RATE_MIN_HZ <= fs <= SAMPLE_RATE_MAX_HZ:   # False for NaN
        return 'bad_sample_rate'
    nyquist = fs if msg.is_complex else fs / 2.0
    if not abs(msg.intermediate_frequency_hz) < nyquist:
        return 'bad_intermediate_frequency'
    if not SCALE_MIN <= msg.scale <= SCALE_MAX:
        return 'bad_scale'
    if not 0.0 <= msg.center_frequency_hz <= CENTER_FREQUENCY_MAX_HZ:
        return 'bad_center_frequency'
    if len(msg.samples) == 0:
        return 'empty_block'
    if len(msg.samples) % width:
        return 'truncated_sample'
    values = len(msg.samples) // width
    if msg.is_complex and values % 2:
        return 'odd_length_iq'
    n = values // (2 if msg.is_complex else 1)
    if n < min_block_samples:
        return 'short_block'
    if n > max_block_samples:
        return 'long_block'
    if msg.first_sample_index + n > MAX_SAMPLE_INDEX:
        return 'bad_first_sample_index'
    return None


def warm_up(params: RfiMonitorParams) -> None:
    """Run a throw-away monitor on real and complex blocks of noise, then of noise with a saw-tooth chirp, so that
    the compiled (numba) functions of both the quiet and the tracking paths (the sweep profile, law and shape) are
    compiled or loaded from the cache at start-up, not on the first blocks of a live stream (seconds of CPU on a
    fresh install, which the load shedding would otherwise pay for by shedding the first blocks, or the input queue
    by dropping them)."""
    rng = np.random.default_rng(0)
    n = max(params.min_block_samples, 8192)
    fs = 4.0e6
    t = np.arange(n) / fs
    tau = np.mod(t, 64 / fs)                               # a 64-sample saw-tooth over 1 MHz
    for cplx in (False, True):
        mon = RfiMonitor(params)
        fif = 0.0 if cplx else 1.0e6
        phase = 2 * np.pi * (fif * t - 0.5e6 * tau + 0.5 * (1e6 / (64 / fs)) * tau ** 2)
        for k, jam in enumerate((0.0, 4.0, 4.0)):
            if cplx:
                z = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2) + jam * np.exp(1j * phase)
                x = np.empty(2 * n)
                x[0::2], x[1::2] = z.real, z.imag
            else:
                x = rng.standard_normal(n) + jam * np.cos(phase)
            mon.process(x, fs, fif, k * n, 1 + k * int(n / fs * 1e9), is_complex=cplx, full_scale=64.0)
    if params.spectral_step.enabled:
        spectral_step_warm_up(params.classifier.nfft)


def peek_stamp_ns(raw: bytes) -> int | None:
    """header.stamp of a serialised IfSamples in ns, read from its first bytes (little-endian CDR: a 4-byte
    encapsulation header, then stamp.sec int32 and stamp.nanosec uint32), or None if the bytes do not look
    like that (the message is then deserialised and checked as usual)."""
    if len(raw) < 12 or raw[0] != 0 or raw[1] not in (1, 3):      # CDR_LE / PL_CDR_LE
        return None
    sec = int.from_bytes(raw[4:8], 'little', signed=True)
    nsec = int.from_bytes(raw[8:12], 'little')
    if sec <= 0 or nsec >= NS_PER_S:
        return None
    return sec * NS_PER_S + nsec


def decode_counts(msg: IfSamples) -> np.ndarray:
    """The block's stored values (counts), read only: int8 or int16, shape (n,) real or (2n,) I, Q."""
    return np.frombuffer(msg.samples, dtype=SAMPLE_DTYPES[msg.sample_format])


def is_blank(counts: np.ndarray, is_complex: bool) -> bool:
    """True if the block has no variation: every value equal (real), or every I and every Q equal."""
    if not is_complex:
        return bool(counts.min() == counts.max())
    i, q = counts[0::2], counts[1::2]
    return bool(i.min() == i.max() and q.min() == q.max())


def count_range(bits: int) -> tuple[int, int]:
    """(lowest, highest) count a front end of ``bits`` bits per real value can deliver: two's complement
    ``[-2**(bits-1), 2**(bits-1) - 1]`` for bits >= 4; odd sign/magnitude levels ``+-(2**bits - 1)`` for 1-3 bits
    (MAX2769-type: 2 bits are +-1, +-3), which also holds a 1-3 bit two's-complement front end's values."""
    if bits < 4:
        return -(2 ** bits - 1), 2 ** bits - 1
    return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1


def exceeds_bits(counts: np.ndarray, bits: int) -> bool:
    """True if a stored value lies outside :func:`count_range` of the declared ``bits_per_sample`` (issue 27 item
    3: a 16-bit container declaring 8 bits with values to +-32767 is malformed, not a clipped block). Values
    that fill their container (8 bits in INT8, 16 in INT16) cannot exceed it."""
    lo, hi = count_range(bits)
    info = np.iinfo(counts.dtype)
    if lo <= info.min and hi >= info.max:
        return False
    return bool(counts.min() < lo or counts.max() > hi)


def decode_samples(msg: IfSamples) -> np.ndarray:
    """The block's values in volts: float64, shape (n,) real or (2n,) interleaved I, Q.

    ``msg`` must have passed :func:`check_block`. Values are ``count * scale``.
    """
    return decode_counts(msg).astype(np.float64) * msg.scale


def full_scale(msg: IfSamples) -> float | None:
    """Largest magnitude of the front end, V: (2**(bits - 1) - 1) * scale for bits >= 4, else None
    (odd-level 1-3 bit quantisers reach their top level in normal operation)."""
    if msg.bits_per_sample < 4:
        return None
    return float((2 ** (msg.bits_per_sample - 1) - 1) * msg.scale)


def jammer_state_msg(est: JammerEstimate, block: IfSamples) -> JammerState:
    """JammerEstimate -> rfi_msgs/JammerState (header and center frequency from the block).

    float32 fields are rounded to float32 here, so the message is the same whether a subscriber gets
    it over the wire or in-process (rclpy keeps a Python float's float64 value until serialisation).
    """
    m = JammerState()
    m.header = block.header
    m.type = int(est.type)
    m.confidence = float(np.float32(est.confidence))
    m.jammer_to_noise_db = float(est.jammer_to_noise_db)
    m.jammer_to_signal_db = float(est.jammer_to_signal_db)
    m.frequency_hz = float(est.frequency_hz)
    m.frequency_std_hz = float(est.frequency_std_hz)
    m.sweep_rate_hz_per_s = float(est.sweep_rate_hz_per_s)
    m.sweep_period_s = float(est.sweep_period_s)
    m.sweep_start_frequency_hz = float(est.sweep_start_frequency_hz)
    m.sweep_bandwidth_hz = float(est.sweep_bandwidth_hz)
    m.center_frequency_hz = float(block.center_frequency_hz)
    m.sample_rate_hz = float(est.sample_rate_hz)
    m.noise_reference = int(est.noise_reference)
    m.jammer_to_noise_is_lower_bound = bool(est.jammer_to_noise_is_lower_bound)
    m.clipped_fraction = float(np.float32(est.clipped_fraction))
    m.sweep_shape = int(est.sweep_shape)
    m.in_band_fraction = float(np.float32(est.in_band_fraction))
    return m


def rejected_total(counts: Counter[str]) -> int:
    """Sum of the ``rejected_*`` counters."""
    return sum(v for k, v in counts.items() if k.startswith('rejected_'))


class RfiMonitorNode(Node):
    """Thin node around :class:`rfi_monitor.monitor.RfiMonitor` (see module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('rfi_monitor', **kwargs)
        self.params = declare(self, MonitorNodeParams)
        self.runtime = RuntimeParameters(self, self.params)  # the settable parameters: applied between blocks
        self._window = CountWindow(self.params.diagnostics_window_s)
        self.worker: AnalysisWorker | None = None
        if self.params.analysis_worker and self.params.estimator == 'stft':
            try:
                self.worker = AnalysisWorker()
            except (RuntimeError, OSError) as err:
                self.get_logger().error(f'analysis_worker: the worker process did not start ({err}); analysing '
                                        'every block in this process')
        self.monitor = RfiMonitor(self.params.monitor_params(), worker=self.worker)
        warm_up(self.params.monitor_params())
        self.counts: Counter[str] = Counter()
        self.health = InputHealth()
        self._gate = StampGate(self.params.max_stamp_jump_s, self.params.stamp_jump_confirmations)
        self._core_counters: dict[str, int] = {}
        self._last_type: int | None = None
        self._last_clipped_fraction = 0.0
        self.load = LoadPolicy(self._load_params(self.params))
        self._errors_at_last_report = 0
        self._handler_errors_at_last_report = 0
        self._diag_timer = StampTimer(self.params.diagnostics_period_s)
        self.state_pub = self.create_publisher(JammerState, 'rfi/jammer_state', DATA_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # raw: bytes that rclpy cannot deserialise reach on_raw_block and are counted as malformed
        # (a non-raw subscription would drop them inside rclpy, seen only as a sequence gap)
        self.subscription = subscribe_input(self, IfSamples, IF_TOPIC, self.on_raw_block, self.health, raw=True,
                                            warning_throttle_s=self.params.warning_throttle_s)
        self.stale_watch = StaleInputWatch(self, self.health, self.params.input_timeout_s, self.publish_stale)

    def destroy_node(self) -> None:
        """Stop the analysis worker (if any), then the node."""
        if self.worker is not None:
            self.worker.close()
        super().destroy_node()

    def on_raw_block(self, raw: bytes | IfSamples) -> None:
        """A serialised block: deserialised by rclpy, or counted as ``rejected_malformed_message`` (a message
        object, as an in-process hand-over may give, goes straight to :meth:`on_block`)."""
        if self.runtime.pending:
            self.runtime.apply_pending(self._apply_parameters)
        if isinstance(raw, IfSamples):
            self.on_block(raw)
            return
        cpu0 = time.thread_time()
        try:
            stamp = peek_stamp_ns(raw)
            mode = self._load_mode(stamp, None) if stamp is not None else None
            if mode == SHED:
                # shed before the bytes are even deserialised: a node behind its stream must get cheaper
                self.counts['blocks_received'] += 1
                decision = self._gate.admit(stamp)
                if not decision.accepted:
                    self.counts[f'rejected_{decision.reason}'] += 1
                    return
                self.counts['blocks_shed'] += 1
                if self._diag_timer.due(stamp):
                    self._publish(lambda: self.diagnostics(stamp))
                return
            try:
                msg = deserialize_message(raw, IfSamples)
            except Exception as err:  # noqa: BLE001 - rclpy raises RMWError (and others) on malformed CDR
                self.counts['blocks_received'] += 1
                self.counts['rejected_malformed_message'] += 1
                self.get_logger().warn(f'IF block rejected: malformed message ({len(raw)} bytes: '
                                       f'{type(err).__name__})', throttle_duration_sec=self.params.warning_throttle_s)
                return
            self._handle(msg, load_mode=mode)
        finally:
            self.load.spend(time.thread_time() - cpu0)

    def on_block(self, msg: IfSamples) -> None:
        """Account for one block: processed (one JammerState), shed or rejected under a named reason; never
        raises."""
        cpu0 = time.thread_time()
        try:
            self._handle(msg, load_mode=None)
        finally:
            self.load.spend(time.thread_time() - cpu0)

    def _handle(self, msg: IfSamples, load_mode: str | None) -> None:
        """on_block's work; ``load_mode``: FULL or LIGHT when the load decision (:meth:`_load_mode`) was made on the
        raw bytes already, None when it is to be made here."""
        self.counts['blocks_received'] += 1
        stamp_ns: int | None = None
        try:
            reason, stamp_ns = self._admit_stamp(msg)
            if reason is None:
                reason = check_block(msg, self.params.min_block_samples, self.params.max_block_samples)
            mode = load_mode if load_mode is not None else (
                self._load_mode(stamp_ns, msg) if reason is None and stamp_ns is not None else FULL)
            if reason is None and mode == SHED:
                self.counts['blocks_shed'] += 1
            elif reason is None:
                reason = self._analyse(stamp_ns, msg, light=mode == LIGHT)
        except Exception as err:  # noqa: BLE001 - a bug in the checks: count it, never lose the block
            self.get_logger().error(f'IF block dropped, the node raised {type(err).__name__}: {err}',
                                    throttle_duration_sec=self.params.warning_throttle_s)
            reason = 'node_error'
        if reason is not None:
            self.counts[f'rejected_{reason}'] += 1
            self.get_logger().warn(f'IF block at {stamp_to_ns(msg.header.stamp)} ns rejected: {reason}',
                                   throttle_duration_sec=self.params.warning_throttle_s)
        if stamp_ns is not None and self._diag_timer.due(stamp_ns):
            self._publish(lambda: self.diagnostics(stamp_ns))

    @staticmethod
    def _load_params(params: MonitorNodeParams) -> LoadPolicyParams:
        return LoadPolicyParams(max_cpu_load=params.max_cpu_load, light_analysis_debt_s=params.light_analysis_debt_s,
                                max_block_age_s=params.max_block_age_s, light_allowed=params.estimator == 'stft')

    def _load_mode(self, stamp_ns: int, msg: IfSamples | None) -> str:
        """FULL, LIGHT or SHED for this block: :class:`rfi_monitor.load_policy.LoadPolicy` (a replay: FULL, always),
        given the block's duration (``msg`` None: a block judged on its raw bytes), its reception time (the system
        clock when the middleware does not report it) and its time in the input queue."""
        covered_s = 0.0
        if msg is not None and msg.sample_format in SAMPLE_WIDTH_BYTES and msg.sample_rate_hz > 0:
            n = len(msg.samples) // SAMPLE_WIDTH_BYTES[msg.sample_format] // (2 if msg.is_complex else 1)
            covered_s = n / msg.sample_rate_hz
        received_ns = self.health.last_received_ns
        return self.load.decide(stamp_ns, received_ns if received_ns > 0 else time.time_ns(), covered_s,
                                self.health.queued_s())

    def _admit_stamp(self, msg: IfSamples) -> tuple[str | None, int | None]:
        """(rejection reason or None, the stamp in ns if the StampGate accepted it)."""
        if msg.header.stamp.nanosec >= NS_PER_S:
            return 'bad_stamp_nanosec', None
        stamp_ns = stamp_to_ns(msg.header.stamp)
        decision = self._gate.admit(stamp_ns)
        if not decision.accepted:
            return decision.reason, None
        if decision.restart:
            self.counts['stamp_restarts'] += 1
            self.load.restart()
            self.get_logger().warn(f'IF block stamps jumped to {stamp_ns} ns (confirmed by '
                                   f'{self.params.stamp_jump_confirmations} blocks): new time line')
        return None, stamp_ns

    def _analyse(self, stamp_ns: int, msg: IfSamples, light: bool = False) -> str | None:
        """Run the core on a well-formed block (``light``: the light analysis will do) and publish its estimate;
        return a rejection reason."""
        counts = decode_counts(msg)
        if exceeds_bits(counts, int(msg.bits_per_sample)):
            return 'values_exceed_bits'
        if is_blank(counts, bool(msg.is_complex)):
            return 'blank_block'
        try:
            est = self.monitor.process(
                counts.astype(np.float64) * msg.scale, msg.sample_rate_hz, msg.intermediate_frequency_hz,
                msg.first_sample_index, stamp_ns, is_complex=bool(msg.is_complex),
                full_scale=full_scale(msg) if self.params.check_saturation else None, bits=int(msg.bits_per_sample),
                light=light)
        except Exception as err:  # noqa: BLE001 - the checks should make this unreachable; count it, keep going
            self.get_logger().error(f'core raised on a checked IF block ({type(err).__name__}: {err})',
                                    throttle_duration_sec=self.params.warning_throttle_s)
            return 'core_error'
        self._core_counters = dict(est.counters)
        if not est.valid:
            return est.rejection or NON_FINITE
        self.counts['blocks_processed'] += 1
        if est.light:
            self.counts['blocks_light'] += 1
        self._last_type = int(est.type)
        self._last_clipped_fraction = float(est.clipped_fraction)
        self.state_pub.publish(jammer_state_msg(est, msg))
        self.counts['states_published'] += 1
        return None

    def _publish(self, make: Any) -> None:
        """Publish the diagnostics ``make()`` builds; a failure is logged, never raised (diagnostics only)."""
        try:
            self.diag_pub.publish(make())
        except Exception as err:  # noqa: BLE001 - a report must never end the node
            self.get_logger().error(f'/diagnostics not published: {type(err).__name__}: {err}',
                                    throttle_duration_sec=self.params.warning_throttle_s)

    def _apply_parameters(self, old: MonitorNodeParams, new: MonitorNodeParams) -> None:
        """A change of the settable parameters (node-level only: hardware_id, the diagnostics window and
        thresholds, warning_throttle_s; the core's parameters are read-only)."""
        self.params = new
        self._window.window_ns = int(round(new.diagnostics_window_s * 1e9))
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{name} = {getattr(new, name)!r}' for name in changed_names(old, new)))

    def publish_stale(self, silent_s: float) -> None:
        """StaleInputWatch: a STALE status stamped with the node clock (no input for ``silent_s`` s)."""
        def make() -> DiagnosticArray:
            topic = self.subscription.topic_name
            return diagnostic_array(max(0, self.get_clock().now().nanoseconds), 'rfi_monitor', self.params.hardware_id,
                                    STALE, f'no input on {topic} for {silent_s:.1f} s', self.accounting())
        self._publish(make)

    def accounting(self) -> dict[str, object]:
        """Counters of the node, the core and the subscription, and whether every block received is accounted for."""
        values: dict[str, object] = dict(sorted(self.counts.items()))
        for key in ('blocks_received', 'blocks_processed', 'blocks_light', 'states_published', 'stamp_restarts',
                    'blocks_shed', 'blocks_shed_stale'):
            values.setdefault(key, 0)
        core = self._core_counters
        values['gaps'] = core.get('gaps', 0)
        values['rate_changes'] = core.get('rate_changes', 0)
        values.update({f'core.{k}': v for k, v in sorted(core.items()) if k not in ('gaps', 'rate_changes')})
        values['calibrated'] = self.monitor.calibrated
        values['last_type'] = 'none yet' if self._last_type is None else TYPE_NAMES.get(self._last_type, '?')
        values['last_clipped_fraction'] = self._last_clipped_fraction
        values['live_stream'] = 'unknown' if self.load.live is None else self.load.live
        values['blocks_shed_stale'] = self.load.counts['shed_stale']
        for key in ('full', 'light', 'shed', 'shed_stale', 'not_live'):
            values[f'load.{key}'] = self.load.counts[key]
        values.update(self.health.values())
        received = self.counts['blocks_received']
        values['accounting_ok'] = (self.health.counts[f'{self.subscription.topic_name}.received'] == received
                                   == self.counts['blocks_processed'] + self.counts['blocks_shed']
                                   + rejected_total(self.counts))
        return values

    def diagnostics(self, stamp_ns: int) -> DiagnosticArray:
        """The /diagnostics message at ``stamp_ns`` (levels: see the module docstring)."""
        values = self.accounting()
        rejected = rejected_total(self.counts)
        errors = self.counts['rejected_core_error'] + self.counts['rejected_node_error']
        new_errors = errors - self._errors_at_last_report
        self._errors_at_last_report = errors
        lost = self.health.lost_total()
        handler_errors = self.health.callback_errors_total()
        new_handler_errors = handler_errors - self._handler_errors_at_last_report
        self._handler_errors_at_last_report = handler_errors
        state = f'last type {values["last_type"]}' if self.monitor.calibrated else 'learning the noise floor'
        degraded = self._degraded(stamp_ns, rejected, lost)  # every report moves the window
        if not values['accounting_ok']:
            level, text = ERROR, 'block accounting does not add up'
        elif new_errors:
            level, text = ERROR, f'{new_errors} blocks made the core or the node raise since the last report'
        elif new_handler_errors:
            level, text = ERROR, f'the input handler raised {new_handler_errors} times since the last report'
        elif degraded:
            level, text = WARN, (f'inputs degraded (window {self.params.diagnostics_window_s:g} s): '
                                 + '; '.join(degraded))
        else:
            level, text = OK, 'monitoring'
        return diagnostic_array(stamp_ns, 'rfi_monitor', self.params.hardware_id, level, f'{text}; {state}', values)

    def _degraded(self, stamp_ns: int, rejected: int, lost: int) -> list[str]:
        """WARN texts: rejected / lost fractions of the blocks over diagnostics_window_s above their thresholds
        (an isolated rejected block among many stays OK)."""
        w = self._window.update(stamp_ns, {'received': self.counts['blocks_received'], 'rejected': rejected,
                                           'lost': lost})
        return (degraded_inputs([('blocks rejected', w['rejected'], w['received'])], self.params.warn_rejected_fraction)
                + degraded_inputs([('messages lost', w['lost'], w['received'] + w['lost'])],
                                  self.params.warn_lost_fraction))


def main(argv=None) -> int:
    return run_node(RfiMonitorNode, executable='rfi_monitor_node', params_cls=MonitorNodeParams, topics=TOPICS,
                    summary='Detect, classify and track GNSS jammers from IF sample blocks (Kang et al.).',
                    argv=argv)

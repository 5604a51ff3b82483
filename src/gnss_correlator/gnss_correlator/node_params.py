"""Parameters of gnss_correlator_node, each written once (pure: no rclpy); the shipped
``config/gnss_correlator.yaml`` is generated from them (:data:`CONFIG_FILE`, ``tools/generate_config.py``)."""

from __future__ import annotations

from dataclasses import dataclass

from gnss_correlator.receiver import IQ_SCALINGS, ReceiverConfig
from gnss_correlator.tracking import TrackingConfig
from rfi_node_common.diagnostics import NodeDiagnosticsParams, hardware_id_parameter
from rfi_node_common.params import USER, ConfigFile, parameter, validate_ranges


@dataclass(frozen=True)
class CorrelatorNodeParams(NodeDiagnosticsParams):
    """Parameters of the gnss_correlator node (documented for users in config/gnss_correlator.yaml).

    Notes:
        Acquisition: parallel code-phase FFT search (Borre et al. 2007) with a derived threshold
        (gnss_correlator.acquisition). Tracking: Kaplan & Hegarty Fig. 5-23 and Table 5-6
        (gnss_correlator.tracking). Output convention: Zhao et al., eq. 2-3 (gnss_correlator.receiver).
    """

    prns: tuple[int, ...] = parameter(
        list(range(1, 33)), 'GPS PRNs searched by the acquisition (1..37).', group=USER)
    spectrum_inverted: bool = parameter(
        False, 'Complex samples whose spectrum is inverted (the signal is I - jQ): conjugated before use. True '
        'for the PocketSDR 4 MHz I/Q sample capture (docs/gnss_correlator/README.md). Real samples say it with a '
        'negative IF in the IfSamples message instead.', group=USER)
    iq_scaling: str = parameter(
        'unit_amplitude', "Normalisation of the published I/Q; must equal imm_carrier's iq_scaling: "
        'unit_amplitude (signal amplitude 1) or unit_noise (noise std 1 per component).',
        choices=IQ_SCALINGS, group=USER)
    frame_id: str = parameter(
        'gnss_receiver', 'header.frame_id of the published CorrelatorArray (the receiver).', group=USER)
    doppler_max_hz: float = parameter(
        5000.0, 'Acquisition Doppler range +-, Hz: satellite motion (about +-5 kHz) plus the oscillator offset '
        '(a 1 ppm TCXO adds 1.6 kHz).', minimum=100.0, maximum=50000.0, group=USER)
    batch_ms: float = parameter(
        10.0, 'Stream time gathered before the receiver is called, ms (the answers move by up to this, not their '
        'values: the periods do not depend on the block size). Measured in process (12 channels, 4 MS/s complex, '
        'load 12): the receiver cost 0.92 of real time in CPU fed 1-ms blocks (if_source\'s and the monitor\'s '
        'default) and 0.36 fed 10-ms blocks; 0: every block at once.', minimum=0.0, maximum=1000.0)
    idle_flush_ms: float = parameter(
        50.0, 'Wall time without an input block after which the gathered blocks are processed and the stream\'s '
        'counters reported, ms (the end of a stream; a live stream of blocks shorter than batch_ms never waits '
        'this long between two).', minimum=1.0, maximum=10000.0)
    acquisition_ms: int = parameter(
        10, 'Milliseconds of samples per acquisition (1-ms coherent sums added non-coherently); more finds '
        'weaker satellites and takes longer.', minimum=2, maximum=100)
    acquisition_hold_s: float = parameter(
        4.0, 'Stream time held (checked, not yet tracked) while the first acquisition of a stream runs in the '
        'worker thread, s: the input keeps being taken meanwhile; past it the node waits for the search. The '
        'outputs do not depend on it. Memory: 4 bytes per real sample held, 8 per complex one (16.368 MS/s real: '
        '65 MB per s; twice that when a scale that is not a power of two makes single precision inexact); '
        '0: the first acquisition in the callback.', minimum=0.0, maximum=60.0)
    false_alarm_probability: float = parameter(
        1e-3, 'Stated false-alarm probability of one satellite search (the threshold is derived from it).',
        minimum=1e-9, maximum=0.1)
    reacquisition_period_s: float = parameter(
        10.0, 'Stream time between searches for the PRNs not tracked, s. Each search runs in a worker thread '
        '(0.3-2 s of CPU) while the tracked channels go on.', minimum=0.1, maximum=3600.0)
    reacquisition_lag_s: float = parameter(
        1.0, 'Stream time from the end of a search window to the block where the channels it found start, s. '
        'The node waits for the search there only if it has not finished: a lag longer than a search takes '
        'never delays a block, and the outputs do not depend on the machine.', minimum=0.0, maximum=60.0)
    pll_bandwidth_hz: float = parameter(
        TrackingConfig.pll_bandwidth_hz, 'Noise bandwidth of the second-order Costas PLL, Hz.',
        minimum=1.0, maximum=50.0)
    fll_bandwidth_hz: float = parameter(
        TrackingConfig.fll_bandwidth_hz, 'Noise bandwidth of the first-order FLL assist during pull-in, Hz (0: '
        'none).', minimum=0.0, maximum=50.0)
    fll_assist_ms: int = parameter(
        TrackingConfig.fll_assist_ms, 'Periods (ms) after a channel starts with the FLL assist on.',
        minimum=0, maximum=100000)
    dll_bandwidth_hz: float = parameter(
        TrackingConfig.dll_bandwidth_hz, 'Noise bandwidth of the carrier-aided first-order DLL, Hz.',
        minimum=0.1, maximum=10.0)
    early_late_offset_chips: float = parameter(
        TrackingConfig.early_late_offset_chips, 'Offset of the early and late replicas from the prompt, chips.',
        minimum=0.05, maximum=0.5)
    cn0_window_ms: int = parameter(
        TrackingConfig.cn0_window_ms, 'Periods (ms) in the C/N0 window (noise-reference estimator: prompt power '
        'minus the power of a correlator 300+ chips off the code, over the latter); no correlator is published for '
        'a channel before its first window is full.', minimum=10, maximum=10000)
    coherent_ms: int = parameter(
        1, 'Coherent interval published per channel, ms: 1, or 20 = one correlator per navigation data bit once '
        'the channel is bit-synchronised (histogram of prompt sign changes; 1-ms ones before).', minimum=1, maximum=20)
    lock_window_ms: int = parameter(
        TrackingConfig.lock_window_ms, 'Periods (ms) of the lock rule: a channel is locked while its PLL '
        'discriminator std over them is at most lock_phase_std_max_rad and it made no half-cycle wrap.',
        minimum=10, maximum=10000)
    lock_phase_std_max_rad: float = parameter(
        TrackingConfig.lock_phase_std_max_rad, 'Largest PLL discriminator std of a locked channel over '
        'lock_window_ms, rad (0.5: the 1-ms discriminator noise near 33 dB-Hz).', minimum=0.01, maximum=1.5707963)
    wrap_block_ms: int = parameter(
        TrackingConfig.wrap_block_ms, 'Prompts summed per block of the slip detector: a half-cycle wrap is a change '
        'of the blocks\' Costas angle by more than pi/2 (1: consecutive 1-ms prompts, fastest; more: fewer noise '
        'wraps below ~38 dB-Hz, a slip seen up to that many ms later). At most lock_window_ms / 2.',
        minimum=1, maximum=5000)
    min_cn0_dbhz: float = parameter(
        30.0, 'A channel whose C/N0 stays below this for drop_after_ms periods is dropped, dB-Hz.',
        minimum=0.0, maximum=60.0)
    drop_after_ms: int = parameter(
        200, 'Periods (ms) in a row below min_cn0_dbhz before a channel is dropped.', minimum=1, maximum=100000)
    max_block_samples: int = parameter(
        40_000_000, 'Longest IF block accepted, samples (complex: I/Q pairs); longer ones are rejected '
        '(long_block).', minimum=1, maximum=2 ** 31 - 1)
    hardware_id: str = hardware_id_parameter('gnss_receiver')  # type: ignore[assignment]
    # the stamp gate, silence watch and /diagnostics parameters: rfi_node_common.diagnostics.NodeDiagnosticsParams

    def __post_init__(self) -> None:
        validate_ranges(self)
        try:
            self.receiver()
        except ValueError as err:
            raise ValueError(f'invalid receiver parameters: {err}') from None

    def receiver(self) -> ReceiverConfig:
        """The core's configuration."""
        tracking = TrackingConfig(
            pll_bandwidth_hz=self.pll_bandwidth_hz, fll_bandwidth_hz=self.fll_bandwidth_hz,
            fll_assist_ms=self.fll_assist_ms, dll_bandwidth_hz=self.dll_bandwidth_hz,
            early_late_offset_chips=self.early_late_offset_chips, cn0_window_ms=self.cn0_window_ms,
            lock_window_ms=self.lock_window_ms, lock_phase_std_max_rad=self.lock_phase_std_max_rad,
            wrap_block_ms=self.wrap_block_ms)
        return ReceiverConfig(
            prns=tuple(int(p) for p in self.prns), acquisition_ms=self.acquisition_ms,
            doppler_max_hz=self.doppler_max_hz, false_alarm_probability=self.false_alarm_probability,
            reacquisition_period_s=self.reacquisition_period_s, reacquisition_lag_s=self.reacquisition_lag_s,
            tracking=tracking,
            min_cn0_dbhz=self.min_cn0_dbhz, drop_after_ms=self.drop_after_ms, iq_scaling=self.iq_scaling,
            spectrum_inverted=self.spectrum_inverted, coherent_ms=self.coherent_ms,
            acquisition_hold_s=self.acquisition_hold_s)


CONFIG_FILE = ConfigFile('gnss_correlator', 'config/gnss_correlator.yaml', 'gnss_correlator', CorrelatorNodeParams, """
Parameters of gnss_correlator_node (gnss_correlator/gnss_correlator_node.py, CorrelatorNodeParams).
GENERATED by tools/generate_config.py from gnss_correlator/node_params.py. Change a default or a
description there and run `python tools/generate_config.py`; a test checks this file equals it.
Method and measurements: docs/gnss_correlator/README.md.

Use:   ros2 run gnss_correlator gnss_correlator_node --ros-args --params-file gnss_correlator.yaml
Every value below is the default. An invalid value stops the node with a one-line error naming the
parameter, and so does a parameter the node does not have. Floats need a decimal point.

Input  /rfi/if_samples (rfi_msgs/IfSamples): the front end's stream, as rfi_monitor takes it (real or
       complex, INT8 or INT16, any rate from 2 MS/s, IF from the message). A change of rate, IF or
       sample type, or a gap in first_sample_index, restarts acquisition (counted).
Output /gnss/correlators (rfi_msgs/CorrelatorArray): one array per 1-ms interval of the stream with
       the prompt of every tracked channel whose code period ended in it, in imm_carrier's convention
       (the carrier NCO in the role of the open-loop replica); stamp = end of the interval, from the
       IfSamples stamps. /diagnostics: counters every diagnostics_period_s of stamp time.
""")
"""The shipped config/gnss_correlator.yaml (:func:`rfi_node_common.params.config_yaml`)."""

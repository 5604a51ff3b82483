"""The parameters of the GNSS/UWB fusion filter, in groups: the bases of ``fusion_params.FusionParams``.

Pure core (no rclpy). One frozen dataclass per group of parameters; each field is a parameter of fusion_node written
once (:func:`rfi_node_common.params.parameter`: default, description, range, group, settable while running), and each
group's docstring holds the design notes of its fields (why, and the evidence). ``FusionParams`` joins them, validates
them and derives the values the filter uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gnss_common.jamming_weights import TrackingLoopParams
from rfi_node_common.message_checks import UWB_RANGE_MAX_M
from rfi_node_common.params import USER, internal, parameter


@dataclass(frozen=True)
class SensorModelParams:
    """FusionParams, sensors and models (.measurement_models, .gnss_update, .uwb_update).

    Design notes (why, and the evidence; the meaning is in each field's description):
        glonass_pseudorange_error_factor: the sigma of a GLONASS pseudorange from its C/N0 (or
            elevation, or the receiver's std) times this: GLONASS code has larger errors than the
            CDMA systems' (FDMA inter-frequency biases, broadcast orbit and clock; ESBC00DNK's mean
            within-satellite residual std 1.03 m against 0.45-0.54 m for GPS, Galileo, BeiDou).
            1.5 is RTKLIB's convention (``EFACT_GLO`` in ``pntpos.c``, ``varerr``; SBAS 3.0, which the
            filter skips), not a value fitted here; the constant part of the GLONASS error is the
            per-satellite bias state's (``glonass_satellite_bias_std_m``).
        pseudorange_broadcast_std_m: the sigma from C/N0 (Cao et al., eq. 12) is the tracking noise
            alone; a real pseudorange also carries its satellite's broadcast orbit and clock error
            (SISRE), independent of C/N0 and elevation, which the project's SPP puts in its weights
            (``gnss_common.spp.SppParams.sigma_broadcast_m`` = 1 m). With 1 m the weights are flatter: on
            ESBC00DNK's whole day, GPS alone, the filter goes from 1.47 m to 1.37 m horizontal RMS (our
            SPP 1.44 m), on ARL1 / GEONET 0759 / 3040 from 25 / 15 / 18 % to 21 / 22 / 21 % better than
            SPP; but ESBC00DNK with GPS + Galileo + BeiDou gets worse (1.045 -> 1.10 m horizontal), and
            so do the simulated receivers of docs/uwb_gnss_fusion/motion_model.md horizontally (static
            0.58 -> 0.63 m; 3D 1.07 -> 0.99 m; 30 dB J/S mean 3D 2.18 -> 2.24 m), so it is off (0) by
            default: docs/uwb_gnss_fusion/fusion_esbc_diagnosis.md.
    """

    use_gnss: bool = parameter(
        True,
        'Apply GNSS pseudoranges (Cao et al., eq. 5). false: UWB-only filter (needs 3 anchors to initialise).',
        group=USER,
    )
    use_doppler: bool = parameter(
        True,
        'Apply pseudorange rates (Doppler) as well as pseudoranges.',
    )
    use_uwb: bool = parameter(
        True,
        'Apply UWB ranges (Cao et al., eq. 7). false: the GNSS-only baseline filter of the paper.',
        group=USER,
    )
    accel_psd_m2ps3: float = parameter(
        0.1,
        'White-acceleration PSD per axis of the constant-velocity model, m^2/s^3.',
        minimum=1e-09, maximum=10000.0,
    )


@dataclass(frozen=True)
class StaticModelParams:
    """FusionParams, the static model and its detector (.motion_model, issue 27 item 4).

    Design notes (why, and the evidence; the meaning is in each field's description):
        motion_detection: let :class:`.motion_model.StationarityDetector` switch between the moving
            model and a static one (GNSS epochs in the earth frame, no UWB range in the last
            ``uwb_init_window_s``); False: always the moving model.
        anchors: optional registry ``((anchor_id, x, y, z), ...)`` in the anchors' frame, m. If
            non-empty, ranges from other anchor ids are rejected ("unknown_anchor") and the
            registered position is used.
    """

    motion_detection: bool = parameter(
        True,
        'Find out from the GNSS epochs whether the receiver is static and then run the static model '
        '(uwb_gnss_fusion.motion_model; not while UWB ranges arrive). False: always the moving model.',
    )
    static_enter_s: float = parameter(
        10.0,
        'How long every GNSS epoch must show a velocity consistent with zero before the receiver is '
        'declared static, s.',
        minimum=0.0, maximum=3600.0,
    )
    static_accel_psd_m2ps3: float = parameter(
        1.0e-8,
        'White-acceleration PSD per axis of the static model, m^2/s^3.',
        minimum=1e-15, maximum=10000.0,
    )
    static_velocity_std_mps: float = parameter(
        1.0e-3,
        '1-sigma per axis of the zero-velocity update applied when the receiver is declared static, m/s.',
        minimum=1e-06, maximum=10.0,
    )
    clock_h0_s: float = parameter(
        2.0e-19,
        'Receiver clock white-FM coefficient h0, s.',
        minimum=1e-30, maximum=1e-12,
    )
    clock_h_minus2_hz: float = parameter(
        2.0e-20,
        'Receiver clock random-walk-FM coefficient h_-2, 1/s.',
        minimum=0.0, maximum=1e-12,
    )
    uwb_range_std_m: float = parameter(
        0.1,
        'UWB range 1-sigma used when a UwbRange gives NaN range_std_m, m. DW1000 line of sight: 0.05-0.1. '
        'Values larger than about 0.3 let range-only updates pull the estimate towards the anchors '
        '(docs/uwb_gnss_fusion/fusion_jamming.md, known limitations).',
        minimum=0.0001, maximum=100.0, read_only=False, group=USER,
    )
    uwb_lever_arm_m: tuple[float, float, float] = parameter(
        (0.0, 0.0, 0.0),
        'UWB tag minus GNSS antenna, in the state frame (ECEF or map), m, [x, y, z]. The filter has no '
        'attitude, so this is a fixed offset in that frame; keep it zero when the tag sits at the antenna.',
        group=USER,
    )
    uwb_max_range_m: float = parameter(
        500.0,
        'Longest physical UWB range; longer ranges are rejected, m (at most the node\'s input check, '
        'rfi_node_common.message_checks.UWB_RANGE_MAX_M, 10 km).',
        minimum=1.0, maximum=UWB_RANGE_MAX_M, read_only=False,
    )
    anchors: tuple[tuple[str, float, float, float], ...] = internal(())
    gate_probability: float = parameter(
        0.9999,
        'Per-measurement innovation gate, probability of the 1-dof chi-square (1: no gating).',
        minimum=0.5, maximum=1.0,
    )
    elevation_mask_deg: float = parameter(
        10.0,
        "Satellites below this elevation are rejected, deg. 10 deg (the SPP's mask): below it residual "
        'troposphere and multipath dominate on real stations (docs/uwb_gnss_fusion/fusion_real_gnss.md).',
        minimum=-90.0, maximum=89.0, read_only=False, group=USER,
    )
    min_cn0_dbhz: float = parameter(
        20.0,
        'Pseudoranges with a lower reported C/N0 are rejected, dB-Hz.',
        minimum=0.0, maximum=70.0, read_only=False, group=USER,
    )
    nominal_cn0_dbhz: float = parameter(
        45.0,
        'Jammer-free C/N0 to which eq. 4 applies the received J/S, dB-Hz (typical open sky: 45).',
        minimum=0.0, maximum=70.0, read_only=False, group=USER,
    )
    pseudorange_broadcast_std_m: float = parameter(
        0.0,
        "1-sigma of each pseudorange's broadcast orbit and clock error (signal-in-space range error), m, added "
        'in quadrature to the sigma from C/N0 or elevation (not to a receiver-reported std). 0: tracking noise only.',
        minimum=0.0, maximum=100.0,
    )
    glonass_pseudorange_error_factor: float = parameter(
        1.5,
        'GLONASS pseudorange 1-sigmas are multiplied by this (the FDMA inter-frequency code biases and the '
        "broadcast orbit/clock; RTKLIB's EFACT_GLO convention, 1.5). 1: weighted as the CDMA systems "
        '(docs/uwb_gnss_fusion/fusion_multignss.md).',
        minimum=1.0, maximum=100.0,
    )
    jammer_quality_factor: float = parameter(
        1.0,
        'Jamming resistance quality factor Q of eq. 4: 1 for narrowband / swept (chirp) jammers, about 1.5 '
        'for matched-spectrum, 2 for wideband noise.',
        minimum=0.01, maximum=100.0, read_only=False, group=USER,
    )
    jammer_info_timeout_s: float = parameter(
        2.0,
        'A J/S older than this is ignored, s.',
        minimum=0.01, maximum=3600.0, read_only=False,
    )
    loop: TrackingLoopParams = internal(default_factory=TrackingLoopParams)


@dataclass(frozen=True)
class InitialisationParams:
    """FusionParams, initialisation (.initialisation).

    Design notes (why, and the evidence; the meaning is in each field's description):
        init_clock_drift_unobserved_std_mps: clock-drift 1-sigma at an initialisation where the
            drift is unobserved (no Doppler in the fix) and no earlier drift estimate exists, m/s
            (1000 m/s covers a crystal's +-3 ppm; GEONET receivers drift by +418 and -330 m/s). On a
            reinitialisation the drift of the lost state is kept (the oscillator did not change).
    """

    min_satellites_init: int = parameter(
        5,
        'Satellites needed to initialise from GNSS alone.',
        minimum=4, maximum=64,
    )
    init_position_std_m: float = parameter(
        10.0,
        'Initial position 1-sigma per axis, m.',
        minimum=0.001, maximum=10000000.0,
    )
    init_velocity_std_mps: float = parameter(
        1.0,
        'Initial velocity 1-sigma per axis, m/s.',
        minimum=0.0001, maximum=10000.0,
    )
    init_clock_bias_std_m: float = parameter(
        10.0,
        'Initial receiver clock bias 1-sigma, m.',
        minimum=0.001, maximum=10000000.0,
    )
    init_clock_drift_std_mps: float = parameter(
        1.0,
        'Initial receiver clock drift 1-sigma, m/s.',
        minimum=0.0001, maximum=10000.0,
    )
    init_clock_drift_unobserved_std_mps: float = parameter(
        1000.0,
        'Clock drift 1-sigma at an initialisation without Doppler and without an earlier drift estimate, '
        'm/s.',
        minimum=0.0001, maximum=100000.0,
    )


@dataclass(frozen=True)
class DivergenceParams:
    """FusionParams, time gaps and divergence (.divergence), re-initialisation."""

    max_prediction_s: float = parameter(
        120.0,
        'A measurement further than this after the filter time resets the filter, s.',
        minimum=0.01, maximum=3600.0,
    )
    max_position_std_m: float = parameter(
        200.0,
        'A larger position 1-sigma (any axis) is declared divergence, m.',
        minimum=0.01, maximum=10000000.0, read_only=False,
    )
    divergence_gnss_epochs: int = parameter(
        5,
        'Consecutive GNSS epochs with at least half of >= 4 pseudoranges gated out that declare '
        'divergence.',
        minimum=1, maximum=100000, read_only=False,
    )
    divergence_uwb_ranges: int = parameter(
        40,
        'Window of recent UWB ranges (all anchors) examined for divergence.',
        minimum=1, maximum=100000,
    )
    reference_max_age_s: float = parameter(
        5.0,
        'A reference (SPP) solution older than this is not used to re-initialise, s.',
        minimum=0.01, maximum=3600.0,
    )
    uwb_init_window_s: float = parameter(
        1.0,
        'Ranges used for UWB multilateration must lie within this window, s.',
        minimum=0.01, maximum=3600.0,
    )


@dataclass(frozen=True)
class BeyondPaperParams:
    """FusionParams, beyond the paper: UWB latency, divergence window, iterated update, Huber, common-mode screen.

    Design notes (why, and the evidence; the meaning is in each field's description):
        divergence_uwb_gated_fraction: divergence is declared when at least this fraction of the
            last ``divergence_uwb_ranges`` ranges was gated out, in (0, 1] (1: that many
            consecutive gated ranges, the original rule).
        uwb_latency_s: age of a UWB range at its stamp, s (>= 0; 0: the paper's model). The range
            is modelled as the distance at ``stamp - uwb_latency_s`` (constant-velocity
            back-propagation). Beyond the paper; set it from the ranging hardware / time-base
            calibration, not per data set.
        max_update_iterations: Gauss-Newton (iterated) refinement steps allowed after a cubature
            update whose linearisation error is significant (0: the plain CKF update of Cao et al.
            eq. 17-24). Beyond the paper; see :meth:`.ckf.CubatureKalmanFilter.update`.
        uwb_huber_k_positive: Huber threshold for positive UWB innovations (measured range longer
            than predicted, the non-line-of-sight direction); inf: positive innovations are not
            down-weighted.
        common_mode_screen: before the CKF update, drop pseudoranges and pseudorange rates whose
            innovation departs from the epoch's median (common clock) innovation by more than the
            gate allows with the clock-free variance (:mod:`.robust_screen`; beyond the paper).
            Counted as ``common_mode_pseudorange`` / ``common_mode_doppler``; they count as gated
            for the divergence rule.
        receiver_clock_steps: take a step common to every pseudorange that the predicted clock
            cannot explain (at least five satellites and more than half agreeing) for a step of the
            receiver clock and move the clock bias by it before the screen and the update, instead
            of rejecting every pseudorange and rebuilding the position
            (:func:`.clock_steps.receiver_clock_step`; beyond the paper). Whole milliseconds (the
            usual adjustment of receivers whose clock drifts) are counted as
            ``receiver_clock_step_ms``, other steps as ``receiver_clock_step``.
    """

    uwb_latency_s: float = parameter(
        0.0,
        'Age of a UWB range at its stamp (modelled by constant-velocity back-propagation), s.',
        minimum=0.0, maximum=1.0,
    )
    divergence_uwb_gated_fraction: float = parameter(
        0.5,
        'Divergence is declared when at least this fraction of the last divergence_uwb_ranges ranges was '
        'gated out (1.0: that many consecutive gated ranges).',
        minimum=0.01, maximum=1.0, read_only=False,
    )
    max_update_iterations: int = parameter(
        5,
        'Gauss-Newton refinement steps allowed after a cubature update with a significant linearisation '
        'error (0: the plain CKF update of the paper).',
        minimum=0, maximum=50, read_only=False,
    )
    nonlinearity_threshold: float = parameter(
        0.05,
        'Refine an update when its linearisation-error variance exceeds this fraction of the measurement '
        'noise variance.',
        minimum=1e-06, maximum=1000000.0, read_only=False,
    )
    uwb_huber_k: float = parameter(
        math.inf,
        'Huber threshold on the normalised UWB innovation (.inf: off).',
        minimum=0.01, read_only=False,
    )
    uwb_huber_k_positive: float = parameter(
        math.inf,
        'Huber threshold for positive UWB innovations (NLOS direction; .inf: not down-weighted).',
        minimum=0.01, read_only=False,
    )
    common_mode_screen: bool = parameter(
        True,
        'Drop pseudoranges / rates whose innovation departs from the epoch median (common clock) beyond '
        'the gate with the clock-free variance, before the CKF update (beyond the paper).',
        read_only=False,
    )
    receiver_clock_steps: bool = parameter(
        True,
        'Take a pseudorange step common to all satellites (>= 5 and more than half agreeing) that the '
        'predicted clock cannot explain for a receiver clock step (e.g. 1 ms adjustments) and move the '
        'clock by it, instead of rejecting every pseudorange (beyond the paper).',
        read_only=False,
    )


@dataclass(frozen=True)
class MultiGnssParams:
    """FusionParams, multi-GNSS: inter-system clock biases (issue 15 item 1).

    Design notes (why, and the evidence; the meaning is in each field's description):
        multi_gnss: use Galileo, BeiDou, GLONASS and QZSS satellites as well as GPS, each system
            other than the reference (GPS) with an inter-system clock bias state (appended to the
            state when the system is first seen, so that a GPS-only stream keeps the 8-state
            filter; process model and initialisation: :data:`INTER_SYSTEM_BIAS_PSD_M2PS`,
            :data:`INTER_SYSTEM_BIAS_INIT_STD_M`, :data:`INTER_SYSTEM_BIAS_MAX_GAP_S`); False: GPS
            only, the others counted as ``skipped_constellation.<name>``. SBAS is always skipped.
    """

    multi_gnss: bool = parameter(
        True,
        'Use Galileo, BeiDou, GLONASS and QZSS satellites as well as GPS, each system other than GPS with an '
        'inter-system clock bias state (added when the system is first seen: a GPS-only input keeps the '
        '8-state filter). false: GPS only, the others counted as skipped_constellation.<name>. Gain on a '
        'real station: docs/uwb_gnss_fusion/fusion_multignss.md.',
        group=USER,
    )


@dataclass(frozen=True)
class CorrelatedErrorParams:
    """FusionParams, time-correlated pseudorange errors, one Gauss-Markov state per satellite (issue 15 item 2).

    Design notes (why, and the evidence; the meaning is in each field's description):
        pseudorange_correlated_std_m / pseudorange_correlated_tau_s: stationary 1-sigma (m) and
            correlation time (s) of the time-correlated part of each pseudorange error (residual
            orbit, clock and atmosphere, multipath), a first-order Gauss-Markov state per tracked
            satellite (Brown & Hwang, 4th ed., sec. 4.2), allocated when the satellite appears and
            removed after :data:`CORRELATED_ERROR_MAX_GAP_TAU` correlation times unseen. Treated
            as white, such errors are averaged over every epoch of a correlation time and the
            filter becomes overconfident (docs/uwb_gnss_fusion/fusion_never_worse.md).
            Std 0: off (white pseudorange errors, the 8-state filter). On the real 30 s stations a
            sigma of 0.3 m with tau 600 s reaches 20 % horizontal gain over SPP on all three but
            costs 3D RMS on GEONET; it stays off (docs/uwb_gnss_fusion/fusion_real_gnss.md, section 5).
        glonass_satellite_bias_std_m: GLONASS (FDMA) code carries a bias per satellite that one
            inter-system bias cannot absorb: the receiver's inter-frequency code bias of each
            frequency channel (it depends on the receiver's RF front end and differs between brands;
            Wanninger & Wallstab-Freitag 2007) and the satellite's equipment group delay, up to 2 ns
            (0.6 m) for GLONASS-M and not in the broadcast message (GLONASS ICD 2008). A random-constant
            state per GLONASS satellite with this prior 1-sigma (1 m: the order of both together;
            ESBC00DNK measures a 1.26 m spread of the per-satellite GLONASS means against GPS's 0.63 m,
            docs/uwb_gnss_fusion/fusion_multignss.md) absorbs it as the geometry changes. Removed after
            :data:`GLONASS_BIAS_MAX_GAP_S` unseen. With ``pseudorange_correlated_std_m`` > 0 every
            satellite has a Gauss-Markov state and a GLONASS satellite's sigma is the root-sum-square
            of both. 0: no such states (before issue 27 item 4: adding GLONASS worsened ESBC00DNK's
            whole-day 3D RMS from 1.22 to 1.26 m).
    """

    pseudorange_correlated_std_m: float = parameter(
        0.0,
        'Stationary 1-sigma of the time-correlated pseudorange error, m: one first-order Gauss-Markov '
        'state per tracked satellite (0: off, white pseudorange errors).',
        minimum=0.0, maximum=100.0,
    )
    pseudorange_correlated_tau_s: float = parameter(
        60.0,
        'Correlation time of that error, s.',
        minimum=0.1, maximum=86400.0,
    )
    glonass_satellite_bias_std_m: float = parameter(
        1.0,
        'Prior 1-sigma of a constant code bias state per GLONASS satellite, m: the FDMA channel\'s receiver '
        'inter-frequency code bias and the satellite equipment delay the broadcast message does not give '
        '(0: none; with pseudorange_correlated_std_m > 0 it is added to the GLONASS satellites\' '
        'Gauss-Markov sigma instead).',
        minimum=0.0, maximum=100.0,
    )


@dataclass(frozen=True)
class MirrorAmbiguityParams:
    """FusionParams, the mirror ambiguity of coplanar anchors, resolved by GNSS (issue 15 item 2).

    Design notes (why, and the evidence; the meaning is in each field's description):
        uwb_mirror_test: resolve the mirror ambiguity of coplanar anchors (three anchors always
            are) with the pseudoranges: a GNSS log-likelihood ratio of the reflection of the
            estimate across the anchors' plane against the estimate, accumulated over the epochs,
            and a jump to the mirror when it exceeds ``uwb_mirror_switch_log_lr``
            (:mod:`.mirror_test`; beyond the paper). Active only with GNSS and UWB, in the earth
            frame, while the anchors heard within ``uwb_init_window_s`` lie in a plane.
            Counted as ``uwb_mirror_switch``.
        uwb_gated_anchor_reinit: when one anchor has had ``divergence_uwb_ranges`` consecutive
            ranges gated while a multi-start multilateration on the latest range of every anchor
            heard (at least four; three with ``uwb_tag_side_of_anchor_plane``, the fix on that side
            of their plane) explains all of them within ``UWB_FIX_CONSISTENT_SIGMA`` range
            1-sigmas and lies outside the 3-dof gate around the state, reinitialise the position
            from that fix: the state sits in a wrong local minimum of the ranges (e.g. near the
            mirror of three of four anchors after a GNSS start metres off in height) and the gate
            keeps out the anchor that would pull it back. If no such fix exists the anchor's ranges
            are faulty (e.g. NLOS) and stay gated. At most once per anchor id in the filter's life
            (a biased anchor whose fix also explains the ranges in a weak geometry must not make the
            filter cycle). Beyond the paper; counted as ``uwb_anchor_gated_reinit``.
        uwb_tag_side_of_anchor_plane: what the installer knows of the mirror ambiguity: -1 the tag
            moves below the plane of its coplanar anchors (anchors mounted high), +1 above it, 0
            unknown (the default). With -1 or +1, whenever the anchors heard are coplanar and the
            estimate lies on the other side of their plane (along the local vertical), the filter
            jumps to its mirror (position, velocity and covariance reflected; counted as
            ``uwb_side_prior_flip``) and the GNSS test (``uwb_mirror_test``) is not used. For tags
            that stay clearly on one side: a tag that crosses the plane is pulled back to the side
            given. Beyond the paper.
        uwb_mirror_covariance: while the side is unknown (``uwb_tag_side_of_anchor_plane`` 0) and the
            anchors heard are coplanar, add the mirror ambiguity to the published position
            covariance: ``p d^2`` along the plane's normal, ``d`` the distance from the estimate to its
            mirror and ``p`` the probability of the wrong side (:mod:`.mirror_test`). Without it three
            anchors publish centimetre 1-sigmas for a solution that is on the mirror, 1.3 m off, in
            about a third of the simulated runs (``docs/uwb_gnss_fusion/fusion_never_worse.md``). The
            filter's own covariance is unchanged. Beyond the paper.
        uwb_mirror_gnss_std_m: 1-sigma of the GNSS position error along the normal of the anchors'
            plane (about the vertical error of single-frequency GNSS), m, for that probability:
            ``p = Phi(-d / (2 sigma))`` with GNSS, 0.5 without (> 0).
    """

    uwb_mirror_test: bool = parameter(
        False,
        'Resolve the mirror ambiguity of coplanar anchors (three anchors always are) with a GNSS '
        'log-likelihood ratio of the reflected estimate against the estimate, accumulated over the '
        'epochs (beyond the paper; counted as uwb_mirror_switch).',
    )
    uwb_mirror_switch_log_lr: float = parameter(
        1.0,
        'Jump to the mirror when that log-likelihood ratio exceeds this (natural log; evidence scaled to '
        'independent samples with pseudorange_correlated_tau_s).',
        minimum=0.01, maximum=100.0,
    )
    uwb_gated_anchor_reinit: bool = parameter(
        True,
        'Reinitialise the position from a multilateration fix that explains the latest range of every '
        'anchor (at least four; three with uwb_tag_side_of_anchor_plane) and lies outside the 3-dof gate '
        'around the state, when one anchor has had divergence_uwb_ranges consecutive ranges gated (the '
        'state is in a wrong local minimum); at most once per anchor id. Beyond the paper; counted as '
        'uwb_anchor_gated_reinit.',
    )
    uwb_tag_side_of_anchor_plane: int = parameter(
        0,
        "The installer's knowledge of the mirror ambiguity of coplanar anchors (three anchors always are): "
        'the tag moves below (-1) or above (+1) the plane of its coplanar anchors (along the local '
        'vertical), or unknown (0). With -1/+1 an estimate on the other side is reflected back across the '
        'plane (counted as uwb_side_prior_flip) and uwb_mirror_test is not used. Beyond the paper.',
        minimum=-1, maximum=1, group=USER,
    )
    uwb_mirror_covariance: bool = parameter(
        True,
        "While the side of the anchors' plane is unknown and the anchors heard are coplanar, add the "
        'mirror ambiguity (p d^2 along the plane normal) to the published position covariance (beyond '
        'the paper).',
        read_only=False,
    )
    uwb_mirror_gnss_std_m: float = parameter(
        2.0,
        "1-sigma of the GNSS position error along the normal of the anchors' plane, m: the probability "
        'of the wrong side is Phi(-d / (2 sigma)) with GNSS, 0.5 without.',
        minimum=0.01, maximum=100.0, read_only=False,
    )


@dataclass(frozen=True)
class RangeNoiseParams:
    """FusionParams, range noise: curvature term and adaptive estimate per anchor (issue 15 item 2).

    Design notes (why, and the evidence; the meaning is in each field's description):
        uwb_range_curvature_noise: add to each range's noise variance the second-order variance of
            the range over the position uncertainty across its line of sight
            (:func:`.ckf_kernels.range_curvature_variance`, ``|T P T|_F^2 / (2 rho^2)``): caps the
            information a stream of precise ranges piles up while the tag is uncertain across the
            line of sight (1-2 anchors), and vanishes once the position is known. Beyond the paper.
        uwb_range_noise_adaptive: estimate each anchor's range noise from its own innovations
            (:class:`.uwb_update.RangeNoiseEstimate`): a factor on the stated variance (the
            message's ``range_std_m`` or ``uwb_range_std_m``), so that the weight of the ranges
            follows the hardware. The 1-sigma used stays within
            [``uwb_range_std_floor_m``, ``uwb_range_std_ceiling_m``] (widened to include the stated
            1-sigma). Counted as ``uwb_noise_estimates`` once per anchor. Acts while GNSS is used (the
            weight of the ranges against the pseudoranges); without GNSS only with
            ``uwb_range_noise_adaptive_without_gnss``. Beyond the paper.
        uwb_range_noise_adaptive_without_gnss: also estimate the range noise in a filter without GNSS
            (``use_gnss`` false or the map frame; default false: on the real Hanyang cases, UWB alone,
            the estimate scored 1.25 / 0.60 / 1.07 m against 1.17 / 0.56 / 1.13 m with the stated noise,
            because with a moving tag the innovations also carry the motion model's errors).
        uwb_iterate_min_anchors: with GNSS in use, a range may be refined by the iterated update
            (``max_update_iterations``) only while at least this many anchors were heard within
            ``uwb_init_window_s`` (0: always; default 3). With one or two anchors the iterated point
            moves along directions the ranges do not observe and the information of a stream of ranges
            leaks across their lines of sight (the fused filter got worse than GNSS alone at +22 / +30 dB
            with the adaptive noise; docs/uwb_gnss_fusion/fusion_never_worse.md); three or more anchors fix
            the position among themselves and need the refinement. The UWB-only filter is never limited.
            Beyond the paper.
        divergence_fix_confirm_s: the filter starts from a GNSS snapshot fix, and a GNSS-declared divergence
            re-initialises from one, only when an earlier fix, at least this many seconds before (and at most
            ten times that), agrees with it within 3 combined standard deviations (0: at once, the default).
            Until then a diverging state is kept (not reset), the fix is held for the next comparison, and
            the events are counted as ``gnss_init_unconfirmed`` / ``divergence_unconfirmed``. Outlier
            bursts under jamming (0.2-2 s) make the state gate most pseudoranges for a few epochs while it
            is right, and a fix of such an epoch is wrong; two fixes a second apart from different bursts
            rarely agree, while a state that really diverged is outvoted by fixes that do. Beyond the paper.
        uwb_range_bias_std_m: while GNSS is used and fewer than three anchors were heard within
            ``uwb_init_window_s`` (ranges alone do not fix the position), the ranges of one anchor
            are taken to share a bias of this 1-sigma, m, over ``uwb_range_bias_time_s``: the n-th
            range of the anchor within that time is applied with the variance ``std^2 + n
            uwb_range_bias_std_m^2`` (0: off). A stream of 20 Hz ranges then tells a few times this
            much along a line of sight, not millimetres, and that information no longer leaks across
            lines of sight that turn as the estimate moves (one anchor at +30 dB: 3.93 -> 2.40 m 3D
            against GNSS alone 2.39 m; docs/uwb_gnss_fusion/fusion_never_worse.md). Two-way UWB ranges
            do carry biases of centimetres to decimetres that change slowly (antenna delay against
            signal level and orientation, multipath). Beyond the paper.
        uwb_range_std_floor_m / uwb_range_std_ceiling_m: bounds of the estimated 1-sigma, m. The
            floor (1 cm) lies below the precision of two-way-ranging UWB chips (DW1000 / DW3000
            datasheets: about 10 cm; 2-5 cm measured static, line of sight): it only stops a run
            of small innovations from collapsing the weight. The ceiling (1 m) is where an anchor
            stops being worth more than the gate; NLOS ranges beyond it are the gate's business.
    """

    uwb_range_curvature_noise: bool = parameter(
        True,
        'Add to each range variance the second-order (curvature) variance of the range over the position '
        'uncertainty across its line of sight (beyond the paper).',
    )
    uwb_range_noise_adaptive: bool = parameter(
        True,
        "Estimate each anchor's range noise from its innovations, a factor on the stated variance "
        '(range_std_m of the message or uwb_range_std_m); beyond the paper, counted as '
        'uwb_noise_estimates. Acts while GNSS is used (the weight of ranges against pseudoranges).',
    )
    uwb_range_noise_adaptive_without_gnss: bool = parameter(
        False,
        'Also estimate the range noise without GNSS (use_gnss false or the map frame); off by default: '
        'with a moving tag the innovations also carry the motion model errors.',
    )
    uwb_range_noise_window: int = parameter(
        200,
        'Fading memory of that estimate, ranges per anchor.',
        minimum=10, maximum=100000,
    )
    uwb_range_std_floor_m: float = parameter(
        0.01,
        'Smallest estimated range 1-sigma, m (widened to the stated 1-sigma).',
        minimum=0.0001, maximum=10.0,
    )
    uwb_range_std_ceiling_m: float = parameter(
        1.0,
        'Largest estimated range 1-sigma, m (widened to the stated 1-sigma).',
        minimum=0.001, maximum=100.0,
    )
    uwb_iterate_min_anchors: int = parameter(
        3,
        'With GNSS, refine a range by the iterated update only while at least this many anchors were '
        'heard within uwb_init_window_s (0: always). With 1-2 anchors the iterated point leaks '
        'information across the lines of sight; beyond the paper.',
        minimum=0, maximum=64,
    )
    divergence_fix_confirm_s: float = parameter(
        1.0,
        'Start from a GNSS snapshot fix, or re-initialise from one after a GNSS-declared divergence, '
        'only when an earlier fix this many seconds (up to ten times that) before agrees within 3 '
        'combined sigmas; meanwhile a diverging state is kept (0: at once). Beyond the paper.',
        minimum=0.0, maximum=3600.0,
    )
    uwb_range_bias_std_m: float = parameter(
        0.05,
        'With GNSS and fewer than three anchors heard, the ranges of one anchor share a bias of this '
        '1-sigma over uwb_range_bias_time_s: the n-th range in that time is applied with variance std^2 '
        '+ n * this^2, so a stream of ranges does not leak information across its turning line of sight, '
        'm (0: off). Beyond the paper.',
        minimum=0.0, maximum=10.0,
    )
    uwb_range_bias_time_s: float = parameter(
        60.0,
        'Time over which the ranges of one anchor share that bias, s.',
        minimum=0.1, maximum=3600.0,
    )

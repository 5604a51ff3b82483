"""Prompt correlator measurement model and the plain data types of the carrier trackers.

Convention (shared with rfi_sim.correlators): the correlator's replica is open loop,
so the angle of the prompt correlator of interval k is the accumulated satellite-motion phase
``Phi_sm,k = sum_{j<=k} predicted_phase_change_rad_j`` (known to the receiver from ephemeris)
plus the residual phase ``phi_k`` (receiver clock phase plus the channel's constant initial phase),
which is what the trackers estimate:

    I_k = d_k A cos(Phi_sm,k + phi_k) + v_I,   Q_k = d_k A sin(Phi_sm,k + phi_k) + v_Q

(Zhao et al., eq. 2-3, with Delta phi_tot = Delta phi_sm + Delta phi_clk). The phase is taken at the
end of the interval (the stamp); the intra-interval rotation and its sinc amplitude loss are
neglected (clock frequency errors here are well below 1/T).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

CN0_MIN_DBHZ = 0.0
"""Lowest C/N0 accepted as physical, dB-Hz."""
CN0_MAX_DBHZ = 70.0
"""Highest C/N0 accepted as physical, dB-Hz."""

MIN_INTEGRATION_TIME_S = 1e-4
"""Default shortest coherent integration time accepted, s (0.1 ms: below any GNSS receiver's prompt
correlator; Zhao et al. use 1-20 ms)."""
MAX_INTEGRATION_TIME_S = 0.1
"""Default longest coherent integration time accepted, s (100 ms: the longest coherent integration of
pilot signals in use; a data signal cannot integrate beyond its 20 ms bit)."""

MAX_PREDICTED_DOPPLER_HZ = 1.0e5
"""|predicted_phase_change_rad| above 2 pi x this x T is rejected as absurd, Hz (a receiver on a LEO
satellite sees at most about +-45 kHz of Doppler at L1; terrestrial receivers +-5 kHz)."""

MAX_RESIDUAL_PHASE_RAD = 1.0e9
"""A tracker whose residual phase exceeds this in magnitude has diverged, rad (beyond it a float64
phase keeps less than 1.2e-7 rad of resolution; a 1 Hz residual frequency takes 5 years to get there)."""

IQ_SCALINGS = ("unit_amplitude", "unit_noise")
"""How correlators are normalised: A = 1 (Zhao et al., eq. 5) or noise sigma = 1."""

METHOD_IMM = 1
METHOD_PLL = 2
"""Method codes, identical to rfi_msgs/CarrierPhase constants."""

CORRELATOR_LOCK_UNKNOWN = 0
CORRELATOR_LOCK_LOST = 1
CORRELATOR_LOCK_HELD = 2
"""The producer's carrier-lock codes of a correlator, identical to rfi_msgs/Correlator CARRIER_LOCK_* (0: the
producer does not say, as the simulator's open-loop replica; 1: its carrier loop lost lock; 2: in lock)."""


def iq_amplitude_and_noise_std(
    cn0_dbhz: float, integration_time_s: float, iq_scaling: str = "unit_amplitude"
) -> tuple[float, float]:
    """Signal amplitude A and per-component noise std sigma_v of the prompt correlators.

    Args:
        cn0_dbhz: carrier-to-noise density ratio, dB-Hz.
        integration_time_s: coherent integration time T, s, > 0.
        iq_scaling: "unit_amplitude" (A = 1, Zhao et al. eq. 5) or "unit_noise" (sigma_v = 1).

    Returns:
        (A, sigma_v) in correlator units. A^2 / (2 sigma_v^2) = T C/N0.

    Notes:
        Zhao et al., eq. 4-5: C/N0 = 10^(C/N0_dBHz / 10), sigma_v = 1 / sqrt(0.04 C/N0) for
        T = 20 ms, i.e. sigma_v = 1 / sqrt(2 T C/N0) with A = 1 (Kaplan & Hegarty: prompt SNR T C/N0
        per component pair).
    """
    if not math.isfinite(integration_time_s) or integration_time_s <= 0.0:
        raise ValueError(f"integration_time_s must be finite and > 0, got {integration_time_s!r}")
    if not math.isfinite(cn0_dbhz):
        raise ValueError(f"cn0_dbhz must be finite, got {cn0_dbhz!r}")
    if iq_scaling not in IQ_SCALINGS:
        raise ValueError(f"iq_scaling must be one of {IQ_SCALINGS}, got {iq_scaling!r}")
    return amp_sigma(float(cn0_dbhz), float(integration_time_s), iq_scaling == "unit_noise")


@njit(cache=True)
def amp_sigma(cn0_dbhz: float, t: float, unit_noise: bool) -> tuple[float, float]:
    """(A, sigma_v) of :func:`iq_amplitude_and_noise_std` without its checks, for compiled kernels: the one
    computation of ``A / sigma_v = sqrt(2 T C/N0)`` (Zhao et al., eq. 4-5) that the IMM, the PLL and the tracker
    use. ``cn0_dbhz`` dB-Hz, ``t`` = T in s, ``unit_noise``: sigma_v = 1 (else A = 1)."""
    ratio = math.sqrt(2.0 * t * 10.0 ** (cn0_dbhz / 10.0))
    if unit_noise:
        return ratio, 1.0
    return 1.0, 1.0 / ratio


def expected_iq(
    phase_rad: np.ndarray, data_bit: np.ndarray, amplitude: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free prompt correlators d A cos(theta), d A sin(theta) (Zhao et al., eq. 2-3).

    Args:
        phase_rad: total correlator angle theta (satellite motion + residual), rad, any shape.
        data_bit: navigation data bit, +1 or -1, broadcastable to phase_rad.
        amplitude: A, correlator units, broadcastable.

    Returns:
        (I, Q), same shape as the broadcast inputs.
    """
    theta = np.asarray(phase_rad, dtype=float)
    d = np.asarray(data_bit, dtype=float)
    return d * amplitude * np.cos(theta), d * amplitude * np.sin(theta)


@dataclass(frozen=True)
class CorrelatorSample:
    """One channel's prompt correlator over one interval (mirrors rfi_msgs/Correlator.msg).

    Attributes:
        constellation: GnssMeasurement constellation code.
        svid: satellite number.
        integration_time_s: coherent integration time T, s (> 0).
        in_phase: prompt I, correlator units.
        quadrature: prompt Q, same unit.
        cn0_dbhz: receiver's C/N0 estimate, dB-Hz (NaN = unknown).
        predicted_phase_change_rad: satellite-motion phase change over the interval, rad.
        carrier_lock: the producer's own carrier lock, CORRELATOR_LOCK_UNKNOWN (0, the default), _LOST (1) or
            _HELD (2) (rfi_msgs/Correlator CARRIER_LOCK_*).
    """

    constellation: int
    svid: int
    integration_time_s: float
    in_phase: float
    quadrature: float
    cn0_dbhz: float
    predicted_phase_change_rad: float
    carrier_lock: int = 0


@dataclass(frozen=True)
class CarrierPhaseEstimate:
    """One channel's carrier-phase estimate at one stamp (mirrors rfi_msgs/CarrierPhase.msg).

    Attributes:
        stamp_ns: stamp of the correlator interval it answers, ns.
        constellation, svid: channel identity.
        method: METHOD_IMM or METHOD_PLL.
        phase_rad: residual carrier phase (clock part plus constant offset), rad, unwrapped.
        phase_std_rad: 1-sigma of phase_rad, rad (NaN for the PLL).
        frequency_hz: residual carrier frequency (clock frequency error), Hz.
        frequency_std_hz: 1-sigma of frequency_hz, Hz (NaN for the PLL).
        data_bit: most probable data bit, -1 or +1 (0 if undecided).
        data_bit_probability: probability of data_bit, 0..1.
        mode_probabilities: (P(bit=+1), P(bit=-1)) for the IMM; () for single-mode trackers.
        locked: True only while the estimate is valid and in lock.
        cycle_slips: slips detected on this channel since it started (see the tracker docs).
    """

    stamp_ns: int
    constellation: int
    svid: int
    method: int
    phase_rad: float
    phase_std_rad: float
    frequency_hz: float
    frequency_std_hz: float
    data_bit: int
    data_bit_probability: float
    mode_probabilities: tuple[float, ...]
    locked: bool
    cycle_slips: int


def check_step_inputs(cn0_dbhz: float, integration_time_s: float, predicted_phase_change_rad: float) -> None:
    """Refuse a scalar tracker step's invalid T, C/N0 or phase change (the tracker counts these before).

    Args:
        cn0_dbhz: C/N0, dB-Hz, in [CN0_MIN_DBHZ, CN0_MAX_DBHZ].
        integration_time_s: coherent integration time T, s, finite and > 0.
        predicted_phase_change_rad: satellite-motion phase change over the interval, rad, finite.

    Raises:
        ValueError: naming the first invalid input, in the order T, C/N0, phase change.
    """
    if not (math.isfinite(integration_time_s) and integration_time_s > 0.0):
        raise ValueError(f"integration_time_s must be finite and > 0, got {integration_time_s!r}")
    if not (math.isfinite(cn0_dbhz) and CN0_MIN_DBHZ <= cn0_dbhz <= CN0_MAX_DBHZ):
        raise ValueError(f"cn0_dbhz must be in [{CN0_MIN_DBHZ}, {CN0_MAX_DBHZ}], got {cn0_dbhz!r}")
    if not math.isfinite(predicted_phase_change_rad):
        raise ValueError("predicted_phase_change_rad must be finite")


@dataclass(frozen=True)
class CorrelatorBatch:
    """One channel's correlators as a tracker's ``process_batch`` takes them: per-sample arrays and
    which samples are accepted.

    Attributes:
        in_phase, quadrature: prompt I, Q, shape (n,) (NaN: the tracker coasts).
        cn0_dbhz, integration_time_s, predicted_phase_change_rad: shape (n,), dB-Hz, s, rad.
        accepted: shape (n,), bool: T finite and > 0, C/N0 in range and a finite phase change.
        counters: rejected_integration_time, rejected_cn0, rejected_predicted_phase (each sample
            counted once, under its first invalid input) and coasted_nonfinite_iq (accepted, NaN I/Q).
    """

    in_phase: np.ndarray
    quadrature: np.ndarray
    cn0_dbhz: np.ndarray
    integration_time_s: np.ndarray
    predicted_phase_change_rad: np.ndarray
    accepted: np.ndarray
    counters: dict[str, int]

    def per_sample(self, name: str, value: np.ndarray | float) -> np.ndarray:
        """``value`` as a contiguous float array of shape (n,): a scalar is repeated.

        Raises:
            ValueError: an array of another shape.
        """
        n = self.in_phase.size
        a = np.broadcast_to(np.asarray(value, dtype=float), (n,)) if np.ndim(value) == 0 \
            else np.asarray(value, float)
        if a.shape != (n,):
            raise ValueError(f"{name} must be a scalar or have shape ({n},), got {a.shape}")
        return np.ascontiguousarray(a)


def correlator_batch(
    in_phase: np.ndarray,
    quadrature: np.ndarray | float,
    cn0_dbhz: np.ndarray | float,
    integration_time_s: np.ndarray | float,
    predicted_phase_change_rad: np.ndarray | float,
) -> CorrelatorBatch:
    """Check and shape the inputs of a tracker's ``process_batch`` (IMM and PLL alike).

    Args:
        in_phase: prompt I, shape (n,), n >= 1.
        quadrature, cn0_dbhz, integration_time_s, predicted_phase_change_rad: shape (n,) or scalar.

    Returns:
        :class:`CorrelatorBatch`.

    Raises:
        ValueError: ``in_phase`` not a non-empty 1-D array, or another input of the wrong shape.
    """
    zi = np.asarray(in_phase, dtype=float)
    if zi.ndim != 1 or zi.size == 0:
        raise ValueError("in_phase must be a non-empty 1-D array")
    shape = CorrelatorBatch(zi, zi, zi, zi, zi, zi, {})
    zq = shape.per_sample("quadrature", quadrature)
    cn0 = shape.per_sample("cn0_dbhz", cn0_dbhz)
    t = shape.per_sample("integration_time_s", integration_time_s)
    dphi = shape.per_sample("predicted_phase_change_rad", predicted_phase_change_rad)
    ok_t = np.isfinite(t) & (t > 0)
    ok_cn0 = np.isfinite(cn0) & (cn0 >= CN0_MIN_DBHZ) & (cn0 <= CN0_MAX_DBHZ)
    ok_dphi = np.isfinite(dphi)
    accepted = ok_t & ok_cn0 & ok_dphi
    counters = {
        "rejected_integration_time": int(np.sum(~ok_t)),
        "rejected_cn0": int(np.sum(ok_t & ~ok_cn0)),
        "rejected_predicted_phase": int(np.sum(ok_t & ok_cn0 & ~ok_dphi)),
        "coasted_nonfinite_iq": int(np.sum(accepted & ~(np.isfinite(zi) & np.isfinite(zq)))),
    }
    return CorrelatorBatch(zi, zq, cn0, t, dphi, accepted, counters)


class CompiledChannelLoop:
    """What the IMM and the PLL share: their checked parameters, the state and output arrays their compiled step
    and run kernels update in place, whether a state has been set, and the start of a batch.

    Subclasses set :attr:`NOT_INITIALISED` (the message of a step before ``initialize``), :attr:`PARAMS_TYPE`
    (the parameter dataclass they take) and :attr:`STATE_LEN`, :attr:`OUT_LEN` (their kernels' array lengths).

    Raises:
        ValueError: ``params`` not a :attr:`PARAMS_TYPE`.
    """

    NOT_INITIALISED = "not initialised"
    PARAMS_TYPE: type = object
    STATE_LEN = 0
    OUT_LEN = 0

    def __init__(self, params: Any) -> None:
        if not isinstance(params, self.PARAMS_TYPE):
            name = self.PARAMS_TYPE.__name__
            raise ValueError(f"params must be {'an' if name[0] in 'AEIOU' else 'a'} {name}")
        self.params = params
        self._st = np.zeros(self.STATE_LEN)
        self._out = np.zeros(self.OUT_LEN)
        self._initialized = False

    @property
    def initialized(self) -> bool:
        """True once a state has been set (``initialize`` or ``initialize_from_correlator``)."""
        return self._initialized

    def _require_initialized(self) -> None:
        if not self._initialized:
            raise ValueError(self.NOT_INITIALISED)

    def _start_batch(self, *correlators: np.ndarray | float) -> tuple[CorrelatorBatch, np.ndarray, np.ndarray]:
        """The checked batch of ``correlators`` (the arguments of :func:`correlator_batch`, in its order), the
        indices of its accepted samples and the output rows for the run kernel to fill, shape
        (n, output length), NaN where a sample is rejected.

        Raises:
            ValueError: the loop not initialised, or an input of the wrong shape.
        """
        self._require_initialized()
        batch = correlator_batch(*correlators)  # type: ignore[arg-type]
        return batch, np.flatnonzero(batch.accepted), np.full((batch.in_phase.size, self._out.size), np.nan)

"""Prompt-correlator simulator for carrier tracking through interference (Zhao et al. scenario).

Several satellites share one receiver clock, simulated from its h-coefficients exactly as the
discrete two-state model implies (gnss_common.clock_model.simulate_clock). Per satellite: a
satellite-motion phase from a linear Doppler profile (known to the receiver and delivered as
``predicted_phase_change_rad``), 50 bit/s navigation data aligned to the 20 ms grid, a C/N0 profile
(nominal, then a drop at the interference onset) and white Gaussian I/Q noise.

Correlator convention (imm_carrier.measurement_model): open-loop replica, angle of interval k
``theta_k = Phi_sm,k + phi_k`` with ``Phi_sm,k`` the accumulated satellite-motion phase and
``phi_k = phi0 + 2 pi f_L1 x_clk(t_k)`` the residual phase (truth), taken at the interval end;
``I + jQ = d_k A exp(j theta_k) + v``, v ~ N(0, sigma_v^2) per component (Zhao et al., eq. 2-5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gnss_common.clock_model import RUBIDIUM_LPFRS, ClockHCoefficients, simulate_clock
from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_NAV_BIT_RATE_HZ, TWO_PI


@dataclass(frozen=True)
class CorrelatorScenario:
    """Scenario of the correlator simulator (defaults: Zhao et al., Section VI-A).

    Attributes:
        svids: satellite numbers (paper: PRN 1, 30, 7, 11, 28).
        cn0_drops_db: C/N0 drop of each satellite at the onset, dB, same length as svids
            (paper: 0, 6, 16, 26, 36).
        nominal_cn0_dbhz: C/N0 before the onset, dB-Hz (paper: 51).
        onset_s: interference onset, s after start (paper: 120 s; 110 s in Section VIII-A).
        duration_s: scenario length, s (paper: 4 min).
        integration_time_s: coherent integration time T, s; 0.02 / T must be an integer
            (paper: 20 ms and 1 ms).
        clock: receiver clock h-coefficients (paper: LPFRS rubidium).
        clock_initial_frequency_hz: clock frequency error at t = 0, Hz at the carrier.
        carrier_hz: carrier frequency, Hz.
        doppler_range_hz: satellite Doppler at t = 0 drawn uniformly in +- this, Hz.
        doppler_rate_range_hzps: Doppler rate drawn uniformly in +- this, Hz/s.
        iq_scaling: "unit_amplitude" (A = 1, eq. 5) or "unit_noise" (sigma_v = 1).
        cn0_transition_s: the drop is a linear ramp over this time, s (0: a step).
    """

    svids: tuple[int, ...] = (1, 30, 7, 11, 28)
    cn0_drops_db: tuple[float, ...] = (0.0, 6.0, 16.0, 26.0, 36.0)
    nominal_cn0_dbhz: float = 51.0
    onset_s: float = 120.0
    duration_s: float = 240.0
    integration_time_s: float = 0.02
    clock: ClockHCoefficients = RUBIDIUM_LPFRS
    clock_initial_frequency_hz: float = 0.0
    carrier_hz: float = GPS_L1_FREQUENCY_HZ
    doppler_range_hz: float = 3000.0
    doppler_rate_range_hzps: float = 0.8
    iq_scaling: str = "unit_amplitude"
    cn0_transition_s: float = 0.0

    def __post_init__(self) -> None:
        if len(self.svids) == 0 or len(self.svids) != len(self.cn0_drops_db):
            raise ValueError("svids and cn0_drops_db must be non-empty and of equal length")
        if len(set(self.svids)) != len(self.svids) or any(int(s) <= 0 for s in self.svids):
            raise ValueError("svids must be distinct positive integers")
        for key in ("duration_s", "integration_time_s", "carrier_hz"):
            v = getattr(self, key)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"CorrelatorScenario.{key} must be finite and > 0, got {v!r}")
        bits_per_t = 1.0 / (GPS_NAV_BIT_RATE_HZ * self.integration_time_s)
        if (
            self.integration_time_s > 1.0 / GPS_NAV_BIT_RATE_HZ + 1e-12
            or abs(bits_per_t - round(bits_per_t)) > 1e-9
        ):
            raise ValueError("integration_time_s must divide the 20 ms data bit (e.g. 0.02, 0.01, 0.001)")
        for key in ("onset_s", "doppler_range_hz", "doppler_rate_range_hzps", "cn0_transition_s"):
            v = getattr(self, key)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"CorrelatorScenario.{key} must be finite and >= 0, got {v!r}")
        cn0 = [self.nominal_cn0_dbhz - d for d in self.cn0_drops_db]
        if not all(math.isfinite(c) and 0.0 <= c <= 70.0 for c in cn0 + [self.nominal_cn0_dbhz]):
            raise ValueError("C/N0 values must stay within 0..70 dB-Hz")
        if self.iq_scaling not in ("unit_amplitude", "unit_noise"):
            raise ValueError("iq_scaling must be 'unit_amplitude' or 'unit_noise'")
        if not math.isfinite(self.clock_initial_frequency_hz):
            raise ValueError("clock_initial_frequency_hz must be finite")

    @property
    def n_steps(self) -> int:
        """Number of correlator intervals."""
        return int(round(self.duration_s / self.integration_time_s))


@dataclass(frozen=True)
class SatelliteCorrelators:
    """Simulated correlators and truth of one satellite, arrays of shape (n,).

    Attributes:
        svid: satellite number.
        stamps_ns: end of each interval, ns from the scenario start (int64).
        integration_time_s: T, s.
        in_phase, quadrature: prompt I and Q, correlator units.
        cn0_dbhz: true C/N0 (also the receiver's estimate here), dB-Hz.
        predicted_phase_change_rad: satellite-motion phase change over each interval, rad.
        truth_phase_rad: residual phase phi_k = phi0 + clock phase, rad (unwrapped).
        truth_frequency_hz: clock frequency error at the carrier, Hz.
        truth_bits: data bit of each interval, +1 / -1 (int8).
        amplitude, noise_std: A and sigma_v per interval, correlator units.
    """

    svid: int
    stamps_ns: np.ndarray
    integration_time_s: float
    in_phase: np.ndarray
    quadrature: np.ndarray
    cn0_dbhz: np.ndarray
    predicted_phase_change_rad: np.ndarray
    truth_phase_rad: np.ndarray
    truth_frequency_hz: np.ndarray
    truth_bits: np.ndarray
    amplitude: np.ndarray
    noise_std: np.ndarray


@dataclass(frozen=True)
class CorrelatorSimulation:
    """Output of :func:`simulate_correlators`: the scenario, the satellites, the common clock truth."""

    scenario: CorrelatorScenario
    satellites: tuple[SatelliteCorrelators, ...]
    clock_phase_rad: np.ndarray  # shape (n,), 2 pi f_c x_clk at the stamps, rad
    clock_frequency_hz: np.ndarray  # shape (n,), f_c y_clk at the stamps, Hz
    seed: int = 0
    notes: dict[str, str] = field(default_factory=dict)

    def by_svid(self, svid: int) -> SatelliteCorrelators:
        """The satellite with this svid (KeyError if absent)."""
        for s in self.satellites:
            if s.svid == svid:
                return s
        raise KeyError(svid)


def cn0_profile_dbhz(
    time_s: np.ndarray, nominal_dbhz: float, drop_db: float, onset_s: float, transition_s: float = 0.0
) -> np.ndarray:
    """C/N0 over time: nominal, then nominal - drop after the onset (linear ramp over transition_s), dB-Hz."""
    t = np.asarray(time_s, dtype=float)
    if transition_s > 0:
        frac = np.clip((t - onset_s) / transition_s, 0.0, 1.0)
    else:
        frac = (t >= onset_s).astype(float)
    return nominal_dbhz - drop_db * frac


def simulate_correlators(scenario: CorrelatorScenario, seed: int) -> CorrelatorSimulation:
    """Simulate prompt correlators of all satellites of the scenario.

    Args:
        scenario: the scenario.
        seed: seed of np.random.default_rng (clock, data, Doppler and noise all derive from it).

    Returns:
        CorrelatorSimulation with per-satellite arrays of length scenario.n_steps.

    Notes:
        Zhao et al., eq. 2-5 (I/Q, sigma_v = 1/sqrt(2 T C/N0) for A = 1), eq. 7-8 (clock, exact W),
        Section VI-A (scenario). The clock is common to all satellites; each satellite has its own
        initial phase phi0 ~ U(-pi, pi). The receiver's predicted satellite-motion phase equals the
        truth (ephemeris-aided static receiver, Section II-A).
    """
    rng = np.random.default_rng(seed)
    t_int = scenario.integration_time_s
    n = scenario.n_steps
    clock_seed = int(rng.integers(0, 2**63 - 1))
    x_s, y = simulate_clock(
        scenario.clock,
        t_int,
        n,
        seed=clock_seed,
        y0=scenario.clock_initial_frequency_hz / scenario.carrier_hz,
    )
    # Sample k = 1..n is the end of interval k.
    clock_phase = TWO_PI * scenario.carrier_hz * x_s[1:]
    clock_freq = scenario.carrier_hz * y[1:]
    k = np.arange(1, n + 1)
    t_end = k * t_int
    stamps_ns = np.round(t_end * 1e9).astype(np.int64)
    steps_per_bit = int(round(1.0 / (GPS_NAV_BIT_RATE_HZ * t_int)))
    bit_index = (k - 1) // steps_per_bit
    n_bits = int(bit_index[-1]) + 1
    sats = []
    for svid, drop in zip(scenario.svids, scenario.cn0_drops_db, strict=True):
        f_d0 = rng.uniform(-scenario.doppler_range_hz, scenario.doppler_range_hz)
        f_dd = rng.uniform(-scenario.doppler_rate_range_hzps, scenario.doppler_rate_range_hzps)
        # Exact phase change of f_d(t) = f_d0 + f_dd t over [t_end - T, t_end].
        t0 = t_end - t_int
        dphi = TWO_PI * (f_d0 * t_int + 0.5 * f_dd * (t_end**2 - t0**2))
        sat_phase = np.cumsum(np.mod(dphi + math.pi, TWO_PI) - math.pi)  # = sum of dphi modulo 2 pi
        phi0 = rng.uniform(-math.pi, math.pi)
        truth_phase = phi0 + clock_phase
        bits = np.where(rng.random(n_bits) < 0.5, 1, -1).astype(np.int8)[bit_index]
        cn0 = cn0_profile_dbhz(
            t_end, scenario.nominal_cn0_dbhz, drop, scenario.onset_s, scenario.cn0_transition_s
        )
        ratio = np.sqrt(2.0 * t_int * 10.0 ** (cn0 / 10.0))
        if scenario.iq_scaling == "unit_amplitude":
            amp = np.ones(n)
            sigma = 1.0 / ratio
        else:
            amp = ratio
            sigma = np.ones(n)
        theta = sat_phase + truth_phase
        i_q = bits * amp * np.cos(theta) + sigma * rng.standard_normal(n)
        q_q = bits * amp * np.sin(theta) + sigma * rng.standard_normal(n)
        sats.append(
            SatelliteCorrelators(
                svid=int(svid),
                stamps_ns=stamps_ns,
                integration_time_s=t_int,
                in_phase=i_q,
                quadrature=q_q,
                cn0_dbhz=cn0,
                predicted_phase_change_rad=dphi,
                truth_phase_rad=truth_phase,
                truth_frequency_hz=clock_freq.copy(),
                truth_bits=bits,
                amplitude=amp,
                noise_std=sigma,
            )
        )
    return CorrelatorSimulation(
        scenario=scenario,
        satellites=tuple(sats),
        clock_phase_rad=clock_phase,
        clock_frequency_hz=clock_freq,
        seed=seed,
    )

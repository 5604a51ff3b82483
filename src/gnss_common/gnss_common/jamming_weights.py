"""Jammer-aware measurement weighting: effective C/N0 and code/frequency tracking jitter.

Pure functions, numpy-vectorised, no ROS. Used by the fusion filter to turn a J/S (from the RFI
monitor) or a measurement's own C/N0 into pseudorange and pseudorange-rate variances, and by the
GNSS/UWB simulator to generate the matching noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnss_common.constants import GPS_CA_CHIP_RATE_HZ, GPS_L1_WAVELENGTH_M, SPEED_OF_LIGHT_MPS

CA_CHIP_LENGTH_M = SPEED_OF_LIGHT_MPS / GPS_CA_CHIP_RATE_HZ
"""Length of one GPS C/A chip, m (about 293.05 m)."""


def effective_cn0_dbhz(
    cn0_dbhz, jammer_to_signal_db, quality_factor: float = 1.0, chip_rate_hz: float = GPS_CA_CHIP_RATE_HZ
):
    """Effective carrier-to-noise density under a jammer.

    Args:
        cn0_dbhz: jammer-free C/N0, dB-Hz, scalar or array.
        jammer_to_signal_db: jammer-to-signal power ratio C_j/C, dB, scalar or array
            (broadcast against ``cn0_dbhz``). ``-inf`` means no jammer.
        quality_factor: spectral separation (jamming resistance quality) factor Q, dimensionless,
            > 0 (Kaplan & Hegarty: 1 narrowband, 1.5 wideband BPSK-matched, 2 band-limited noise).
        chip_rate_hz: spreading code chip rate f_c, chip/s.

    Returns:
        Effective C/N0, dB-Hz, same shape as the broadcast inputs.

    Notes:
        Cao et al., eq. 4 (from Kaplan & Hegarty, 3rd ed., sec. 9.2):
        ``(C/N0)_eff = -10 log10(10^(-C/N0/10) + 10^(J/S/10) / (Q f_c))``.
    """
    if quality_factor <= 0.0 or chip_rate_hz <= 0.0:
        raise ValueError("quality_factor and chip_rate_hz must be > 0")
    cn0 = np.asarray(cn0_dbhz, dtype=float)
    js = np.asarray(jammer_to_signal_db, dtype=float)
    lin = 10.0 ** (-cn0 / 10.0) + 10.0 ** (js / 10.0) / (quality_factor * chip_rate_hz)
    return -10.0 * np.log10(lin)


@dataclass(frozen=True)
class TrackingLoopParams:
    """Receiver tracking-loop parameters for the jitter formulas (Kaplan & Hegarty, sec. 8.8).

    Attributes:
        dll_bandwidth_hz: code loop noise bandwidth B_n, Hz (carrier-aided DLL), > 0.
        correlator_spacing_chips: early-late spacing d, chips, in (0, 1].
        integration_time_s: predetection integration time T, s, > 0.
        fll_bandwidth_hz: frequency loop noise bandwidth, Hz, > 0.
        code_floor_m: 1-sigma pseudorange error floor added in quadrature (multipath, residual
            atmosphere, ephemeris), m, >= 0.
        rate_floor_mps: 1-sigma pseudorange-rate floor added in quadrature, m/s, >= 0.
    """

    dll_bandwidth_hz: float = 1.0
    correlator_spacing_chips: float = 0.5
    integration_time_s: float = 0.02
    fll_bandwidth_hz: float = 2.0
    code_floor_m: float = 0.5
    rate_floor_mps: float = 0.02

    def __post_init__(self) -> None:
        if not self.dll_bandwidth_hz > 0.0:
            raise ValueError(f"dll_bandwidth_hz must be > 0, got {self.dll_bandwidth_hz}")
        if not 0.0 < self.correlator_spacing_chips <= 1.0:
            raise ValueError(
                f"correlator_spacing_chips must be in (0, 1], got {self.correlator_spacing_chips}"
            )
        if not self.integration_time_s > 0.0:
            raise ValueError(f"integration_time_s must be > 0, got {self.integration_time_s}")
        if not self.fll_bandwidth_hz > 0.0:
            raise ValueError(f"fll_bandwidth_hz must be > 0, got {self.fll_bandwidth_hz}")
        if not (self.code_floor_m >= 0.0 and self.rate_floor_mps >= 0.0):
            raise ValueError("code_floor_m and rate_floor_mps must be >= 0")


def dll_jitter_m(cn0_dbhz, loop: TrackingLoopParams):
    """Thermal-noise code tracking jitter of a noncoherent early-minus-late power DLL.

    Args:
        cn0_dbhz: C/N0 (or effective C/N0), dB-Hz, scalar or array.
        loop: tracking-loop parameters.

    Returns:
        1-sigma pseudorange jitter, m (without the floor).

    Notes:
        Kaplan & Hegarty, 3rd ed., eq. 8.53 (infinite front-end bandwidth form):
        ``sigma^2 [chip^2] = B_n d / (2 C/N0) (1 + 2 / (T C/N0 (2 - d)))``, times the chip length.
    """
    cn0 = 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0)
    d = loop.correlator_spacing_chips
    var_chip2 = (
        loop.dll_bandwidth_hz * d / (2.0 * cn0) * (1.0 + 2.0 / (loop.integration_time_s * cn0 * (2.0 - d)))
    )
    return CA_CHIP_LENGTH_M * np.sqrt(var_chip2)


def fll_jitter_mps(cn0_dbhz, loop: TrackingLoopParams):
    """Thermal-noise frequency tracking jitter of an FLL, as a pseudorange-rate error.

    Args:
        cn0_dbhz: C/N0 (or effective C/N0), dB-Hz, scalar or array.
        loop: tracking-loop parameters.

    Returns:
        1-sigma pseudorange-rate jitter, m/s (without the floor).

    Notes:
        Kaplan & Hegarty, 3rd ed., eq. 8.47 with F = 1 above 35 dB-Hz and F = 2 below:
        ``sigma_f [Hz] = 1 / (2 pi T) sqrt(4 F B_n / (C/N0) (1 + 1 / (T C/N0)))``; the rate error is
        ``lambda_L1 sigma_f`` (Cao et al., eq. 6).
    """
    cn0_db = np.asarray(cn0_dbhz, dtype=float)
    cn0 = 10.0 ** (cn0_db / 10.0)
    factor = np.where(cn0_db >= 35.0, 1.0, 2.0)
    t = loop.integration_time_s
    sigma_hz = np.sqrt(4.0 * factor * loop.fll_bandwidth_hz / cn0 * (1.0 + 1.0 / (t * cn0))) / (
        2.0 * np.pi * t
    )
    return GPS_L1_WAVELENGTH_M * sigma_hz


def measurement_sigmas(cn0_dbhz, jammer_to_signal_db, loop: TrackingLoopParams, quality_factor: float = 1.0):
    """Pseudorange and pseudorange-rate 1-sigma for given C/N0 and J/S.

    Args:
        cn0_dbhz: jammer-free C/N0 per satellite, dB-Hz, shape (n,) or scalar.
        jammer_to_signal_db: J/S, dB (NaN or -inf: no jammer information, use ``cn0_dbhz`` as is).
        loop: tracking-loop parameters.
        quality_factor: Q of eq. 4, dimensionless.

    Returns:
        ``(sigma_pr_m, sigma_rate_mps, cn0_eff_dbhz)`` arrays of the broadcast shape.

    Notes:
        Cao et al., eq. 4 for the effective C/N0, then Kaplan & Hegarty eq. 8.53 (DLL) and 8.47
        (FLL), each root-sum-squared with its floor.
    """
    js = np.asarray(jammer_to_signal_db, dtype=float)
    js = np.where(np.isnan(js), -np.inf, js)
    cn0_eff = effective_cn0_dbhz(cn0_dbhz, js, quality_factor)
    s_pr = np.hypot(dll_jitter_m(cn0_eff, loop), loop.code_floor_m)
    s_rate = np.hypot(fll_jitter_mps(cn0_eff, loop), loop.rate_floor_mps)
    return s_pr, s_rate, cn0_eff

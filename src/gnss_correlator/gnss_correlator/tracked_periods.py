"""The code periods one block of tracking closed (:class:`TrackedPeriods`): what
:class:`gnss_correlator.tracking.Tracker` returns and the receiver, the bit synchroniser and the benchmarks read
(the correlator sums, the loops' discriminators and NCO state, C/N0 and the lock rule, one row per period)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrackedPeriods:
    """The code periods closed in one block, all channels, in order of their end.

    Attributes (each shape (n,)):
        prn: the channel's PRN.
        end_index: absolute (fractional) sample index where the period ended (code NCO at chip 1023).
        start_index: absolute (fractional) sample index where it started.
        early, prompt, late: complex correlator sums, (input units) x samples; phases relative to the
            carrier NCO, conjugated for a spectrally inverted IF.
        doppler_hz: carrier NCO Doppler during the period, Hz.
        nco_phase_rad: the NCO's accumulated Doppler phase at the period's end, rad, since the
            channel's start (2 pi int f_d dt).
        code_rate_hz: code NCO rate during the period, chips/s.
        pll_error_rad, fll_error_hz, dll_error_chips: discriminator outputs.
        n_samples: samples summed.
        period: the period's count since the channel's start (0 is partial).
        noise_reference: the noise-reference correlator (the same code ``noise_offset_chips`` away from the
            prompt, same carrier wipe-off), complex, same unit as the prompt.
        cn0_dbhz: C/N0 over the last ``cn0_window_ms`` periods by the noise-reference estimator (module
            docstring), dB-Hz (NaN until the window is full); at least its floor.
        cn0_m2m4_dbhz: C/N0 of the moments estimator over the same prompts, dB-Hz (NaN until full, or when
            the moments give no signal power); kept for comparison: it takes a jammer's coherent residue in
            the prompt for signal.
        lock_indicator: smoothed cos(2 e_p) over the same window, [-1, 1] (NaN until full).
        noise_power: noise (and interference) power of one prompt (I and Q together) over the same window:
            the noise reference's mean power, (input units x samples)^2 (NaN until full); the signal power is
            ``noise_power x 10^(cn0_dbhz / 10) x T``.
        phase_error_std_rad: std of the PLL discriminator over the last ``lock_window_ms`` periods, rad (NaN
            until that window is full).
        half_cycle_wraps: half-cycle wraps of the discriminator in that window (NaN until full).
        locked: the lock rule (module docstring) over that window; False until it is full.
    """

    prn: np.ndarray
    end_index: np.ndarray
    start_index: np.ndarray
    early: np.ndarray
    prompt: np.ndarray
    late: np.ndarray
    doppler_hz: np.ndarray
    nco_phase_rad: np.ndarray
    code_rate_hz: np.ndarray
    pll_error_rad: np.ndarray
    fll_error_hz: np.ndarray
    dll_error_chips: np.ndarray
    n_samples: np.ndarray
    period: np.ndarray
    noise_reference: np.ndarray
    cn0_dbhz: np.ndarray
    cn0_m2m4_dbhz: np.ndarray
    lock_indicator: np.ndarray
    noise_power: np.ndarray
    phase_error_std_rad: np.ndarray
    half_cycle_wraps: np.ndarray
    locked: np.ndarray

    def of(self, prn: int) -> TrackedPeriods:
        """The rows of one PRN."""
        m = self.prn == prn
        return TrackedPeriods(**{k: getattr(self, k)[m] for k in self.__dataclass_fields__})

    @staticmethod
    def concatenate(parts: list[TrackedPeriods]) -> TrackedPeriods:
        """Rows of several blocks, in order."""
        return TrackedPeriods(**{k: np.concatenate([getattr(p, k) for p in parts])
                                 for k in TrackedPeriods.__dataclass_fields__})

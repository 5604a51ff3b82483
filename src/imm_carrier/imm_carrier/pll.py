"""Costas PLL baseline: two-quadrant arctangent discriminator, third-order loop filter, eq. 10 schedule.

The correlators are open loop (measurement_model.py), so the loop is closed digitally: the
prompt correlator is rotated by the NCO phase (accumulated satellite-motion phase plus the loop's
own residual phase) before the discriminator. The per-step loop is compiled with numba.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gnss_common.constants import TWO_PI
from imm_carrier.layout import PLL_OUT_LEN, PLL_STATE_LEN, PllOut, PllState
from imm_carrier.measurement_model import (
    IQ_SCALINGS,
    CompiledChannelLoop,
    amp_sigma,
    check_step_inputs,
)
from rfi_node_common.params import check_positive_finite, parameter

# Third-order loop constants (Kaplan & Hegarty, "Understanding GPS", loop filter table):
# omega0 = Bn / 0.7845, F(s) = b3 w0 + a3 w0^2 / s + w0^3 / s^2.
THIRD_ORDER_BN_TO_W0 = 0.7845
THIRD_ORDER_A3 = 1.1
THIRD_ORDER_B3 = 2.4

_EQ10_COEFFS_MS = (3e-19, -1.3e-13, 1.5e-8, -7e-4, 15.5)  # t^4 .. t^0, t in ms (Zhao et al., eq. 10)


def _eq10_poly(t_s: float | np.ndarray) -> float | np.ndarray:
    t_ms = np.asarray(t_s, dtype=float) * 1e3
    a4, a3, a2, a1, a0 = _EQ10_COEFFS_MS
    return (((a4 * t_ms + a3) * t_ms + a2) * t_ms + a1) * t_ms + a0


def bandwidth_schedule_hz(
    elapsed_s: float | np.ndarray, start_hz: float = 15.0, end_hz: float = 1.0, duration_s: float = 70.0
) -> np.ndarray:
    """PLL noise bandwidth B_n(t) tightening from start_hz to end_hz over duration_s, then constant.

    Args:
        elapsed_s: time since the loop started, s, any shape, >= 0.
        start_hz, end_hz: bandwidths at t = 0 and t >= duration_s, Hz.
        duration_s: tightening duration, s.

    Returns:
        B_n, Hz, same shape as elapsed_s.

    Notes:
        Zhao et al., eq. 10: ``B_n = 3e-19 t^4 - 1.3e-13 t^3 + 1.5e-8 t^2 - 7e-4 t + 15.5``. The text
        does not give the unit of t; with t in seconds B_n stays at 15.45 Hz after 70 s, with t in
        milliseconds it falls from 15.5 Hz to 2.6 Hz at 70 s (the printed coefficients are rounded),
        monotonically. We keep the paper's polynomial shape (t in ms) and map it affinely so that it
        runs exactly from start_hz at t = 0 to end_hz at t = duration_s (the text: "from 15 to 1 Hz in
        the first 70 sec"), the shape being stretched to duration_s.
    """
    t = np.clip(np.asarray(elapsed_s, dtype=float), 0.0, duration_s)
    u = t * (70.0 / duration_s)  # map onto the paper's 70 s
    p0 = _eq10_poly(0.0)
    p1 = _eq10_poly(70.0)
    frac = (_eq10_poly(u) - p1) / (p0 - p1)
    return np.asarray(end_hz + (start_hz - end_hz) * frac, dtype=float)


@dataclass(frozen=True)
class PllParams:
    """Parameters of the Costas PLL baseline.

    Fields written with :func:`rfi_node_common.params.parameter` are parameters of imm_carrier_node:
    their default, description and range are there (``--help``, config/imm_carrier.yaml).

    Attributes:
        iq_scaling: "unit_amplitude" or "unit_noise" (only for the lock indicator).
    """

    start_bandwidth_hz: float = parameter(
        15.0,
        'PLL noise bandwidth when a channel starts, Hz (paper: 15).',
        minimum=0.01, maximum=100.0,
    )
    end_bandwidth_hz: float = parameter(
        1.0,
        'PLL noise bandwidth after the tightening, Hz (paper: 1); <= pll_start_bandwidth_hz.',
        minimum=0.01, maximum=100.0,
    )
    tightening_duration_s: float = parameter(
        70.0,
        'Time over which the PLL bandwidth goes from start to end (eq. 10 shape), s (paper: 70).',
        minimum=0.001, maximum=100000.0,
    )
    iq_scaling: str = "unit_amplitude"
    lock_time_constant_s: float = parameter(
        1.0,
        'Time constant of the PLL lock indicator averages, s.',
        minimum=0.001, maximum=1000.0,
    )
    lock_threshold: float = parameter(
        0.5,
        'PLL reported locked while the estimate of cos(2 phase error) exceeds this, dimensionless.',
        minimum=0.01, maximum=0.99,
    )

    def __post_init__(self) -> None:
        check_positive_finite(
            self, ("start_bandwidth_hz", "end_bandwidth_hz", "tightening_duration_s", "lock_time_constant_s")
        )
        if self.end_bandwidth_hz > self.start_bandwidth_hz:
            raise ValueError("PllParams.end_bandwidth_hz must not exceed start_bandwidth_hz")
        if self.iq_scaling not in IQ_SCALINGS:
            raise ValueError(f"iq_scaling must be one of {IQ_SCALINGS}, got {self.iq_scaling!r}")
        if not (0.0 < self.lock_threshold < 1.0):
            raise ValueError("PllParams.lock_threshold must be in (0, 1)")


# The state and output layouts of the compiled step: imm_carrier.layout (PllState, PllOut).


@njit(cache=True)
def scheduled_bandwidth_hz(elapsed_s, start_hz, end_hz, duration_s):
    """Scalar compiled form of :func:`bandwidth_schedule_hz` (same polynomial, same Horner order)."""
    t = min(max(elapsed_s, 0.0), duration_s)
    u = t * (70.0 / duration_s)
    a4, a3, a2, a1, a0 = _EQ10_COEFFS_MS
    um = u * 1e3
    p = (((a4 * um + a3) * um + a2) * um + a1) * um + a0
    p1m = 70.0 * 1e3
    p1 = (((a4 * p1m + a3) * p1m + a2) * p1m + a1) * p1m + a0
    return end_hz + (start_hz - end_hz) * ((p - p1) / (a0 - p1))


@njit(cache=True)
def pll_step(st, zi, zq, tk, dphi, bn, amp, alpha, out):
    """One Costas PLL step on scalars; st: float64[8] in place; out: float64[5] written.

    NaN or infinite I/Q: the NCO free-runs (no discriminator update).
    """
    sat = st[PllState.SAT_PHASE] + dphi
    sat = sat - TWO_PI * math.floor((sat + math.pi) / TWO_PI)
    st[PllState.SAT_PHASE] = sat
    st[PllState.NCO_PHASE] += tk * st[PllState.NCO_RATE]
    st[PllState.ELAPSED] += tk
    e = 0.0
    if zi == zi and zq == zq and abs(zi) < math.inf and abs(zq) < math.inf:
        th = sat + st[PllState.NCO_PHASE]
        c = math.cos(th)
        s = math.sin(th)
        ir = zi * c + zq * s
        qr = -zi * s + zq * c
        if ir != 0.0:
            e = math.atan(qr / ir)
        elif qr != 0.0:
            e = math.copysign(0.5 * math.pi, qr)
        w0 = bn / THIRD_ORDER_BN_TO_W0
        st[PllState.ACCELERATION] += tk * w0 * w0 * w0 * e
        st[PllState.VELOCITY] += tk * (st[PllState.ACCELERATION] + THIRD_ORDER_A3 * w0 * w0 * e)
        st[PllState.NCO_RATE] = st[PllState.VELOCITY] + THIRD_ORDER_B3 * w0 * e
        a2 = amp * amp
        st[PllState.EMA_DIFF] += alpha * ((ir * ir - qr * qr) / a2 - st[PllState.EMA_DIFF])
        st[PllState.EMA_SUM] += alpha * ((ir * ir + qr * qr) / a2 - st[PllState.EMA_SUM])
    out[PllOut.PHASE] = st[PllState.NCO_PHASE] + e
    out[PllOut.FREQUENCY] = st[PllState.VELOCITY]
    out[PllOut.DISCRIMINATOR] = e
    out[PllOut.BANDWIDTH] = bn
    out[PllOut.LOCK_METRIC] = st[PllState.EMA_DIFF]


@njit(cache=True)
def _pll_run(st, zi, zq, t, dphi, bn, cn0, unit_noise, alpha, out):
    """Costas PLL over a batch (:func:`pll_step` per sample, the amplitude from C/N0 by ``amp_sigma``); out:
    float64[n, 5]."""
    row = np.empty(PLL_OUT_LEN)
    for k in range(zi.shape[0]):
        pll_step(st, zi[k], zq[k], t[k], dphi[k], bn[k], amp_sigma(cn0[k], t[k], unit_noise)[0], alpha[k], row)
        for m in range(PLL_OUT_LEN):
            out[k, m] = row[m]


@dataclass(frozen=True)
class PllStepResult:
    """Result of one PLL step: phase_rad (NCO residual phase + discriminator, rad), frequency_hz
    (velocity integrator, Hz), discriminator_rad, bandwidth_hz, lock_metric (noise-corrected
    cos 2 dphi estimate), locked."""

    phase_rad: float
    frequency_hz: float
    discriminator_rad: float
    bandwidth_hz: float
    lock_metric: float
    locked: bool


@dataclass(frozen=True)
class PllBatchResult:
    """Per-sample arrays of :meth:`CostasPll.process_batch`, each shape (n,)."""

    phase_rad: np.ndarray
    frequency_hz: np.ndarray
    discriminator_rad: np.ndarray
    bandwidth_hz: np.ndarray
    lock_metric: np.ndarray
    accepted: np.ndarray
    locked: np.ndarray
    counters: dict[str, int] = field(default_factory=dict)


class CostasPll(CompiledChannelLoop):
    """Costas PLL with a third-order loop filter and the bandwidth schedule of Zhao et al., eq. 10.

    Notes:
        Discriminator atan(Q/I) (Kaplan & Hegarty, Costas discriminators), insensitive to the data bit,
        hence a pi (half-cycle) ambiguity. Loop filter: rectangular-integrator third-order loop with
        w0 = B_n / 0.7845, a3 = 1.1, b3 = 2.4 (Kaplan & Hegarty). Lock indicator: exponential averages of
        I'^2 - Q'^2 normalised by A^2 from C/N0 (an unbiased estimate of cos 2 dphi).
    """

    NOT_INITIALISED = "PLL not initialised"
    PARAMS_TYPE = PllParams
    STATE_LEN = PLL_STATE_LEN
    OUT_LEN = PLL_OUT_LEN
    params: PllParams

    @property
    def elapsed_s(self) -> float:
        """Time since the loop started (sum of integration times), s."""
        return float(self._st[PllState.ELAPSED])

    @property
    def residual_phase_rad(self) -> float:
        """Current NCO residual phase, rad."""
        return float(self._st[PllState.NCO_PHASE])

    @property
    def satellite_phase_rad(self) -> float:
        """Accumulated satellite-motion phase (wrapped), rad."""
        return float(self._st[PllState.SAT_PHASE])

    def initialize(self, phase_rad: float, frequency_hz: float, satellite_phase_rad: float = 0.0) -> None:
        """Set the NCO residual phase (rad), frequency (Hz) and the accumulated satellite phase (rad)."""
        if not all(math.isfinite(v) for v in (phase_rad, frequency_hz, satellite_phase_rad)):
            raise ValueError("PLL initial values must be finite")
        self._st[:] = 0.0
        self._st[PllState.NCO_PHASE] = phase_rad
        self._st[PllState.NCO_RATE] = self._st[PllState.VELOCITY] = TWO_PI * frequency_hz
        self._st[PllState.SAT_PHASE] = satellite_phase_rad
        self._st[PllState.EMA_DIFF] = 1.0
        self._st[PllState.EMA_SUM] = 1.0
        self._initialized = True

    def initialize_from_correlator(
        self, in_phase: float, quadrature: float, predicted_phase_change_rad: float, frequency_hz: float = 0.0
    ) -> None:
        """Start the NCO on atan(Q/I) of one correlator (Costas: modulo pi)."""
        if not all(math.isfinite(v) for v in (in_phase, quadrature, predicted_phase_change_rad)):
            raise ValueError("cannot initialise from non-finite correlator values")
        sat = predicted_phase_change_rad - TWO_PI * math.floor(
            (predicted_phase_change_rad + math.pi) / TWO_PI
        )
        self.initialize(math.atan2(quadrature, in_phase) - sat, frequency_hz, sat)

    def process_batch(
        self,
        in_phase: np.ndarray,
        quadrature: np.ndarray | float,
        cn0_dbhz: np.ndarray | float,
        integration_time_s: np.ndarray | float,
        predicted_phase_change_rad: np.ndarray,
    ) -> PllBatchResult:
        """Run the loop over a sequence of correlators of this channel.

        Args:
            in_phase, quadrature: prompt I, Q, shape (n,) (NaN: NCO free-runs).
            cn0_dbhz: C/N0 for the lock indicator's amplitude, dB-Hz, scalar or (n,).
            integration_time_s: T, s, scalar or (n,).
            predicted_phase_change_rad: satellite-motion phase change, rad, (n,).

        Returns:
            PllBatchResult; samples with invalid T, C/N0 or phase change are rejected and counted.
        """
        batch, idx, raw = self._start_batch(
            in_phase, quadrature, cn0_dbhz, integration_time_s, predicted_phase_change_rad
        )
        zi, zq, cn0 = batch.in_phase, batch.quadrature, batch.cn0_dbhz
        t, dphi = batch.integration_time_s, batch.predicted_phase_change_rad
        accepted, counters = batch.accepted, batch.counters
        if idx.size:
            ta = t[idx]
            elapsed = self._st[PllState.ELAPSED] + np.cumsum(ta)
            bn = bandwidth_schedule_hz(
                elapsed - ta,
                self.params.start_bandwidth_hz,
                self.params.end_bandwidth_hz,
                self.params.tightening_duration_s,
            )
            alpha = np.minimum(ta / self.params.lock_time_constant_s, 1.0)
            sub = np.empty((idx.size, PLL_OUT_LEN))
            _pll_run(self._st, np.ascontiguousarray(zi[idx]), zq[idx], ta, dphi[idx], bn, cn0[idx],
                     self.params.iq_scaling == "unit_noise", alpha, sub)
            raw[idx] = sub
        finite = np.isfinite(raw[:, 0]) & np.isfinite(raw[:, 1])
        return PllBatchResult(
            phase_rad=raw[:, 0],
            frequency_hz=raw[:, 1] / TWO_PI,
            discriminator_rad=raw[:, 2],
            bandwidth_hz=raw[:, 3],
            lock_metric=raw[:, 4],
            accepted=accepted,
            locked=accepted & finite & (raw[:, 4] > self.params.lock_threshold),
            counters=counters,
        )

    def update(
        self,
        in_phase: float,
        quadrature: float,
        cn0_dbhz: float,
        integration_time_s: float,
        predicted_phase_change_rad: float,
    ) -> PllStepResult:
        """One loop step (compiled scalar step, same arithmetic as :meth:`process_batch`).

        Args and units as :meth:`process_batch`, for one sample (NaN I/Q: the NCO free-runs).

        Raises:
            ValueError: not initialised, or invalid T, C/N0 or phase change (the tracker counts these
            before calling).
        """
        check_step_inputs(cn0_dbhz, integration_time_s, predicted_phase_change_rad)
        self._require_initialized()
        p = self.params
        t = float(integration_time_s)
        bn = scheduled_bandwidth_hz(
            self._st[PllState.ELAPSED], p.start_bandwidth_hz, p.end_bandwidth_hz, p.tightening_duration_s
        )
        amp = amp_sigma(float(cn0_dbhz), t, p.iq_scaling == "unit_noise")[0]
        alpha = min(t / p.lock_time_constant_s, 1.0)
        out = self._out
        pll_step(
            self._st, float(in_phase), float(quadrature), t, float(predicted_phase_change_rad), bn, amp, alpha, out
        )
        o = out.tolist()
        finite = math.isfinite(o[0]) and math.isfinite(o[1])
        return PllStepResult(
            o[0], o[1] / TWO_PI, o[2], o[3], o[4], finite and o[4] > p.lock_threshold
        )

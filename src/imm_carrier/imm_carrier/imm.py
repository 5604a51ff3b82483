"""Two-mode IMM carrier-phase filter (data bit +1 / -1) with an h-coefficient clock model.

The per-step filter is compiled with numba on scalars (no numpy 2x2 calls): a two-mode step costs
about a microsecond, so one process keeps up with 32 channels at 1 kHz. A generic, callable-based
IMM (:func:`imm_carrier.imm_reference.imm_step_reference`, numpy, N modes) is the readable
reference; the unit tests check that the compiled filter equals it to rounding.

State of each mode: ``x = [phi (rad), omega (rad/s)]``, the residual carrier phase (receiver clock
phase plus the channel's constant offset) and its rate, with the satellite-motion phase accumulated
separately from the correlators' ``predicted_phase_change_rad`` (see measurement_model.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from gnss_common.clock_model import (
    PROCESS_NOISE_FORMS,
    RUBIDIUM_LPFRS,
    ClockHCoefficients,
)
from gnss_common.constants import GPS_L1_FREQUENCY_HZ, TWO_PI
from imm_carrier.layout import IMM_OUT_LEN, IMM_STATE_LEN, ImmOut, ImmState
from imm_carrier.measurement_model import (
    IQ_SCALINGS,
    CompiledChannelLoop,
    amp_sigma,
    check_step_inputs,
)
from rfi_node_common.params import USER, check_positive_finite, parameter

# The state and output layouts of the compiled step: imm_carrier.layout (ImmState, ImmOut).


@dataclass(frozen=True)
class ImmParams:
    """Parameters of the IMM carrier filter.

    Fields written with :func:`rfi_node_common.params.parameter` are parameters of imm_carrier_node:
    their default, description and range are there (``--help``, config/imm_carrier.yaml).

    Attributes:
        clock: h-coefficients of the receiver clock model (default: the paper's LPFRS rubidium).
    """

    clock: ClockHCoefficients = RUBIDIUM_LPFRS
    process_noise_form: str = parameter(
        "brown_hwang",
        'Discretisation of the clock process noise W: brown_hwang (exact, W22 = S_g T) or zhao_eq8 (text of '
        'the paper, W22 = S_f/T + 4 S_g T/3).',
        choices=PROCESS_NOISE_FORMS,
    )
    process_noise_scale: float = parameter(
        1.0,
        'Factor on the whole process noise W of the IMM (sensitivity study), dimensionless.',
        minimum=1e-06, maximum=1000000000000.0,
    )
    carrier_hz: float = parameter(
        GPS_L1_FREQUENCY_HZ,
        'Carrier frequency of the tracked signal, Hz (default GPS L1). Converts the clock model into carrier '
        'phase. Change only for another signal (e.g. L5: 1176450000.0).',
        minimum=1e6, maximum=1e11, group=USER,
    )
    bit_transition_probability: float = parameter(
        0.5,
        'Probability that the navigation data bit changes between two 20 ms bits (IMM mode transition), '
        '0..1; 0.5 = independent bits (the paper).',
        minimum=0.0, maximum=1.0,
    )
    iq_scaling: str = parameter(
        "unit_amplitude",
        'Normalisation of the input correlators (Zhao et al., eq. 2-5): unit_amplitude (signal amplitude 1, '
        'noise std 1/sqrt(2 T C/N0), eq. 5) or unit_noise (noise std 1, amplitude from C/N0). Must match the '
        "receiver's output.",
        choices=IQ_SCALINGS, group=USER,
    )
    initial_phase_std_rad: float = parameter(
        0.5,
        'IMM phase 1-sigma when a channel starts from its first correlator, rad.',
        minimum=1e-06, maximum=10.0,
    )
    initial_frequency_std_hz: float = parameter(
        1.0,
        'IMM frequency 1-sigma when a channel starts, Hz.',
        minimum=1e-09, maximum=10000.0,
    )
    lock_phase_std_max_rad: float = parameter(
        0.5,
        'IMM estimate reported locked only while its phase 1-sigma is below this, rad.',
        minimum=1e-06, maximum=3.141592653589793,
    )
    slip_jump_threshold_rad: float = parameter(
        math.pi / 2.0,
        'An IMM update moving the phase more than this from its prediction counts as a detected cycle slip, '
        'rad.',
        minimum=0.001, maximum=6.283185307179586,
    )

    def __post_init__(self) -> None:
        if not isinstance(self.clock, ClockHCoefficients):
            raise ValueError("clock must be a ClockHCoefficients")
        if self.process_noise_form not in PROCESS_NOISE_FORMS:
            raise ValueError(
                f"process_noise_form must be one of {PROCESS_NOISE_FORMS}, got {self.process_noise_form!r}"
            )
        if self.iq_scaling not in IQ_SCALINGS:
            raise ValueError(f"iq_scaling must be one of {IQ_SCALINGS}, got {self.iq_scaling!r}")
        check_positive_finite(self, (
            "process_noise_scale",
            "carrier_hz",
            "initial_phase_std_rad",
            "initial_frequency_std_hz",
            "lock_phase_std_max_rad",
            "slip_jump_threshold_rad",
        ))
        p = self.bit_transition_probability
        if not (isinstance(p, (int, float)) and 0.0 <= p <= 1.0):
            raise ValueError(f"ImmParams.bit_transition_probability must be in [0, 1], got {p!r}")

    @property
    def q_phase(self) -> tuple[float, float]:
        """(q_f, q_g): S_f and S_g in phase units (rad^2 s, rad^2/s^3) times process_noise_scale."""
        k = (TWO_PI * self.carrier_hz) ** 2 * self.process_noise_scale
        return k * self.clock.s_f, k * self.clock.s_g


@njit(cache=True)
def _process_noise(q_f: float, q_g: float, t: float, form_code: int) -> tuple[float, float, float]:
    """W of Zhao et al. eq. 8 in phase units (form 0: Brown & Hwang exact; 1: text of eq. 8)."""
    w11 = q_f * t + q_g * t * t * t / 3.0
    w12 = q_g * t * t / 2.0
    if form_code == 0:
        w22 = q_g * t
    else:
        w22 = q_f / t + 4.0 * q_g * t / 3.0
    return w11, w12, w22


@njit(cache=True)
def wrap_phase(a: float) -> float:
    return a - TWO_PI * math.floor((a + math.pi) / TWO_PI)


@njit(cache=True)
def _log0(x: float) -> float:
    """log x, with log 0 = -inf (a transition probability of exactly 0 or 1)."""
    return math.log(x) if x > 0.0 else -math.inf


@njit(cache=True)
def _logaddexp(a: float, b: float) -> float:
    """log(exp a + exp b) without overflow or underflow; -inf if both are -inf."""
    m = max(a, b)
    if m == -math.inf:
        return -math.inf
    return m + math.log1p(math.exp(-abs(a - b)))


@njit(cache=True)
def _mixing(l1: float, l2: float, p_change: float) -> tuple[float, float, float, float, float, float]:
    """Mixing probabilities of the two modes, transition matrix [[1-p, p], [p, 1-p]], in the log domain:
    log c_j = log sum_i Pi[i, j] mu_i, log mu_{i|j} = log Pi[i, j] + log mu_i - log c_j (Bar-Shalom et al.,
    Section 11.6.6, step 1).

    Args:
        l1, l2: log mode probabilities before the step.
        p_change: probability of a bit change over the interval.

    Returns:
        (mu_{1|1}, mu_{2|1}, mu_{1|2}, mu_{2|2}, log c_1, log c_2).
    """
    ls = _log0(1.0 - p_change)
    lp = _log0(p_change)
    b11, b21 = ls + l1, lp + l2
    b12, b22 = lp + l1, ls + l2
    lc1 = _logaddexp(b11, b21)
    lc2 = _logaddexp(b12, b22)
    if lc1 > -math.inf:
        a11 = math.exp(b11 - lc1)
        a21 = math.exp(b21 - lc1)
    else:  # mode 1 impossible a priori: its mixed state has zero weight, any convex mix will do
        a11 = math.exp(l1)
        a21 = math.exp(l2)
    if lc2 > -math.inf:
        a12 = math.exp(b12 - lc2)
        a22 = math.exp(b22 - lc2)
    else:
        a12 = math.exp(l1)
        a22 = math.exp(l2)
    return a11, a21, a12, a22, lc1, lc2


@njit(cache=True)
def _mode_log_probabilities(valid: bool, lc1: float, lc2: float, ll1: float, ll2: float) -> tuple[float, float]:
    """Updated log mode probabilities, log mu_j = log c_j + log L_j - log sum_i c_i L_i (step 5). In the log
    domain a mode whose probability is below the smallest double (e.g. the other bit after 20 looks at T = 1 ms
    and 60 dB-Hz, log mu = -80 000) keeps its exact log value instead of 0, so no 0/0 can arise. Not ``valid``
    (prediction only) or both likelihoods non-finite (absurd I/Q): the predicted probabilities."""
    if valid:
        lu1 = lc1 + ll1
        lu2 = lc2 + ll2
        lt = _logaddexp(lu1, lu2)
        if not abs(lt) < math.inf:  # no mode information
            lu1, lu2, lt = lc1, lc2, _logaddexp(lc1, lc2)
    else:
        lu1, lu2, lt = lc1, lc2, _logaddexp(lc1, lc2)
    return lu1 - lt, lu2 - lt


@njit(cache=True)
def imm_step(st, zi, zq, amp, sig, t, dphi, p_change, prior_plus, q_f, q_g, form_code, out):
    """One IMM cycle (mixing, mode-matched EKF prediction and update, mode probabilities, combination).

    st: state, float64[13], updated in place; out: float64[11], written. Zhao et al., Fig. 2-3;
    Bar-Shalom, Li & Kirubarajan (2001), Section 11.6.6 (IMM). NaN zi/zq: prediction only.

    The mode probabilities are kept as logarithms (state slots 10-11) and combined with log-sum-exp.
    In linear form a probability that underflows to exactly 0 (inside a data bit at T = 1 ms and high
    C/N0 the other bit's probability falls by 2 T C/N0 = 4000 in log per look at 60 dB-Hz) made
    ``c_j L_j`` zero for both modes as soon as one correlator favoured the vanished mode by more than
    ~745 (exp underflow), and the normalisation divided 0 by 0. The log form is exact, needs no floor
    (a floor would change the filter's answer, e.g. let a glitch flip a bit that cannot change), and
    equals the linear IMM to rounding wherever that one is defined (tested against the reference).
    """
    # 1. Mixing probabilities (log domain).
    a11, a21, a12, a22, lc1, lc2 = _mixing(st[ImmState.LOGMU], st[ImmState.LOGMU + 1], p_change)
    if prior_plus == prior_plus:  # known or partly known bit: overrides the predicted mode probability
        c1 = min(max(prior_plus, 1e-12), 1.0 - 1e-12)
        lc1 = math.log(c1)
        lc2 = math.log1p(-c1)
    x1p, x1w = st[ImmState.X1], st[ImmState.X1 + 1]
    x2p, x2w = st[ImmState.X2], st[ImmState.X2 + 1]
    p1a, p1b, p1c = st[ImmState.P1], st[ImmState.P1 + 1], st[ImmState.P1 + 2]
    p2a, p2b, p2c = st[ImmState.P2], st[ImmState.P2 + 1], st[ImmState.P2 + 2]
    w11, w12, w22 = _process_noise(q_f, q_g, t, form_code)
    sat = wrap_phase(st[ImmState.SAT] + dphi)
    st[ImmState.SAT] = sat
    valid = zi == zi and zq == zq and abs(zi) < math.inf and abs(zq) < math.inf
    ll = np.empty(2)
    pr = np.empty((2, 4))  # predicted phi, omega, p11, p22 per mode
    for j in range(2):
        if j == 0:
            wa, wb, d = a11, a21, 1.0
        else:
            wa, wb, d = a12, a22, -1.0
        # 2. Mixed initial condition of mode j.
        mp = wa * x1p + wb * x2p
        mw = wa * x1w + wb * x2w
        d1p, d1w, d2p, d2w = x1p - mp, x1w - mw, x2p - mp, x2w - mw
        pa = wa * (p1a + d1p * d1p) + wb * (p2a + d2p * d2p)
        pb = wa * (p1b + d1p * d1w) + wb * (p2b + d2p * d2w)
        pc = wa * (p1c + d1w * d1w) + wb * (p2c + d2w * d2w)
        # 3. Prediction (Zhao et al., eq. 7-8).
        mp = mp + t * mw
        pa = pa + 2.0 * t * pb + t * t * pc + w11
        pb = pb + t * pc + w12
        pc = pc + w22
        pr[j, 0], pr[j, 1], pr[j, 2], pr[j, 3] = mp, mw, pa, pc
        # 4. EKF update on I/Q (Zhao et al., eq. 2-3), scalarised: S = A^2 p11 u u^T + sigma^2 I.
        if valid:
            th = sat + mp
            s = math.sin(th)
            c = math.cos(th)
            ri = zi - d * amp * c
            rq = zq - d * amp * s
            y = -s * ri + c * rq
            denom = sig * sig + amp * amp * pa
            g = d * amp * y / denom
            quad = (ri * ri + rq * rq - amp * amp * pa / denom * y * y) / (sig * sig)
            ll[j] = -0.5 * quad - 0.5 * (math.log(sig * sig) + math.log(denom)) - math.log(TWO_PI)
            k = amp * amp / denom
            mp = mp + g * pa
            mw = mw + g * pb
            na = pa - k * pa * pa
            nb = pb - k * pa * pb
            nc = pc - k * pb * pb
            pa, pb, pc = na, nb, nc
        else:
            ll[j] = 0.0
        if j == 0:
            n1p, n1w, n1a, n1b, n1c = mp, mw, pa, pb, pc
        else:
            n2p, n2w, n2a, n2b, n2c = mp, mw, pa, pb, pc
    # Combined prior (before the update), weighted by the predicted mode probabilities.
    cw1 = math.exp(lc1 - _logaddexp(lc1, lc2))
    cw2 = 1.0 - cw1
    prior_phi = cw1 * pr[0, 0] + cw2 * pr[1, 0]
    prior_om = cw1 * pr[0, 1] + cw2 * pr[1, 1]
    prior_p11 = cw1 * (pr[0, 2] + (pr[0, 0] - prior_phi) ** 2) + cw2 * (
        pr[1, 2] + (pr[1, 0] - prior_phi) ** 2
    )
    prior_p22 = cw1 * (pr[0, 3] + (pr[0, 1] - prior_om) ** 2) + cw2 * (pr[1, 3] + (pr[1, 1] - prior_om) ** 2)
    # 5. Mode probabilities (log domain).
    l1, l2 = _mode_log_probabilities(valid, lc1, lc2, ll[0], ll[1])
    mu1 = math.exp(l1)
    mu2 = math.exp(l2)
    # 6. Combination.
    phi = mu1 * n1p + mu2 * n2p
    om = mu1 * n1w + mu2 * n2w
    e1p, e1w, e2p, e2w = n1p - phi, n1w - om, n2p - phi, n2w - om
    out[ImmOut.PHI] = phi
    out[ImmOut.OMEGA] = om
    out[ImmOut.P11] = mu1 * (n1a + e1p * e1p) + mu2 * (n2a + e2p * e2p)
    out[ImmOut.P12] = mu1 * (n1b + e1p * e1w) + mu2 * (n2b + e2p * e2w)
    out[ImmOut.P22] = mu1 * (n1c + e1w * e1w) + mu2 * (n2c + e2w * e2w)
    out[ImmOut.MU1] = mu1
    out[ImmOut.MU2] = mu2
    out[ImmOut.PRIOR_PHI] = prior_phi
    out[ImmOut.PRIOR_P11] = prior_p11
    out[ImmOut.PRIOR_P22] = prior_p22
    out[ImmOut.USED] = 1.0 if valid else 0.0
    st[ImmState.X1], st[ImmState.X1 + 1] = n1p, n1w
    st[ImmState.P1], st[ImmState.P1 + 1], st[ImmState.P1 + 2] = n1a, n1b, n1c
    st[ImmState.X2], st[ImmState.X2 + 1] = n2p, n2w
    st[ImmState.P2], st[ImmState.P2 + 1], st[ImmState.P2 + 2] = n2a, n2b, n2c
    st[ImmState.LOGMU], st[ImmState.LOGMU + 1] = l1, l2


@njit(cache=True)
def _imm_run(st, zi, zq, cn0, t, dphi, p_change, prior_plus, q_f, q_g, form_code, unit_noise, out):
    """Batch of IMM steps for one channel; out: float64[n, 11]."""
    row = np.empty(IMM_OUT_LEN)
    for k in range(zi.shape[0]):
        amp, sig = amp_sigma(cn0[k], t[k], unit_noise)
        imm_step(
            st, zi[k], zq[k], amp, sig, t[k], dphi[k], p_change[k], prior_plus[k], q_f, q_g, form_code, row
        )
        for m in range(IMM_OUT_LEN):
            out[k, m] = row[m]


@dataclass(frozen=True)
class ImmStepResult:
    """Result of one IMM step.

    Attributes:
        phase_rad: combined residual phase estimate, rad (unwrapped).
        phase_std_rad: its 1-sigma, rad.
        frequency_hz: combined residual frequency (clock frequency error), Hz.
        frequency_std_hz: its 1-sigma, Hz.
        phase_frequency_cov_rad_hz: covariance of phase and frequency, rad Hz.
        mode_probabilities: (P(bit=+1), P(bit=-1)).
        data_bit: most probable bit, +1 / -1 (0 if tied).
        data_bit_probability: its probability.
        prior_phase_rad: combined predicted phase before the update, rad.
        prior_phase_std_rad: 1-sigma of the prediction (P-bar of Zhao et al., Fig. 9), rad.
        prior_frequency_std_hz: 1-sigma of the predicted frequency, Hz.
        measurement_used: False when the I/Q were not finite (prediction only).
        locked: estimate finite and phase_std_rad below the lock threshold.
        slip_detected: the update moved the phase more than slip_jump_threshold_rad.
    """

    phase_rad: float
    phase_std_rad: float
    frequency_hz: float
    frequency_std_hz: float
    phase_frequency_cov_rad_hz: float
    mode_probabilities: tuple[float, float]
    data_bit: int
    data_bit_probability: float
    prior_phase_rad: float
    prior_phase_std_rad: float
    prior_frequency_std_hz: float
    measurement_used: bool
    locked: bool
    slip_detected: bool


@dataclass(frozen=True)
class ImmBatchResult:
    """Per-sample arrays of :meth:`ImmCarrierFilter.process_batch`, each shape (n,).

    ``accepted`` is False where the sample was rejected (non-finite or non-positive integration
    time, C/N0 outside [0, 70] dB-Hz or non-finite predicted phase change); the estimates there
    are NaN and ``locked`` False. ``counters`` counts rejections and coasted (NaN I/Q) samples.
    """

    phase_rad: np.ndarray
    phase_std_rad: np.ndarray
    frequency_hz: np.ndarray
    frequency_std_hz: np.ndarray
    mode_probability_plus: np.ndarray
    prior_phase_rad: np.ndarray
    prior_phase_std_rad: np.ndarray
    prior_frequency_std_hz: np.ndarray
    measurement_used: np.ndarray
    accepted: np.ndarray
    locked: np.ndarray
    counters: dict[str, int] = field(default_factory=dict)


class ImmCarrierFilter(CompiledChannelLoop):
    """Two-mode (data bit +1 / -1) IMM estimating the residual carrier phase of one channel.

    Time is not read: each step propagates by the correlator's integration time (s).

    Example:
        >>> f = ImmCarrierFilter(ImmParams())
        >>> f.initialize(phase_rad=0.3, frequency_hz=0.0, phase_std_rad=0.1, frequency_std_hz=0.1)
        >>> r = f.update(1.0, 0.3, cn0_dbhz=51.0, integration_time_s=0.02, predicted_phase_change_rad=0.0)
        >>> abs(r.phase_rad - 0.29) < 0.05
        True

    Notes:
        Zhao et al., Section II (eq. 1-5, Fig. 2-3) and Section III (eq. 7-8).
    """

    NOT_INITIALISED = "filter not initialised: call initialize() or initialize_from_correlator()"
    PARAMS_TYPE = ImmParams
    STATE_LEN = IMM_STATE_LEN
    OUT_LEN = IMM_OUT_LEN
    params: ImmParams

    def __init__(self, params: ImmParams) -> None:
        super().__init__(params)
        self._q_f, self._q_g = params.q_phase
        self._form_code = PROCESS_NOISE_FORMS.index(params.process_noise_form)
        self._unit_noise = params.iq_scaling == "unit_noise"

    @property
    def residual_phase_rad(self) -> float:
        """Current combined residual phase, rad."""
        mu1, mu2 = math.exp(self._st[ImmState.LOGMU]), math.exp(self._st[ImmState.LOGMU + 1])
        return float(mu1 * self._st[ImmState.X1] + mu2 * self._st[ImmState.X2])

    @property
    def satellite_phase_rad(self) -> float:
        """Accumulated satellite-motion phase (wrapped), rad."""
        return float(self._st[ImmState.SAT])

    def initialize(
        self,
        phase_rad: float,
        frequency_hz: float,
        phase_std_rad: float,
        frequency_std_hz: float,
        mode_probability_plus: float = 0.5,
        satellite_phase_rad: float = 0.0,
    ) -> None:
        """Set the state (e.g. from a PLL at hand-over, Zhao et al. Fig. 12).

        Args:
            phase_rad: residual phase, rad.
            frequency_hz: residual frequency, Hz.
            phase_std_rad: 1-sigma, rad, > 0.
            frequency_std_hz: 1-sigma, Hz, > 0.
            mode_probability_plus: P(bit = +1), 0..1.
            satellite_phase_rad: accumulated satellite-motion phase at this instant, rad.
        """
        vals = (phase_rad, frequency_hz, phase_std_rad, frequency_std_hz, satellite_phase_rad)
        if not all(math.isfinite(v) for v in vals) or phase_std_rad <= 0 or frequency_std_hz <= 0:
            raise ValueError("initial state must be finite with positive standard deviations")
        if not 0.0 <= mode_probability_plus <= 1.0:
            raise ValueError("mode_probability_plus must be in [0, 1]")
        omega = TWO_PI * frequency_hz
        pa = phase_std_rad**2
        pc = (TWO_PI * frequency_std_hz) ** 2
        st = self._st
        st[ImmState.X1], st[ImmState.X1 + 1], st[ImmState.X2], st[ImmState.X2 + 1] = phase_rad, omega, phase_rad, omega
        st[ImmState.P1], st[ImmState.P1 + 1], st[ImmState.P1 + 2] = pa, 0.0, pc
        st[ImmState.P2], st[ImmState.P2 + 1], st[ImmState.P2 + 2] = pa, 0.0, pc
        st[ImmState.LOGMU] = math.log(mode_probability_plus) if mode_probability_plus > 0.0 else -math.inf
        st[ImmState.LOGMU + 1] = math.log1p(-mode_probability_plus) if mode_probability_plus < 1.0 else -math.inf
        st[ImmState.SAT] = satellite_phase_rad
        self._initialized = True

    def initialize_from_correlator(
        self, in_phase: float, quadrature: float, predicted_phase_change_rad: float, frequency_hz: float = 0.0
    ) -> None:
        """Initialise from one correlator: phase = atan2(Q, I) minus the satellite-motion phase.

        The phase has the usual pi ambiguity of an unknown data bit (taken as +1). Uses the
        initial standard deviations of the parameters.
        """
        if not all(
            math.isfinite(v) for v in (in_phase, quadrature, predicted_phase_change_rad, frequency_hz)
        ):
            raise ValueError("cannot initialise from non-finite correlator values")
        sat = float(wrap_phase(predicted_phase_change_rad))
        self.initialize(
            math.atan2(quadrature, in_phase) - sat,
            frequency_hz,
            self.params.initial_phase_std_rad,
            self.params.initial_frequency_std_hz,
            0.5,
            sat,
        )

    def _check_scalar_inputs(
        self, cn0_dbhz: float, integration_time_s: float, predicted_phase_change_rad: float
    ) -> None:
        self._require_initialized()
        check_step_inputs(cn0_dbhz, integration_time_s, predicted_phase_change_rad)

    def update(
        self,
        in_phase: float,
        quadrature: float,
        cn0_dbhz: float,
        integration_time_s: float,
        predicted_phase_change_rad: float,
        bit_transition_probability: float | None = None,
        bit_prior_plus: float = math.nan,
    ) -> ImmStepResult:
        """One IMM step with one prompt correlator.

        Args:
            in_phase, quadrature: prompt I and Q, correlator units (NaN: prediction only).
            cn0_dbhz: C/N0 used for A and sigma_v, dB-Hz, in [0, 70].
            integration_time_s: coherent integration time T, s, > 0 (also the propagation step).
            predicted_phase_change_rad: satellite-motion phase change over the interval, rad.
            bit_transition_probability: overrides the parameter for this step (e.g. 0 inside a
                data bit when T < 20 ms), 0..1.
            bit_prior_plus: known (1.0 / 0.0) or partly known P(bit = +1) for this interval; NaN
                for unknown (Zhao & Pervan 2019, data-bit knowledge).

        Returns:
            ImmStepResult.

        Raises:
            ValueError: not initialised, or T, C/N0 or the phase change invalid (the tracker
            counts these before calling).
        """
        self._check_scalar_inputs(cn0_dbhz, integration_time_s, predicted_phase_change_rad)
        p = (
            self.params.bit_transition_probability
            if bit_transition_probability is None
            else bit_transition_probability
        )
        if not 0.0 <= p <= 1.0:
            raise ValueError("bit_transition_probability must be in [0, 1]")
        amp, sig = amp_sigma(cn0_dbhz, integration_time_s, self._unit_noise)
        out = self._out
        imm_step(
            self._st,
            float(in_phase),
            float(quadrature),
            amp,
            sig,
            integration_time_s,
            predicted_phase_change_rad,
            p,
            float(bit_prior_plus),
            self._q_f,
            self._q_g,
            self._form_code,
            out,
        )
        return self._result(out)

    def _result(self, out: np.ndarray) -> ImmStepResult:
        o = out.tolist()  # plain floats: much cheaper than numpy scalar indexing
        phase = o[ImmOut.PHI]
        omega = o[ImmOut.OMEGA]
        mu1 = o[ImmOut.MU1]
        mu2 = o[ImmOut.MU2]
        phase_std = math.sqrt(max(o[ImmOut.P11], 0.0))
        finite = math.isfinite(phase) and math.isfinite(omega) and math.isfinite(phase_std)
        bit = 1 if mu1 > mu2 else (-1 if mu2 > mu1 else 0)
        prior_phase = o[ImmOut.PRIOR_PHI]
        return ImmStepResult(
            phase_rad=phase,
            phase_std_rad=phase_std,
            frequency_hz=omega / TWO_PI,
            frequency_std_hz=math.sqrt(max(o[ImmOut.P22], 0.0)) / TWO_PI,
            phase_frequency_cov_rad_hz=o[ImmOut.P12] / TWO_PI,
            mode_probabilities=(mu1, mu2),
            data_bit=bit,
            data_bit_probability=max(mu1, mu2),
            prior_phase_rad=prior_phase,
            prior_phase_std_rad=math.sqrt(max(o[ImmOut.PRIOR_P11], 0.0)),
            prior_frequency_std_hz=math.sqrt(max(o[ImmOut.PRIOR_P22], 0.0)) / TWO_PI,
            measurement_used=o[ImmOut.USED] > 0.5,
            locked=finite and phase_std < self.params.lock_phase_std_max_rad,
            slip_detected=finite and abs(phase - prior_phase) > self.params.slip_jump_threshold_rad,
        )

    def process_batch(
        self,
        in_phase: np.ndarray,
        quadrature: np.ndarray,
        cn0_dbhz: np.ndarray | float,
        integration_time_s: np.ndarray | float,
        predicted_phase_change_rad: np.ndarray,
        bit_transition_probability: np.ndarray | float | None = None,
        bit_prior_plus: np.ndarray | float = math.nan,
    ) -> ImmBatchResult:
        """Run the filter over a sequence of correlators of this channel (compiled loop).

        Args:
            in_phase, quadrature: prompt I, Q, shape (n,), correlator units (NaN: coast).
            cn0_dbhz: C/N0, dB-Hz, shape (n,) or scalar.
            integration_time_s: T, s, shape (n,) or scalar.
            predicted_phase_change_rad: satellite-motion phase change per interval, rad, shape (n,).
            bit_transition_probability: per-sample or scalar override, 0..1.
            bit_prior_plus: per-sample or scalar P(bit=+1); NaN = unknown.

        Returns:
            ImmBatchResult; rejected samples leave the state untouched and are counted.
        """
        batch, idx, raw = self._start_batch(
            in_phase, quadrature, cn0_dbhz, integration_time_s, predicted_phase_change_rad
        )
        zi, zq, cn0 = batch.in_phase, batch.quadrature, batch.cn0_dbhz
        t, dphi = batch.integration_time_s, batch.predicted_phase_change_rad
        pch = batch.per_sample(
            "bit_transition_probability",
            self.params.bit_transition_probability
            if bit_transition_probability is None
            else bit_transition_probability,
        )
        prior = batch.per_sample("bit_prior_plus", bit_prior_plus)
        if np.any(~((pch >= 0) & (pch <= 1))):
            raise ValueError("bit_transition_probability must be in [0, 1]")
        accepted, counters = batch.accepted, batch.counters
        if idx.size:
            sub = np.empty((idx.size, IMM_OUT_LEN))
            _imm_run(
                self._st,
                np.ascontiguousarray(zi[idx]),
                zq[idx],
                cn0[idx],
                t[idx],
                dphi[idx],
                pch[idx],
                prior[idx],
                self._q_f,
                self._q_g,
                self._form_code,
                self._unit_noise,
                sub,
            )
            raw[idx] = sub
        phase_std = np.sqrt(np.maximum(raw[:, ImmOut.P11], 0.0))
        finite = np.isfinite(raw[:, ImmOut.PHI]) & np.isfinite(raw[:, ImmOut.OMEGA]) & np.isfinite(phase_std)
        return ImmBatchResult(
            phase_rad=raw[:, ImmOut.PHI],
            phase_std_rad=phase_std,
            frequency_hz=raw[:, ImmOut.OMEGA] / TWO_PI,
            frequency_std_hz=np.sqrt(np.maximum(raw[:, ImmOut.P22], 0.0)) / TWO_PI,
            mode_probability_plus=raw[:, ImmOut.MU1],
            prior_phase_rad=raw[:, ImmOut.PRIOR_PHI],
            prior_phase_std_rad=np.sqrt(np.maximum(raw[:, ImmOut.PRIOR_P11], 0.0)),
            prior_frequency_std_hz=np.sqrt(np.maximum(raw[:, ImmOut.PRIOR_P22], 0.0)) / TWO_PI,
            measurement_used=raw[:, ImmOut.USED] > 0.5,
            accepted=accepted,
            locked=accepted & finite & (phase_std < self.params.lock_phase_std_max_rad),
            counters=counters,
        )

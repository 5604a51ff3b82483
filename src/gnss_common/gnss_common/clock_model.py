"""Receiver clock model from power-law h-coefficients: PSD, Allan variance, discrete process noise.

Shared by the IMM carrier tracker (phase/frequency form, rad and rad/s) and the GNSS/UWB fusion
filter (range form, m and m/s). Pure numpy/scipy, no ROS.

Conventions
-----------
* ``h`` are the one-sided power-law coefficients of the fractional-frequency PSD
  ``S_y(f) = h2 f^2 + h1 f + h0 + h_-1 / f + h_-2 / f^2`` (1/Hz), as in the table of
  Zhao et al., Fig. 4 (IEEE Std 1139). The carrier-phase PSD is ``S_phi(f) = nu0^2 S_y(f) / f^2``
  in rad^2/Hz (Zhao et al., eq. 6 and the S_phi column of Fig. 4).
* The two-state clock is ``[x, y]`` with ``x`` the time error (s) and ``y = dx/dt`` the
  fractional frequency (s/s), driven by white noises of two-sided PSD ``S_f = h0 / 2`` (on x,
  white FM) and ``S_g = 2 pi^2 h_-2`` (on y, random-walk FM) (Zhao et al., eq. 8 and the text below
  it; Brown & Hwang, "Introduction to Random Signals and Applied Kalman Filtering", clock model
  section). h_-1, h1 and h2 are not representable by this two-state model and are ignored by the
  discrete model (they still enter the PSD and Allan-variance functions).

Decision on W(2,2) (papers/README.md)
-------------------------------------
The text of Zhao et al. eq. 8 reads ``W22 = S_f / dt + 4 S_g dt / 3``; the exact discretisation
of the continuous two-state model (Brown & Hwang) gives ``W22 = S_g T``. We use the exact form
(``form="brown_hwang"``, the default) because (i) it is the covariance of the state increment of
the continuous model whose PSD is eq. 6, so a clock simulated with it has exactly the Allan
variance ``h0/(2 tau) + (2 pi^2/3) h_-2 tau`` (tested), and (ii) it composes:
``W(2T) = F W(T) F^T + W(T)``, which the eq. 8 text form violates (its S_f/dt term makes the
phase variance over 2T equal 3 S_f T instead of 2 S_f T). The text form is kept as
``form="zhao_eq8"`` for the sensitivity study only; it corresponds to treating the frequency state
as the frequency averaged over the interval (white FM averaged over dt has variance S_f/dt).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS

PROCESS_NOISE_FORMS = ("brown_hwang", "zhao_eq8")
"""Accepted values of the ``form`` argument of the process-noise functions."""


@dataclass(frozen=True)
class ClockHCoefficients:
    """Power-law coefficients of the one-sided fractional-frequency PSD S_y(f), each in 1/Hz^(a+1).

    Attributes:
        h2: white PM coefficient, S_y term h2 f^2 (Hz^-3).
        h1: flicker PM coefficient, S_y term h1 f (Hz^-2).
        h0: white FM coefficient, S_y term h0 (Hz^-1, i.e. s).
        h_minus1: flicker FM coefficient, S_y term h_-1 / f (dimensionless).
        h_minus2: random-walk FM coefficient, S_y term h_-2 / f^2 (Hz).
        name: label for tables and plots.

    Notes:
        Zhao et al., eq. 6 and Fig. 4. All coefficients must be finite and >= 0.
    """

    h0: float
    h_minus2: float
    h_minus1: float = 0.0
    h1: float = 0.0
    h2: float = 0.0
    name: str = "custom"

    def __post_init__(self) -> None:
        for key in ("h0", "h_minus2", "h_minus1", "h1", "h2"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"ClockHCoefficients.{key} must be a finite number >= 0, got {value!r}")

    @property
    def s_f(self) -> float:
        """Two-sided PSD of the white noise on the time error, S_f = h0 / 2, s (Zhao et al., eq. 8)."""
        return self.h0 / 2.0

    @property
    def s_g(self) -> float:
        """Two-sided PSD of the white noise on the fractional frequency, S_g = 2 pi^2 h_-2, 1/s."""
        return 2.0 * math.pi**2 * self.h_minus2

    def scaled(
        self, h0_factor: float = 1.0, h_minus2_factor: float = 1.0, name: str | None = None
    ) -> ClockHCoefficients:
        """Return a copy with h0 (i.e. S_f) and h_-2 (i.e. S_g) multiplied by the given factors.

        Used for the sensitivity study of Zhao et al., Section IX (S_f x 1e3, S_g x 1e3).
        """
        return replace(
            self,
            h0=self.h0 * h0_factor,
            h_minus2=self.h_minus2 * h_minus2_factor,
            name=name if name is not None else self.name,
        )


RUBIDIUM_LPFRS = ClockHCoefficients(h0=5e-25, h_minus2=1e-30, name="Rubidium LPFRS")
"""SpectraTime LPFRS rubidium bound of Zhao et al., Section III-A-1 (h0 = 5e-25, h_-2 = 1e-30)."""

RUBIDIUM_LPFRS_VIBRATION = ClockHCoefficients(h0=2e-21, h_minus2=1e-30, name="Rubidium LPFRS, vibration")
"""Vibration-case bound of Zhao et al., Section III-B (h0 = 2e-21, h_-2 = 1e-30)."""

TCXO = ClockHCoefficients(h0=1e-21, h_minus1=1e-20, h_minus2=2e-20, name="TCXO")
"""Typical TCXO: Van Dierendonck's values as tabulated in Kaplan & Hegarty, "Understanding GPS",
2nd ed., oscillator h-parameter table (h0 = 1e-21, h_-1 = 1e-20, h_-2 = 2e-20). Its S_f is 2000 times
the LPFRS value, matching Zhao et al., Section IX ("about 1e3 times")."""

OCXO = ClockHCoefficients(h0=2.51e-26, h_minus1=2.51e-23, h_minus2=2.51e-22, name="OCXO")
"""Typical OCXO: Van Dierendonck's values as tabulated in Kaplan & Hegarty, "Understanding GPS",
2nd ed., oscillator h-parameter table (h0 = 2.51e-26, h_-1 = 2.51e-23, h_-2 = 2.51e-22)."""

OCXO_BROWN_HWANG = ClockHCoefficients(h0=8e-20, h_minus1=2e-21, h_minus2=4e-23, name="OCXO (Brown & Hwang)")
"""Ovenized crystal of Brown & Hwang, "Introduction to Random Signals and Applied Kalman Filtering",
table of typical clock h-parameters (h0 = 8e-20, h_-1 = 2e-21, h_-2 = 4e-23)."""

COMPENSATED_CRYSTAL_BROWN_HWANG = ClockHCoefficients(
    h0=2e-19, h_minus1=7e-21, h_minus2=2e-20, name="Compensated crystal (Brown & Hwang)"
)
"""Compensated (temperature-compensated) crystal of Brown & Hwang, same table
(h0 = 2e-19, h_-1 = 7e-21, h_-2 = 2e-20)."""

PRESETS = {
    "rubidium": RUBIDIUM_LPFRS,
    "rubidium_vibration": RUBIDIUM_LPFRS_VIBRATION,
    "tcxo": TCXO,
    "ocxo": OCXO,
    "ocxo_brown_hwang": OCXO_BROWN_HWANG,
    "compensated_crystal_brown_hwang": COMPENSATED_CRYSTAL_BROWN_HWANG,
}
"""Clock presets by name (for node parameters)."""


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


def fractional_frequency_psd(h: ClockHCoefficients, f_hz: np.ndarray) -> np.ndarray:
    """One-sided fractional-frequency PSD S_y(f), 1/Hz.

    Args:
        h: clock coefficients.
        f_hz: Fourier frequencies, Hz, any shape, > 0.

    Returns:
        S_y(f), 1/Hz, same shape as f_hz.

    Notes:
        Zhao et al., Fig. 4, column S_y(f).
    """
    f = np.asarray(f_hz, dtype=float)
    if np.any(~np.isfinite(f)) or np.any(f <= 0.0):
        raise ValueError("f_hz must be finite and > 0")
    return h.h2 * f**2 + h.h1 * f + h.h0 + h.h_minus1 / f + h.h_minus2 / f**2


def phase_noise_psd_rad2_per_hz(
    h: ClockHCoefficients, f_hz: np.ndarray, carrier_hz: float = GPS_L1_FREQUENCY_HZ
) -> np.ndarray:
    """One-sided carrier phase-noise PSD S_phi(f) = nu0^2 S_y(f) / f^2, rad^2/Hz.

    Args:
        h: clock coefficients.
        f_hz: Fourier frequencies, Hz, any shape, > 0.
        carrier_hz: carrier frequency nu0, Hz.

    Returns:
        S_phi(f), rad^2/Hz, same shape as f_hz.

    Notes:
        Zhao et al., eq. 6 (with nu0^2 written out, as in the S_phi column of Fig. 4).
    """
    carrier_hz = _check_positive("carrier_hz", carrier_hz)
    f = np.asarray(f_hz, dtype=float)
    return carrier_hz**2 * fractional_frequency_psd(h, f) / f**2


def allan_variance(h: ClockHCoefficients, tau_s: np.ndarray, f_high_hz: float = 1e3) -> np.ndarray:
    """Allan variance sigma_y^2(tau) implied by the h-coefficients, dimensionless.

    Args:
        h: clock coefficients.
        tau_s: averaging times, s, any shape, > 0.
        f_high_hz: measurement high-frequency cut-off f_h, Hz (only the h1 and h2 terms use it).

    Returns:
        sigma_y^2(tau), same shape as tau_s.

    Notes:
        Zhao et al., Fig. 4 (from IEEE Std 1139):
        ``sigma^2 = A h_-2 tau + B h_-1 + C h0 / tau + D h1 / tau^2 + E h2 / tau^2`` with
        A = 2 pi^2 / 3, B = 2 ln 2, C = 1/2, D = (1.038 + 3 ln(2 pi f_h tau)) / (4 pi^2),
        E = 3 f_h / (4 pi^2).
    """
    f_high_hz = _check_positive("f_high_hz", f_high_hz)
    tau = np.asarray(tau_s, dtype=float)
    if np.any(~np.isfinite(tau)) or np.any(tau <= 0.0):
        raise ValueError("tau_s must be finite and > 0")
    a = 2.0 * math.pi**2 / 3.0
    b = 2.0 * math.log(2.0)
    c = 0.5
    d = (1.038 + 3.0 * np.log(2.0 * math.pi * f_high_hz * tau)) / (4.0 * math.pi**2)
    e = 3.0 * f_high_hz / (4.0 * math.pi**2)
    return a * h.h_minus2 * tau + b * h.h_minus1 + c * h.h0 / tau + (d * h.h1 + e * h.h2) / tau**2


def allan_deviation(h: ClockHCoefficients, tau_s: np.ndarray, f_high_hz: float = 1e3) -> np.ndarray:
    """Allan deviation sigma_y(tau), dimensionless; square root of :func:`allan_variance`."""
    return np.sqrt(allan_variance(h, tau_s, f_high_hz))


def fit_h_bound(
    tau_s: np.ndarray,
    adev_spec: np.ndarray,
    terms: tuple[str, ...] = ("h0", "h_minus2"),
    name: str = "fitted bound",
) -> ClockHCoefficients:
    """Smallest h-coefficients whose Allan deviation bounds a specification from above.

    Solves the linear programme ``min sum_i model(tau_i) / spec(tau_i)^2`` subject to
    ``model(tau_i) >= spec(tau_i)^2`` and ``h >= 0``, where ``model`` is the Allan variance of
    :func:`allan_variance` restricted to ``terms`` (a subset of "h0", "h_minus1", "h_minus2").
    This is the paper's procedure of bounding the datasheet Allan-deviation curve with straight
    lines (Zhao et al., Section III-A-1) made reproducible.

    Args:
        tau_s: averaging times of the specification, s, shape (n,), > 0.
        adev_spec: specified Allan deviations at tau_s, dimensionless, shape (n,), > 0.
        terms: which coefficients to fit (others are zero).
        name: label of the result.

    Returns:
        The fitted coefficients; allan_deviation(result, tau_s) >= adev_spec (to LP tolerance).

    Notes:
        Zhao et al., Fig. 4 coefficients A, B, C; scipy.optimize.linprog (HiGHS).
    """
    from scipy.optimize import linprog

    tau = np.asarray(tau_s, dtype=float)
    spec = np.asarray(adev_spec, dtype=float)
    if tau.ndim != 1 or spec.shape != tau.shape or tau.size == 0:
        raise ValueError("tau_s and adev_spec must be 1-D arrays of the same non-zero length")
    if np.any(~np.isfinite(tau)) or np.any(tau <= 0) or np.any(~np.isfinite(spec)) or np.any(spec <= 0):
        raise ValueError("tau_s and adev_spec must be finite and > 0")
    basis = {
        "h0": 0.5 / tau,
        "h_minus1": np.full_like(tau, 2.0 * math.log(2.0)),
        "h_minus2": 2.0 * math.pi**2 / 3.0 * tau,
    }
    if not terms or any(t not in basis for t in terms):
        raise ValueError(f"terms must be a non-empty subset of {tuple(basis)}, got {terms!r}")
    var = spec**2
    # Scale columns so the LP is well conditioned (h values span 1e-30..1e-19).
    cols = np.stack([basis[t] / var for t in terms], axis=1)  # model/spec^2 per unit h
    scale = 1.0 / cols.max(axis=0)
    a_scaled = cols * scale
    res = linprog(
        c=a_scaled.sum(axis=0),
        A_ub=-a_scaled,
        b_ub=-np.ones(tau.size),
        bounds=[(0, None)] * len(terms),
        method="highs",
    )
    if not res.success:
        raise ValueError(f"bound fit failed: {res.message}")
    values = {t: float(v * s) for t, v, s in zip(terms, res.x, scale, strict=True)}
    return ClockHCoefficients(
        h0=values.get("h0", 0.0),
        h_minus1=values.get("h_minus1", 0.0),
        h_minus2=values.get("h_minus2", 0.0),
        name=name,
    )


def transition_matrix(dt_s: float) -> np.ndarray:
    """State transition F = [[1, dt], [0, 1]] of the two-state clock, shape (2, 2) (Zhao et al., eq. 7)."""
    dt_s = _check_positive("dt_s", dt_s)
    return np.array([[1.0, dt_s], [0.0, 1.0]])


def clock_process_noise_s(h: ClockHCoefficients, dt_s: float, form: str = "brown_hwang") -> np.ndarray:
    """Discrete process noise W of the clock state [x (s), y (s/s)] over dt_s.

    Args:
        h: clock coefficients (h0 and h_-2 are used).
        dt_s: propagation interval T, s, > 0.
        form: "brown_hwang" (exact discretisation, default) or "zhao_eq8" (the text of eq. 8).

    Returns:
        W, shape (2, 2), units [[s^2, s], [s, 1]].

    Notes:
        Zhao et al., eq. 7-8 with S_f = h0/2, S_g = 2 pi^2 h_-2. "brown_hwang":
        ``[[S_f T + S_g T^3/3, S_g T^2/2], [S_g T^2/2, S_g T]]``. "zhao_eq8": same but
        ``W22 = S_f / T + 4 S_g T / 3``. See the module docstring for the decision.
    """
    dt_s = _check_positive("dt_s", dt_s)
    s_f, s_g = h.s_f, h.s_g
    w11 = s_f * dt_s + s_g * dt_s**3 / 3.0
    w12 = s_g * dt_s**2 / 2.0
    if form == "brown_hwang":
        w22 = s_g * dt_s
    elif form == "zhao_eq8":
        w22 = s_f / dt_s + 4.0 * s_g * dt_s / 3.0
    else:
        raise ValueError(f"form must be one of {PROCESS_NOISE_FORMS}, got {form!r}")
    return np.array([[w11, w12], [w12, w22]])


def clock_process_noise_m(h: ClockHCoefficients, dt_s: float, form: str = "brown_hwang") -> np.ndarray:
    """Discrete process noise of the receiver clock state [c dt (m), c ddt (m/s)] over dt_s.

    For the GNSS/UWB fusion filter's clock bias and drift states.

    Args:
        h: clock coefficients.
        dt_s: propagation interval, s, > 0.
        form: see :func:`clock_process_noise_s`.

    Returns:
        W, shape (2, 2), units [[m^2, m^2/s], [m^2/s, m^2/s^2]].

    Notes:
        c^2 times :func:`clock_process_noise_s` (Brown & Hwang clock model; Zhao et al., eq. 8).
    """
    return SPEED_OF_LIGHT_MPS**2 * clock_process_noise_s(h, dt_s, form)


def clock_process_noise_phase(
    h: ClockHCoefficients, dt_s: float, carrier_hz: float = GPS_L1_FREQUENCY_HZ, form: str = "brown_hwang"
) -> np.ndarray:
    """Discrete process noise of the carrier clock state [phase (rad), phase rate (rad/s)] over dt_s.

    Args:
        h: clock coefficients.
        dt_s: propagation interval (coherent integration time T_s), s, > 0.
        carrier_hz: carrier frequency nu0, Hz.
        form: see :func:`clock_process_noise_s`.

    Returns:
        W, shape (2, 2), units [[rad^2, rad^2/s], [rad^2/s, rad^2/s^2]].

    Notes:
        (2 pi nu0)^2 times :func:`clock_process_noise_s`: phase = 2 pi nu0 x (Zhao et al., eq. 7-8).
    """
    carrier_hz = _check_positive("carrier_hz", carrier_hz)
    return (2.0 * math.pi * carrier_hz) ** 2 * clock_process_noise_s(h, dt_s, form)


def simulate_clock(
    h: ClockHCoefficients,
    dt_s: float,
    n_steps: int,
    seed: int,
    x0_s: float = 0.0,
    y0: float = 0.0,
    n_realizations: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate the two-state clock exactly as the discrete model (eq. 7, exact W) implies.

    Args:
        h: clock coefficients (h0, h_-2 used).
        dt_s: sample interval, s, > 0.
        n_steps: number of samples after the initial one, >= 1.
        seed: seed of np.random.default_rng.
        x0_s: initial time error, s.
        y0: initial fractional frequency, s/s.
        n_realizations: if given, simulate that many independent clocks (leading axis).

    Returns:
        (x_s, y): time error (s) and fractional frequency at t = k dt_s, k = 0..n_steps, each of
        shape (n_steps + 1,) or (n_realizations, n_steps + 1).

    Notes:
        x_{k+1} = x_k + T y_k + w1, y_{k+1} = y_k + w2, (w1, w2) ~ N(0, W_brown_hwang(T)).
    """
    if int(n_steps) < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps!r}")
    n_steps = int(n_steps)
    w = clock_process_noise_s(h, dt_s, "brown_hwang")
    rng = np.random.default_rng(seed)
    shape = (n_steps,) if n_realizations is None else (int(n_realizations), n_steps)
    # Cholesky of a PSD 2x2 that may be singular (h0 = 0 or h_-2 = 0).
    l11 = math.sqrt(w[0, 0])
    l21 = w[0, 1] / l11 if l11 > 0 else 0.0
    l22 = math.sqrt(max(w[1, 1] - l21**2, 0.0))
    n1 = rng.standard_normal(shape)
    n2 = rng.standard_normal(shape)
    w1 = l11 * n1
    w2 = l21 * n1 + l22 * n2
    zeros = np.zeros(shape[:-1] + (1,))
    y = y0 + np.concatenate([zeros, np.cumsum(w2, axis=-1)], axis=-1)
    dx = dt_s * y[..., :-1] + w1
    x = x0_s + np.concatenate([zeros, np.cumsum(dx, axis=-1)], axis=-1)
    return x, y


def allan_variance_from_phase(x_s: np.ndarray, dt_s: float, m: int) -> float:
    """Overlapping Allan variance at tau = m dt_s from time-error samples, dimensionless.

    Args:
        x_s: time-error samples, s, shape (n,) or (r, n) (realisations pooled).
        dt_s: sample interval, s.
        m: averaging factor, >= 1, with 2 m < n.

    Returns:
        sigma_y^2(m dt_s) = <(x_{k+2m} - 2 x_{k+m} + x_k)^2> / (2 tau^2).

    Notes:
        IEEE Std 1139 / NIST TN 1337 overlapping estimator.
    """
    x = np.asarray(x_s, dtype=float)
    if m < 1 or 2 * m >= x.shape[-1]:
        raise ValueError("need 1 <= m and 2 m < number of samples")
    tau = m * dt_s
    d2 = x[..., 2 * m :] - 2.0 * x[..., m:-m] + x[..., : -2 * m]
    return float(np.mean(d2**2) / (2.0 * tau**2))


def vibration_phase_psd_rad2_per_hz(
    f_hz: np.ndarray,
    vibration_psd_g2_per_hz: np.ndarray,
    g_sensitivity_per_g: float = 2e-10,
    carrier_hz: float = GPS_L1_FREQUENCY_HZ,
) -> np.ndarray:
    """Extra carrier phase-noise PSD caused by random vibration, rad^2/Hz.

    Args:
        f_hz: Fourier (vibration) frequencies, Hz, shape (n,), > 0.
        vibration_psd_g2_per_hz: one-sided acceleration PSD G_g(f) at f_hz, g^2/Hz, shape (n,), >= 0.
        g_sensitivity_per_g: oscillator g-sensitivity k_g, 1/g (the paper's bound on k_g N: 2e-10).
        carrier_hz: carrier frequency f0, Hz.

    Returns:
        G_phi,vib(f) = (k_g f0)^2 G_g(f) / f^2, rad^2/Hz, shape (n,).

    Notes:
        Zhao et al., eq. 9 (after Hegarty 1997). The g-sensitivity turns acceleration a(t) into a
        fractional frequency k_g a(t), so S_y,vib(f) = k_g^2 G_g(f), a white-FM-like term: the h0 that
        bounds it is :func:`vibration_h0_bound`.
    """
    f = np.asarray(f_hz, dtype=float)
    g = np.asarray(vibration_psd_g2_per_hz, dtype=float)
    if f.shape != g.shape or np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise ValueError("f_hz must be finite, > 0 and of the same shape as vibration_psd_g2_per_hz")
    if np.any(~np.isfinite(g)) or np.any(g < 0):
        raise ValueError("vibration_psd_g2_per_hz must be finite and >= 0")
    _check_positive("g_sensitivity_per_g", g_sensitivity_per_g)
    _check_positive("carrier_hz", carrier_hz)
    return (g_sensitivity_per_g * carrier_hz) ** 2 * g / f**2


def vibration_h0_bound(
    clock: ClockHCoefficients, vibration_psd_g2_per_hz: np.ndarray, g_sensitivity_per_g: float = 2e-10
) -> ClockHCoefficients:
    """Clock coefficients with h0 inflated so that white FM bounds the clock plus vibration PSD.

    The vibration adds S_y,vib(f) = k_g^2 G_g(f); a constant h0' bounds h0 + S_y,vib(f) for every f
    when h0' = h0 + k_g^2 max_f G_g(f). h_-2 is kept (Zhao et al., Section III-B keep h_-2 = 1e-30
    and raise h0 to 2e-21; with k_g = 2e-10 that corresponds to max G_g = 0.05 g^2/Hz).

    Args:
        clock: the static clock coefficients.
        vibration_psd_g2_per_hz: acceleration PSD samples, g^2/Hz, any shape, >= 0.
        g_sensitivity_per_g: oscillator g-sensitivity, 1/g.

    Returns:
        Coefficients with the inflated h0.

    Notes:
        Zhao et al., eq. 9 and Fig. 7-8.
    """
    g = np.asarray(vibration_psd_g2_per_hz, dtype=float)
    if g.size == 0 or np.any(~np.isfinite(g)) or np.any(g < 0):
        raise ValueError("vibration_psd_g2_per_hz must be non-empty, finite and >= 0")
    _check_positive("g_sensitivity_per_g", g_sensitivity_per_g)
    return replace(
        clock, h0=clock.h0 + g_sensitivity_per_g**2 * float(g.max()), name=f"{clock.name} + vibration"
    )

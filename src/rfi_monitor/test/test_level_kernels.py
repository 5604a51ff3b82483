"""The compiled passes of the level stages (issue 26 item 2) against the numpy expressions they replaced, to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import fft as sp_fft

from rfi_monitor.spectral_autocorrelation import _bin_covariances, _noise_moments, spectral_autocorrelation
from rfi_monitor.stft import stft_power


def _reference_autocorrelation(x: np.ndarray, cplx: bool, L: int, max_lag: int):
    """spectral_autocorrelation as numpy expressions (the sequential sums of the original compiled loops)."""
    S, _ = stft_power(x, L, cplx)
    T = S.shape[0]
    b0 = 1 if (not cplx and S.shape[1] > 3) else 0
    A = np.sqrt(S[:, b0:S.shape[1] - b0])                    # float32 (frames, bins)
    nb = A.shape[1]
    m = np.empty(nb, dtype=np.float32)
    for b in range(nb):                                      # double sums in frame order
        acc = 0.0
        for t in range(T):
            acc += float(A[t, b])
        m[b] = np.float32(max(acc / T, 1e-300))
    E = A / m - np.float32(1.0)
    if nb > 1:
        acc_t = np.zeros(T)
        for b in range(nb):
            acc_t += E[:, b].astype(np.float64)
        E = E - (acc_t / nb).astype(np.float32)[:, None]
    Et = np.ascontiguousarray(E.T)
    c0, c1 = _bin_covariances(Et, T)
    q = float(np.sum(c0 * c0))
    g = float(np.trace(c0))
    copies = g * g / q if q > 0 else 0.0
    spread = g
    if T > 1:
        q += 2.0 * float(np.sum(c1 * c1))
        g += 2.0 * float(np.trace(c1))
    nf = sp_fft.next_fast_len(T + max_lag + 1, real=True)
    F = sp_fft.rfft(Et, nf, axis=1)
    P = (F.real.astype(np.float64) ** 2 + F.imag.astype(np.float64) ** 2).sum(axis=0)
    R = sp_fft.irfft(P, nf)[: max_lag + 1]
    n_prod = np.maximum(T - np.arange(max_lag + 1), 0)
    return R + n_prod * (g / T), n_prod * q, T, copies, spread


@pytest.mark.parametrize("cplx", [False, True])
@pytest.mark.parametrize("L,n", [(8, 4000), (32, 38192), (16, 1024)])
def test_spectral_autocorrelation_matches_numpy(cplx: bool, L: int, n: int) -> None:
    rng = np.random.default_rng(L + n + cplx)
    x = rng.standard_normal(n) * 3.0
    if cplx:
        x = x + 1j * rng.standard_normal(n)
    T = (n - L) // (L // 2) + 1
    max_lag = int(0.75 * T)
    got = spectral_autocorrelation(x, cplx, L, max_lag)
    ref = _reference_autocorrelation(x, cplx, L, max_lag)
    assert got[2:] == ref[2:]
    # the moments to the bit; the autocorrelation to the rounding of the sum over bins (numpy's order differs)
    np.testing.assert_allclose(got[0], ref[0], rtol=1e-9, atol=1e-9 * float(np.max(np.abs(ref[0]))))
    np.testing.assert_array_equal(got[1], ref[1])


def test_noise_moments_are_numpy_sums() -> None:
    rng = np.random.default_rng(3)
    for nb, nfr in ((15, 2386), (8, 37), (3, 2), (1, 9)):
        Et = np.zeros((nb, nfr + 11), dtype=np.float32)
        Et[:, :nfr] = rng.standard_normal((nb, nfr)).astype(np.float32)
        c0, c1 = _bin_covariances(Et, nfr)
        q0, g0 = float(np.sum(c0 * c0)), float(np.trace(c0))
        q, g, copies, spread = _noise_moments(Et, nfr)
        assert spread == g0 and copies == g0 * g0 / q0
        if nfr > 1:
            assert q == q0 + 2.0 * float(np.sum(c1 * c1)) and g == g0 + 2.0 * float(np.trace(c1))

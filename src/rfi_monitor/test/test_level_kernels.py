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


def test_arange_is_numpys() -> None:
    from rfi_monitor.chirp_comb import _arange
    rng = np.random.default_rng(11)
    for _ in range(2000):
        c, w, step = rng.uniform(2, 300), rng.uniform(1e-3, 3), rng.uniform(1e-3, 0.3)
        np.testing.assert_array_equal(_arange(c - w, c + w + 1e-12, step), np.arange(c - w, c + w + 1e-12, step))


def test_fine_candidates_as_the_python_loop() -> None:
    from rfi_monitor.chirp_comb import FINE_HALF_WIDTH, ChirpComb, _fine_candidates
    rng = np.random.default_rng(12)
    for lag_limit, lmax, kc, kf in ((1789, 238, 16, 128), (95, 23, 16, 128), (300, 75, 2, 2)):
        periods = ChirpComb()._comb_grid(4, lmax, lag_limit, kc)[0]
        for _ in range(20):
            top = rng.choice(periods.size, size=min(12, periods.size), replace=False).tolist()
            cand: list[float] = []                       # the loop _fine_candidates compiled
            for i in top:
                p0 = float(periods[i])
                k0 = max(2, min(kc, int(lag_limit // p0)))
                k1 = max(2, min(kf, int(lag_limit // p0)))
                cand.extend(np.arange(p0 - FINE_HALF_WIDTH / k0, p0 + FINE_HALF_WIDTH / k0 + 1e-12,
                                      0.5 / k1).tolist())
            ref = np.asarray([c for c in cand if 4 <= c <= lmax] or [float(periods[top[0]])])
            np.testing.assert_array_equal(_fine_candidates(periods, top, 4, lmax, lag_limit, kc, kf), ref)


@pytest.mark.parametrize("width", [1, 2, 4, 15, 31])
def test_smooth_template_is_scipys_median_filter(width: int) -> None:
    from scipy.ndimage import median_filter

    from rfi_monitor.classifier import smooth_template
    rng = np.random.default_rng(width)
    for size in (5, 129, 1024):
        p = rng.exponential(size=size)
        p[size // 3] = 1e4                                 # a tone never enters the template
        t = median_filter(p, size=width, mode="nearest")
        t = np.maximum(t, 1e-6 * np.max(t))
        np.testing.assert_array_equal(smooth_template(p, width), t / t.sum())
        q = np.round(p * 2)                                # ties (and zeros) in the sliding window
        t = median_filter(q, size=width, mode="nearest")
        t = np.maximum(t, 1e-6 * np.max(t))
        np.testing.assert_array_equal(smooth_template(q, width), t / t.sum())


def test_noise_reference_medians_are_numpys() -> None:
    """The learned floor's and shape's medians (noise_reference: every quiet block) equal np.median's to the bit, odd
    and even counts, ties included."""
    from rfi_monitor.noise_reference import _median, _median_rows
    rng = np.random.default_rng(3)
    for k in range(1, 12):
        for _ in range(50):
            v = (rng.exponential(size=k) * 10.0 ** rng.integers(-6, 6)).tolist()
            assert _median(v) == float(np.median(v))
            a = rng.exponential(size=(k, 129))
            a[:, ::7] = np.round(a[:, ::7])
            np.testing.assert_array_equal(_median_rows(a), np.median(a, axis=0))


@pytest.mark.parametrize("cplx", [False, True])
def test_welch_psd_compiled_path_is_the_numpy_path(cplx: bool) -> None:
    """The compiled path (all frames) against the numpy expressions of the generic path (frames selected: here all of
    them, in order, through the selection's index)."""
    from rfi_monitor.classifier import _hann32, _normalised, welch_psd
    rng = np.random.default_rng(20 + cplx)
    for n, nfft in ((38192, 256), (10000, 1024), (4096, 64)):
        x = rng.standard_normal(n) * 7.0
        if cplx:
            x = x + 1j * rng.standard_normal(n)
        nfr = n // nfft
        fr = x[: nfr * nfft].reshape(nfr, nfft)
        fw = fr.astype(np.complex64 if cplx else np.float32)
        fw *= _hann32(nfft)
        spec = sp_fft.fft(fw, axis=1) if cplx else sp_fft.rfft(fw, axis=1)
        if cplx:
            v = np.ascontiguousarray(spec).view(np.float32)
            p2 = np.einsum("ij,ij->j", v, v).astype(np.float64)
            p = np.fft.fftshift((p2[0::2] + p2[1::2]) / nfr)
            fv = np.ascontiguousarray(fr).view(np.float64).ravel()
        else:
            p = (spec.real.astype(np.float64) ** 2 + spec.imag.astype(np.float64) ** 2).sum(axis=0) / nfr
            fv = x[: nfr * nfft]
        ref = _normalised(p, float(np.add.reduce(fv * fv)) / (nfr * nfft))
        psd, frames = welch_psd(x, nfft, 1 << 30)
        assert frames == nfr
        if cplx:
            np.testing.assert_array_equal(psd, ref)
        else:   # the sum over frames in another order than frame_power's
            np.testing.assert_allclose(psd, ref, rtol=1e-12)


@pytest.mark.parametrize("mode", ["nearest", "wrap", "reflect"])
@pytest.mark.parametrize("n,width", [(513, 31), (1024, 31), (129, 7), (129, 8), (20, 31), (5, 7), (256, 15)])
def test_running_median_is_scipys_median_filter(mode: str, n: int, width: int) -> None:
    """The compiled running median (the CW statistic's, mode wrap for complex input and reflect for real; the noise
    template's, mode nearest) equals scipy.ndimage.median_filter (even widths and windows wider than the vector
    included), with equal values in the window."""
    from scipy.ndimage import median_filter

    from rfi_monitor.numpy_kernels import MEDIAN_NEAREST, MEDIAN_REFLECT, MEDIAN_WRAP, running_median
    x = np.random.default_rng(n + width).gamma(3.0, size=n)
    x[1] = x[3]
    code = {"nearest": MEDIAN_NEAREST, "wrap": MEDIAN_WRAP, "reflect": MEDIAN_REFLECT}[mode]
    got = running_median(x, width, code)
    assert np.array_equal(got, median_filter(x, size=width, mode=mode))


@pytest.mark.parametrize("cplx", [True, False])
def test_cw_test_is_the_numpy_expressions(cplx: bool) -> None:
    """CwStatistic.test (compiled scores) gives to the bit what the scipy median filter and numpy expressions gave,
    on a summed PSD with a tone."""
    from scipy.ndimage import median_filter

    from rfi_monitor.cw_statistic import CwStatistic
    rng = np.random.default_rng(5)
    B, K = (1024, 300) if cplx else (513, 300)
    P = rng.gamma(K, 1.0 / K, size=B) * (1.0 + 0.3 * np.cos(np.arange(B) / 40.0))
    P[200] += 1.0
    cw = CwStatistic(31)
    score, f, excess = cw.test(P, K, cplx, 1e-4)
    Pm = P.copy()
    if not cplx:
        Pm[0], Pm[-1] = P[1], P[-2]
    ref = np.maximum(median_filter(Pm, size=31, mode="wrap" if cplx else "reflect") / cw._median_ratio(K), 1e-300)
    s = P / ref / cw._threshold(K, B, cplx, 1e-4)
    if not cplx:
        s[0] = s[-1] = 0.0
    j = int(np.argmax(s))
    assert j == 200 and score == s[j] and score > 1.0
    assert f == ((j - B // 2) / B if cplx else j / (2 * (B - 1)))
    assert excess == float(np.sum(P[j - 2:j + 3] - ref[j - 2:j + 3]) / max(float(ref.sum()), 1e-300))


def test_coarse_top_is_the_numpy_selection() -> None:
    """The comb's compiled coarse selection: the same largest combs as numpy's argpartition, ordered best first with
    equal combs (common: neighbouring candidates with the same rounded lags) to the shorter period, then the
    separation rule."""
    from rfi_monitor.chirp_comb import _coarse_top, _comb_z, _comb_z_prefix, _separated, comb_lags, compact_lags
    rng = np.random.default_rng(3)
    lag_limit = 900
    periods = np.arange(4.0, 200.0, 1.0 / 32)
    _, idx, mask = comb_lags(periods, lag_limit, 16)
    r = rng.standard_normal(lag_limit + 1)
    v = 1.0 + rng.random(lag_limit + 1)
    z = _comb_z(r, v, idx, mask)
    numpy_top = np.argpartition(z, z.size - 240)[z.size - 240:]
    ranked = np.lexsort((np.arange(z.size), -z))[:240]          # best first, ties to the lower index
    assert np.array_equal(np.sort(z[ranked]), np.sort(z[numpy_top]))
    assert np.unique(z[ranked]).size < ranked.size               # ties present: the rule is exercised
    lags, counts = compact_lags(idx, mask, lag_limit)
    assert lags.dtype == np.int16 and np.array_equal(_comb_z_prefix(r, v, lags, counts), z)
    got = _coarse_top(r, v, lags, counts, periods, 240, 12)
    assert np.array_equal(got, _separated(ranked, periods, 12))
    assert got.size == 12
    # ties across the n_top-th value (r zero on most lags: many equal combs), and more wanted than there are
    r0 = np.where(rng.random(lag_limit + 1) < 0.97, 0.0, r)
    z0 = _comb_z(r0, v, idx, mask)
    for n_top in (240, 3, z0.size + 5):
        ranked0 = np.lexsort((np.arange(z0.size), -z0))[:n_top]
        assert z0[ranked0[-1]] == z0[ranked0[-1] + 1] or n_top > z0.size or n_top == 3
        got0 = _coarse_top(r0, v, lags, counts, periods, n_top, 12)
        assert np.array_equal(got0, _separated(ranked0, periods, 12))

"""Oracle tests of ``gnss_common.moments``: the M2M4 powers from exact moments, from samples of a constant-envelope
signal in circular Gaussian noise, and at the edges (noise alone, no noise, NaN)."""

import math

import numpy as np
import pytest

from gnss_common.moments import m2m4_powers


@pytest.mark.parametrize(('ps', 'pn'), [(1.0, 0.0), (1.0, 1.0), (0.01, 3.0), (250.0, 0.5)])
def test_exact_moments_give_the_powers(ps, pn):
    m2 = ps + pn
    m4 = ps * ps + 4.0 * ps * pn + 2.0 * pn * pn
    got_ps, got_pn = m2m4_powers(m2, m4)
    assert got_ps == pytest.approx(ps, rel=1e-9, abs=1e-12)
    assert got_pn == pytest.approx(pn, rel=1e-9, abs=1e-12)
    assert got_ps + got_pn == m2  # P_n is M2 - P_s


def test_samples_of_a_tone_in_noise():
    rng = np.random.default_rng(3)
    n = 200_000
    ps, pn = 2.0, 0.5
    x = math.sqrt(ps) * np.exp(1j * rng.uniform(0, 2 * np.pi, n)) \
        + math.sqrt(pn / 2) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    q = np.abs(x) ** 2
    got_ps, got_pn = m2m4_powers(float(q.mean()), float((q * q).mean()))
    assert got_ps == pytest.approx(ps, rel=0.02)
    assert got_pn == pytest.approx(pn, rel=0.05)


def test_edges():
    # noise alone whose moments scatter to 2 M2^2 < M4: no signal power, all of M2 is noise
    assert m2m4_powers(1.0, 2.1) == (0.0, 1.0)
    # a constant envelope alone (M4 = M2^2): no noise
    assert m2m4_powers(3.0, 9.0) == (3.0, 0.0)
    # a limiter's flattening (M4 < M2^2) leaves negative noise, not floored here
    assert m2m4_powers(1.0, 0.8)[1] < 0.0
    assert all(math.isnan(v) for v in m2m4_powers(math.inf, math.inf))
    assert all(math.isnan(v) for v in m2m4_powers(math.nan, 1.0))

"""Oracle tests of ``gnss_common.multilateration``: the tag found from exact and noisy ranges, the
mirror ambiguity of a flat anchor set resolved by the guess, refusals counted as None."""

import numpy as np

from gnss_common.multilateration import gauss_newton, multilaterate

FLAT = np.array([[0.0, 0.0, 2.0], [30.0, 0.0, 2.5], [0.0, 25.0, 1.5]])
SPREAD = np.array([[0.0, 0.0, 2.0], [30.0, 0.0, 12.0], [0.0, 25.0, 8.0], [28.0, 27.0, 20.0]])
TAG = np.array([11.0, 7.0, 1.0])


def ranges_to(anchors, tag):
    return np.linalg.norm(anchors - tag, axis=1)


def test_exact_ranges_give_the_tag_from_any_start():
    x, ok, rms = gauss_newton(SPREAD, ranges_to(SPREAD, TAG), np.array([15.0, 12.0, 5.0]), 20, 1e-9)
    assert ok and rms < 1e-9
    np.testing.assert_allclose(x, TAG, atol=1e-7)
    np.testing.assert_allclose(multilaterate(SPREAD, ranges_to(SPREAD, TAG)), TAG, atol=1e-6)


def test_noisy_ranges_stay_near_the_tag():
    rng = np.random.default_rng(7)
    r = ranges_to(SPREAD, TAG) + rng.normal(0, 0.02, 4)
    x = multilaterate(SPREAD, r, np.array([15.0, 12.0, 5.0]))
    assert x is not None and np.linalg.norm(x - TAG) < 0.2


def test_the_guess_picks_the_side_of_a_flat_anchor_set():
    """Three anchors: the tag and its mirror across the anchors' plane fit the ranges equally."""
    r = ranges_to(FLAT, TAG)
    normal = np.cross(FLAT[1] - FLAT[0], FLAT[2] - FLAT[0])
    normal /= np.linalg.norm(normal)
    mirror = TAG - 2 * np.dot(TAG - FLAT[0], normal) * normal
    assert np.allclose(ranges_to(FLAT, mirror), r)
    np.testing.assert_allclose(multilaterate(FLAT, r, TAG + [0.5, -0.5, -0.3]), TAG, atol=1e-6)
    np.testing.assert_allclose(multilaterate(FLAT, r, mirror + [0.5, -0.5, 0.3]), mirror, atol=1e-6)


def test_refusals():
    r = ranges_to(SPREAD, TAG)
    bad = r.copy()
    bad[0] += 1000.0  # no point fits: the residual is far above 1 m
    assert multilaterate(SPREAD, bad) is None
    assert multilaterate(SPREAD, bad, max_rms_m=np.inf) is not None
    nan = r.copy()
    nan[2] = np.nan
    assert multilaterate(SPREAD, nan) is None
    assert multilaterate(SPREAD[:2], r[:2]) is None  # two anchors
    assert multilaterate(SPREAD, r[:3]) is None  # shapes that do not match
    x, ok, rms = gauss_newton(SPREAD, r, SPREAD[0].copy(), 20, 1e-6)  # an iterate on an anchor
    assert not ok and np.isnan(rms)


"""gnss_common.corrections.carrier_levelled_ionosphere_m: the ionosphere's changes from the L1/L2
carrier, its level per arc from a model (synthetic oracles)."""

import math

import numpy as np
import pytest

from gnss_common.constants import GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ, SPEED_OF_LIGHT_MPS
from gnss_common.corrections import GEOMETRY_FREE_SLIP_M, carrier_levelled_ionosphere_m

F1, F2 = GPS_L1_FREQUENCY_HZ, GPS_L2_FREQUENCY_HZ
GAMMA_MINUS_1 = (F1 / F2) ** 2 - 1.0
LAMBDA1 = SPEED_OF_LIGHT_MPS / F1


def _sky(n: int = 120, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(epochs, true L1 delay m, model delay m): a morning rise the model gets wrong in slope and level."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    truth = 4.0 + 3.0 * np.sin(k / n * 2.5) + 0.02 * rng.standard_normal(n).cumsum() * 0.1
    model = 3.0 + 1.0 * (k / n)  # the broadcast model: too flat, too low
    return k, truth, model


def test_changes_follow_the_carrier_and_the_level_is_the_model_mean():
    k, truth, model = _sky()
    gf = GAMMA_MINUS_1 * truth + 12.34  # phase L1 - L2 in m: (gamma - 1) I + ambiguity
    got = carrier_levelled_ionosphere_m(k, gf, model, F1, F2)
    # the within-arc variation is the truth's, to rounding; the arc's mean is the model's
    np.testing.assert_allclose(got - got.mean(), truth - truth.mean(), atol=1e-9)
    assert got.mean() == pytest.approx(model.mean(), abs=1e-9)
    # so its error is a constant: smaller than the model's varying error
    assert np.std(got - truth) < 1e-9 < np.std(model - truth)


def test_a_cycle_slip_and_a_gap_start_new_arcs():
    k, truth, model = _sky()
    gf = GAMMA_MINUS_1 * truth + 5.0
    gf[40:] += LAMBDA1  # one L1 cycle: 0.19 m, more than the slip threshold
    assert LAMBDA1 > GEOMETRY_FREE_SLIP_M
    keep = np.ones(k.size, dtype=bool)
    keep[80:85] = False  # a tracking gap of 5 epochs
    got = carrier_levelled_ionosphere_m(k[keep], gf[keep], model[keep], F1, F2)
    arcs = (slice(0, 40), slice(40, 80), slice(80, None))
    for sel in arcs:  # each arc levelled on its own: its mean is the model's mean over it
        assert got[sel].mean() == pytest.approx(model[keep][sel].mean(), abs=1e-9)
        np.testing.assert_allclose(np.diff(got[sel]), np.diff(truth[keep][sel]), atol=1e-9)


def test_missing_phase_or_model_gives_nan_and_model_gaps_do_not_split():
    k, truth, model = _sky(20)
    gf = GAMMA_MINUS_1 * truth
    gf[5] = math.nan  # one epoch without L2: no value there, and a new arc after it
    model_part = model.copy()
    model_part[12:] = math.nan  # the model missing for part of an arc: the rest levels it
    got = carrier_levelled_ionosphere_m(k, gf, model_part, F1, F2)
    assert math.isnan(got[5]) and np.all(np.isfinite(np.delete(got, 5)))
    assert got[6:12].mean() == pytest.approx(model[6:12].mean(), abs=1e-9)
    none = carrier_levelled_ionosphere_m(k, gf, np.full(k.size, math.nan), F1, F2)
    assert np.all(np.isnan(none))


@pytest.mark.parametrize("bad", [
    dict(epoch_index=np.array([0, 2, 1])),
    dict(geometry_free_phase_m=np.zeros(2)),
    dict(f1_hz=F2, f2_hz=F1),
])
def test_bad_input_is_a_clear_error(bad):
    args = dict(epoch_index=np.arange(3), geometry_free_phase_m=np.zeros(3), model_delay_m=np.ones(3),
                f1_hz=F1, f2_hz=F2)
    args.update(bad)
    with pytest.raises(ValueError):
        carrier_levelled_ionosphere_m(**args)

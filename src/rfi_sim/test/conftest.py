"""Checks shared by the rfi_sim tests (fixtures: the tests run with ``--import-mode=importlib``, so a helper
module beside them cannot be imported)."""

from collections.abc import Callable, Sequence

import numpy as np
import pytest


def _check_split_invariant(make_simulator: Callable, sizes: Sequence[int]) -> list:
    """Blocks of ``sizes`` samples from one simulator hold the samples and truth of one block of their sum from
    another simulator made the same way (same seed); returns the blocks."""
    whole = make_simulator().generate(sum(sizes))
    sim = make_simulator()
    parts = [sim.generate(m) for m in sizes]
    np.testing.assert_array_equal(np.concatenate([p.counts for p in parts]), whole.counts)
    np.testing.assert_array_equal(np.concatenate([p.truth.frequency_hz for p in parts], axis=1),
                                  whole.truth.frequency_hz)
    np.testing.assert_array_equal(np.concatenate([p.truth.sweep_start_indices[0] for p in parts]),
                                  whole.truth.sweep_start_indices[0])
    return parts


@pytest.fixture
def check_split_invariant() -> Callable:
    """:func:`_check_split_invariant`: ``check_split_invariant(lambda: IfSimulator(...), sizes)``."""
    return _check_split_invariant

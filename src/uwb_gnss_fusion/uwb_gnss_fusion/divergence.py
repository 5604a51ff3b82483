"""Divergence detection of the fusion filter: when its state can no longer be trusted.

Pure core (no rclpy); beyond Cao et al. Three rules:

* the position covariance has grown past ``max_position_std_m`` or the state is not finite
  (:func:`position_lost`);
* GNSS: at least half of the pseudoranges of a well-observed epoch (>= 4) are gated or screened
  out, for ``divergence_gnss_epochs`` epochs in a row (:func:`gnss_epoch_inconsistent`);
* UWB: at least ``divergence_uwb_gated_fraction`` of the last ``divergence_uwb_ranges`` ranges
  (all anchors together) were gated out (:class:`GatedWindow`). A single anchor that still agrees
  (the state sits on its range sphere) does not mask it.

What the filter does then (re-solve the clock, or re-initialise) is its policy
(:mod:`.initialisation`, :meth:`.fusion_filter.FusionFilter`).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np


def position_lost(p: np.ndarray, nominal: np.ndarray, max_position_std_m: float) -> bool:
    """True when a position variance exceeds ``max_position_std_m^2`` or the state is not finite.

    Args:
        p: error covariance, (8, 8) (read only).
        nominal: nominal state, (8,).
        max_position_std_m: the largest position 1-sigma per axis, m.
    """
    worst = max(p[0, 0], p[1, 1], p[2, 2])
    return not (worst <= max_position_std_m**2 and math.isfinite(float(nominal.sum())))


def gnss_epoch_inconsistent(n_applied: int, n_screened: int, n_gated: int) -> bool:
    """Whether an epoch counts towards GNSS divergence: at least four pseudoranges, and at least half
    of them gated (``n_gated``) or screened out (``n_screened``) of ``n_applied + n_screened``."""
    total = n_applied + n_screened
    return total >= 4 and (n_gated + n_screened) * 2 >= total


class GatedWindow:
    """The outcome (gated or not) of the last ``length`` UWB ranges, with a running count.

    Args:
        length: window length (``divergence_uwb_ranges``), >= 1.
    """

    def __init__(self, length: int) -> None:
        self._window: deque[int] = deque(maxlen=length)
        self.gated = 0

    def __len__(self) -> int:
        return len(self._window)

    @property
    def length(self) -> int:
        """The window length."""
        return self._window.maxlen or 1

    def push(self, accepted: bool) -> None:
        """Record one range's outcome."""
        window = self._window
        if len(window) == window.maxlen:
            self.gated -= window[0]
        window.append(0 if accepted else 1)
        self.gated += 0 if accepted else 1

    def diverged(self, gated_fraction: float) -> bool:
        """The window is full and at least ``gated_fraction`` of it was gated."""
        return len(self._window) == self.length and self.gated >= gated_fraction * self.length

    def agrees(self, gated_fraction: float) -> bool:
        """The window is at least half full and less than ``gated_fraction`` of it was gated."""
        return 2 * len(self._window) >= self.length and self.gated < gated_fraction * len(self._window)


def clock_reset_variances(p: np.ndarray, clock_bias_std_m: float, clock_drift_std_mps: float) -> np.ndarray:
    """Variances of ``[c dt, c ddt]`` when the clock is re-solved with the position kept, m^2, (m/s)^2.

    The bias variance adds the position variance (trace of the position block of ``p``), since the
    clock is solved from ranges computed at that uncertain position.
    """
    return np.array([clock_bias_std_m**2 + float(p[0:3, 0:3].trace()), clock_drift_std_mps**2])

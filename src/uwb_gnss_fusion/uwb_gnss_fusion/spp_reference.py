"""SPP solutions on demand, as the fusion filter's independent reference for re-initialisation.

Pure core (no rclpy). The node keeps the recent GNSS epochs here (:meth:`SppReferenceCache.add`) and
gives :meth:`SppReferenceCache.reference` to :class:`.fusion_filter.FusionFilter` as its
``reference_provider``: the filter asks only when it diverges, so SPP (Cao et al., sec. IV, the
GNSS-only baseline, eq. 5-6) solves only the epochs needed, each at most once, instead of every epoch.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from gnss_common.observations import GnssEpoch
from gnss_common.spp import SinglePointPositioner, SppResult

NS_PER_S = 1_000_000_000

Reference = tuple[int, np.ndarray, float, float]
"""(stamp ns, ECEF position m (3,), position 1-sigma m, clock bias m): a ``reference_provider`` answer."""


class SppReferenceCache:
    """The GNSS epochs of the last ``max_age_s``, each solved by SPP when first asked for.

    Args:
        positioner: the SPP solver (its last valid fix seeds the next solution).
        max_age_s: epochs older than this before the newest one (or the asked stamp) are not used, s
            (the filter's ``reference_max_age_s``).
        on_solved: called with True / False after each solution, valid or not (the node counts them).
    """

    def __init__(
        self,
        positioner: SinglePointPositioner,
        max_age_s: float,
        on_solved: Callable[[bool], None] | None = None,
    ) -> None:
        self.positioner = positioner
        self._max_age_ns = max_age_s * NS_PER_S
        self._on_solved = on_solved
        self._epochs: deque[list] = deque()  # [epoch, solved result or None], oldest first

    def __len__(self) -> int:
        return len(self._epochs)

    def add(self, epoch: GnssEpoch) -> None:
        """Keep ``epoch`` (stamps non-decreasing) and drop those older than ``max_age_s`` before it."""
        epochs = self._epochs
        epochs.append([epoch, None])
        oldest = epoch.stamp_ns - self._max_age_ns
        while epochs[0][0].stamp_ns < oldest:
            epochs.popleft()

    def clear(self) -> None:
        """Forget the epochs and the positioner's state (a restart)."""
        self.positioner.reset()
        self._epochs.clear()

    def reference(self, stamp_ns: int) -> Reference | None:
        """The newest valid SPP fix of the kept epochs stamped at most ``stamp_ns`` and at least
        ``stamp_ns - max_age_s`` (each epoch solved once), or None.

        The 1-sigma is the square root of the largest ECEF position variance of the fix.
        """
        oldest = stamp_ns - self._max_age_ns
        for entry in reversed(self._epochs):
            epoch, res = entry
            if epoch.stamp_ns > stamp_ns:
                continue
            if epoch.stamp_ns < oldest:
                break
            if res is None:
                res = entry[1] = self._solve(epoch)
            if res.valid:
                std_m = math.sqrt(float(np.max(np.diag(res.covariance)[:3])))
                return epoch.stamp_ns, res.position_ecef_m, std_m, res.clock_bias_m
        return None

    def _solve(self, epoch: GnssEpoch) -> SppResult:
        res = self.positioner.process(epoch)
        if self._on_solved is not None:
            self._on_solved(res.valid)
        return res

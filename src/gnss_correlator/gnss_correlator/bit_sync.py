"""GPS L1 C/A bit synchronisation: where the 20-ms data bits start, from the signs of the 1-ms prompts (pure: no rclpy).

A navigation data bit lasts 20 C/A code periods and starts on a code epoch, so a change of the prompt's sign
(the bit, once the Costas loop holds the carrier within +-pi/2) can only happen between two periods ``k - 1`` and
``k`` with ``k`` on one residue modulo 20. The histogram method (Kaplan & Hegarty, "Understanding GPS", 2nd ed.,
sec. 5.13; Parkinson & Spilker vol. I ch. 8) counts the sign changes per residue ``k mod 20`` (``k`` the period's
count since the channel started: :attr:`gnss_correlator.tracking.TrackedPeriods.period`).

Counted: a change between two consecutive full periods whose prompts both have ``|I| >= |Q|`` (the carrier phase
error within +-45 deg, where the sign is the bit's rather than the noise's); a period with ``|I| < |Q|`` breaks
the chain.

**Decision rule**: the channel is bit-synchronised on residue ``r`` when its bin holds ``n_1 >= min_transitions``
changes and at least ``min_ratio`` times the second-fullest bin ``n_2`` (``n_1 >= min_ratio n_2``); once taken the
decision is kept for the channel's life (a half-cycle slip inverts the bits but does not move their edges).
Rationale, defaults 6 and 4:

* no bit structure (an unlocked channel: sign changes spread evenly over the 20 residues): the chance that 6 or
  more changes land in one bin with at most a quarter of that in any other is below 1e-5 (all 6 in one bin:
  20 / 20^6 = 3e-7; 7 with one elsewhere: 20 x 19 x 7 / 20^7 = 2e-6; more changes only spread it further);
* a locked channel: the true edge collects half of the bits (about 25 changes per second); a sign error of the
  1-ms prompt (probability Q(sqrt(2 T C/N0)): 2e-4 at 38 dB-Hz, 6e-3 at 35) puts two changes into other bins,
  spread over 19 of them, so the ratio holds down to ~33 dB-Hz; at 45 dB-Hz six changes take ~12 bits (0.25 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gnss_correlator.tracked_periods import TrackedPeriods

PERIODS_PER_BIT = 20
"""C/A code periods per navigation data bit (IS-GPS-200: 50 bit/s, 1 ms code)."""


@dataclass(frozen=True)
class BitSyncConfig:
    """Decision rule of the histogram (module docstring).

    Attributes:
        min_transitions: changes the fullest bin must hold, >= 3.
        min_ratio: how many times the second-fullest bin the fullest must hold, >= 1.
    """

    min_transitions: int = 6
    min_ratio: float = 4.0

    def __post_init__(self) -> None:
        if self.min_transitions < 3:
            raise ValueError(f'min_transitions must be >= 3, got {self.min_transitions}')
        if not self.min_ratio >= 1.0:
            raise ValueError(f'min_ratio must be >= 1, got {self.min_ratio}')


class BitSync:
    """Histograms of prompt sign changes per PRN, fed the periods of every block in order.

    Example:
        >>> import numpy as np
        >>> from gnss_correlator.tracked_periods import TrackedPeriods
        >>> k = np.arange(1, 201)
        >>> bits = np.where((k - 3) // 20 % 2 == 0, 1.0, -1.0)  # a bit edge at every k = 3 mod 20, alternating
        >>> nan = np.full(k.size, np.nan)
        >>> p = TrackedPeriods(prn=np.full(k.size, 5), end_index=k * 1.0, start_index=k - 1.0, early=bits + 0j,
        ...     prompt=bits + 0j, late=bits + 0j, doppler_hz=nan, nco_phase_rad=nan, code_rate_hz=nan,
        ...     pll_error_rad=nan, fll_error_hz=nan, dll_error_chips=nan, n_samples=k * 0, period=k,
        ...     noise_reference=nan + 0j, cn0_dbhz=nan, cn0_m2m4_dbhz=nan, lock_indicator=nan, noise_power=nan,
        ...     phase_error_std_rad=nan, half_cycle_wraps=nan, locked=k > 0)
        >>> s = BitSync()
        >>> s.update(p)
        >>> s.edge(5)
        3
    """

    def __init__(self, config: BitSyncConfig = BitSyncConfig()) -> None:
        self.config = config
        self._hist: dict[int, np.ndarray] = {}
        self._last: dict[int, tuple[int, float]] = {}  # PRN -> (period, sign of I) of its last usable period
        self._edge: dict[int, int] = {}
        self._decided_at: dict[int, int] = {}

    def update(self, periods: TrackedPeriods) -> None:
        """Count the sign changes of one block's periods (rows of several PRNs, each PRN's in order)."""
        for prn in np.unique(periods.prn):
            o = periods.of(int(prn))
            key = int(prn)
            hist = self._hist.setdefault(key, np.zeros(PERIODS_PER_BIT, dtype=np.int64))
            last = self._last.get(key)
            for k, z in zip(o.period.tolist(), o.prompt.tolist(), strict=True):
                if k < 1 or not abs(z.real) >= abs(z.imag):  # the partial first period, or the sign in doubt
                    last = None
                    continue
                sign = 1.0 if z.real >= 0 else -1.0
                if last is not None and last[0] == k - 1 and last[1] != sign:
                    hist[k % PERIODS_PER_BIT] += 1
                    if key not in self._edge:
                        self._decide(key, hist, k)
                last = (k, sign)
            if last is None:
                self._last.pop(key, None)
            else:
                self._last[key] = last

    def _decide(self, prn: int, hist: np.ndarray, k: int) -> None:
        order = np.argsort(hist)
        n1, n2 = int(hist[order[-1]]), int(hist[order[-2]])
        if n1 >= self.config.min_transitions and n1 >= self.config.min_ratio * n2:
            self._edge[prn] = int(order[-1])
            self._decided_at[prn] = k

    def edge(self, prn: int) -> int | None:
        """The residue r (0..19) such that a bit starts with every period k = r mod 20 of ``prn``; None until
        the decision."""
        return self._edge.get(int(prn))

    def decided_at(self, prn: int) -> int | None:
        """The period count at which ``prn`` was synchronised; None until then."""
        return self._decided_at.get(int(prn))

    def histogram(self, prn: int) -> np.ndarray:
        """Sign changes counted per residue of ``prn``, shape (20,) (zeros for an unknown PRN)."""
        return self._hist.get(int(prn), np.zeros(PERIODS_PER_BIT, dtype=np.int64)).copy()

    def forget(self, prn: int) -> None:
        """Drop a channel's histogram and decision (its channel stopped or restarted)."""
        for d in (self._hist, self._last, self._edge, self._decided_at):
            d.pop(int(prn), None)

    def reset(self) -> None:
        """Forget every channel."""
        for d in (self._hist, self._last, self._edge, self._decided_at):
            d.clear()

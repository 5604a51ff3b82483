"""IMM carrier-phase tracking with data-bit modes and h-coefficient clock models, beside a Costas PLL
baseline (Zhao, Khanafseh, Pervan).
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

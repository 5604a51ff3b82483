"""Tightly-coupled GNSS/UWB cubature Kalman filter on asynchronous pseudorange, Doppler and UWB ranges,
robust to jamming (Cao et al.).
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

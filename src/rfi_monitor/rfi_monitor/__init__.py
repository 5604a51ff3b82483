"""Detect, classify and track GNSS jammers (CW, chirp, wideband) from IF sample blocks with an adaptive
fading Kalman filter (Kang et al.).
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

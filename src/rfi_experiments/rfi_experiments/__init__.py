"""Jamming experiments for the suite: scenario simulation, bag play and record, in-process bag replay,
evaluation and reports.
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

"""GNSS correlators from front-end IF samples (issue 29): GPS L1 C/A acquisition (acquisition.py),
tracking with a DLL and an FLL-assisted PLL on 1-ms correlators (tracking.py), and the node that
publishes /gnss/correlators for imm_carrier.
"""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

"""Simulators of the suite's inputs: IF samples with jammers, GNSS/UWB measurements, correlator outputs."""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

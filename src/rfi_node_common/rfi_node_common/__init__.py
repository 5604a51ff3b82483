"""ROS plumbing shared by the nodes of the suite (the algorithm cores never import it)."""

from gnss_common import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

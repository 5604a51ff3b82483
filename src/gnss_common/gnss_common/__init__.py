"""Pure-Python GNSS foundations shared by the suite's nodes (never imports rclpy)."""

from . import numba_cache as _numba_cache  # noqa: F401  (first: kernels cached on the suite's sources)

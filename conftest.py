"""Test-session settings shared by every test directory.

DDS traffic of the tests stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and on
a domain of its own, so concurrent test runs or a running robot do not cross-talk with it.
Fast DDS publishes synchronously (from the publishing thread), which cuts the latency of each
hop about threefold here and so the time of the tests that replay bags over DDS.
"""

import os
import sys

import pytest

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
os.environ.setdefault('RMW_FASTRTPS_PUBLICATION_MODE', 'SYNCHRONOUS')

WARM_UPS = '''
from gnss_common import multi_gnss_rows, multilateration
multi_gnss_rows.warm_up(); multilateration.warm_up()
from gnss_integrity import kernels, uwb_range_rate
kernels.warm_up(); uwb_range_rate.warm_up()
from uwb_gnss_fusion import ckf_kernels, fusion_output, local_frame
ckf_kernels.warm_up(); local_frame.warm_up(); fusion_output.warm_up()
from rfi_monitor.monitor import RfiMonitorParams
from rfi_monitor.warm_up import warm_up
warm_up(RfiMonitorParams())
'''
"""The warm-ups the nodes run before they subscribe (as benchmarks/numba_cache_cost.py lists them)."""


@pytest.fixture(scope='session')
def warm_kernels():
    """The suite's numba kernels compiled into their on-disk cache once, before any timed wait of the session.

    After a source edit and ``make setup`` every kernel compiles again on its next use (docs/numba_cache.md:
    about 2 minutes of CPU in all), and a test that starts node processes paid for it inside waits it does not
    control (``run --timeout``, launch's start-up): beside a CPU hog they ran out. Tests that start the nodes as
    processes use this fixture, so that the compile is paid here, in one process, bounded only by its progress
    (it spends CPU all along), and their nodes load the kernels from the cache. On a warm cache it costs the
    loading (about 7 s). Tests of the kernels themselves do not use it."""
    from rfi_node_common import testing

    # limit_s: about 2 minutes of CPU on a cold cache took over 10 minutes of wall time beside 2 hogs at load 15;
    # the stall bound (no CPU spent for testing.STALL_S) is what catches a hang
    done = testing.run_process([sys.executable, '-c', WARM_UPS], 'the warm-up of the numba kernels', text=True,
                               limit_s=3600.0)
    assert done.returncode == 0, done.stderr[-3000:]

"""Test-session settings shared by every test directory.

DDS traffic of the tests stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and on
a domain of its own, so concurrent test runs or a running robot do not cross-talk with it.
Fast DDS publishes synchronously (from the publishing thread), which cuts the latency of each
hop about threefold here and so the time of the tests that replay bags over DDS.
"""

import os

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
os.environ.setdefault('RMW_FASTRTPS_PUBLICATION_MODE', 'SYNCHRONOUS')

"""Test-session settings shared by every test directory.

DDS traffic of the tests stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and on
a domain of its own, so concurrent test runs or a running robot do not cross-talk with it.
"""

import os

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))

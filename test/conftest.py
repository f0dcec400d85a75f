"""Test isolation: every test run gets its own ROS_DOMAIN_ID and localhost-only discovery."""
import os
import random

import pytest

if not os.environ.get("KITE_RTO_TEST_DOMAIN"):            # unset or empty
    # One domain per pytest process, chosen from the pid so parallel runs on one machine do not hear each other.
    os.environ["KITE_RTO_TEST_DOMAIN"] = str(random.Random(os.getpid()).randint(1, 100))
os.environ["ROS_DOMAIN_ID"] = os.environ["KITE_RTO_TEST_DOMAIN"]
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long end-to-end or fault tests (run with -m slow)")
    config.addinivalue_line("markers", "ros: starts ROS 2 nodes over DDS")
    config.addinivalue_line("markers", "faults: fault-injection suite (scripts/faults.sh), issue 7")


@pytest.fixture
def ros_env():
    """Environment for node subprocesses: the test run's domain, localhost discovery, unbuffered output."""
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    return env

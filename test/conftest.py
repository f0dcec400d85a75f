"""Test isolation (every test run gets its own ROS_DOMAIN_ID and localhost-only discovery), the shared helpers of
``test/support/`` on the import path, and the quick tier (``-m quick``) marked by folder."""
import os
import random
import sys
from pathlib import Path

import pytest

TEST_DIR = Path(__file__).resolve().parent
sys.path.insert(0, str(TEST_DIR / "support"))       # rosutil, faultgraph, ...: `from rosutil import Probe` anywhere

QUICK_FOLDERS = ("kite", "flight", "gma", "rto", "runtime", "campaign")
"""The pure core's folders: their tests start no ROS process and form the quick tier, except :data:`NOT_QUICK`."""
NOT_QUICK = {
    "test_kite_rto.py", "test_lifecycle_run.py", "test_baselines.py",      # the kite's RTO flown by the pure runner
    "test_plan_lockstep.py",                                                  # ... and by the lockstep graph
    "test_run_description.py::test_the_plants_configuration_is_stored_with_the_description",    # ... and by the
    "test_run_description.py::test_a_failed_write_of_the_description_keeps_it_and_the_run_goes_on",  # storage
    "test_run_description.py::test_a_bad_configuration_is_rejected_and_the_run_goes_on",        # tests' flight
    "test_kite_ocp.py",                                                       # the lap OCP solved with IPOPT
    "test_campaign_executor.py",                                              # Dask scheduler and worker processes
    "test_gma_noise.py", "test_gma_noise_filter.py", "test_gma_bound_hold.py",   # many noisy GMA runs
    "test_gma_docs.py",                                                       # the GMA guide's examples, run
    "test_gma_safety.py::test_default_steps_violate_the_plant_constraint",
    "test_controller.py::test_smooth_setpoint_change",
    "test_wind_field.py::test_box_mean_and_intensity",
    "test_wind_turns.py::test_a_30_degree_turn_left_at_the_old_azimuth_costs_about_cos_squared",   # long flights
    "test_wind_follow.py::test_after_a_30_degree_turn_the_path_follows_and_keeps_the_energy",      # in a turning wind
}
"""Pure tests left out of the quick tier (a file name, or file name::test name without parameters): each file or
test takes seconds, the tier's budget is a minute on 2 cores (docs/testing.md)."""

if not os.environ.get("KITE_RTO_TEST_DOMAIN"):            # unset or empty
    # One domain per pytest process, chosen from the pid so parallel runs on one machine do not hear each other.
    os.environ["KITE_RTO_TEST_DOMAIN"] = str(random.Random(os.getpid()).randint(1, 100))
os.environ["ROS_DOMAIN_ID"] = os.environ["KITE_RTO_TEST_DOMAIN"]
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long end-to-end or fault tests (run with -m slow)")
    config.addinivalue_line("markers", "ros: starts ROS 2 nodes over DDS")
    config.addinivalue_line("markers", "faults: fault-injection suite (scripts/faults.sh)")
    config.addinivalue_line("markers", "quick: the pure core's fast tests (-m quick: under a minute; set by folder "
                                       "in test/conftest.py)")


def _quick(item) -> bool:
    path = Path(str(item.fspath)).resolve()
    try:
        folder = path.relative_to(TEST_DIR).parts[0]
    except ValueError:
        return False
    name = getattr(item, "originalname", item.name)
    return (folder in QUICK_FOLDERS and path.name not in NOT_QUICK and f"{path.name}::{name}" not in NOT_QUICK
            and item.get_closest_marker("slow") is None and item.get_closest_marker("ros") is None)


@pytest.hookimpl(tryfirst=True)             # before -m deselects
def pytest_collection_modifyitems(config, items):
    for item in items:
        if _quick(item):
            item.add_marker(pytest.mark.quick)


@pytest.fixture
def ros_env():
    """Environment for node subprocesses: the test run's domain, localhost discovery, unbuffered output."""
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    return env

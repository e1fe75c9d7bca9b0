import os
import shutil
import signal
import sys
import tempfile
from pathlib import Path

import pytest


# A suite started as a shell script's background job (`scripts/test.sh &`) inherits SIGINT ignored,
# and every process a test starts would inherit it too: they start as from a terminal instead
# (test_manual_bench and test_rig_faults start characterise with SIGINT ignored on purpose).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Parallel test runs must not see each other's nodes: discovery and data on loopback only, and this
# run's in-process nodes on a domain leased for the whole session (node processes lease their own:
# domains.py). UDP only, by the shipped Fast DDS profile: with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# rmw_fastrtps always adds its shared-memory transport, and a port segment a killed node left in
# /dev/shm made the next participant on that port spin for ever in rclpy.create_node (full runs hung
# or nodes never came up; several tests kill nodes on purpose). SYSTEM_DEFAULT leaves the transports
# to the profile, which keeps discovery on 127.0.0.1 as LOCALHOST does.
from softcath_ros.resources import config_dir  # noqa: E402

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SYSTEM_DEFAULT"
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(config_dir() / "dds" / "loopback_udp.xml")
from softcath_ros.graph import lease_domain  # noqa: E402

_SESSION_DOMAIN = lease_domain()
os.environ["ROS_DOMAIN_ID"] = str(_SESSION_DOMAIN.domain)


@pytest.fixture(autouse=True)
def _release_private_domains():
    """Leases a test took (domains.private_domain) end with the test."""
    from domains import LEASES

    taken = len(LEASES)
    yield
    while len(LEASES) > taken:
        LEASES.pop().release()

# Every run starts from an empty cache of its own (set here, at import, so the subprocesses the
# tests start inherit it), so no test passes on results an earlier run left behind.
RUN_CACHE = Path(tempfile.mkdtemp(prefix="softcath-test-cache-"))
os.environ["SOFTCATH_CACHE"] = str(RUN_CACHE)


def pytest_unconfigure(config):
    shutil.rmtree(RUN_CACHE, ignore_errors=True)


@pytest.fixture
def implemented_design():
    from softcath_ros.core.design import load_design

    return load_design("implemented_5mm")


@pytest.fixture
def design_dict():
    """The implemented design as a mutable mapping, for validation tests."""
    from softcath_ros.core.yaml_io import load_yaml
    from softcath_ros.resources import find

    return load_yaml(find("design", "implemented_5mm").read_text())


def pytest_report_header(config):
    return (f"python {sys.version.split()[0]}, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', 'unset')}, "
            f"cache {RUN_CACHE} (removed at the end)")


@pytest.fixture
def start_node():
    """model_node processes on private domains with a client in this process (test_model_node.Running)."""
    from test_model_node import Running

    running = []

    def start(*ros_args, env_extra=None):
        r = Running(*ros_args, env_extra=env_extra)
        running.append(r)
        return r

    yield start
    for r in running:
        r.close()

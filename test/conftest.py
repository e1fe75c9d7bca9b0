import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DESIGNS = REPO / "softcath_ros" / "config" / "designs"

# Parallel test runs must not see each other's nodes: loopback only, and this run's in-process
# nodes on a domain leased for the whole session (node processes lease their own: domains.py).
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
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


@pytest.fixture
def implemented_design():
    from softcath_ros.core.design import load_design

    return load_design(DESIGNS / "implemented_5mm.yaml")


@pytest.fixture
def design_dict():
    """The implemented design as a mutable mapping, for validation tests."""
    from softcath_ros.core.yaml_io import load_yaml

    return load_yaml((DESIGNS / "implemented_5mm.yaml").read_text())


def pytest_report_header(config):
    return f"python {sys.version.split()[0]}, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', 'unset')}"

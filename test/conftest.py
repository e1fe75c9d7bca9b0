import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DESIGNS = REPO / "softcath_ros" / "config" / "designs"

# Parallel test runs must not see each other's nodes (see scripts/test.sh).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


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

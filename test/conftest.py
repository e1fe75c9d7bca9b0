import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DESIGNS = REPO / "softcath_ros" / "config" / "designs"

# Parallel test runs must not see each other's nodes (see scripts/test.sh).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

# Every run starts from an empty cache of its own (set here, at import, so the subprocesses the
# tests start inherit it), so no test passes on results an earlier run left behind.
RUN_CACHE = Path(tempfile.mkdtemp(prefix="softcath-test-cache-"))
os.environ["SOFTCATH_CACHE"] = str(RUN_CACHE)


def pytest_unconfigure(config):
    shutil.rmtree(RUN_CACHE, ignore_errors=True)


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
    return (f"python {sys.version.split()[0]}, ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', 'unset')}, "
            f"cache {RUN_CACHE} (removed at the end)")

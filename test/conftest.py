import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

import pytest


# A suite started as a shell script's background job (`scripts/test.sh &`) inherits SIGINT ignored,
# and every process a test starts would inherit it too: they start as from a terminal instead
# (test_manual_bench and test_rig_faults start characterise with SIGINT ignored on purpose).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Parallel test runs must not see each other's nodes: loopback only, and this run's in-process
# nodes on a domain leased for the whole session (node processes lease their own: domains.py).
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
from softcath_ros.graph import lease_domain  # noqa: E402

_SESSION_DOMAIN = lease_domain()
os.environ["ROS_DOMAIN_ID"] = str(_SESSION_DOMAIN.domain)


def _clean_dds_shared_memory() -> None:
    """Remove Fast DDS shared-memory files whose owners are gone. With LOCALHOST discovery
    rmw_fastrtps always adds the shared-memory transport, and a participant opening a port segment
    that a killed process left behind can spin forever (a CI run hung so in rclpy.create_node);
    several tests kill nodes on purpose. (The wheels' ``fastdds shm clean`` was run here as well:
    it recognises none of this Fast DDS's files, so it cost a process per test and cleaned nothing.)"""
    _remove_unused_dds_shared_memory()


def _remove_unused_dds_shared_memory() -> None:
    """Unlink the Fast DDS shared-memory files no live process has open or mapped. ``fastdds shm
    clean`` of the wheels does not recognise this Fast DDS's files ("0 ports in use" beside hundreds
    of them), and a port segment a killed node left half made makes the next participant on that port
    spin for ever in rclpy.create_node (seen in full runs)."""
    shm = Path("/dev/shm")
    names = {p.name for p in shm.glob("*fastdds*")} if shm.is_dir() else set()
    if not names:
        return
    used = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            used.update(line.split("/dev/shm/", 1)[1].strip() for line in (proc / "maps").read_text().splitlines()
                        if "/dev/shm/" in line)
            for fd in (proc / "fd").iterdir():
                target = os.readlink(fd)
                if target.startswith("/dev/shm/"):
                    used.add(target[len("/dev/shm/"):])
        except OSError:
            continue   # the process ended meanwhile, or is not ours to read
    # a file made in the last minute may belong to a node starting now that has not mapped it yet
    # (the other test worker's graph): only older ones are left-overs
    recent = time.time() - 60.0
    for name in names - {u.replace(" (deleted)", "") for u in used}:
        try:
            if (shm / name).stat().st_mtime < recent:
                (shm / name).unlink()
        except OSError:
            pass


def _dds_shared_memory() -> set:
    shm = Path("/dev/shm")
    return {p.name for p in shm.glob("*fastdds*")} if shm.is_dir() else set()


_clean_dds_shared_memory()
_SHM_AFTER_CLEAN = [_dds_shared_memory()]


def _clean_if_changed() -> None:
    if _dds_shared_memory() != _SHM_AFTER_CLEAN[0]:
        _clean_dds_shared_memory()
        _SHM_AFTER_CLEAN[0] = _dds_shared_memory()


@pytest.fixture(autouse=True)
def _release_private_domains():
    """Leases a test took (domains.private_domain) end with the test; no test starts on, or
    leaves behind, a dead process's DDS shared memory (cleaned before and after each test when
    /dev/shm changed: a process killed at a test's end may still hold its segments for a moment)."""
    from domains import LEASES

    _clean_if_changed()
    taken = len(LEASES)
    yield
    while len(LEASES) > taken:
        LEASES.pop().release()
    _clean_if_changed()

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

"""softcath_ros.graph: readiness is an event in the process's output, and a NodeGraph stops its
nodes cleanly and gives its domain back."""
import subprocess
import sys

import pytest

from softcath_ros.core.errors import SoftcathError
from softcath_ros.graph import READY_MARK, NodeGraph, lease_domain, wait_ready


def _script(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def test_wait_ready_returns_the_output_up_to_the_mark_or_says_why_not():
    up = _script(f"import time; print('loading', flush=True); print('{READY_MARK} now', flush=True); time.sleep(60)")
    try:
        assert wait_ready(up, timeout_s=60).splitlines() == ["loading", f"{READY_MARK} now"]
    finally:
        up.kill()
        up.wait()
    dead = _script("print('[ERROR] cannot start: no design'); raise SystemExit(2)")
    with pytest.raises(SoftcathError, match="exited with 2 before it was ready: .*no design"):
        wait_ready(dead, timeout_s=60)
    silent = _script("import time; time.sleep(60)")
    try:
        with pytest.raises(SoftcathError, match="not ready after 0.5 s"):
            wait_ready(silent, timeout_s=0.5)
    finally:
        silent.kill()
        silent.wait()


@pytest.mark.ros
def test_node_graph_waits_for_its_nodes_stops_them_cleanly_and_releases_its_domain():
    pytest.importorskip("rclpy")
    with NodeGraph() as graph:
        procs = [graph.start("model_node"), graph.start("sim_bench_node")]
        outputs = graph.wait_ready(*procs, timeout_s=120)
        assert all(READY_MARK in out for out in outputs)
        domain = graph.domain
        assert graph.stop() == {"model_node": 0, "sim_bench_node": 0}
    with lease_domain((domain, domain)) as again:  # released with the graph
        assert again.domain == domain

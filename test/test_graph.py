"""softcath_ros.graph: readiness is said over ROS (topics.READY), a step of a node's work is an
event in its output, and a NodeGraph stops its nodes cleanly and gives its domain back."""
import subprocess
import sys

import pytest

from softcath_ros import topics
from softcath_ros.core.errors import SoftcathError
from softcath_ros.graph import NodeGraph, last_leased, lease_domain, wait_output, wait_ready


def _script(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def test_wait_output_returns_the_output_up_to_the_mark_or_says_why_not():
    up = _script("import time; print('loading', flush=True); print('starting protocol now', flush=True); "
                 "time.sleep(60)")
    try:
        assert wait_output(up, "starting protocol", timeout_s=60).splitlines() == ["loading", "starting protocol now"]
    finally:
        up.kill()
        up.wait()
    dead = _script("print('[ERROR] cannot start: no design'); raise SystemExit(2)")
    with pytest.raises(SoftcathError, match="exited with 2 before 'starting protocol': .*no design"):
        wait_output(dead, "starting protocol", timeout_s=60)
    silent = _script("import time; time.sleep(60)")
    try:
        with pytest.raises(SoftcathError, match="no 'starting protocol' after 0.5 s"):
            wait_output(silent, "starting protocol", timeout_s=0.5)
    finally:
        silent.kill()
        silent.wait()


@pytest.mark.ros
def test_wait_ready_is_said_over_ros_not_in_the_output():
    """A process that prints what a node logs but never announces itself on /softcath/ready is not
    ready; one that ends first is named with its output's tail."""
    pytest.importorskip("rclpy")
    with lease_domain() as lease:
        talker = _script("import time; print('spinning on the events executor', flush=True); time.sleep(60)")
        try:
            with pytest.raises(SoftcathError, match="not ready after 1 s"):
                wait_ready(talker, lease.domain, timeout_s=1.0)
        finally:
            talker.kill()
            talker.wait()
        dead = subprocess.Popen([sys.executable, "-c", "print('[ERROR] cannot start: no design'); raise SystemExit(2)"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        with pytest.raises(SoftcathError, match="exited with 2 before it was ready: .*no design"):
            wait_ready(dead, lease.domain, timeout_s=60)


@pytest.mark.ros
def test_node_graph_waits_for_its_nodes_stops_them_cleanly_and_releases_its_domain():
    pytest.importorskip("rclpy")
    with NodeGraph() as graph:
        procs = [graph.start("model_node"), graph.start("sim_bench_node")]
        graph.wait_ready(*procs, timeout_s=120)
        said = {info["node"] for pid, info in graph.watch.ready.items() if pid in {p.pid for p in procs}}
        assert said == {"/" + topics.MODEL_NODE, "/" + topics.SIM_BENCH_NODE}
        domain = graph.domain
        assert graph.stop() == {"model_node": 0, "sim_bench_node": 0}
    with lease_domain((domain, domain)) as again:  # released with the graph
        assert again.domain == domain


def test_the_least_recently_leased_domain_is_leased_first(tmp_path, monkeypatch):
    """A domain a graph used a moment ago may still carry its nodes' DDS traffic in shared memory:
    leases go to the domain leased longest ago (NodeGraph's as the tests' private ones). The lock
    files are this test's own: the other test worker leases from the shared ones meanwhile."""
    import os
    import time

    import softcath_ros.graph as graph

    monkeypatch.setattr(graph, "LOCK_DIR", tmp_path)
    lo, hi = 224, 229
    now = time.time()
    for i, d in enumerate(range(lo, hi + 1)):     # 226 leased longest ago, then 227, ...
        (tmp_path / f"{d}.lock").touch()
        os.utime(tmp_path / f"{d}.lock", (now, now - 100 if d == 226 else now - 50 + i))
    with lease_domain((lo, hi)) as first:
        assert first.domain == 226 and last_leased(226) > now - 10
    with lease_domain((lo, hi)) as second:
        assert second.domain != 226


@pytest.mark.ros
def test_a_ready_watch_keeps_every_nodes_announcement_that_arrives_between_two_polls():
    """Several nodes' latched READY samples arriving before the watch takes one are all counted
    (with a depth of 1 each replaced the one before, and a node of the lab graph never counted as
    ready under load)."""
    import json
    import time

    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    from domains import private_domain
    from softcath_ros.graph import ReadyWatch

    domain = private_domain()
    watch = ReadyWatch(domain)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    try:
        nodes = [rclpy.create_node(f"announcer_{i}", context=context) for i in range(5)]
        pubs = [n.create_publisher(String, topics.READY, qos) for n in nodes]
        end = time.monotonic() + 60
        while any(p.get_subscription_count() < 1 for p in pubs):
            assert time.monotonic() < end, "the watch was not discovered"
            time.sleep(0.05)
        for i, pub in enumerate(pubs):
            pub.publish(String(data=json.dumps({"node": f"/announcer_{i}", "pid": 1000 + i})))
        time.sleep(1.0)   # every sample arrives before the watch takes any
        end = time.monotonic() + 30
        while len(watch.ready) < 5 and time.monotonic() < end:
            watch.poll(0.1)
        assert sorted(watch.ready) == [1000, 1001, 1002, 1003, 1004]
    finally:
        watch.close()
        rclpy.try_shutdown(context=context)

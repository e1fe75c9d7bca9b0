"""characterise's supervision of its graph (bench/supervisor.py) on a fake clock: no ROS, no threads."""
import pytest

from softcath_ros.bench.supervisor import (BringUpBench, Fail, GraphState, GraphSupervisor, KillBench, Say,
                                           StartBench, StopBench)

DT = 0.1
HELPERS = ["sim_bench_node", "model_node"]


def _sup(**kw):
    opts = dict(timeout_s=170.0, helper_ready_s=60.0, bench_ready_s=60.0, child_grace={"model_node": 0.0},
                default_grace_s=1.5)
    opts.update(kw)
    return GraphSupervisor(list(HELPERS), **opts)


def _until(sup, t, obs, stop):
    """Update every DT from ``t`` with ``obs(t)`` = (ready, exited, has_output) until ``stop(cmds)``."""
    while True:
        t = round(t + DT, 9)
        cmds = sup.update(t, *obs(t))
        if stop(cmds):
            return cmds, t
        assert t < 1000


def test_bench_node_starts_once_every_helper_said_it_spins():
    sup = _sup()
    assert sup.update(0.0, set(), {}) == []
    assert sup.update(5.0, {"model_node"}, {}) == []
    assert sup.update(9.0, set(HELPERS), {}) == [StartBench(1)] and sup.state is GraphState.BENCH


def test_a_helper_not_spinning_by_helper_ready_s_is_said_and_bench_node_starts_anyway():
    sup = _sup()
    assert sup.update(0.0, set(), {}) == []
    cmds, t = _until(sup, 0.0, lambda t: ({"model_node"}, {}, False), lambda c: c)
    assert t == pytest.approx(60.0)
    assert isinstance(cmds[0], Say) and cmds[0].text.startswith("sim_bench_node is not spinning after 60 s")
    assert cmds[-1] == StartBench(1)


def test_a_helper_that_ends_before_it_is_ready_fails_the_run():
    sup = _sup()
    assert sup.update(1.0, set(), {"model_node": 2}) == [Fail("model_node", 2)] and sup.state is GraphState.DONE


def test_bench_node_is_brought_up_once_it_spins_and_only_once():
    sup = _sup()
    sup.update(0.0, set(HELPERS), {})
    assert sup.update(1.0, set(HELPERS), {}) == []
    ready = set(HELPERS) | {"bench_node"}
    assert sup.update(2.0, ready, {}) == [BringUpBench()]
    assert sup.update(3.0, ready, {}) == [] and sup.update(4.0, ready, {}) == []


def test_the_watchdog_stops_bench_node_after_timeout_and_kills_it_after_its_grace():
    sup = _sup(timeout_s=30.0)
    sup.update(0.0, set(HELPERS), {})
    ready = set(HELPERS) | {"bench_node"}
    assert sup.update(DT, ready, {}) == [BringUpBench()]
    cmds, t = _until(sup, DT, lambda t: (ready, {}, True), lambda c: c)
    # brought up: stopped through its lifecycle (deactivate: it vents; then shutdown)
    assert cmds == [StopBench(lifecycle=True)] and t == pytest.approx(30.0) and sup.timed_out
    cmds, t2 = _until(sup, t, lambda t: (ready, {}, True), lambda c: c)
    assert cmds == [KillBench()] and t2 - t == pytest.approx(15.0)
    assert sup.update(t2 + DT, ready, {"bench_node": -9}) == [] and sup.state is GraphState.DONE


def test_a_bench_node_hung_before_it_spins_is_started_once_more_and_only_once():
    sup = _sup(bench_ready_s=3.0)
    sup.update(0.0, set(HELPERS), {})
    cmds, t = _until(sup, 0.0, lambda t: (set(HELPERS), {}, False), lambda c: c)
    assert cmds == [StopBench(lifecycle=False)] and t == pytest.approx(3.0) and sup.stalled   # not up: SIGINT
    cmds = sup.update(t + DT, set(HELPERS), {"bench_node": 1})
    assert "not spinning after 3 s" in cmds[0].text and "started again" in cmds[0].text
    assert cmds[-1] == StartBench(2)
    # the second one is never judged hung: only the watchdog stops it
    cmds, t3 = _until(sup, t + DT, lambda t: (set(HELPERS), {}, False), lambda c: c)
    assert cmds == [StopBench()] and sup.timed_out and t3 - (t + DT) == pytest.approx(170.0)


def test_a_slow_bench_node_that_made_its_recording_is_waited_for():
    sup = _sup(bench_ready_s=3.0, timeout_s=20.0)
    sup.update(0.0, set(HELPERS), {})
    cmds, t = _until(sup, 0.0, lambda t: (set(HELPERS), {}, True), lambda c: c)
    assert t == pytest.approx(20.0) and sup.timed_out and not sup.stalled


@pytest.mark.parametrize("helper, grace", [("model_node", 0.0), ("sim_bench_node", 1.5)])
def test_a_helper_that_dies_mid_run_gets_bench_node_stopped_after_its_grace(helper, grace):
    sup = _sup()
    sup.update(0.0, set(HELPERS), {})
    ready = set(HELPERS) | {"bench_node"}
    assert sup.update(10.0, ready, {}) == [BringUpBench()]
    cmds, t = _until(sup, 10.0, lambda t: (ready, {helper: -9}, True), lambda c: c)
    assert cmds == [StopBench(lifecycle=True)] and t - (10.0 + DT) == pytest.approx(grace)
    assert sup.died == [f"{helper} exited (-9)"]
    # bench_node ends: no retry after a death
    assert sup.update(t + 1, ready, {helper: -9, "bench_node": 5}) == [] and sup.state is GraphState.DONE

"""characterise drives the rig's managed (lifecycle) nodes: configure, then activate, over the
lifecycle_msgs services (bench/bringup.py decides); the node that fails a check is named in one line."""
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("serial")

from hardware_emulators import SerialRegulatorEmulator  # noqa: E402
from lifecycle_listener import LifecycleListener  # noqa: E402
from softcath_ros import topics  # noqa: E402
from softcath_ros.bench.bringup import AskState, Bringup, Teardown, Transition  # noqa: E402
from softcath_ros.cli.managed import activate_managed  # noqa: E402
from softcath_ros.graph import NodeGraph, ReadyWatch, wait_ready  # noqa: E402

pytestmark = [pytest.mark.ros]
NODE = "/" + topics.REGULATOR_NODE


def test_bringup_configures_then_activates_and_names_the_node_that_fails():
    b = Bringup(["/a", "/b"], timeout_s=30.0)
    assert b.start(0.0) == [AskState("/a"), AskState("/b")]
    assert b.on_state("/a", "unconfigured") == [Transition("/a", "configure")]
    assert b.on_state("/b", "active") == [] and not b.done
    assert b.on_transition("/a", "configure", True) == [AskState("/a")]
    assert b.on_state("/a", "inactive") == [Transition("/a", "activate")]
    assert b.on_transition("/a", "activate", True) == [AskState("/a")]
    assert b.on_state("/a", "active") == [] and b.done and b.failure is None
    bad = Bringup(["/reg"], timeout_s=30.0)
    bad.start(0.0)
    bad.on_transition("/reg", "configure", False, "configure failed: cannot open serial port /x")
    assert bad.done and bad.failure == "/reg failed to configure: configure failed: cannot open serial port /x"
    silent = Bringup(["/gone"], timeout_s=30.0)
    silent.start(0.0)
    silent.update(29.9)
    assert not silent.done
    silent.update(30.0)
    assert silent.failure.startswith("/gone not active after 30 s")
    final = Bringup(["/f"])
    final.start(0.0)
    final.on_state("/f", "finalized")
    assert "cannot be activated" in final.failure


def test_teardown_deactivates_then_shuts_down_and_a_node_that_ended_is_done():
    t = Teardown(["/bench", "/idle"], timeout_s=5.0)
    assert t.start(0.0) == [AskState("/bench"), AskState("/idle")]
    assert t.on_state("/bench", "active") == [Transition("/bench", "deactivate")]
    assert t.on_state("/idle", "unconfigured") == [Transition("/idle", "shutdown")]
    assert t.on_transition("/bench", "deactivate", True) == [AskState("/bench")]
    assert t.on_state("/bench", "inactive") == [Transition("/bench", "shutdown")]
    t.on_ended("/bench")                 # bench_node ends by itself once deactivated (vented, finalised)
    assert not t.done
    assert t.on_transition("/idle", "shutdown", True) == [AskState("/idle")]
    t.on_state("/idle", "finalized")
    assert t.done and t.failure is None
    silent = Teardown(["/hung"], timeout_s=5.0)
    silent.start(0.0)
    silent.update(5.0)
    assert silent.failure.startswith("/hung not finalized after 5 s")
    up = Bringup(["/gone"])
    up.start(0.0)
    up.on_ended("/gone")
    assert up.failure == "/gone ended before it was activated"


def test_a_regulator_left_unconfigured_is_configured_and_activated():
    emu = SerialRegulatorEmulator(1).start()
    try:
        with NodeGraph() as graph:
            proc = graph.start("regulator_node", {"backend": "serial", "port": emu.port, "autostart": False})
            graph.wait_ready(proc)
            said = []
            # A watch of its own (as characterise's): once the node said it spins and is managed, its
            # services are waited for, however slow their discovery is (no fixed window).
            fresh = ReadyWatch(graph.domain)
            try:
                wait_ready(proc, watch=fresh)
                assert activate_managed(fresh, said.append, discovery_s=0.0) == [NODE]
            finally:
                fresh.close()
            assert said == [f"[characterise] configure {NODE}", f"[characterise] activate {NODE}"]
            listener = LifecycleListener(graph.domain, topics.REGULATOR_NODE, {})
            try:
                assert listener.state() == "active"
            finally:
                listener.close()
            said.clear()
            assert activate_managed(graph.watch, said.append, discovery_s=0.0) == [NODE] and said == []  # active
    finally:
        emu.close()


@pytest.mark.timeout(240)
def test_characterise_rig_ros_names_the_managed_node_that_fails_its_check(tmp_path):
    with NodeGraph() as graph:
        proc = graph.start("regulator_node", {"backend": "serial", "port": "/nonexistent/tty", "autostart": False})
        graph.wait_ready(proc)
        run = subprocess.run([str(Path(sys.executable).parent / "softcath"), "characterise", "--rig", "ros",
                              "--protocol", "quick", "--output-dir", str(tmp_path)], env=graph.env,
                             capture_output=True, text=True, timeout=200)
    assert run.returncode == 2, run.stdout + run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert f"{NODE} failed to configure" in lines[0] and "cannot open serial port /nonexistent/tty" in lines[0]


@pytest.mark.timeout(240)
def test_characterise_rig_ros_without_a_rig_names_bench_node_failing_its_configure_check(tmp_path):
    """bench_node starts unconfigured; characterise configures it: its check (the rig's topics on the
    graph within --wait-timeout) fails, named in one line, exit 3 (no rig), nothing recorded."""
    with NodeGraph() as graph:
        run = subprocess.run([str(Path(sys.executable).parent / "softcath"), "characterise", "--rig", "ros",
                              "--protocol", "quick", "--wait-timeout", "1", "--output-dir", str(tmp_path)],
                             env=graph.env, capture_output=True, text=True, timeout=200)
    assert run.returncode == 3, run.stdout + run.stderr
    assert f"[characterise] configure /{topics.BENCH_NODE}" in run.stdout
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert f"/{topics.BENCH_NODE} failed to configure" in lines[0] and "no rig after 1 s" in lines[0], lines[0]
    assert f"{topics.pressure_measured_topic(0)}: no publisher" in lines[0]
    assert not list(tmp_path.glob("bench_quick_*"))


@pytest.mark.timeout(240)
def test_bench_node_is_managed_configure_opens_activate_runs_deactivate_vents_and_stops(tmp_path):
    """bench_node with autostart off: nothing recorded until configured; activate runs the protocol;
    deactivate mid-run: the abort marker, zero command, the recording finalised incomplete (exit 130)."""
    from lifecycle_msgs.msg import Transition as TransitionMsg

    from bench_procs import summary
    from softcath_ros.graph import wait_output
    from softcath_ros.recording.reader import iter_messages, read_metadata

    with NodeGraph() as graph:
        rig = graph.start("sim_bench_node", {"legacy_topics": "false"})
        bench = graph.start("bench_node", {"protocol": "quick", "output_dir": tmp_path, "name": "managed",
                                           "autostart": False})
        graph.wait_ready(rig, bench, timeout_s=120)
        assert not (tmp_path / "managed").exists()
        said = []
        assert activate_managed(graph.watch, said.append) == ["/" + topics.BENCH_NODE]
        before = wait_output(bench, "step 8/28", timeout_s=120)
        listener = LifecycleListener(graph.domain, topics.BENCH_NODE, {})
        try:
            assert listener.transition(TransitionMsg.TRANSITION_DEACTIVATE)
        finally:
            listener.close()
        out = before + bench.communicate(timeout=60)[0]
    assert bench.returncode == 130, out
    s = summary(out)
    assert s["complete"] is False and s["error"].startswith("interrupted (lifecycle deactivate): stopped and vented"), s
    path = tmp_path / "managed" / "managed_0.mcap"
    assert read_metadata(path)["softcath_result"]["complete"] == "false"
    marks = [m.message.data for m in iter_messages(path, topics=[topics.BENCH_STEP])]
    assert '"protocol_abort"' in marks[-1]
    assert list([m.message.data for m in iter_messages(path, topics=[topics.PRESSURE_CMD])][-1]) == [0.0]

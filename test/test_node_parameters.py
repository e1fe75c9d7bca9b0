"""The one parameter helper every node declares with: types, ranges (in the descriptor, for
tools), choices, finite checks and read-only start-up parameters; every fault is one line."""
import math
import os
import subprocess
import sys

import pytest

rclpy = pytest.importorskip("rclpy")
pytestmark = pytest.mark.ros

from rclpy.parameter import Parameter  # noqa: E402

from softcath_ros.core.errors import SoftcathError  # noqa: E402
from softcath_ros.nodes.parameters import declare  # noqa: E402


@pytest.fixture
def make_node():
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = []

    def make(**overrides):
        node = rclpy.create_node("param_probe", context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        nodes.append(node)
        return node

    yield make
    for n in nodes:
        n.destroy_node()
    rclpy.shutdown(context=context)


def test_defaults_ranges_and_read_only(make_node):
    node = make_node()
    assert declare(node, "rate_hz", 100.0, "rate", minimum=1.0, maximum=1e4) == 100.0
    desc = node.describe_parameter("rate_hz")
    assert desc.read_only and desc.floating_point_range[0].from_value == 1.0
    assert declare(node, "points", 20, "points", minimum=2, maximum=10000) == 20
    assert node.describe_parameter("points").integer_range[0].to_value == 10000
    result = node.set_parameters([Parameter("rate_hz", value=5.0)])[0]
    assert not result.successful and node.get_parameter("rate_hz").value == 100.0


def test_float_parameters_take_integers(make_node):
    assert declare(make_node(max_pressure=40000), "max_pressure", 50000.0, "limit") == 40000.0


@pytest.mark.parametrize("name,default,value,kw,words", [
    ("rate_hz", 100.0, 0.0, {"minimum": 1.0}, "[1, inf]"),
    ("rate_hz", 100.0, math.nan, {}, "finite"),
    ("rate_hz", 100.0, math.inf, {"maximum": 1e4}, "finite"),
    ("rate_hz", 100.0, "fast", {}, "number"),
    ("points", 20, 20_000_000, {"minimum": 2, "maximum": 10000}, "[2, 10000]"),
    ("points", 20, 2.5, {}, "int"),
    ("executor", "events", "turbo", {"choices": ("events", "single")}, "not one of"),
])
def test_bad_values_are_one_line_errors(make_node, name, default, value, kw, words):
    with pytest.raises(SoftcathError) as e:
        declare(make_node(**{name: value}), name, default, "x", **kw)
    assert words in str(e.value) and name in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("node,param", [("sim_bench_node", "regulator_time_constant:=0.0"),
                                        ("sim_bench_node", "gauge_noise:=-1.0"),
                                        ("sim_bench_node", "pressure_shift:=.nan"),
                                        ("allocation_node", "max_request_curvature:=.nan"),
                                        ("model_node", "backbone_points:=20000000")])
def test_nodes_refuse_bad_parameters_at_start_in_one_line(node, param):
    env = dict(os.environ)   # the suite's loopback discovery (conftest)
    proc = subprocess.run([sys.executable, "-m", f"softcath_ros.nodes.{node}", "--ros-args", "-p", param],
                          env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert param.split(":=")[0] in proc.stderr and "Traceback" not in proc.stderr


PARAMS_FILES = {
    "syntax": ("softcath_model:\n  ros__parameters: [1,\n", "not valid YAML"),
    "no_ros_parameters": ("softcath_model:\n  design: implemented_5mm\n", "no ros__parameters"),
    "duplicate_keys": ("softcath_model:\n  ros__parameters:\n    design: implemented_5mm\n"
                       "    design: three_channel_5mm\n", "duplicate key 'design'"),
    "integer_beyond_64_bits": ("/**:\n  ros__parameters:\n    backbone_points: 99999999999999999999\n", "64 bits"),
    "alias": ("a: &x {ros__parameters: {backbone_points: 5}}\nsoftcath_model: *x\n", "aliases"),
    "not_utf8": (b"softcath_model:\n  ros__parameters:\n    design: \xff\n", "not UTF-8"),
    "missing": (None, "cannot read"),
}


def _start(node: str, *ros_args: str, timeout: float = 60.0, cwd=None) -> subprocess.CompletedProcess:
    env = dict(os.environ)   # the suite's loopback discovery (conftest)
    return subprocess.run([sys.executable, "-m", f"softcath_ros.nodes.{node}", "--ros-args", *ros_args],
                          env=env, capture_output=True, text=True, timeout=timeout, cwd=cwd)


EVERY_NODE = ["allocation_node", "bench_node", "model_node", "regulator_node", "scale_node", "sim_bench_node",
              "steer_driver", "steer_node", "tracker_node"]


@pytest.mark.parametrize("node", EVERY_NODE)
def test_a_misspelt_parameter_is_refused_in_one_line(tmp_path, node):
    """rcl keeps a parameter a node does not declare and the node would start on the default: refused
    (exit 2, one line, the near name suggested) before the node opens a recording or builds a rung."""
    proc = _start(node, "-p", "desgin:=three_channel_5mm", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "has no parameter 'desgin'" in lines[0], proc.stderr
    assert ("(did you mean 'design'?)" in lines[0]) == (" design," in lines[0]), lines[0]   # where it has one
    assert list(tmp_path.iterdir()) == []         # no recording folder, nothing written


@pytest.mark.parametrize("content, words", [
    ("softcath_model:\n  ros__parameters:\n    desgin: three_channel_5mm\n", "'desgin' (did you mean 'design'?)"),
    ("/**:\n  ros__parameters:\n    publish_rate: 100.0\n", "'publish_rate'"),
    ("softcath_modle:\n  ros__parameters:\n    design: three_channel_5mm\n",
     "no section for node /softcath_model (it has /softcath_modle)"),
    ("/lab:\n  softcath_model:\n    ros__parameters:\n      design: three_channel_5mm\n",
     "no section for node /softcath_model (it has /lab/softcath_model)"),
])
def test_a_params_file_the_node_would_ignore_is_refused_in_one_line(tmp_path, content, words):
    path = tmp_path / "params.yaml"
    path.write_text(content)
    proc = _start("model_node", "--params-file", str(path))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], proc.stderr


def test_params_file_sections_match_as_rcl_matches_them(tmp_path):
    from softcath_ros.nodes.parameters import params_file_sections, section_matches

    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters: {a: 1}\nlab:\n  softcath_model:\n    ros__parameters: {a: 1}\n"
                    "/lab/*:\n  ros__parameters: {a: 1}\n")
    assert params_file_sections(str(path)) == ["/**", "/lab/softcath_model", "/lab/*"]
    node = "/softcath_model"
    assert section_matches("/**", node) and section_matches("softcath_model", node)
    assert section_matches("/**/softcath_model", node) and section_matches("/*", node)
    assert section_matches("/lab/*", "/lab/softcath_model") and section_matches("/**", "/lab/softcath_model")
    assert not section_matches("/lab/softcath_model", node) and not section_matches("/softcath_modle", node)
    assert not section_matches("/*", "/lab/softcath_model")


@pytest.mark.parametrize("case", sorted(PARAMS_FILES))
def test_bad_params_files_are_one_line_before_rcl_reads_them(tmp_path, case):
    content, words = PARAMS_FILES[case]
    path = tmp_path / "params.yaml"
    if content is not None:
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    proc = _start("model_node", "--params-file", str(path))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and str(path) in lines[0], proc.stderr


@pytest.mark.parametrize("node", ["allocation_node", "sim_bench_node", "bench_node", "tracker_node", "regulator_node",
                                  "scale_node"])
def test_every_node_checks_its_params_file(tmp_path, node):
    path = tmp_path / "params.yaml"
    path.write_text("some_node:\n  rate_hz: 5\n")
    proc = _start(node, "--params-file", str(path))
    assert proc.returncode == 2 and "no ros__parameters" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("rule, words", [("backbone_points:=[1,", "not valid YAML"),
                                         ("backbone_points", "expected NAME:=VALUE"),
                                         ("backbone_points:=abc", "backbone_points")])
def test_bad_parameter_rules_are_one_line(rule, words):
    proc = _start("model_node", "-p", rule)
    assert proc.returncode == 2 and words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_discovery_stays_on_this_machine_unless_set():
    from softcath_ros.graph import default_to_localhost_discovery, graph_env

    env = {}
    assert default_to_localhost_discovery(env) == "LOCALHOST" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert default_to_localhost_discovery({"ROS_AUTOMATIC_DISCOVERY_RANGE": ""}) == "LOCALHOST"
    explicit = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert default_to_localhost_discovery(explicit) == "SUBNET"
    assert graph_env(120, base={})["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert graph_env(120, base=explicit)["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


def test_a_node_started_without_the_variable_uses_localhost_discovery():
    """The executable itself sets it (before rclpy starts): the node's environment shows it."""
    code = ("import os, sys\nfrom softcath_ros.nodes import runtime\n"
            "sys.argv = ['x', '--ros-args', '--params-file', '/nonexistent']\n"
            "code = runtime.run_node(lambda: None)\n"
            "print(os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'), code)\n")
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.stdout.split() == ["LOCALHOST", "2"], proc.stdout + proc.stderr


NODE_CLASSES = {"allocation_node": "AllocationNode", "bench_node": "BenchNode", "model_node": "ModelNode",
                "sim_bench_node": "SimBenchNode", "steer_node": "SteerNode"}


@pytest.mark.parametrize("name", sorted(NODE_CLASSES))
def test_shipped_params_files_set_only_parameters_their_node_declares(tmp_path, monkeypatch, name):
    """rcl ignores a parameter a node does not declare: a misspelt key in a shipped file would
    silently do nothing. Each file names its node, and every key is declared with that type."""
    import importlib

    from softcath_ros.core.yaml_io import load_yaml_file
    from softcath_ros.resources import find, shipped_names

    assert name in shipped_names("params")
    path = find("params", name)
    (node_key, body), = load_yaml_file(path).items()
    wanted = body["ros__parameters"]
    monkeypatch.chdir(tmp_path)                     # bench_node opens its recording under runs/
    context = rclpy.Context()
    module = importlib.import_module(f"softcath_ros.nodes.{name}")
    # a managed node is not brought up (bench_node's configure would wait for a rig): declarations are the point
    from rclpy.lifecycle import LifecycleNode

    managed = issubclass(getattr(module, NODE_CLASSES[name]), LifecycleNode) and "autostart" not in wanted
    rclpy.init(context=context, args=["--ros-args", "--params-file", str(path),
                                      *(["-p", "autostart:=false"] if managed else [])])
    node = getattr(module, NODE_CLASSES[name])(context=context)
    try:
        assert node.get_name() == node_key
        undeclared = sorted(set(wanted) - set(node._parameters))
        assert not undeclared, f"{path.name} sets undeclared parameters {undeclared}"
        for key, value in wanted.items():
            got = node.get_parameter(key).value
            if isinstance(value, float) or isinstance(got, float):
                assert got == pytest.approx(value), key
            else:
                assert got == value, key
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_no_shipped_params_file_puts_a_node_on_a_real_time_class():
    """SCHED_FIFO (as root on a lab PC) can starve everything else: opt in with -p, never by default."""
    from softcath_ros.core.yaml_io import load_yaml_file
    from softcath_ros.resources import find, shipped_names

    for name in shipped_names("params"):
        for section, body in load_yaml_file(find("params", name)).items():
            assert body["ros__parameters"].get("realtime_priority", 0) == 0, (name, section)


@pytest.mark.parametrize("node", ["allocation_node", "model_node", "sim_bench_node", "steer_node"])
def test_a_node_refuses_an_offline_rung_at_once(node):
    """model:=fe3d used to start silently and spend its first minutes timing one solve: refused in
    one line, before any rung is built (the timeout is far below one fe3d solve)."""
    proc = _start(node, "-p", "model:=fe3d", timeout=30.0)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "model fe3d is no live rung" in lines[0] and "model:=surrogate" in lines[0], proc.stderr

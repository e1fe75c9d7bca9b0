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
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run([sys.executable, "-m", f"softcath_ros.nodes.{node}", "--ros-args", "-p", param],
                          env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert param.split(":=")[0] in proc.stderr and "Traceback" not in proc.stderr

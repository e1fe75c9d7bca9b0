"""Hostile inputs, property-based (Hypothesis): designs, scenes, protocols, YAML text and CLI
arguments. Every input either loads/runs or is refused with one ``SoftcathError`` line: never
another exception (a traceback), never a hang (each call is timed), never a non-finite number in
what is returned or written. Calls run in-process so a few hundred cases take seconds."""
import copy
import io
import json
import math
import time
from contextlib import redirect_stderr, redirect_stdout

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from softcath_ros.bench.protocol import MAX_STEPS, expand_steps, protocol_from_dict
from softcath_ros.cli import main as cli_main
from softcath_ros.core.design import design_from_dict, load_design
from softcath_ros.core.errors import SoftcathError
from softcath_ros.core.scene import scene_from_dict
from softcath_ros.core.yaml_io import MAX_BYTES, load_yaml, load_yaml_file
from softcath_ros.resources import find

# Derandomised (the same cases every run, so a failure reproduces) and no example database in the
# checkout; raise max_examples locally to search further.
FUZZ = settings(max_examples=150, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
CALL_BUDGET_S = 20.0  # any single load or command (a loaded CI machine included); a hang shows as a failure

# Values a hostile file can hold: every YAML type, the edges of numbers, huge counts, path tricks.
SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-10**400, max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0, -1, 1e-12, 1e8, 2**63, 10**20]),
    st.text(max_size=12), st.sampled_from(["../../ESCAPED", "x/../../y", "", "a" * 200, "abc", "1e400"]))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=3)),
                      max_leaves=8)


def _paths(d, prefix=()):
    """Every key path in a nested mapping/list (where a mutation can land)."""
    yield prefix
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _paths(v, prefix + (i,))


def _mutated(base, data):
    """``base`` with one value (at a random path) replaced, or one key deleted or added."""
    doc = copy.deepcopy(base)
    paths = [p for p in _paths(doc) if p]
    path = data.draw(st.sampled_from(paths))
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    action = data.draw(st.sampled_from(["replace", "replace", "delete", "add"]))
    if action == "delete" and isinstance(parent, dict):
        del parent[path[-1]]
    elif action == "add" and isinstance(parent, dict):
        parent[data.draw(st.text(max_size=8))] = data.draw(VALUES)
    else:
        parent[path[-1]] = data.draw(VALUES)
    return doc


def _timed(fn, *args):
    t0 = time.monotonic()
    try:
        return fn(*args)
    finally:
        assert time.monotonic() - t0 < CALL_BUDGET_S, f"{fn.__name__} took {time.monotonic() - t0:.1f} s"


def _finite_numbers(obj) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(_finite_numbers(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return all(_finite_numbers(v) for v in obj)
    return True


def _one_line(exc: SoftcathError) -> None:
    assert "\n" not in str(exc), str(exc)


DESIGN = load_yaml_file(find("design", "implemented_5mm"))
DESIGN_3 = load_yaml_file(find("design", "three_channel_5mm"))
PROTOCOL = load_yaml_file(find("protocol", "default"))
PROTOCOL_DIR = load_yaml_file(find("protocol", "three_channel_directions"))
SCENE = load_yaml_file(find("scene", "device_in_lumen"))


@FUZZ
@given(st.data())
def test_mutated_designs_load_or_fail_in_one_line(data):
    doc = _mutated(data.draw(st.sampled_from([DESIGN, DESIGN_3])), data)
    try:
        design = _timed(design_from_dict, doc)
    except SoftcathError as exc:
        return _one_line(exc)
    assert _finite_numbers(design.to_dict())
    assert design.max_pressure > 0 and math.isfinite(design.max_pressure)
    assert "/" not in design.name and ".." not in design.name


@FUZZ
@given(st.data())
def test_mutated_protocols_load_bounded_or_fail_in_one_line(implemented_design, data):
    doc = _mutated(data.draw(st.sampled_from([PROTOCOL, PROTOCOL_DIR])), data)
    try:
        protocol = _timed(protocol_from_dict, doc)
        if protocol.drive == "channels":
            steps = _timed(expand_steps, protocol, implemented_design.n_channels, implemented_design.max_pressure)
            assert len(steps) <= MAX_STEPS
            assert all(0 <= p <= implemented_design.max_pressure for s in steps for p in s.pressures)
    except SoftcathError as exc:
        return _one_line(exc)
    assert "/" not in protocol.name and ".." not in protocol.name
    assert all(math.isfinite(v) for v in protocol.levels + protocol.directions_deg)


@FUZZ
@given(st.data())
def test_mutated_scenes_load_or_fail_in_one_line(data):
    doc = _mutated(SCENE, data)
    try:
        scene = _timed(scene_from_dict, doc)
    except SoftcathError as exc:
        return _one_line(exc)
    assert 0 <= scene.pressure_range[0] < scene.pressure_range[1] <= scene.design.max_pressure


# YAML text assembled from fragments that broke loaders: huge integers, deep nesting, aliases,
# duplicate keys, tabs, control characters, unterminated flows.
FRAGMENTS = st.sampled_from([
    "length: " + "1" + "0" * 400 + "\n", "[" * 200, "{" * 200, "a: &x [1, 2]\nb: *x\n", "limits: 1\nlimits: 2\n",
    "name: x\n", "\t", "\x00", "\x85", "- ", ": ", "? ", "!!python/object:os.system ['true']\n", "a: !!binary AAAA\n",
    "%YAML 1.1\n---\n", "---\n", "...\n", "'unterminated", "a: 1e400\n", "a: .nan\n", "a:\n  - b: c\n    - d\n",
    "0x" + "f" * 300 + "\n", "1:2:3:4\n"])


@FUZZ
@given(st.lists(st.one_of(FRAGMENTS, st.text(max_size=20)), max_size=12))
def test_yaml_text_parses_or_fails_in_one_line(parts):
    try:
        _timed(load_yaml, "".join(parts), "fuzz")
    except SoftcathError as exc:
        _one_line(exc)


@pytest.mark.parametrize("content, words", [
    (b"length: " + b"1" + b"0" * 400, "too large"),
    (b"[" * 100_000, "nested deeper"),
    (b"a: &a [x, x]\nb: &b [*a, *a]\nc: [*b, *b]\n", "aliases"),
    (b"a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n" + b"".join(      # the billion laughs, 9 levels
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]\n".encode() for i in range(1, 10)), "aliases"),
    (b"limits: {max_pressure: 1}\nlimits: {max_pressure: 1000000000}\n", "duplicate key 'limits'"),
    (b"name: \xff\xfe\n", "not UTF-8"),
    (b"# padding\n" * (MAX_BYTES // 10 + 10), "larger than"),
])
def test_hostile_design_files_are_one_line_errors(tmp_path, content, words):
    import tracemalloc

    path = tmp_path / "hostile.yaml"
    path.write_bytes(content)
    t0 = time.monotonic()
    with pytest.raises(SoftcathError) as e:
        load_design(str(path))
    assert time.monotonic() - t0 < CALL_BUDGET_S
    tracemalloc.start()            # once more, for the memory it takes (tracing slows it down)
    try:
        with pytest.raises(SoftcathError):
            load_design(str(path))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20, f"{peak / 2**20:.0f} MiB"
    assert words in str(e.value) and str(path) in str(e.value) and "\n" not in str(e.value)


def _cli(argv):
    """Run ``softcath ARGV`` in-process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.monotonic()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = cli_main(argv)
        except SystemExit as exc:   # argparse refusing an argument
            code = exc.code
    assert time.monotonic() - t0 < CALL_BUDGET_S, f"{argv} took {time.monotonic() - t0:.1f} s"
    return code, out.getvalue(), err.getvalue()


NUMBER_TEXT = st.one_of(st.sampled_from(["nan", "inf", "-inf", "1e400", "0", "-1", "1e8", "100000000", "2e-3",
                                         "0.04", "abc", "", "1,2", "0x10", "0.1bar", "15kPa", "1e3Pa", "2barr",
                                         "bar", "-0.1bar", "nanbar", "1e400kPa"]),
                        st.floats(allow_nan=False, allow_infinity=False).map(repr))


@settings(max_examples=120, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["predict", "sweep", "allocate"]), st.lists(NUMBER_TEXT, min_size=3, max_size=3))
def test_cli_numbers_give_valid_output_or_one_line_exit_2(tmp_path_factory, command, numbers):
    a, b, c = numbers
    if command == "predict":
        argv = ["predict", "--design", "implemented_5mm", "--pressure", a, "--length", b, "--json", "--unit", "Pa"]
    elif command == "sweep":
        out = tmp_path_factory.mktemp("sweep") / "s"
        argv = ["sweep", "--design", "implemented_5mm", "--from", a, "--to", b, "--steps", c, "--no-plot",
                "--out", str(out), "--json", "--unit", "Pa"]
    else:
        argv = ["allocate", "--design", "three_channel_5mm", "--curvature", f"{a},{b}", "--reachable-set", c,
                "--json"]
    code, out, err = _cli(argv)
    assert "Traceback" not in err
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err
        return
    assert code in (0, 1), (argv, code, err)
    doc = json.loads(out, parse_constant=lambda name: pytest.fail(f"{name} in JSON output of {argv}"))
    assert _finite_numbers(doc)
    if command == "predict":   # a converged answer has every number (none replaced by null)
        assert all(None not in r["tip_position_m"] + r["curvature_per_m"] for r in doc["results"] if r["converged"])
    if command == "allocate":
        assert all(0 <= p <= load_design("three_channel_5mm").max_pressure for p in doc["pressures_pa"])


@pytest.mark.parametrize("content", [b"hello, not a recording\n", bytes(range(256)) * 20,
                                     b"\x89MCAP0\r\n\x01" + b"\xff" * 8, b""])
@pytest.mark.parametrize("command", ["report", "calibrate", "recover"])
def test_cli_on_files_that_are_not_recordings_is_one_line_exit_2(tmp_path, content, command):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    code, _, err = _cli([command, str(path)])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


PARAMS = load_yaml_file(find("params", "model_node"))


@FUZZ
@given(st.data())
def test_params_files_are_checked_at_least_as_strictly_as_rcl(tmp_path_factory, data):
    """A mutated params file is refused in one line by the runtime's check, or rcl accepts it
    too (so no accepted file reaches rcl's multi-line RCLError)."""
    import yaml as pyyaml

    rclpy = pytest.importorskip("rclpy")
    from softcath_ros.nodes.command_line import check_params_file

    doc = _mutated(PARAMS, data)
    path = tmp_path_factory.mktemp("params") / "p.yaml"
    try:
        path.write_text(pyyaml.safe_dump(doc))
    except (pyyaml.YAMLError, ValueError, OverflowError):
        return                                   # not representable as YAML text
    try:
        _timed(check_params_file, str(path))
    except SoftcathError as exc:
        return _one_line(exc)
    context = rclpy.Context()
    rclpy.init(context=context, args=["x", "--ros-args", "--params-file", str(path)])   # must not raise
    rclpy.shutdown(context=context)


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory):
    from softcath_ros.recording import BagWriter

    bag = tmp_path_factory.mktemp("rec") / "bench_fuzz"
    with BagWriter(bag, custom_data={"protocol": "quick"}) as w:
        w.add_topic("/softcath/bench/angle", "std_msgs/msg/Float64")
        w.add_metadata("softcath", {"protocol": "quick", "design": "implemented_5mm", "simulated": "true"})
        w.add_attachment("design.yaml", "application/yaml", b"name: [")
        for i in range(200):
            w.write("/softcath/bench/angle", b"\x00\x01\x00\x00" + float(i).hex().encode()[:8], log_time_ns=i + 1)
            if i % 50 == 49:
                w.flush()
    return w.path.read_bytes()


@settings(max_examples=60, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_damaged_recordings_recover_or_fail_in_one_line(tmp_path_factory, small_recording, data):
    """Cut, flipped or spliced bytes of a real recording: `recover` rebuilds it or says in one
    line why not, and `report` on the result never tracebacks."""
    blob = bytearray(small_recording)
    for _ in range(data.draw(st.integers(0, 4))):
        i = data.draw(st.integers(0, len(blob) - 1))
        blob[i] = data.draw(st.integers(0, 255))
    blob = bytes(blob[:data.draw(st.integers(0, len(blob)))])
    folder = tmp_path_factory.mktemp("damaged") / "bench_fuzz"
    folder.mkdir()
    path = folder / "bench_fuzz_0.mcap"
    path.write_bytes(blob)
    for argv in (["recover", str(path), "--json"], ["report", str(folder), "--design", "implemented_5mm",
                                                    "--out", str(folder.parent / "report")]):
        code, out, err = _cli(argv)
        assert "Traceback" not in err and code in (0, 2), (argv, code, err)
        if code == 2:
            assert len(err.strip().splitlines()) == 1, err
        elif argv[0] == "recover":
            assert _finite_numbers(json.loads(out))

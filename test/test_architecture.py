"""The package's layering, read from the source: no import cycles between modules, and the pure
core (physics, numerics, bench analysis, recording) never imports rclpy."""
import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "softcath_ros"
PURE = ("softcath_ros.core", "softcath_ros.bench", "softcath_ros.recording")


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every module (of this package or not) that ``name`` imports, at top level or inside functions."""
    is_package = path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for alias in node.names:  # `from pkg import submodule` imports the submodule
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in known else target)
    return found


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(name, path, known) for name, path in mods.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle among the package's own modules, or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node] & graph.keys()):
            if nxt == node:
                continue
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def test_no_import_cycles():
    cycle = _cycle(_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "numpy"}, "b": set()}) is None


@pytest.mark.parametrize("layer", PURE)
def test_pure_layers_never_import_ros(layer):
    offenders = {name: sorted(i for i in imports if i.split(".")[0] in ("rclpy", "rosidl_runtime_py"))
                 for name, imports in _graph().items() if name == layer or name.startswith(layer + ".")}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, f"{layer} imports ROS: {offenders}"


def test_the_ladder_does_not_import_model_selection():
    """'auto' lives above the ladder: core/models names its module as a string, imported on first use."""
    graph = _graph()
    assert "softcath_ros.core.models" in graph["softcath_ros.core.model_selection"]
    assert not [m for m, imports in graph.items()
                if m.startswith("softcath_ros.core.models") and "softcath_ros.core.model_selection" in imports]


def test_arrows_point_down():
    """The bottom modules (the error base, the resource finder) import nothing of the package above
    them, and importing core registers nothing by side effect (its __init__ imports nothing)."""
    graph = _graph()
    for bottom in ("softcath_ros.errors", "softcath_ros.resources"):
        assert not {m for m in graph[bottom] if m.startswith("softcath_ros.") and m != "softcath_ros.errors"}, bottom
    assert not {m for m in graph["softcath_ros.core"] if m.startswith("softcath_ros")}


def test_the_physics_below_the_rungs_imports_no_rung():
    """The rod's law and the section problem (core/rod, core/section_fe) are what rungs are made of:
    they import no rung (the moment-curvature law is a function of the section problem)."""
    graph = _graph()
    up = {m: {i for i in imports if i.startswith("softcath_ros.core.models")} for m, imports in graph.items()
          if m.startswith(("softcath_ros.core.rod", "softcath_ros.core.section_fe"))}
    assert not {m: i for m, i in up.items() if i}


def test_model_auto_works_in_a_fresh_interpreter():
    """make_model("auto") needs no earlier import of core/model_selection."""
    import subprocess
    import sys

    code = ("from softcath_ros.core.models import make_model; from softcath_ros.core.scene import load_scene; "
            "s = load_scene('free_bending_live'); print(make_model('auto', s.design, scene=s).selection.rung)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip(), out.stderr[-1000:]


def test_rung_capabilities_need_no_rung_and_no_ngsolve():
    import subprocess
    import sys

    code = ("import sys; from softcath_ros.core.models import RUNGS, rung_info; "
            "[rung_info(r) for r in RUNGS]; assert 'ngsolve' not in sys.modules; "
            "assert 'rclpy' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_a_model_answering_from_a_shipped_table_and_the_simulated_rig_import_no_scipy():
    """A node's start-up path (model_node's surrogate on its shipped table, sim_bench_node's truth)
    reads the source rung's RungInfo but builds no rung: scipy (0.3-0.4 s of CPU per node start)
    stays unloaded until a solve needs it."""
    import subprocess
    import sys

    code = ("import sys; import numpy as np; from softcath_ros.core.design import load_design; "
            "from softcath_ros.core.models import make_model; "
            "from softcath_ros.bench.sim_rig import RigParams, SimulatedRig, truth_model; "
            "d = load_design('implemented_5mm'); m = make_model('surrogate', d); "
            "assert m.evaluate(np.array([[20000.0]])).converged[0]; "
            "rig = SimulatedRig(truth_model('surrogate', d, RigParams()), RigParams()); rig.advance(0.01, np.array([2e4])); "
            "assert np.isfinite(rig.read().angle); "
            "loaded = sorted(n for n in sys.modules if n.split('.')[0] == 'scipy'); assert not loaded, loaded[:5]")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-1500:]


def test_declared_rung_options_match_the_constructors():
    """Each rung's RungInfo lists exactly the options its constructor takes (more when it passes
    further options on, as the rod to its source rung)."""
    import inspect

    from softcath_ros.core.models import RUNGS, rung_class
    from softcath_ros.core.options import option_names

    for name in RUNGS:
        cls = rung_class(name)
        params = inspect.signature(cls.__init__).parameters
        named = {p for p, v in params.items() if p not in ("self", "design")
                 and v.kind not in (inspect.Parameter.VAR_KEYWORD, inspect.Parameter.VAR_POSITIONAL)}
        declared = set(option_names(cls.info.options))
        assert named <= declared, (name, named - declared)
        takes_more = any(v.kind is inspect.Parameter.VAR_KEYWORD for v in params.values())
        assert takes_more or declared == named, (name, declared - named)


def test_declared_study_options_match_run():
    import inspect

    from softcath_ros.core.options import option_names
    from softcath_ros.core.studies import STUDIES, study_module

    for name in STUDIES:
        module = study_module(name)
        params = list(inspect.signature(module.run).parameters)[2:]   # after design, ctx
        assert option_names(module.OPTIONS) == params, name

"""The one way a softcath node declares a parameter.

Each parameter has a type (its default's), a description, an optional range or set of choices
and a finite check; ranges go into the ParameterDescriptor, so `ros2 param describe` shows them.
Parameters read once at start-up are read-only: a run-time ``set_parameters`` is refused instead
of reporting success and being ignored. A float parameter also accepts an integer
(``-p max_pressure:=40000``). A default that costs work is computed only when needed.
Anything wrong is one ``SoftcathError`` line at start-up.
"""
from __future__ import annotations

import math

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException

from ..core.errors import SoftcathError


def declare(node, name: str, default, description: str, *, minimum=None, maximum=None, choices=None,
            read_only: bool = True, ignore_override: bool = False):
    """Declare ``name`` on ``node`` and return its checked value (float parameters as float).
    ``default`` may be a function giving a float, called only when the parameter is not given: a
    default that costs a model built for it."""
    if callable(default):
        default = 0.0 if name in _given(node) and not ignore_override else float(default())
    numeric = isinstance(default, float)
    desc = ParameterDescriptor(description=description, read_only=read_only, dynamic_typing=numeric)
    if choices is not None:
        desc.additional_constraints = f"one of: {', '.join(map(str, choices))}"
    try:
        value = node.declare_parameter(name, default, desc, ignore_override=ignore_override).value
    except ParameterException as exc:
        raise SoftcathError(f"parameter {name}: {str(exc).splitlines()[0]}") from None
    if numeric:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SoftcathError(f"parameter {name} = {value!r}: must be a number")
        value = float(value)
        if not math.isfinite(value):
            raise SoftcathError(f"parameter {name} = {value!r}: must be finite")
    elif isinstance(default, bool) != isinstance(value, bool) or (
            isinstance(default, int) and not isinstance(value, int)):
        raise SoftcathError(f"parameter {name} = {value!r}: must be {type(default).__name__}")
    if choices is not None and value not in choices:
        raise SoftcathError(f"parameter {name} = {value!r}: not one of {tuple(choices)}")
    if minimum is not None and value < minimum or maximum is not None and value > maximum:
        lo = "-inf" if minimum is None else f"{minimum:g}"
        hi = "inf" if maximum is None else f"{maximum:g}"
        raise SoftcathError(f"parameter {name} = {value!r}: must lie in [{lo}, {hi}]")
    if minimum is not None or maximum is not None:
        _describe_range(desc, numeric, minimum, maximum)
    return value


def _given(node) -> dict:
    """The parameters set for ``node`` by ``-p`` or a params file, by name."""
    return node._parameter_overrides   # rclpy keeps them only there: no public getter exists


def _describe_range(desc: ParameterDescriptor, numeric: bool, minimum, maximum) -> None:
    """The range in the descriptor, for tools (set after the check: rclpy would otherwise refuse
    an out-of-range value with its own multi-line message)."""
    if numeric:
        desc.floating_point_range = [FloatingPointRange(
            from_value=float(-1e308 if minimum is None else minimum),
            to_value=float(1e308 if maximum is None else maximum), step=0.0)]
    else:
        desc.integer_range = [IntegerRange(from_value=int(-2**63 if minimum is None else minimum),
                                           to_value=int(2**63 - 1 if maximum is None else maximum), step=0)]


def refuse_unknown_parameters(node, params_files: list[str] | None = None, later: tuple = ()) -> None:
    """Refuse, in one line, what rcl would silently ignore: a parameter set for ``node`` (by ``-p`` or
    a params file) that it does not declare (a misspelt ``desgin``), and a params file none of whose
    sections names this node (``/**`` and ``*`` wildcards count). Called once a node has declared
    every parameter, before it acts on any; ``params_files`` default to the ones the process was
    started with (runtime.run_node); ``later``: names the node declares after this check."""
    import difflib

    from .command_line import started_params_files

    declared = set(node.list_parameters([], 0).names) | set(later)
    unknown = sorted(set(_given(node)) - declared)
    name = node.get_fully_qualified_name()
    if unknown:
        hints = [f"'{u}'" + (f" (did you mean '{close[0]}'?)" if (close := difflib.get_close_matches(u, declared, 1))
                             else "") for u in unknown]
        raise SoftcathError(f"{name} has no parameter {', '.join(hints)}; it declares: {', '.join(sorted(declared))}")
    for path in started_params_files() if params_files is None else params_files:
        sections = params_file_sections(path)
        if not any(section_matches(s, name) for s in sections):
            raise SoftcathError(f"params file {path}: no section for node {name} (it has {', '.join(sections)}); "
                                f"the form is {name.lstrip('/')}: {{ros__parameters: {{...}}}}, or /** for every node")


def params_file_sections(path: str) -> list[str]:
    """The node paths of a (checked, command_line.check_params_file) params file: '/ns/node', '/**', ..."""
    from ..core.yaml_io import load_yaml_file

    out = []

    def walk(value, where: str) -> None:
        if isinstance(value, dict) and "ros__parameters" not in value:
            for key, inner in value.items():
                walk(inner, f"{where}/{str(key).strip('/')}")
        else:
            out.append(where)

    for key, value in load_yaml_file(path, f"params file {path}").items():
        walk(value, "/" + str(key).strip("/"))
    return out


def section_matches(section: str, node_name: str) -> bool:
    """Whether the params-file section ``section`` applies to the node ``node_name`` (fully
    qualified), as rcl matches them: ``*`` stands for one name part, ``**`` for any number."""
    def match(pattern: list[str], name: list[str]) -> bool:
        if not pattern:
            return not name
        if pattern[0] == "**":
            return any(match(pattern[1:], name[i:]) for i in range(len(name) + 1))
        return bool(name) and pattern[0] in ("*", name[0]) and match(pattern[1:], name[1:])

    return match([t for t in section.split("/") if t], [t for t in node_name.split("/") if t])

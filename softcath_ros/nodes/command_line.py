"""A node's command line and params files, checked before rcl reads them.

rcl refuses a bad ``-p`` rule or params file with a multi-line RCLError traceback, and rclpy's own
parser (``rclpy.parameter.parameter_dict_from_yaml_file``) is unbounded and accepts values rcl
refuses; so the rules rcl applies are checked here first, each fault in one line, with the one
bounded YAML reader (core/yaml_io.py).
"""
from __future__ import annotations

from ..core.errors import SoftcathError, shown

_started_argv: list[str] = []     # the command line run_node started this process's node with


def record_started_argv(argv: list[str]) -> None:
    """Remember the command line this process's node was started with (run_node)."""
    _started_argv[:] = argv


INT64 = (-2**63, 2**63 - 1)


def ros_arguments(argv: list[str]) -> list[str]:
    """The ROS arguments in ``argv``: everything between ``--ros-args`` and ``--`` (or the end)."""
    out, inside = [], False
    for a in argv:
        if a == "--ros-args":
            inside = True
        elif a == "--" and inside:
            inside = False
        elif inside:
            out.append(a)
    return out


def params_files(argv: list[str]) -> list[str]:
    """The ``--params-file PATH`` arguments among the ROS arguments of ``argv``."""
    ros = ros_arguments(argv)
    return [ros[i + 1] if i + 1 < len(ros) else "" for i, a in enumerate(ros) if a == "--params-file"]


def started_params_files() -> list[str]:
    """The ``--params-file`` paths of the command line ``run_node`` started with ([] in-process)."""
    return params_files(_started_argv)


def check_parameter_rules(argv: list[str]) -> None:
    """Check ``-p NAME:=VALUE`` rules before rcl does (its refusal is a multi-line error): the
    ``:=`` is there and VALUE is YAML (as rcl reads it)."""
    from ..core.yaml_io import load_yaml

    ros = ros_arguments(argv)
    for i, a in enumerate(ros):
        if a not in ("-p", "--param"):
            continue
        rule = ros[i + 1] if i + 1 < len(ros) else ""
        name, sep, value = rule.partition(":=")
        if not sep or not name:
            raise SoftcathError(f"-p {shown(rule)}: expected NAME:=VALUE")
        load_yaml(value, f"-p {name}")


def check_params_file(path: str) -> None:
    """Check a node parameter file before rcl reads it, so every fault is one line (rcl's own
    messages come as a multi-line RCLError traceback): it exists, is bounded YAML with unique keys
    (core.yaml_io), maps node names (optionally nested in namespaces, or ``/**``) to
    ``ros__parameters`` mappings, and every value is a bool, integer (int64), finite-or-not float,
    string or a list of one of those."""
    from ..core.yaml_io import load_yaml_file

    if not path:
        raise SoftcathError("--params-file needs a file name")
    data = load_yaml_file(path, f"params file {path}")
    if not isinstance(data, dict) or not data:
        raise SoftcathError(f"params file {path}: must map node names to {{ros__parameters: {{...}}}}")

    def node_entry(value, where: str) -> None:
        if not where or where.endswith("/"):
            raise SoftcathError(f"params file {path}: an empty node name ('{where}')")
        if not isinstance(value, dict):
            raise SoftcathError(f"params file {path}: '{where}' must be a mapping with ros__parameters")
        if "ros__parameters" not in value:
            for key, inner in value.items():       # a namespace level: /ns: {node: {ros__parameters}}
                if not isinstance(inner, dict):
                    raise SoftcathError(f"params file {path}: '{where}' has no ros__parameters (found '{key}' "
                                        "instead); the form is NODE_NAME: {ros__parameters: {name: value}}")
                node_entry(inner, f"{where}/{key}")
            return
        for key in value:
            if key != "ros__parameters":
                raise SoftcathError(f"params file {path}: '{where}.{key}' beside ros__parameters; "
                                    "parameters go under ros__parameters")
        parameters(value["ros__parameters"], f"{where}.ros__parameters")

    def parameters(value, where: str) -> None:
        if not isinstance(value, dict):
            raise SoftcathError(f"params file {path}: '{where}' must be a mapping of parameter: value")
        for name, v in value.items():
            at = f"{where}.{name}"
            if name is None or str(name) == "":
                raise SoftcathError(f"params file {path}: '{where}' has a parameter without a name")
            if isinstance(v, dict):              # nested names: a.b: value
                if not v:
                    raise SoftcathError(f"params file {path}: '{at}' is an empty mapping, not a value")
                parameters(v, at)
                continue
            if isinstance(v, list) and not v:
                raise SoftcathError(f"params file {path}: '{at}' is an empty list (rcl cannot type it)")
            items = v if isinstance(v, list) else [v]
            for item in items:
                if item is None or not isinstance(item, (bool, int, float, str)):
                    raise SoftcathError(f"params file {path}: '{at}' = {shown(item)}: a parameter is a bool, number, "
                                        "string or a list of one kind")
                if isinstance(item, int) and not isinstance(item, bool) and not INT64[0] <= item <= INT64[1]:
                    raise SoftcathError(f"params file {path}: '{at}' = {shown(item)}: integer beyond 64 bits")
            if isinstance(v, list) and len({type(i) for i in v}) > 1:
                raise SoftcathError(f"params file {path}: '{at}' = {shown(v)}: a list parameter holds one kind of value")

    for key, value in data.items():
        node_entry(value, str(key))

"""The one way a softcath node declares a parameter.

Each parameter has a type (its default's), a description, an optional range or set of choices
and a finite check; ranges go into the ParameterDescriptor, so `ros2 param describe` shows them.
Parameters read once at start-up are read-only: a run-time ``set_parameters`` is refused instead
of reporting success and being ignored. A float parameter also accepts an integer
(``-p max_pressure:=40000``). Anything wrong is one ``SoftcathError`` line at start-up.
"""
from __future__ import annotations

import math

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException

from ..core.errors import SoftcathError


def declare(node, name: str, default, description: str, *, minimum=None, maximum=None, choices=None,
            read_only: bool = True, ignore_override: bool = False):
    """Declare ``name`` on ``node`` and return its checked value (float parameters as float)."""
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

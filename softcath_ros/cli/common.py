"""Helpers shared by the `softcath` subcommands."""
from __future__ import annotations

import argparse
import math

import numpy as np

from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR, PRESSURE_UNITS, parse_pressure, parse_pressure_list, pressure_unit


def finite_float(text: str) -> float:
    """argparse type: a finite number (``nan``/``inf`` are refused, as every number a user gives)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be positive")
    return value


def bounded_float(lo: float, hi: float):
    """argparse type: a finite number in [lo, hi]."""
    def parse(text: str) -> float:
        value = finite_float(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{value:g}: must lie in [{lo:g}, {hi:g}]")
        return value
    parse.__name__ = "number"
    return parse


def check_rung_names(names) -> None:
    """Each of ``names`` a rung (or a chooser such as auto), else the one-line 'unknown model' error:
    before anything is started that would fail on it later."""
    from ..core.models import CHOOSERS, rung_class

    for name in names:
        if name not in CHOOSERS:
            rung_class(name)


def bounded_int(lo: int, hi: int):
    """argparse type: an integer in [lo, hi] (counts that size memory and run time are bounded)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{value}: must lie in [{lo}, {hi}]")
        return value
    parse.__name__ = "integer"
    return parse


def checked_length(design, length: float | None) -> float:
    """``--length`` (m) checked as a body length (plausible, so a slip of mm for m is named), or the
    design's when not given."""
    from ..core.errors import DesignError

    if length is None:
        return design.length
    try:
        return design.with_length(length).length
    except DesignError as exc:
        raise SoftcathError(f"--length {length:g}: {exc.reason}") from None


def parse_pressures(values: list[str], n_channels: int, unit: str | None) -> np.ndarray:
    """Each value is one command: a pressure, or a comma list with one per channel (core/units.py rule)."""
    rows = []
    for v in values:
        row = parse_pressure_list(v, "--pressure", unit)
        if len(row) != n_channels:
            raise SoftcathError(f"--pressure {v!r}: {len(row)} value(s) for a design with {n_channels} channel(s)")
        rows.append(row)
    return np.asarray(rows, dtype=float)


def unit_name(text: str) -> str:
    """argparse type of ``--unit``: Pa, kPa or bar in any case, as its canonical name."""
    try:
        return pressure_unit(text)
    except SoftcathError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_unit_argument(parser, options: str) -> None:
    """``--unit``: the unit of the bare numbers in ``options``; without it each carries its own."""
    parser.add_argument("--unit", type=unit_name, default=None, metavar="|".join(PRESSURE_UNITS),
                        help=f"unit of bare numbers in {options}; without it each pressure carries its unit "
                             "(0.15bar, 15kPa, 15000Pa); a bare number is refused")


DEFAULT_RUNG = "surrogate"   # the section rung's shipped table: accurate and fast (the nodes' default too)


def add_model_argument(parser, what: str = "model rung") -> None:
    """``--model``, defaulting to the accurate rung; the closed form stays available by name."""
    from ..core.models import available_models

    parser.add_argument("--model", default=DEFAULT_RUNG,
                        help=f"{what} (default {DEFAULT_RUNG}: the section rung's shipped table; closed_form: "
                             f"fast, rough): {', '.join(available_models())}")


def add_option_argument(parser) -> None:
    parser.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                        help="a rung option (repeatable), e.g. mesh_size=0.0004; `softcath models` lists them")


def parse_model_options(rung: str, items: list[str]) -> dict:
    """``NAME=VALUE`` items checked against the options rung ``rung`` declares and converted to
    their declared kind (bool, int, float, str; others cannot be given on the command line)."""
    from ..core.models import rung_info

    if not items:
        return {}
    if rung == "auto":
        raise SoftcathError("--option: give options to a named rung, not to --model auto")
    info = rung_info(rung)
    kinds = {o.name: o.kind for o in info.options}
    out = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise SoftcathError(f"--option {item!r}: expected NAME=VALUE")
        kind = kinds.get(name)
        if kind is None:
            known = ", ".join(kinds) or "none"
            raise SoftcathError(f"--option {name}: model '{rung}' has no such option; its options: {known}")
        try:
            if kind == "bool":
                if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError
                out[name] = text.lower() in ("true", "1", "yes")
            elif kind in ("int", "float", "str"):
                out[name] = {"int": int, "float": float, "str": str}[kind](text)
            else:
                raise SoftcathError(f"--option {name}: takes a {kind}, which the command line cannot give")
        except ValueError:
            raise SoftcathError(f"--option {name}={text}: expected a {kind}") from None
        if kind == "float" and not math.isfinite(out[name]):
            raise SoftcathError(f"--option {name}={text}: must be finite")
    return out


def check_pressure_limits(pressures: np.ndarray, design) -> None:
    """Gauge pressures in [0, max_pressure] (the design's safety limit), else a one-line error."""
    if np.any(pressures < 0):
        raise SoftcathError("pressures are gauge pressures and must not be negative")
    top = float(pressures.max()) if pressures.size else 0.0
    if top > design.max_pressure:
        raise SoftcathError(f"pressure {top:g} Pa ({top / PA_PER_BAR:g} bar) exceeds design '{design.name}' "
                            f"max_pressure {design.max_pressure:g} Pa ({design.max_pressure / PA_PER_BAR:g} bar)")

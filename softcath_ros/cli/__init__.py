"""`softcath` command line (README.md, "Commands").

Each subcommand is a module in this package with ``register(subparsers)``; the
handler it sets as ``func`` returns the exit code. Add new ones to ``SUBCOMMANDS`` (module names; ``import_csv``
registers ``softcath import``).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ..core.errors import SoftcathError

SUBCOMMANDS = [
    "characterise",
    "import_csv",
    "calibrate",
    "report",
    "recover",
    "predict",
    "models",
    "allocate",
    "sweep",
    "chart",
    "envelope",
    "study",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="softcath", description="softcath_ros command line: model, "
                                     "steer and characterise a soft catheter actuator (see README).")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def command_names() -> list[str]:
    """The subcommands as typed (a module may register another name: import_csv -> import)."""
    parser = build_parser()
    return [name for action in parser._subparsers._group_actions for name in action.choices]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SoftcathError as exc:
        print(f"softcath {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"softcath {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

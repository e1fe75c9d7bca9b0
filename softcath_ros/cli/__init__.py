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
    "surrogate",
    "steer_sim",
    "track",
    "design",
]


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a bad argument is one line (``softcath CMD: error: ...``) and exit 2, like
    every other user error; ``--help`` still shows the usage."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="softcath", description="softcath_ros command line: model, "
                                     "steer and characterise a soft catheter actuator (see README).")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    for name in SUBCOMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    parser.subcommands = sub.choices   # name as typed -> its parser (argparse keeps no public handle)
    return parser


def command_names() -> list[str]:
    """The subcommands as typed (a module may register another name: import_csv -> import)."""
    return list(build_parser().subcommands)


def main(argv: list[str] | None = None) -> int:
    from ..graph import default_to_localhost_discovery

    default_to_localhost_discovery()
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:   # --help (0), or a bad argument (2; its one line is printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        return args.func(args)
    except SoftcathError as exc:   # bad input: 2 (a failed rig check carries its own: 3)
        print(f"softcath {args.command}: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    except OSError as exc:  # a file the user named cannot be read or written (missing folder, permission)
        where = f": {exc.filename}" if exc.filename else ""
        print(f"softcath {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"softcath {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

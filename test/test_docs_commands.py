"""The commands README.md and docs/ show: every `softcath` and `pressure_sweep` line in a code block
parses as written and gives its pressures by the one unit rule (core/units.py); the README's Quick
start predictions run as written (the other lines run in test_docs_run.py or the tests it names)."""
import pytest

from doc_commands import doc_argv, doc_commands
from softcath_ros.cli import build_parser, main
from softcath_ros.core.units import parse_pressure_list

PRESSURE_DESTS = {"pressure": "--pressure", "p_from": "--from", "p_to": "--to", "max_pressure": "--max-pressure",
                  "start": "--from", "stop": "--to"}
# The README's Quick start lines run here (by the start of their words); test_docs_run.py counts them as run.
QUICK_START = [
    "predict --design implemented_5mm --pressure 0.1 0.2 --unit bar",
    "predict --design implemented_5mm --model surrogate --pressure 0.15 --unit bar --json",
    "predict --design implemented_5mm --model auto --scene free_bending_live",
    "sweep --design implemented_5mm --model section --to 0.25bar",
    "allocate --design three_sector_5mm --curvature 3,0 --json",
]


def documented_commands():
    """(file:line, tool, argv) of each command line in a fenced block of README.md and docs/
    (doc_commands.py)."""
    return [(c.where, c.tool, list(c.argv)) for c in doc_commands()]


def readme_line(prefix: str) -> list[str]:
    return doc_argv(("README.md",), f"softcath {prefix}")


def test_documented_commands_parse_and_give_each_pressure_its_unit():
    from softcath_ros.tools.pressure_sweep import build_parser as sweep_parser, sweep_range

    commands = documented_commands()
    assert len(commands) > 20 and any(t != "softcath" for _, t, _ in commands)
    for where, tool, argv in commands:
        args = (build_parser() if tool == "softcath" else sweep_parser()).parse_args(argv)
        if tool != "softcath":
            sweep_range(args)
        for dest, option in PRESSURE_DESTS.items():
            values = getattr(args, dest, None)
            for value in [] if values is None else values if isinstance(values, list) else [values]:
                parse_pressure_list(value, option, args.unit)   # raises naming the option and the line's value


@pytest.mark.parametrize("prefix", QUICK_START)
def test_readme_quick_start_runs_as_written(prefix, tmp_path, monkeypatch, capsys):
    argv = readme_line(prefix)
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert out.strip()
    if argv[0] == "sweep":
        assert (tmp_path / "runs" / "sweep.csv").is_file()

"""One rule for every pressure a user types (core/units.py, README "Pressures"): a unit suffix or the
tool's --unit; a bare number is refused in one line naming the option, never read as Pa silently."""
import json

import pytest

from softcath_ros.cli import build_parser, main
from softcath_ros.core.errors import SoftcathError
from softcath_ros.core.units import parse_pressure, parse_pressure_list


@pytest.mark.parametrize("text, unit, pa", [
    ("0.15bar", None, 15000.0), ("15kPa", None, 15000.0), ("15000Pa", None, 15000.0), ("0.15 BAR", None, 15000.0),
    ("15kpa", None, 15000.0), (".2bar", None, 20000.0), ("1.5e4Pa", None, 15000.0), ("0.15", "bar", 15000.0),
    ("15", "kPa", 15000.0), ("15000", "Pa", 15000.0), ("15kPa", "bar", 15000.0),   # a suffix wins over --unit
    ("0", None, 0.0), ("0.0", None, 0.0),                                         # zero is zero in every unit
])
def test_a_pressure_carries_its_unit(text, unit, pa):
    assert parse_pressure(text, "--pressure", unit) == pytest.approx(pa)


@pytest.mark.parametrize("text, fragment", [
    ("0.15", "--pressure 0.15: which unit? write 0.15bar, 0.15kPa or 0.15Pa (or give --unit Pa|kPa|bar)"),
    ("15000", "which unit?"), ("0.15psi", "unknown pressure unit 'psi'"), ("bar", "not a pressure"),
    ("nanbar", "not a pressure"), ("1e400Pa", "not a pressure"), ("0.1 bar bar", "not a pressure"), ("", "not a pressure"),
])
def test_a_bare_or_bad_pressure_is_refused_naming_the_option(text, fragment):
    with pytest.raises(SoftcathError) as exc:
        parse_pressure(text, "--pressure")
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_a_comma_list_takes_one_unit_per_value_or_the_commands():
    assert parse_pressure_list("0.1bar,0,5kPa", "--pressure") == pytest.approx([1e4, 0.0, 5e3])
    assert parse_pressure_list("0.1,0,0.05", "--pressure", "bar") == pytest.approx([1e4, 0.0, 5e3])
    with pytest.raises(SoftcathError, match="--pressure 0.05: which unit"):
        parse_pressure_list("0.1bar,0,0.05", "--pressure")


# Every option of `softcath` that takes a pressure, with the rest of a command that would run.
PRESSURE_OPTIONS = {
    ("predict", "--pressure"): ["predict", "--design", "implemented_5mm", "--model", "closed_form", "--pressure"],
    ("sweep", "--from"): ["sweep", "--design", "implemented_5mm", "--model", "closed_form", "--to", "0.25bar",
                          "--no-plot", "--from"],
    ("sweep", "--to"): ["sweep", "--design", "implemented_5mm", "--model", "closed_form", "--no-plot", "--to"],
    ("allocate", "--max-pressure"): ["allocate", "--design", "three_channel_5mm", "--model", "closed_form",
                                     "--curvature", "3,0", "--max-pressure"],
    ("study", "--pressure"): ["study", "sensitivity", "--design", "implemented_5mm", "--model", "closed_form",
                              "--pressure"],
    ("steer-sim", "--max-pressure"): ["steer-sim", "--max-pressure"],
}


def _pressure_options():
    """(command, option) of every option whose help says it takes a pressure."""
    found = set()
    for name, sub in build_parser().subcommands.items():
        for action in sub._actions:
            help_text = (action.help or "").lower()
            if action.option_strings and "pressure" in help_text and action.dest != "unit" \
                    and "number of pressures" not in help_text:
                found.add((name, action.option_strings[0]))
    return found


def test_every_pressure_option_follows_the_rule():
    """A new pressure option is listed here (and so tested below), takes text (the rule parses it), and its
    command has the shared --unit."""
    assert _pressure_options() == set(PRESSURE_OPTIONS)
    subs = build_parser().subcommands
    for name, option in PRESSURE_OPTIONS:
        actions = {a.option_strings[0]: a for a in subs[name]._actions if a.option_strings}
        assert actions[option].type is None and actions["--unit"].type.__name__ == "unit_name", (name, option)


@pytest.mark.parametrize("key", list(PRESSURE_OPTIONS), ids=lambda k: " ".join(k))
def test_a_bare_pressure_is_a_one_line_exit_2_on_every_command(key, capsys, tmp_path, monkeypatch):
    """`predict --pressure 0.15` predicted a straight body (0.15 Pa) and exited 0; now every command says
    which option lacks its unit, before it runs anything."""
    monkeypatch.chdir(tmp_path)
    assert main([*PRESSURE_OPTIONS[key], "0.15"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{key[1]} 0.15: which unit?" in err[0], err


def test_predict_reads_a_suffix_as_the_unit_option_does(capsys):
    base = ["predict", "--design", "implemented_5mm", "--model", "closed_form", "--json", "--pressure"]
    answers = []
    for argv in (["0.15bar"], ["15kPa"], ["0.15", "--unit", "bar"], ["15", "--unit", "kpa"], ["15000Pa"]):
        assert main([*base, *argv]) == 0
        answers.append({k: v for k, v in json.loads(capsys.readouterr().out)["results"][0].items()
                        if k != "solve_time_s"})
    assert all(a == answers[0] for a in answers) and answers[0]["pressures_pa"] == [15000.0]
    assert answers[0]["radius_of_curvature_m"] < 0.2    # bent, not the straight body 0.15 Pa gives


def test_sweep_reads_from_and_to_with_their_units(tmp_path, capsys):
    assert main(["sweep", "--design", "implemented_5mm", "--model", "closed_form", "--from", "5kPa", "--to",
                 "0.25bar", "--steps", "3", "--no-plot", "--out", str(tmp_path / "s"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["pressure_pa"] for r in doc["results"]] == pytest.approx([5e3, 15e3, 25e3])


def test_pressure_sweep_tool_follows_the_rule(capsys):
    """tools/pressure_sweep defaulted to bar where softcath defaulted to Pa: now the same rule (refused
    before it looks for model_node)."""
    from softcath_ros.tools.pressure_sweep import main as sweep_main

    with pytest.raises(SystemExit) as exc:
        sweep_main(["--to", "0.25"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1 and "--to 0.25: which unit?" in err[0], err
    with pytest.raises(SystemExit) as exc:
        sweep_main(["--to", "0.25", "--unit", "psi"])
    assert exc.value.code == 2


def test_the_manual_bench_gauge_takes_a_unit_or_bar():
    from softcath_ros.bench.manual import parse_entry

    assert parse_entry("7 @ 0.2", "force", 35000.0).gauge_bar == pytest.approx(0.2)   # the prompt asks for bar
    assert parse_entry("7 @ 20kPa", "force", 35000.0).gauge_bar == pytest.approx(0.2)

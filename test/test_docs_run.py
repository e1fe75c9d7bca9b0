"""Every command README.md and docs/ show a user runs in a test as written (the words of the doc line,
globs expanded as a shell would): here, in a fresh folder holding what the page says the user has (a
bench recording under runs/, lab.csv, the calibration file), or in the test ELSEWHERE names.
test_every_documented_command_runs_in_a_test fails when a page gains a command that nothing runs."""
import csv
import glob
import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from doc_commands import ROOT, doc_argv, doc_commands, matching
from softcath_ros.cli import main
from test_docs_commands import QUICK_START

README = ("README.md",)
CALIBRATION = ("docs/calibration.md",)
# key: (pages, start of the line); each names one command (the same line on several pages runs once)
RUN_HERE = {
    "report quick": (README, "softcath report runs/bench_quick_*/"),
    "calibrate quick": (README, "softcath calibrate runs/bench_quick_*/"),
    "predict calibrated quick": (README, "softcath predict --design implemented_5mm --pressure 0.35 --unit bar "
                                         "--calibration runs/bench_quick_<stamp>/"),
    "report default": (("docs/bench.md",), "softcath report runs/bench_default_*/"),
    "calibrate default": (("docs/bench.md", "docs/calibration.md"), "softcath calibrate runs/bench_default_*/"),
    "predict CAL": (CALIBRATION, "softcath predict "),
    "sweep CAL": (CALIBRATION, "softcath sweep "),
    "allocate CAL": (CALIBRATION, "softcath allocate "),
    "report CAL": (CALIBRATION, "softcath report "),
    "recover": (("docs/bench.md",), "softcath recover "),
    "import": (("docs/bench.md",), "softcath import lab.csv "),
    "calibrate import": (("docs/bench.md",), "softcath calibrate runs/bench_imported_lab/"),
    "chart": (("docs/benchmarks.md",), "softcath chart"),
    "surrogate check": (("docs/models/surrogate.md",), "softcath surrogate check --shipped"),
    "steer circle": (("docs/steering.md",), "softcath steer-sim --trajectory circle "),
}
# (pages, start of the line, the test that runs those lines of the first page as written; the other
# pages may only repeat them)
ELSEWHERE = [
    *[(README, f"softcath {p}", "test_docs_commands.py::test_readme_quick_start_runs_as_written") for p in QUICK_START],
    (README, "python -m softcath_ros.tools.pressure_sweep ", "test_model_node.py::test_readme_nodes_over_topics_run_as_written"),
    (README, "softcath characterise --protocol quick",
     "test_bench_nodes.py::test_characterise_records_model_predictions_and_writes_the_report"),
    (README, "softcath characterise --protocol three_channel_directions",
     "test_bench_nodes.py::test_readme_direction_protocol_runs_through_the_cli_as_written"),
    (("docs/design_file.md",), "softcath design ",
     "test_design_shapes.py::test_the_commands_in_the_design_file_page_run_as_written"),
    (("docs/tracker.md",), "softcath track ", "test_tracker.py::test_the_documented_commands_run_as_written"),
    (("docs/lab.md",), "softcath track ", "test_lab_doc.py::test_the_camera_lines_run_as_written"),
    (("docs/steering.md",), "softcath steer-sim --trajectory step",
     "test_steer_nodes.py::test_steer_sim_step_line_runs_over_dds_and_beats_open_loop"),
    (("docs/lab.md", "docs/rig.md"), "softcath characterise --rig ros",
     "test_lab_doc.py::test_the_first_recording_line_runs_as_written_and_drives_every_managed_node"),
]
STAMP = "20261201_100000"


def line(key: str) -> list[str]:
    return doc_argv(*RUN_HERE[key])


def run(argv: list[str], capsys) -> str:
    """softcath with the line's words, each glob expanded as bash would (one that matches nothing stays);
    exit 0, returns stdout."""
    words = [hit for w in argv for hit in (sorted(glob.glob(w)) if glob.has_magic(w) else []) or [w]]
    code = main(words)
    out, err = capsys.readouterr()
    assert code == 0, f"softcath {' '.join(argv)}: exit {code}: {err[-2000:]}"
    return out


@pytest.fixture(scope="module")
def bench_run():
    """A simulated bench run of the quick protocol (the rig's truth: the surrogate at 0.75 p, as
    sim_bench_node's), made once on a fake clock; ``place(folder, name)`` writes it as `softcath
    characterise` would to folder/runs/name/name_0.mcap."""
    from bench_sim_helpers import run_offline, write_recording
    from softcath_ros.bench.protocol import load_protocol
    from softcath_ros.bench.sim_rig import RigParams, SimulatedRig
    from softcath_ros.core.design import load_design
    from softcath_ros.core.models import make_model

    design = load_design("implemented_5mm")
    rig = SimulatedRig(make_model("surrogate", design), RigParams(seed=1))
    events, streams = run_offline(load_protocol("quick"), rig, dt=0.05)   # 50 ms ticks: a fifth of the rod solves

    def place(folder: Path, name: str) -> Path:
        return write_recording(folder / "runs" / name, events, streams, yaml.safe_dump(design.to_dict()), rig=rig)

    place.events, place.streams = events, streams
    return place


def test_readme_bench_lines_run_as_written(bench_run, tmp_path, monkeypatch, capsys):
    """After `softcath characterise --protocol quick` (test_bench_nodes.py): report, calibrate, and
    predict with the calibration file it wrote (the line's <stamp> is the run's)."""
    name = f"bench_quick_{STAMP}"
    bench_run(tmp_path, name)
    monkeypatch.chdir(tmp_path)
    run(line("report quick"), capsys)
    assert "## Angle bench" in (tmp_path / "runs" / name / "report.md").read_text()
    run(line("calibrate quick"), capsys)
    cal = yaml.safe_load((tmp_path / "runs" / name / "implemented_5mm.calibration.yaml").read_text())
    assert cal["rung"] == "surrogate" and cal["rms_after"] < cal["rms_before"]
    argv = line("predict calibrated quick")
    out = run([w.replace("<stamp>", STAMP) for w in argv], capsys)
    assert out.startswith("model surrogate calibrated, design implemented_5mm")


def test_bench_and_calibration_pages_run_as_written(bench_run, tmp_path, monkeypatch, capsys):
    """docs/bench.md after scripts/demo.sh (runs/bench_default_*/), and docs/calibration.md's lines with
    CAL.yaml, the file calibrate wrote: each applies the calibration."""
    name = f"bench_default_{STAMP}"
    bench_run(tmp_path, name)
    monkeypatch.chdir(tmp_path)
    report = tmp_path / "runs" / name / "report.md"
    run(line("report default"), capsys)
    assert "## Blocking-force bench" in report.read_text()
    run(line("calibrate default"), capsys)
    shutil.copy(tmp_path / "runs" / name / "implemented_5mm.calibration.yaml", "CAL.yaml")
    predicted = json.loads(run(line("predict CAL"), capsys))
    assert predicted["model"] == "surrogate calibrated" and predicted["calibration"]["file"] == "CAL.yaml"
    run(line("sweep CAL"), capsys)
    swept = json.loads((tmp_path / "sweep_implemented_5mm_section.json").read_text())
    assert swept["model"] == "section calibrated" and all(r["converged"] for r in swept["results"])
    assert "calibrated" in run(line("allocate CAL"), capsys)
    report.unlink()
    run(line("report CAL"), capsys)
    assert "calibrated" in report.read_text()


def test_recover_line_runs_as_written(bench_run, tmp_path, monkeypatch, capsys):
    """docs/bench.md: a recording cut short (the recorder killed) is rebuilt in place."""
    from mcap.reader import make_reader

    mcap = bench_run(tmp_path, "bench_x")
    assert mcap == tmp_path / "runs" / "bench_x" / "bench_x_0.mcap"
    whole = mcap.read_bytes()
    mcap.write_bytes(whole[:int(len(whole) * 0.7)])
    monkeypatch.chdir(tmp_path)
    out = run(line("recover"), capsys)
    assert "was truncated" in out and "recovered recording:" in out
    with open(mcap, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and sum(summary.statistics.channel_message_counts.values()) > 100


def test_import_lines_run_as_written(bench_run, tmp_path, monkeypatch, capsys):
    """docs/bench.md: lab.csv in the page's columns (the readings of a simulated run: angles in deg,
    the scale in g, none below 0), imported, then calibrated."""
    from softcath_ros.bench.analysis import rows_from_events

    rows = rows_from_events(bench_run.events, bench_run.streams)
    with open(tmp_path / "lab.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["pressure_bar", "reading", "unit", "trial", "phase", "sample_length_mm"])
        for r in rows:
            reading, unit = ((math.degrees(r.angle), "deg") if r.bench == "angle" else (r.force / 9.80665e-3, "g"))
            out.writerow([f"{r.pressure_cmd[0] / 1e5:g}", f"{max(reading, 0.0):.4f}", unit, r.trial + 1, r.phase,
                          f"{r.length * 1e3:g}"])
    monkeypatch.chdir(tmp_path)
    run(line("import"), capsys)
    bag = tmp_path / "runs" / "bench_imported_lab"
    assert "## Blocking-force bench" in (bag / "report.md").read_text()
    run(line("calibrate import"), capsys)
    cal = yaml.safe_load((bag / "implemented_5mm.calibration.yaml").read_text())
    assert cal["n_residuals"] == len(rows) and cal["rms_after"] < cal["rms_before"]


def test_chart_line_runs_as_written(tmp_path, monkeypatch, capsys):
    """docs/benchmarks.md: the charts redrawn from the committed rows, here of a copy of the checkout's
    benchmarks/results/ (the command writes beside the CSV)."""
    from softcath_ros.cli import chart

    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    shutil.copy(ROOT / "benchmarks" / "results" / "ladder_chart.csv", results)
    monkeypatch.setattr(chart, "checkout_root", lambda: tmp_path)
    monkeypatch.chdir(tmp_path)
    run(line("chart"), capsys)
    for stem in ("ladder_chart", "ladder_chart_lengths", "ladder_chart_directions"):
        assert (results / f"{stem}.png").stat().st_size > 10_000
    with open(results / "ladder_chart_lengths.csv") as f:
        assert list(csv.DictReader(f))


def test_surrogate_check_line_runs_as_written(tmp_path, monkeypatch, capsys):
    from softcath_ros.resources import shipped_names

    monkeypatch.chdir(tmp_path)
    out = run(line("surrogate check"), capsys)
    assert sorted(re.findall(r"^current: (\w+):", out, re.M)) == shipped_names("design")


@pytest.mark.ros
@pytest.mark.timeout(300)
def test_steer_sim_circle_line_runs_as_written(tmp_path):
    """docs/steering.md: the circle, open loop, over DDS (nodes as processes on a private domain)."""
    from domains import private_env

    argv = line("steer circle")
    res = subprocess.run([str(Path(sys.executable).parent / "softcath"), *argv], env=private_env(), cwd=tmp_path,
                         capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr[-2000:]
    rms = float(re.search(r"open_loop: tip error RMS ([\d.]+) mm", res.stdout).group(1))
    assert 0 < rms < 50
    recording = Path(re.search(r"^recording: (.*)$", res.stdout, re.M).group(1))
    assert recording.is_relative_to(tmp_path / "runs") and recording.is_file()
    assert (recording.parent / "tip_paths.png").is_file()


def test_every_documented_command_runs_in_a_test():
    """Each command line of the pages is run here or by the test ELSEWHERE names (which exists, and
    reads that page); no entry is stale."""
    commands = doc_commands()
    claims = [(pages, prefix) for pages, prefix in RUN_HERE.values()] + [(p, s) for p, s, _ in ELSEWHERE]
    unclaimed = [c.where + ": " + c.text for c in commands
                 if not any(c.doc in pages and c.text.startswith(prefix) for pages, prefix in claims)]
    assert not unclaimed, f"documented commands that no test runs: {unclaimed}"
    for key, (pages, prefix) in RUN_HERE.items():
        line(key)                                                     # one command, found
        assert re.search(rf'line\("{re.escape(key)}"\)', Path(__file__).read_text().split("def test_every")[0]), key
    for pages, prefix, test in ELSEWHERE:
        run_there = {c.argv for c in matching(pages[:1], prefix)}
        assert run_there, f"stale: {pages[0]} shows no {prefix!r}"
        assert {c.argv for c in matching(pages, prefix)} == run_there, f"{pages[1:]} show other {prefix!r} lines"
        file, name = test.split("::")
        source = (ROOT / "test" / file).read_text()
        assert f"def {name}(" in source, test
        assert Path(pages[0]).name in source or Path(pages[0]).stem == "README" and "README" in source, \
            f"{test} does not read {pages[0]}"

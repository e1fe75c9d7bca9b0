"""benchmarks/harness.py: timing over repeats, results and charts with the machine metadata; and
every benchmark script still loads (imports resolve) without running its measurement."""
import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture
def harness(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import harness

    monkeypatch.setattr(harness, "RESULTS", tmp_path)
    return harness


def test_timing_gives_median_and_spread(harness):
    calls = []
    per_call = harness.time_loops(lambda: calls.append(1), repeats=5, calls=10)
    assert len(per_call) == 5 and len(calls) == 50 and all(t >= 0 for t in per_call)
    assert harness.median_time(lambda: None, repeats=3) >= 0
    s = harness.summary([1.0, 2.0, 3.0, 4.0, 100.0])
    assert s["median_s"] == 3.0 and s["min_s"] == 1.0 and s["max_s"] == 100.0 and s["iqr_s"] == 2.0 and s["n"] == 5
    assert list(harness.time_each(lambda x: x, [1, 2, 3]).shape) == [3]


def test_results_and_figure_carry_the_machine_metadata(harness, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stem = harness.write_results("probe", {"case": "x", "load_average_before": "mine"}, [{"a": 1, "b": 2.5}])
    doc = json.loads(stem.with_suffix(".json").read_text())
    meta = doc["meta"]
    assert doc["results"] == [{"a": 1, "b": 2.5}] and stem.with_suffix(".csv").read_text().startswith("a,b")
    assert meta["case"] == "x" and meta["load_average_before"] == "mine"   # the script's own keys win
    for key in ("python", "cpu", "cpu_count", "load_average_after", "git_commit", "date"):
        assert meta[key] not in (None, "")
    assert {"softcath_ros", "numpy", "scipy"} <= set(meta["packages"])
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = Path(harness.save_figure(fig, "probe"))
    assert path == tmp_path / "probe.png" and path.stat().st_size > 1000 and not plt.get_fignums()


def test_every_benchmark_script_loads():
    """Import each script as a module (its measurement runs only as __main__), in one interpreter."""
    scripts = sorted(p for p in BENCHMARKS.glob("*.py") if p.name != "harness.py")
    code = ("import runpy, sys\nsys.path.insert(0, sys.argv[1])\n"
            "for path in sys.argv[2:]:\n    runpy.run_path(path, run_name='benchmark_import_check')\n")
    out = subprocess.run([sys.executable, "-c", code, str(BENCHMARKS), *map(str, scripts)], capture_output=True,
                         text=True, timeout=110)
    assert out.returncode == 0, out.stderr[-2000:]


def test_section_vs_fe3d_reads_sweep_and_stability_results(harness, tmp_path, monkeypatch):
    """Both fe3d result shapes: fe3d_sweep.py's rows (a converged flag, radius_l_over_theta_mm) and
    fe3d_stability.py's (accepted states only, R_C_mm, inf when unbent); unconverged, unbent and
    zero-pressure rows are left out, and the error is the section's R_C over the row's."""
    import section_vs_fe3d

    monkeypatch.setattr(section_vs_fe3d, "RESULTS", tmp_path)
    meta = {"length_m": 0.02, "design": "implemented_5mm"}
    sweep = [{"pressure_bar": 0.0, "converged": True, "radius_l_over_theta_mm": None},
             {"pressure_bar": 0.1, "converged": True, "radius_l_over_theta_mm": 50.0},
             {"pressure_bar": 0.2, "converged": False, "radius_l_over_theta_mm": 17.0}]
    stability = [{"pressure_bar": 0.0, "R_C_mm": float("inf")}, {"pressure_bar": 0.15, "R_C_mm": 30.0}]
    (tmp_path / "a.json").write_text(json.dumps({"meta": meta, "results": sweep}))
    (tmp_path / "b.json").write_text(json.dumps({"meta": meta, "results": stability}))
    assert section_vs_fe3d.main(["--fe3d", "a", "b", "--name", "pair"]) == 0
    rows = json.loads((tmp_path / "pair.json").read_text())["results"]
    assert [(r["pressure_bar"], r["fe3d_rc_mm"]) for r in rows] == [(0.1, 50.0), (0.15, 30.0)]
    for r in rows:
        assert r["section_vs_fe3d"] == pytest.approx(r["section_rc_mm"] / r["fe3d_rc_mm"] - 1.0)
    (tmp_path / "c.json").write_text("{}")
    assert section_vs_fe3d.main(["--fe3d", "c"]) == 2


def test_benchmark_pressures_carry_their_unit(harness):
    """The tools' one pressure rule holds in the benchmark scripts too: a suffix gives the unit, a
    bare non-zero number is refused naming the option (not read as bar or Pa silently)."""
    import argparse
    import re

    parse = harness.pressure_option("--to")
    assert parse("0.35bar") == 35000.0 and parse("15kPa") == 15000.0 and parse("0") == 0.0
    with pytest.raises(argparse.ArgumentTypeError, match=r"--to 0\.35: which unit\? write 0\.35bar"):
        parse("0.35")
    option = re.compile(r'add_argument\("--(?:to|from|step|pressure|top-pressure|max-step|fixed-steps|initial-step|'
                        r'hysteresis|rung-max-pressure)"[^)]*type=float[^)]*\)')
    bare = [f"{p.name}: {m.group(0)}" for p in BENCHMARKS.glob("*.py") for m in option.finditer(p.read_text())
            if "degree" not in m.group(0)]   # (a --step in degrees is no pressure)
    assert not bare, f"pressure options read as bare floats: {bare}"


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_long_run_stops_on_a_signal_and_keeps_what_it_measured(sig, tmp_path):
    """stop_on_signals: SIGINT (even when the run was started with it ignored, as a job backgrounded from
    a script is) and SIGTERM raise KeyboardInterrupt in the run, which writes what it has."""
    child = (f"import os, signal, sys; sys.path.insert(0, {str(BENCHMARKS)!r}); import harness\n"
             f"harness.RESULTS = __import__('pathlib').Path({str(tmp_path)!r})\n"
             "harness.stop_on_signals()\nrows = [{'p': 0.1}]\n"
             f"try:\n    os.kill(os.getpid(), signal.{sig})\n    import time; time.sleep(5); rows.append({{'p': 0.2}})\n"
             "except KeyboardInterrupt:\n    pass\n"
             "with harness.signals_held():\n    os.kill(os.getpid(), signal.SIGTERM)   # ignored while writing\n"
             "    harness.write_results('partial', {}, rows)\n")
    out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=60,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert out.returncode == 0, out.stderr
    assert json.loads((tmp_path / "partial.json").read_text())["results"] == [{"p": 0.1}]

"""`softcath chart`: the main chart plus one chart and CSV per case family, from ladder_chart's CSV."""
import csv

import pytest

from softcath_ros.cli.chart import draw_all, load_rows
from softcath_ros.core.errors import SoftcathError


def _rows():
    rows = []
    for case, family, length, ref in (("1ch 40mm", "length", 0.04, "fe3d mesh 1.4, 1.2 mm layers"),
                                      ("1ch 17mm", "length", 0.017, "fe3d mesh 1.4, 1.2 mm layers"),
                                      ("3ch one channel", "direction", 0.04, "section D/40"),
                                      ("3ch pair 2:1", "direction", 0.04, "section D/40")):
        for setting, err, cost in (("closed_form", 2.0, 3e-6), ("surrogate (of section D/20)", 0.03, 2e-5),
                                   (ref, 0.0, 60.0)):
            for p in (10000.0, 20000.0):
                rows.append({"case": case, "family": family, "design": "d", "length_m": length,
                             "direction": "1 0.5 0", "setting": setting, "rung": setting.split()[0],
                             "pressure_pa": p, "pressures_pa": f"{p:g}", "s_per_eval": cost,
                             "converged": p < 20000.0 or setting != "closed_form", "reference": ref,
                             "boundary_pa": 27500.0, "fails_beyond": True, "rc_m": 0.05,
                             "rc_rel_error": err * p / 20000.0, "tip_error_mm": 10 * err, "direction_error_deg": 0.1})
    return rows


def test_chart_draws_main_and_family_charts(tmp_path):
    path = tmp_path / "ladder.csv"
    rows = _rows()
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written = draw_all(load_rows(str(path)), tmp_path / "ladder.png")
    names = sorted(p.name for p in written)
    assert names == ["ladder.png", "ladder_directions.csv", "ladder_directions.png", "ladder_lengths.csv",
                     "ladder_lengths.png"]
    assert all(p.stat().st_size > 1000 for p in written if p.suffix == ".png")
    with open(tmp_path / "ladder_lengths.csv") as f:
        assert {r["case"] for r in csv.DictReader(f)} == {"1ch 40mm", "1ch 17mm"}


def test_chart_refuses_an_old_csv(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text("setting,pressure_pa\nx,1\n")
    with pytest.raises(SoftcathError, match="re-run benchmarks/ladder_chart.py"):
        load_rows(str(path))


def test_chart_without_results_says_so_in_one_line():
    with pytest.raises(SoftcathError, match="--csv: no committed results outside a source checkout") as exc:
        load_rows(None)
    assert "\n" not in str(exc.value)


def test_chart_marks_each_points_reference(tmp_path):
    """A case whose reference changes with pressure (fe3d where it converged, the section rung above)
    is drawn, and the legend of markers names both references."""
    from softcath_ros.cli.chart import _reference_legend, _reference_marker

    rows = [r for r in _rows() if r["case"] == "1ch 40mm"]
    for r in rows:
        if r["pressure_pa"] == 20000.0:
            r["reference"] = "section D/20"
    path = tmp_path / "mixed.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    written = draw_all(load_rows(str(path)), tmp_path / "mixed.png")
    assert all(p.stat().st_size > 1000 for p in written if p.suffix == ".png")
    assert _reference_legend(rows) == "filled circle: fe3d mesh 1.4, 1.2 mm layers, open diamond: section D/20"
    assert _reference_marker("") == "x"


def test_no_legend_covers_an_axes(tmp_path, monkeypatch):
    """Every chart's legends sit outside all of its axes (below or beside them), so none covers a point."""
    from softcath_ros.cli import chart

    figures = []

    def keep(plt, fig, path):
        fig.canvas.draw()
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
        renderer = fig.canvas.get_renderer()
        figures.append((path, [lg.get_window_extent(renderer) for lg in legends],
                        [ax.get_window_extent(renderer) for ax in fig.axes]))
        plt.close(fig)
        return path

    monkeypatch.setattr(chart, "_save", keep)
    chart.draw_all(_rows(), tmp_path / "ladder.png")
    assert len(figures) == 3
    for path, legends, axes in figures:
        assert legends, path
        for legend in legends:
            covered = [a for a in axes if legend.overlaps(a)]
            assert not covered, f"{path}: a legend at {legend} covers an axes at {covered[0]}"

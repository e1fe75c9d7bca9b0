"""Design studies (issue 7): variants, cached cases, executors, trends, CLI.

Coarse section meshes (D/12) and few cases keep this file fast; the full studies run in
benchmarks/study_speed.py and their outputs are committed under docs/studies/."""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
import pytest

from softcath_ros.core.studies import channel_shift, device_stiffness, miniaturise, sensitivity
from softcath_ros.core.studies.cases import CaseSpec
from softcath_ros.core.studies.context import StudyContext
from softcath_ros.core.studies.runner import CaseCache, RunStats, run_cases
from softcath_ros.core.studies.variation import (area_ratio, make_variant, min_wall_of, scale_design_dict,
                                                 stacked_layout)
from sector_designs import THREE_SECTOR_5MM

COARSE = {"mesh_size": 5e-3 / 12}


@pytest.fixture
def ctx(tmp_path):
    return StudyContext(options=dict(COARSE), workers=1, cache=CaseCache(tmp_path / "cache"), progress=False)


def _specs(design, ctx, pressures_bar=(0.05, 0.10, 0.15)):
    return [ctx.spec(design, [p * 1e5]) for p in pressures_bar]


# ------------------------------------------------------------------ variants
def test_stacked_layout_reproduces_the_implemented_section(implemented_design):
    d = implemented_design
    lay = stacked_layout(d.outer_diameter, d.lumen.diameter, 0.6e-3, 0.6e-3, 0.6e-3)
    assert lay["channels"][0]["diameter"] == pytest.approx(d.channels[0].diameter)
    assert lay["channels"][0]["center"][1] == pytest.approx(d.channels[0].center[1])
    assert lay["lumen"]["center"][1] == pytest.approx(d.lumen.center[1])
    assert min_wall_of(d) == pytest.approx(0.6e-3)


def test_infeasible_variant_is_reported_with_the_design_error(implemented_design):
    def too_far_out(data):
        data["channels"][0]["center"] = [0.0, 1.55e-3]   # outer wall 0.1 mm

    v = make_variant(implemented_design, "out", "shift", 0.5e-3, too_far_out)
    assert not v.feasible and v.design is None
    assert "channels[0].center" in v.reason and "thinner than the minimum" in v.reason
    ok = make_variant(implemented_design, "in", "shift", -0.1e-3,
                      lambda data: data["channels"][0].__setitem__("center", [0.0, 0.95e-3]))
    assert ok.feasible and ok.design.channels[0].center[1] == pytest.approx(0.95e-3)


def test_infeasible_rows_are_kept_not_solved(implemented_design, ctx):
    variants = channel_shift.variants(implemented_design)
    rows = ctx.evaluate(variants[:2], "test")          # -0.5 mm (infeasible), -0.4 mm
    assert rows[0]["status"].startswith("infeasible:") and rows[0]["radius_of_curvature_mm"] is None
    assert rows[1]["converged"] and rows[1]["radius_of_curvature_mm"] > 0
    assert ctx.stats.solved == 1


def test_scaling_keeps_the_area_ratio_and_scales_the_walls(implemented_design):
    from softcath_ros.core.design import design_from_dict

    data = implemented_design.to_dict()
    scale_design_dict(data, 0.4)
    data["min_wall_thickness"] = 0.2e-3
    small = design_from_dict(data)
    assert area_ratio(small) == pytest.approx(area_ratio(implemented_design))
    assert min_wall_of(small) == pytest.approx(0.24e-3)   # docs/actuator.md: 0.6 mm walls -> 0.24 mm at 2 mm


def test_sensitivity_variants_cover_the_published_parameters(implemented_design):
    vs = sensitivity.variants(implemented_design)
    groups = {v.parameter for v in vs}
    assert groups == {"reinforcement pitch", "thread diameter", "thread shape", "fibre diameter",
                      "fibre placement", "material set"}
    for g in groups:   # exactly one baseline per group, and it is the design itself
        base = [v for v in vs if v.parameter == g and v.baseline]
        assert len(base) == 1 and base[0].design.content_hash() == implemented_design.content_hash()
    none = next(v for v in vs if v.label == "none")
    assert none.design.limiting_fibre is None
    top = next(v for v in vs if v.label == "top")
    assert top.design.limiting_fibre.center[1] > 0


# ------------------------------------------------------------------ cases, cache, executors
def test_second_run_is_served_from_the_cache(implemented_design, ctx):
    specs = _specs(implemented_design, ctx)
    first = run_cases(specs, workers=1, cache=ctx.cache, progress=False, stats=(s1 := RunStats()))
    second = run_cases(specs, workers=1, cache=ctx.cache, progress=False, stats=(s2 := RunStats()))
    assert s1.solved == 3 and s2.solved == 0 and s2.cached == 3
    assert [r["results"][0]["radius_of_curvature_m"] for r in first] == \
           [r["results"][0]["radius_of_curvature_m"] for r in second]
    rc = [r["results"][0]["radius_of_curvature_m"] for r in first]
    assert rc[0] > rc[1] > rc[2]   # more pressure, tighter bend


def test_cache_key_changes_with_what_changes_the_answer(implemented_design, ctx):
    a = ctx.spec(implemented_design)
    assert a.key() == ctx.spec(implemented_design).key()
    assert a.key() != CaseSpec(a.design, a.rung, a.pressures, {"mesh_size": 4e-4}).key()
    assert a.key() != ctx.spec(implemented_design, [0.1e5]).key()
    assert a.key() != CaseSpec(a.design, "closed_form", a.pressures, {}).key()


class InterruptingExecutor:
    """Runs cases synchronously and simulates Ctrl-C on the n-th submission."""

    def __init__(self, interrupt_at: int):
        self.n, self.at = 0, interrupt_at

    def submit(self, fn, *args):
        self.n += 1
        if self.n == self.at:
            raise KeyboardInterrupt
        f = Future()
        f.set_result(fn(*args))
        return f


def test_interrupted_study_resumes_from_the_cache(implemented_design, ctx):
    specs = _specs(implemented_design, ctx)
    with pytest.raises(KeyboardInterrupt):
        run_cases(specs, executor=InterruptingExecutor(3), cache=ctx.cache, progress=False)
    stats = RunStats()
    run_cases(specs, workers=1, cache=ctx.cache, progress=False, stats=stats)
    assert stats.cached == 2 and stats.solved == 1


def test_any_concurrent_futures_executor_gives_the_same_answers(implemented_design, ctx, tmp_path):
    specs = _specs(implemented_design, ctx)
    serial = run_cases(specs, workers=1, cache=False, progress=False)
    with ThreadPoolExecutor(max_workers=2) as pool:
        threaded = run_cases(specs, executor=pool, cache=False, progress=False)
    for a, b in zip(serial, threaded):
        assert a["results"][0]["curvature_per_m"] == pytest.approx(b["results"][0]["curvature_per_m"], rel=1e-9)


def test_a_case_that_raises_is_reported_not_fatal(implemented_design, ctx):
    bad = CaseSpec(implemented_design.to_dict(), "no_such_rung", ((15000.0,),), {})
    out = run_cases([bad, ctx.spec(implemented_design)], workers=1, cache=False, progress=False,
                    stats=(stats := RunStats()))
    assert not out[0]["results"][0]["converged"] and "case failed" in out[0]["results"][0]["message"]
    assert out[1]["results"][0]["converged"] and stats.errors == 1


def test_a_command_beyond_the_rungs_range_says_did_not_converge(implemented_design, ctx):
    row = ctx.evaluate([make_variant(implemented_design, "base", "p", 0, lambda d: None)], "t")[0]
    assert row["converged"]
    ctx.pressure = 0.35e5   # past the empty lumen's closing (~0.22 bar with its wall contact off)
    ctx.options = dict(ctx.options, contact_distance=None)
    row = ctx.evaluate([make_variant(implemented_design, "base", "p", 0, lambda d: None)], "t")[0]
    assert not row["converged"] and row["status"].startswith("did not converge")


def test_dask_scheduler_needs_the_cluster_extra(monkeypatch):
    import sys

    from softcath_ros.core.errors import SoftcathError
    from softcath_ros.core.studies.runner import make_executor

    monkeypatch.setitem(sys.modules, "dask.distributed", None)   # as if the extra were not installed
    with pytest.raises(SoftcathError, match=r"softcath_ros\[cluster\]"):
        make_executor(scheduler="tcp://127.0.0.1:1")


def test_dask_client_executor_runs_the_cases_unchanged(implemented_design, ctx):
    distributed = pytest.importorskip("dask.distributed")
    specs = _specs(implemented_design, ctx, (0.05, 0.15))
    serial = run_cases(specs, workers=1, cache=False, progress=False)
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None) as client:
        remote = run_cases(specs, executor=client.get_executor(), cache=False, progress=False)
    for a, b in zip(serial, remote):
        assert a["results"][0]["curvature_per_m"] == pytest.approx(b["results"][0]["curvature_per_m"], rel=1e-9)


# ------------------------------------------------------------------ trends that could fail
def test_channel_towards_the_outer_wall_bends_more(implemented_design, ctx):
    vs = {round(v.value * 1e3, 2): v for v in channel_shift.variants(implemented_design)}
    rows = ctx.evaluate([vs[-0.3], vs[0.0], vs[0.3]], "shift")
    rc = [r["radius_of_curvature_mm"] for r in rows]
    assert rc[0] > rc[1] > rc[2]


def test_device_stiffness_raises_rc_linearly(implemented_design, ctx):
    vs = [v for v in device_stiffness.variants(implemented_design) if v.value * 1e6 in (0.0, 1.0, 4.0)]
    rows = ctx.evaluate(vs, "device")
    ei = np.array([r["device_ei_n_mm2"] for r in rows])
    rc = np.array([r["radius_of_curvature_mm"] for r in rows])
    assert np.all(np.diff(rc) > 0)
    fit = device_stiffness.linear_fit(ei, rc)
    assert fit["r2"] > 0.999 and fit["intercept"] == pytest.approx(rc[0], rel=0.02)


def test_smaller_actuator_bends_more_at_equal_pressure(implemented_design, ctx):
    vs = miniaturise.variants(implemented_design, diameters_mm=(5.0, 2.0, 1.5))
    rows = ctx.evaluate(vs, "mini")
    assert rows[1]["radius_of_curvature_mm"] < rows[0]["radius_of_curvature_mm"]
    # geometric similarity: R_C proportional to D
    assert rows[1]["radius_of_curvature_mm"] / 2.0 == pytest.approx(rows[0]["radius_of_curvature_mm"] / 5.0, rel=0.02)
    assert not rows[2]["feasible"] and "thinner than the minimum" in rows[2]["status"]   # 0.18 mm walls


# ------------------------------------------------------------------ CLI
def test_cli_study_writes_csv_png_and_markdown(tmp_path, monkeypatch, capsys):
    from softcath_ros.cli import main

    monkeypatch.setenv("SOFTCATH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    rc = main(["study", "device-stiffness", "--design", "implemented_5mm", "--mesh-size", str(COARSE["mesh_size"]),
               "--workers", "1", "--out", str(out), "--quiet", "--pressure", "0.1", "--unit", "bar"])
    assert rc == 0
    for ext in ("csv", "png", "md"):
        assert (out / f"device-stiffness_implemented_5mm.{ext}").stat().st_size > 100
    md = (out / "device-stiffness_implemented_5mm.md").read_text()
    assert "rung: `section`" in md and "max relative R_C error" in md and "0.1 bar" in md
    assert "holds" in capsys.readouterr().out


def test_cli_study_rejects_bad_input(capsys):
    from softcath_ros.cli import main

    assert main(["study", "sensitivity", "--design", "implemented_5mm", "--pressure", "2", "--unit", "bar"]) == 2
    assert "--pressure" in capsys.readouterr().err
    assert main(["study", "sensitivity", "--design", "implemented_5mm", "--max-stretch", "2"]) == 2
    assert "no such option" in capsys.readouterr().err


def test_optimise_shapes_fans_keeping_the_lumen_and_the_minimum_walls():
    """The optimiser's variables are shapes (fans: span, radii, depth, fillet, walls); every grid
    point is a valid design with the lumen kept at 1.5 mm and every wall at least the minimum, or
    is refused as infeasible by the design validation (never loaded half-valid)."""
    import itertools

    from softcath_ros.core.design import load_design
    from softcath_ros.core.studies.optimise import Search

    for name, count in (("implemented_5mm", 1), (THREE_SECTOR_5MM, 3)):
        base = load_design(name)
        search = Search(base, StudyContext(rung="closed_form"), count, 2.0)
        names = [v.name for v in search.variables]
        assert "span" in names and ("depth" in names if count == 1 else "lumen wall" in names)
        assert "fillet" in names
        variants = [search.variant(x) for x in itertools.product(*(v.grid for v in search.variables))]
        assert all(v.feasible or ("\n" not in v.reason and "channels" in v.reason) for v in variants)
        assert sum(v.feasible for v in variants) >= len(variants) // 2
        for d in (v.design for v in variants if v.feasible):
            assert d.n_channels == count and {c.kind for c in d.channels} == {"sector"}
            assert d.lumen.diameter == base.lumen.diameter
            assert min_wall_of(d) >= base.min_wall_thickness - 1e-9
    # a fan reaching the axis is refused in one line, not built
    bad = Search(load_design("implemented_5mm"), StudyContext(rung="closed_form"), 1, 2.0).variant((0.5, 2.5, 180.0, 0.2))
    assert not bad.feasible and "\n" not in bad.reason


@pytest.mark.slow
def test_the_two_dof_search_reaches_fans_within_the_stretch_limit(tmp_path):
    """The 2-DOF fans stretch most at their ends, which round up under pressure: fans spanning their
    whole third (the old search, span set by the wall between fans) stretched past 2.0 at 0.14 bar
    with walls of 0.5-1.3 mm alike. With the span a variable, the grid alone (coarse section rung)
    finds round-ended fans within the limit on the minimum walls, and a wider fan of the grid breaks it."""
    from softcath_ros.core.design import load_design
    from softcath_ros.core.studies.optimise import Search

    ctx = StudyContext(options=dict(COARSE), pressure=14000.0, workers=1, cache=CaseCache(tmp_path / "cache"),
                       progress=False)
    search = Search(load_design(THREE_SECTOR_5MM), ctx, 3, 2.0, max_iter=0)
    best = search.run()
    assert best is not None and best["max_principal_stretch"] <= 2.0 and best["radius_of_curvature_mm"] < 60.0
    assert best["thinnest_wall_mm"] == pytest.approx(0.5, abs=0.02)
    assert any(r["max_principal_stretch"] and r["max_principal_stretch"] > 2.0 for r in search.history.values())


def test_optimise_names_the_best_feasible_candidate_and_writes_its_design_file_and_curves(tmp_path):
    """optimise.run on a stand-in rung (R_C falls as the channel grows; past an area ratio of 0.29 the
    stretch limit binds): the optimum is the largest feasible channel, named in the table and
    written as a loadable design file; the curves CSV has every design at every pressure."""
    import yaml

    from softcath_ros.core.design import design_from_dict, load_design
    from softcath_ros.core.studies import optimise

    class StandIn(StudyContext):
        def solve(self, specs, label):
            out = []
            for spec in specs:
                ratio = area_ratio(design_from_dict(spec.design))
                out.append({"results": [{"radius_of_curvature_m": 0.01 / ratio, "max_principal_stretch": 1.0 + ratio / 0.29,
                                         "converged": True, "message": ""} for _ in spec.pressures]})
            return out

    base = load_design("implemented_5mm")
    result = optimise.run(base, StandIn(rung="section"), max_iter=0)
    stem = "optimised_1dof_5mm"
    assert result.rows[0]["label"] == "baseline" and result.rows[1]["design"] == stem
    feasible = [r for r in result.meta["history"] if r["feasible"]]
    best = max(feasible, key=lambda r: r["area_ratio"])
    assert result.rows[1]["area_ratio"] == pytest.approx(best["area_ratio"]) and best["area_ratio"] < 0.29
    written = design_from_dict(yaml.safe_load(result.extra_files[f"{stem}.yaml"]))
    assert written.name == stem and written.channels[0].kind == "sector"
    assert written.lumen.diameter == base.lumen.diameter
    assert result.meta["design_file"] == f"{stem}.yaml"
    csv = result.extra_files[f"{stem}_curves.csv"].splitlines()
    assert len(csv) == 1 + 2 * len(optimise.CURVE_BAR)   # baseline (the implemented design) and the optimum
    assert any(f.startswith("optimum (1 fan(s))") for f in result.findings)
    result.plot(str(tmp_path / "optimise.png"))
    assert (tmp_path / "optimise.png").stat().st_size > 0


def test_the_walls_verdict_measures_the_wall_between_fans_as_the_design_validation_does():
    """Three fans whose inner corners are 0.51 mm apart (a chord at the inner arc: on the 0.5 mm minimum,
    within the verdict's 0.02 mm) but whose fillets round those corners away: the silicone between them
    is 0.55 mm at its thinnest, so the fans are not as large as the walls allow. The verdict quotes the
    true minimum distance between the outlines, the design validation's measure."""
    import math

    import yaml

    from softcath_ros.core.design import design_from_dict
    from softcath_ros.core.studies.optimise import _walls_verdict
    from softcath_ros.core.studies.variation import channel_wall_of
    from softcath_ros.resources import find

    data = yaml.safe_load(find("design", "optimised_2dof_5mm").read_text())
    span = 120.0 - 2.0 * math.degrees(math.asin(0.51e-3 / (2.0 * data["channels"][0]["inner_radius"])))

    def fans(fillet):
        for c in data["channels"]:
            c["span"], c["fillet"] = span, fillet
        return design_from_dict(data)

    sharp, round_ended = fans(0.0), fans(1e-4)
    assert channel_wall_of(sharp) == pytest.approx(0.51e-3, abs=1e-9)        # the chord, corners unrounded
    assert _walls_verdict(sharp, 3, True).endswith(": holds")
    between = channel_wall_of(round_ended)
    assert 0.54e-3 < between < 0.55e-3
    verdict = _walls_verdict(round_ended, 3, True)
    assert verdict.endswith("does not hold") and f"{between * 1e3:.2f} mm of silicone between them" in verdict
    a, b = round_ended.section.channels[:2]     # the outlines' distance, on polygons within 1 nm of them
    assert between == pytest.approx(a.outline.polygon(1e-9).distance(b.outline.polygon(1e-9)), abs=1e-7)


def test_optimise_refuses_a_rung_without_stretch(tmp_path, capsys):
    """The optimiser's stretch limit needs the principal stretch: a rung that reports none (the closed
    form) is refused in one line before any candidate is solved, not a TypeError mid-search."""
    from softcath_ros.cli import main

    assert main(["study", "optimise", "--design", "implemented_5mm", "--model", "closed_form", "--pressure", "0.14bar",
                 "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "softcath study: error: rung closed_form reports no principal stretch, which the optimiser's stretch limit "
        "needs: use --model section"]
    assert not any(tmp_path.iterdir())


def test_a_studys_rung_error_is_not_claimed_where_the_rung_is_its_own_reference():
    """A study on the fan design quotes the section rung's error from the shipped envelope: at 20 mm and
    0.05 bar against fe3d (the committed sweep), 4.2 % (section-8; 6.3 % on section-7); at 40 mm and 0.14 bar only the section rung itself
    is the reference, so no error is claimed there (not 0 %)."""
    from softcath_ros.core.studies.output import rung_accuracy

    low = rung_accuracy("section", "three_sector_5mm", {}, 5000.0, 0.02)
    assert low["measured_on"] == "three_sector_5mm" and 0.035 < low["error_rc_rel_at_pressure_and_length"] < 0.05
    high = rung_accuracy("section", "three_sector_5mm", {}, 14000.0, 0.04)
    assert high["error_rc_rel_at_pressure"] is None and "error_rc_rel_at_pressure_and_length" not in high
    assert "at 0.15 bar not measured ('section D/20' is the reference there)" in high["note"]
    surrogate = rung_accuracy("surrogate", "three_sector_5mm", {}, 14000.0, 0.04)
    assert "(against section D/20)" in surrogate["note"] and surrogate["error_rc_rel_at_pressure"] < 0.01
    assert "(against" not in rung_accuracy("section", "implemented_5mm", {}, 15000.0, 0.04)["note"]

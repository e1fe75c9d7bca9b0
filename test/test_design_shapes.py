"""Shaped holes from files and the `softcath design` commands: CAD outlines (DXF, SVG), the example
designs of docs/design_file.md, and every command the page shows, run as written."""
import copy
import math
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softcath_ros.cli import main
from softcath_ros.core.design import design_from_dict, load_design
from softcath_ros.core.errors import DesignError
from sector_designs import THREE_SECTOR_5MM

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"
DOC = ROOT / "docs" / "design_file.md"


def with_channel(design_dict, channel, tmp_path=None, **extra):
    d = copy.deepcopy(design_dict)
    d["channels"] = [channel]
    d.update(extra)
    return d


def d_segment_area(r=2.0e-3, h=0.1e-3):
    return r * r * math.acos(h / r) - h * math.sqrt(r * r - h * h)


def test_dxf_lines_and_arcs_and_polyline_with_bulge_give_the_same_exact_d(design_dict):
    base = {"shape": "file", "path": str(EXAMPLES / "d_channel.dxf"), "units": "mm"}
    a = design_from_dict(with_channel(design_dict, {**base, "layer": "CHANNEL"}))
    b = design_from_dict(with_channel(design_dict, {**base, "layer": "CHANNEL_POLYLINE"}))
    assert a.channels[0].area == pytest.approx(d_segment_area(), rel=1e-12)
    assert b.channels[0].area == pytest.approx(d_segment_area(), rel=1e-12)
    np.testing.assert_allclose(a.channels[0].center, b.channels[0].center, atol=1e-15)
    assert np.count_nonzero(a.channels[0].outline.bulges) == 1      # the arc stayed an arc


def test_the_example_dxf_script_writes_the_committed_outlines(tmp_path, design_dict):
    out = tmp_path / "d.dxf"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "example_dxf.py"), str(out)], check=True,
                   capture_output=True)
    for layer in ("CHANNEL", "CHANNEL_POLYLINE"):
        new = design_from_dict(with_channel(design_dict, {"shape": "file", "path": str(out), "layer": layer}))
        old = design_from_dict(with_channel(design_dict, {"shape": "file", "path": str(EXAMPLES / "d_channel.dxf"),
                                                          "layer": layer}))
        assert new.content_hash() == old.content_hash()


@pytest.mark.parametrize("spec,field,words", [
    ({"layer": "OPEN"}, "channels[0].layer", "open"),
    ({"layer": "NOPE"}, "channels[0].layer", "no entities on this layer"),
    ({"layer": "CHANNEL", "units": "inch"}, "channels[0].units", "'mm' or 'm'"),
    ({"layer": "CHANNEL", "units": "m"}, "channels[0].path", "implausible"),       # drawn in mm, read as m
    ({"id": "x"}, "channels[0].layer", "layer"),
    ({"layer": "CHANNEL", "path": "missing.dxf"}, "channels[0].path", "no such file"),
    ({"layer": "CHANNEL", "path": "notes.txt"}, "channels[0].path", ".dxf or .svg"),
])
def test_bad_cad_references_are_one_line_refusals(design_dict, tmp_path, spec, field, words):
    shutil.copy(EXAMPLES / "d_channel.dxf", tmp_path / "d.dxf")
    (tmp_path / "notes.txt").write_text("x")
    ch = {"shape": "file", "path": "d.dxf", **spec}
    with pytest.raises(DesignError) as info:
        design_from_dict(with_channel(design_dict, ch), source=str(tmp_path / "design.yaml"))
    assert info.value.field == field and words in str(info.value) and "\n" not in str(info.value)


HALF_CHORD = math.sqrt(2.0**2 - 0.1**2)   # mm: the D's corners on the 2 mm circle
SVG = f"""<svg xmlns="http://www.w3.org/2000/svg" width="10mm" height="10mm" viewBox="-5 -5 10 10">
  <path id="d" d="M {HALF_CHORD!r} -0.1 A 2 2 0 0 0 {-HALF_CHORD!r} -0.1 Z"/>
  <circle id="lumen" cx="0" cy="1.15" r="0.75"/>
  <rect id="box" x="-0.5" y="-1.5" width="1" height="1"/>
  <path id="open" d="M 0 0 L 1 0 L 1 -1"/>
  <path id="curvy" d="M -1 -0.5 C -1 -2, 1 -2, 1 -0.5 Z"/>
</svg>"""


def test_svg_elements_by_id_with_y_flipped(design_dict, tmp_path):
    (tmp_path / "s.svg").write_text(SVG)
    src = str(tmp_path / "design.yaml")
    d = design_from_dict(with_channel(design_dict, {"shape": "file", "path": "s.svg", "id": "d"},
                                      lumen={"shape": "file", "path": "s.svg", "id": "lumen"}), source=src)
    assert d.channels[0].area == pytest.approx(d_segment_area(), rel=1e-9)
    assert d.channels[0].center[1] > 0.5e-3                         # drawn above the axis once y is flipped
    assert d.lumen.area == pytest.approx(math.pi * 0.75e-3**2, rel=1e-9)
    assert d.lumen.center == pytest.approx((0.0, -1.15e-3), abs=1e-12)
    box = design_from_dict(with_channel(design_dict, {"shape": "file", "path": "s.svg", "id": "box"}), source=src)
    assert box.channels[0].area == pytest.approx(1e-6, rel=1e-12)
    curvy = design_from_dict(with_channel(design_dict, {"shape": "file", "path": "s.svg", "id": "curvy"}), source=src)
    assert 1.5e-6 < curvy.channels[0].area < 2.5e-6               # a Bezier: chords within 0.1 um
    for bad, words in (("open", "open"), ("nope", "no shape with this id")):
        with pytest.raises(DesignError, match=words):
            design_from_dict(with_channel(design_dict, {"shape": "file", "path": "s.svg", "id": bad}), source=src)


def test_a_file_hole_saved_in_a_recording_loads_without_the_drawing(design_dict):
    d = load_design(EXAMPLES / "dxf_d_channel.yaml")
    saved = d.to_dict()
    assert saved["channels"][0]["shape"] == "polygon"
    again = design_from_dict(saved)
    assert again.content_hash() == d.content_hash()
    assert again.channels[0].area == pytest.approx(d.channels[0].area, rel=1e-15)


@pytest.mark.parametrize("channel,field,words", [
    ({"shape": "polygon", "points": [[0, 0.0005], [0.001, 0.0015], [0.001, 0.0005], [0, 0.0015]]},
     "channels[0].points", "not simple"),
    ({"shape": "polygon", "points": [[0, 0.0005], [0.001, 0.0005], [0.0005, 0.0015]], "fillet": 0.001},
     "channels[0].fillet", "too large"),
    ({"shape": "sector", "inner_radius": 0.001, "outer_radius": 0.002, "direction": 90, "span": 60,
      "fillet": 0.0006}, "channels[0].fillet", "half the radial depth"),
    ({"shape": "sector", "inner_radius": 0.002, "outer_radius": 0.001, "direction": 90, "span": 60},
     "channels[0].outer_radius", "larger than inner_radius"),
    ({"shape": "sector", "inner_radius": 0.001, "outer_radius": 0.002, "direction": 90, "span": 360},
     "channels[0].span", "(0, 360)"),
    ({"shape": "hexagon"}, "channels[0].shape", "unknown shape"),
    ({"shape": "sector", "radius": 1}, "channels[0].radius", "unknown key"),
    ({"shape": "polygon", "points": [[0, 0], [1e-3, 0]]}, "channels[0].points", "three vertices"),
    ({"shape": "polygon", "points": [[0, 0]]}, "channels[0].points", "2 to"),
])
def test_bad_shapes_are_refused_naming_the_field(design_dict, channel, field, words):
    with pytest.raises(DesignError) as info:
        design_from_dict(with_channel(design_dict, channel))
    assert info.value.field == field and words in str(info.value), str(info.value)


def test_a_device_must_fit_a_shaped_lumen(design_dict):
    d = copy.deepcopy(design_dict)
    d["lumen"] = {"shape": "polygon", "points": [[-0.0006, -0.0018], [0.0006, -0.0018], [0.0006, -0.0006],
                                                 [-0.0006, -0.0006]]}
    d["limiting_fibre"] = None
    d["device"] = {"diameter": 0.0012, "bending_stiffness": 1e-6}    # the square's inscribed circle
    design_from_dict(d)
    d["device"]["diameter"] = 0.0012 + 1e-7
    with pytest.raises(DesignError, match="largest circle the polygon lumen holds"):
        design_from_dict(d)


def doc_commands() -> list[str]:
    """The `softcath design` lines in the page's code blocks."""
    blocks = re.findall(r"```[a-z]*\n(.*?)```", DOC.read_text(), flags=re.S)
    return [line.strip() for b in blocks for line in b.splitlines() if line.strip().startswith("softcath design")]


def test_the_commands_in_the_design_file_page_run_as_written(tmp_path, monkeypatch, capsys):
    commands = doc_commands()
    assert len(commands) >= 6
    shutil.copytree(EXAMPLES, tmp_path / "docs" / "examples")
    monkeypatch.chdir(tmp_path)
    for cmd in commands:
        assert main(shlex.split(cmd)[1:]) == 0, cmd
    out = capsys.readouterr().out
    assert "thinnest wall: 0.5000 mm" in out and "3-fold rotation" in out and "area ratio" in out
    assert (tmp_path / "sectors.png").stat().st_size > 10_000
    for shape in ("circle", "sector", "polygon", "file"):   # the page's pictures, drawn again
        assert (tmp_path / "docs" / "img" / f"design_{shape}.png").stat().st_size > 10_000


def test_the_refusal_shown_in_the_page_is_the_one_given(design_dict):
    line = re.search(r"`(design field 'channels\[0\]\.inner_radius'[^`]*)`", DOC.read_text()).group(1)
    d = design_dict
    d.update(limiting_fibre=None, lumen={"diameter": 0.0015, "center": [0.0, 0.0]}, min_wall_thickness=0.0005,
             channels=[{"shape": "sector", "inner_radius": 0.00124, "outer_radius": 0.002, "direction": 90,
                        "span": 90}])
    with pytest.raises(DesignError) as info:
        design_from_dict(d)
    assert str(info.value) == line


@pytest.mark.parametrize("name", ["sectors", "polygon", "dxf_d_channel"])
def test_the_pictures_in_the_page_are_of_the_examples(name):
    """Each example loads and the page shows its picture (made by `softcath design show`)."""
    assert load_design(EXAMPLES / f"{name}.yaml").section.thinnest_wall().thickness >= 0.5e-3 - 1e-9
    shape = {"sectors": "sector", "polygon": "polygon", "dxf_d_channel": "file"}[name]
    assert f"(img/design_{shape}.png)" in DOC.read_text() and (ROOT / "docs" / "img" / f"design_{shape}.png").is_file()


def test_check_of_a_bad_design_is_one_line_and_exit_2(tmp_path, capsys, design_dict):
    import yaml

    bad = with_channel(design_dict, {"shape": "sector", "inner_radius": 0.0012, "outer_radius": 0.0026,
                                     "direction": 90, "span": 60})
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(bad))
    for argv in (["design", "check", str(path)], ["design", "show", str(path), "--out", str(tmp_path / "b.png")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "channels[0].outer_radius" in err and "outside the body" in err
    assert main(["design", "show", "implemented_5mm", "--out", str(tmp_path / "x.jpg")]) == 2
    assert main(["design", "check", "implemented_5mm", "--json"]) == 0
    import json
    doc = json.loads(capsys.readouterr().out)
    assert doc["thinnest_wall"]["thickness_m"] == pytest.approx(0.6e-3) and doc["symmetry"]["rotation_order"] == 1


def test_dxf_polyline_reversed_chains_and_two_loops(design_dict, tmp_path):
    import ezdxf

    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    square = [(-0.5, 0.5), (0.5, 0.5), (0.5, 1.5), (-0.5, 1.5)]
    msp.add_polyline2d(square, close=True, dxfattribs={"layer": "POLY"})
    # a D from a line drawn right to left and an arc (ARCs run counter-clockwise): joined end to end
    msp.add_line((0.6, 1.0), (-0.6, 1.0), dxfattribs={"layer": "CHAIN"})
    msp.add_arc((0, 1.0), 0.6, 0, 180, dxfattribs={"layer": "CHAIN"})
    msp.add_circle((0, 1.0), 0.3, dxfattribs={"layer": "TWO"})
    msp.add_circle((0, -1.0), 0.3, dxfattribs={"layer": "TWO"})
    msp.add_line((0, 0), (1, 0), dxfattribs={"layer": "GAP"})
    msp.add_line((1, 0.01), (1, 1), dxfattribs={"layer": "GAP"})
    msp.add_line((1, 1), (0, 0), dxfattribs={"layer": "GAP"})
    path = tmp_path / "parts.dxf"
    doc.saveas(path)
    ch = {"shape": "file", "path": str(path), "units": "mm"}
    poly = design_from_dict(with_channel(design_dict, {**ch, "layer": "POLY"}))
    assert poly.channels[0].area == pytest.approx(1e-6, rel=1e-12)
    chain = design_from_dict(with_channel(design_dict, {**ch, "layer": "CHAIN"}))
    assert chain.channels[0].area == pytest.approx(math.pi * 0.6e-3**2 / 2, rel=1e-12)
    for layer, words in (("TWO", "expected one closed polyline or circle"), ("GAP", "open")):
        with pytest.raises(DesignError, match=words):
            design_from_dict(with_channel(design_dict, {**ch, "layer": layer}))


from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

DXF_TEXT = (EXAMPLES / "d_channel.dxf").read_bytes()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, len(DXF_TEXT)), junk=st.binary(max_size=200), suffix=st.sampled_from([".dxf", ".svg"]))
def test_malformed_cad_files_are_one_line_refusals(design_dict, tmp_path, cut, junk, suffix):
    """A truncated or corrupted drawing is refused naming the field, never a traceback."""
    data = DXF_TEXT[:cut] + junk if suffix == ".dxf" else SVG.encode()[: cut % len(SVG)] + junk
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(data)
    key = {"layer": "CHANNEL"} if suffix == ".dxf" else {"id": "d"}
    try:
        design_from_dict(with_channel(design_dict, {"shape": "file", "path": str(path), **key}))
    except DesignError as exc:
        assert "\n" not in str(exc) and exc.field.startswith("channels[0]")


def test_the_shipped_sector_design_passes_its_check_with_its_fabrication_minimum(capsys):
    """three_sector_5mm: three fans round the 1.5 mm lumen, every wall >= 0.5 mm (its stated
    min_wall_thickness), 3-fold with three mirror lines, the channels' area from the real outlines."""
    import json

    from softcath_ros.cli import main

    assert main(["design", "check", THREE_SECTOR_5MM, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    design = load_design(THREE_SECTOR_5MM)
    assert design.min_wall_thickness == pytest.approx(0.5e-3) and design.lumen.diameter == pytest.approx(1.5e-3)
    assert {c.kind for c in design.channels} == {"sector"}
    assert 0.5e-3 - 1e-9 <= doc["thinnest_wall"]["thickness_m"] <= 0.51e-3   # on the minimum, not above it
    assert doc["symmetry"]["rotation_order"] == 3
    assert design.section.area_ratio > 0.30   # three_channel_5mm's circles: 0.036

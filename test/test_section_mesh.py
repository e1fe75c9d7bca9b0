"""The section rung's mesher (section_fe/mesh.py, Triangle): any valid outline meshes with the
outline's area and walls on the outlines; a symmetric design gets a symmetric mesh; a design
turned about the body axis answers turned."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from sector_designs import three_sector
from softcath_ros.core.design import design_from_dict, load_design
from softcath_ros.core.errors import DesignError
from softcath_ros.core.models import make_model
from softcath_ros.core.section_fe.mesh import mesh_section

BAR = 1e5


def _check_mesh(design, h):
    section = design.section
    mesh = mesh_section(section, h)
    assert mesh.area() == pytest.approx(section.silicone_area, rel=1e-3)
    # every wall node (corners and midsides) lies on its own outline: exactly, or within the
    # tolerance symmetry is found to (geometry.symmetry: 1e-5 R) where the mesh is a symmetric image
    outlines = [section.outer] + [o.outline for o in section.holes]
    for edges, outline in zip([mesh.outer_edges] + mesh.hole_edges, outlines):
        off = max(outline.distance_to_point(p) for p in mesh.nodes[np.unique(edges)])
        assert off < 2e-5 * section.outer_radius
        # closed and counter-clockwise about the hole
        assert np.array_equal(edges[1:, 0], edges[:-1, 2]) and edges[-1, 2] == edges[0, 0]
        p = mesh.nodes[edges[:, 0]]
        assert np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]) > 0
    # counter-clockwise elements, none degenerate
    p = mesh.nodes[mesh.triangles[:, :3]]
    area2 = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    assert area2.min() > 0
    return mesh


def _design(channels, lumen=True):
    d = load_design("three_channel_5mm").to_dict()
    d.update(name="random_section", channels=channels, min_wall_thickness=0.0002)
    if not lumen:
        d["lumen"] = None
    return design_from_dict(d)


sectors = st.builds(lambda ri, depth, direction, span, fillet: {
    "shape": "sector", "inner_radius": ri, "outer_radius": ri + depth, "direction": direction,
    "span": span, "fillet": fillet}, st.floats(0.0009, 0.0015), st.floats(0.0002, 0.0009),
    st.floats(-180.0, 180.0), st.floats(10.0, 170.0), st.sampled_from([0.0, 0.00005]))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sectors, st.integers(1, 6), st.booleans())
# a pentagon's corner on the mirror line, ~1.6e-9 R off the wedge's ray (its angle is rounded to
# 1e-6 deg): the ray cut the corner's edge 2e-9 R from its end and the wall lost its chain
@example(sector={"shape": "sector", "inner_radius": 0.0010072756630819524, "outer_radius": 0.0012072756630819525,
                 "direction": 1.1315991095045206, "span": 10.0, "fillet": 0.0}, sides=5, lumen=False)
def test_random_sectors_mesh_with_their_area_or_are_refused(sector, sides, lumen):
    """A sector channel and a convex polygon one (``sides`` > 2) or none: the design is refused
    in one line (DesignError) or meshes with the outlines' area (1e-3) and walls on them."""
    channels = [sector]
    if sides > 2:
        a = np.radians(sector["direction"] + 180.0) + 2 * np.pi * np.arange(sides) / sides
        c = 0.00165 * np.array([math.cos(np.radians(sector["direction"] + 180.0)),
                                math.sin(np.radians(sector["direction"] + 180.0))])
        channels.append({"shape": "polygon", "points": (c + 0.0004 * np.column_stack([np.cos(a), np.sin(a)])).tolist()})
    try:
        design = _design(channels, lumen)
    except DesignError as exc:
        assert "\n" not in str(exc)
        return
    _check_mesh(design, design.outer_diameter / 20)


@pytest.mark.parametrize("turn", [0.0, 37.0])
def test_a_three_fold_design_gets_a_three_fold_mesh(turn):
    design = three_sector(turn=turn, fillet=0.00005)
    mesh = _check_mesh(design, design.outer_diameter / 20)
    assert mesh.rotations == 3 and len(mesh.mirror_lines) == 3
    assert mesh.symmetric == (turn == 0.0)
    tree = cKDTree(mesh.nodes)
    tris = {tuple(sorted(t)) for t in mesh.triangles[:, :3].tolist()}
    for kind, deg in (("turn", 120.0), ("turn", 240.0), ("mirror", 90.0 + turn)):   # mirror: channel 0's mid-line
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        c2, s2 = math.cos(math.radians(2 * deg)), math.sin(math.radians(2 * deg))
        m = np.array([[c, -s], [s, c]]) if kind == "turn" else np.array([[c2, s2], [s2, -c2]])
        d, idx = tree.query(mesh.nodes @ m.T)
        assert d.max() < 1e-12
        assert {tuple(sorted(t)) for t in idx[mesh.triangles[:, :3]].tolist()} == tris


def _turned(design, degrees):
    """The design turned about the body axis (circles: their centres; sectors: their direction)."""
    t = math.radians(degrees)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    d = design.to_dict()

    def turn(hole):
        if hole is None:
            return None
        hole = dict(hole)
        if hole.get("shape") == "sector":
            hole["direction"] += degrees
        else:
            hole["center"] = (rot @ np.asarray(hole["center"])).tolist()
        return hole

    d["channels"] = [turn(c) for c in d["channels"]]
    d["lumen"] = turn(d["lumen"])
    if d.get("limiting_fibre"):
        d["limiting_fibre"] = turn(d["limiting_fibre"])
    return design_from_dict(d)


@pytest.mark.parametrize("name", ["implemented_5mm", "no_symmetry"])
def test_a_turned_design_answers_turned(name):
    """Turned by 120 degrees about the axis, a design bends by the same amount (0.1 %) in the
    direction turned by 120 degrees (0.1 deg): the mesh turns with the design. (Not yet for every
    design: one sector channel alone, turned, bends 0.4 % less at 0.05 bar; Triangle's refinement
    of the turned input differs.)"""
    if name == "implemented_5mm":
        design, p = load_design(name), 0.15 * BAR
    else:   # a sector channel and an off-axis round one: no symmetry at all
        design, p = _design([{"shape": "sector", "inner_radius": 0.0012, "outer_radius": 0.0019,
                              "direction": 100.0, "span": 80.0, "fillet": 0.0},
                             {"diameter": 0.0006, "center": [0.0004, -0.0016]}]), 0.05 * BAR
    answers = []
    for degrees in (0.0, 120.0):
        turned = _turned(design, degrees)
        state = make_model("section", turned).evaluate(np.eye(turned.n_channels)[:1] * p)
        assert state.converged.all(), state.message
        answers.append(state.curvature[0])
    (k0, k1) = answers
    assert np.hypot(*k1) == pytest.approx(np.hypot(*k0), rel=1e-3)
    turn = math.degrees(math.atan2(k1[1], k1[0]) - math.atan2(k0[1], k0[0]))
    assert abs(math.remainder(turn - 120.0, 360.0)) < 0.1


@pytest.mark.parametrize("name", ["implemented_5mm", "optimised_1dof_5mm", "optimised_2dof_5mm", "three_channel_5mm"])
def test_every_shipped_design_meshes(name):
    """optimised_1dof_5mm's channel wall passes through the body axis, where the wedge's rays
    meet: the wall is cut there (it was dropped from the wedge before)."""
    design = load_design(name)
    _check_mesh(design, design.outer_diameter / 20)


def test_a_symmetry_found_to_round_off_meshes_as_the_exact_one():
    """three_channel_5mm with centres written to 10 digits (as the optimiser once wrote it): its
    mirror lines are found 1e-9 deg off 30 / 90 / 150 deg. It gets the same mesh, with its nodes on
    the y axis at x = 0 exactly (the symmetric gauge pins them; before, it pinned off the axis and
    every state of the section was a saddle)."""
    exact = load_design("three_channel_5mm")
    written = exact.to_dict()
    written["channels"] = [{"diameter": 0.00055, "center": c} for c in
                           ([0.0, 0.001625], [-0.001407291281, -0.0008125], [0.001407291281, -0.0008125])]
    a = mesh_section(exact.section, 0.00025)
    b = mesh_section(design_from_dict(written).section, 0.00025)
    assert b.symmetric and np.count_nonzero(b.nodes[:, 0] == 0.0) > 10
    assert a.n_nodes == b.n_nodes and np.abs(a.nodes - b.nodes).max() < 1e-9

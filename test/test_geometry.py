"""core/geometry: exact outlines, section properties, walls, symmetry; shaped holes in designs."""
import copy
import math
from pathlib import Path

import numpy as np
import pytest

from softcath_ros.core.design import ShapedHole, design_from_dict
from softcath_ros.core.errors import DesignError
from softcath_ros.core.geometry import Outline, PolygonShape, Sector, symmetry
from softcath_ros.core.geometry.shapes import polygon_outline, sector_outline
from softcath_ros.core.models import make_model


def sector_design(design_dict, span=95.0, fillet=0.1e-3, n=3, ri=1.25e-3, ro=2.0e-3, first=90.0):
    d = copy.deepcopy(design_dict)
    d.update(limiting_fibre=None, min_wall_thickness=0.5e-3,
             lumen={"diameter": 1.5e-3, "center": [0.0, 0.0]},
             channels=[{"shape": "sector", "inner_radius": ri, "outer_radius": ro,
                        "direction": first + 360.0 * i / n, "span": span, "fillet": fillet} for i in range(n)])
    return d


def fine_polygon_integrals(outline, tol):
    """The same integrals over a fine polygon: converges linearly in ``tol`` to the exact ones."""
    return Outline(outline.polygon_points(tol)).integrals


@pytest.mark.parametrize("outline", [
    Outline.circle((0.3e-3, 1.05e-3), 0.85e-3),
    sector_outline(Sector(1.25e-3, 2.0e-3, 90.0, 100.0, 0.1e-3)),
    sector_outline(Sector(0.0, 2.0e-3, 30.0, 200.0, 0.1e-3)).mirrored(0.3),
    polygon_outline(PolygonShape(((0, 0), (1e-3, 0), (1e-3, 1e-3), (0.5e-3, 0.4e-3), (0, 1e-3)), 0.1e-3)),
    # flat arcs of large circles (integrated over their chords) and a major arc, either way round
    Outline([(0, 0), (1e-3, 0), (1e-3, 1e-3), (0, 1e-3)], [0.02, -0.3, 0.0, 1e-4]),
    Outline([(-1e-3, 0.2e-3), (1e-3, 0.2e-3)], [0.0, 2.5]),
    Outline([(0, 0), (0, 1e-3), (1e-3, 1e-3), (1e-3, 0)], [0.3, 0, 0, 0]),   # given clockwise
])
def test_exact_integrals_are_the_limit_of_fine_polygons(outline):
    exact = outline.integrals
    errors = []
    for tol in (1e-10, 1e-12):
        fine = fine_polygon_integrals(outline, tol)
        j = exact.centroidal_second
        errors.append((abs(fine.area - exact.area) / exact.area,
                       np.abs(fine.centroidal_second - j).max() / np.abs(j).max()))
        np.testing.assert_allclose(fine.centroid, exact.centroid, atol=1e-6 * math.sqrt(exact.area))
    # the polygon's error falls 100x with its chord tolerance: the exact value is its limit
    assert errors[1][0] < errors[0][0] / 50 and errors[1][1] < errors[0][1] / 50 + 1e-12
    assert errors[1][0] < 1e-8 and errors[1][1] < 1e-8


def test_circle_properties_are_the_circle_formulas():
    r = 0.85e-3
    i = Outline.circle((0.2e-3, -0.4e-3), r).integrals
    assert i.area == pytest.approx(math.pi * r * r, rel=1e-14)
    np.testing.assert_allclose(i.centroid, [0.2e-3, -0.4e-3], rtol=1e-13)
    np.testing.assert_allclose(i.centroidal_second, math.pi * r**4 / 4 * np.eye(2), atol=1e-12 * r**4)


def test_sector_design_loads_with_exact_areas_and_walls(design_dict):
    d = design_from_dict(sector_design(design_dict, fillet=0.0))
    assert all(isinstance(c, ShapedHole) for c in d.channels)
    area = math.radians(95.0) / 2 * (2.0e-3**2 - 1.25e-3**2)
    assert d.channels[0].area == pytest.approx(area, rel=1e-12)
    # centroid of an annular sector: 2/3 (ro^3 - ri^3)/(ro^2 - ri^2) sin(a)/a on its mid-line
    a = math.radians(47.5)
    y = 2 / 3 * (2.0e-3**3 - 1.25e-3**3) / (2.0e-3**2 - 1.25e-3**2) * math.sin(a) / a
    np.testing.assert_allclose(d.channels[0].center, [0.0, y], atol=1e-15)
    wall = d.section.thinnest_wall()
    assert wall.thickness == pytest.approx(0.5e-3, abs=1e-12)    # lumen wall 1.25 - 0.75 mm, outer 2.5 - 2.0 mm


def test_wall_exactly_at_the_minimum_is_accepted_and_below_refused(design_dict):
    design_from_dict(sector_design(design_dict, ri=0.75e-3 + 0.5e-3))
    with pytest.raises(DesignError) as info:
        design_from_dict(sector_design(design_dict, ri=0.75e-3 + 0.49e-3))
    assert info.value.field == "channels[0].inner_radius" and "0.490 mm" in str(info.value)
    with pytest.raises(DesignError) as info:
        design_from_dict(sector_design(design_dict, ro=2.01e-3))
    assert info.value.field == "channels[0].outer_radius" and "outer wall 0.490 mm" in str(info.value)
    with pytest.raises(DesignError) as info:       # neighbours too close: walls between the radial edges
        design_from_dict(sector_design(design_dict, span=118.0))
    assert "wall to channels[0]" in str(info.value) or "overlaps" in str(info.value)


def test_containment_is_decided_on_the_exact_arcs_not_the_chords():
    r = 1e-3
    circle = Outline.circle((0.0, 0.0), r)
    p0, p1 = circle.polygon_points()[:2]
    half = 0.5 * math.atan2(p1[1], p1[0])                 # half-way between two polygon vertices
    sagitta = r * (1.0 - math.cos(half))                  # the chord's distance inside the arc there
    between = (r - 0.5 * sagitta) * np.array([math.cos(half), math.sin(half)])   # inside the arc, outside the chord
    assert circle.contains(between) and not circle.contains(between * (r + 0.5 * sagitta) / (r - 0.5 * sagitta))
    assert not circle.contains((r, 0.0))                  # on the outline: not inside


@pytest.mark.parametrize("channel", [
    {"shape": "sector", "inner_radius": 0.0, "outer_radius": 1.95e-3, "direction": 0.0, "span": 298.0, "fillet": 0.6e-3},
    {"shape": "polygon", "points": [[-1e-3, -1e-3], [1e-3, -1e-3], [1e-3, 1e-3], [-1e-3, 1e-3]]},
])
def test_a_circular_hole_wholly_inside_a_shaped_one_is_refused_as_overlapping(design_dict, channel):
    d = copy.deepcopy(design_dict)
    d.update(limiting_fibre=None, min_wall_thickness=0.05e-3, channels=[channel],
             lumen={"diameter": 0.5e-3, "center": [0.0, 0.0]})
    with pytest.raises(DesignError) as info:   # its centre is 0.5 mm or more from the outline: no wall at all
        design_from_dict(d)
    assert info.value.field.startswith("channels[0].") and str(info.value).endswith("overlaps lumen")


def test_closed_form_takes_sectors_and_bends_away_from_each(design_dict):
    d = design_from_dict(sector_design(design_dict))
    model = make_model("closed_form", d)
    for i, a in enumerate(np.radians([90, 210, 330])):
        p = np.zeros(3)
        p[i] = 2e4
        k = model.evaluate(p).curvature
        assert math.cos(math.atan2(k[1], k[0]) - (a + math.pi)) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(model.evaluate(np.full(3, 2e4)).curvature, 0.0, atol=1e-9)
    areas = model.section.pressure_areas
    np.testing.assert_allclose(areas, d.channels[0].area, rtol=1e-12)


def test_three_fold_and_mirror_symmetry_found_from_the_outlines(design_dict):
    d = design_from_dict(sector_design(design_dict))
    sym = symmetry(d.section)
    assert sym.rotation_order == 3 and sym.rotation_permutation == (1, 2, 0, 3)
    assert len(sym.mirrors) == 3 and sym.has_mirror(math.pi / 2) is not None
    assert sym.has_mirror(math.pi / 2).permutation == (0, 2, 1, 3)
    # one sector a little wider: no rotation, one mirror left (through the wider one's mid-line)
    dd = sector_design(design_dict)
    dd["channels"][0]["span"] = 90.0
    sym = symmetry(design_from_dict(dd).section)
    assert sym.rotation_order == 1 and [round(math.degrees(m.angle), 9) for m in sym.mirrors] == [90.0]
    # the shipped circles: three-fold, three mirrors
    from softcath_ros.core.design import load_design
    sym = symmetry(load_design("three_channel_5mm").section)
    assert sym.rotation_order == 3 and len(sym.mirrors) == 3
    sym = symmetry(load_design("implemented_5mm").section)
    assert sym.rotation_order == 1 and [m.angle for m in sym.mirrors] == [pytest.approx(math.pi / 2)]


def test_round_trip_of_shaped_holes(design_dict):
    d = design_from_dict(sector_design(design_dict))
    again = design_from_dict(d.to_dict())
    assert again == d and again.content_hash() == d.content_hash()
    dd = sector_design(design_dict)
    dd["channels"][1]["span"] = 94.0
    assert design_from_dict(dd).content_hash() != d.content_hash()


def test_circle_only_code_refuses_shaped_holes_in_one_line(design_dict):
    d = design_from_dict(sector_design(design_dict))
    with pytest.raises(DesignError, match="reads circular holes only"):
        d.channels[0].radius


@pytest.mark.parametrize("ri,direction,span", [(1.25e-3, 90.0, 95.0), (0.0, 30.0, 200.0), (0.3e-3, -17.0, 10.0)])
def test_annular_sector_integrals_equal_the_polar_formulas(ri, direction, span):
    ro = 2.0e-3
    o = sector_outline(Sector(ri, ro, direction, span))
    a0, a1 = math.radians(direction - span / 2), math.radians(direction + span / 2)
    q2 = (ro**4 - ri**4) / 4.0
    q1 = (ro**3 - ri**3) / 3.0
    exact_xx = q2 * ((a1 - a0) / 2 + (math.sin(2 * a1) - math.sin(2 * a0)) / 4)
    exact_yy = q2 * ((a1 - a0) / 2 - (math.sin(2 * a1) - math.sin(2 * a0)) / 4)
    exact_xy = q2 * (math.sin(a1) ** 2 - math.sin(a0) ** 2) / 2
    i = o.integrals
    assert i.area == pytest.approx((ro**2 - ri**2) / 2 * (a1 - a0), rel=1e-13)
    np.testing.assert_allclose(i.first, [q1 * (math.sin(a1) - math.sin(a0)), q1 * (math.cos(a0) - math.cos(a1))],
                               atol=1e-13 * ro**3)
    np.testing.assert_allclose(i.second, [[exact_xx, exact_xy], [exact_xy, exact_yy]], atol=1e-13 * ro**4)


def facing_arcs(design_dict, c, rho=0.5e-3, theta=math.radians(60), wall=0.3e-3):
    """Two D-shaped channels whose round sides face each other across x = 0: wall 2 (c - rho)."""
    x, y, b = -c + rho * math.cos(theta), rho * math.sin(theta), math.tan(theta / 2)
    d = copy.deepcopy(design_dict)
    d.update(limiting_fibre=None, lumen=None, min_wall_thickness=wall, channels=[
        {"shape": "polygon", "points": [[x, -y, b], [x, y]]},
        {"shape": "polygon", "points": [[-x, y, b], [-x, -y]]}])
    return d


def test_a_wall_between_two_arcs_at_the_minimum_is_accepted_and_1_um_under_refused(design_dict):
    d = design_from_dict(facing_arcs(design_dict, c=0.65e-3))
    wall = d.section.wall_between(*d.section.holes)
    assert wall.thickness == pytest.approx(0.3e-3, abs=1e-7)
    with pytest.raises(DesignError) as info:
        design_from_dict(facing_arcs(design_dict, c=0.65e-3 - 0.5e-6))
    assert info.value.field == "channels[1].points" and "wall to channels[0]" in str(info.value)


def test_a_wall_between_two_radial_edges_at_the_minimum_is_accepted_and_1_um_under_refused(design_dict):
    ri, w = 1.25e-3, 0.5e-3
    gap = 2 * math.degrees(math.asin(w / (2 * ri)))     # between the inner corners of the two sectors
    d = design_from_dict(sector_design(design_dict, span=180.0 - gap, fillet=0.0, n=2, ri=ri))
    assert d.section.wall_between(*d.section.channels).thickness == pytest.approx(w, abs=1e-12)
    gap_under = 2 * math.degrees(math.asin((w - 1e-6) / (2 * ri)))
    with pytest.raises(DesignError, match="thinner than the minimum"):
        design_from_dict(sector_design(design_dict, span=180.0 - gap_under, fillet=0.0, n=2, ri=ri))


def test_a_design_turned_keeps_its_shapes_and_its_answers_turn_with_it(design_dict):
    from softcath_ros.core.design import load_design

    for d in (design_from_dict(sector_design(design_dict, n=3)), load_design("implemented_5mm"),
              load_design(Path(__file__).resolve().parents[1] / "docs/examples/polygon.yaml")):
        turned = d.rotated(math.radians(120.0))
        c, s = math.cos(math.radians(120.0)), math.sin(math.radians(120.0))
        rot = np.array([[c, -s], [s, c]])
        for a, b in zip(d.section.holes, turned.section.holes):
            assert b.area == pytest.approx(a.area, rel=1e-12)
            np.testing.assert_allclose(b.centroid, rot @ a.centroid, atol=1e-15)
        k0 = make_model("closed_form", d).curvature_per_pa
        k1 = make_model("closed_form", turned).curvature_per_pa
        np.testing.assert_allclose(k1, rot @ k0, atol=1e-12 * np.abs(k0).max())
    three = design_from_dict(sector_design(design_dict, n=3))
    assert symmetry(three.rotated(0.3).section).rotation_order == 3


def test_symmetry_survives_positions_typed_to_the_micrometre_and_not_a_10_um_shift(design_dict):
    d = sector_design(design_dict, n=3)
    r = 1.625e-3
    d["channels"] = [{"diameter": 0.55e-3, "center": [round(r * math.cos(a), 6), round(r * math.sin(a), 6)]}
                     for a in np.radians([90, 210, 330])]
    sym = symmetry(design_from_dict(d).section)
    assert sym.rotation_order == 3 and len(sym.mirrors) == 3
    d["channels"][1]["center"][0] += 10e-6
    sym = symmetry(design_from_dict(d).section)
    assert sym.rotation_order == 1 and sym.mirrors == ()


def test_symmetry_is_found_once_per_section_content_and_the_tolerance(design_dict):
    from softcath_ros.core.geometry.symmetry import _symmetry_of

    d = sector_design(design_dict, n=3)
    first = symmetry(design_from_dict(d).section)
    assert symmetry(design_from_dict(copy.deepcopy(d)).section) is first   # the same content: kept
    _symmetry_of.cache_clear()
    assert symmetry(design_from_dict(d).section) == first                   # ... and what a new search finds
    d["channels"][1]["direction"] += math.degrees(10e-6 / 1.6e-3)           # channel 1 moved ~10 um along its arc
    moved = design_from_dict(d).section
    assert symmetry(moved).rotation_order == 1                               # not the kept answer
    assert symmetry(moved, tolerance=30e-6).rotation_order == 3              # the tolerance is part of the key
    assert symmetry(moved).rotation_order == 1

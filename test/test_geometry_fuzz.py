"""Random sectors and polygons, valid and not: each design builds or is refused in one line naming
a field (never another exception), and what builds is checked independently on fine polygons."""
import copy
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from softcath_ros.core.design import design_from_dict
from softcath_ros.core.errors import DesignError
from softcath_ros.core.geometry import WALL_TOLERANCE, Arc, symmetry
from softcath_ros.core.models import make_model

MM = 1e-3
SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

size = st.floats(0.0, 3.0 * MM, allow_nan=False)
sector = st.fixed_dictionaries({
    "shape": st.just("sector"), "inner_radius": size, "outer_radius": size,
    "direction": st.floats(-400.0, 400.0), "span": st.floats(-5.0, 365.0),
    "fillet": st.one_of(st.just(0.0), st.floats(0.0, 0.6 * MM))})


@st.composite
def star_polygon(draw):
    """Points round a centre at sorted angles (mostly simple), some with bulges, maybe a fillet."""
    n = draw(st.integers(3, 8))
    cx, cy = draw(st.floats(-2 * MM, 2 * MM)), draw(st.floats(-2 * MM, 2 * MM))
    angles = sorted(draw(st.lists(st.floats(0, 2 * math.pi), min_size=n, max_size=n)))
    radii = draw(st.lists(st.floats(0.0, 1.5 * MM), min_size=n, max_size=n))
    bulges = draw(st.lists(st.one_of(st.just(0.0), st.floats(-1.5, 1.5), st.floats(-2e6, 2e6)), min_size=n, max_size=n))
    pts = [[cx + r * math.cos(a), cy + r * math.sin(a)] + ([b] if b else []) for a, r, b in zip(angles, radii, bulges)]
    if draw(st.booleans()):                       # shuffled: often crossing itself
        pts = draw(st.permutations(pts))
    spec = {"shape": "polygon", "points": pts}
    if draw(st.booleans()):
        spec["fillet"] = draw(st.floats(0.0, 0.4 * MM))
    return spec


def base(design_dict, channels, lumen, min_wall):
    d = copy.deepcopy(design_dict)
    d.update(channels=channels, lumen=lumen, limiting_fibre=None, min_wall_thickness=min_wall, device=None)
    return d


def build_or_refuse(data):
    """The design, or None after a one-line DesignError; any other exception fails the test."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)   # no NaN arithmetic on the way either
            return design_from_dict(data)
    except DesignError as exc:
        text = str(exc)
        assert "\n" not in text and text.startswith("design field '") and len(text) < 400, text
        return None


FINE_CHORD = 1e-9   # m: the independent polygons' chords stray from the arcs by at most this


def chord_area_bound(outline, poly):
    """Largest |exact area - polygon area|: each chord cuts off a segment no bigger than its length
    times FINE_CHORD (so at most arc length x FINE_CHORD in all), plus rounding in the two shoelace
    sums (n terms, each under 4 R^2 for points within R of the axis or of the first point)."""
    arcs = sum(e.radius * abs(e.sweep) for e in outline.edges() if isinstance(e, Arc))
    pts = np.asarray(poly.exterior.coords)
    reach = float(np.abs(pts).max())
    return arcs * FINE_CHORD + 16 * len(pts) * np.finfo(float).eps * 4 * reach**2


def check_independently(design):
    """Walls and containment measured on polygons 10x finer than the validator's, properties finite."""
    wmin, big_r = design.min_wall_thickness, design.outer_radius
    section = design.section
    fine = [h.outline.polygon(FINE_CHORD) for h in section.holes]
    for h, poly in zip(section.holes, fine):
        assert poly.is_valid and poly.area > 0
        pts = np.asarray(poly.exterior.coords)
        assert np.hypot(pts[:, 0], pts[:, 1]).max() <= big_r - wmin + WALL_TOLERANCE + 1e-9
        assert abs(h.area - poly.area) <= chord_area_bound(h.outline, poly)
    for i, a in enumerate(fine):
        for b in fine[i + 1:]:
            assert a.distance(b) >= wmin - WALL_TOLERANCE - 4e-9   # accepted below the minimum; 2 nm chords each side
    model = make_model("closed_form", design)
    state = model.evaluate(np.full(design.n_channels, 1e4))
    assert np.all(np.isfinite(state.curvature)) and np.isfinite(state.axial_stretch).all()


lumen = st.one_of(st.none(), st.builds(lambda d: {"diameter": d, "center": [0.0, 0.0]}, st.floats(0.2 * MM, 2 * MM)))
min_wall = st.floats(0.01 * MM, 0.6 * MM)


@SETTINGS
@given(channels=st.lists(sector, min_size=1, max_size=4), lumen=lumen, min_wall=min_wall)
@example(channels=[{"shape": "sector", "inner_radius": 0.0, "outer_radius": 0.001953125, "direction": 0.0,
                    "span": 298.0, "fillet": 0.0006}],
         lumen={"diameter": 0.001, "center": [0.0, 0.0]}, min_wall=4.893229318281241e-05)   # lumen inside the sector
def test_random_sectors_build_or_are_refused_in_one_line(design_dict, channels, lumen, min_wall):
    design = build_or_refuse(base(design_dict, channels, lumen, min_wall))
    if design is not None:
        check_independently(design)


@SETTINGS
@given(channels=st.lists(star_polygon(), min_size=1, max_size=3), lumen=lumen, min_wall=min_wall)
@example(channels=[{"shape": "polygon", "points": [[0.0, 0.0], [0.0005838610265287033, 0.0, 0.25],
                                                   [0.0013208214886099696, 0.0, 0.125]]}],
         lumen=None, min_wall=0.0005505769710604583)   # a thin lens: chords miss 1.2e-5 of its area at 1 nm
@example(channels=[{"shape": "polygon", "points": [[0.0010424500152085377, 0.0], [0.001077083534935671, 0.0, -1.0],
                                                   [-0.00028751130709102975, 0.0],
                                                   [0.00046326543800936373, 0.0011692655023106172]]}],
         lumen={"diameter": 0.0002, "center": [0.0, 0.0]}, min_wall=1e-05)   # lumen inside the polygon
def test_random_polygons_build_or_are_refused_in_one_line(design_dict, channels, lumen, min_wall):
    design = build_or_refuse(base(design_dict, channels, lumen, min_wall))
    if design is not None:
        check_independently(design)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(2, 5), turn=st.floats(-180.0, 180.0), ri=st.floats(1.0 * MM, 1.5 * MM),
       depth=st.floats(0.3 * MM, 1.0 * MM), gap=st.floats(15.0, 60.0), fillet=st.floats(0.0, 0.1 * MM))
def test_an_n_fold_sector_design_is_found_n_fold_and_answers_n_fold(design_dict, n, turn, ri, depth, gap, fillet):
    span = 360.0 / n - gap
    channels = [{"shape": "sector", "inner_radius": ri, "outer_radius": ri + depth, "direction": turn + 360.0 * i / n,
                 "span": span, "fillet": fillet} for i in range(n)]
    design = build_or_refuse(base(design_dict, channels, {"diameter": 1.5 * MM, "center": [0.0, 0.0]}, 0.1 * MM))
    if design is None:
        return
    sym = symmetry(design.section)
    assert sym.rotation_order == n and len(sym.mirrors) == n
    assert sym.rotation_permutation[:n] == tuple((i + 1) % n for i in range(n))
    model = make_model("closed_form", design)
    k0 = model.evaluate(np.eye(n)[0] * 1e4).curvature
    c, s = math.cos(2 * math.pi / n), math.sin(2 * math.pi / n)
    k1 = model.evaluate(np.eye(n)[1] * 1e4).curvature
    np.testing.assert_allclose(k1, [c * k0[0] - s * k0[1], s * k0[0] + c * k0[1]], atol=1e-9 * np.abs(k0).max())

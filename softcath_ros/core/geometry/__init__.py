"""Geometry of the cross-section (pure, no ROS): holes as exact outlines, validation by true
minimum wall distance, exact section properties, symmetry found from the outlines.

Public API (what rungs and meshers read):
- ``Outline``: a closed loop of lines and circular arcs (vertices + DXF bulges), counter-clockwise;
  ``.edges()`` (``Line``/``Arc``), ``.polygon(tolerance)`` (shapely), ``.integrals`` (exact area,
  first and second moments), ``.area``, ``.centroid``.
- ``Section``: ``outer_radius``/``outer``, ``holes`` (``SectionHole``: ``name``, ``role``
  channel|lumen, ``outline``, ``polygon``, ``shape`` as written), ``channels``, ``lumen``,
  ``fibre`` (``Circle``), ``silicone()``, ``walls()``, ``thinnest_wall()``, ``area_ratio``.
  A design's section: ``Design.section`` (core/design.py).
- ``check_section(section, min_wall)``: refuses in one ``DesignError`` line.
- ``symmetry(section)``: mirror lines and n-fold rotation, with the hole permutations.
"""
from .outline import CHORD_TOLERANCE, Arc, Line, Outline, SectionIntegrals
from .section import WALL_CHORD_TOLERANCE, WALL_TOLERANCE, Circle, Section, SectionHole, Wall, check_section
from .shapes import FileShape, PolygonShape, Sector, parse_shape, shape_kind, shape_outline
from .symmetry import Mirror, Symmetry, symmetry

__all__ = ["CHORD_TOLERANCE", "WALL_CHORD_TOLERANCE", "WALL_TOLERANCE", "Arc", "Line", "Outline",
           "SectionIntegrals", "Circle", "Section", "SectionHole", "Wall", "check_section", "FileShape",
           "PolygonShape", "Sector", "parse_shape", "shape_kind", "shape_outline", "Mirror", "Symmetry",
           "symmetry"]

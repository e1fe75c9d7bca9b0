"""Design files: one actuator per YAML file (docs/design_file.md), loaded and validated.

Every error names the offending field and value (``DesignError``). Coordinates are
on the cross-section, origin on the body axis, metres.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from pathlib import Path

from .yaml_io import load_yaml_file
from .errors import DesignError
from .materials import YeohMaterial, material_from_spec
from .checks import NAME_RULE, is_file_name
from .plausibility import check_plausible, plausible_length
from . import geometry
from .geometry.shapes import nonnegative_field as _nonnegative, number_field as _number, required_field as _req

# Thinnest silicone wall we accept unless the design states its own minimum (m).
# 0.2 mm is about what moulding of Ecoflex reliably gives; the implemented design has 0.6 mm.
DEFAULT_MIN_WALL = 0.2e-3


@dataclass(frozen=True)
class Hole:
    """A circular hole in the section: a pressurised channel or the lumen (m)."""

    diameter: float
    center: tuple[float, float]
    kind = "circle"

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def area(self) -> float:
        return math.pi * self.radius**2

    @property
    def shape(self) -> geometry.Circle:
        return geometry.Circle(self.center, self.radius)

    @property
    def outline(self) -> geometry.Outline:
        return geometry.Outline.circle(self.center, self.radius)

    def spec(self) -> dict:
        return {"diameter": self.diameter, "center": list(self.center)}

    def sizes(self, name: str) -> list[tuple[str, float]]:
        """(field, m) of the sizes the plausibility check reads."""
        return [(f"{name}.diameter", self.diameter), (f"{name}.center[0]", self.center[0]),
                (f"{name}.center[1]", self.center[1])]


@dataclass(frozen=True)
class ShapedHole:
    """A hole of another shape (sector, polygon, CAD outline): ``center`` is its area centroid,
    where the pressure on its end cap acts. Code that still reads only circles asks for
    ``diameter``/``radius`` and is refused in one line."""

    shape: object                     # geometry.Sector | PolygonShape | FileShape
    center: tuple[float, float]
    field_name: str = field(default="", compare=False)
    outline: geometry.Outline = field(default=None, compare=False, repr=False)   # built from shape if not given

    def __post_init__(self):
        if self.outline is None:
            object.__setattr__(self, "outline", geometry.shape_outline(self.shape, self.field_name or self.kind))
        c = self.outline.centroid
        if math.dist(c, self.center) > 1e-12 + 1e-9 * math.hypot(*c):
            raise DesignError(self.field_name or self.kind, list(self.center),
                              f"a {self.kind} moves with its outline, not by its centre alone")

    @property
    def kind(self) -> str:
        return self.shape.kind

    @property
    def area(self) -> float:
        return self.outline.area

    def _circles_only(self):
        raise DesignError(self.field_name or "hole", self.kind,
                          "this part of softcath reads circular holes only; give it a design of circles")

    @property
    def diameter(self) -> float:
        self._circles_only()

    @property
    def radius(self) -> float:
        self._circles_only()

    def spec(self) -> dict:
        return self.shape.spec()

    def sizes(self, name: str) -> list[tuple[str, float]]:
        """(field, m) of the sizes the plausibility check reads."""
        shape = self.shape
        if shape.kind == "sector":
            return [(f"{name}.inner_radius", shape.inner_radius), (f"{name}.outer_radius", shape.outer_radius),
                    (f"{name}.fillet", shape.fillet)]
        field_name = f"{name}.points" if shape.kind == "polygon" else f"{name}.path"
        largest = max(abs(c) for p in shape.points for c in p[:2])
        return [(field_name, largest)] + ([(f"{name}.fillet", shape.fillet)] if shape.kind == "polygon" else [])


@dataclass(frozen=True)
class LimitingFibre:
    """Strain-limiting fibre embedded in the silicone (m); nearly inextensible."""

    diameter: float
    center: tuple[float, float]
    material: YeohMaterial

    @property
    def area(self) -> float:
        return math.pi * (0.5 * self.diameter) ** 2


@dataclass(frozen=True)
class Reinforcement:
    """Helical/ring thread on the outside that stops radial expansion (m, Pa)."""

    pitch: float
    thread_diameter: float
    shape: str  # "square" | "round"
    youngs_modulus: float
    poisson_ratio: float

    @property
    def thread_area(self) -> float:
        """Cross-section area of one thread, m^2 (square of side d, or circle of diameter d)."""
        d = self.thread_diameter
        return d * d if self.shape == "square" else math.pi * d * d / 4.0

    @property
    def hoop_stiffness_per_length(self) -> float:
        """Homogenised hoop membrane stiffness E A / pitch, N/m."""
        return self.youngs_modulus * self.thread_area / self.pitch

    @property
    def hoop_bending_stiffness_per_length(self) -> float:
        """The rings' own bending stiffness E I / pitch, N m (I of a square or a round thread)."""
        d = self.thread_diameter
        second_moment = d ** 4 / 12.0 if self.shape == "square" else math.pi * d ** 4 / 64.0
        return self.youngs_modulus * second_moment / self.pitch


@dataclass(frozen=True)
class Device:
    """A tool in the lumen (camera lead, ...). ``bending_stiffness`` in N m^2."""

    diameter: float
    bending_stiffness: float


@dataclass(frozen=True)
class Design:
    name: str
    length: float
    outer_diameter: float
    channels: tuple[Hole | ShapedHole, ...]
    lumen: Hole | ShapedHole | None
    limiting_fibre: LimitingFibre | None
    reinforcement: Reinforcement | None
    cap_thickness: float
    material: YeohMaterial
    device: Device | None
    max_pressure: float
    min_wall_thickness: float = DEFAULT_MIN_WALL
    source: str | None = field(default=None, compare=False)

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def outer_radius(self) -> float:
        return 0.5 * self.outer_diameter

    @cached_property
    def section(self) -> geometry.Section:
        """The cross-section as outlines (core/geometry): what every rung reads."""
        holes = [geometry.SectionHole(f"channels[{i}]", "channel", c.outline, c.shape)
                 for i, c in enumerate(self.channels)]
        if self.lumen is not None:
            holes.append(geometry.SectionHole("lumen", "lumen", self.lumen.outline, self.lumen.shape))
        f = self.limiting_fibre
        fibre = None if f is None else geometry.Circle(f.center, 0.5 * f.diameter)
        return geometry.Section(self.outer_radius, tuple(holes), fibre)

    @property
    def all_circles(self) -> bool:
        """Every hole a circle (what rungs not yet reading outlines need)."""
        return all(isinstance(h, Hole) for h in self.channels + ((self.lumen,) if self.lumen else ()))

    def with_length(self, length: float) -> "Design":
        return replace(self, length=plausible_length(_positive(length, "length")))

    def rotated(self, angle: float) -> "Design":
        """The design with its section turned by ``angle`` (rad, counter-clockwise) about the body
        axis: every hole (any shape) and the fibre, re-validated; the body is a circle."""
        c, s = math.cos(angle), math.sin(angle)

        def turn(p):
            return [c * p[0] - s * p[1], s * p[0] + c * p[1]] + list(p[2:])

        def turn_hole(spec: dict) -> dict:
            if "center" in spec:
                return {**spec, "center": turn(spec["center"])}
            if spec["shape"] == "sector":
                return {**spec, "direction": spec["direction"] + math.degrees(angle)}
            return {**spec, "points": [turn(p) for p in spec["points"]]}

        data = self.to_dict()
        data["channels"] = [turn_hole(h) for h in data["channels"]]
        if data["lumen"] is not None:
            data["lumen"] = turn_hole(data["lumen"])
        if data["limiting_fibre"] is not None:
            data["limiting_fibre"]["center"] = turn(data["limiting_fibre"]["center"])
        return design_from_dict(data, source=self.source)

    def to_dict(self) -> dict:
        """The design as a plain mapping in the design-file schema (round-trips through load)."""
        d = {
            "name": self.name,
            "length": self.length,
            "outer_diameter": self.outer_diameter,
            "channels": [c.spec() for c in self.channels],
            "lumen": None if self.lumen is None else self.lumen.spec(),
            "limiting_fibre": None if self.limiting_fibre is None else {
                "diameter": self.limiting_fibre.diameter,
                "center": list(self.limiting_fibre.center),
                "material": _material_dict(self.limiting_fibre.material)},
            "reinforcement": None if self.reinforcement is None else asdict(self.reinforcement),
            "cap_thickness": self.cap_thickness,
            "material": _material_dict(self.material),
            "device": None if self.device is None else asdict(self.device),
            "limits": {"max_pressure": self.max_pressure},
            "min_wall_thickness": self.min_wall_thickness,
        }
        return d

    def content_hash(self) -> str:
        """Stable hash of everything that affects physics (for result caches)."""
        blob = json.dumps(self.to_dict(), sort_keys=True, default=float).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def per_section_hash(self) -> str:
        """The content hash with the length left out (set to 1 m): what an answer per section
        (the section rung, the closed form, their tables) depends on."""
        return replace(self, length=1.0).content_hash()


def _material_dict(m: YeohMaterial) -> dict:
    return {"model": "yeoh", "c1": m.c1, "c2": m.c2, "c3": m.c3,
            "bulk_modulus": m.bulk_modulus, "density": m.density}


# --------------------------------------------------------------------------- loading

_REQUIRED = ("name", "length", "outer_diameter", "channels", "material", "limits")
_OPTIONAL = {"lumen": None, "limiting_fibre": None, "reinforcement": None, "device": None,
             "cap_thickness": 1.0e-3, "min_wall_thickness": DEFAULT_MIN_WALL, "description": ""}


def resolve_design_path(name_or_path: str | Path) -> Path:
    """A path as given if it exists, else a shipped design by name (with or without .yaml)."""
    from ..resources import ResourceNotFound, find

    try:
        return find("design", name_or_path)
    except ResourceNotFound as exc:
        raise DesignError("design", str(name_or_path), f"no such file or shipped design; shipped: {exc.known}") from None


def load_design(name_or_path: str | Path) -> Design:
    """Load and validate a design file (path, or the name of a shipped design)."""
    path = resolve_design_path(name_or_path)
    return design_from_dict(load_yaml_file(path), source=str(path))


def design_from_dict(data, source: str | None = None) -> Design:
    """The validated design from a design file's mapping (``source``: its path, for CAD outlines beside it)."""
    if not isinstance(data, dict):
        raise DesignError("design", data, "must be a mapping of fields")
    for key in _REQUIRED:
        if key not in data:
            raise DesignError(key, None, "missing required field")
    for key in data:
        if key not in _REQUIRED and key not in _OPTIONAL:
            raise DesignError(key, data[key], f"unknown field; known: {sorted(_REQUIRED + tuple(_OPTIONAL))}")
    get = lambda k: data.get(k, _OPTIONAL.get(k))  # noqa: E731

    name = data["name"]
    if not is_file_name(name):
        raise DesignError("name", name, NAME_RULE)
    length = _positive(data["length"], "length")
    outer = _positive(data["outer_diameter"], "outer_diameter")
    min_wall = _positive(get("min_wall_thickness"), "min_wall_thickness")

    raw_channels = data["channels"]
    if not isinstance(raw_channels, list) or not raw_channels:
        raise DesignError("channels", raw_channels, "must be a non-empty list of holes ({diameter, center} or {shape: ...})")
    base_dir = None if source is None else Path(source).parent   # CAD outlines are found beside the file
    channels = tuple(_hole(c, f"channels[{i}]", base_dir) for i, c in enumerate(raw_channels))
    lumen = None if get("lumen") is None else _hole(get("lumen"), "lumen", base_dir)

    material = material_from_spec(data["material"], "material")

    fibre = None if get("limiting_fibre") is None else _limiting_fibre(get("limiting_fibre"))
    reinforcement = None if get("reinforcement") is None else _reinforcement(get("reinforcement"))
    device = None if get("device") is None else _device(get("device"), lumen)

    limits = _mapping(data["limits"], "limits", {"max_pressure"})
    if "max_pressure" not in limits:
        raise DesignError("limits.max_pressure", None, "missing: every design must state its safe maximum pressure (Pa)")
    max_pressure = _positive(limits["max_pressure"], "limits.max_pressure")
    cap = _positive(get("cap_thickness"), "cap_thickness")

    design = Design(name=name, length=length, outer_diameter=outer, channels=channels, lumen=lumen,
                    limiting_fibre=fibre, reinforcement=reinforcement, cap_thickness=cap,
                    material=material, device=device, max_pressure=max_pressure,
                    min_wall_thickness=min_wall, source=source)
    check_plausible(design)
    if cap >= length:
        raise DesignError("cap_thickness", cap, f"not shorter than the length {length}")
    check_geometry(design)
    if device is not None and isinstance(lumen, ShapedHole):
        room = design.section.largest_inscribed_diameter(design.section.lumen)
        if device.diameter > room + 1e-8:   # a device drawn to the lumen's size fits
            raise DesignError("device.diameter", device.diameter,
                              f"larger than the largest circle the {lumen.kind} lumen holds ({room:.6g} m)")
    return design


def _limiting_fibre(value) -> LimitingFibre:
    f = _mapping(value, "limiting_fibre", {"diameter", "center", "material"})
    return LimitingFibre(
        diameter=_positive(_req(f, "diameter", "limiting_fibre"), "limiting_fibre.diameter"),
        center=_point(_req(f, "center", "limiting_fibre"), "limiting_fibre.center"),
        material=material_from_spec(f.get("material", "polyester_fibre"), "limiting_fibre.material"))


def _reinforcement(value) -> Reinforcement:
    r = _mapping(value, "reinforcement", {"pitch", "thread_diameter", "shape", "youngs_modulus", "poisson_ratio"})
    shape = r.get("shape", "square")
    if shape not in ("square", "round"):
        raise DesignError("reinforcement.shape", shape, "must be 'square' or 'round'")
    nu = _number(_req(r, "poisson_ratio", "reinforcement"), "reinforcement.poisson_ratio")
    if not -1.0 < nu < 0.5:
        raise DesignError("reinforcement.poisson_ratio", nu, "must lie in (-1, 0.5)")
    reinforcement = Reinforcement(
        pitch=_positive(_req(r, "pitch", "reinforcement"), "reinforcement.pitch"),
        thread_diameter=_positive(_req(r, "thread_diameter", "reinforcement"), "reinforcement.thread_diameter"),
        shape=shape,
        youngs_modulus=_positive(_req(r, "youngs_modulus", "reinforcement"), "reinforcement.youngs_modulus"),
        poisson_ratio=nu)
    if reinforcement.thread_diameter > reinforcement.pitch:
        raise DesignError("reinforcement.thread_diameter", reinforcement.thread_diameter,
                          f"larger than the pitch {reinforcement.pitch}: threads would overlap")
    return reinforcement


def _device(value, lumen) -> Device:
    """The tool in the lumen; a circular lumen must be at least as wide (a shaped one is checked on the section)."""
    dv = _mapping(value, "device", {"diameter", "bending_stiffness"})
    device = Device(diameter=_positive(_req(dv, "diameter", "device"), "device.diameter"),
                    bending_stiffness=_nonnegative(_req(dv, "bending_stiffness", "device"),
                                                   "device.bending_stiffness"))
    if lumen is None:
        raise DesignError("device", value, "a device needs a lumen, and lumen is null")
    if isinstance(lumen, Hole) and device.diameter > lumen.diameter:
        raise DesignError("device.diameter", device.diameter, f"larger than the lumen diameter {lumen.diameter}")
    return device


def check_geometry(design: Design) -> None:
    """Outlines simple, holes inside the body with walls >= the minimum (true minimum distance),
    holes apart, fibre inside silicone (core/geometry ``check_section``)."""
    geometry.check_section(design.section, design.min_wall_thickness)


def _mapping(value, field_name, allowed):
    if not isinstance(value, dict):
        raise DesignError(field_name, value, "must be a mapping (or null)")
    for key in value:
        if key not in allowed:
            raise DesignError(f"{field_name}.{key}", value[key], f"unknown key; allowed: {sorted(allowed)}")
    return value


def _hole(value, field_name, base_dir: Path | None = None) -> Hole | ShapedHole:
    """A hole mapping: a circle {diameter, center} (``shape: circle`` optional) or {shape: ...}."""
    kind = geometry.shape_kind(value, field_name)
    if kind != "circle":
        shape = geometry.parse_shape(value, field_name, base_dir)
        outline = geometry.shape_outline(shape, field_name)
        return ShapedHole(shape, tuple(float(c) for c in outline.centroid), field_name, outline)
    m = {k: v for k, v in value.items() if k != "shape"}
    return Hole(diameter=_positive(_req(m, "diameter", field_name), f"{field_name}.diameter"),
                center=_point(_req(m, "center", field_name), f"{field_name}.center"))


def _point(value, field_name) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise DesignError(field_name, value, "must be a list [x, y] in metres")
    return (_number(value[0], f"{field_name}[0]"), _number(value[1], f"{field_name}[1]"))


def _positive(value, field_name) -> float:
    v = _number(value, field_name)
    if v <= 0:
        raise DesignError(field_name, v, "must be positive")
    return v

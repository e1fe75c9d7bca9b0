"""Scenes: what is in the world and what the user needs from a model (docs/architecture.md "Scenes").

A scene file (YAML, SI units) names the design, a device in the lumen, loads or contact,
gravity, the pressure range, the accuracy and the rate required:

    name: free_bending_live
    design: implemented_5mm            # shipped design name or path (relative to the scene file)
    length: 0.040                      # m, optional: the actuated length, if not the design file's
    device: null                       # or {diameter: m, bending_stiffness: N m^2}
    loads: {tip_force: null, contact: null}   # tip_force: [fx, fy, fz] N; contact: see below
    gravity: false                     # or [gx, gy, gz] m/s^2 in softcath_base (e.g. [0, -9.81, 0])
    pressure_range: [0.0, 20000.0]     # Pa, per channel
    required_accuracy: 0.05            # largest acceptable relative error in R_C against the reference
    required_rate: 1000.0              # Hz, commands the model must answer per second

Contact is a plane the tip presses on (frictionless; the tip may slide and rotate on it):

    contact: {kind: tip_plane, normal: [nx, ny, nz], point: [x, y, z] | rest_tip}

``normal`` points from the surface to the side the actuator is on (softcath_base); ``point`` is a
point on the surface (m), or ``rest_tip``: the surface touches the tip of the straight,
unpressurised body (the blocking-force bench's scale, tared at p = 0).

``features`` lists what a model must model for the scene (free bending always; device
stiffness, tip load, contact, gravity when present); model selection (core/model_selection.py)
matches them against the rungs' capabilities.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from .design import Design, Device, load_design
from .checks import finite_number
from .errors import SoftcathError, shown
from .rod.loads import REST_TIP, Loads, TipPlaneContact
from .yaml_io import load_yaml_file

FEATURES = ("free_bending", "device_stiffness", "tip_load", "contact", "gravity")


class SceneError(SoftcathError):
    """A scene field is missing or malformed; names the field and the value found."""

    def __init__(self, field: str, value, reason: str):
        self.field, self.value, self.reason = field, value, reason
        super().__init__(f"scene field '{field}' = {shown(value)}: {reason}")


@dataclass(frozen=True)
class Scene:
    name: str
    design: Design                       # with the scene's device, if it names one
    tip_force: tuple[float, float, float] | None   # N, softcath_base
    contact: TipPlaneContact | None                # a plane the tip presses on
    gravity: tuple[float, float, float] | None     # m/s^2, softcath_base
    pressure_range: tuple[float, float]  # Pa
    required_accuracy: float             # relative R_C error
    required_rate: float                 # Hz
    description: str = ""

    @property
    def features(self) -> tuple[str, ...]:
        need = ["free_bending"]
        if self.design.device is not None:
            need.append("device_stiffness")
        if self.tip_force is not None:
            need.append("tip_load")
        if self.contact is not None:
            need.append("contact")
        if self.gravity is not None:
            need.append("gravity")
        return tuple(need)

    @property
    def loads(self) -> Loads:
        return Loads(tip_force=self.tip_force, gravity=self.gravity, contact=self.contact)


_KEYS = {"name", "description", "design", "length", "device", "loads", "gravity", "pressure_range",
         "required_accuracy", "required_rate"}


def _number(value, field: str, positive: bool = False) -> float:
    v = finite_number(value)
    if v is None:
        raise SceneError(field, value, "must be a finite number")
    if positive and v <= 0:
        raise SceneError(field, v, "must be positive")
    return v


def scene_from_dict(raw, base_dir: Path | None = None) -> Scene:
    if not isinstance(raw, dict):
        raise SceneError("<scene>", raw, "a scene is a mapping of fields")
    unknown = set(raw) - _KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise SceneError(key, raw[key], f"unknown field; known: {', '.join(sorted(_KEYS))}")
    for key in ("name", "design", "pressure_range", "required_accuracy", "required_rate"):
        if key not in raw:
            raise SceneError(key, None, "required")
    name = raw["name"]
    if not isinstance(name, str) or not name:
        raise SceneError("name", name, "must be a non-empty string")
    ref = raw["design"]
    if not isinstance(ref, str):
        raise SceneError("design", ref, "must be a shipped design name or a path")
    if base_dir is not None and (base_dir / ref).is_file():
        ref = str(base_dir / ref)
    try:
        design = load_design(ref)
    except SoftcathError as exc:
        raise SceneError("design", raw["design"], str(exc)) from None
    if raw.get("length") is not None:  # e.g. the 17 mm blocking-force sample of a 40 mm design
        design = design.with_length(_number(raw["length"], "length", positive=True))
    dev = raw.get("device")
    if dev is not None:
        if not isinstance(dev, dict) or set(dev) != {"diameter", "bending_stiffness"}:
            raise SceneError("device", dev, "must be null or {diameter: m, bending_stiffness: N m^2}")
        if design.lumen is None:
            raise SceneError("device", dev, f"design '{design.name}' has no lumen to hold it")
        d = _number(dev["diameter"], "device.diameter", positive=True)
        if d >= design.lumen.diameter:
            raise SceneError("device.diameter", d, f"must be smaller than the lumen ({design.lumen.diameter} m)")
        ei = _number(dev["bending_stiffness"], "device.bending_stiffness")
        if ei < 0:
            raise SceneError("device.bending_stiffness", ei, "must not be negative")
        design = replace(design, device=Device(diameter=d, bending_stiffness=ei))
    loads = raw.get("loads") or {}
    if not isinstance(loads, dict) or set(loads) - {"tip_force", "contact"}:
        raise SceneError("loads", loads, "must be a mapping with tip_force and/or contact")
    tip = loads.get("tip_force")
    if tip is not None:
        tip = _vector(tip, "loads.tip_force", "must be null or [fx, fy, fz] in N")
    contact = _contact(loads.get("contact"))
    gravity = raw.get("gravity", False)
    gravity = None if gravity is False or gravity is None else _vector(
        gravity, "gravity", "must be false or the acceleration [gx, gy, gz] in m/s^2 (softcath_base, "
        "e.g. [0, -9.81, 0])")
    pr = raw["pressure_range"]
    if not isinstance(pr, list) or len(pr) != 2:
        raise SceneError("pressure_range", pr, "must be [low, high] in Pa")
    lo, hi = (_number(v, "pressure_range") for v in pr)
    if not 0 <= lo < hi:
        raise SceneError("pressure_range", pr, "needs 0 <= low < high (Pa)")
    if hi > design.max_pressure:
        raise SceneError("pressure_range", pr, f"exceeds the design's max_pressure {design.max_pressure:g} Pa")
    acc = _number(raw["required_accuracy"], "required_accuracy", positive=True)
    rate = _number(raw["required_rate"], "required_rate", positive=True)
    desc = raw.get("description", "")
    return Scene(name=name, design=design, tip_force=tip, contact=contact, gravity=gravity,
                 pressure_range=(lo, hi), required_accuracy=acc, required_rate=rate,
                 description=desc if isinstance(desc, str) else "")


def _vector(value, field: str, form: str = "must be [x, y, z] (softcath_base)") -> tuple[float, float, float]:
    """Three numbers; ``form`` is the error's reason when ``value`` is not a list of three."""
    if not isinstance(value, list) or len(value) != 3:
        raise SceneError(field, value, form)
    return tuple(_number(v, field) for v in value)


def _contact(raw) -> TipPlaneContact | None:
    if raw is None:
        return None
    form = "null or {kind: tip_plane, normal: [nx, ny, nz], point: [x, y, z] m | rest_tip}"
    if not isinstance(raw, dict) or set(raw) - {"kind", "normal", "point"} or "normal" not in raw:
        raise SceneError("loads.contact", raw, f"must be {form}")
    if raw.get("kind", "tip_plane") != "tip_plane":
        raise SceneError("loads.contact.kind", raw["kind"], "only 'tip_plane' (the tip on a plane) is modelled")
    normal = _vector(raw["normal"], "loads.contact.normal")
    if math.hypot(*normal) == 0:
        raise SceneError("loads.contact.normal", raw["normal"], "must not be zero")
    point = raw.get("point", REST_TIP)
    if point != REST_TIP:
        point = _vector(point, "loads.contact.point")
    return TipPlaneContact(normal=tuple(v / math.hypot(*normal) for v in normal), point=point)


def load_scene(name_or_path: str | Path) -> Scene:
    """A scene file, or the name of a shipped scene."""
    from ..resources import ResourceNotFound, find

    try:
        path = find("scene", name_or_path)
    except ResourceNotFound as exc:
        raise SceneError("<file>", str(name_or_path),
                         f"no such file or shipped scene (shipped: {', '.join(exc.known)})") from None
    raw = load_yaml_file(path)
    return scene_from_dict(raw, base_dir=path.parent)

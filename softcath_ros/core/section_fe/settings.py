"""The section problem's settings (discretisation and solver; all of them enter cache keys) and
the discretised problem they make of a design: what the section rung and the rod's
moment-curvature law (``moment.py``) both solve."""
from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..design import Design
from ..errors import ModelError

if TYPE_CHECKING:   # imported where used: reading the settings (fe3d's lumen_fill check) needs no mesher
    from .mesh import SectionMesh
    from .problem import SectionProblem


@dataclass(frozen=True)
class SectionSettings:
    """Discretisation and solver settings (all of them go into the cache key)."""

    mesh_size: float | None = None      # m; None: outer diameter / 20
    tol: float = 1e-6                   # Newton step tolerance (non-dimensional: u / R, lambda, k R);
                                        # the error left after that step is of the order of its square
    max_newton: int = 10
    initial_step: float = 2000.0        # Pa
    max_step: float = 4000.0            # Pa
    min_step: float = 50.0              # Pa: smallest step (sharp turns of the path need it)
    adaptive: bool = True               # False: fixed steps of initial_step, no cutting
    hoop_tension_only: bool = False     # rings carry compression too (as the reference FE's solid rings)
    ring_bending: bool = True           # the rings' own bending stiffness (E I / pitch): without it a compressed
                                        # ring wrinkles at the element scale (the held section at low pressure)
    min_hole_gap: float = 0.05          # stop when opposite walls of a hole come closer (x its diameter)
    contact_resolution: float = 250.0   # Pa: how finely that pressure is located
    local_radius: float = 5000.0        # Pa: a command this close to a solved one starts from it
    pressure_load: str = "follower"     # "follower": on the deformed channel walls and the end caps;
                                        # "end_cap": only the end caps' axial force (the closed form's load)
    lumen_fill: float | None = None     # fill the empty lumen with a soft compressible solid whose shear
                                        # modulus is this fraction of the silicone's (a self-contact proxy);
                                        # None: empty lumen (with wall contact, below)
    contact_distance: float | None = 0.01  # self-contact of every empty hole's wall: barrier distance as a
                                           # fraction of the hole's diameter (section_fe/terms/contact.py);
                                           # None: no contact, the ramp stops when the walls touch

    def key(self) -> dict:
        """The settings as they enter cache keys; an unset lumen_fill is left out, so results without
        a fill keep the keys they had before the option existed."""
        out = asdict(self)
        if out["lumen_fill"] is None:
            del out["lumen_fill"]
        return out

    def resolved_mesh_size(self, design: Design) -> float:
        return self.mesh_size if self.mesh_size is not None else design.outer_diameter / 20.0


def lumen_fill_fraction(value, rung: str) -> float | None:
    """A rung's ``lumen_fill`` option checked: None (empty lumen) or the fill's shear modulus as a
    fraction in (0, 1) of the silicone's. ``rung`` prefixes the error ("model 'section'", "fe3d")."""
    if value is None:
        return None
    if isinstance(value, bool) or not 0.0 < float(value) < 1.0:
        raise ModelError(f"{rung}: lumen_fill = {value!r} must be a fraction of the silicone's shear modulus "
                         "in (0, 1), or None for an empty lumen")
    return float(value)


@dataclass
class DiscretisedSection:
    mesh: SectionMesh
    mesh_hash: str           # the mesh itself, for cache keys: a mesher change that keeps the node count
                             # must not find the old mesh's answers
    problem: SectionProblem


def discretise(design: Design, settings: SectionSettings) -> DiscretisedSection:
    """The section of ``design`` meshed and posed as ``settings`` say (one-line ModelError for bad ones)."""
    from .mesh import mesh_section
    from .problem import SectionProblem

    h = settings.resolved_mesh_size(design)
    fill = lumen_fill_fraction(settings.lumen_fill, "model 'section'")
    if fill is not None:
        if design.lumen is None:
            raise ModelError(f"model 'section': lumen_fill = {fill!r} but design '{design.name}' has no lumen")
    section = design.section
    mesh = mesh_section(section, h, filled=() if fill is None else (len(section.holes) - 1,))
    if settings.pressure_load not in ("follower", "end_cap"):
        raise ModelError(f"model 'section': pressure_load '{settings.pressure_load}' must be "
                         "'follower' or 'end_cap'")
    mesh_hash = hashlib.sha256(np.ascontiguousarray(mesh.nodes).tobytes()
                               + np.ascontiguousarray(mesh.triangles).tobytes()).hexdigest()[:16]
    problem = SectionProblem(design, mesh, hoop_tension_only=settings.hoop_tension_only,
                             ring_bending=settings.ring_bending,
                             end_cap_only=settings.pressure_load == "end_cap",
                             lumen_fill=fill, contact_distance=settings.contact_distance)
    return DiscretisedSection(mesh=mesh, mesh_hash=mesh_hash, problem=problem)

__all__ = ["DiscretisedSection", "SectionSettings", "discretise", "lumen_fill_fraction"]

"""Blocking force: the scale's normal reaction on the tip, from the rod statics (core/rod).

The blocking-force bench holds the cantilevered actuator horizontally with a scale under its
tip, touching it at p = 0 (the reading there is tared). The force is the reaction of a
frictionless plane through the tip of the straight body, normal to the bending direction, on
a clamped Kirchhoff rod (``core/rod/statics.py``; for the linear law its tip cap is rigid where
the rung keeps the cap straight, ``core/prediction.arc_and_cap``); the tip may slide and rotate
on the scale.
What the sections carry:
- the model is the ``rod`` rung: its own moment-curvature law (from the section rung by
  default: M(kappa, p) of the section held at each curvature, so the stiffening and the wall
  deformation under pressure are in it);
- any other rung: the linear law M = EI (kappa - kappa_free) about that rung's free curvature,
  with the transformed section's EI along the bending direction (device included). For small
  deflection this is F = 3 EI kappa / (2 l), the end moment EI kappa balanced by the tip force.
Gravity is not included: the bench tares the reading at p = 0.
"""
from __future__ import annotations

import numpy as np

from ..core.prediction import arc_and_cap
from ..core.rod.law import LinearLaw
from ..core.rod.loads import PlanarLoads, PlaneContact
from ..core.rod.statics import solve_rod
from ..core.section_properties import transformed_section

N_SEGMENTS = 40


def bench_contact(length: float) -> PlanarLoads:
    """The scale in the bending plane (a along the base axis, b along the bending direction)."""
    return PlanarLoads(contact=PlaneContact(normal=(0.0, -1.0), point=(float(length), 0.0)))


class BlockingForce:
    """Blocking force (N) for one model and sample length l (m); NaN where the model cannot answer."""

    def __init__(self, model):
        self.model = model
        self.stiffness = transformed_section(model.design).bending_stiffness  # (2, 2) N m^2

    def from_curvature(self, curvature: np.ndarray, length: float) -> np.ndarray:
        """From free curvatures (..., 2) 1/m, through the linear law about each of them."""
        k = np.atleast_2d(np.asarray(curvature, dtype=float))
        out = np.zeros(len(k))
        cap = arc_and_cap(self.model, length)[1]
        for i, ki in enumerate(k):
            mag = float(np.hypot(*ki))
            if not np.isfinite(mag):
                out[i] = np.nan
                continue
            if mag == 0:
                continue
            e = ki / mag
            law = LinearLaw(float(e @ self.stiffness @ e), lambda p, mag=mag: mag, source="linear law")
            out[i] = solve_rod(law.at(0.0), length, bench_contact(length), N_SEGMENTS, cap=cap).contact_force
        return out if np.ndim(curvature) > 1 else out[0]

    def __call__(self, pressures, length: float) -> np.ndarray:
        if not self.model.info.solves_backbone:   # free curvature through the linear law
            return self.from_curvature(self.model.evaluate(pressures).curvature, length)
        p = np.asarray(pressures, dtype=float)
        # one ramp through the pressures (the rod's solve of an array), each state from the last
        sols = self.model.solve(np.atleast_2d(p)[:, 0], length=length, loads=bench_contact(length))
        out = np.array([sol.contact_force if sol.converged else np.nan for sol in sols])
        return out if p.ndim > 1 else out[0]

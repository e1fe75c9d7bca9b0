"""fe3d variants kept for comparison studies (benchmarks/fe3d_sensitivity.py, fe3d_rings.py,
fe3d_three_channel.py --mirror-mesh); the production rung (core/models/fe3d.py) has none of them.

* ``formulation="displacement"``: P2 displacement only, the volume penalised directly
  (K/2 (J - 1)^2): locks for nearly incompressible silicone; measures how much a standard element
  would stiffen the body.
* ``reinforcement="rings"``: every ring resolved by the mesh along z (a band per thread, hoop
  stiffness E A / thread width on the bands only) instead of the homogenised membrane.
* ``mirror_mesh=True``: the full body meshed as the half section and its mirror image, so a full
  model shares the half model's discretisation.

Needs the ``fe`` extra (NGSolve).
"""
from __future__ import annotations

from ..core.errors import ModelError
from ..core.fe3d.mesh import build_mesh
from ..core.fe3d.solver import Fe3dProblem, _ng
from ..core.models.fe3d import Fe3dModel


class Fe3dVariantProblem(Fe3dProblem):
    """Fe3dProblem with a displacement-only element and/or resolved rings."""

    def __init__(self, *args, formulation: str = "mixed", reinforcement: str = "membrane", **kwargs):
        self.formulation, self.reinforcement = formulation, reinforcement
        super().__init__(*args, **kwargs)

    def _build_prism(self, design, mesh_settings, half, lumen_fill):
        return build_mesh(design, mesh_settings, half, lumen_fill=lumen_fill, rings=self.reinforcement == "rings")

    def _reinforcement_energy(self, u):
        if self.reinforcement != "rings":
            return super()._reinforcement_energy(u)
        ng = _ng()
        r = self.design.reinforcement
        return ng.Variation(self._hoop_energy(u, r.youngs_modulus * r.thread_area / r.thread_diameter)
                            * ng.ds("ring"))

    def _body_energy(self, F, q, mats):
        if self.formulation != "displacement":
            return super()._body_energy(F, q, mats)
        ng = _ng()
        mesh = self.mesh
        J = ng.Det(F)
        from ..core.energy import isochoric_i1, yeoh

        c = [self.mesh.MaterialCF({k: m[j] for k, m in mats.items()}, default=0.0) for j in range(3)]
        bulk = mesh.MaterialCF({k: m[3] for k, m in mats.items()}, default=1.0)
        mixed = mesh.MaterialCF({k: 1.0 for k in mats}, default=0.0)
        iso = yeoh(isochoric_i1(ng.Trace(F.trans * F), J), *c)
        # q decouples (stays 0); the volume is penalised directly
        return iso + mixed * 0.5 * bulk * (J - 1.0) ** 2 - q * q / 2.0

    def _update_pressure_field(self) -> None:
        if self.formulation != "displacement":
            super()._update_pressure_field()


class Fe3dVariantModel(Fe3dModel):
    """The fe3d rung with the comparison-only options (module docstring); every other option as
    Fe3dModel's. Cached apart from the production rung (the variant enters the key)."""

    name = "fe3d_variant"
    problem_class = Fe3dVariantProblem

    def __init__(self, design, formulation: str = "mixed", reinforcement: str = "membrane",
                 mirror_mesh: bool = False, half: bool | None = None, **options):
        if formulation not in ("mixed", "displacement"):
            raise ModelError(f"fe3d: formulation = {formulation!r} must be 'mixed' or 'displacement'")
        if reinforcement not in ("membrane", "rings"):
            raise ModelError(f"fe3d: reinforcement = {reinforcement!r} must be 'membrane' or 'rings'")
        if mirror_mesh and half is True:
            raise ModelError("fe3d: mirror_mesh meshes the full body: it needs half = False")
        self.formulation, self.reinforcement, self.mirror_mesh = formulation, reinforcement, bool(mirror_mesh)
        super().__init__(design, half=False if mirror_mesh else half, **options)

    def _variant(self) -> dict:
        return {"formulation": self.formulation, "reinforcement": self.reinforcement, "mirror_mesh": self.mirror_mesh}

    def _problem_options(self) -> dict:
        return {"formulation": self.formulation, "reinforcement": self.reinforcement}

    def _turns_to_mirror(self) -> bool:
        return self.mirror_mesh or super()._turns_to_mirror()

    @property
    def problem(self):
        return self.problem_for(None) if self.mirror_mesh else super().problem

    def problem_for(self, direction):
        """``mirror_mesh``: the full body meshed mirror symmetric about the direction's mirror plane,
        or one of the section's; else Fe3dModel's."""
        if not self.mirror_mesh:
            return super().problem_for(direction)
        turn = self.mirror_rotation(direction)
        if turn is None:
            turn = self.mirror_rotation(None)
        if turn is None:
            raise ModelError(f"fe3d: mirror_mesh: {self.design.name}'s section has no mirror plane")
        return self._problem_on("mirror", turn)

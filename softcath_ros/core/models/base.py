"""The interface every rung of the model ladder implements.

A model maps channel pressures (Pa, gauge) to a bend state: the curvature vector
k = (kx, ky) in 1/m and the axial stretch of the backbone. Convention: the
backbone bends *towards* the direction k/|k| in the xy-plane of ``softcath_base``
with curvature |k| (so a channel at +y, which lengthens the +y side, gives k
pointing to -y).

Each rung class declares what it can do in ``info`` (a ``RungInfo``): the scene features it
models, whether it has a linear gain or solves its own backbone, and the options its
constructor takes. Callers read that declaration (or the registry's ``rung_info``), never probe.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from ..design import Design
from ..errors import ModelError
from ..options import Option
from ..scene import FEATURES   # what a rung can model: the scene's features (the envelope's capabilities)


@dataclass(frozen=True)
class RungInfo:
    """What a rung can do, declared on its class (no instance, no heavy import needed)."""

    summary: str                                  # one line: what the rung is
    models: tuple[str, ...] = ("free_bending",)   # scene features it models (FEATURES)
    linear_gain: bool = False        # linear in pressure: ``curvature_per_pa`` (2, C), ``stretch_per_pa`` (C,)
                                     # and the one-command fast path ``curvature_single(p)`` -> (k, stretch)
    pair_jacobian: bool = False      # answers ``pair_jacobian(i, j, p_i, p_j)``: two active channels, the others at
                                     # zero -> (curvature, stretch, dk/dp_i, dk/dp_j) in plain floats, or None
                                     # where it refuses (the surrogate's pair tables; the allocator's Newton)
    solves_backbone: bool = False    # its own backbone and tip pose (BendState.backbone, .tip) replace the arc's,
                                     # and it answers ``solve(pressure, length, loads)`` (planar loads)
    depends_on_length: bool = False  # its answers are of a body of the design's length (end effects, a solved
                                     # backbone), not per section: another length is another body (``at_length``)
    arc_spans_cap: bool = False      # its curvature is of an arc fitted to the whole body's tip, the cap included
                                     # (fe3d); else of the channelled part, the tip cap straight beyond it
    options: tuple[Option, ...] = ()
    more_options: str = ""           # where options not listed go (e.g. "passed to the source rung"); "" = refused
    needs: str = ""                  # optional dependency ("fe" extra), "" = none
    live: bool = True                # answers a command within a second or so, so a node may serve it; False:
                                     # offline only (fe3d: a minute or more per command), a node refuses it
    builds: str = ""                 # what constructing it computes when neither shipped nor cached (a node says
                                     # so at start and shows progress: its ``progress`` option); "" = nothing slow

    def __post_init__(self):
        unknown = [f for f in self.models if f not in FEATURES]
        if unknown:
            raise ValueError(f"RungInfo.models: unknown feature(s) {unknown}; known: {FEATURES}")

    def accepts(self, name: str) -> bool:
        return bool(self.more_options) or any(o.name == name for o in self.options)


def options_of(settings_cls, descriptions: dict[str, str]) -> tuple[Option, ...]:
    """Rung options from a settings dataclass's fields (kind from the annotation) and their descriptions."""
    kinds = {"bool": "bool", "int": "int", "float": "float", "str": "str", "dict": "mapping"}
    out = []
    for f in fields(settings_cls):
        ann = str(f.type).replace(" | None", "")
        out.append(Option(f.name, kinds.get(ann, "object"), descriptions[f.name]))
    return tuple(out)


@dataclass
class TipPose:
    """The tip of a solved body in softcath_base (leading axis N as the BendState's)."""

    position: np.ndarray                      # (..., 3) m
    angle: np.ndarray                         # (...) rad, bending angle at the tip
    orientation_xyzw: np.ndarray | None = None   # (..., 4); None when the rung measures only the position


@dataclass
class SolverDiagnostics:
    """How an iterative rung reached its answer (leading axis N as the BendState's; None: not reported)."""

    newton_iterations: np.ndarray | None = None   # (...) int
    channel_area: np.ndarray | None = None        # (..., C) m^2: section rung's cross-section, fe3d's mid-length
    channel_volume: np.ndarray | None = None      # (..., C) m^3 (fe3d)
    time_s: np.ndarray | None = None              # (...) wall time of the solve at each command (fe3d)
    negative_directions: np.ndarray | None = None  # (...) int: the tangent's negative eigenvalues at the state
                                                   # reached (section; 0: stable, > 0: a saddle, refused; -1: none)
    mesh_nodes: int | None = None
    mesh_size: float | None = None                # m
    cached: bool = False                          # the whole batch came from the disk cache
    law: str = ""                                 # rod: where its moment-curvature law comes from


@dataclass
class BendState:
    """Result of a model evaluation. Batched: leading axis N, or no axis for one command.

    The optional fields are None unless the rung produces them (``RungInfo`` says which)."""

    curvature: np.ndarray       # (..., 2) 1/m
    axial_stretch: np.ndarray   # (...) dimensionless, 1 = unstretched
    converged: np.ndarray       # (...) bool
    message: str = ""           # why a solve did not converge (empty when all did)
    tip: TipPose | None = None                  # the solved body's tip (rod; fe3d: position and angle)
    backbone: np.ndarray | None = None          # (..., n+1, 3) m: joint positions of a solved backbone (rod)
    contact_force: np.ndarray | None = None     # (...) N: the tip's contact reaction (rod with contact)
    radius_l_over_theta: np.ndarray | None = None   # (...) m: R_C = L / theta, inf when straight (fe3d)
    last_converged: list | None = None          # per command: for a failed one, the last state reached on its
                                                # ramp {"pressure", "curvature", "axial_stretch"} (section)
    diagnostics: SolverDiagnostics | None = None

    def has_optional_fields(self) -> bool:
        return not (self.tip is None and self.backbone is None and self.contact_force is None
                    and self.radius_l_over_theta is None and self.last_converged is None
                    and self.diagnostics is None)

    def command(self, i: int) -> "BendState":
        """The state of command ``i`` of a batch, with the leading axis removed from every field."""
        def at(v):
            return None if v is None else v[i]

        tip = None if self.tip is None else TipPose(self.tip.position[i], self.tip.angle[i],
                                                    at(self.tip.orientation_xyzw))
        diag = None
        if self.diagnostics is not None:
            d = self.diagnostics
            diag = replace(d, newton_iterations=at(d.newton_iterations), channel_area=at(d.channel_area),
                           channel_volume=at(d.channel_volume), time_s=at(d.time_s),
                           negative_directions=at(d.negative_directions))
        return replace(self, curvature=self.curvature[i], axial_stretch=self.axial_stretch[i],
                       converged=self.converged[i], tip=tip, backbone=at(self.backbone),
                       contact_force=at(self.contact_force), radius_l_over_theta=at(self.radius_l_over_theta),
                       last_converged=at(self.last_converged), diagnostics=diag)


class BendModel:
    """Base class: subclasses set ``name`` and ``info`` and implement ``_evaluate_batch``."""

    name = "abstract"
    info = RungInfo(summary="abstract rung")
    built_now = False   # True when the constructor built a table the cache did not hold (surrogate)
    solver_version: str | None = None   # bumped when the rung's answers change: part of every cache key
    made_with: dict | None = None       # the options make_model built it with (what ``at_length`` rebuilds with)

    def __init__(self, design: Design):
        self.design = design

    @property
    def n_channels(self) -> int:
        return self.design.n_channels

    @property
    def pressure_range(self) -> tuple[float, float]:
        """Pa: the channel pressures this rung answers. The design's limit unless the rung knows a
        narrower range up front (a table refuses outside the range it was built on)."""
        return 0.0, float(self.design.max_pressure)

    def evaluate(self, pressures) -> BendState:
        """Bend state for one pressure vector (shape (C,)) or a batch (shape (N, C)), Pa."""
        p = np.asarray(pressures, dtype=float)
        single = p.ndim == 1
        batch = p[None, :] if single else p
        if batch.ndim != 2 or batch.shape[1] != self.n_channels:
            raise ModelError(f"model '{self.name}' for design '{self.design.name}' expects "
                             f"{self.n_channels} channel pressure(s) per command, got shape {p.shape}")
        state = self._evaluate_batch(batch)
        if not single:
            return state
        if state.has_optional_fields():
            return state.command(0)
        # the common case, kept cheap (a fast rung answers in microseconds): no optional fields to cut
        state.curvature = state.curvature[0]
        state.axial_stretch = state.axial_stretch[0]
        state.converged = state.converged[0]
        return state

    def _evaluate_batch(self, pressures: np.ndarray) -> BendState:  # pragma: no cover - abstract
        raise NotImplementedError

    def max_principal_stretch(self, pressures) -> float | None:
        """Largest principal stretch in the silicone at a solved command (Pa), for rungs that resolve
        the section's strain field; None for the others."""
        return None

    def at_length(self, length: float) -> "BendModel":
        """This rung for a body of actuated length ``length`` (m). A rung answering per section
        (``info.depends_on_length`` False) is itself: its arc is laid out at that length. One that
        solves a body of the design's length is built again for that length with the options
        ``make_model`` built it with (a rung constructed directly, without them, refuses)."""
        if not self.info.depends_on_length or math.isclose(length, self.design.length, rel_tol=1e-12):
            return self
        if self.made_with is None:
            raise ModelError(f"model '{self.name}' solves a body of design '{self.design.name}''s length "
                             f"({self.design.length * 1e3:.4g} mm), not {length * 1e3:.4g} mm: build it for a "
                             f"design of length {length:.6g} m")
        other = type(self)(self.design.with_length(length), **self.made_with)
        other.made_with = dict(self.made_with)
        return other

"""What every study shares: the rung and pressure it evaluates at, where cases run, and the
result (rows + findings + a plot) that core/studies/output.py writes as CSV, PNG and Markdown."""
from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Callable

from ..design import Design
from ..units import PA_PER_BAR
from .cases import CaseSpec
from .runner import CaseCache, RunStats, run_cases
from .variation import Variant

# R_C at 0.15 bar: the published reference pressure at which the section rung converges on the
# implemented design (it stops near 0.275 bar when the lumen closes; varied designs may stop sooner).
DEFAULT_PRESSURE = 0.15 * PA_PER_BAR


@dataclass
class StudyContext:
    rung: str = "section"
    options: dict = field(default_factory=dict)   # rung options, e.g. {"mesh_size": 4e-4}
    pressure: float = DEFAULT_PRESSURE            # Pa, on channel 0 (other channels at zero)
    channel: int = 0
    workers: int | None = None                    # local processes (default: one per CPU)
    executor: Executor | None = None              # any concurrent.futures executor instead
    cache: CaseCache | bool = True
    progress: bool = True
    stats: RunStats = field(default_factory=RunStats)

    def command(self, design: Design, pressure: float | None = None) -> tuple:
        p = [0.0] * design.n_channels
        p[self.channel if self.channel < design.n_channels else 0] = self.pressure if pressure is None else pressure
        return tuple(p)

    def spec(self, design: Design, pressures: list[float] | None = None) -> CaseSpec:
        """A case: ``design`` at the study pressure, or at each of ``pressures`` (one batch, one ramp)."""
        rows = [self.command(design)] if pressures is None else [self.command(design, p) for p in pressures]
        return CaseSpec(design=design.to_dict(), rung=self.rung, pressures=tuple(rows), options=dict(self.options))

    def solve(self, specs: list[CaseSpec], desc: str) -> list[dict]:
        return run_cases(specs, executor=self.executor, workers=self.workers, cache=self.cache,
                         progress=self.progress, desc=desc, stats=self.stats)

    def evaluate(self, variants: list[Variant], desc: str) -> list[dict]:
        """One table row per variant at the study pressure; infeasible variants are rows too."""
        feasible = [v for v in variants if v.feasible]
        results = iter(self.solve([self.spec(v.design) for v in feasible], desc))
        rows = []
        for v in variants:
            row = {"parameter": v.parameter, "label": v.label, "value": v.value,
                   "baseline": v.baseline, "feasible": v.feasible, **dict(v.info)}
            if not v.feasible:
                row.update(converged=False, radius_of_curvature_mm=None, curvature_per_m=None,
                           max_principal_stretch=None, status=f"infeasible: {v.reason}")
            else:
                r = next(results)["results"][0]
                rc = r["radius_of_curvature_m"]
                row.update(converged=r["converged"], radius_of_curvature_mm=None if rc is None else rc * 1e3,
                           curvature_per_m=None if rc is None else 1.0 / rc,
                           max_principal_stretch=r["max_principal_stretch"],
                           status="ok" if r["converged"] else (
                               r["message"] if r["message"].startswith("case failed")
                               else f"did not converge: {r['message']}"))
            rows.append(row)
        return rows


@dataclass
class StudyResult:
    name: str
    title: str
    design: str
    rows: list[dict]                      # the CSV and Markdown table
    columns: list[tuple[str, str]]        # (row key, Markdown header) for the table
    findings: list[str]                   # one line per trend checked, with numbers
    plot: Callable[[str], None]           # draws the PNG at the path given
    extra_files: dict = field(default_factory=dict)   # name -> text, written beside the outputs
    meta: dict = field(default_factory=dict)

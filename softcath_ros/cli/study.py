"""`softcath study NAME --design D`: a design study (core/studies), written as CSV + PNG + Markdown
(+ JSON) under --out. Cases run on local processes by default, on a Dask cluster with
--scheduler, and are cached per case so an interrupted study resumes where it stopped."""
from __future__ import annotations

import time
from pathlib import Path

from ..core import json_output
from ..core.errors import SoftcathError
from ..core.units import PA_PER_BAR
from .common import add_unit_argument, bounded_int, parse_pressure, positive_float


def register(sub) -> None:
    from ..core.studies import STUDIES

    p = sub.add_parser("study", help="design studies: sensitivity, channel shift, area ratio, device stiffness, "
                                     "miniaturisation, optimisation (CSV + PNG + Markdown)")
    p.add_argument("name", choices=list(STUDIES), help="which study")
    p.add_argument("--design", required=True, help="design YAML file, or the name of a shipped design")
    p.add_argument("--model", default="section", help="model rung (default section)")
    p.add_argument("--pressure", default=None,
                   help="pressure on channel 0 at which R_C is compared, e.g. 0.15bar (default 0.15 bar)")
    add_unit_argument(p, "--pressure")
    p.add_argument("--mesh-size", type=positive_float, default=None,
                   help="section rung element size in m (default: the rung's, outer diameter / 20)")
    p.add_argument("--min-wall", type=positive_float, default=None,
                   help="fabrication minimum wall in m for channel-shift, area-ratio, miniaturise (default 0.2 mm)")
    p.add_argument("--max-stretch", type=positive_float, default=None,
                   help="optimise: largest principal stretch allowed in the silicone (default 2.0)")
    p.add_argument("--workers", type=bounded_int(1, 256), default=None,
                   help="local worker processes (default: one per CPU; 1 solves in this process)")
    p.add_argument("--scheduler", default=None,
                   help="address of a Dask distributed scheduler (tcp://host:8786) to run the cases on "
                        "(needs the 'cluster' extra)")
    p.add_argument("--out", default="studies", help="output directory (default ./studies)")
    p.add_argument("--no-cache", action="store_true", help="solve every case again (the cache is not read)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--json", action="store_true", help="print the study's JSON to stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..core.design import load_design
    from ..core.models import RUNGS, make_model
    from ..core.options import option_names
    from ..core.studies import study_module
    from ..core.studies.context import DEFAULT_PRESSURE, StudyContext
    from ..core.studies.output import write_study
    from ..core.studies.runner import make_executor

    design = load_design(args.design)
    if args.model not in RUNGS:
        make_model(args.model, design)   # raises the 'unknown model' error listing the rungs
    pressure = DEFAULT_PRESSURE if args.pressure is None else parse_pressure(args.pressure, "--pressure", args.unit)
    if not 0 < pressure <= design.max_pressure:
        raise SoftcathError(f"--pressure {pressure / PA_PER_BAR:g} bar: must be positive and at most the design's "
                            f"limit {design.max_pressure / PA_PER_BAR:g} bar")
    options = {}
    if args.mesh_size is not None:
        if args.mesh_size <= 0:
            raise SoftcathError(f"--mesh-size {args.mesh_size}: must be positive (m)")
        options["mesh_size"] = args.mesh_size
    module = study_module(args.name)
    extra = {}
    accepted = option_names(module.OPTIONS)   # what the study declares its run() takes
    for flag, key in (("min_wall", "min_wall"), ("max_stretch", "max_stretch")):
        value = getattr(args, flag)
        if value is not None:
            if key not in accepted:
                raise SoftcathError(f"--{flag.replace('_', '-')}: study '{args.name}' has no such option")
            if value <= 0:
                raise SoftcathError(f"--{flag.replace('_', '-')} {value}: must be positive")
            extra[key] = value
    if args.workers is not None and args.workers < 1:
        raise SoftcathError(f"--workers {args.workers}: need at least 1")
    Path(args.out).mkdir(parents=True, exist_ok=True)   # a folder that cannot be made fails now, not after the run
    executor, where = make_executor(args.workers, args.scheduler)
    ctx = StudyContext(rung=args.model, options=options, pressure=pressure, workers=args.workers,
                       executor=executor, cache=not args.no_cache, progress=not args.quiet)
    t0 = time.perf_counter()
    try:
        result = module.run(design, ctx, **extra)
    finally:
        if executor is not None and args.scheduler is None:
            executor.shutdown(wait=True, cancel_futures=True)
    elapsed = time.perf_counter() - t0
    result.meta.update(wall_time_s=elapsed, cases=ctx.stats.__dict__, executor=where)
    files = write_study(result, ctx, args.out, length=design.length)
    if args.json:
        print(json_output.dumps({"study": result.name, "design": result.design, "rung": ctx.rung, "files": files,
                          "findings": result.findings, "meta": {k: v for k, v in result.meta.items()
                                                                if k not in ("history", "curves")},
                          "rows": result.rows}, indent=2, default=str))
    else:
        print(f"study {result.name} on {design.name}, rung {ctx.rung}, {pressure / PA_PER_BAR:g} bar: "
              f"{ctx.stats.cases} cases ({ctx.stats.cached} cached, {ctx.stats.solved} solved, "
              f"{ctx.stats.errors} failed) on {where} in {elapsed:.1f} s")
        for f in result.findings:
            print(f"- {f}")
        for path in files.values():
            print(f"wrote {path}")
    return 0

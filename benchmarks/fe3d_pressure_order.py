"""fe3d trial: the element pressure's order (Fe3dProblem pressure_order 0: the default P2/P0, 1: P2/P1)
on a ramp with lumen contact, printing per accepted step R_C = L/theta, the lumen wall's smallest hoop
stretch, its smallest det F (core/fe3d/measure.py lumen_wall_stretch) and the smallest gap.

    .venv/bin/python benchmarks/fe3d_pressure_order.py ORDER LENGTH_M TO_BAR MESH CONTACT STEP_BAR
    (MESH: "coarse" for test/test_fe3d.py's mesh or a scale of the default; CONTACT: d_hat / lumen diameter)
    e.g. .venv/bin/python benchmarks/fe3d_pressure_order.py 1 0.01 0.35 coarse 0.02 0.05

Output: stdout (the committed runs: benchmarks/results/fe3d_pressure_order_*.txt).
"""
import sys, time, json, numpy as np
from softcath_ros.core.design import load_design
from softcath_ros.core.fe3d.mesh import MeshSettings
from softcath_ros.core.fe3d.ramp import run_ramp
from softcath_ros.core.fe3d.measure import lumen_wall_stretch
from softcath_ros.core.fe3d.solver import Fe3dProblem, NewtonSettings
COARSE = MeshSettings(section_h=1.0e-3, wall_h=0.7e-3, layer_h=4.5e-3, cap_layers=1)


def main(argv) -> int:
    if len(argv) != 6:
        print(__doc__.split("Output:")[0], file=sys.stderr)
        return 2
    order = int(argv[0]); length = float(argv[1]); to = float(argv[2])
    mesh = COARSE if argv[3] == "coarse" else MeshSettings().scaled(float(argv[3]))
    cd = float(argv[4]); step = float(argv[5])
    d = load_design("implemented_5mm").with_length(length)
    pb = Fe3dProblem(d, mesh, NewtonSettings(threads=1), None, contact_distance=cd, pressure_order=order)
    print("ndof", pb.fes.ndof, flush=True)
    t0 = time.perf_counter()
    class P:
        shown = 0.0
        def update(self, n): self.shown += n
        def set_postfix_str(self, s):
            w = lumen_wall_stretch(pb)
            from softcath_ros.core.fe3d.measure import measure
            m = measure(pb)
            th = m["bending_angle_rad"]
            print(f"{self.shown/1e5:.4f} bar {s} t={time.perf_counter()-t0:.0f}s RC={length/th*1e3 if th>0 else 0:.4f}mm "
                  f"hoop={w['min_hoop_stretch']:.3f} detF={w['min_det_f']:.3f} nrm={w['normal_stretch_there']:.3f} "
                  f"at={np.round(w['min_principal_at_m']*1e3,2)} gap={m.get('lumen_min_gap_m',0)*1e6:.1f}um", flush=True)
    cps = np.round(np.arange(step, to + 1e-9, step), 6) * 1e5
    r = run_ramp(pb, [1.0], cps, progress=P())
    print(r.converged, r.message, f"{time.perf_counter()-t0:.0f}s", flush=True)
    return 0 if r.converged else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""3D finite-element engine of the fe3d rung (NGSolve, imported lazily): mesh, problem, measurement, ramp."""

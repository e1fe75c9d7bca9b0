"""Rod statics with a moment-curvature law (the `rod` rung): laws, loads, the planar solver."""

"""Camera frames of a bent body with known truth: the tracker's tests, its benchmark, and trying
`softcath track` without a camera.

The body is our constant-curvature backbone (core.kinematics: the channelled arc and the straight
cap) drawn with the design's outer diameter and a flat end, seen perpendicular to the bending
plane, on a plain or graph-paper background, with uneven light, blur and noise, and optionally an
ArUco marker on the clamp (its top edge ``marker_gap_mm`` below the base, centred on the axis).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.kinematics import backbone_poses
from .tracker_scene import ARUCO_DICTIONARY
from .vision import cv2_module

SUPERSAMPLE = 4   # the body's edges are anti-aliased by drawing at this multiple and averaging


@dataclass(frozen=True)
class SceneLook:
    size: tuple[int, int] = (1280, 720)      # width, height, px
    mm_per_px: float = 0.08
    base_px: tuple[float, float] = (640.0, 660.0)
    axis_deg: float = -90.0                  # the unbent axis in the image (-90: straight up)
    background: str = "plain"                # or "graph" (1 mm and 10 mm lines)
    grid_darkness: tuple = (0.12, 0.22)      # share of the paper's brightness the 1 mm / 10 mm lines take
    light: float = 0.35                      # brightness falls by up to this share across the frame
    blur_px: float = 1.2                     # Gaussian blur sigma (focus), px
    noise: float = 4.0                       # Gaussian noise sigma, grey levels
    body_grey: int = 60
    paper_grey: int = 235
    marker_mm: float | None = None           # draw an ArUco marker (id 0) of this side on the clamp
    marker_gap_mm: float = 2.0
    seed: int = 0


def truth(theta: float, length: float, cap: float, n: int = 400) -> np.ndarray:
    """Backbone (n, 2) [across, along] in m of a body of ``length`` (channelled arc + ``cap``) bent by ``theta``."""
    arc = length - cap
    pos, _ = backbone_poses(np.array([theta / arc, 0.0]), arc, n, cap)
    return pos[:, [0, 2]]


def render(theta: float, length: float, diameter: float, cap: float = 1e-3, look: SceneLook = SceneLook()):
    """(BGR frame, truth dict: ``bend_angle_deg``, ``tip_mm`` [across, along]) of a body of
    ``length`` and ``diameter`` (m) bent by ``theta`` (rad, positive to the right of the axis as seen)."""
    cv2 = cv2_module()
    rng = np.random.default_rng(look.seed)
    w, h = look.size
    a = math.radians(look.axis_deg)
    along = np.array([math.cos(a), math.sin(a)])
    across = np.array([-along[1], along[0]])
    base = np.asarray(look.base_px, float)
    scale = 1e3 / look.mm_per_px        # px per m

    def to_px(p):  # [across, along] m -> image px
        return base + np.outer(p[:, 1], along) * scale + np.outer(p[:, 0], across) * scale

    bb = truth(theta, length, cap)
    t = np.gradient(bb, axis=0)
    t /= np.hypot(t[:, 0], t[:, 1])[:, None]
    normal = np.column_stack([t[:, 1], -t[:, 0]])     # in [across, along]
    r = 0.5 * diameter
    outline = np.vstack([to_px(bb + r * normal), to_px(bb - r * normal)[::-1]])
    # a clamp behind the base: a dark block (the body leaves it at the base)
    clamp = np.array([[-1.6 * diameter, -0.012], [1.6 * diameter, -0.012], [1.6 * diameter, 0.0],
                      [-1.6 * diameter, 0.0]])
    ss = SUPERSAMPLE
    mask = np.zeros((h * ss, w * ss), np.uint8)
    fix = 16 * ss

    def fill(poly_px, value):
        cv2.fillPoly(mask, [np.round((poly_px + 0.5) * fix - 8).astype(np.int32).reshape(-1, 1, 2)], value,
                     cv2.LINE_8, shift=4)

    if not look.marker_mm:   # (with a marker, the marker is the clamp's face)
        fill(to_px(clamp), 200)
    fill(outline, 255)
    cover = cv2.resize(mask, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0

    img = np.full((h, w), float(look.paper_grey), np.float32)
    if look.background == "graph":
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        for pitch_mm, darken, half_px in ((1.0, look.grid_darkness[0], 0.6), (10.0, look.grid_darkness[1], 1.0)):
            pitch = pitch_mm / look.mm_per_px
            for coord in (xs, ys):
                d = np.abs(((coord + 0.5) % pitch) - pitch / 2) - (pitch / 2 - half_px)
                img *= 1.0 - darken * np.clip(d + 0.5, 0.0, 1.0)
    if look.marker_mm:   # printed with a white margin of one module around it
        side = look.marker_mm / look.mm_per_px
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
        n, pad = 600, 100
        sheet = np.pad(cv2.aruco.generateImageMarker(dictionary, 0, n), pad, constant_values=255).astype(np.float32)
        top_mid = base - along * (look.marker_gap_mm / look.mm_per_px)
        tl = top_mid - across * side / 2      # corners tl, tr, br, bl: upright along the axis
        dst = np.array([tl, tl + across * side, tl + across * side - along * side, tl - along * side], np.float32)
        src = np.array([[pad, pad], [pad + n, pad], [pad + n, pad + n], [pad, pad + n]], np.float32) - 0.5
        warp = cv2.getPerspectiveTransform(src, dst)
        paper = cv2.warpPerspective(sheet, warp, (w, h), flags=cv2.INTER_LINEAR, borderValue=0.0)
        on = cv2.warpPerspective(np.ones_like(sheet), warp, (w, h), flags=cv2.INTER_LINEAR, borderValue=0.0)
        printed = 20.0 + 225.0 * paper / np.maximum(on, 1e-6) / 255.0
        img = (1 - on) * img + on * printed
    img = img * (1 - cover) + look.body_grey * cover
    # uneven light: a slope across the frame and a darker corner
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    light = 1.0 - look.light * (0.6 * xs / w + 0.4 * ((xs / w) ** 2 + (ys / h) ** 2) / 2)
    img *= light
    if look.blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), look.blur_px)
    img += rng.normal(0.0, look.noise, img.shape).astype(np.float32)
    gray = np.clip(np.round(img), 0, 255).astype(np.uint8)
    frame = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    tip = bb[-1] * 1e3
    return frame, {"bend_angle_deg": math.degrees(theta), "tip_mm": [float(tip[0]), float(tip[1])]}


DEMO_LOOK = SceneLook(background="graph", mm_per_px=0.1, base_px=(500.0, 520.0), marker_mm=10.0, marker_gap_mm=2.0)


def write_demo_frames(folder, angles_deg=(0, 45, 90, 135, 180), design_name: str = "implemented_5mm") -> list[dict]:
    """Frames of the design's body at ``angles_deg`` (graph paper, 0.1 mm/px, a 10 mm ArUco marker
    on the clamp 2 mm below the base) as ``frame_NNN.png`` in ``folder``, their truth in
    ``truth.json``; returns the truths."""
    import json
    from pathlib import Path

    from ..core.design import load_design

    cv2 = cv2_module()
    design = load_design(design_name)
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    truths = []
    for i, deg in enumerate(angles_deg):
        frame, t = render(math.radians(deg), design.length, design.outer_diameter, design.cap_thickness,
                          SceneLook(**{**DEMO_LOOK.__dict__, "seed": i}))
        cv2.imwrite(str(out / f"frame_{i:03d}.png"), frame)
        truths.append({"frame": i, **t})
    (out / "truth.json").write_text(json.dumps(truths, indent=1))
    return truths


def main(argv=None) -> int:
    """``python -m softcath_ros.bench.tracker_render FOLDER``: demo frames to try `softcath track` on."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m softcath_ros.bench.tracker_render",
                                 description="render frames of the body with known truth (docs/tracker.md)")
    ap.add_argument("folder")
    args = ap.parse_args(argv)
    truths = write_demo_frames(args.folder)
    print(f"wrote {len(truths)} frames and truth.json to {args.folder}")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())

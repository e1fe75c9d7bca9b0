"""`softcath track INPUT`: measure the bending sample in camera frames (docs/tracker.md).

INPUT is a video file, a folder of images or a camera device index. The scale, base and unbent
direction are set once, on the first frame (given, or from ArUco markers). Per frame: the bend
angle, the tip [across, along] the unbent axis, R_C = l / theta and a quality figure, or why the
frame cannot be measured. ``--json`` writes every frame; ``--overlay DIR`` each frame with the
fitted backbone drawn.
"""
from __future__ import annotations

import sys
from pathlib import Path

from ..core import json_output
from ..core.errors import SoftcathError
from .common import bounded_int, positive_float

PROGRESS_FROM = 50   # frames: longer inputs show a progress bar


def register(sub) -> None:
    p = sub.add_parser("track", help="measure bend angle, tip and R_C of the sample in camera frames")
    p.add_argument("input", metavar="INPUT", help="video file, folder of images, or camera device index (0, 1, ...)")
    scale = p.add_mutually_exclusive_group(required=True)
    scale.add_argument("--mm-per-px", type=positive_float, help="image scale in the bending plane, mm per pixel")
    scale.add_argument("--aruco-mm", type=positive_float,
                       help="scale from ArUco markers (4x4_50) of this printed side (mm) in the bending plane")
    p.add_argument("--base-px", metavar="X,Y", help="the body's centre where it leaves the clamp, pixels")
    p.add_argument("--toward-px", metavar="X,Y", help="a point on the unbent axis beyond the base, pixels")
    p.add_argument("--clamp-marker", type=bounded_int(0, 49), metavar="ID",
                   help="take base and unbent direction from this ArUco marker on the clamp (upright, its top "
                        "edge --clamp-gap-mm below the clamp's exit, centred on the body)")
    p.add_argument("--clamp-gap-mm", type=float, default=0.0,
                   help="distance from the clamp marker's top edge to the base along the axis, mm (default 0)")
    p.add_argument("--length", type=positive_float, help="the sample's length, m (R_C = l / theta; default: "
                   "the backbone length seen)")
    p.add_argument("--cap-mm", type=float, default=0.0,
                   help="the straight tip beyond the bending part, mm (the design's cap_thickness; default 0)")
    p.add_argument("--diameter-mm", type=positive_float, help="the body's width, mm (default: measured on the first frame)")
    p.add_argument("--color", metavar="H,S,V:H,S,V", help="the body's HSV colour range (OpenCV: H 0-179) "
                   "instead of 'darker than the background'")
    p.add_argument("--mirror", action="store_true",
                   help="positive bending is to the left of the unbent axis as seen (default: to the right)")
    p.add_argument("--overlay", metavar="DIR", help="write each frame with the fitted backbone drawn into DIR")
    p.add_argument("--max-frames", type=bounded_int(1, 10**9), help="stop after this many frames (a camera runs until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="machine-readable output: every frame")
    p.set_defaults(func=run)


def build_scene(args, first_frame):
    """The Scene from the arguments and (for markers) the first frame; one-line errors."""
    from ..bench.tracker_scene import scene_from_settings

    return scene_from_settings(first_frame, mm_per_px=args.mm_per_px, aruco_mm=args.aruco_mm, base_px=args.base_px,
                               toward_px=args.toward_px, clamp_marker=args.clamp_marker,
                               clamp_gap_mm=args.clamp_gap_mm, length_m=args.length, cap_mm=args.cap_mm,
                               diameter_mm=args.diameter_mm, color=args.color, mirror=args.mirror)


def run(args) -> int:
    from ..bench.frames import FrameSource
    from ..bench.tracker import Tracker, draw_overlay
    from ..bench.vision import cv2_module

    source = FrameSource(args.input)
    try:
        first = source.first()
        scene = build_scene(args, first.pixels)
        tracker = Tracker(scene)
        overlay = Path(args.overlay) if args.overlay else None
        if overlay is not None:
            overlay.mkdir(parents=True, exist_ok=True)
        results = []
        bar = None
        total = min(source.total or 0, args.max_frames or 10**12) if source.total else None
        if source.live or (total or 0) >= PROGRESS_FROM:
            from tqdm import tqdm

            bar = tqdm(total=total, desc="track", unit="frame", file=sys.stderr)
        interrupted = False
        try:
            for frame in source:
                if args.max_frames is not None and frame.index >= args.max_frames:
                    break
                m = tracker.measure(frame.pixels, frame.index, frame.time_s)
                results.append((frame.name, m))
                if not args.json:
                    print(_line(frame.name, m), flush=True)
                if overlay is not None and frame.pixels is not None:
                    cv2 = cv2_module()
                    target = overlay / f"{Path(frame.name).stem or frame.index}.png"
                    if not cv2.imwrite(str(target), draw_overlay(frame.pixels, m, scene)):
                        raise SoftcathError(f"--overlay {overlay}: cannot write {target.name}")
                if bar is not None:
                    bar.update(1)
        except KeyboardInterrupt:   # Ctrl-C: what was measured is still reported (a camera ends so)
            interrupted = True
        finally:
            if bar is not None:
                bar.close()
    finally:
        source.close()
    measured = sum(1 for _, m in results if m.ok)
    if args.json:
        doc = {"input": str(args.input), "scene": {"mm_per_px": scene.mm_per_px, "base_px": list(scene.base_px),
                                                   "toward_px": list(scene.toward_px), "length_m": scene.length_m,
                                                   "mirror": scene.mirror, "cap_mm": scene.cap_mm,
                                                   "width_mm": (tracker.width_px or 0) * scene.mm_per_px},
               "frames_total": len(results), "frames_measured": measured, "interrupted": interrupted,
               "frames": [dict(m.as_dict(), name=name) for name, m in results]}
        json_output.dump(doc, sys.stdout, indent=1)
        print()
    else:
        print(f"{measured} of {len(results)} frames measured (scale {scene.mm_per_px:.5f} mm/px)"
              + (", interrupted" if interrupted else ""))
    return 130 if interrupted and not source.live else 0


def _line(name: str, m) -> str:
    if not m.ok:
        return f"{name}: not measured: {m.reason}"
    return (f"{name}: theta {m.bend_angle_deg:8.2f} deg  tip [{m.tip_mm[0]:7.2f}, {m.tip_mm[1]:7.2f}] mm  "
            f"R_C {m.radius_of_curvature_mm:8.2f} mm  quality {m.quality:.2f}")

"""The tracker's scene: what is fixed for a run (scale, base, unbent direction, colour), given as
settings or taken once from ArUco markers in the first frame (docs/tracker.md)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import SoftcathError
from .vision import crossings, cv2_module, sample

ARUCO_DICTIONARY = "DICT_4X4_50"   # the marker family we print (docs/tracker.md)


@dataclass(frozen=True)
class Scene:
    """What is fixed for a run. Image coordinates: x right, y down, pixels."""
    mm_per_px: float
    base_px: tuple[float, float]
    toward_px: tuple[float, float]       # any point on the unbent axis beyond the base
    length_m: float | None = None        # the sample's length (R_C = l / theta); None: the measured one
    mirror: bool = False                 # positive bending to the left of the unbent axis (as seen)
    hsv_range: tuple | None = None       # ((h, s, v) low, (h, s, v) high): the body's colour
    diameter_mm: float | None = None     # the body's width; None: measured on the first frame
    cap_mm: float | None = None          # the straight tip beyond the bending part (the design's cap)

    def __post_init__(self):
        if not (math.isfinite(self.mm_per_px) and self.mm_per_px > 0):
            raise SoftcathError(f"scale {self.mm_per_px!r} mm/px: must be a positive number")
        d = np.subtract(self.toward_px, self.base_px)
        if not np.all(np.isfinite(d)) or np.hypot(*d) < 1.0:
            raise SoftcathError("--toward-px must be a point at least 1 px away from --base-px")
        if self.length_m is not None and not (math.isfinite(self.length_m) and 0 < self.length_m < 10):
            raise SoftcathError(f"--length {self.length_m!r}: a sample length in m, e.g. 0.04")
        if self.diameter_mm is not None and not (math.isfinite(self.diameter_mm) and self.diameter_mm > 0):
            raise SoftcathError(f"--diameter-mm {self.diameter_mm!r}: must be a positive number")

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors (image) along the unbent axis and across it (positive bending side)."""
        d = np.subtract(self.toward_px, self.base_px).astype(float)
        d /= np.hypot(*d)
        n = np.array([-d[1], d[0]])      # the right of the axis as seen, looking from base to tip
        return d, (-n if self.mirror else n)


def parse_point(text: str, what: str) -> tuple[float, float]:
    """``X,Y`` pixels, or the one-line error naming ``what``."""
    parts = str(text).split(",")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        raise SoftcathError(f"{what} {text!r}: expected X,Y in pixels, e.g. 640,700") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise SoftcathError(f"{what} {text!r}: must be finite")
    return x, y


def parse_hsv_range(text: str, what: str = "--color") -> tuple:
    """``H,S,V:H,S,V`` (OpenCV ranges: H 0-179, S and V 0-255) -> (low, high)."""
    try:
        lo, hi = (tuple(int(v) for v in part.split(",")) for part in str(text).split(":"))
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError
    except ValueError:
        raise SoftcathError(f"{what} {text!r}: expected H,S,V:H,S,V, e.g. 35,80,40:85,255,255") from None
    tops = (179, 255, 255)
    if any(not 0 <= v <= t for part in (lo, hi) for v, t in zip(part, tops)) or any(a > b for a, b in zip(lo, hi)):
        raise SoftcathError(f"{what} {text!r}: H in 0-179, S and V in 0-255, low <= high")
    return lo, hi


def find_markers(frame) -> list[tuple[int, np.ndarray]]:
    """ArUco markers (``ARUCO_DICTIONARY``) in ``frame``: (id, corners (4, 2) px) each; corners in the
    marker's own order: top-left, top-right, bottom-right, bottom-left."""
    cv2 = cv2_module()
    gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
    detector = cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())
    corners, ids, _ = detector.detectMarkers(gray)
    if ids is None:
        return []
    out = []
    for c, i in zip(corners, ids.ravel()):
        c = np.asarray(c, dtype=float).reshape(4, 2)
        out.append((int(i), _refine_corners(gray, c, cv2)))
    return out


def _refine_corners(gray, corners: np.ndarray, cv2) -> np.ndarray:
    """Marker corners from its four outer edges, each a line fitted through sub-pixel edge points
    (half-way between the white margin and the black border) along the side's middle: the scale is
    only as good as the side measured, and the detector's corners are a pixel short."""
    image = gray.astype(np.float32)
    side = float(np.mean([np.hypot(*(corners[(k + 1) % 4] - corners[k])) for k in range(4)]))
    reach = 0.45 * side / 6                          # within one module (the border is one module wide)
    offsets = np.arange(-reach, reach + 0.125, 0.25)
    lines = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        e = (b - a) / np.hypot(*(b - a))
        outward = np.array([e[1], -e[0]])            # corners run clockwise as seen
        points = []
        for t in np.linspace(0.2, 0.8, 15):
            q = a + t * (b - a)
            prof = sample(image, q[0] + offsets * outward[0], q[1] + offsets * outward[1], cv2)
            if np.isnan(prof).any():
                continue
            cut = crossings(prof, 0.5 * (prof.min() + prof.max()))
            if cut.size == 1:
                points.append(q + (offsets[0] + 0.25 * cut[0]) * outward)
        if len(points) < 5:
            return corners                            # too close to the frame's edge: as detected
        pts = np.asarray(points)
        centre = pts.mean(axis=0)
        direction = np.linalg.svd(pts - centre)[2][0]
        lines.append((centre, direction))
    refined = []
    for k in range(4):   # corner k is where side k-1 meets side k
        (p1, d1), (p2, d2) = lines[k - 1], lines[k]
        t = np.linalg.solve(np.column_stack([d1, -d2]), p2 - p1)
        refined.append(p1 + t[0] * d1)
    return np.asarray(refined)


def scene_from_markers(frame, aruco_mm: float | None, clamp_marker: int | None, clamp_gap_mm: float = 0.0,
                       **scene) -> Scene:
    """The ``Scene`` with the scale and/or the base taken from ArUco markers in ``frame``.

    ``aruco_mm``: the printed side of the markers (mm): mm/px from the clamp marker, else from the
    mean side of every marker found. ``clamp_marker``: the id of the marker on the clamp, upright
    along the unbent axis with its top edge ``clamp_gap_mm`` below the clamp's exit (centred on the
    body): the base lies that far above the edge's midpoint, the unbent direction is the marker's up. Other ``scene`` fields as ``Scene``'s."""
    markers = find_markers(frame)
    if not markers:
        raise SoftcathError(f"no ArUco marker ({ARUCO_DICTIONARY}) found in the first frame")
    chosen = markers
    if clamp_marker is not None:
        chosen = [m for m in markers if m[0] == clamp_marker]
        if not chosen:
            raise SoftcathError(f"--clamp-marker {clamp_marker}: no such marker in the first frame "
                                f"(found ids {sorted(m[0] for m in markers)})")
        c = chosen[0][1]
        up = 0.5 * (c[0] + c[1]) - 0.5 * (c[2] + c[3])
        side_px = float(np.mean([np.hypot(*(c[(k + 1) % 4] - c[k])) for k in range(4)]))
        mm_per_px = aruco_mm / side_px if aruco_mm is not None else scene["mm_per_px"]
        top = 0.5 * (c[0] + c[1]) + up / np.hypot(*up) * clamp_gap_mm / mm_per_px
        scene["base_px"] = (float(top[0]), float(top[1]))
        scene["toward_px"] = (float(top[0] + up[0]), float(top[1] + up[1]))
    if aruco_mm is not None:
        sides = [np.hypot(*(c[(k + 1) % 4] - c[k])) for _, c in chosen for k in range(4)]
        scene["mm_per_px"] = aruco_mm / float(np.mean(sides))
    return Scene(**scene)


def scene_from_settings(first_frame, *, mm_per_px=None, aruco_mm=None, base_px=None, toward_px=None,
                        clamp_marker=None, clamp_gap_mm=0.0, length_m=None, cap_mm=0.0, diameter_mm=None,
                        color=None, mirror=False, flag="--") -> Scene:
    """The Scene from the user's settings (``softcath track``'s options, tracker_node's parameters;
    ``flag`` prefixes their names in errors) and, for markers, the first frame; one-line errors."""
    def name(option: str) -> str:
        return flag + (option.replace("-", "_") if flag != "--" else option)

    if (mm_per_px is None) == (aruco_mm is None):
        raise SoftcathError(f"give the scale: {name('mm-per-px')} or {name('aruco-mm')} (one of them)")
    if clamp_marker is None and (not base_px or not toward_px):
        raise SoftcathError(f"give {name('base-px')} X,Y and {name('toward-px')} X,Y, or {name('clamp-marker')} ID")
    if clamp_marker is not None and (base_px or toward_px):
        raise SoftcathError(f"{name('clamp-marker')} sets the base and axis: leave out {name('base-px')}/"
                            f"{name('toward-px')}")
    if clamp_marker is not None and aruco_mm is None:
        raise SoftcathError(f"{name('clamp-marker')} needs {name('aruco-mm')} (the marker's printed side)")
    if not 0 <= cap_mm < 100 or not 0 <= clamp_gap_mm < 1000:
        raise SoftcathError(f"{name('cap-mm')} and {name('clamp-gap-mm')} are lengths in mm, at least 0")
    fields = dict(length_m=length_m, mirror=mirror, diameter_mm=diameter_mm, cap_mm=cap_mm,
                  hsv_range=parse_hsv_range(color, name("color")) if color else None)
    if clamp_marker is None:
        fields["base_px"] = parse_point(base_px, name("base-px"))
        fields["toward_px"] = parse_point(toward_px, name("toward-px"))
        height, width = first_frame.shape[:2]
        x, y = fields["base_px"]
        if not (0 <= x < width and 0 <= y < height):
            raise SoftcathError(f"{name('base-px')} {base_px}: outside the {width}x{height} frame")
    if aruco_mm is None:
        return Scene(mm_per_px=mm_per_px, **fields)
    fields.setdefault("base_px", (0.0, 0.0))
    fields.setdefault("toward_px", (0.0, -1.0))
    return scene_from_markers(first_frame, aruco_mm, clamp_marker, clamp_gap_mm=clamp_gap_mm, mm_per_px=1.0,
                              **fields)

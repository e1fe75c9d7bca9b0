"""Camera measurement of a bending sample: backbone, bend angle, tip and R_C = l / theta per frame.

The scene (docs/tracker.md): the camera looks perpendicular onto the bending plane; the body is
darker than its background (plain or graph paper, lit unevenly) or lies in an HSV colour range.
The scale (mm per pixel), the base (the body's centre where it leaves the clamp) and the unbent
direction are fixed for a run (``Scene``), given or taken once from ArUco markers (bench/tracker_scene.py).

Per frame ``Tracker.measure`` walks the body from the base: each cross-section perpendicular to the
predicted tangent gives the body's two edges (sub-pixel, at half the body's contrast) and their
midpoint on the centreline; the walk ends where the body does, and the tip is the body's end along
the last tangent. The tangent angle along the backbone is unwrapped (angles beyond 180 deg stay
what they are); the bend angle is its value at the tip from a local fit. A frame it cannot measure
gets ``ok = False`` and the reason, never a guess.

Pure: numpy and OpenCV (the ``vision`` extra, imported here only), no ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .tracker_scene import Scene
from .vision import crossings, cv2_module, sample

BACKBONE_POINTS = 21               # the backbone is resampled to this many points, base to tip
MIN_QUALITY = 0.6                  # fewer clean cross-sections than this share: no measurement
MIN_SECTIONS = 4
LENGTH_TOLERANCE = 0.25            # measured backbone length vs --length: relative deviation allowed
DOWNSCALE = 8                      # background brightness is estimated on a frame this much smaller
NO_BODY = "no body at the base point (darker than the background, or in the colour range)"
SECTION_STEP = 0.25                # cross-sections this many body widths apart
BASE_FIT_SECTIONS = 4              # the first centres that place the base on the centreline
MAX_UNCLEAN_RUN = 4                # this many unclean cross-sections in a row: the body is lost
MAX_TURN = 0.35                    # rad between chords (a body bends < 0.13 rad per step)


@dataclass
class Measurement:
    """One frame's result; the numbers are None when ``ok`` is False (``reason`` says why)."""
    frame: int
    ok: bool
    reason: str = ""
    time_s: float | None = None
    bend_angle_deg: float | None = None
    tip_mm: list | None = None                 # [across, along] the unbent axis from the base
    radius_of_curvature_mm: float | None = None  # l / theta
    quality: float | None = None               # share of clean cross-sections (1 = all)
    width_mm: float | None = None              # median body width seen
    length_measured_mm: float | None = None    # backbone length base to tip as seen
    backbone_mm: list | None = None            # [[across, along], ...] base to tip
    backbone_px: np.ndarray | None = field(default=None, repr=False)   # for the overlay

    def as_dict(self) -> dict:
        out = {k: getattr(self, k) for k in ("frame", "ok", "reason", "time_s", "bend_angle_deg", "tip_mm",
                                             "radius_of_curvature_mm", "quality", "width_mm",
                                             "length_measured_mm", "backbone_mm")}
        if self.ok:
            del out["reason"]
        return out


def _rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


class Tracker:
    """Measures frames of one scene; keeps the body's width and contrast found on the first frame."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.cv2 = cv2_module()
        self.width_px = None if scene.diameter_mm is None else scene.diameter_mm / scene.mm_per_px
        self.contrast = None      # the body's score (0 background, ~1 black) where it is surely body

    # -- the body score: 0 on the background, larger on the body -------------------------------
    def _score_images(self, frame):
        """(image, background): score = 1 - image / background (the background sampled at 1/DOWNSCALE),
        or (the colour mask itself (0..1), None) with ``--color``."""
        cv2 = self.cv2
        if self.scene.hsv_range is not None:
            lo, hi = self.scene.hsv_range
            mask = cv2.inRange(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), lo, hi)
            return cv2.GaussianBlur(mask, (5, 5), 0).astype(np.float32) * (1 / 255.0), None
        gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        small = cv2.resize(gray, (max(1, gray.shape[1] // DOWNSCALE), max(1, gray.shape[0] // DOWNSCALE)),
                           interpolation=cv2.INTER_AREA)
        # the local background: the brightest around, over more than the body's width (the body
        # and graph-paper lines vanish), smoothed: uneven light divides out
        wide = self.width_px if self.width_px is not None else min(gray.shape) / 6
        k = 2 * int(math.ceil(1.2 * wide / DOWNSCALE)) + 1
        bg = cv2.dilate(small, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
        bg = cv2.blur(bg, (k, k)).astype(np.float32)
        return gray, np.maximum(bg, 1.0)

    def _score(self, images, xs, ys):
        image, bg = images
        cv2 = self.cv2
        if bg is None:
            return sample(image, xs, ys, cv2)
        g = sample(image, xs, ys, cv2)
        half = 0.5 * (DOWNSCALE - 1)
        b = sample(bg, (xs - half) / DOWNSCALE, (ys - half) / DOWNSCALE, cv2)
        return 1.0 - g / b

    # -- one cross-section ----------------------------------------------------------------------
    def _section(self, images, point, normal, half_width, threshold):
        """(left, right) edge offsets (px along ``normal``) of the body run nearest ``point``, whether
        both edges were found, or None when no body is there. (Plain Python over the few edges: this
        runs some 40 times a frame.)"""
        u = self._offsets(half_width)
        s = self._score(images, point[0] + u * normal[0], point[1] + u * normal[1])
        outside = np.isnan(s)
        out_any = bool(outside.any())
        if out_any:
            s[outside] = -1.0   # beyond the frame: no body, unless the body reaches there
        first, last = float(u[0]), float(u[-1])
        cuts = (first + 0.5 * crossings(s, threshold)).tolist()
        edges = ([-math.inf] if s[0] > threshold else []) + cuts + ([math.inf] if s[-1] > threshold else [])
        if len(edges) < 2:
            return None
        best, nearest = None, math.inf
        for lo, hi in zip(edges[::2], edges[1::2]):
            mid = abs(max(lo, first) + min(hi, last))
            if mid < nearest:
                best, nearest = (lo, hi), mid
        lo, hi = best
        clean = math.isfinite(lo) and math.isfinite(hi)
        lo, hi = max(lo, first), min(hi, last)
        if out_any and outside[(u >= lo - 2) & (u <= hi + 2)].any():
            raise _LeavesImage
        return lo, hi, clean

    def _offsets(self, half_width):
        key = round(half_width, 3)
        if getattr(self, "_offsets_key", None) != key:
            self._offsets_key, self._offsets_u = key, np.arange(-half_width, half_width + 0.25, 0.5)
        return self._offsets_u

    def _calibrate(self, images) -> str:
        """Width and contrast of the body at the base (first frame); '' or why not."""
        along, across = self.scene.axes
        h = images[0].shape
        point = np.asarray(self.scene.base_px, float)
        half = 0.5 * min(h[0], h[1]) / 4 if self.width_px is None else 1.5 * self.width_px
        u = np.arange(-half, half + 0.25, 0.5)
        best = None
        for step in (0.5, 1.0, 1.5):   # a little way out from the clamp
            p = point + along * step * (self.width_px or 20.0)
            s = self._score(images, p[0] + u * across[0], p[1] + u * across[1])
            if np.isnan(s).any():
                return "the base point lies too close to the frame's edge"
            level = float(np.percentile(s, 95))
            if level < 0.15:
                continue
            inside = s > 0.5 * level
            mid = len(u) // 2
            if not inside[mid]:
                continue
            lo, hi = mid, mid
            while lo > 0 and inside[lo - 1]:
                lo -= 1
            while hi < len(u) - 1 and inside[hi + 1]:
                hi += 1
            if lo == 0 or hi == len(u) - 1:
                continue
            best = (u[hi] - u[lo] + 0.5, float(np.median(s[lo:hi + 1])))
            break
        if best is None:
            return NO_BODY
        if self.width_px is None:
            self.width_px = best[0]
        self.contrast = best[1]
        return ""

    # -- a frame ----------------------------------------------------------------------------------
    def measure(self, frame, index: int = 0, time_s: float | None = None) -> Measurement:
        def fail(reason: str) -> Measurement:
            return Measurement(frame=index, ok=False, reason=reason, time_s=time_s)

        if frame is None or getattr(frame, "ndim", 0) not in (2, 3) or frame.size == 0:
            return fail("unreadable frame")
        if self.scene.hsv_range is not None and (frame.ndim != 3 or frame.shape[2] != 3):
            return fail("a colour range needs colour frames; this one is grey")
        images = self._score_images(frame)
        if self.contrast is None:
            why = self._calibrate(images)
            if why:
                return fail(why)
            images = self._score_images(frame)   # again with the width now known
        try:
            return self._walk(images, index, time_s, frame.shape)
        except _LeavesImage:
            return fail("the body leaves the image")

    @staticmethod
    def _base_on_centreline(pts, along, across):
        """The base moved across onto the body's centreline: the first centres' offsets across the axis
        fitted as a + c s^2 (the body leaves the clamp along the axis, so no linear term); a given base a
        pixel or two off the centre would otherwise shift the tip and tilt the first chord."""
        first = pts[1:1 + BASE_FIT_SECTIONS] - pts[0]
        s, lateral = first @ along, first @ across
        a, _ = np.linalg.lstsq(np.column_stack([np.ones_like(s), s * s]), lateral, rcond=None)[0]
        return pts[0] + a * across

    def _walk(self, images, index, time_s, shape) -> Measurement:
        """The frame's measurement: the body traced from the base, its tip found, the result checked."""
        sc = self.scene
        step = max(2.0, SECTION_STEP * self.width_px)
        expected = (sc.length_m * 1e3 / sc.mm_per_px) if sc.length_m else math.hypot(*shape[:2])
        max_steps = int(2.0 * expected / step) + 8
        centres, widths, clean, ended, lost = self._trace(images, step, max_steps)
        if lost:
            walked = (len(centres) - 1) * step * sc.mm_per_px
            return Measurement(frame=index, ok=False, time_s=time_s,
                               reason=f"lost the body {walked:.0f} mm from the base: something crosses or touches it")
        if not ended:
            return Measurement(frame=index, ok=False, time_s=time_s,
                               reason=f"the body does not end within {max_steps * step * sc.mm_per_px:.0f} mm of the base")
        if len(centres) - 1 < MIN_SECTIONS:
            return Measurement(frame=index, ok=False, time_s=time_s, reason=(
                "too little body beyond the base" if len(centres) > 1 else NO_BODY))
        along, across = sc.axes
        pts = np.asarray(centres)
        pts[0] = self._base_on_centreline(pts, along, across)
        tip = self._tip(images, pts, step)
        if tip is None:
            return Measurement(frame=index, ok=False, time_s=time_s, reason="the tip's end is not clear")
        return self._result(index, time_s, pts, *tip, widths, clean)

    def _trace(self, images, step, max_steps):
        """The body's centres from the base, one cross-section a ``step`` along the predicted tangent:
        (centres, widths of the clean sections, clean per section, whether the body ended, whether it was lost)."""
        along, _ = self.scene.axes
        w = self.width_px
        threshold = 0.5 * self.contrast
        half = 0.9 * w
        centres, widths, clean = [np.asarray(self.scene.base_px, float)], [], []
        chord_dir, turn = along.copy(), 0.0
        unclean_run = 0
        for _ in range(max_steps):
            predicted = _rotate(chord_dir, turn)
            p = centres[-1] + step * predicted
            tangent = _rotate(chord_dir, 1.5 * turn)   # the tangent at p on a circle through the last chords
            normal = np.array([-tangent[1], tangent[0]])
            cut = self._section(images, p, normal, half, threshold)
            if cut is None or cut[1] - cut[0] < 0.5 * w:
                return centres, widths, clean, True, False
            lo, hi, ok = cut
            good = ok and abs(hi - lo - w) < 0.25 * w
            clean.append(good)
            if good:
                offset, unclean_run = 0.5 * (lo + hi), 0
                widths.append(hi - lo)
            else:   # something touches the body: trust the edge that lies where an edge should, else the prediction
                unclean_run += 1
                if unclean_run > MAX_UNCLEAN_RUN:
                    return centres, widths, clean, False, True
                sides = ([lo + 0.5 * w] if lo > -half + 0.5 else []) + ([hi - 0.5 * w] if hi < half - 0.5 else [])
                offset = min(sides, key=abs) if sides else 0.0
                offset = offset if abs(offset) < 0.25 * w else 0.0
            c = p + normal * offset
            chord = c - centres[-1]
            new_dir = chord / np.hypot(*chord)
            new_turn = math.atan2(chord_dir[0] * new_dir[1] - chord_dir[1] * new_dir[0], float(chord_dir @ new_dir))
            if len(centres) > 1:
                if abs(new_turn) > MAX_TURN:
                    return centres, widths, clean, False, True
                turn = new_turn
            chord_dir = new_dir
            centres.append(c)
        return centres, widths, clean, False, False

    def _tip(self, images, pts, step):
        """(tip px, bend angle) from the traced centres: the angle at the bending part's end from a fit of
        the chords' angles, the tip the body's end along the last tangent; None when that end is not clear."""
        sc = self.scene
        along, across = sc.axes
        chords = np.diff(pts, axis=0)
        seg = np.hypot(chords[:, 0], chords[:, 1])
        # tangent angle from the unbent axis, positive towards the bending side, unwrapped
        phi = np.unwrap(np.arctan2(chords @ across, chords @ along))
        s_mid = np.cumsum(seg) - 0.5 * seg
        s_end = float(seg.sum())
        theta = _tip_angle_fit(s_mid, phi, s_end)
        # the tip: the body's end along the last tangent
        t_img = along * math.cos(theta) + across * math.sin(theta)
        threshold = 0.5 * self.contrast
        v = np.arange(0.0, step + self.width_px, 0.5)
        sv = self._score(images, pts[-1][0] + v * t_img[0], pts[-1][1] + v * t_img[1])
        falls = crossings(np.nan_to_num(sv, nan=-1.0), threshold)
        if falls.size and np.isnan(sv[:int(falls[0]) + 4]).any():
            raise _LeavesImage
        if sv[0] <= threshold or falls.size == 0:
            return None
        cap = (sc.cap_mm or 0.0) / sc.mm_per_px
        if cap > 0:   # the bending part ends a cap before the tip: its tangent there, not extrapolated
            theta = _tip_angle_fit(s_mid, phi, s_end + 0.5 * falls[0] - cap)
            t_img = along * math.cos(theta) + across * math.sin(theta)
        return pts[-1] + 0.5 * falls[0] * t_img, theta

    def _result(self, index, time_s, pts, tip, theta, widths, clean) -> Measurement:
        """The measurement from the backbone (centres and tip), or not ok when too little of it was clean
        or its length disagrees with the sample's."""
        sc = self.scene
        along, across = sc.axes
        base = pts[0]
        backbone = np.vstack([pts, tip])
        seg = np.hypot(*np.diff(backbone, axis=0).T)
        s = np.concatenate(([0.0], np.cumsum(seg)))
        quality = float(np.mean(clean))
        widths_mm = float(np.median(widths)) * sc.mm_per_px if widths else math.nan
        length_mm = float(s[-1]) * sc.mm_per_px
        result = Measurement(frame=index, ok=False, time_s=time_s, quality=quality, width_mm=widths_mm,
                             length_measured_mm=length_mm)
        if quality < MIN_QUALITY:
            result.reason = (f"only {quality:.0%} of the body's cross-sections are clean (need "
                             f"{MIN_QUALITY:.0%}): something crosses or touches the body")
            return result
        if sc.length_m and abs(length_mm / (sc.length_m * 1e3) - 1) > LENGTH_TOLERANCE:
            result.reason = (f"the backbone seen is {length_mm:.1f} mm long, --length says "
                             f"{sc.length_m * 1e3:g} mm: the body is hidden, cut or leaves the view")
            return result
        # resampled backbone (px and mm [across, along] from the base)
        si = np.linspace(0.0, s[-1], BACKBONE_POINTS)
        resampled = np.column_stack([np.interp(si, s, backbone[:, 0]), np.interp(si, s, backbone[:, 1])])
        rel = (resampled - base) * sc.mm_per_px
        mm = np.column_stack([rel @ across, rel @ along])
        tip_rel = (tip - base) * sc.mm_per_px
        length = sc.length_m * 1e3 if sc.length_m else length_mm
        result.ok = True
        result.bend_angle_deg = math.degrees(theta)
        result.tip_mm = [float(tip_rel @ across), float(tip_rel @ along)]
        result.radius_of_curvature_mm = length / abs(theta) if theta != 0 else math.inf
        result.backbone_mm = mm.round(4).tolist()
        result.backbone_px = resampled
        return result


def _tip_angle_fit(s_mid, phi, s_at):
    """The tangent angle at arc length ``s_at``: a quadratic in arc length through the chords' angles
    before it (exact for constant curvature, follows a curvature that changes along the body, and
    averages the noise of every cross-section)."""
    keep = s_mid <= s_at
    return float(np.polyval(np.polyfit(s_mid[keep], phi[keep], 2), s_at))


class _LeavesImage(Exception):
    """A cross-section reached beyond the frame."""


def draw_overlay(frame, m: Measurement, scene: Scene):
    """``frame`` (colour copy) with the fitted backbone, base, axis and the result drawn on it."""
    cv2 = cv2_module()
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame.copy()
    along, _ = scene.axes
    base = np.asarray(scene.base_px)
    axis_end = base + along * 0.25 * min(img.shape[:2])
    cv2.line(img, tuple(int(round(v)) for v in base), tuple(int(round(v)) for v in axis_end), (255, 160, 0), 1,
             cv2.LINE_AA)
    if m.ok:
        pts = np.round(m.backbone_px * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], False, (0, 0, 255), 2, cv2.LINE_AA, shift=4)
        tip = tuple(int(round(v)) for v in m.backbone_px[-1])
        cv2.circle(img, tip, 5, (0, 255, 0), 2, cv2.LINE_AA)
        text = (f"theta {m.bend_angle_deg:.1f} deg  tip [{m.tip_mm[0]:.1f}, {m.tip_mm[1]:.1f}] mm  "
                f"R_C {m.radius_of_curvature_mm:.1f} mm  q {m.quality:.2f}")
        colour = (0, 128, 0)
    else:
        text, colour = f"not measured: {m.reason}", (0, 0, 255)
    cv2.putText(img, f"frame {m.frame}: {text}", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2, cv2.LINE_AA)
    return img

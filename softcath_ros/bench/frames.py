"""Frames from a camera device, a video file or a folder of images (OpenCV), with their capture time.

``open_frames(INPUT)`` checks the input at once (one-line ``SoftcathError`` when it is missing or
unreadable) and yields ``Frame``s; a single image in a folder that cannot be read is a frame
without pixels (the tracker says so for that frame), not the end of the run.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import SoftcathError
from .vision import cv2_module

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class Frame:
    index: int
    pixels: np.ndarray | None     # BGR or grey; None: this frame could not be read
    time_s: float | None          # capture time: the video's own clock, or the wall clock for a camera
    name: str = ""


class FrameSource:
    """Iterable of ``Frame``; ``total`` is the number of frames when known (progress), ``live``
    is True for a camera (its frames are stamped with the time they were grabbed)."""

    def __init__(self, spec: str):
        self.spec = str(spec)
        self.total: int | None = None
        self.live = False
        self._files: list[Path] | None = None
        self._capture = None
        path = Path(self.spec)
        cv2 = cv2_module()
        if self.spec.isdigit() and not path.exists():
            self.live = True
            self._capture = cv2.VideoCapture(int(self.spec))
            if not self._capture.isOpened():
                raise SoftcathError(f"camera {self.spec}: cannot be opened (no such device, or busy)")
        elif path.is_dir():
            self._files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not self._files:
                raise SoftcathError(f"{self.spec}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
            self.total = len(self._files)
        elif path.is_file():
            self._capture = cv2.VideoCapture(str(path))
            ok = self._capture.isOpened() and self._capture.grab()
            if not ok:
                raise SoftcathError(f"{self.spec}: not a video OpenCV can read")
            self._capture.release()
            self._capture = cv2.VideoCapture(str(path))
            n = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            self.total = n if n > 0 else None
        else:
            raise SoftcathError(f"{self.spec}: no such file, folder or camera")

    def first(self) -> Frame:
        """The first readable frame (the scene is set up on it), or the one-line error."""
        for f in self:
            self.rewind()
            if f.pixels is not None:
                return f
            break
        raise SoftcathError(f"{self.spec}: the first frame cannot be read")

    def __iter__(self):
        cv2 = cv2_module()
        if self._files is not None:
            for i, p in enumerate(self._files):
                yield Frame(i, cv2.imread(str(p), cv2.IMREAD_COLOR), None, p.name)
            return
        i = 0
        while True:
            ok, pixels = self._capture.read()
            stamp = time.time() if self.live else self._capture.get(cv2.CAP_PROP_POS_MSEC) * 1e-3
            if not ok:
                return
            yield Frame(i, pixels, stamp, f"frame_{i:06d}")
            i += 1

    def rewind(self) -> None:
        """Back to the first frame (files only; a camera goes on)."""
        if self._capture is not None and not self.live:
            self._capture.release()
            self._capture = cv2_module().VideoCapture(self.spec)

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()


class TrackedInput:
    """tracker_node's core: an input (camera, video file or folder) and the tracker set on its first
    frame, in the lifecycle of the device cores (bench/hardware) so nodes/device_node.py drives it:
    ``configure`` opens the input and sets the scene (False and ``reason`` on a fault), ``activate``,
    ``deactivate``, ``next_frame`` and ``measure``, ``close``. No ROS."""

    def __init__(self, spec: str, settings: dict, loop: bool = False):
        self.spec, self.settings, self.loop = str(spec), dict(settings), loop
        self.state, self.reason = "unconfigured", ""
        self.source: FrameSource | None = None
        self.tracker = self.scene = self._frames = None
        self.ended = False
        self.measured = self.unmeasured = 0
        self.last_problem = ""      # why the last frame that could not be measured was not

    @property
    def name(self) -> str:
        return self.spec

    @property
    def live(self) -> bool:
        return self.source is not None and self.source.live

    def configure(self, sleep=None) -> bool:
        from .tracker import Tracker
        from .tracker_scene import scene_from_settings

        try:
            source = FrameSource(self.spec)
            try:
                scene = scene_from_settings(source.first().pixels, flag="", **self.settings)
            except SoftcathError:
                source.close()
                raise
        except SoftcathError as exc:
            self.reason = str(exc)
            return False
        self.source, self.scene, self.tracker, self._frames = source, scene, Tracker(scene), iter(source)
        self.state, self.reason = "inactive", ""
        return True

    def activate(self) -> None:
        self.state = "active"

    def deactivate(self) -> None:
        self.state = "inactive"

    def close(self) -> None:
        if self.source is not None:
            self.source.close()
        self.source = self.tracker = self._frames = None
        self.state = "unconfigured"

    def next_frame(self) -> Frame | None:
        """The next frame, or None once the input has no more (``ended``; a video or folder replays
        from its start with ``loop``)."""
        frame = next(self._frames, None)
        if frame is None and self.loop and not self.source.live:
            self.source.rewind()
            self._frames = iter(self.source)
            frame = next(self._frames, None)
        self.ended = frame is None
        return frame

    def measure(self, frame: Frame):
        """The frame's Measurement; one that is not ``ok`` is counted with its reason (never a guess)."""
        m = self.tracker.measure(frame.pixels, frame.index)
        if m.ok:
            self.measured += 1
        else:
            self.unmeasured += 1
            self.last_problem = m.reason
        return m

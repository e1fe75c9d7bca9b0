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

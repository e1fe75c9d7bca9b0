"""OpenCV for the camera tracker (the ``vision`` extra, imported here only) and sub-pixel sampling of
an image: bilinear samples along a line and where they cross a level."""
from __future__ import annotations

import numpy as np

from ..core.errors import SoftcathError


def cv2_module():
    """OpenCV, or the one-line install hint (it is the ``vision`` extra)."""
    try:
        import cv2
    except ImportError:
        raise SoftcathError("the camera tracker needs OpenCV: pip install 'softcath_ros[vision]' "
                            "(opencv-python-headless)") from None
    # OpenCV's own warnings (a camera index it cannot open, a codec) would add lines to our one-line
    # errors: they are said by us instead
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    return cv2


def sample(image: np.ndarray, xs: np.ndarray, ys: np.ndarray, cv2) -> np.ndarray:
    """Bilinear samples of ``image`` at (xs, ys) (same shape); outside the image: nan."""
    mx = np.ascontiguousarray(xs, dtype=np.float32).reshape(1, -1)
    my = np.ascontiguousarray(ys, dtype=np.float32).reshape(1, -1)
    out = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    return out.reshape(np.shape(xs))


def crossings(values: np.ndarray, threshold: float) -> np.ndarray:
    """Sub-pixel positions (fractional sample index) where ``values`` crosses ``threshold``."""
    above = values > threshold
    i = np.flatnonzero(above[1:] != above[:-1])
    a, b = values[i], values[i + 1]
    return i + (threshold - a) / (b - a)

"""Lens distortion of pixel coordinates: image (distorted) <-> ideal pinhole pixels.

"Ideal" pixels are where a distortion-free camera with the same K would see a point; tag
sides are straight lines there.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["to_ideal", "to_image"]

# The default 5 iterations leave ~0.05 px near the image corners of a k1 = -0.3 lens.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


def to_ideal(pts: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Image points (..., 2) -> ideal pinhole pixels (..., 2) of the same K."""
    pts = np.asarray(pts, dtype=np.float64)
    out = cv2.undistortPoints(pts.reshape(-1, 1, 2), K, dist, None, K,
                              criteria=_UNDISTORT_CRITERIA)
    return out.reshape(pts.shape)


def to_image(pts: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Ideal pinhole pixels (..., 2) -> image points (..., 2) under distortion `dist`."""
    pts = np.asarray(pts, dtype=np.float64)
    flat = pts.reshape(-1, 2)
    norm = np.column_stack([(flat - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T,
                            np.ones(len(flat))])
    out, _ = cv2.projectPoints(norm, np.zeros(3), np.zeros(3), K, dist)
    return out.reshape(pts.shape)

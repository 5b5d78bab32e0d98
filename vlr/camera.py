"""Camera calibration: OpenCV intrinsics plus the camera's pose in the palm frame.

The camera frame here is OpenCV's: +z forward (optical axis), +x right, +y down in the image.
`T_palm_cam` maps camera-frame points to palm-frame points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraCalibration:
    """Pinhole camera with OpenCV distortion, and its extrinsics in the palm frame.

    Attributes:
        width, height: image size [px].
        K: 3x3 camera matrix [px].
        dist: OpenCV distortion coefficients (k1, k2, p1, p2, k3), any length OpenCV takes.
        T_palm_cam: 4x4 homogeneous pose of the OpenCV camera frame in the palm frame [m].
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    T_palm_cam: np.ndarray

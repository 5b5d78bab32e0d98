"""Synthetic AprilTag images with a known pose, for perception tests.

The tag texture (`models.make_tags.tag_image`, black square = 8/10 of its side) is mapped
into the image by the homography of a pinhole camera (OpenCV convention, pixel centres at
integer coordinates), rendered SUPERSAMPLE times finer and box-filtered down, so each pixel
integrates the scene over its area as a real sensor pixel does.

Texture placement in the object frame O (vlr.perception.pose): texel (u, v) of the stored
image (u right, v down) sits at x_O = ((u + 0.5)/N - 0.5) * side, y_O = ((v + 0.5)/N - 0.5) *
side, z_O = 0, where N is the texture size in texels and side = tag_size * 10/8; a camera
whose axes equal O's sees the tag upright.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from vlr.models.make_tags import TEXTURE_PER_BLACK, tag_image

from vlr.camera import CameraCalibration, pose_to_matrix

SUPERSAMPLE = 4
TEXTURE_PIXELS_PER_CELL = 96  # texels finer than the supersampled pixels: no texture blur


@functools.lru_cache(maxsize=8)
def _texture(tag_id: int) -> np.ndarray:
    return tag_image(tag_id, TEXTURE_PIXELS_PER_CELL)


def ideal_calibration(width: int = 640, height: int = 480, fovy_deg: float = 70.0,
                      T_palm_cam: np.ndarray | None = None) -> CameraCalibration:
    """A distortion-free calibration with square pixels and the centred principal point."""
    f = (height / 2) / np.tan(np.radians(fovy_deg) / 2)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    return CameraCalibration(width=width, height=height, K=K, dist=np.zeros(5),
                             T_palm_cam=np.eye(4) if T_palm_cam is None else T_palm_cam)


def pose_cam_object(distance: float, tilt_deg: float = 0.0, tilt_axis_deg: float = 0.0,
                    spin_deg: float = 0.0, offset: tuple[float, float] = (0.0, 0.0)
                    ) -> np.ndarray:
    """T_cam_O for a tag `distance` [m] ahead, its normal tilted by `tilt_deg` about an in-plane
    axis at `tilt_axis_deg` from x, spun by `spin_deg` about its normal, shifted by `offset`
    [m] across the optical axis."""
    a = np.radians(tilt_axis_deg)
    axis = np.array([np.cos(a), np.sin(a), 0.0])
    R = (Rotation.from_rotvec(np.radians(tilt_deg) * axis)
         * Rotation.from_euler("z", spin_deg, degrees=True)).as_matrix()
    return pose_to_matrix([offset[0], offset[1], distance], R)


def render_tag(cal: CameraCalibration, T_cam_O: np.ndarray, tag_id: int, tag_size: float,
               background: int = 60, supersample: int = SUPERSAMPLE) -> np.ndarray:
    """A uint8 grey image of the tag at pose T_cam_O (O = the tag frame of vlr.perception)."""
    tex = _texture(tag_id)
    n = tex.shape[0]
    side = tag_size * TEXTURE_PER_BLACK
    # texel (u, v) -> (x_O, y_O, 1), texel centres at integers, texture edges at -0.5 and n-0.5
    A = np.array([[side / n, 0, (0.5 / n - 0.5) * side],
                  [0, side / n, (0.5 / n - 0.5) * side],
                  [0, 0, 1]])
    s = supersample
    # low-res pixel centre u maps to high-res coordinate s*u + (s-1)/2 (pixel-centre convention)
    S = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]])
    Rt = np.column_stack([T_cam_O[:3, 0], T_cam_O[:3, 1], T_cam_O[:3, 3]])
    H = S @ cal.K @ Rt @ A
    hi = cv2.warpPerspective(tex, H, (cal.width * s, cal.height * s), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    if s == 1:
        return hi
    lo = hi.reshape(cal.height, s, cal.width, s).astype(np.float32).mean(axis=(1, 3))
    return np.clip(np.rint(lo), 0, 255).astype(np.uint8)


def true_corners(cal: CameraCalibration, T_cam_O: np.ndarray, tag_size: float) -> np.ndarray:
    """The black square's corners in the image (4, 2), in the detector's order: the printed
    tag's top-left, top-right, bottom-right, bottom-left."""
    h = tag_size / 2
    pts_O = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]])
    rvec, _ = cv2.Rodrigues(T_cam_O[:3, :3])
    img, _ = cv2.projectPoints(pts_O, rvec, T_cam_O[:3, 3], cal.K, cal.dist)
    return img.reshape(4, 2)


def rotation_error_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of R_a^T R_b [deg]."""
    return float(np.degrees(Rotation.from_matrix(R_a.T @ R_b).magnitude()))

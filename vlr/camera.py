"""Camera calibration: OpenCV intrinsics plus the camera's pose in the palm frame.

The camera frame here is OpenCV's: +z forward (optical axis), +x right, +y down in the image,
and pixel (0, 0)'s CENTRE is at image coordinate (0, 0). `T_palm_cam` maps camera-frame points
to palm-frame points: p_palm = T_palm_cam @ [p_cam, 1].

MuJoCo's camera frame (looks along -z, +y up, +x right) is converted in exactly one place,
`R_MUJOCO_TO_OPENCV` / `calibration_from_mujoco_camera`; nothing else in the project should
flip camera axes.

Calibration file format (YAML; `load_calibration` / `save_calibration`)::

    # vlr camera calibration
    width: 640                       # image size [px]
    height: 480
    camera_matrix:                   # OpenCV K, 3x3, row-major [px]
      - [415.69, 0.0, 319.5]
      - [0.0, 415.69, 239.5]
      - [0.0, 0.0, 1.0]
    dist_coeffs: [0.0, 0.0, 0.0, 0.0, 0.0]   # OpenCV (k1, k2, p1, p2[, k3[, k4, k5, k6 ...]])
    extrinsics:                      # pose of the OpenCV camera frame in the palm frame
      translation: [0.0, 0.0, -0.01]           # camera origin in the palm frame [m]
      rotation:                                # R_palm_cam, 3x3 row-major; its COLUMNS are
        - [1.0, 0.0, 0.0]                      # the camera's x, y, z axes in the palm frame
        - [0.0, 1.0, 0.0]
        - [0.0, 0.0, 1.0]

This example is a camera 10 mm below the palm surface looking up (+z_cam = +z_palm), image
right along +x_palm, image down along +y_palm. Instead of `rotation`, `extrinsics` may give
`quaternion_xyzw: [x, y, z, w]` (scalar LAST, as scipy's `Rotation.from_quat`); exactly one of
the two. `save_calibration` always writes the matrix. A rotation must be orthonormal to 1e-6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from vlr.io import write_text_atomic
from vlr.spec import SpecError, load_yaml_mapping

__all__ = [
    "CalibrationError",
    "CameraCalibration",
    "R_MUJOCO_TO_OPENCV",
    "calibration_from_mujoco_camera",
    "load_calibration",
    "save_calibration",
    "calibration_to_dict",
    "pose_to_matrix",
    "invert_pose",
]

# Rotation taking OpenCV camera-frame coordinates to MuJoCo camera-frame coordinates (and back:
# it is its own inverse). MuJoCo's camera looks along -z with +y up; OpenCV's looks along +z
# with +y down; both have +x to the right. So R_world_cv = R_world_mj @ R_MUJOCO_TO_OPENCV.
R_MUJOCO_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
R_MUJOCO_TO_OPENCV.setflags(write=False)

_ROTATION_TOL = 1e-6
_DIST_LENGTHS = (4, 5, 8, 12, 14)  # what OpenCV's distortion models accept


class CalibrationError(SpecError):
    """A calibration value or file is invalid; the message names the bad key/value (and file).
    A ValueError, and a SpecError so that the CLI prints it as one line."""


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class CameraCalibration:
    """Pinhole camera with OpenCV distortion, and its extrinsics in the palm frame.

    Attributes:
        width, height: image size [px].
        K: 3x3 camera matrix [px] (OpenCV convention: pixel centres at integer coordinates).
        dist: OpenCV distortion coefficients (k1, k2, p1, p2, k3), any length OpenCV takes.
        T_palm_cam: 4x4 homogeneous pose of the OpenCV camera frame in the palm frame [m].

    The arrays are copied to read-only float arrays and validated on construction (finite K
    with positive focal lengths, orthonormal right-handed rotation, positive image size);
    a bad value raises `CalibrationError`.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    T_palm_cam: np.ndarray

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                raise CalibrationError(f"calibration {name} = {v!r} must be a positive integer")
            object.__setattr__(self, name, int(v))
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise CalibrationError(f"calibration K = {self.K!r} must be a finite 3x3 matrix")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise CalibrationError(f"calibration K has focal lengths fx = {K[0, 0]}, "
                                   f"fy = {K[1, 1]}; both must be > 0")
        if not np.allclose(K[1, 0], 0) or not np.allclose(K[2], [0, 0, 1]):
            raise CalibrationError(f"calibration K = {K.tolist()} must have the form "
                                   "[[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
        dist = np.asarray(self.dist, dtype=float).ravel()
        if dist.size not in _DIST_LENGTHS or not np.all(np.isfinite(dist)):
            raise CalibrationError(f"calibration dist = {self.dist!r} must hold "
                                   f"{' or '.join(map(str, _DIST_LENGTHS))} finite numbers")
        T = np.asarray(self.T_palm_cam, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise CalibrationError(f"calibration T_palm_cam = {self.T_palm_cam!r} must be a "
                                   "finite 4x4 matrix")
        if not np.allclose(T[3], [0, 0, 0, 1]):
            raise CalibrationError(f"calibration T_palm_cam last row {T[3].tolist()} must be "
                                   "[0, 0, 0, 1]")
        _check_rotation(T[:3, :3], "calibration T_palm_cam rotation")
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "dist", _readonly(dist))
        object.__setattr__(self, "T_palm_cam", _readonly(T))

    @property
    def T_cam_palm(self) -> np.ndarray:
        """4x4 pose of the palm frame in the camera frame (inverse of `T_palm_cam`)."""
        return invert_pose(self.T_palm_cam)


def _check_rotation(R: np.ndarray, what: str, tol: float = _ROTATION_TOL) -> None:
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > tol:
        raise CalibrationError(f"{what} {np.round(R, 9).tolist()} is not orthonormal "
                               f"(max |R^T R - I| = {err:.2e} > {tol:.0e})")
    if np.linalg.det(R) < 0:
        raise CalibrationError(f"{what} {np.round(R, 9).tolist()} is a reflection "
                               "(det = -1), not a rotation")


# --------------------------------------------------------------------------- poses

def pose_to_matrix(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from a translation (3,) and a 3x3 rotation matrix."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(rotation, dtype=float)
    T[:3, 3] = np.asarray(position, dtype=float)
    return T


def invert_pose(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (uses R^T rather than a general matrix inverse)."""
    T = np.asarray(T, dtype=float)
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


# --------------------------------------------------------------------------- MuJoCo

def calibration_from_mujoco_camera(fovy_deg: float, width: int, height: int,
                                   cam_pos_palm: np.ndarray,
                                   cam_xmat_palm: np.ndarray) -> CameraCalibration:
    """The ideal (distortion-free) calibration of a MuJoCo camera rendering width x height.

    Args:
        fovy_deg: the MuJoCo camera's vertical field of view `fovy` [deg].
        width, height: render size [px].
        cam_pos_palm: the camera's position in the palm frame [m], (3,).
        cam_xmat_palm: the MuJoCo camera's orientation in the palm frame, 3x3, columns = the
            MuJoCo camera axes (as `data.cam_xmat` reshaped to 3x3, if the palm is the world).

    MuJoCo renders with OpenGL: `fovy` spans the full image height measured between pixel
    EDGES, and the optical axis passes through the middle of the viewport, i.e. at edge
    coordinate (width/2, height/2). OpenCV puts pixel (0, 0)'s centre at coordinate 0, so its
    edges are at -0.5 and the optical axis is at ((width - 1)/2, (height - 1)/2). Checked
    against MuJoCo renders (tests/test_camera_calibration.py): a sphere on the optical axis
    lands exactly there, off-axis spheres within 0.07 px (their centroids' own aliasing)
    where (width/2, height/2) is 0.5 px off; rendered tags give poses within 2 um.
    """
    if not (math.isfinite(fovy_deg) and 0 < fovy_deg < 180):
        raise CalibrationError(f"fovy_deg = {fovy_deg!r} must be in (0, 180)")
    f = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    # Square pixels: MuJoCo derives the horizontal extent from the aspect ratio. The principal
    # point is the viewport centre in OpenCV's pixel-centre coordinates (see above).
    K = np.array([[f, 0.0, (width - 1) / 2.0],
                  [0.0, f, (height - 1) / 2.0],
                  [0.0, 0.0, 1.0]])
    R_palm_cv = np.asarray(cam_xmat_palm, dtype=float).reshape(3, 3) @ R_MUJOCO_TO_OPENCV
    return CameraCalibration(width=width, height=height, K=K, dist=np.zeros(5),
                             T_palm_cam=pose_to_matrix(np.asarray(cam_pos_palm, float).ravel(),
                                                       R_palm_cv))


# --------------------------------------------------------------------------- YAML

def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CalibrationError(f"{where} = {value!r} must be a number")
    if not math.isfinite(value):
        raise CalibrationError(f"{where} = {value!r} must be finite")
    return float(value)


def _array(value: Any, shape: tuple[int, ...], where: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=object)
    except ValueError:  # ragged nested lists
        raise CalibrationError(f"{where} = {value!r} must have shape {shape}") from None
    if arr.shape != shape:
        raise CalibrationError(f"{where} = {value!r} must have shape {shape}, got {arr.shape}")
    return np.array([_number(v, where) for v in arr.ravel()], dtype=float).reshape(shape)


def _calibration_from_dict(data: Any) -> CameraCalibration:
    if not isinstance(data, dict):
        raise CalibrationError(f"must hold a mapping, got {type(data).__name__}")
    for key in ("width", "height", "camera_matrix", "dist_coeffs", "extrinsics"):
        if key not in data:
            raise CalibrationError(f"missing key {key!r}")
    unknown = set(data) - {"width", "height", "camera_matrix", "dist_coeffs", "extrinsics"}
    if unknown:
        raise CalibrationError(f"unknown keys {sorted(unknown)}")
    size = {}
    for key in ("width", "height"):
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise CalibrationError(f"{key} = {v!r} must be a positive integer")
        size[key] = v
    K = _array(data["camera_matrix"], (3, 3), "camera_matrix")
    dist_raw = data["dist_coeffs"]
    if not isinstance(dist_raw, list):
        raise CalibrationError(f"dist_coeffs = {dist_raw!r} must be a list of numbers")
    dist = _array(dist_raw, (len(dist_raw),), "dist_coeffs")
    ext = data["extrinsics"]
    if not isinstance(ext, dict):
        raise CalibrationError(f"extrinsics = {ext!r} must be a mapping")
    unknown = set(ext) - {"translation", "rotation", "quaternion_xyzw"}
    if unknown:
        raise CalibrationError(f"extrinsics has unknown keys {sorted(unknown)} (expected "
                               "translation and one of rotation, quaternion_xyzw)")
    if "translation" not in ext:
        raise CalibrationError("missing key 'extrinsics.translation'")
    t = _array(ext["translation"], (3,), "extrinsics.translation")
    if ("rotation" in ext) == ("quaternion_xyzw" in ext):
        raise CalibrationError("extrinsics needs exactly one of 'rotation' (3x3) and "
                               "'quaternion_xyzw' ([x, y, z, w])")
    if "rotation" in ext:
        R = _array(ext["rotation"], (3, 3), "extrinsics.rotation")
        _check_rotation(R, "extrinsics.rotation")
    else:
        q = _array(ext["quaternion_xyzw"], (4,), "extrinsics.quaternion_xyzw")
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-6:
            raise CalibrationError(f"extrinsics.quaternion_xyzw = {q.tolist()} must have unit "
                                   f"norm, got {norm:.9f}")
        R = Rotation.from_quat(q).as_matrix()
    return CameraCalibration(width=size["width"], height=size["height"], K=K, dist=dist,
                             T_palm_cam=pose_to_matrix(t, R))


def load_calibration(path: str | Path) -> CameraCalibration:
    """Read a calibration YAML file (format in the module docstring).

    Raises:
        CalibrationError: (a ValueError) naming the file and the bad key or value.
    """
    data = load_yaml_mapping(path, "calibration file", CalibrationError)
    try:
        return _calibration_from_dict(data)
    except CalibrationError as exc:
        raise CalibrationError(f"calibration file {path}: {exc}") from None


def calibration_to_dict(cal: CameraCalibration) -> dict[str, Any]:
    """The YAML mapping `save_calibration` writes (plain Python floats, exact round trip)."""
    return {
        "width": int(cal.width),
        "height": int(cal.height),
        "camera_matrix": cal.K.tolist(),
        "dist_coeffs": cal.dist.tolist(),
        "extrinsics": {
            "translation": cal.T_palm_cam[:3, 3].tolist(),
            "rotation": cal.T_palm_cam[:3, :3].tolist(),
        },
    }


def save_calibration(cal: CameraCalibration, path: str | Path) -> None:
    """Write `cal` as YAML, atomically: a temporary file in the same folder, then os.replace,
    so a reader never sees a half-written calibration."""
    path = Path(path)
    text = "# vlr camera calibration (format: vlr/camera.py)\n" + yaml.safe_dump(
        calibration_to_dict(cal), sort_keys=False, default_flow_style=None)
    write_text_atomic(path, text)

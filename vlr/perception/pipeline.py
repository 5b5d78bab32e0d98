"""`observe`: one camera image in, the POM pose in the palm frame out (or None)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vlr.camera import CameraCalibration
from vlr.perception import lens
from vlr.perception.detect import DetectorConfig, detect_tags, refine_edges
from vlr.perception.pose import solve_tag_pose

__all__ = ["Observation", "observe", "to_gray"]

_N_TAG_IDS = 587          # tag36h11
_MIN_CONTRAST = 20        # grey levels: a frame flatter than this holds no readable tag


@dataclass(frozen=True)
class Observation:
    """A tag seen by the palm camera.

    Attributes:
        position: the POM (tag centre, origin of the object frame O) in the palm frame [m], (3,).
        rotation: R_palm_O, 3x3: the columns are O's axes in the palm frame.
        reprojection_px: RMS distance between the corners and the pose's projection [px].
        corners: the black square's corners in the image (4, 2) [px], OpenCV pixel-centre
            convention, detector order (printed tag's top-left, top-right, bottom-right,
            bottom-left).
        tag_pose_cam: T_cam_O, 4x4, the tag in the OpenCV camera frame [m].
        refined: the corners come from the edge-line refinement (about 0.01 px); False means
            aruco's SUBPIX corners (about 0.15 px), only with `observe(allow_unrefined=True)`.
    """

    position: np.ndarray
    rotation: np.ndarray
    reprojection_px: float
    corners: np.ndarray
    tag_pose_cam: np.ndarray
    refined: bool = True

    @property
    def T_palm_object(self) -> np.ndarray:
        """4x4 pose of O in the palm frame."""
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.position
        return T


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def to_gray(image: np.ndarray) -> np.ndarray:
    """A uint8 grey view/copy of a uint8 image (H, W), (H, W, 1), (H, W, 3) or (H, W, 4).

    Three channels are read as RGB (MuJoCo's order); for a black-and-white tag RGB and BGR
    give the same grey. Raises ValueError for another dtype or shape.
    """
    if image.dtype != np.uint8:
        raise ValueError(f"image dtype {image.dtype} must be uint8")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_RGBA2GRAY)
    raise ValueError(f"image shape {image.shape} must be (H, W), (H, W, 1), (H, W, 3) "
                     "or (H, W, 4)")


def _check_args(calibration: CameraCalibration, tag_id: int, tag_size: float,
                max_reprojection_px: float, border_margin_px: float) -> None:
    if not isinstance(calibration, CameraCalibration):
        raise ValueError(f"calibration {type(calibration).__name__} must be a "
                         "CameraCalibration")
    if isinstance(tag_id, bool) or not isinstance(tag_id, (int, np.integer)) \
            or not 0 <= tag_id < _N_TAG_IDS:
        raise ValueError(f"tag_id {tag_id!r} must be a tag36h11 id (0..{_N_TAG_IDS - 1})")
    if isinstance(tag_size, bool) or not isinstance(tag_size, (int, float, np.floating)) \
            or not math.isfinite(tag_size) or tag_size <= 0:
        raise ValueError(f"tag_size {tag_size!r} must be a finite length > 0 [m]")
    if not (isinstance(max_reprojection_px, (int, float, np.floating))
            and max_reprojection_px > 0):
        raise ValueError(f"max_reprojection_px {max_reprojection_px!r} must be > 0")
    if not (isinstance(border_margin_px, (int, float, np.floating)) and border_margin_px >= 0):
        raise ValueError(f"border_margin_px {border_margin_px!r} must be >= 0")


def observe(image: np.ndarray | None, calibration: CameraCalibration, tag_id: int,
            tag_size: float, *, max_reprojection_px: float = 2.0,
            border_margin_px: float = 3.0, allow_unrefined: bool = False,
            config: DetectorConfig | None = None) -> Observation | None:
    """The pose of tag `tag_id` (black square `tag_size` [m]) in the palm frame, or None.

    Pipeline: grey image; AprilTag 36h11 detection (vlr.perception.detect); corners of the
    requested id refined by line fits to the square's sides (undistorted first if the
    calibration has distortion); IPPE_SQUARE pose with fallbacks and LM refinement
    (vlr.perception.pose); mapped to the palm frame through `calibration.T_palm_cam`.

    Returns None, never a stale or partial pose, when the image is None, empty or flat (e.g.
    black); no tag or only other ids are found; the id is found more than once; a corner lies
    within `border_margin_px` of the image edge (a tag partly out of view); the corners do
    not refine (cells under 2.5 px across, an edge largely hidden) unless `allow_unrefined`;
    the pose is not finite or lies behind the camera; or the RMS reprojection error exceeds
    `max_reprojection_px`. (Four corners always fit a square closely, so the reprojection
    check only catches gross failures.)

    `allow_unrefined` accepts aruco's SUBPIX corners from the full detector when the edge
    refinement fails, flagged `refined=False`: about 10x the pose error for tags of a few
    hundred pixels, and mm or degrees for tags of 30 px, so the default refuses them.

    Raises:
        ValueError: for bad arguments: a non-uint8 image or one of another shape or size than
            the calibration's, tag_size <= 0, an id outside 0..586, or non-positive thresholds.
    """
    _check_args(calibration, tag_id, tag_size, max_reprojection_px, border_margin_px)
    if image is None:
        return None
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        return None
    gray = to_gray(image)
    if gray.shape != (calibration.height, calibration.width):
        raise ValueError(f"image size {gray.shape[1]}x{gray.shape[0]} does not match the "
                         f"calibration's {calibration.width}x{calibration.height}")
    lo, hi = cv2.minMaxLoc(gray)[:2]
    if hi - lo < _MIN_CONTRAST:
        return None
    gray = np.ascontiguousarray(gray)

    config = config or DetectorConfig()
    h, w = gray.shape
    K, dist = calibration.K, calibration.dist
    distorted = bool(np.any(dist != 0))
    # The fast (ArUco3) detector first; the full one if it misses the tag or its corners do
    # not refine. Unrefined corners are used only from the full detector (SUBPIX, within
    # ~0.5 px); the fast one's can be 3 px off.
    ideal = fallback = None
    for fast in ((True, False) if config.fast_min_side_ratio is not None else (False,)):
        found = [d for d in detect_tags(gray, config, fast) if d.tag_id == tag_id]
        if len(found) > 1:  # a duplicated id: no way to tell which is the object's
            return None
        if not found:
            continue
        seed = found[0].corners
        m = border_margin_px
        if np.any(seed[:, 0] < m) or np.any(seed[:, 0] > w - 1 - m) \
                or np.any(seed[:, 1] < m) or np.any(seed[:, 1] > h - 1 - m):
            return None
        ideal = refine_edges(gray, seed, K, dist)
        if ideal is not None:
            break
        if not fast:
            fallback = seed
    if ideal is not None:
        result = solve_tag_pose(ideal, tag_size, K, None)
        corners = lens.to_image(ideal, K, dist) if distorted else ideal
    elif fallback is not None and allow_unrefined:
        # flagged by refined=False: about 0.15 px corners, ~10x the pose error
        result = solve_tag_pose(fallback, tag_size, K, dist)
        corners = fallback
    else:
        return None
    if result is None:
        return None
    T_cam_O, rms = result
    if not (np.all(np.isfinite(T_cam_O)) and math.isfinite(rms)) or T_cam_O[2, 3] <= 0:
        return None
    if rms > max_reprojection_px:
        return None
    T_palm_O = calibration.T_palm_cam @ T_cam_O
    return Observation(position=_frozen(T_palm_O[:3, 3]), rotation=_frozen(T_palm_O[:3, :3]),
                       reprojection_px=float(rms), corners=_frozen(corners),
                       tag_pose_cam=_frozen(T_cam_O), refined=ideal is not None)

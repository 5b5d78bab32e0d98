"""A ChArUco board and an AprilTag as the simulated palm camera sees them, and the calibration
that camera truly has: the views `vlr camera-calibrate --sim` and its tests calibrate on.

The scene is the palm camera alone, with the sim's field of view (sim.model.CAMERA_FOVY_DEG)
and image size, mounted a little off the palm axis and tilted (MOUNT_POS, MOUNT_TILT_DEG), and
the printed board and tag as unlit cards on mocap bodies. Poses are in the palm frame: a
position [m] and a rotation vector [deg]; the identity faces the camera, and a tag's body
frame is the `--tag-pose` frame of `vlr camera-calibrate`.

The lens: a barrel lens's image corners see rays from outside the pinhole field of view, so
the scene is rendered a margin larger on each side at the same focal length (a wider fovy);
each output pixel reads that render at its undistorted position (the maps of
sim.camera_effects, shifted by the margin). Then the sensor's effects (exposure, blur, noise)
apply. The truth: K of the MJCF camera (vlr.camera.calibration_from_mujoco_camera) cropped to
the output, dist = the lens's coefficients, T_palm_cam = the camera's mounting.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import mujoco
import numpy as np
from scipy.spatial.transform import Rotation
from vlr.models.make_tags import TEXTURE_PER_BLACK, tag_image
from vlr.sim.camera_effects import CameraEffects, apply_effects, distortion_maps
from vlr.sim.model import CAMERA_FOVY_DEG, CAMERA_HEIGHT

from vlr.camera import CameraCalibration, calibration_from_mujoco_camera, invert_pose
from vlr.errors import UserError
from vlr.perception import lens

__all__ = ["DEFAULT_EFFECTS", "CalibrationViews", "RenderingUnavailable", "SimTag",
           "board_poses", "compare_to_truth", "lens_gap_px", "render_board_views"]

Pose = tuple[Sequence[float], Sequence[float]]  # position [m], rotation vector [deg]

WIDTH, HEIGHT = 640, 480                      # the palm camera's render (sim SimOptions)
# The camera sits 1.5 mm and 1 mm off the palm axis, tilted by about 2 degrees.
MOUNT_POS = (0.0015, -0.001, CAMERA_HEIGHT)
MOUNT_TILT_DEG = (1.5, -1.2, 0.8)
# A barrel lens with small tangential terms (k1, k2, p1, p2, k3), a sensor of 1.5 grey levels.
DEFAULT_EFFECTS = CameraEffects(noise_std=1.5, distortion=(-0.12, 0.03, 4e-4, -3e-4, 0.0))
PIXELS_PER_SQUARE = 120                       # board texture resolution
# Sampled board poses: the palm camera's working distance [m], the tilt about an axis in the
# board's plane [deg], and how far from the image centre the board's centre goes (share of
# the half width and height); a pose is kept when most corners are well inside the image.
DEPTH_M = (0.085, 0.14)
TILT_DEG = (15.0, 35.0)
REACH = 0.75
MIN_CORNERS_INSIDE = 0.6
BORDER_PX = 10.0
MAX_OBLIQUE_DEG = 55.0


class RenderingUnavailable(UserError):
    """MuJoCo cannot render offscreen here (no EGL)."""


@dataclass(frozen=True)
class SimTag:
    """The AprilTag 36h11 of the scene: its id, black square side [m] and pose in the palm
    (X Y Z [m], RX RY RZ [deg]), 65 mm above the palm, turned and tilted a little."""

    tag_id: int = 7
    size: float = 0.02
    pose: tuple[float, float, float, float, float, float] = (0.003, -0.004, 0.065,
                                                             4.0, -6.0, 25.0)


@dataclass(frozen=True)
class CalibrationViews:
    """Rendered RGB uint8 images of the board (one per pose) and of the tag (None without
    one), the board poses, and the calibration of the camera that saw them."""

    boards: list[np.ndarray]
    tag: np.ndarray | None
    poses: list[Pose]
    truth: CameraCalibration


def _png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    assert ok, "PNG encoding of an in-memory texture"
    return buf.tobytes()


def _numbers(values: Sequence[float]) -> str:
    return " ".join(repr(float(x)) for x in values)


def _scene_xml(board_size: tuple[float, float], tag_side: float, fovy: float, width: int,
               height: int) -> str:
    cam_quat = (Rotation.from_rotvec(MOUNT_TILT_DEG, degrees=True)
                * Rotation.from_euler("x", 180, degrees=True)).as_quat(scalar_first=True)
    # Emissive, unlit materials: the texture's grey levels reach the image unshaded. Each
    # card is a thin box turned by pi about x so that its textured face, at z = 0 of its body,
    # looks at the camera unmirrored (as sim/model.py does for the object tags).
    return f"""<mujoco>
      <visual><headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
        <quality offsamples="8"/><global offwidth="{width}" offheight="{height}"/></visual>
      <asset>
        <texture name="board" type="2d" file="board.png"/>
        <texture name="tag" type="2d" file="tag.png"/>
        <material name="board" texture="board" emission="1" specular="0" rgba="1 1 1 1"/>
        <material name="tag" texture="tag" emission="1" specular="0" rgba="1 1 1 1"/>
      </asset>
      <worldbody>
        <camera name="palm_camera" pos="{_numbers(MOUNT_POS)}"
                quat="{_numbers(cam_quat)}" fovy="{fovy!r}"/>
        <body name="board" mocap="true" pos="0 0 -1">
          <geom type="box" size="{board_size[0] / 2!r} {board_size[1] / 2!r} 0.0005"
                pos="0 0 0.0005" quat="0 1 0 0" material="board"/>
        </body>
        <body name="tag" mocap="true" pos="0 0 -1">
          <geom type="box" size="{tag_side / 2!r} {tag_side / 2!r} 0.0005" pos="0 0 0.0005"
                quat="0 1 0 0" material="tag"/>
        </body>
      </worldbody></mujoco>"""


def _margin(K: np.ndarray, distortion: Sequence[float], width: int,
            height: int) -> tuple[int, int]:
    """Pixels to render beyond each side so that every output pixel's ray is in the render
    (plus one for the bilinear lookup)."""
    map_x, map_y = distortion_maps(K, tuple(distortion), width, height)
    over_x = max(0.0, -float(map_x.min()), float(map_x.max()) - (width - 1))
    over_y = max(0.0, -float(map_y.min()), float(map_y.max()) - (height - 1))
    return math.ceil(over_x) + 1, math.ceil(over_y) + 1


def _board_corners(board: cv2.aruco.CharucoBoard) -> np.ndarray:
    """The inner chessboard corners (N, 3) [m] about the board's centre (a symmetric set:
    the same in the card's frame and in OpenCV's board frame turned about the centre)."""
    sx, sy = board.getChessboardSize()
    s = board.getSquareLength()
    x, y = np.meshgrid((np.arange(1, sx) - sx / 2) * s, (np.arange(1, sy) - sy / 2) * s)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def _pose_matrix(pose: Pose) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(pose[1], degrees=True).as_matrix()
    T[:3, 3] = pose[0]
    return T


def _pose_fits(board_corners: np.ndarray, T_palm_board: np.ndarray,
               truth: CameraCalibration) -> bool:
    """Most corners inside the image (inside the lens's valid field too), the board not seen
    too obliquely."""
    T = invert_pose(truth.T_palm_cam) @ T_palm_board
    pts = board_corners @ T[:3, :3].T + T[:3, 3]
    if np.any(pts[:, 2] <= 0):
        return False
    normal_cos = abs(T[:3, 2] @ (-T[:3, 3] / np.linalg.norm(T[:3, 3])))
    if normal_cos < math.cos(math.radians(MAX_OBLIQUE_DEG)):
        return False
    K = truth.K
    ideal = (pts[:, :2] / pts[:, 2:]) * np.diag(K)[:2] + K[:2, 2]
    image = lens.to_image(ideal, K, truth.dist)
    # A radial polynomial folds rays far outside the field back into the image: a corner
    # counts only if its ray is within the image corners' field.
    w, h = truth.width, truth.height
    edge = lens.to_ideal(np.array([[0.0, 0.0], [w - 1.0, h - 1.0]]), K, truth.dist)
    r_max = np.max(np.linalg.norm(edge - K[:2, 2], axis=1))
    inside = ((image[:, 0] >= BORDER_PX) & (image[:, 0] <= w - 1 - BORDER_PX)
              & (image[:, 1] >= BORDER_PX) & (image[:, 1] <= h - 1 - BORDER_PX)
              & (np.linalg.norm(ideal - K[:2, 2], axis=1) < r_max))
    return bool(inside.mean() >= MIN_CORNERS_INSIDE)


def board_poses(board: cv2.aruco.CharucoBoard, n: int, rng: np.random.Generator,
                truth: CameraCalibration) -> list[Pose]:
    """`n` board poses in the palm frame: centres spread over a 3 x 3 grid of the image
    (each cell once per round of 9, in random order), at the working distance, tilted about a
    random axis and turned about the board's normal at random; each keeps most of the board
    in view (resampled until it does)."""
    corners = _board_corners(board)
    K_inv = np.linalg.inv(truth.K)
    half = np.array([truth.width / 2, truth.height / 2])
    poses: list[Pose] = []
    cells: list[int] = []
    for _ in range(n):
        if not cells:
            cells = list(rng.permutation(9))
        cell = cells.pop()
        centre = (np.array([cell % 3, cell // 3]) - 1) * (2 / 3)   # cell centre in [-1, 1]
        for _attempt in range(1000):
            a = np.clip(centre + rng.uniform(-1 / 3, 1 / 3, 2), -1, 1) * REACH
            uv = truth.K[:2, 2] + a * half
            depth = rng.uniform(*DEPTH_M)
            p_cam = depth * (K_inv @ np.array([uv[0], uv[1], 1.0]))
            position = truth.T_palm_cam[:3, :3] @ p_cam + truth.T_palm_cam[:3, 3]
            phi = rng.uniform(0, 2 * math.pi)
            tilt = Rotation.from_rotvec(math.radians(rng.uniform(*TILT_DEG))
                                        * np.array([math.cos(phi), math.sin(phi), 0.0]))
            turn = Rotation.from_euler("z", rng.uniform(-180, 180), degrees=True)
            rotvec = (tilt * turn).as_rotvec(degrees=True)
            pose = (tuple(float(x) for x in position), tuple(float(x) for x in rotvec))
            if _pose_fits(corners, _pose_matrix(pose), truth):
                poses.append(pose)
                break
        else:
            raise RuntimeError(f"no board pose keeps the board in view (image cell {cell})")
    return poses


def render_board_views(board: cv2.aruco.CharucoBoard, views: int | Sequence[Pose] = 15, *,
                       tag: SimTag | None = SimTag(), seed: int = 0,
                       effects: CameraEffects = DEFAULT_EFFECTS, width: int = WIDTH,
                       height: int = HEIGHT) -> CalibrationViews:
    """The board at `views` (a count of poses to sample, or the poses), then the tag alone,
    through the camera's lens and sensor `effects`; seeded: the same seed, the same images.

    `effects.distortion` is the lens (None: a pinhole); its other effects but frame drops
    apply to every image. Raises RenderingUnavailable if MuJoCo cannot render here."""
    rng = np.random.default_rng(seed)
    texture = board.generateImage(
        (board.getChessboardSize()[0] * PIXELS_PER_SQUARE + PIXELS_PER_SQUARE,
         board.getChessboardSize()[1] * PIXELS_PER_SQUARE + PIXELS_PER_SQUARE),
        marginSize=PIXELS_PER_SQUARE // 2, borderBits=1)
    metres_per_px = board.getSquareLength() / PIXELS_PER_SQUARE
    board_size = (texture.shape[1] * metres_per_px, texture.shape[0] * metres_per_px)
    tag_id = tag.tag_id if tag is not None else 0
    tag_side = (tag.size if tag is not None else 0.02) * TEXTURE_PER_BLACK

    f = (height / 2) / math.tan(math.radians(CAMERA_FOVY_DEG) / 2)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    distortion = effects.distortion or (0.0,) * 5
    mx, my = _margin(K, distortion, width, height)
    wide_w, wide_h = width + 2 * mx, height + 2 * my
    wide_fovy = math.degrees(2 * math.atan((wide_h / 2) / f))
    model = mujoco.MjModel.from_xml_string(
        _scene_xml(board_size, tag_side, wide_fovy, wide_w, wide_h),
        {"board.png": _png(texture), "tag.png": _png(tag_image(tag_id))})
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    wide = calibration_from_mujoco_camera(float(model.cam_fovy[0]), wide_w, wide_h,
                                          data.cam_xpos[0], data.cam_xmat[0].reshape(3, 3))
    K = wide.K.copy()
    K[:2, 2] -= (mx, my)  # the output is the render's centre crop
    truth = CameraCalibration(width, height, K, np.asarray(distortion, dtype=float),
                              wide.T_palm_cam)
    poses = list(views) if not isinstance(views, int) else board_poses(board, views, rng, truth)

    map_x, map_y = distortion_maps(K, distortion, width, height)
    map_x, map_y = map_x + np.float32(mx), map_y + np.float32(my)
    sensor = replace(effects, distortion=None, drop_rate=0.0)
    try:
        renderer = mujoco.Renderer(model, wide_h, wide_w)
    except Exception as exc:  # no EGL (or no display for another MUJOCO_GL)
        raise RenderingUnavailable(f"MuJoCo cannot render offscreen here "
                                   f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')}): "
                                   f"{str(exc).strip().splitlines()[-1]}") from None
    away = ((0.0, 0.0, -1.0), (0.0, 0.0, 0.0))  # behind the camera

    def shot(board_pose: Pose | None, tag_pose: Pose | None) -> np.ndarray:
        for mocap, pose in ((0, board_pose), (1, tag_pose)):
            pos, rotvec = pose if pose is not None else away
            data.mocap_pos[mocap] = pos
            data.mocap_quat[mocap] = Rotation.from_rotvec(rotvec, degrees=True).as_quat(
                scalar_first=True)
        mujoco.mj_forward(model, data)
        renderer.update_scene(data, camera="palm_camera")
        image = cv2.remap(renderer.render(), map_x, map_y, cv2.INTER_LINEAR)
        return apply_effects(image, sensor, rng, truth)

    try:
        boards = [shot(pose, None) for pose in poses]
        tag_view = shot(None, (tag.pose[:3], tag.pose[3:])) if tag is not None else None
    finally:
        renderer.close()
    return CalibrationViews(boards, tag_view, poses, truth)


# --------------------------------------------------------------------------- truth

def lens_gap_px(estimated: CameraCalibration, truth: CameraCalibration,
                points: np.ndarray) -> np.ndarray:
    """For image points (N, 2) of the true camera: how far [px] the estimated camera (K and
    dist) images the same rays, (N,). Intrinsics and lens in one figure: coefficients that
    trade off (k2 against k3) but make the same lens give no gap."""
    ideal = lens.to_ideal(points, truth.K, truth.dist)
    rays = np.column_stack([(ideal - truth.K[:2, 2]) / np.diag(truth.K)[:2],
                            np.ones(len(points))])
    fitted, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), estimated.K, estimated.dist)
    return np.linalg.norm(fitted.reshape(-1, 2) - points, axis=1)


def _five(dist: np.ndarray) -> np.ndarray:
    """(k1, k2, p1, p2, k3) of any OpenCV coefficient vector (absent ones are 0)."""
    out = np.zeros(5)
    d = np.asarray(dist, dtype=float).ravel()[:5]
    out[:d.size] = d
    return out


def compare_to_truth(estimated: CameraCalibration, truth: CameraCalibration,
                     seen: np.ndarray | None = None, step_px: float = 8.0) -> dict:
    """The estimate's errors against the truth: fx, fy, cx, cy (signed, % of the true value),
    the true distortion coefficients (k1, k2, p1, p2, k3) and the estimate's differences from
    them, the lens gap (lens_gap_px) over a grid of the image, edges included, every
    `step_px` (RMS and max) and its max within the convex hull of `seen` (the corners the
    board put in the image; beyond them the fit extrapolates), and the camera's pose in the
    palm (position [mm], rotation [deg])."""
    est = np.array([estimated.K[0, 0], estimated.K[1, 1], estimated.K[0, 2], estimated.K[1, 2]])
    tru = np.array([truth.K[0, 0], truth.K[1, 1], truth.K[0, 2], truth.K[1, 2]])
    rel = 100 * (est / tru - 1)
    u, v = np.meshgrid(np.linspace(0, truth.width - 1, math.ceil((truth.width - 1) / step_px) + 1),
                       np.linspace(0, truth.height - 1,
                                   math.ceil((truth.height - 1) / step_px) + 1))
    grid = np.column_stack([u.ravel(), v.ravel()])
    gap = lens_gap_px(estimated, truth, grid)
    out = {"fx_pct": rel[0], "fy_pct": rel[1], "cx_pct": rel[2], "cy_pct": rel[3],
           "dist_true": _five(truth.dist).tolist(),
           "dist_diff": (_five(estimated.dist) - _five(truth.dist)).tolist(),
           "lens_rms_px": float(np.sqrt(np.mean(gap ** 2))), "lens_max_px": float(gap.max())}
    if seen is not None and len(seen) >= 3:
        hull = cv2.convexHull(np.asarray(seen, dtype=np.float32).reshape(-1, 1, 2))
        within = np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), False) >= 0
                           for x, y in grid])
        out["lens_max_seen_px"] = float(gap[within].max()) if within.any() else float("nan")
    dR = estimated.T_palm_cam[:3, :3].T @ truth.T_palm_cam[:3, :3]
    out["position_mm"] = 1e3 * float(np.linalg.norm(estimated.T_palm_cam[:3, 3]
                                                    - truth.T_palm_cam[:3, 3]))
    out["rotation_deg"] = float(np.degrees(Rotation.from_matrix(dR).magnitude()))
    return {k: (float(v) if isinstance(v, np.floating) else v) for k, v in out.items()}

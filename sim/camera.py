"""The simulated palm camera: offscreen rendering under EGL, optional degradations.

The calibration comes from the MJCF camera through `vlr.camera.calibration_from_mujoco_camera`,
the one place where MuJoCo's camera frame becomes OpenCV's.
"""

from __future__ import annotations

import atexit
import weakref
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from vlr.camera import CameraCalibration, calibration_from_mujoco_camera

if TYPE_CHECKING:
    from vlr.sim.backend import SimHand

CAMERA_NAME = "palm_camera"


def calibration_of(model: mujoco.MjModel, data: mujoco.MjData,
                   width: int | None = None, height: int | None = None) -> CameraCalibration:
    """The ideal calibration of the palm camera, extrinsics in the palm frame."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    cam = model.camera(CAMERA_NAME).id
    palm = model.body("palm").id
    R_wp = data.xmat[palm].reshape(3, 3)
    p_wp = data.xpos[palm]
    pos = R_wp.T @ (data.cam_xpos[cam] - p_wp)
    xmat = R_wp.T @ data.cam_xmat[cam].reshape(3, 3)
    w = width or model.vis.global_.offwidth
    h = height or model.vis.global_.offheight
    return calibration_from_mujoco_camera(float(model.cam_fovy[cam]), int(w), int(h), pos, xmat)


def _visual_option() -> mujoco.MjvOption:
    """Only visual geoms (group 2) and the tag: collision duplicates (group 3) hidden, and
    no sites (the POM site would mark the tag's centre)."""
    opt = mujoco.MjvOption()
    opt.geomgroup[:] = [1, 1, 1, 0, 0, 0]
    opt.sitegroup[:] = 0
    return opt


_VISUAL = _visual_option()
# Hands with open renderers, closed at exit before EGL is: `atexit` runs its handlers last
# registered first, and mujoco.egl registers its teardown when the first renderer is made;
# a renderer left to the garbage collector at exit printed EGL tracebacks.
_OPEN: weakref.WeakSet = weakref.WeakSet()


def _close_open() -> None:
    for hand in list(_OPEN):
        hand.close()


def _renderer(hand: SimHand, key: object, width: int, height: int) -> mujoco.Renderer:
    """The hand's renderer for `key`, made on first use."""
    r = hand.renderers.get(key)
    if r is None:
        r = hand.renderers[key] = mujoco.Renderer(hand.model, height=height, width=width)
        if not _OPEN:
            atexit.unregister(_close_open)
            atexit.register(_close_open)
        _OPEN.add(hand)
    return r


def render_palm_camera(hand: SimHand) -> np.ndarray | None:
    """An RGB frame of the palm camera after the hand's camera effects (None = dropped)."""
    opts = hand.options
    r = _renderer(hand, "palm", opts.width, opts.height)
    r.update_scene(hand.data, camera=CAMERA_NAME, scene_option=_VISUAL)
    image = r.render()
    if opts.effects is None:
        return image
    from vlr.sim.camera_effects import apply_effects

    return apply_effects(image, opts.effects, hand.rng, hand.calibration)


def render_scene(hand: SimHand, width: int = 640, height: int = 480,
                 camera: str = "scene_camera") -> np.ndarray:
    """A third-person view of the hand and object (for pictures and render_mode)."""
    r = _renderer(hand, (width, height), width, height)
    r.update_scene(hand.data, camera=camera, scene_option=_VISUAL)
    return r.render()

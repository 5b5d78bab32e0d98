"""vlr.perception: tag pose accuracy on synthetic and MuJoCo-rendered images, the face-on
IPPE pitfall, and every "no observation" case."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.tag_images import (
    ideal_calibration,
    pose_cam_object,
    render_tag,
    rotation_error_deg,
    true_corners,
)
from vlr.camera import pose_to_matrix
from vlr.perception import (
    R_MARKER_TO_OBJECT,
    DetectorConfig,
    detect_tags,
    marker_to_object,
    observe,
    refine_edges,
    solve_tag_pose,
)
from vlr.perception.pose import _IPPE_ORDER, _rz, object_corners, reprojection_rms

TAG_ID = 3
TAG_SIZE = 0.030  # the objects' black square (models/objects/*.yaml)

# distance [m], tilt [deg], tilt axis [deg], spin [deg], offset across the axis [m]
POSES = [
    (0.040, 0.0, 0.0, 0.0, (0.0, 0.0)),
    (0.040, 15.0, 30.0, 17.0, (0.002, -0.001)),
    (0.050, 0.0, 0.0, 180.0, (0.0, 0.0)),
    (0.050, 25.0, 120.0, -70.0, (-0.003, 0.002)),
    (0.050, 8.0, 250.0, 95.0, (0.001, 0.003)),
    (0.060, 30.0, 200.0, 140.0, (0.002, 0.002)),
    (0.060, 12.0, 300.0, -150.0, (-0.004, -0.003)),
]


def _palm_calibration(width: int, height: int):
    # A camera 4 mm under the palm surface looking up, turned about its axis: the palm
    # transform must be applied.
    R = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    return ideal_calibration(width, height, 60.0, pose_to_matrix([0.001, -0.002, -0.004], R))


def _noisy(image: np.ndarray, rng: np.random.Generator, noise: float,
           blur: float) -> np.ndarray:
    out = cv2.GaussianBlur(image, (0, 0), blur) if blur > 0 else image
    out = out.astype(float) + rng.normal(0.0, noise, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("size", [(640, 480), (320, 240)])
@pytest.mark.parametrize("noise, blur", [(0.0, 0.0), (3.0, 0.8)])
def test_pose_accuracy_on_synthetic_images(size, noise, blur) -> None:
    cal = _palm_calibration(*size)
    rng = np.random.default_rng(7)
    pos_err, rot_err = [], []
    for z, tilt, axis, spin, offset in POSES:
        T_cam_O = pose_cam_object(z, tilt, axis, spin, offset)
        image = _noisy(render_tag(cal, T_cam_O, TAG_ID, TAG_SIZE), rng, noise, blur)
        obs = observe(image, cal, TAG_ID, TAG_SIZE)
        assert obs is not None, (z, tilt, spin)
        assert obs.refined
        T_palm_O = cal.T_palm_cam @ T_cam_O
        pos_err.append(np.linalg.norm(obs.position - T_palm_O[:3, 3]))
        rot_err.append(rotation_error_deg(obs.rotation, T_palm_O[:3, :3]))
        np.testing.assert_allclose(cal.T_palm_cam @ obs.tag_pose_cam, obs.T_palm_object,
                                   atol=1e-12)
        assert np.max(np.abs(obs.corners - true_corners(cal, T_cam_O, TAG_SIZE))) < 0.1
        assert 0 <= obs.reprojection_px < 0.1
    # The brief's bounds, and the 10x tighter level this pipeline reaches (a regression
    # guard: SUBPIX corners alone gave ~0.02 mm and ~0.15 deg here).
    assert max(pos_err) < 1e-4 and max(rot_err) < 0.5
    assert max(pos_err) < 2e-5 and max(rot_err) < 0.1, (pos_err, rot_err)


@pytest.mark.parametrize("size, tilt", [((640, 480), 60.0), ((320, 240), 50.0)])
def test_steeply_viewed_tag(size, tilt) -> None:
    # Cells across the far sides shrink to 4-5 px: the refinement windows follow them.
    cal = ideal_calibration(*size, 60.0)
    rng = np.random.default_rng(11)
    for axis in (0.0, 70.0, 135.0, 250.0):
        T = pose_cam_object(0.06, tilt, axis, 20.0)
        image = _noisy(render_tag(cal, T, TAG_ID, TAG_SIZE), rng, 2.0, 0.7)
        obs = observe(image, cal, TAG_ID, TAG_SIZE)
        assert obs is not None and obs.refined
        assert np.linalg.norm(obs.position - T[:3, 3]) < 1e-4
        assert rotation_error_deg(obs.rotation, T[:3, :3]) < 0.5


def test_exactly_face_on_is_finite_and_correct() -> None:
    # R_cam_M = Rx(pi) for a face-on tag: OpenCV's IPPE_SQUARE reports success with NaN or a
    # pose tens of pixels off there; and so for O's frame at a spin of pi.
    cal = ideal_calibration(640, 480, 60.0)
    for spin in (0.0, 90.0, 180.0, -90.0, 45.0):
        for offset in ((0.0, 0.0), (0.003, 0.002)):
            T = pose_cam_object(0.05, 0.0, 0.0, spin, offset)
            # exact corners
            sol = solve_tag_pose(true_corners(cal, T, TAG_SIZE), TAG_SIZE, cal.K)
            assert sol is not None
            np.testing.assert_allclose(sol[0], T, atol=1e-9)
            assert sol[1] < 1e-6
            # rendered
            obs = observe(render_tag(cal, T, TAG_ID, TAG_SIZE), cal, TAG_ID, TAG_SIZE)
            assert obs is not None and np.all(np.isfinite(obs.tag_pose_cam))
            assert np.linalg.norm(obs.position - T[:3, 3]) < 1e-5
            assert rotation_error_deg(obs.rotation, T[:3, :3]) < 0.05


def test_opencv_ippe_square_fails_face_on() -> None:
    """Documents the pitfall `solve_tag_pose` avoids (if OpenCV fixes it, fine: drop this)."""
    cal = ideal_calibration(640, 480, 60.0)
    T = pose_cam_object(0.05, 0.0, 0.0, 0.0, (0.003, 0.002))
    h = TAG_SIZE / 2
    marker = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
    ok, rvec, tvec = cv2.solvePnP(marker, true_corners(cal, T, TAG_SIZE), cal.K, None,
                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    bad = not np.all(np.isfinite(rvec))
    if not bad:
        R = cv2.Rodrigues(rvec)[0] @ R_MARKER_TO_OBJECT
        bad = rotation_error_deg(R, T[:3, :3]) > 1.0
    if not bad:
        pytest.skip("this OpenCV's IPPE_SQUARE handles the face-on tag")
    assert ok  # it claims success


def test_ippe_corner_orders_match_their_frames() -> None:
    h = 1.0
    square = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
    corners_O = object_corners(2 * h)
    for k, order in enumerate(_IPPE_ORDER):
        R_O_S = _rz(-k)
        np.testing.assert_allclose(square @ R_O_S.T, corners_O[order], atol=1e-12)


def test_marker_frame_to_object_frame() -> None:
    T_cam_M = pose_to_matrix([0.0, 0.0, 0.05], np.diag([1.0, -1.0, -1.0]))  # face-on marker
    T_cam_O = marker_to_object(T_cam_M)
    np.testing.assert_allclose(T_cam_O[:3, :3], np.eye(3))  # O's z looks away from camera
    np.testing.assert_allclose(T_cam_O[:3, 3], T_cam_M[:3, 3])


def test_edge_refinement_beats_subpix() -> None:
    cal = ideal_calibration(640, 480, 60.0)
    T = pose_cam_object(0.05, 20.0, 60.0, 33.0, (0.002, 0.001))
    image = render_tag(cal, T, TAG_ID, TAG_SIZE)
    truth = true_corners(cal, T, TAG_SIZE)
    (det,) = detect_tags(image, DetectorConfig(), fast=False)
    refined = refine_edges(image, det.corners)
    assert refined is not None
    assert np.max(np.abs(refined - truth)) < 0.03
    assert np.max(np.abs(refined - truth)) < 0.5 * np.max(np.abs(det.corners - truth))
    # a seed 3 px off still converges
    assert np.max(np.abs(refine_edges(image, truth + [[3, -2], [-2, 2], [1, 3], [-3, -1]])
                         - truth)) < 0.03


def test_large_tag_with_white_border_cut_by_the_frame() -> None:
    # 32 mm away the texture (white border included) is taller than the image, the black
    # square is 451 px and 14 px from the top and bottom edges: still a good observation.
    cal = ideal_calibration(640, 480, 60.0)
    T = pose_cam_object(0.032, 0.0, 0.0, 10.0)
    corners = true_corners(cal, T, TAG_SIZE)
    assert np.ptp(corners[:, 1]) * 1.25 > 480 and corners[:, 1].min() > 10
    obs = observe(render_tag(cal, T, TAG_ID, TAG_SIZE), cal, TAG_ID, TAG_SIZE)
    assert obs is not None and np.linalg.norm(obs.position - T[:3, 3]) < 1e-5


def test_picks_requested_id_among_several() -> None:
    cal = ideal_calibration(640, 480, 60.0)
    small = 0.012
    T_a = pose_cam_object(0.06, 5.0, 0.0, 10.0, (-0.016, 0.0))
    T_b = pose_cam_object(0.06, 5.0, 90.0, -20.0, (0.016, 0.0))
    a = render_tag(cal, T_a, 5, small).astype(np.int16)
    b = render_tag(cal, T_b, 9, small).astype(np.int16)
    background = 60
    image = np.clip(a + b - background, 0, 255).astype(np.uint8)
    for tag_id, T in ((5, T_a), (9, T_b)):
        obs = observe(image, cal, tag_id, small)
        assert obs is not None
        assert np.linalg.norm(obs.position - T[:3, 3]) < 5e-5
    assert observe(image, cal, 3, small) is None


# --------------------------------------------------------------------------- None cases

@pytest.fixture(scope="module")
def cal640():
    return ideal_calibration(640, 480, 60.0)


def test_no_tag_returns_none(cal640) -> None:
    rng = np.random.default_rng(0)
    clutter = cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 3)
    assert observe(clutter, cal640, TAG_ID, TAG_SIZE) is None
    assert observe(np.full((480, 640), 128, np.uint8), cal640, TAG_ID, TAG_SIZE) is None


def test_black_none_and_empty_frames_return_none(cal640) -> None:
    assert observe(np.zeros((480, 640), np.uint8), cal640, TAG_ID, TAG_SIZE) is None
    assert observe(np.zeros((480, 640, 3), np.uint8), cal640, TAG_ID, TAG_SIZE) is None
    assert observe(None, cal640, TAG_ID, TAG_SIZE) is None
    assert observe(np.zeros((0, 0), np.uint8), cal640, TAG_ID, TAG_SIZE) is None


def test_wrong_id_returns_none(cal640) -> None:
    image = render_tag(cal640, pose_cam_object(0.05, 10.0, 0.0, 0.0), 4, TAG_SIZE)
    assert observe(image, cal640, 4, TAG_SIZE) is not None
    assert observe(image, cal640, TAG_ID, TAG_SIZE) is None


@pytest.mark.parametrize("offset", [(0.024, 0.0), (0.0, -0.018), (0.016, 0.014)])
def test_tag_partly_out_of_view_returns_none(cal640, offset) -> None:
    T = pose_cam_object(0.05, 0.0, 0.0, 0.0, offset)
    corners = true_corners(cal640, T, TAG_SIZE)
    assert np.any(corners < 0) or np.any(corners[:, 0] > 639) or np.any(corners[:, 1] > 479)
    assert observe(render_tag(cal640, T, TAG_ID, TAG_SIZE), cal640, TAG_ID, TAG_SIZE) is None


def test_corner_near_border_returns_none(cal640) -> None:
    # the black square fully inside but a corner within the margin: no reliable edge fit
    T = pose_cam_object(0.05, 0.0, 0.0, 0.0, (0.0, 0.0))
    corners = true_corners(cal640, T, TAG_SIZE)
    top = corners[:, 1].min()
    T = pose_cam_object(0.05, 0.0, 0.0, 0.0, (0.0, -(top - 1.5) * 0.05 / cal640.K[1, 1]))
    corners = true_corners(cal640, T, TAG_SIZE)
    assert 0 < corners[:, 1].min() < 3
    assert observe(render_tag(cal640, T, TAG_ID, TAG_SIZE), cal640, TAG_ID, TAG_SIZE) is None


def test_reprojection_threshold(cal640) -> None:
    image = render_tag(cal640, pose_cam_object(0.05, 20.0, 10.0, 5.0), TAG_ID, TAG_SIZE)
    obs = observe(image, cal640, TAG_ID, TAG_SIZE)
    assert obs is not None
    assert observe(image, cal640, TAG_ID, TAG_SIZE,
                   max_reprojection_px=obs.reprojection_px / 2) is None
    # a wrong tag size cannot make the four corners fit worse (a square is a square), so the
    # reprojection check is for bad corners; a wrong size scales the distance instead
    big = observe(image, cal640, TAG_ID, 2 * TAG_SIZE)
    assert big is not None and big.position[2] == pytest.approx(2 * obs.position[2], rel=1e-6)


def test_unrefinable_tags_need_allow_unrefined(cal640) -> None:
    # 0.5 m away the 30 mm tag is 25 px wide, cells 3 px: too small for edge profiles
    T = pose_cam_object(0.5, 10.0, 30.0, 10.0)
    image = render_tag(cal640, T, TAG_ID, TAG_SIZE)
    assert observe(image, cal640, TAG_ID, TAG_SIZE) is None
    obs = observe(image, cal640, TAG_ID, TAG_SIZE, allow_unrefined=True)
    assert obs is not None and not obs.refined
    assert np.max(np.abs(obs.corners - true_corners(cal640, T, TAG_SIZE))) < 2.0


def test_reprojection_rms_of_the_true_pose_is_zero(cal640) -> None:
    T = pose_cam_object(0.05, 20.0, 10.0, 5.0)
    corners = true_corners(cal640, T, TAG_SIZE)
    assert reprojection_rms(T, TAG_SIZE, corners, cal640.K) < 1e-9
    assert reprojection_rms(T, TAG_SIZE, corners + [0.3, 0.4], cal640.K) \
        == pytest.approx(0.5, abs=1e-9)


def test_colour_images_are_accepted(cal640) -> None:
    grey = render_tag(cal640, pose_cam_object(0.05, 10.0, 0.0, 0.0), TAG_ID, TAG_SIZE)
    ref = observe(grey, cal640, TAG_ID, TAG_SIZE)
    for image in (np.dstack([grey] * 3), np.dstack([grey] * 4), grey[..., None]):
        obs = observe(image, cal640, TAG_ID, TAG_SIZE)
        assert obs is not None
        np.testing.assert_allclose(obs.position, ref.position, atol=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    (dict(tag_size=0.0), "tag_size"),
    (dict(tag_size=-0.03), "tag_size"),
    (dict(tag_size=float("nan")), "tag_size"),
    (dict(tag_id=587), "tag_id"),
    (dict(tag_id=-1), "tag_id"),
    (dict(image=np.zeros((480, 640), np.float32)), "dtype float32"),
    (dict(image=np.zeros((480, 640, 2), np.uint8)), "shape"),
    (dict(image=np.zeros((240, 320), np.uint8)), "320x240"),
    (dict(max_reprojection_px=0.0), "max_reprojection_px"),
])
def test_bad_arguments_raise(cal640, kwargs, match) -> None:
    args = dict(image=np.zeros((480, 640), np.uint8), calibration=cal640, tag_id=TAG_ID,
                tag_size=TAG_SIZE)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        observe(**args)


def test_observation_is_frozen(cal640) -> None:
    image = render_tag(cal640, pose_cam_object(0.05, 10.0, 0.0, 0.0), TAG_ID, TAG_SIZE)
    obs = observe(image, cal640, TAG_ID, TAG_SIZE)
    with pytest.raises(ValueError):
        obs.position[0] = 1.0
    with pytest.raises(AttributeError):
        obs.reprojection_px = 0.0


# --------------------------------------------------------------------------- MuJoCo renders

def test_pose_on_mujoco_renders(tmp_path) -> None:
    """A tag card built as sim/model.py builds it (a box whose +z face carries the texture,
    turned by pi about x so that face looks down -z_O), rendered by MuJoCo, is recovered in
    the palm frame: O's convention, the texture mapping and the calibration agree."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    mujoco = pytest.importorskip("mujoco")
    from vlr.models.make_tags import TEXTURE_PER_BLACK, tag_image

    from vlr.camera import calibration_from_mujoco_camera

    png = tmp_path / "tag.png"
    cv2.imwrite(str(png), tag_image(TAG_ID))
    side = TAG_SIZE * TEXTURE_PER_BLACK
    width, height, fovy = 640, 480, 60.0
    xml = f"""<mujoco><compiler angle="radian"/>
      <visual><headlight ambient="0.5 0.5 0.5" diffuse="0.4 0.4 0.4" specular="0 0 0"/>
        <quality shadowsize="0"/><global offwidth="{width}" offheight="{height}"/></visual>
      <asset><texture name="tag" type="2d" file="{png}"/>
        <material name="tag" texture="tag" specular="0" shininess="0"/></asset>
      <worldbody>
        <body name="palm" pos="0.01 0.02 0.03" quat="0.9 0.1 0.2 0.3">
          <camera name="cam" pos="0 0 -0.004" quat="0 1 0 0" fovy="{fovy}"/></body>
        <body name="obj" mocap="true">
          <geom type="box" size="{side / 2} {side / 2} 0.001" pos="0 0 0.001" quat="0 1 0 0"
                material="tag"/></body>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    R_wp, p_wp = data.xmat[1].reshape(3, 3), data.xpos[1].copy()
    cal = calibration_from_mujoco_camera(fovy, width, height, R_wp.T @ (data.cam_xpos[0] - p_wp),
                                         R_wp.T @ data.cam_xmat[0].reshape(3, 3))
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as exc:
        pytest.skip(f"MuJoCo offscreen rendering unavailable: {exc}")
    rng = np.random.default_rng(0)
    try:
        for _ in range(6):
            axis = np.r_[rng.normal(size=2), 0.0]
            R_PO = (Rotation.from_euler("z", rng.uniform(-np.pi, np.pi))
                    * Rotation.from_rotvec(np.radians(rng.uniform(0, 25)) * axis
                                           / np.linalg.norm(axis))).as_matrix()
            p_PO = np.r_[rng.uniform(-0.003, 0.003, 2), rng.uniform(0.04, 0.06)]
            data.mocap_pos[0] = p_wp + R_wp @ p_PO
            data.mocap_quat[0] = Rotation.from_matrix(R_wp @ R_PO).as_quat(scalar_first=True)
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera="cam")
            obs = observe(renderer.render(), cal, TAG_ID, TAG_SIZE)
            assert obs is not None
            assert np.linalg.norm(obs.position - p_PO) < 2e-5
            assert rotation_error_deg(obs.rotation, R_PO) < 0.05
    finally:
        renderer.close()

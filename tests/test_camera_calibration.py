"""Camera calibration: YAML format, validation, and the MuJoCo -> OpenCV camera conversion
checked against real MuJoCo renders."""

from __future__ import annotations

import math
import os
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from vlr.camera import (
    R_MUJOCO_TO_OPENCV,
    CalibrationError,
    CameraCalibration,
    calibration_from_mujoco_camera,
    invert_pose,
    load_calibration,
    pose_to_matrix,
    save_calibration,
)


def _calibration() -> CameraCalibration:
    R = Rotation.from_euler("xyz", [0.1, -0.2, 0.3]).as_matrix()
    return CameraCalibration(
        width=640, height=480,
        K=np.array([[415.6921938165306, 0.0, 319.5], [0.0, 415.6921938165306, 239.5],
                    [0.0, 0.0, 1.0]]),
        dist=np.array([-0.12, 0.034, 1e-4, -2e-4, 0.001]),
        T_palm_cam=pose_to_matrix([0.001, -0.002, -0.004], R))


def test_yaml_round_trip_is_exact(tmp_path: Path) -> None:
    cal = _calibration()
    path = tmp_path / "cam.yaml"
    save_calibration(cal, path)
    back = load_calibration(path)
    assert (back.width, back.height) == (640, 480)
    np.testing.assert_array_equal(back.K, cal.K)
    np.testing.assert_array_equal(back.dist, cal.dist)
    np.testing.assert_array_equal(back.T_palm_cam, cal.T_palm_cam)
    # atomic write: nothing but the file itself is left behind, and overwriting works
    save_calibration(back, path)
    assert [p.name for p in tmp_path.iterdir()] == ["cam.yaml"]


def test_yaml_accepts_a_quaternion(tmp_path: Path) -> None:
    cal = _calibration()
    q = Rotation.from_matrix(cal.T_palm_cam[:3, :3]).as_quat()  # x, y, z, w
    save_calibration(cal, tmp_path / "a.yaml")
    data = yaml.safe_load((tmp_path / "a.yaml").read_text())
    del data["extrinsics"]["rotation"]
    data["extrinsics"]["quaternion_xyzw"] = q.tolist()
    path = tmp_path / "q.yaml"
    path.write_text(yaml.safe_dump(data))
    np.testing.assert_allclose(load_calibration(path).T_palm_cam, cal.T_palm_cam, atol=1e-12)


def test_docstring_example_loads(tmp_path: Path) -> None:
    import vlr.camera

    doc = vlr.camera.__doc__
    start = doc.rindex("\n", 0, doc.index("# vlr camera calibration")) + 1
    block = doc[start:doc.index("This example")]
    path = tmp_path / "example.yaml"
    path.write_text(textwrap.dedent(block))
    cal = load_calibration(path)
    assert cal.K[0, 2] == 319.5 and cal.T_palm_cam[2, 3] == -0.01


def _write(tmp_path: Path, mutate) -> Path:
    cal = _calibration()
    path = tmp_path / "cam.yaml"
    save_calibration(cal, path)
    data = yaml.safe_load(path.read_text())
    mutate(data)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("mutate, words", [
    (lambda d: d.pop("camera_matrix"), ["missing key", "camera_matrix"]),
    (lambda d: d.update(width=0), ["width", "0"]),
    (lambda d: d.update(height="480"), ["height", "'480'"]),
    (lambda d: d.update(camera_matrix=[[-400, 0, 320], [0, 400, 240], [0, 0, 1]]),
     ["focal", "-400"]),
    (lambda d: d.update(camera_matrix=[[400, 0, 320], [0, 400, 240]]),
     ["camera_matrix", "shape"]),
    (lambda d: d.update(camera_matrix=[[400, 0, ".nan"], [0, 400, 240], [0, 0, 1]]),
     ["camera_matrix", "number"]),
    (lambda d: d.update(dist_coeffs=[0.1, 0.2, 0.3]), ["dist"]),
    (lambda d: d["extrinsics"].update(rotation=[[1, 0, 0], [0, 1, 0], [0, 0.1, 1]]),
     ["extrinsics.rotation", "orthonormal"]),
    (lambda d: d["extrinsics"].update(rotation=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]),
     ["reflection"]),
    (lambda d: d["extrinsics"].update(quaternion_xyzw=[0, 0, 0, 1]), ["exactly one"]),
    (lambda d: d["extrinsics"].pop("translation"), ["extrinsics.translation"]),
    (lambda d: d.update(focal=1.0), ["unknown keys", "focal"]),
])
def test_malformed_yaml_names_key_and_file(tmp_path: Path, mutate, words) -> None:
    path = _write(tmp_path, mutate)
    with pytest.raises(CalibrationError) as err:
        load_calibration(path)
    message = str(err.value)
    assert str(path) in message
    for w in words:
        assert w in message, message
    assert isinstance(err.value, ValueError)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="does not exist"):
        load_calibration(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("width: [640\n")
    with pytest.raises(CalibrationError, match="not valid YAML"):
        load_calibration(bad)
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(CalibrationError, match="mapping"):
        load_calibration(bad)


def test_constructor_validates_and_freezes() -> None:
    cal = _calibration()
    with pytest.raises(ValueError):
        cal.K[0, 0] = 1.0  # read-only
    with pytest.raises(CalibrationError, match="T_palm_cam rotation"):
        CameraCalibration(640, 480, cal.K, cal.dist, np.diag([1.0, 1.0, 2.0, 1.0]))
    with pytest.raises(CalibrationError, match="width"):
        CameraCalibration(-1, 480, cal.K, cal.dist, cal.T_palm_cam)
    np.testing.assert_allclose(cal.T_cam_palm @ cal.T_palm_cam, np.eye(4), atol=1e-15)
    np.testing.assert_allclose(invert_pose(cal.T_palm_cam), np.linalg.inv(cal.T_palm_cam),
                               atol=1e-15)


def test_mujoco_to_opencv_axes() -> None:
    # A MuJoCo camera with identity orientation looks along -z with +y up: OpenCV's camera
    # then has z = -z, y = -y (image down) and the same x.
    cal = calibration_from_mujoco_camera(60.0, 640, 480, [0, 0, 0], np.eye(3))
    np.testing.assert_array_equal(cal.T_palm_cam[:3, :3], R_MUJOCO_TO_OPENCV)
    assert cal.K[1, 1] == pytest.approx(240 / math.tan(math.radians(30)))
    assert (cal.K[0, 2], cal.K[1, 2]) == (319.5, 239.5)
    with pytest.raises(CalibrationError, match="fovy"):
        calibration_from_mujoco_camera(0.0, 640, 480, [0, 0, 0], np.eye(3))


# --------------------------------------------------------------------------- MuJoCo renders

_SPHERES_PALM = [(0.0, 0.0, 0.20), (0.05, 0.03, 0.20), (-0.06, 0.025, 0.25),
                 (0.04, -0.05, 0.18), (-0.035, -0.04, 0.22), (-0.05, 0.06, 0.26)]
_RADIUS = 0.003


def _render_spheres(width: int, height: int, fovy: float):
    os.environ.setdefault("MUJOCO_GL", "egl")
    mujoco = pytest.importorskip("mujoco")
    # A tilted "palm" body carrying the camera, which looks up along +z_palm (quat = pi about
    # x), as the palm camera does; spheres are placed in the palm frame.
    palm_quat = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_quat(scalar_first=True)
    spheres = "\n".join(f'<geom type="sphere" size="{_RADIUS}" pos="{x} {y} {z}" '
                        'material="white"/>' for x, y, z in _SPHERES_PALM)
    xml = f"""<mujoco>
      <visual><headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
        <quality offsamples="16"/><global offwidth="{width}" offheight="{height}"/></visual>
      <asset><material name="white" rgba="1 1 1 1" emission="1"/></asset>
      <worldbody>
        <body name="palm" pos="0.1 -0.05 0.3" quat="{' '.join(map(str, palm_quat))}">
          <camera name="cam" pos="0.003 -0.002 -0.004" quat="0 1 0 0" fovy="{fovy}"/>
          {spheres}
        </body>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as exc:  # no EGL on this machine
        pytest.skip(f"MuJoCo offscreen rendering unavailable: {exc}")
    try:
        renderer.update_scene(data, camera="cam")
        image = renderer.render()
    finally:
        renderer.close()
    palm = model.body("palm").id
    R_wp, p_wp = data.xmat[palm].reshape(3, 3), data.xpos[palm]
    cam_pos = R_wp.T @ (data.cam_xpos[0] - p_wp)
    cam_xmat = R_wp.T @ data.cam_xmat[0].reshape(3, 3)
    return image, cam_pos, cam_xmat


def _blob_centroids(image: np.ndarray) -> np.ndarray:
    g = image[..., 0].astype(float) / 255.0
    n, labels = cv2.connectedComponents((g > 0.002).astype(np.uint8))
    out = []
    for i in range(1, n):
        ys, xs = np.nonzero(labels == i)
        w = g[ys, xs]  # anti-aliased coverage: intensity-weighted centroid
        out.append([(w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()])
    return np.array(out)


def _sphere_image_centres(cal: CameraCalibration, K: np.ndarray) -> np.ndarray:
    """Centres of the spheres' exact image ellipses (a sphere's outline under perspective is a
    conic whose centre is NOT the projected sphere centre; here the difference is < 0.03 px
    but the test should not depend on it)."""
    T_cam_palm = cal.T_cam_palm
    Kinv = np.linalg.inv(K)
    out = []
    for p in _SPHERES_PALM:
        c = T_cam_palm[:3, :3] @ np.array(p) + T_cam_palm[:3, 3]
        # tangent cone: rays x with (x.c)^2 = |x|^2 (|c|^2 - r^2)
        Q = Kinv.T @ (np.outer(c, c) - (c @ c - _RADIUS**2) * np.eye(3)) @ Kinv
        out.append(-np.linalg.solve(Q[:2, :2], Q[:2, 2]))
    return np.array(out)


@pytest.mark.parametrize("width, height, fovy", [(640, 480, 50.0), (321, 240, 45.0)])
def test_calibration_matches_mujoco_render(width: int, height: int, fovy: float) -> None:
    image, cam_pos, cam_xmat = _render_spheres(width, height, fovy)
    cal = calibration_from_mujoco_camera(fovy, width, height, cam_pos, cam_xmat)
    seen = _blob_centroids(image)
    assert len(seen) == len(_SPHERES_PALM)
    expected = _sphere_image_centres(cal, cal.K)
    # cv2.projectPoints of the sphere centres agrees with the ellipse centres
    T = cal.T_cam_palm
    proj, _ = cv2.projectPoints(np.array(_SPHERES_PALM), cv2.Rodrigues(T[:3, :3])[0],
                                T[:3, 3], cal.K, cal.dist)
    np.testing.assert_allclose(proj.reshape(-1, 2), expected, atol=0.05)
    # match each blob to its nearest expected centre
    err = np.array([np.min(np.linalg.norm(expected - s, axis=1)) for s in seen])
    assert err.max() < 0.1, err
    # the other principal-point convention, (width/2, height/2), is off by half a pixel
    K_half = cal.K.copy()
    K_half[:2, 2] = [width / 2, height / 2]
    wrong = _sphere_image_centres(cal, K_half)
    err_half = np.array([np.min(np.linalg.norm(wrong - s, axis=1)) for s in seen])
    assert err_half.min() > 0.4, err_half

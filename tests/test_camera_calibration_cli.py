"""`vlr camera-calibrate` on MuJoCo renders of the printed board and a tag, seen by a palm
camera with the model's field of view and resolution, a mounting error, lens distortion and
sensor noise (vlr.sim.calibration_views); the truth comes from the MJCF camera
(vlr.camera.calibration_from_mujoco_camera) and the distortion put on the frames
(sim.camera_effects), not from the calibration code."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.camera import load_calibration
from vlr.cli import main
from vlr.perception import lens

WIDTH, HEIGHT = 640, 480
SQUARE, SQUARES = 0.012, (7, 5)               # the command's default board
DPI = 254                                     # 120 px per 12 mm square
TAG_ID, TAG_SIZE = 7, 0.02
TAG_POSE = (0.003, -0.004, 0.065, 4.0, -6.0, 25.0)  # palm frame: m, rotation vector deg
# Board poses in the palm: centre (x, y, z) [m] and rotation vector [deg] (identity: facing
# the camera); offsets put corners in every part of the image, tilts give the focal length.
BOARD_POSES = [
    ((0.000, 0.000, 0.100), (0, 0, 0)),
    ((-0.042, -0.032, 0.110), (25, -20, 5)),
    ((0.042, -0.032, 0.110), (25, 20, -5)),
    ((-0.042, 0.032, 0.110), (-25, -20, -8)),
    ((0.042, 0.032, 0.110), (-25, 20, 8)),
    ((0.000, 0.000, 0.085), (0, 35, 90)),
    ((0.000, 0.000, 0.090), (35, 0, 10)),
    ((-0.040, 0.000, 0.120), (0, -30, 0)),
    ((0.040, 0.000, 0.120), (0, 30, 0)),
    ((0.000, -0.030, 0.115), (30, 0, 0)),
    ((0.000, 0.030, 0.115), (-30, 0, 180)),
    ((0.010, 0.005, 0.140), (15, 15, 30)),
]
TAG_ARGS = ["--tag-id", str(TAG_ID), "--tag-size", str(TAG_SIZE),
            "--tag-pose", *map(str, TAG_POSE)]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Board views at BOARD_POSES and a tag image as the distorting, noisy palm camera sees
    them (the lens and noise of calibration_views.DEFAULT_EFFECTS), and the true calibration:
    {"views": DIR, "tag": FILE, "truth": CameraCalibration}."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    views_module = pytest.importorskip("vlr.sim.calibration_views")
    from vlr.hardware.camera_calibration import BoardSpec

    root = tmp_path_factory.mktemp("camcal")
    board_png = root / "board.png"
    assert main(["camera-calibrate", "--print-board", str(board_png), "--dpi", str(DPI)]) == 0
    pps = round(SQUARE / 0.0254 * DPI)
    # The printed board is the one rendered: squares and a half-square margin.
    assert cv2.imread(str(board_png), cv2.IMREAD_GRAYSCALE).shape == \
        ((SQUARES[1] + 1) * pps, (SQUARES[0] + 1) * pps)
    assert pps == views_module.PIXELS_PER_SQUARE
    tag = views_module.SimTag(TAG_ID, TAG_SIZE, TAG_POSE)
    try:
        sim = views_module.render_board_views(BoardSpec().board(), BOARD_POSES, tag=tag,
                                              seed=0)
    except views_module.RenderingUnavailable as exc:
        pytest.skip(str(exc))
    assert (sim.truth.width, sim.truth.height) == (WIDTH, HEIGHT)
    views = root / "views"
    views.mkdir()
    for k, image in enumerate(sim.boards):
        cv2.imwrite(str(views / f"view_{k:02d}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    tag_png = root / "tag.png"
    cv2.imwrite(str(tag_png), cv2.cvtColor(sim.tag, cv2.COLOR_RGB2BGR))
    return {"views": views, "tag": tag_png, "truth": sim.truth}


def _errors(cal, truth) -> dict[str, float]:
    rel = np.abs(np.array([cal.K[0, 0], cal.K[1, 1], cal.K[0, 2], cal.K[1, 2]])
                 / np.array([truth.K[0, 0], truth.K[1, 1], truth.K[0, 2], truth.K[1, 2]]) - 1)
    dR = cal.T_palm_cam[:3, :3].T @ truth.T_palm_cam[:3, :3]
    return {"fx": rel[0], "fy": rel[1], "cx": rel[2], "cy": rel[3],
            "position_mm": 1e3 * float(np.linalg.norm(cal.T_palm_cam[:3, 3]
                                                      - truth.T_palm_cam[:3, 3])),
            "rotation_deg": float(np.degrees(Rotation.from_matrix(dR).magnitude()))}


def _distortion_gap_px(cal, truth, radius_px: float) -> float:
    """Largest distance [px] between where the fitted and the true camera image the same ray,
    over the image within `radius_px` of its centre."""
    u, v = np.meshgrid(np.arange(0, WIDTH, 10.0), np.arange(0, HEIGHT, 10.0))
    pts = np.stack([u.ravel(), v.ravel()], axis=1)
    pts = pts[np.linalg.norm(pts - truth.K[:2, 2], axis=1) <= radius_px]
    ideal = lens.to_ideal(pts, truth.K, truth.dist)
    rays = np.column_stack([(ideal - truth.K[:2, 2]) / np.diag(truth.K)[:2], np.ones(len(pts))])
    fitted, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), cal.K, cal.dist)
    return float(np.max(np.linalg.norm(fitted.reshape(-1, 2) - pts, axis=1)))


def _assert_accurate(err: dict[str, float]) -> None:
    for key in ("fx", "fy", "cx", "cy"):
        assert err[key] < 0.005, err
    assert err["position_mm"] < 0.5, err
    assert err["rotation_deg"] < 0.2, err


def test_calibrates_rendered_views_from_a_folder(rendered, tmp_path, capsys) -> None:
    out = tmp_path / "camera.yaml"
    rc = main(["camera-calibrate", "--images", str(rendered["views"]), "--tag-image",
               str(rendered["tag"]), *TAG_ARGS, "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert f"view {len(BOARD_POSES)} (" in text and "% of the image covered" in text
    cal = load_calibration(out)
    assert (cal.width, cal.height) == (WIDTH, HEIGHT)
    err = _errors(cal, rendered["truth"])
    print({k: round(v, 6) for k, v in err.items()}, text, sep="\n")
    _assert_accurate(err)
    # The coefficients trade off (k2 against k3), the lens they make must not, where the
    # board was seen (the views reach 300 px from the centre; no distortion model would be
    # 19 px off there). Beyond it the fit extrapolates: 2.4 px in the image corners.
    gap = _distortion_gap_px(cal, rendered["truth"], 300.0)
    print(f"lens model within 300 px of the centre: {gap:.3f} px")
    assert gap < 1.0
    assert [p.name for p in tmp_path.iterdir()] == ["camera.yaml"]

    # No tag: the intrinsics are recalibrated and the extrinsics of --out kept.
    rc = main(["camera-calibrate", "--images", str(rendered["views"]), "--out", str(out)])
    assert rc == 0
    np.testing.assert_array_equal(load_calibration(out).T_palm_cam, cal.T_palm_cam)


def test_live_camera_keeps_moving_views_until_covered(rendered, tmp_path, monkeypatch,
                                                       capsys) -> None:
    import vlr.hardware.camera_calibration as cc
    from vlr.hardware.camera import FakeCamera

    board = [cv2.imread(str(p)) for p in sorted(rendered["views"].iterdir())]
    tag = cv2.imread(str(rendered["tag"]))
    # Each board view arrives three times (a still board: one kept), then the tag.
    frames = iter([f for f in board for _ in range(3)] + [tag] * 20)

    def source():
        return cv2.cvtColor(next(frames), cv2.COLOR_BGR2RGB)

    monkeypatch.setattr("vlr.hardware.camera.OpenCVCamera",
                        lambda index, width=None, height=None: FakeCamera(source=source))
    monkeypatch.setattr("builtins.input", lambda prompt="": "")
    monkeypatch.setattr(cc, "TAG_TIMEOUT_S", 30.0)
    out = tmp_path / "camera.yaml"
    saved = tmp_path / "kept"
    rc = main(["camera-calibrate", "--camera", "0", *TAG_ARGS, "--out", str(out),
               "--min-views", "8", "--min-coverage", "0.6", "--tag-frames", "5",
               "--save-views", str(saved)])
    text = capsys.readouterr().out
    assert rc == 0, text
    lines = [line for line in text.splitlines() if line.startswith("view ")]
    assert len(lines) >= 8 and len(lines) == len(list(saved.iterdir()))
    assert "over 5 frames" in text
    _assert_accurate(_errors(load_calibration(out), rendered["truth"]))

    # The tag never shows: one line naming it once the wait is over, and no file.
    frames = iter([f for f in board for _ in range(3)] + [board[0]] * 1000)
    monkeypatch.setattr(cc, "TAG_TIMEOUT_S", 0.3)
    none = tmp_path / "none.yaml"
    rc = main(["camera-calibrate", "--camera", "0", *TAG_ARGS, "--out", str(none),
               "--min-views", "8", "--min-coverage", "0.6"])
    assert rc == 2
    assert f"camera (for 0.3 s): tag {TAG_ID} not found" in _error_line(capsys)
    assert not none.exists()


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("vlr camera-calibrate: error: ")
    return err[0]


def test_bad_input_is_one_line_and_no_file(rendered, tmp_path, capsys) -> None:
    out = tmp_path / "out" / "camera.yaml"
    empty = tmp_path / "empty"
    empty.mkdir()
    args = ["camera-calibrate", *TAG_ARGS, "--out", str(out)]
    assert main([*args, "--images", str(empty), "--tag-image", str(rendered["tag"])]) == 2
    assert str(empty) in _error_line(capsys)

    few = tmp_path / "few"
    few.mkdir()
    for p in sorted(rendered["views"].iterdir())[:2]:
        (few / p.name).write_bytes(p.read_bytes())
    (few / "tag.png").write_bytes(rendered["tag"].read_bytes())  # no board in it
    assert main([*args, "--images", str(few), "--tag-image", str(rendered["tag"])]) == 2
    assert "seen in 2 of 3 images" in _error_line(capsys)

    # The tag is looked for after the calibration: a board view holds no 36h11 tag.
    not_tag = sorted(rendered["views"].iterdir())[0]
    assert main([*args, "--images", str(rendered["views"]), "--tag-image", str(not_tag)]) == 2
    line = _error_line(capsys)
    assert str(not_tag) in line and f"tag {TAG_ID} not found" in line

    assert main([*args, "--images", str(rendered["views"]), "--tag-image",
                 str(rendered["tag"]), "--tag-pose", "0", "0", "nan", "0", "0", "0"]) == 2
    assert "--tag-pose" in _error_line(capsys)
    assert main(["camera-calibrate", "--images", str(rendered["views"]), "--out",
                 str(out)]) == 2  # no tag and no calibration to keep the extrinsics of
    assert "no tag given" in _error_line(capsys)
    assert main(["camera-calibrate", "--print-board", str(tmp_path / "b.png"),
                 "--marker-length", "0.02"]) == 2
    assert "--marker-length 0.02" in _error_line(capsys)
    assert not out.exists() and not (tmp_path / "b.png").exists()
    assert not out.parent.exists() or not any(out.parent.iterdir())


def test_command_line_error_exits_2_without_traceback(tmp_path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    tag = tmp_path / "tag.png"
    tag.touch()
    proc = subprocess.run([sys.executable, "-m", "vlr.cli", "camera-calibrate", "--images",
                           str(empty), *TAG_ARGS, "--tag-image", str(tag), "--out",
                           str(tmp_path / "c.yaml")], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"vlr camera-calibrate: error: --images {empty}: no images "
        "(.png, .jpg, .jpeg, .bmp, .tif, .tiff) in it"]


# --------------------------------------------------------------------------- --sim

def _sim_table(text: str) -> dict[str, float]:
    """The --sim table's signed errors: fx..cy [%], k1..k3, and the lens and pose lines."""
    out = {m[0]: float(m[1]) for m in re.findall(r"^  (f[xy]|c[xy]) \[px\] .* ([+-][\d.]+)%$",
                                                 text, re.M)}
    out |= {m[0]: float(m[1]) for m in re.findall(r"^  (k1|k2|p1|p2|k3) .* ([+-][\d.]+)$",
                                                  text, re.M)}
    lens_line = re.search(r"max ([\d.]+) where the board was seen, ([\d.]+) anywhere", text)
    pose = re.search(r"camera in the palm: ([\d.]+) mm and ([\d.]+) deg off", text)
    out |= {"lens_seen_px": float(lens_line[1]), "lens_max_px": float(lens_line[2]),
            "position_mm": float(pose[1]), "rotation_deg": float(pose[2])}
    return out


def test_sim_calibrates_its_own_views_against_the_known_camera(rendered, tmp_path,
                                                                capsys) -> None:
    """`--sim` at its defaults: the YAML written, the printed errors are the YAML's errors
    against the camera the views were rendered with (the fixture's truth: the same mounting,
    lens and size), and they are small."""
    out = tmp_path / "camera.yaml"
    assert main(["camera-calibrate", "--sim", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "view 15 (view_015.png)" in text
    cal = load_calibration(out)
    truth = rendered["truth"]
    assert (cal.width, cal.height) == (WIDTH, HEIGHT)
    err = _errors(cal, truth)
    table = _sim_table(text)
    print(text, {k: round(v, 6) for k, v in err.items()}, sep="\n")
    for key, rc in {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}.items():
        assert table[key] == pytest.approx(100 * (cal.K[rc] / truth.K[rc] - 1), abs=6e-4)
    for k, name in enumerate(("k1", "k2", "p1", "p2", "k3")):
        assert table[name] == pytest.approx(cal.dist[k] - truth.dist[k], abs=6e-6)
    assert table["position_mm"] == pytest.approx(err["position_mm"], abs=6e-4)
    assert table["rotation_deg"] == pytest.approx(err["rotation_deg"], abs=6e-4)
    _assert_accurate(err)
    assert table["lens_seen_px"] < 1.0 and table["lens_max_px"] < 5.0
    assert _distortion_gap_px(cal, truth, 300.0) < 1.0
    assert "# --sim --seed 0: fx " in out.read_text()
    assert [p.name for p in tmp_path.iterdir()] == ["camera.yaml"]


def test_sim_is_seeded_and_its_views_calibrate_the_same_from_a_folder(rendered, tmp_path,
                                                                       capsys) -> None:
    def sim(name: str, *extra: str) -> tuple[str, object]:
        out = tmp_path / name
        assert main(["camera-calibrate", "--sim", "--sim-views", "10", *extra, "--out",
                     str(out)]) == 0
        text = capsys.readouterr().out
        table = text[text.index("against the sim's truth"):text.index("wrote ")]
        return table, load_calibration(out)

    saved = tmp_path / "views"
    table, cal = sim("a.yaml", "--save-views", str(saved))
    again, cal_again = sim("b.yaml")
    assert again == table
    assert (tmp_path / "a.yaml").read_text() == (tmp_path / "b.yaml").read_text()
    other, cal_other = sim("c.yaml", "--seed", "1")
    assert other != table and not np.array_equal(cal_other.K, cal.K)
    _assert_accurate(_errors(cal_other, rendered["truth"]))

    # The saved views through --images: the same detection and calibration, the same camera.
    assert sorted(p.name for p in saved.iterdir()) == [f"view_{k:03d}.png" for k in
                                                       range(1, 11)]
    assert main(["camera-calibrate", "--images", str(saved), "--out",
                 str(tmp_path / "a.yaml")]) == 0
    np.testing.assert_array_equal(load_calibration(tmp_path / "a.yaml").K, cal.K)
    np.testing.assert_array_equal(load_calibration(tmp_path / "a.yaml").dist, cal.dist)


@pytest.mark.parametrize("extra, named", [
    (["--images", "views"], "--images views and --sim: give one source"),
    (["--camera", "0"], "--camera 0 and --sim: give one source"),
    (["--sim-views", "5"], "--sim-views 5: must be from --min-views (10) to 200"),
    (["--sim-views", "12", "--min-views", "13"], "--sim-views 12: must be from --min-views"),
    (["--sim-views", "500"], "--sim-views 500:"),
    (["--tag-image", "tag.png"], "--tag-image tag.png: --sim renders its own tag view"),
    (["--width", "320", "--height", "240"], "--width 320 --height 240: --sim renders"),
    (["--tag-size", "-1"], "--tag-size -1.0: must be a length > 0"),
    (["--seed", "-1"], "--seed -1: must be 0 or more"),
    (["--save-views", "/proc/views"], "--save-views /proc/views: cannot write there"),
])
def test_sim_bad_input_is_one_line_and_no_file(extra, named, tmp_path, capsys) -> None:
    out = tmp_path / "camera.yaml"
    assert main(["camera-calibrate", "--sim", *extra, "--out", str(out)]) == 2
    assert named in _error_line(capsys)
    assert not out.exists()


def test_sim_without_rendering_is_one_line(tmp_path, monkeypatch, capsys) -> None:
    pytest.importorskip("mujoco")

    def no_egl(*args, **kwargs):
        raise RuntimeError("cannot initialize EGL\nno display")

    monkeypatch.setattr("mujoco.Renderer", no_egl)
    out = tmp_path / "camera.yaml"
    assert main(["camera-calibrate", "--sim", "--out", str(out)]) == 2
    assert "MuJoCo cannot render offscreen here" in _error_line(capsys)
    monkeypatch.setitem(sys.modules, "vlr.sim.calibration_views", None)  # import fails
    assert main(["camera-calibrate", "--sim", "--out", str(out)]) == 2
    assert "--sim needs MuJoCo rendering" in _error_line(capsys)
    assert not out.exists()


def test_sources_clash_in_one_line_without_usage(tmp_path) -> None:
    proc = subprocess.run([sys.executable, "-m", "vlr.cli", "camera-calibrate", "--sim",
                           "--images", str(tmp_path), "--out", str(tmp_path / "c.yaml")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"vlr camera-calibrate: error: --images {tmp_path} and --sim: give one source of "
        "board views (--images, --camera or --sim)"]


def test_hardware_side_does_not_import_the_sim() -> None:
    code = ("import sys, vlr.hardware.camera_calibration, vlr.hardware.camera; "
            "print(sorted(m for m in sys.modules if m.startswith('vlr.sim') or m == 'mujoco'))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"

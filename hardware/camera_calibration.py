"""`vlr camera-calibrate`: the palm camera's calibration YAML from a ChArUco board and an AprilTag.

1. Intrinsics and lens distortion (OpenCV's k1, k2, p1, p2, k3) from views of a printed
   ChArUco board (`cv2.aruco.CharucoDetector`, `cv2.calibrateCamera`): a folder of images
   (`--images DIR`) or a live camera (`--camera INDEX`: a frame is kept when the board has
   moved since every kept view, until `--min-views` views have put corners in
   `--min-coverage` of an 8 x 6 grid over the image).
2. The camera's pose in the palm frame from an AprilTag 36h11 at a known palm pose: its
   corners found and refined as `vlr.perception.observe` does, its pose solved with the new
   intrinsics (IPPE_SQUARE, then Levenberg-Marquardt), and T_palm_cam = T_palm_tag T_cam_tag^-1,
   averaged over the tag images (or `--tag-frames` live frames).

The tag frame is vlr/perception/pose.py's object frame: origin at the black square's centre,
x along the printed tag's top edge (left to right), y down the printed tag, z into the
surface it is stuck on (the printed face looks along -z). `--tag-pose X Y Z RX RY RZ` is that
origin in the palm frame [m] and the frame's rotation vector (axis times angle) [deg]: `0 0 0.06
0 0 0` is a tag 60 mm above the palm centre facing the camera, its top edge along +x_palm.

The result is the YAML of vlr/camera.py, written atomically and only once it loads; without
a tag, the extrinsics of an existing `--out` file are kept (intrinsics recalibrated alone).

`--sim` tries it all without a camera: `--sim-views` board views and a tag view rendered by
the sim's palm camera with a known mounting, lens and sensor noise (vlr.sim.calibration_views,
imported only then), calibrated as `--images` is, and the result's errors against that
camera printed and put in the YAML's header.

    vlr camera-calibrate --print-board board.png
    vlr camera-calibrate --sim --out sim_camera.yaml
    vlr camera-calibrate --images views/ --tag-image tag.png --tag-id 0 --tag-size 0.02 \\
        --tag-pose 0 0 0.06 0 0 0 --out camera.yaml
    vlr camera-calibrate --camera 0 --tag-id 0 --tag-size 0.02 --tag-pose 0 0 0.06 0 0 0 \\
        --out camera.yaml
"""

from __future__ import annotations

import argparse
import importlib
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from vlr.camera import (
    CameraCalibration,
    calibration_to_dict,
    invert_pose,
    load_calibration,
    pose_to_matrix,
)
from vlr.errors import UserError
from vlr.io import atomic_path, check_output_dir, check_output_file, read_line
from vlr.perception import detect_tags, observe, to_gray

__all__ = ["BoardSpec", "BoardView", "Coverage", "IntrinsicsFit", "board_image", "calibrate",
           "camera_pose_from_tags", "capture_views", "detect_board", "image_files",
           "tag_pose_matrix", "views_from_folder", "views_from_images", "write_board",
           "write_calibration", "register", "run"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MIN_CORNERS = 6            # per view; fewer hardly constrain the view's homography
GRID = (8, 6)              # coverage cells across x and down y
MIN_SHIFT = 0.05           # live: the board must move this share of the image diagonal
NO_FRAME_TIMEOUT_S = 5.0
TAG_TIMEOUT_S = 60.0
SIM_VIEWS = 15             # --sim: fx, fy within 0.13% over seeds 0-4 (10 views: 0.19%)
MAX_SIM_VIEWS = 200
_N_TAG_IDS = 587           # tag36h11


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares across (x) and down (y), square and marker sides [m], and the
    ArUco dictionary's OpenCV name (e.g. DICT_5X5_100)."""

    squares_x: int = 7
    squares_y: int = 5
    square_length: float = 0.012
    marker_length: float = 0.009
    dictionary: str = "DICT_5X5_100"

    def board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board; raises UserError naming a bad flag."""
        for flag, v in (("--squares-x", self.squares_x), ("--squares-y", self.squares_y)):
            if v < 3:
                raise UserError(f"{flag} {v}: a board needs at least 3 squares each way")
        for flag, v in (("--square-length", self.square_length),
                        ("--marker-length", self.marker_length)):
            if not (math.isfinite(v) and v > 0):
                raise UserError(f"{flag} {v}: must be a length > 0 [m]")
        if self.marker_length >= self.square_length:
            raise UserError(f"--marker-length {self.marker_length}: must be less than "
                            f"--square-length {self.square_length}")
        name = self.dictionary.upper()
        if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
            raise UserError(f"--dictionary {self.dictionary}: not an OpenCV ArUco dictionary "
                            "(e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250)")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
        needed = self.squares_x * self.squares_y // 2
        if needed > dictionary.bytesList.shape[0]:
            raise UserError(f"--dictionary {self.dictionary}: has "
                            f"{dictionary.bytesList.shape[0]} markers, the board needs {needed}")
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_length,
                                      self.marker_length, dictionary)

    def __str__(self) -> str:
        return (f"{self.squares_x}x{self.squares_y} squares of {self.square_length * 1e3:g} mm, "
                f"markers {self.marker_length * 1e3:g} mm, {self.dictionary}")


def board_image(spec: BoardSpec, pixels_per_square: int, margin_squares: float = 0.5
                ) -> np.ndarray:
    """The board as a uint8 grey image with a white margin: squares exactly
    `pixels_per_square` wide, so that printed at the right DPI they are `square_length`."""
    board = spec.board()
    m = round(margin_squares * pixels_per_square)
    size = (spec.squares_x * pixels_per_square + 2 * m, spec.squares_y * pixels_per_square + 2 * m)
    return board.generateImage(size, marginSize=m, borderBits=1)


@dataclass(frozen=True)
class BoardView:
    """The ChArUco corners seen in one image: their ids, board points (N, 3) [m] and image
    points (N, 2) [px]."""

    name: str
    ids: np.ndarray
    object_points: np.ndarray
    image_points: np.ndarray


def detect_board(detector: cv2.aruco.CharucoDetector, image: np.ndarray,
                 name: str = "") -> BoardView | None:
    """The board's corners in `image`, or None with fewer than MIN_CORNERS or all on a line
    (no homography: calibrateCamera would fail on that view)."""
    corners, ids, _, _ = detector.detectBoard(to_gray(image))
    if ids is None or len(ids) < MIN_CORNERS:
        return None
    board = detector.getBoard()
    if board.checkCharucoCornersCollinear(ids):
        return None
    obj, img = board.matchImagePoints(corners, ids)
    return BoardView(name, ids.ravel().astype(int), obj.reshape(-1, 3).astype(np.float32),
                     img.reshape(-1, 2).astype(np.float32))


class Coverage:
    """Which cells of a GRID over the image have had a corner detected."""

    def __init__(self, width: int, height: int, grid: tuple[int, int] = GRID) -> None:
        self.width, self.height = width, height
        self.hits = np.zeros((grid[1], grid[0]), dtype=bool)

    def add(self, points: np.ndarray) -> None:
        rows, cols = self.hits.shape
        # OpenCV pixel centres are integers: the image spans [-0.5, size - 0.5].
        ix = np.clip(((points[:, 0] + 0.5) * cols / self.width).astype(int), 0, cols - 1)
        iy = np.clip(((points[:, 1] + 0.5) * rows / self.height).astype(int), 0, rows - 1)
        self.hits[iy, ix] = True

    @property
    def fraction(self) -> float:
        return float(self.hits.mean())


@dataclass(frozen=True)
class IntrinsicsFit:
    """calibrateCamera's result: K, dist, the RMS reprojection error [px] over all corners,
    each view's RMS [px], and the standard deviations of fx, fy, cx, cy [px]."""

    K: np.ndarray
    dist: np.ndarray
    rms_px: float
    per_view_px: np.ndarray
    std_fx_fy_cx_cy: np.ndarray


def calibrate(views: Sequence[BoardView], width: int, height: int) -> IntrinsicsFit:
    """Intrinsics and 5 distortion coefficients from the board views (cv2.calibrateCamera)."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    # One thread: OpenCV's threads sum in varying order, and the same views gave fits 1e-13
    # apart; one is also no slower here (0.05 s for 30 views, 0.09 s on two threads).
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        rms, K, dist, _, _, std, _, per_view = cv2.calibrateCameraExtended(
            [v.object_points for v in views], [v.image_points for v in views],
            (width, height), None, None, criteria=criteria)
    except cv2.error as exc:
        raise UserError(f"calibrateCamera failed on {len(views)} views: "
                        f"{str(exc).strip().splitlines()[-1]}") from None
    finally:
        cv2.setNumThreads(threads)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and K[0, 0] > 0
            and K[1, 1] > 0):
        raise UserError(f"calibrateCamera gave no usable camera from {len(views)} views: "
                        "show the board at more distances and tilts")
    return IntrinsicsFit(K=K, dist=dist.ravel()[:5], rms_px=float(rms),
                         per_view_px=np.asarray(per_view, dtype=float).ravel(),
                         std_fx_fy_cx_cy=np.asarray(std, dtype=float).ravel()[:4])


# --------------------------------------------------------------------------- views

def _read_image(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise UserError(f"cannot read image {path}")
    return image


def image_files(folder: Path) -> list[Path]:
    """The images in `folder` (by suffix), sorted; UserError if it is not a folder or has
    none."""
    if not folder.is_dir():
        raise UserError(f"--images {folder}: not a folder")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise UserError(f"--images {folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in it")
    return files


def _progress(view: BoardView, coverage: Coverage, n_views: int) -> str:
    return (f"view {n_views} ({view.name}): {len(view.ids)} corners; {n_views} views, "
            f"{coverage.fraction:.0%} of the image covered")


def views_from_images(images: Sequence[tuple[str, np.ndarray]],
                      detector: cv2.aruco.CharucoDetector, min_views: int,
                      source: str) -> list[BoardView]:
    """The board views in named images of one size, with a line of progress each; UserError
    naming `source` (the flag they came from) if fewer than `min_views` show the board."""
    views: list[BoardView] = []
    coverage = None
    for name, image in images:
        if coverage is None:
            coverage = Coverage(image.shape[1], image.shape[0])
        view = detect_board(detector, image, name)
        if view is None:
            print(f"  {name}: board not found (or under {MIN_CORNERS} corners), skipped")
            continue
        views.append(view)
        coverage.add(view.image_points)
        print(_progress(view, coverage, len(views)))
    if len(views) < min_views:
        raise UserError(f"{source}: the board is seen in {len(views)} of {len(images)} "
                        f"images, need at least {min_views} (--min-views)")
    return views


def views_from_folder(folder: Path, detector: cv2.aruco.CharucoDetector,
                      min_views: int) -> tuple[list[BoardView], int, int]:
    """The board views in a folder's images, and the image size; UserError if the images
    differ in size or fewer than `min_views` show the board."""
    files = image_files(folder)
    images = []
    for path in files:
        image = _read_image(path)
        h, w = image.shape[:2]
        if images and (w, h) != (images[0][1].shape[1], images[0][1].shape[0]):
            h0, w0 = images[0][1].shape[:2]
            raise UserError(f"--images: {path} is {w}x{h}, {files[0].name} {w0}x{h0}: "
                            "take every view at one image size")
        images.append((path.name, image))
    views = views_from_images(images, detector, min_views, f"--images {folder}")
    h, w = images[0][1].shape[:2]
    return views, w, h


def _moved(view: BoardView, kept: Sequence[BoardView], min_shift_px: float) -> bool:
    """True if the board has moved by `min_shift_px` (mean over shared corners) since every
    kept view: still frames add no information but would weigh one pose more."""
    for k in kept:
        shared, a, b = np.intersect1d(view.ids, k.ids, return_indices=True)
        if len(shared) >= 4 and np.mean(np.linalg.norm(view.image_points[a]
                                                        - k.image_points[b], axis=1)) \
                < min_shift_px:
            return False
    return True


def capture_views(camera, detector: cv2.aruco.CharucoDetector, min_views: int,
                  min_coverage: float, save_dir: Path | None = None,
                  clock: Callable[[], float] = time.monotonic
                  ) -> tuple[list[BoardView], int, int]:
    """Board views from a live FrameSource (hardware/camera.py) until at least `min_views`
    are kept and their corners cover `min_coverage` of the GRID; a line of progress per kept
    view. Kept frames go to `save_dir` (PNG) if given."""
    views: list[BoardView] = []
    coverage = None
    frames = 0
    last_frame = clock()
    print(f"show the board to the camera at different distances, tilts and places in the "
          f"image; until {min_views} views cover {min_coverage:.0%} of it (Ctrl-C stops)")
    while coverage is None or len(views) < min_views or coverage.fraction < min_coverage:
        image = camera.read()
        if image is None:
            if clock() - last_frame > NO_FRAME_TIMEOUT_S:
                raise UserError(f"the camera delivered no frame for {NO_FRAME_TIMEOUT_S:g} s")
            continue
        last_frame = clock()
        frames += 1
        h, w = image.shape[:2]
        if coverage is None:
            coverage = Coverage(w, h)
        view = detect_board(detector, image, f"frame {frames}")
        if view is None or not _moved(view, views, MIN_SHIFT * math.hypot(w, h)):
            continue
        views.append(view)
        coverage.add(view.image_points)
        if save_dir is not None:
            save_dir.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(save_dir / f"view_{len(views):03d}.png"), to_gray(image))
        print(_progress(view, coverage, len(views)), flush=True)
    return views, coverage.width, coverage.height


# --------------------------------------------------------------------------- tag

def tag_pose_matrix(values: Sequence[float]) -> np.ndarray:
    """T_palm_tag (4x4) from `--tag-pose X Y Z RX RY RZ` ([m], rotation vector [deg])."""
    v = np.asarray(values, dtype=float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise UserError(f"--tag-pose {list(values)}: give six finite numbers X Y Z [m] "
                        "RX RY RZ [deg]")
    return pose_to_matrix(v[:3], Rotation.from_rotvec(v[3:], degrees=True).as_matrix())


def _tag_in_camera(image: np.ndarray, K: np.ndarray, dist: np.ndarray, tag_id: int,
                   tag_size: float, where: str | None) -> np.ndarray | None:
    """T_cam_tag; if the tag is not seen or not measurable, None, or with `where` a
    UserError naming it and why."""
    gray = np.ascontiguousarray(to_gray(image))
    h, w = gray.shape
    cal = CameraCalibration(width=w, height=h, K=K, dist=dist, T_palm_cam=np.eye(4))
    obs = observe(gray, cal, tag_id, tag_size)
    if obs is not None:
        return np.asarray(obs.tag_pose_cam)
    if where is None:
        return None
    ids = [d.tag_id for d in detect_tags(gray)]
    if tag_id not in ids:
        seen = ", ".join(map(str, sorted(set(ids)))) or "none"
        raise UserError(f"{where}: tag {tag_id} not found (36h11 tags seen: {seen})")
    if ids.count(tag_id) > 1:
        raise UserError(f"{where}: tag {tag_id} is seen {ids.count(tag_id)} times")
    raise UserError(f"{where}: tag {tag_id} found but not measured (partly out of view, "
                    "too small, blurred, or --tag-size wrong?)")


def camera_pose_from_tags(poses_cam_tag: Sequence[np.ndarray], T_palm_tag: np.ndarray
                          ) -> np.ndarray:
    """T_palm_cam from the tag's poses in the camera (averaged: mean position, chordal mean
    rotation) and its known pose in the palm."""
    Ts = np.asarray(poses_cam_tag, dtype=float)
    T = pose_to_matrix(Ts[:, :3, 3].mean(axis=0),
                       Rotation.from_matrix(Ts[:, :3, :3]).mean().as_matrix())
    return T_palm_tag @ invert_pose(T)


def _live_tag_poses(camera, K, dist, tag_id: int, tag_size: float, frames: int,
                    clock: Callable[[], float] = time.monotonic) -> list[np.ndarray]:
    try:
        read_line(f"put tag {tag_id} at its --tag-pose in view of the camera, then press "
                  "Enter: ")
    except EOFError:  # no terminal (a script): look for the tag straight away
        print()
    poses: list[np.ndarray] = []
    start = clock()
    last = None
    while len(poses) < frames:
        if clock() - start > TAG_TIMEOUT_S:
            if last is not None:  # says why in the last frame
                _tag_in_camera(last, K, dist, tag_id, tag_size,
                               f"camera (for {TAG_TIMEOUT_S:g} s)")
            raise UserError(f"the camera delivered no frame in {TAG_TIMEOUT_S:g} s")
        image = camera.read()
        if image is None:
            continue
        last = image
        if (T := _tag_in_camera(image, K, dist, tag_id, tag_size, None)) is not None:
            poses.append(T)
    return poses


# --------------------------------------------------------------------------- output

def _yaml_text(cal: CameraCalibration, header: str) -> str:
    return ("# vlr camera calibration (format: vlr/camera.py)\n"
            + "".join(f"# {line}\n" for line in header.splitlines())
            + yaml.safe_dump(calibration_to_dict(cal), sort_keys=False,
                             default_flow_style=None))


def write_calibration(cal: CameraCalibration, path: Path, header: str) -> None:
    """Write atomically, and only a file that `load_calibration` reads back."""
    with atomic_path(path) as tmp:
        tmp.write_text(_yaml_text(cal, header), encoding="utf-8")
        load_calibration(tmp)


def write_board(spec: BoardSpec, path: Path, dpi: int) -> None:
    """The board image at `dpi` (embedded in the PNG) with squares as close to
    `square_length` as whole printer pixels allow; prints the printed size."""
    from PIL import Image

    pps = max(1, round(spec.square_length / 0.0254 * dpi))
    image = board_image(spec, pps)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG", dpi=(dpi, dpi))
    printed = pps / dpi * 25.4
    print(f"wrote {path}: {spec}; print at 100% ({dpi} dpi): squares {printed:.3f} mm, "
          f"board {spec.squares_x * printed:.1f} x {spec.squares_y * printed:.1f} mm. Measure "
          "the printed squares and markers and pass those lengths")


# --------------------------------------------------------------------------- CLI

def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `camera-calibrate` subcommand (entry point group vlr.commands)."""
    p = subparsers.add_parser("camera-calibrate",
                              help="palm camera intrinsics from a ChArUco board and its pose "
                                   "in the palm from an AprilTag", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    # One of the three, checked in _check_args: argparse's own check prints its usage too.
    src = p.add_argument_group("board views (one of)")
    src.add_argument("--images", type=Path, metavar="DIR", help="folder of board images")
    src.add_argument("--camera", type=int, metavar="INDEX", help="live OpenCV camera index")
    src.add_argument("--sim", action="store_true",
                     help="rendered views of the sim's palm camera with a known lens and "
                          "noise; prints the calibration's errors against that truth")
    src.add_argument("--sim-views", type=int, default=SIM_VIEWS, metavar="N",
                     help=f"--sim: board views to render (default {SIM_VIEWS})")
    src.add_argument("--seed", type=int, default=0,
                     help="--sim: seeds the board poses and the sensor noise (default 0)")
    p.add_argument("--width", type=int, help="live: image width to ask the camera for [px]")
    p.add_argument("--height", type=int, help="live: image height to ask the camera for [px]")
    p.add_argument("--save-views", type=Path, metavar="DIR",
                   help="live or --sim: save the kept board views here (to rerun with "
                        "--images)")
    d = BoardSpec()
    b = p.add_argument_group("board")
    b.add_argument("--squares-x", type=int, default=d.squares_x,
                   help=f"squares across (default {d.squares_x})")
    b.add_argument("--squares-y", type=int, default=d.squares_y,
                   help=f"squares down (default {d.squares_y})")
    b.add_argument("--square-length", type=float, default=d.square_length,
                   help=f"square side [m] (default {d.square_length})")
    b.add_argument("--marker-length", type=float, default=d.marker_length,
                   help=f"marker side [m] (default {d.marker_length})")
    b.add_argument("--dictionary", default=d.dictionary,
                   help=f"ArUco dictionary (default {d.dictionary})")
    b.add_argument("--print-board", type=Path, metavar="FILE.png",
                   help="write the board image to print, then stop unless --images, "
                        "--camera or --sim")
    b.add_argument("--dpi", type=int, default=300, help="--print-board resolution (default 300)")
    b.add_argument("--min-views", type=int, default=10,
                   help="board views needed (default 10)")
    b.add_argument("--min-coverage", type=float, default=0.7,
                   help=f"live: share of an {GRID[0]}x{GRID[1]} image grid the corners must "
                        "reach (default 0.7)")
    t = p.add_argument_group("tag (camera pose in the palm)")
    t.add_argument("--tag-id", type=int, help="AprilTag 36h11 id (--sim: default 7)")
    t.add_argument("--tag-size", type=float,
                   help="the tag's black square side [m] (--sim: default 0.02)")
    t.add_argument("--tag-pose", type=float, nargs=6, metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="tag frame in the palm frame: position [m], rotation vector [deg] "
                        "(--sim: default 0.003 -0.004 0.065 4 -6 25)")
    t.add_argument("--tag-image", type=Path, nargs="+", metavar="FILE",
                   help="image(s) of the tag (default with --camera: live frames)")
    t.add_argument("--tag-frames", type=int, default=10,
                   help="live: tag frames to average (default 10)")
    p.add_argument("--out", type=Path, metavar="FILE.yaml", help="calibration YAML to write")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> np.ndarray | None:
    """Everything that can be checked before the camera runs; T_palm_tag or None. With
    --sim, the tag flags not given take the sim's tag."""
    sources = [flag for flag, given in (("--images", args.images is not None),
                                        ("--camera", args.camera is not None),
                                        ("--sim", args.sim)) if given]
    if not sources:
        raise UserError("give --images DIR, --camera INDEX or --sim (or just --print-board "
                        "FILE.png)")
    if len(sources) > 1:
        named = {"--images": f"--images {args.images}", "--camera": f"--camera {args.camera}",
                 "--sim": "--sim"}
        raise UserError(f"{' and '.join(named[f] for f in sources)}: give one source of board "
                        "views (--images, --camera or --sim)")
    if args.out is None:
        raise UserError("give --out FILE.yaml, the calibration to write")
    if args.out.is_dir():
        raise UserError(f"--out {args.out} is a folder: give the YAML file to write")
    check_output_file(args.out, "--out")   # before the views, not after them
    if args.save_views is not None:
        check_output_dir(args.save_views, "--save-views")
    if (args.width is None) != (args.height is None):
        raise UserError(f"--width {args.width} --height {args.height}: give both or neither")
    if args.min_views < 3:
        raise UserError(f"--min-views {args.min_views}: must be at least 3")
    if not 0.0 <= args.min_coverage <= 1.0:
        raise UserError(f"--min-coverage {args.min_coverage}: must be in [0, 1]")
    if args.sim:
        _check_sim_args(args)
    tag = {"--tag-id": args.tag_id, "--tag-size": args.tag_size, "--tag-pose": args.tag_pose}
    given = [k for k, v in tag.items() if v is not None]
    if not given:
        if args.tag_image:
            raise UserError("--tag-image needs --tag-id, --tag-size and --tag-pose")
        if not args.out.is_file():
            raise UserError(f"no tag given and --out {args.out} does not exist: give --tag-id, "
                            "--tag-size and --tag-pose for the camera's pose in the palm")
        load_calibration(args.out)  # its extrinsics are kept: it must load
        return None
    if len(given) < len(tag):
        missing = [k for k in tag if k not in given]
        raise UserError(f"{', '.join(given)} also needs {', '.join(missing)}")
    if not 0 <= args.tag_id < _N_TAG_IDS:
        raise UserError(f"--tag-id {args.tag_id}: must be a 36h11 id, 0..{_N_TAG_IDS - 1}")
    if not (math.isfinite(args.tag_size) and args.tag_size > 0):
        raise UserError(f"--tag-size {args.tag_size}: must be a length > 0 [m]")
    for path in args.tag_image or ():
        if not path.is_file():
            raise UserError(f"--tag-image {path}: no such file")
    if args.images is not None and not args.tag_image:
        raise UserError("--images needs --tag-image FILE for the tag (or leave the tag out "
                        "to keep the extrinsics of --out)")
    if args.tag_frames < 1:
        raise UserError(f"--tag-frames {args.tag_frames}: must be at least 1")
    return tag_pose_matrix(args.tag_pose)


def _check_sim_args(args: argparse.Namespace) -> None:
    """--sim's own checks; fills the tag flags not given with the sim's tag."""
    if not args.min_views <= args.sim_views <= MAX_SIM_VIEWS:
        raise UserError(f"--sim-views {args.sim_views}: must be from --min-views "
                        f"({args.min_views}) to {MAX_SIM_VIEWS}")
    if args.seed < 0:
        raise UserError(f"--seed {args.seed}: must be 0 or more")
    if args.width is not None or args.height is not None:
        raise UserError(f"--width {args.width} --height {args.height}: --sim renders the sim's "
                        "palm camera at its own size (these are for --camera)")
    if args.tag_image:
        raise UserError(f"--tag-image {args.tag_image[0]}: --sim renders its own tag view")
    tag = _sim_module().SimTag()
    args.tag_id = tag.tag_id if args.tag_id is None else args.tag_id
    args.tag_size = tag.size if args.tag_size is None else args.tag_size
    args.tag_pose = list(tag.pose) if args.tag_pose is None else args.tag_pose


def _sim_module():
    """vlr.sim.calibration_views, imported only for --sim: the hardware side runs without
    the sim's rendering."""
    try:
        return importlib.import_module("vlr.sim.calibration_views")
    except ImportError as exc:
        raise UserError(f"--sim needs MuJoCo rendering (vlr.sim): {exc}") from None


def run(args: argparse.Namespace) -> int:
    """The command: print the board; calibrate; measure the tag; write the YAML."""
    spec = BoardSpec(args.squares_x, args.squares_y, args.square_length, args.marker_length,
                     args.dictionary)
    board = spec.board()
    if args.print_board is not None:
        if args.dpi < 50:
            raise UserError(f"--dpi {args.dpi}: must be at least 50")
        write_board(spec, args.print_board, args.dpi)
        if args.images is None and args.camera is None and not args.sim:
            return 0
    T_palm_tag = _check_args(args)
    detector = cv2.aruco.CharucoDetector(board)
    camera = None
    sim = None
    try:
        if args.images is not None:
            views, width, height = views_from_folder(args.images, detector, args.min_views)
        elif args.sim:
            sim = _render_sim(args, board)
            views = views_from_images(
                [(f"view_{k:03d}.png", image) for k, image in enumerate(sim.boards, 1)],
                detector, args.min_views, f"--sim --sim-views {args.sim_views} --seed "
                f"{args.seed}")
            width, height = sim.truth.width, sim.truth.height
        else:
            from vlr.hardware.camera import OpenCVCamera

            # OpenCV logs each backend it tries on a bad index; CameraError says it in a line.
            level = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
            try:
                camera = OpenCVCamera(args.camera, args.width, args.height)
            finally:
                cv2.utils.logging.setLogLevel(level)
            views, width, height = capture_views(camera, detector, args.min_views,
                                                 args.min_coverage, args.save_views)
        fit = calibrate(views, width, height)
        _print_intrinsics(fit, views)
        if T_palm_tag is None:
            T_palm_cam = load_calibration(args.out).T_palm_cam
            print(f"extrinsics kept from {args.out}")
        else:
            if sim is not None:
                poses = [_tag_in_camera(sim.tag, fit.K, fit.dist, args.tag_id, args.tag_size,
                                        "--sim tag view")]
            elif args.tag_image:
                poses = []
                for path in args.tag_image:
                    image = _read_image(path)
                    if image.shape[:2] != (height, width):
                        raise UserError(f"--tag-image {path} is {image.shape[1]}x"
                                        f"{image.shape[0]}, the board views {width}x{height}")
                    poses.append(_tag_in_camera(image, fit.K, fit.dist, args.tag_id,
                                                args.tag_size, f"--tag-image {path}"))
            else:
                poses = _live_tag_poses(camera, fit.K, fit.dist, args.tag_id, args.tag_size,
                                        args.tag_frames)
            T_palm_cam = camera_pose_from_tags(poses, T_palm_tag)
            _print_pose(T_palm_cam, poses)
    finally:
        if camera is not None:
            camera.close()
    cal = CameraCalibration(width=width, height=height, K=fit.K, dist=fit.dist,
                            T_palm_cam=T_palm_cam)
    header = (f"vlr camera-calibrate: {len(views)} board views ({spec}), RMS reprojection "
              f"{fit.rms_px:.3f} px")
    if sim is not None:
        errors = _sim_module().compare_to_truth(
            cal, sim.truth, np.concatenate([v.image_points for v in views]))
        for line in _sim_report(cal, sim.truth, errors, args):
            print(line)
        header += "\n" + _sim_summary(errors, args)
    write_calibration(cal, args.out, header)
    print(f"wrote {args.out}")
    return 0


def _render_sim(args: argparse.Namespace, board: cv2.aruco.CharucoBoard):
    """The --sim views (vlr.sim.calibration_views.CalibrationViews), saved to --save-views."""
    cv = _sim_module()
    print(f"rendering {args.sim_views} board views and a tag view of the sim's palm camera "
          f"(seed {args.seed})")
    sim = cv.render_board_views(board, args.sim_views, seed=args.seed,
                                tag=cv.SimTag(args.tag_id, args.tag_size,
                                              tuple(args.tag_pose)))
    if args.save_views is not None:
        args.save_views.mkdir(parents=True, exist_ok=True)
        for k, image in enumerate(sim.boards, 1):
            cv2.imwrite(str(args.save_views / f"view_{k:03d}.png"), to_gray(image))
    return sim


def _print_intrinsics(fit: IntrinsicsFit, views: Sequence[BoardView]) -> None:
    (fx, fy), (cx, cy) = np.diag(fit.K)[:2], fit.K[:2, 2]
    s = fit.std_fx_fy_cx_cy
    worst = int(np.argmax(fit.per_view_px))
    print(f"intrinsics from {len(views)} views: fx {fx:.2f} +- {s[0]:.2f}, fy {fy:.2f} +- "
          f"{s[1]:.2f}, cx {cx:.2f} +- {s[2]:.2f}, cy {cy:.2f} +- {s[3]:.2f} px; dist "
          f"{np.array2string(fit.dist, precision=5)}")
    print(f"RMS reprojection {fit.rms_px:.3f} px; worst view {views[worst].name} "
          f"{fit.per_view_px[worst]:.3f} px")
    if fit.rms_px > 1.0:
        print("  over 1 px: blurred views, a board that is not flat, or wrong board "
              "flags; look at the worst views")


def _print_pose(T_palm_cam: np.ndarray, poses: Sequence[np.ndarray]) -> None:
    t = T_palm_cam[:3, 3] * 1e3
    r = Rotation.from_matrix(T_palm_cam[:3, :3]).as_rotvec(degrees=True)
    spread = ""
    if len(poses) > 1:
        sd = np.std([p[:3, 3] for p in poses], axis=0).max() * 1e3
        spread = f" (tag position spread {sd:.3f} mm over {len(poses)} frames)"
    print(f"camera in the palm: position [{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] mm, rotation "
          f"vector [{r[0]:.2f}, {r[1]:.2f}, {r[2]:.2f}] deg{spread}")


def _sim_report(cal: CameraCalibration, truth: CameraCalibration, errors: dict,
                args: argparse.Namespace) -> list[str]:
    """The --sim table: each intrinsic and coefficient, true and calibrated; how far apart
    the true and the calibrated camera image the same rays (over a grid of the image); the
    camera's pose error."""
    lines = [f"against the sim's truth (--seed {args.seed}, {args.sim_views} views):",
             f"  {'':9} {'true':>10} {'calibrated':>11} {'error':>9}"]
    for name, (r, c) in zip(("fx", "fy", "cx", "cy"), ((0, 0), (1, 1), (0, 2), (1, 2)),
                            strict=True):
        lines.append(f"  {name + ' [px]':9} {truth.K[r, c]:10.3f} {cal.K[r, c]:11.3f} "
                     f"{errors[name + '_pct']:+8.3f}%")
    for name, t, d in zip(("k1", "k2", "p1", "p2", "k3"), errors["dist_true"],
                          errors["dist_diff"], strict=True):
        lines.append(f"  {name:9} {t:10.5f} {t + d:11.5f} {d:+9.5f}")
    lines.append(f"  rays imaged apart [px]: RMS {errors['lens_rms_px']:.3f}, max "
                 f"{errors['lens_max_seen_px']:.3f} where the board was seen, "
                 f"{errors['lens_max_px']:.3f} anywhere")
    lines.append(f"  camera in the palm: {errors['position_mm']:.3f} mm and "
                 f"{errors['rotation_deg']:.3f} deg off")
    return lines


def _sim_summary(errors: dict, args: argparse.Namespace) -> str:
    """The --sim errors on one line, for the YAML's header."""
    return (f"--sim --seed {args.seed}: fx {errors['fx_pct']:+.3f}%, fy {errors['fy_pct']:+.3f}%, "
            f"cx {errors['cx_pct']:+.3f}%, cy {errors['cy_pct']:+.3f}%; lens "
            f"{errors['lens_max_seen_px']:.3f} px where seen, {errors['lens_max_px']:.3f} px "
            f"anywhere; pose {errors['position_mm']:.3f} mm, {errors['rotation_deg']:.3f} deg")

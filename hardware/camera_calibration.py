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

    vlr camera-calibrate --print-board board.png
    vlr camera-calibrate --images views/ --tag-image tag.png --tag-id 0 --tag-size 0.02 \\
        --tag-pose 0 0 0.06 0 0 0 --out camera.yaml
    vlr camera-calibrate --camera 0 --tag-id 0 --tag-size 0.02 --tag-pose 0 0 0.06 0 0 0 \\
        --out camera.yaml
"""

from __future__ import annotations

import argparse
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
from vlr.io import atomic_path, read_line
from vlr.perception import detect_tags, observe, to_gray

__all__ = ["BoardSpec", "BoardView", "Coverage", "IntrinsicsFit", "board_image", "calibrate",
           "camera_pose_from_tags", "capture_views", "detect_board", "image_files",
           "tag_pose_matrix", "views_from_folder", "write_board", "write_calibration",
           "register", "run"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MIN_CORNERS = 6            # per view; fewer hardly constrain the view's homography
GRID = (8, 6)              # coverage cells across x and down y
MIN_SHIFT = 0.05           # live: the board must move this share of the image diagonal
NO_FRAME_TIMEOUT_S = 5.0
TAG_TIMEOUT_S = 60.0
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


def views_from_folder(folder: Path, detector: cv2.aruco.CharucoDetector,
                      min_views: int) -> tuple[list[BoardView], int, int]:
    """The board views in a folder's images, and the image size; UserError if the images
    differ in size or fewer than `min_views` show the board."""
    files = image_files(folder)
    views: list[BoardView] = []
    size = None
    coverage = None
    for path in files:
        image = _read_image(path)
        h, w = image.shape[:2]
        if size is None:
            size, coverage = (w, h), Coverage(w, h)
        elif (w, h) != size:
            raise UserError(f"--images: {path} is {w}x{h}, {files[0].name} {size[0]}x{size[1]}: "
                            "take every view at one image size")
        view = detect_board(detector, image, path.name)
        if view is None:
            print(f"  {path.name}: board not found (or under {MIN_CORNERS} corners), skipped")
            continue
        views.append(view)
        coverage.add(view.image_points)
        print(_progress(view, coverage, len(views)))
    if len(views) < min_views:
        raise UserError(f"--images {folder}: the board is seen in {len(views)} of {len(files)} "
                        f"images, need at least {min_views} (--min-views)")
    return views, size[0], size[1]


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
    return (f"# vlr camera calibration (format: vlr/camera.py)\n# {header}\n"
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
    src = p.add_mutually_exclusive_group()
    src.add_argument("--images", type=Path, metavar="DIR", help="folder of board images")
    src.add_argument("--camera", type=int, metavar="INDEX", help="live OpenCV camera index")
    p.add_argument("--width", type=int, help="live: image width to ask the camera for [px]")
    p.add_argument("--height", type=int, help="live: image height to ask the camera for [px]")
    p.add_argument("--save-views", type=Path, metavar="DIR",
                   help="live: save the kept board views here (to rerun with --images)")
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
                   help="write the board image to print, then stop unless --images/--camera")
    b.add_argument("--dpi", type=int, default=300, help="--print-board resolution (default 300)")
    b.add_argument("--min-views", type=int, default=10,
                   help="board views needed (default 10)")
    b.add_argument("--min-coverage", type=float, default=0.7,
                   help=f"live: share of an {GRID[0]}x{GRID[1]} image grid the corners must "
                        "reach (default 0.7)")
    t = p.add_argument_group("tag (camera pose in the palm)")
    t.add_argument("--tag-id", type=int, help="AprilTag 36h11 id")
    t.add_argument("--tag-size", type=float, help="the tag's black square side [m]")
    t.add_argument("--tag-pose", type=float, nargs=6, metavar=("X", "Y", "Z", "RX", "RY", "RZ"),
                   help="tag frame in the palm frame: position [m], rotation vector [deg]")
    t.add_argument("--tag-image", type=Path, nargs="+", metavar="FILE",
                   help="image(s) of the tag (default with --camera: live frames)")
    t.add_argument("--tag-frames", type=int, default=10,
                   help="live: tag frames to average (default 10)")
    p.add_argument("--out", type=Path, metavar="FILE.yaml", help="calibration YAML to write")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> np.ndarray | None:
    """Everything that can be checked before the camera runs; T_palm_tag or None."""
    if args.images is None and args.camera is None:
        raise UserError("give --images DIR or --camera INDEX (or just --print-board FILE.png)")
    if args.out is None:
        raise UserError("give --out FILE.yaml, the calibration to write")
    if args.out.is_dir():
        raise UserError(f"--out {args.out} is a folder: give the YAML file to write")
    if (args.width is None) != (args.height is None):
        raise UserError(f"--width {args.width} --height {args.height}: give both or neither")
    if args.min_views < 3:
        raise UserError(f"--min-views {args.min_views}: must be at least 3")
    if not 0.0 <= args.min_coverage <= 1.0:
        raise UserError(f"--min-coverage {args.min_coverage}: must be in [0, 1]")
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


def run(args: argparse.Namespace) -> int:
    """The command: print the board; calibrate; measure the tag; write the YAML."""
    spec = BoardSpec(args.squares_x, args.squares_y, args.square_length, args.marker_length,
                     args.dictionary)
    board = spec.board()
    if args.print_board is not None:
        if args.dpi < 50:
            raise UserError(f"--dpi {args.dpi}: must be at least 50")
        write_board(spec, args.print_board, args.dpi)
        if args.images is None and args.camera is None:
            return 0
    T_palm_tag = _check_args(args)
    detector = cv2.aruco.CharucoDetector(board)
    camera = None
    try:
        if args.images is not None:
            views, width, height = views_from_folder(args.images, detector, args.min_views)
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
            if args.tag_image:
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
    write_calibration(cal, args.out, f"vlr camera-calibrate: {len(views)} board views "
                                     f"({spec}), RMS reprojection {fit.rms_px:.3f} px")
    print(f"wrote {args.out}")
    return 0


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

"""AprilTag 36h11 detection and sub-pixel corner refinement.

Coordinates are OpenCV's: the centre of pixel (0, 0) is at (0, 0). Corners come in the
detector's order: the printed tag's top-left, top-right, bottom-right, bottom-left (clockwise
in the image when the tag is seen from its printed side).

Corner refinement, measured on box-filtered synthetic renders (48 poses at 40-60 mm, tilts up
to 30 deg, 640x480, tests/tag_images.py), error per corner against the true projection:

* aruco CORNER_REFINE_SUBPIX (cornerSubPix): unbiased, 0.14 px RMS, max 0.4 px; 0.17 px RMS
  with a blur of 1 px. cornerSubPix is made for saddle points; at the OUTER corner of a
  blurred, tilted black square it is pulled along the edges.
* aruco CORNER_REFINE_APRILTAG: 0.07 px spread but a +0.44 px bias in x and y: the AprilTag
  library puts pixel centres at +0.5 (pixel (0, 0) spans [0, 1]), the half-pixel convention
  clash, plus a blur-dependent part (0.46 with more blur) from fitting thresholded boundary
  pixels, so a fixed -0.5 shift would not remove it.
* CORNER_REFINE_CONTOUR and NONE: 0.5 px RMS, max 1.1 px.
* `refine_edges` (ours, what `observe` uses): a straight line fitted to each side of the
  black square from 1 px-spaced sub-pixel edge points, neighbouring lines intersected:
  0.004 px RMS (max 0.02) clean, 0.008 px (max 0.034) with noise sigma 3 and blur 1 px;
  0.009-0.013 px RMS (max 0.065) at 320x240. Unbiased (mean below 0.001 px). aruco's
  SUBPIX corners seed it and stand in, flagged, if it fails.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from vlr.perception import lens

__all__ = ["DetectorConfig", "Detection", "detect_tags", "refine_edges", "get_detector"]


@dataclass(frozen=True)
class DetectorConfig:
    """Detector settings (hashable: detectors are cached per config).

    Attributes:
        min_distance_to_border: aruco minDistanceToBorder [px]. 0: the default (3) drops
            large, fully visible tags whose white border touches the frame; `observe` applies
            its own corner margin instead.
        max_perimeter_rate: aruco maxMarkerPerimeterRate (perimeter / larger image side); a
            tag that nearly fills the frame has a rate close to 4.
        min_perimeter_rate: aruco minMarkerPerimeterRate (its default).
        adaptive_windows: adaptive threshold window sizes (min, max, step) [px].
        fast_min_side_ratio: if set, `detect_tags(..., fast=True)` uses aruco's ArUco3 mode,
            which searches a downscaled image for tags whose side is at least this fraction
            of the larger image side (about 1.5 ms instead of 5 ms at 640x480; its corners
            can be 3 px off, which `refine_edges`' coarse pass absorbs).
    """

    min_distance_to_border: int = 0
    max_perimeter_rate: float = 4.0
    min_perimeter_rate: float = 0.03
    adaptive_windows: tuple[int, int, int] = (3, 23, 10)
    fast_min_side_ratio: float | None = 0.05


@dataclass(frozen=True)
class Detection:
    """One decoded tag: its id and corners (4, 2) [px], detector order."""

    tag_id: int
    corners: np.ndarray


@functools.lru_cache(maxsize=8)
def get_detector(config: DetectorConfig, fast: bool = False) -> cv2.aruco.ArucoDetector:
    """The ArucoDetector for `config` (its ArUco3 variant if `fast`), built once per config:
    construction costs about as much as a detection, and the detector keeps its buffers."""
    params = cv2.aruco.DetectorParameters()
    params.minDistanceToBorder = int(config.min_distance_to_border)
    params.maxMarkerPerimeterRate = float(config.max_perimeter_rate)
    params.minMarkerPerimeterRate = float(config.min_perimeter_rate)
    lo, hi, step = config.adaptive_windows
    params.adaptiveThreshWinSizeMin = int(lo)
    params.adaptiveThreshWinSizeMax = int(hi)
    params.adaptiveThreshWinSizeStep = int(step)
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.cornerRefinementMaxIterations = 50
    params.cornerRefinementMinAccuracy = 0.01
    if fast:
        if config.fast_min_side_ratio is None:
            raise ValueError("fast detection needs DetectorConfig.fast_min_side_ratio")
        params.useAruco3Detection = True
        params.minMarkerLengthRatioOriginalImg = float(config.fast_min_side_ratio)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    return cv2.aruco.ArucoDetector(dictionary, params)


def detect_tags(gray: np.ndarray, config: DetectorConfig = DetectorConfig(),
                fast: bool = False) -> list[Detection]:
    """All 36h11 tags decoded in a uint8 grey image, with aruco's SUBPIX corners (refine
    the one you need with `refine_edges`); `fast` as in `DetectorConfig`."""
    corners, ids, _ = get_detector(config, fast).detectMarkers(gray)
    if ids is None or len(ids) == 0:
        return []
    return [Detection(int(i), np.asarray(c, dtype=np.float64).reshape(4, 2))
            for c, i in zip(corners, ids.ravel(), strict=True)]


# --------------------------------------------------------------------------- edge refinement

_CELLS = 8                # the black square is 8 cells wide (36h11 + 1-cell black border)
_PROFILE_STEP = 0.5       # px between samples across an edge
_MAX_HALF_WINDOW = 6.0    # px, half-length of a profile
_MAX_SEED_ERROR = 4.0     # px: a coarse pass moving a corner further means a bad seed or fit
_MAX_CORNER_SHIFT = 1.5   # px: the fine pass moving a corner further means a bad fit


def refine_edges(gray: np.ndarray, corners: np.ndarray, K: np.ndarray | None = None,
                 dist: np.ndarray | None = None) -> np.ndarray | None:
    """Corners of the black square from line fits to its four sides, or None if unsure.

    For points 1 px apart along each side (away from the corners), the grey profile across
    the side is read by bilinear interpolation over +-min(0.6 cell, 6 px), the cell measured
    across that side, where the inside stays on the tag's black border and the outside on
    its white border. The edge position on each profile is found by the area (first-moment)
    rule:
        e = s_hi - integral (I(s) - I_dark) / (I_bright - I_dark) ds,
    which is exact for any blur (symmetric or not) as long as the window holds the whole
    transition, and, unlike a 50 % crossing on interpolated samples, has no bias on sharp,
    box-filtered edges. A total-least-squares line through each side's points (refitted
    without points beyond 3 robust sigmas, e.g. a finger over the edge), then the
    intersections of neighbouring lines, give the corners.

    With lens distortion (K and a non-zero `dist`) the sides are curved in the image: the
    geometry (sides, profiles, lines) then lives in ideal pinhole pixels of the same K, where
    the sides are straight, and each sample is read at its distorted image position.

    Two passes: a coarse one (profiles 4 px apart, +-0.45 cell) takes seeds up to 4 px off
    (less for small cells) to within ~0.05 px; the fine one (1 px apart) starts there.

    Args:
        gray: uint8 image.
        corners: (4, 2) seed corners in the image (within ~4 px), detector order.
        K, dist: camera matrix and OpenCV distortion, or None for an ideal pinhole image.

    Returns:
        (4, 2) refined corners (in ideal pixels if there is distortion), or None if a side
        has too few good edge points or a corner moved too far (4 px in the coarse pass,
        1.5 px in the fine one).
    """
    seed = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    sample: Callable[[np.ndarray, np.ndarray], np.ndarray]
    if K is not None and dist is not None and np.any(np.asarray(dist) != 0):
        seed = lens.to_ideal(seed, K, dist)

        def sample(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            img = lens.to_image(np.stack([x, y], axis=-1), K, dist)
            return _bilinear(gray, img[..., 0], img[..., 1])
    else:
        def sample(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            return _bilinear(gray, x, y)
    coarse = _refine_once(sample, seed, along_step=4.0, window_cells=0.45,
                          max_shift=_MAX_SEED_ERROR)
    if coarse is None:
        return None
    # Centred on the edges now: a wider window (0.6 cell) holds more of a blurred transition.
    return _refine_once(sample, coarse, along_step=1.0, window_cells=0.6,
                        max_shift=_MAX_CORNER_SHIFT)


def _refine_once(sample: Callable[[np.ndarray, np.ndarray], np.ndarray], quad: np.ndarray,
                 along_step: float, window_cells: float, max_shift: float) -> np.ndarray | None:
    """One pass of `refine_edges` from seed corners `quad` (4, 2); `sample(x, y)` reads
    grey values at points with coordinates x, y."""
    a = quad
    b = np.roll(quad, -1, axis=0)                      # side k runs from corner k to k+1
    lengths = np.linalg.norm(b - a, axis=1)
    d = (b - a) / lengths[:, None]
    n = np.column_stack([-d[:, 1], d[:, 0]])
    outward = np.einsum("ij,ij->i", n, (a + b) / 2 - quad.mean(axis=0)) > 0
    n[~outward] *= -1                                  # towards the white border
    # Cell width ACROSS each side (perspective foreshortens it): the square's extent along
    # the side's normal, from the two opposite corners, over 8 cells.
    opposite = np.stack([np.roll(quad, -2, axis=0), np.roll(quad, -3, axis=0)], axis=1)
    across = np.abs(np.einsum("kjc,kc->kj", opposite - a[:, None, :], n)).mean(axis=1)
    cell = across / _CELLS
    if cell.min() < 2.5:  # too small for profiles that stay within one cell
        return None
    # The window stays on the tag's one-cell borders (black inside, white outside) with room
    # for the seed's error; 6 px holds a blur of sigma 1.5 px.
    half = np.minimum(window_cells * cell, _MAX_HALF_WINDOW)                 # (4,)
    n_s = 2 * int(np.ceil(half.max() / _PROFILE_STEP)) + 1
    s = half[:, None] * np.linspace(-1.0, 1.0, n_s)                          # (4, n_s)
    step = 2.0 * half / (n_s - 1)
    # Same number of profiles per side (vectorised), at most along_step apart, clear of the
    # corners by the blur width and the seed error.
    margin = np.maximum(3.0, 0.08 * lengths)
    usable = lengths - 2 * margin
    if usable.min() < 8.0:
        return None
    n_along = int(usable.max() / along_step) + 1
    t = margin[:, None] + np.linspace(0.0, 1.0, n_along)[None, :] * usable[:, None]
    base = a[:, None, :] + t[..., None] * d[:, None, :]                     # (4, n_along, 2)
    # profile sample points (4, n_along, n_s), x and y apart: no interleaved copies
    x = base[..., 0, None] + s[:, None, :] * n[:, 0, None, None]
    y = base[..., 1, None] + s[:, None, :] * n[:, 1, None, None]
    prof = sample(x, y)
    q = max(2, n_s // 4)  # plateaus: the outer quarter of the window on each side
    dark = prof[..., :q].mean(axis=-1)
    bright = prof[..., -q:].mean(axis=-1)
    contrast = bright - dark
    # trapezoid integral from -half to +half of the bright fraction (I - dark) / contrast
    trapezoid = prof.sum(axis=-1) - 0.5 * (prof[..., 0] + prof[..., -1])
    with np.errstate(divide="ignore", invalid="ignore"):
        area = step[:, None] * (trapezoid - (n_s - 1) * dark) / contrast
    e = half[:, None] - area
    good = (contrast > np.maximum(10.0, 0.5 * np.median(contrast, axis=1, keepdims=True))) \
        & (np.abs(e) < 0.75 * half[:, None])
    edges = base + e[..., None] * n[:, None, :]
    lines = []
    for k in range(4):
        if np.count_nonzero(good[k]) < 8:
            return None
        line = _fit_line(edges[k][good[k]])
        if line is None:
            return None
        lines.append(line)
    out = np.empty((4, 2))
    for k in range(4):
        # corner k joins side k-1 (from corner k-1 to k) and side k (from k to k+1)
        p = _intersect(lines[k - 1], lines[k])
        if p is None or np.linalg.norm(p - quad[k]) > max_shift:
            return None
        out[k] = p
    return out


def _bilinear(gray: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of `gray` at float coordinates x, y (same shape), edges clamped.

    Not cv2.remap: its fixed-point weights quantise positions to 1/32 px, a bias of up to
    0.016 px on an axis-aligned edge, where every profile shares the same phase.
    """
    h, w = gray.shape
    x = np.clip(x, 0.0, w - 1.0)
    y = np.clip(y, 0.0, h - 1.0)
    x0 = np.minimum(x.astype(np.intp), w - 2)  # x >= 0, so truncation is floor
    y0 = np.minimum(y.astype(np.intp), h - 2)
    fx = x - x0
    fy = y - y0
    flat = gray.ravel()
    i = y0 * w + x0
    p00, p01 = flat[i], flat[i + 1]
    p10, p11 = flat[i + w], flat[i + w + 1]
    top = p00 + fx * (p01.astype(np.float64) - p00)
    bottom = p10 + fx * (p11.astype(np.float64) - p10)
    return top + fy * (bottom - top)


def _tls(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = pts.mean(axis=0)
    c = pts - mean
    # principal axis of the 2x2 scatter matrix
    _, vecs = np.linalg.eigh(c.T @ c)
    return mean, vecs[:, 1]


def _fit_line(edge: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(point, unit direction) of a total-least-squares line through edge points (N, 2),
    refitted once without the points beyond 3 robust sigmas."""
    mean, direction = _tls(edge)
    resid = (edge - mean) @ np.array([-direction[1], direction[0]])
    sigma = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
    keep = np.abs(resid) < max(0.05, 3.0 * sigma)
    if np.count_nonzero(keep) < 8:
        return None
    return _tls(edge[keep])


def _intersect(l1: tuple[np.ndarray, np.ndarray],
               l2: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    (p1, d1), (p2, d2) = l1, l2
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 1e-6:
        return None
    t = np.linalg.solve(A, p2 - p1)
    return p1 + t[0] * d1

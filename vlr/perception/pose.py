"""Tag pose from its four corners: the object frame O, IPPE_SQUARE and its pitfalls.

Frames (vlr/spec.py): the object frame O has its origin at the tag centre (the POM), z_O
pointing INTO the object, away from the camera; the printed face looks along -z_O. OpenCV's
marker frame M (the one SOLVEPNP_IPPE_SQUARE's object points are written in) has x along the
printed tag's top edge to the right, y up the printed tag, z out of the printed face towards
the viewer. O is M turned by pi about x_M: x_O = x_M, y_O = -y_M, z_O = -z_M
(`R_MARKER_TO_OBJECT`). So a camera whose axes equal O's sees the tag upright, and a printed
tag's pixel (u right, v down) lies at +x_O, +y_O from the tag's top-left.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = [
    "R_MARKER_TO_OBJECT",
    "marker_to_object",
    "object_corners",
    "solve_tag_pose",
    "reprojection_rms",
]

# R_M_O: columns are O's axes in M (pi about x_M); its own inverse.
R_MARKER_TO_OBJECT = np.diag([1.0, -1.0, -1.0])
R_MARKER_TO_OBJECT.setflags(write=False)

# Cyclic shifts of the detector's corners (top-left, top-right, bottom-right, bottom-left)
# that present them to IPPE_SQUARE as its points 0..3 = (-h, h), (h, h), (h, -h), (-h, -h).
# Shift k makes IPPE's square frame S_k equal O turned by -k * 90 deg about z_O:
# R_O_Sk = Rz(-k 90 deg) (checked in tests/test_perception.py).
_IPPE_ORDER = [np.array([3, 2, 1, 0]), np.array([2, 1, 0, 3]),
               np.array([1, 0, 3, 2]), np.array([0, 3, 2, 1])]


def marker_to_object(T_cam_marker: np.ndarray) -> np.ndarray:
    """T_cam_O from OpenCV's marker pose T_cam_M (4x4): O = M turned by pi about x_M."""
    T = np.array(T_cam_marker, dtype=float, copy=True)
    T[:3, :3] = T[:3, :3] @ R_MARKER_TO_OBJECT
    return T


def object_corners(tag_size: float) -> np.ndarray:
    """The black square's corners in O (4, 3), in the detector's order (top-left, top-right,
    bottom-right, bottom-left of the printed tag)."""
    h = tag_size / 2.0
    return np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])


def _rz(k: int) -> np.ndarray:
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][k % 4]
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def reprojection_rms(T_cam_O: np.ndarray, tag_size: float, corners: np.ndarray,
                     K: np.ndarray, dist: np.ndarray | None = None) -> float:
    """RMS distance [px] between `corners` (4, 2) and the projected black-square corners."""
    rvec, _ = cv2.Rodrigues(T_cam_O[:3, :3])
    proj, _ = cv2.projectPoints(object_corners(tag_size), rvec, T_cam_O[:3, 3], K,
                                np.zeros(5) if dist is None else dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(4, 2) - corners) ** 2, axis=1))))


def _square_frame_shift(corners: np.ndarray) -> int:
    """The k whose IPPE frame S_k = O Rz(-k 90 deg) keeps the pose's rotation angle small.

    OpenCV turns IPPE's rotation into a Rodrigues vector, which is singular at an angle of pi:
    an exactly face-on tag in M's frame (R_cam_M = Rx(pi) Rz(spin)) came back with NaN or a
    pose 10-100 px off while reporting success, and so did O's frame when the tag's top edge
    pointed left in the image (spin near pi). With x_O's image direction phi (the top edge),
    R_cam_O is close to Rz(phi) times a tilt, so R_cam_Sk = R_cam_O Rz(-k 90 deg) with
    k = round(phi / 90 deg) keeps the spin within +-45 deg and the angle well below pi.
    """
    top = corners[1] - corners[0]
    phi = math.atan2(top[1], top[0])
    return int(round(phi / (math.pi / 2))) % 4


def solve_tag_pose(corners: np.ndarray, tag_size: float, K: np.ndarray,
                   dist: np.ndarray | None = None) -> tuple[np.ndarray, float] | None:
    """Pose T_cam_O (4x4) of the tag from its corners, and its RMS reprojection error [px].

    IPPE_SQUARE (Collins & Bartoli 2014) on the black square of side `tag_size`, in a frame
    S_k turned about z_O away from its singular Rodrigues angle (`_square_frame_shift`); of
    its two solutions (the planar ambiguity) the one with the smaller reprojection error wins.
    A non-finite or poorly fitting result (over 1 px) adds generic IPPE and iterative LM
    seeded with the best candidate. The winner is refined by Levenberg-Marquardt on the
    reprojection error (the ML pose for Gaussian corner noise). Returns None if no candidate
    is finite and in front of the camera.
    """
    corners = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64)
    h = tag_size / 2.0
    square = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    k = _square_frame_shift(corners)
    img = np.ascontiguousarray(corners[_IPPE_ORDER[k]])
    candidates: list[np.ndarray] = []
    try:
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(square, img, K, dist,
                                                 flags=cv2.SOLVEPNP_IPPE_SQUARE)
        candidates += [T for r, t in zip(rvecs, tvecs, strict=True)
                       if (T := _to_matrix(r, t)) is not None]
    except cv2.error:
        pass
    best = _best(candidates, square, img, K, dist)
    if best is None or best[1] > 1.0:
        candidates += _fallbacks(square, img, tag_size, K, dist,
                                 None if best is None else best[0])
        best = _best(candidates, square, img, K, dist)
    if best is None:
        return None
    T_cam_S, err = _refine_lm(best[0], best[1], square, img, K, dist)
    # R_cam_O = R_cam_Sk R_Sk_O, with R_O_Sk = Rz(-k 90 deg)
    T_cam_O = T_cam_S.copy()
    T_cam_O[:3, :3] = T_cam_S[:3, :3] @ _rz(k)
    return T_cam_O, err


def _to_matrix(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray | None:
    rvec = np.asarray(rvec, dtype=float).ravel()
    tvec = np.asarray(tvec, dtype=float).ravel()
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec
    return T


def _rms(T: np.ndarray, obj: np.ndarray, img: np.ndarray, K: np.ndarray,
         dist: np.ndarray) -> float:
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    proj, _ = cv2.projectPoints(obj, rvec, T[:3, 3], K, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def _best(candidates: list[np.ndarray], obj: np.ndarray, img: np.ndarray, K: np.ndarray,
          dist: np.ndarray) -> tuple[np.ndarray, float] | None:
    scored = []
    for T in candidates:
        if T[2, 3] <= 0:  # behind the camera
            continue
        err = _rms(T, obj, img, K, dist)
        if math.isfinite(err):
            scored.append((err, T))
    if not scored:
        return None
    err, T = min(scored, key=lambda s: s[0])
    return T, err


def _fallbacks(obj: np.ndarray, img: np.ndarray, tag_size: float, K: np.ndarray,
               dist: np.ndarray, seed: np.ndarray | None) -> list[np.ndarray]:
    out = []
    try:
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
        out += [T for r, t in zip(rvecs, tvecs, strict=True)
                if (T := _to_matrix(r, t)) is not None]
    except cv2.error:
        pass
    # Seed LM with the best so far, or with the square face-on (S_k parallel to the camera)
    # at the distance its size implies.
    if seed is None:
        side = float(np.mean(np.linalg.norm(img - np.roll(img, 1, axis=0), axis=1)))
        z = K[0, 0] * tag_size / max(side, 1e-9)
        c = img.mean(axis=0)
        seed = np.eye(4)  # S_k's axes near the camera's: it is O turned about z_O
        seed[:3, 3] = [(c[0] - K[0, 2]) * z / K[0, 0], (c[1] - K[1, 2]) * z / K[1, 1], z]
    try:
        rvec, _ = cv2.Rodrigues(seed[:3, :3])
        ok, r, t = cv2.solvePnP(obj, img, K, dist, rvec=rvec.copy(),
                                tvec=seed[:3, 3].reshape(3, 1).copy(), useExtrinsicGuess=True,
                                flags=cv2.SOLVEPNP_ITERATIVE)
        if ok and (T := _to_matrix(r, t)) is not None:
            out.append(T)
    except cv2.error:
        pass
    return out


def _refine_lm(T: np.ndarray, err0: float, obj: np.ndarray, img: np.ndarray, K: np.ndarray,
               dist: np.ndarray) -> tuple[np.ndarray, float]:
    """LM on the reprojection error, kept only if finite and not worse."""
    try:
        rvec, _ = cv2.Rodrigues(T[:3, :3])
        r, t = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, T[:3, 3].reshape(3, 1).copy())
        T2 = _to_matrix(r, t)
    except cv2.error:
        T2 = None
    if T2 is not None and T2[2, 3] > 0:
        err2 = _rms(T2, obj, img, K, dist)
        if err2 <= err0:
            return T2, err2
    return T, err0

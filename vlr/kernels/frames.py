"""The contacts between the palm frame and the object frame, batched over the particles:
x = p + R a and a = R^T (x - p) (`vlr.motion.ParticleState.anchor_to_pose`,
`contact_residuals`). NumPy's batched 3x3 products took 3-8 ms a call at 60,000 particles,
four calls a filter iteration."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True)
def _to_palm_batch(points, pos, rot, out):
    """out[q, i] = pos[q] + rot[q] points[q, i]: (P, N, 3) object-frame points to the palm."""
    n_p, n_f = points.shape[0], points.shape[1]
    for q in prange(n_p):
        for i in range(n_f):
            for a in range(3):
                out[q, i, a] = pos[q, a] + (rot[q, a, 0] * points[q, i, 0]
                                            + rot[q, a, 1] * points[q, i, 1]
                                            + rot[q, a, 2] * points[q, i, 2])


@njit(parallel=True, cache=True)
def _to_object_batch(points, pos, rot, out):
    """out[q, i] = rot[q]^T (points[q, i] - pos[q]): (P, N, 3) palm-frame points to the
    object frame."""
    n_p, n_f = points.shape[0], points.shape[1]
    for q in prange(n_p):
        for i in range(n_f):
            d0 = points[q, i, 0] - pos[q, 0]
            d1 = points[q, i, 1] - pos[q, 1]
            d2 = points[q, i, 2] - pos[q, 2]
            for a in range(3):
                out[q, i, a] = rot[q, 0, a] * d0 + rot[q, 1, a] * d1 + rot[q, 2, a] * d2


def _batched(kernel, points, pos, rot) -> np.ndarray:
    out = np.empty(np.shape(points))
    kernel(*(np.ascontiguousarray(a, dtype=float) for a in (points, pos, rot)), out)
    return out


def palm_points(points: np.ndarray, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(P, N, 3) object-frame points in the palm frame, p + R a."""
    return _batched(_to_palm_batch, points, pos, rot)


def object_points(points: np.ndarray, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(P, N, 3) palm-frame points in the object frame, R^T (x - p)."""
    return _batched(_to_object_batch, points, pos, rot)

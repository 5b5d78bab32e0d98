"""The pose likelihood's per-particle terms (Eq. 5 with the grasp's turn, `vlr.observation`),
one pass over the particles.

Per particle: the pose error e = (p - p_obs, rotvec(R R_obs^T)), the turn's direction
v = (a x (p - c_o), a) from its own contacts (`vlr.observation.grasp_turn`), and the
Sherman-Morrison form of e^T (D + s^2 v v^T)^-1 e and of its log normalisation. NumPy and
scipy's `Rotation` did the same in seven passes over (P, 3, 3) arrays, about a twentieth of a
filter iteration; `vlr.observation.rotation_error` and `grasp_turn` stay the reference
(tests/test_turn.py). The model check's predictive (`vlr.model_check`) reads the same
per-particle errors and turns (`pose_errors`) and its mixture's log-densities at 65
observations (`mixture_log_density`).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

# The observation (`vlr.observation.PoseObservation`): its position p (3,) and rotation r
# (3, 3), in the palm frame.
Observed = namedtuple("Observed", "p r")

# The likelihood's scales: d_inv (2,) the base scales' inverse variances (position's,
# rotation's), s2 the turn's variance [rad^2] (0: no turn term), opposed the finger at the
# turn axis's start.
Scales = namedtuple("Scales", "d_inv s2 opposed")

# Per particle, what `pose_terms` writes: quad (P,) and log_norm (P,).
Terms = namedtuple("Terms", "quad log_norm")


@njit(cache=True, inline="always", _nrt=False)
def _dot(R, S, a, b):
    """(R S^T)[a, b]."""
    return R[a, 0] * S[b, 0] + R[a, 1] * S[b, 1] + R[a, 2] * S[b, 2]


@njit(cache=True, inline="always", _nrt=False)
def rotvec_of(R, S):
    """The rotation vector [rad] of R S^T (two rotation matrices), through its unit
    quaternion (Shepperd's choice of the largest of w, x, y, z: accurate at every angle up
    to pi), the quaternion's sign taken with w >= 0, as scipy's `as_rotvec`."""
    r00, r01, r02 = _dot(R, S, 0, 0), _dot(R, S, 0, 1), _dot(R, S, 0, 2)
    r10, r11, r12 = _dot(R, S, 1, 0), _dot(R, S, 1, 1), _dot(R, S, 1, 2)
    r20, r21, r22 = _dot(R, S, 2, 0), _dot(R, S, 2, 1), _dot(R, S, 2, 2)
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        f = 0.25 / w
        x, y, z = (r21 - r12) * f, (r02 - r20) * f, (r10 - r01) * f
    elif r00 >= r11 and r00 >= r22:
        x = 0.5 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        f = 0.25 / x
        w, y, z = (r21 - r12) * f, (r01 + r10) * f, (r02 + r20) * f
    elif r11 >= r22:
        y = 0.5 * math.sqrt(max(1.0 - r00 + r11 - r22, 0.0))
        f = 0.25 / y
        w, x, z = (r02 - r20) * f, (r01 + r10) * f, (r12 + r21) * f
    else:
        z = 0.5 * math.sqrt(max(1.0 - r00 - r11 + r22, 0.0))
        f = 0.25 / z
        w, x, y = (r10 - r01) * f, (r02 + r20) * f, (r12 + r21) * f
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    # atan2(s, w) / s stays accurate as s -> 0 (where w -> 1).
    k = 2.0 * math.atan2(s, w) / s if s > 0.0 else 2.0
    return k * x, k * y, k * z


@njit(cache=True, inline="always", _nrt=False)
def _turn(pos, R, anchors, q, opposed):
    """Particle q's turn direction v = (a x (p - c_o), a) (`vlr.observation.grasp_turn`):
    the unit axis a from the opposed contact c_o to the others' mean (palm frame). (The
    anchors' mean, then the rotation: the contacts are p + R a_i.)"""
    n_f = anchors.shape[1]
    m0 = m1 = m2 = 0.0
    for i in range(n_f):
        if i != opposed:
            m0 += anchors[q, i, 0] / (n_f - 1)
            m1 += anchors[q, i, 1] / (n_f - 1)
            m2 += anchors[q, i, 2] / (n_f - 1)
    o0, o1, o2 = anchors[q, opposed, 0], anchors[q, opposed, 1], anchors[q, opposed, 2]
    co0 = pos[q, 0] + R[0, 0] * o0 + R[0, 1] * o1 + R[0, 2] * o2
    co1 = pos[q, 1] + R[1, 0] * o0 + R[1, 1] * o1 + R[1, 2] * o2
    co2 = pos[q, 2] + R[2, 0] * o0 + R[2, 1] * o1 + R[2, 2] * o2
    b0, b1, b2 = m0 - o0, m1 - o1, m2 - o2
    ax = R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2
    ay = R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2
    az = R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2
    norm = math.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    dx, dy, dz = pos[q, 0] - co0, pos[q, 1] - co1, pos[q, 2] - co2
    return ay * dz - az * dy, az * dx - ax * dz, ax * dy - ay * dx, ax, ay, az


@njit(parallel=True, cache=True)
def pose_terms(pos, rot, anchors, valid, obs, scales, out):
    """Into out (`Terms`): e^T D^-1 e - s^2 (v^T D^-1 e)^2 / g and -log(g) / 2, g = 1 +
    s^2 v^T D^-1 v (`vlr.observation` module docstring); s2 = 0: no turn term (g = 1).
    Invalid rows (a failed solve's, or a pose not finite) get quad = inf.

    pos (P, 3), rot (P, 3, 3), anchors (P, N, 3) [object frame], valid (P,) bool; obs
    (`Observed`) and scales (`Scales`)."""
    n_p = anchors.shape[0]
    # Names of their own: a write into a record's array in a prange body is lost (numba
    # 0.68, `vlr.kernels.solve.solve_batch`).
    quad, log_norm = out.quad, out.log_norm
    p_obs, r_obs = obs.p, obs.r
    d_inv, s2, opposed = scales.d_inv, scales.s2, scales.opposed
    for q in prange(n_p):
        R = rot[q]
        ok = valid[q]
        for a in range(3):
            ok = ok and math.isfinite(pos[q, a])
            for b in range(3):
                ok = ok and math.isfinite(R[a, b])
        if not ok:
            quad[q] = math.inf
            log_norm[q] = 0.0
            continue
        e0, e1, e2 = pos[q, 0] - p_obs[0], pos[q, 1] - p_obs[1], pos[q, 2] - p_obs[2]
        e3, e4, e5 = rotvec_of(R, r_obs)
        quad_q = ((e0 * e0 + e1 * e1 + e2 * e2) * d_inv[0]
                  + (e3 * e3 + e4 * e4 + e5 * e5) * d_inv[1])
        if s2 == 0.0:
            quad[q] = quad_q
            log_norm[q] = 0.0
            continue
        v0, v1, v2, v3, v4, v5 = _turn(pos, R, anchors, q, opposed)
        vde = (v0 * e0 + v1 * e1 + v2 * e2) * d_inv[0] + (v3 * e3 + v4 * e4 + v5 * e5) * d_inv[1]
        vdv = (v0 * v0 + v1 * v1 + v2 * v2) * d_inv[0] + (v3 * v3 + v4 * v4 + v5 * v5) * d_inv[1]
        g = 1.0 + s2 * vdv
        quad[q] = quad_q - s2 * vde * vde / g
        log_norm[q] = -0.5 * math.log(g)


@njit(parallel=True, cache=True)
def pose_errors(pos, rot, anchors, obs, opposed, e, v):
    """Into e (P, 6) each particle's pose error against the observation obs (`Observed`),
    (p - p_obs, rotvec(R R_obs^T)), and into v (P, 6) its turn direction (`_turn`; zeros
    when opposed < 0): the model check's (`vlr.model_check`)."""
    p_obs, r_obs = obs.p, obs.r
    for q in prange(pos.shape[0]):
        R = rot[q]
        for a in range(3):
            e[q, a] = pos[q, a] - p_obs[a]
        e[q, 3], e[q, 4], e[q, 5] = rotvec_of(R, r_obs)
        if opposed < 0:
            for a in range(6):
                v[q, a] = 0.0
        else:
            v[q, 0], v[q, 1], v[q, 2], v[q, 3], v[q, 4], v[q, 5] = _turn(pos, R, anchors, q,
                                                                        opposed)


@njit(parallel=True, cache=True)
def mixture_log_density(e, v, w, d_inv, s2, out):
    """Into out (M,): log sum_i exp(-1/2 (w_m - e_i)^T (D + s^2 v_i v_i^T)^-1 (w_m - e_i)
    - 1/2 log g_i), g_i = 1 + s^2 v_i^T D^-1 v_i: the log-density of each of M points w
    (M, d) under the equal mixture of K Gaussians (Eq. 5 with the turn) about the particles'
    predictions e (K, d) with turn directions v (K, d), up to one constant for all; d_inv
    (d,) the diagonal of D^-1 (Sherman-Morrison, as `pose_terms`)."""
    n_k, d = e.shape
    g, half_log_g = np.empty(n_k), np.empty(n_k)
    for i in range(n_k):
        vdv = 0.0
        for a in range(d):
            vdv += v[i, a] * v[i, a] * d_inv[a]
        g[i] = 1.0 + s2 * vdv
        half_log_g[i] = 0.5 * math.log(g[i])
    for m in prange(w.shape[0]):
        vals = np.empty(n_k)
        top = -math.inf
        for i in range(n_k):
            quad = 0.0
            vde = 0.0
            for a in range(d):
                r = (e[i, a] - w[m, a]) * d_inv[a]
                quad += r * (e[i, a] - w[m, a])
                vde += v[i, a] * r
            vals[i] = -0.5 * (quad - s2 * vde * vde / g[i]) - half_log_g[i]
            top = max(top, vals[i])
        total = 0.0
        for i in range(n_k):
            total += math.exp(vals[i] - top)
        out[m] = top + math.log(total)

"""A finger's planar chain (Eq. 2) and the energy terms of the hand alone: the springs
(Eq. 6), the series tendon (Eq. 7, compliant), the joint stops and gravity.

Every joint of a finger turns about -x_F (`vlr.kinematics`), so in its frame F the chain is
planar: `finger_chain` fills the cumulative angles' sines and cosines and the joints' (y, z)
in F. A term adds its energy, gradient and Hessian into the arrow blocks of one particle
(`arrow`: gA (N, K), A (N, K, K) the fingers', gC (6,), C (6, 6) the object's, B (N, K, 6)
their coupling) in place.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from vlr.kernels.records import JOINTS


@njit(cache=True, inline="always", _nrt=False)
def finger_chain(th, seg, i, k_n, sphi, cphi, qy, qz):
    """Finger i's chain of k_n joints in F (Eq. 2): sphi, cphi (K,) the sines and cosines
    of the cumulative angles, qy, qz (K,) the joints' positions; returns the summed angle
    phi. th, seg (N, K) are one particle's."""
    phi = 0.0
    qy[0] = 0.0
    qz[0] = 0.0
    for k in range(k_n):
        phi += th[i, k]
        sphi[k] = math.sin(phi)
        cphi[k] = math.cos(phi)
        if k < k_n - 1:
            qy[k + 1] = qy[k] + seg[i, k] * sphi[k]
            qz[k + 1] = qz[k] + seg[i, k] * cphi[k]
    return phi


@njit(cache=True, inline="always", _nrt=False)
def distal_point(seg, i, k_n, chain, d):
    """The point d = (dx, dy, dz) of finger i's distal frame D, less the pad centre's z (a
    segment), in F: the chain's last joint plus the rotation by the summed angle. `chain`
    = (sphi, cphi, qy, qz), filled by `finger_chain`."""
    sphi, cphi, qy, qz = chain
    dx, dy, dz = d
    s, c = sphi[k_n - 1], cphi[k_n - 1]
    z = seg[i, k_n - 1] + dz
    return dx, qy[k_n - 1] + dy * c + z * s, qz[k_n - 1] - dy * s + z * c


@njit(cache=True, inline="always", _nrt=False)
def to_palm(hand, i, fx, fy, fz):
    """A point of finger i's frame F in the palm frame."""
    b, r = hand.base_pos, hand.base_rot
    return (b[i, 0] + r[i, 0, 0] * fx + r[i, 0, 1] * fy + r[i, 0, 2] * fz,
            b[i, 1] + r[i, 1, 0] * fx + r[i, 1, 1] * fy + r[i, 1, 2] * fz,
            b[i, 2] + r[i, 2, 0] * fx + r[i, 2, 1] * fy + r[i, 2, 2] * fz)


@njit(cache=True, inline="always", _nrt=False)
def distal_rotation(hand, i, phi, out):
    """out (3, 3) = R_PD of finger i at summed angle phi: base_rot @ plane_rotation(phi)
    (`vlr.kinematics.plane_rotation`, a turn about -x)."""
    rb = hand.base_rot
    c, s = math.cos(phi), math.sin(phi)
    for a in range(3):
        out[a, 0] = rb[i, a, 0]
        out[a, 1] = rb[i, a, 1] * c - rb[i, a, 2] * s
        out[a, 2] = rb[i, a, 1] * s + rb[i, a, 2] * c


@njit(cache=True, inline="always", _nrt=False)
def hand_terms(th, body, hand, cfg, i, sc):
    """Finger i's springs (Eq. 6), stops, series tendon (Eq. 7 compliant, at the commands
    sc.u_b) and link weights, into sc.gA, sc.A; returns their energy [J]. The chain
    (`finger_chain`, into sc) must be filled."""
    stiff, kt, u = body.stiff, body.kt, sc.u_b
    sphi, cphi, qy, qz, gA, A = sc.sphi, sc.cphi, sc.qy, sc.qz, sc.gA, sc.A
    k_n = JOINTS
    e = 0.0
    if cfg.springs:
        for k in range(k_n):
            d = th[i, k] - hand.rest[i, k]
            e += 0.5 * stiff[i, k] * d * d
            gA[i, k] += stiff[i, k] * d
            A[i, k, k] += stiff[i, k]
    if cfg.limits:  # one-sided stiff penalties (docs/METHOD.md 8.2)
        for k in range(k_n):
            d = 0.0
            if th[i, k] < hand.lo[i, k]:
                d = th[i, k] - hand.lo[i, k]
            elif th[i, k] > hand.hi[i, k]:
                d = th[i, k] - hand.hi[i, k]
            if d != 0.0:
                e += 0.5 * cfg.klim * d * d
                gA[i, k] += cfg.klim * d
                A[i, k, k] += cfg.klim
    if cfg.tendon:  # 1/2 k_t max(0, u - s)^2, s = sum r_k (theta_k - lo_k)
        s = 0.0
        for k in range(k_n):
            s += hand.radii[i, k] * (th[i, k] - hand.lo[i, k])
        slack = u[i] - s
        if slack > 0.0:
            e += 0.5 * kt[i] * slack * slack
            for k in range(k_n):
                gA[i, k] -= kt[i] * slack * hand.radii[i, k]
                for m in range(k_n):
                    A[i, k, m] += kt[i] * hand.radii[i, k] * hand.radii[i, m]
    if cfg.link_gravity:  # -m g . x_com of each link
        rb, g, lc = hand.base_rot, hand.gravity, hand.link_com
        gfx = rb[i, 0, 0] * g[0] + rb[i, 1, 0] * g[1] + rb[i, 2, 0] * g[2]
        gfy = rb[i, 0, 1] * g[0] + rb[i, 1, 1] * g[1] + rb[i, 2, 1] * g[2]
        gfz = rb[i, 0, 2] * g[0] + rb[i, 1, 2] * g[1] + rb[i, 2, 2] * g[2]
        gb = (g[0] * hand.base_pos[i, 0] + g[1] * hand.base_pos[i, 1]
              + g[2] * hand.base_pos[i, 2])
        for k in range(k_n):
            m_k = hand.link_mass[i, k]
            cy, cz = lc[i, k, 1], lc[i, k, 2]
            py = qy[k] + cy * cphi[k] + cz * sphi[k]
            pz = qz[k] - cy * sphi[k] + cz * cphi[k]
            e -= m_k * (gb + gfx * lc[i, k, 0] + gfy * py + gfz * pz)
            for j in range(k + 1):
                dy = py - qy[j]
                dz = pz - qz[j]
                # d x / d theta_j = (0, dz, -dy) in F (a turn about -x)
                gA[i, j] -= m_k * (gfy * dz - gfz * dy)
                for m in range(j, k + 1):
                    h = m_k * (gfy * (py - qy[m]) + gfz * (pz - qz[m]))
                    A[i, j, m] += h
                    if m != j:
                        A[i, m, j] += h
    return e


@njit(cache=True, inline="always", _nrt=False)
def object_gravity(p, R, mass, com, hand, gC, C):
    """The object's weight, -m g . (p + R com), into gC, C; returns its energy [J]."""
    g = hand.gravity
    cx, cy, cz = com[0], com[1], com[2]
    wx = p[0] + R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
    wy = p[1] + R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
    wz = p[2] + R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz
    e = -mass * (g[0] * wx + g[1] * wy + g[2] * wz)
    # gamma = R^T g, the weight in O
    g0 = R[0, 0] * g[0] + R[1, 0] * g[1] + R[2, 0] * g[2]
    g1 = R[0, 1] * g[0] + R[1, 1] * g[1] + R[2, 1] * g[2]
    g2 = R[0, 2] * g[0] + R[1, 2] * g[1] + R[2, 2] * g[2]
    for b in range(3):
        gC[b] -= mass * g[b]
    # d/dw: -m (com x gamma)
    gC[3] -= mass * (cy * g2 - cz * g1)
    gC[4] -= mass * (cz * g0 - cx * g2)
    gC[5] -= mass * (cx * g1 - cy * g0)
    gc = g0 * cx + g1 * cy + g2 * cz
    gv = (g0, g1, g2)
    cv = (cx, cy, cz)
    for b in range(3):
        for c in range(3):
            h = 0.5 * (gv[b] * cv[c] + cv[b] * gv[c])
            if b == c:
                h -= gc
            C[3 + b, 3 + c] -= mass * h
    return e


@njit(parallel=True, cache=True)
def contact_points_batch(theta, seg, nrm, hand, out):
    """out (P, N, 3): every particle's pad contact points in the palm frame (Eq. 2;
    `vlr.kinematics.contact_points`, whose batched calls land here)."""
    n_p, n_f, k_n = theta.shape
    n_chunks = min(n_p, 64)
    for ch in prange(n_chunks):
        sphi = np.empty(k_n)
        cphi = np.empty(k_n)
        qy = np.empty(k_n)
        qz = np.empty(k_n)
        for q in range((ch * n_p) // n_chunks, ((ch + 1) * n_p) // n_chunks):
            th, sg, nr = theta[q], seg[q], nrm[q]
            for i in range(n_f):
                finger_chain(th, sg, i, k_n, sphi, cphi, qy, qz)
                r = hand.pad_r[i]
                fx, fy, fz = distal_point(sg, i, k_n, (sphi, cphi, qy, qz),
                                          (hand.pad_xy[i, 0] + r * nr[i, 0],
                                           hand.pad_xy[i, 1] + r * nr[i, 1], r * nr[i, 2]))
                out[q, i, 0], out[q, i, 1], out[q, i, 2] = to_palm(hand, i, fx, fy, fz)

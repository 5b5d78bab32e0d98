"""The motion model's energy in plain NumPy, one particle at a time: the independent
reference the tests check the kernels' energy, gradient and Hessian against (by finite
differences). Slow and literal, term by term as `vlr.motion` describes them."""

from __future__ import annotations

import math

import numpy as np

from vlr.kernels.contacts import SPIN_EPS, STICK_ZONE
from vlr.kinematics import contact_points, plane_rotation
from vlr.surface import FLAT_CURVATURE

__all__ = ["reference_energy"]


def _friction(z: np.ndarray, kc: float, mu: float, lam_n: float) -> float:
    """psi(z) (`vlr.kernels.contacts.friction`)."""
    if not math.isfinite(mu):
        return 0.5 * kc * float(z @ z)
    cap = mu * lam_n
    if not cap > 1e-9:
        return 0.0
    eps = max(cap / kc, STICK_ZONE)
    return cap * (math.sqrt(float(z @ z) + eps * eps) - eps)


def _primitive(kind: str, o, axis, rho, r, k_o):
    """(g, m): the pad centre k_o in O against the primitive (`contacts._primitive`)."""
    if kind == "plane":
        return float(axis @ (k_o - o)) - r, axis
    d = k_o - o
    if kind == "cylinder":
        d = d - (d @ axis) * axis
    L = float(np.linalg.norm(d))
    return L - rho - r, d / L


def reference_energy(motion, state, q: int, u: np.ndarray, theta: np.ndarray,
                     pos: np.ndarray, rot: np.ndarray) -> float:
    """Particle q's energy at (theta, pos, rot) [J], its solve started where it is (Eq. 6, 7
    compliant, 8 pinned or rolling with the pads' friction held at the start's normal
    force, the stops, gravity)."""
    m, cfg = motion.model, motion.config
    g = np.asarray(cfg.gravity, dtype=float)
    theta = np.asarray(theta, dtype=float)
    lim = m.limits
    e = 0.0
    if "springs" in cfg.terms:
        e += 0.5 * np.sum(state.stiffness[q] * (theta - m.rest) ** 2)
    if "limits" in cfg.terms:
        over = np.maximum(0.0, lim[..., 0] - theta) + np.maximum(0.0, theta - lim[..., 1])
        e += 0.5 * cfg.limit_stiffness * np.sum(over**2)
    if "tendon" in cfg.terms:
        slack = np.maximum(0.0, np.asarray(u) - m.tendon_takeup(theta))
        e += 0.5 * np.sum(state.tendon[q] * slack**2)
    if "link_gravity" in cfg.terms:
        seg = state.segments[q]
        phi = np.cumsum(theta, axis=-1)
        q_f = np.zeros(theta.shape + (3,))
        for k in range(1, m.n_joints):
            q_f[:, k, 1] = q_f[:, k - 1, 1] + seg[:, k - 1] * np.sin(phi[:, k - 1])
            q_f[:, k, 2] = q_f[:, k - 1, 2] + seg[:, k - 1] * np.cos(phi[:, k - 1])
        com_f = q_f + np.einsum("nkab,nkb->nka", plane_rotation(phi), m.link_coms)
        com_p = m.base_pos[:, None, :] + np.einsum("nab,nkb->nka", m.base_rot, com_f)
        e -= np.sum(m.link_masses * (com_p @ g))
    if "object_gravity" in cfg.terms:
        mass, com = motion.object_arrays(state)
        e -= mass[q] * g @ (pos + rot @ com[q])
    if "contacts" in cfg.terms:
        e += _rolling(motion, state, q, theta, pos, rot) if cfg.rolling else _pinned(
            motion, state, q, theta, pos, rot)
    return float(e)


def _pinned(motion, state, q, theta, pos, rot) -> float:
    m, kc = motion.model, motion.config.contact_stiffness
    c = contact_points(m, theta[None], state.normals[q][None], state.segments[q][None])[0]
    return 0.5 * kc * float(np.sum((c - (pos + state.anchors[q] @ rot.T)) ** 2))


def _pad(m, theta, seg):
    """Pad centres (N, 3) and distal rotations (N, 3, 3) in the palm."""
    k = contact_points(m, theta[None], np.zeros((1, m.n_fingers, 3)), seg[None])[0]
    rd = np.einsum("nab,nbc->nac", m.base_rot, plane_rotation(theta.sum(-1)))
    return k, rd


def _rolling(motion, state, q, theta, pos, rot) -> float:
    m, cfg = motion.model, motion.config
    kc = cfg.contact_stiffness
    mu = math.inf if cfg.friction is None else cfg.friction
    surf = motion.obj.surface
    rho_all = motion.contact_rho(state)
    seg = state.segments[q]
    th0, p0, r0 = state.theta[q], state.pos[q], state.rot[q]
    k0, rd0 = _pad(m, th0, seg)
    k1, rd1 = _pad(m, theta, seg)
    e = 0.0
    for i in range(m.n_fingers):
        r = float(m.pad_radius[i])
        rho = float(surf.kernel_radius if rho_all is None else rho_all[q, i])
        a = state.anchors[q, i]
        n_p0 = rd0[i] @ state.normals[q, i]
        m0 = -r0.T @ n_p0
        kind, u_dir, axis = "sphere", m0, m0
        if rho >= 1.0 / FLAT_CURVATURE:
            kind = "plane"
        elif surf.kind == "cylinder":
            ax = np.asarray(surf.axis, dtype=float)
            side = m0 - (m0 @ ax) * ax
            if np.linalg.norm(side) > 0.5:
                kind, u_dir, axis = "cylinder", side / np.linalg.norm(side), ax
            else:
                kind = "plane"
        ko0 = r0.T @ (k0[i] - p0)
        w = ko0 - r * m0 - a
        t = r0 @ w
        t = t - (t @ n_p0) * n_p0
        b = a + r0.T @ t
        if kind == "plane":
            o, axis = b, m0
        else:
            o = ko0 - (rho + r + w @ m0) * u_dir
        g0, mm0 = _primitive(kind, o, axis, rho, r, ko0)
        c_o0 = ko0 - (g0 + r) * mm0
        n0 = r0 @ mm0
        c_d0 = -r * rd0[i].T @ n0
        t0 = r0.T @ (t - (t @ n0) * n0)
        lam_n = max(0.0, -kc * g0)
        # at the iterate
        ko = rot.T @ (k1[i] - pos)
        gap, mm = _primitive(kind, o, axis, rho, r, ko)
        c_o = ko - (gap + r) * mm
        dc_d = -r * rd1[i].T @ (rot @ mm) - c_d0
        s = 0.5 * (rot + r0) @ (c_o - c_o0) - 0.5 * (rd1[i] + rd0[i]) @ dc_d
        z = rot @ t0 + s
        z = z - (z @ n0) * n0
        e += 0.5 * kc * gap * gap + _friction(z, kc, mu, lam_n)
        if cfg.spin_friction > 0:
            # the pad's spin about n0: the object's turn less the distal link's
            turn = rot @ r0.T
            vee = 0.5 * np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0],
                                  turn[1, 0] - turn[0, 1]])
            om = -m.base_rot[i][:, 0]
            psi0 = 0.0 if state.spin is None else float(state.spin[q, i])
            psi = psi0 + n0 @ vee - (n0 @ om) * (theta[i].sum() - th0[i].sum())
            cap = cfg.spin_friction * lam_n
            e += cap * (math.sqrt(psi * psi + SPIN_EPS * SPIN_EPS) - SPIN_EPS)
    return e


"""Numba kernels of the motion model (Eq. 6-9): energy terms, their gradients and Hessians,
and the batched damped-Newton (Levenberg-Marquardt) solve. Internal to `vlr.motion`.

Unknowns of one particle: the joint angles theta (N, K) and a small pose change of the object,
(dp, dw) with p <- p + dp, R <- R exp([dw]x). The Hessian has an arrow structure: finger
blocks A_i (K x K) that couple only through the object block C (6 x 6) via B_i (K x 6), so the
Newton system is solved by eliminating the finger blocks (Schur complement): O(N K^3 + 6^3)
per particle instead of O((NK + 6)^3).

Terms are identified by the codes below; `flags[code] != 0` enables a term. Each term adds
its energy, gradient and Hessian blocks in place, inside `_evaluate`; a term that ties a
point fixed in a finger's distal frame to a point fixed in the object goes through `_pair`.
To add a term, add its code here, its branch in `_evaluate` and its energy to the NumPy
reference (`vlr.motion.reference_energy`), which the tests check the kernel against.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

SPRINGS, TENDON, LIMITS, LINK_GRAVITY, OBJECT_GRAVITY, CONTACTS, ROLLING = range(7)
N_TERMS = 7

# Solver status codes (per particle).
OK, NONFINITE, NO_CONVERGENCE, JUMP, INACTIVE = 0, 1, 2, 3, 4

# Indices into the float parameter vector `prm`.
(P_KC, P_KLIM, P_TOL_TH, P_TOL_P, P_MAX_DTH, P_MAX_DP, P_JUMP_TH, P_JUMP_P, P_MU0,
 P_KSPIN, P_SLIDE_FRICTION, P_SPIN_FRICTION, P_SPIN_EPS) = range(13)
N_PRM = 13
# Layout of a rolling frame (one per contact): local centre of curvature in O (3), contact
# normal in the palm frame (3), the finger's summed joint angles (1), the object rotation
# R_PO (9, row-major) at the start of the solve, the contact's normal force then (1) [N]
# (it sets the friction's limits), and the local surface's radius of curvature rho (1) [m]:
# the contact's own, so that a particle can carry an unknown curvature (`vlr.unknowns`).
RL_CENTRE, RL_NORMAL, RL_PHI, RL_ROT, RL_FORCE, RL_RHO, N_RL = 0, 3, 6, 7, 16, 17, 18


@njit(cache=True, inline='always', _nrt=False)
def _finger_chain(th, seg, nrm, i, with_nrm, pcx, pcy, prad, sphi, cphi, qy, qz):
    """Planar chain of finger i in F (Eq. 2): fills sin/cos of cumulative angles and joint
    positions (y, z); returns the contact point (x, y, z) in F (`with_nrm` 0: the pad's
    centre). Indexes th, seg, nrm (N, ...) rather than taking a finger's rows: a row is a
    view, and each view costs two atomic reference counts in the Newton loop."""
    k_n = th.shape[1]
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
    cdx = pcx + prad * with_nrm * nrm[i, 0]
    cdy = pcy + prad * with_nrm * nrm[i, 1]
    cdz = seg[i, k_n - 1] + prad * with_nrm * nrm[i, 2]
    s, c = sphi[k_n - 1], cphi[k_n - 1]
    return (cdx, qy[k_n - 1] + cdy * c + cdz * s, qz[k_n - 1] - cdy * s + cdz * c)


@njit(cache=True, inline='always', _nrt=False)
def _separation(bp, rb, i, fx, fy, fz, p, R, ox, oy, oz):
    """Palm-frame vector from a point fixed in O, (ox, oy, oz), to a point fixed in finger
    i's base frame, (fx, fy, fz): bp[i] + rb[i] f - (p + R o)."""
    return (bp[i, 0] + rb[i, 0, 0] * fx + rb[i, 0, 1] * fy + rb[i, 0, 2] * fz
            - p[0] - (R[0, 0] * ox + R[0, 1] * oy + R[0, 2] * oz),
            bp[i, 1] + rb[i, 1, 0] * fx + rb[i, 1, 1] * fy + rb[i, 1, 2] * fz
            - p[1] - (R[1, 0] * ox + R[1, 1] * oy + R[1, 2] * oz),
            bp[i, 2] + rb[i, 2, 0] * fx + rb[i, 2, 1] * fy + rb[i, 2, 2] * fz
            - p[2] - (R[2, 0] * ox + R[2, 1] * oy + R[2, 2] * oz))


@njit(cache=True, inline='always', _nrt=False)
def _pair(i, k_n, px, py, pz, ax, ay, az, gam, Gam, iso, rb, R, qy, qz, jac, M, lam, gt,
          gA, A, B, gC, C):
    """Gradient and Hessian of phi(v), v = x(theta) - (p + R a): x a point fixed in finger i's
    distal frame ((px, py, pz) in its finger frame F), a a point fixed in O (ax, ay, az);
    rb the base rotations (N, 3, 3).
    gam = dphi/dv (3,), Gam = d2phi/dv2 (3, 3), both in the palm frame; the caller adds phi.
    grad = J^T gam; Hess = J^T Gam J + sum_a gam_a d2v_a (the geometric part).
    iso > 0 says Gam = iso I (the pinned contact, the default hot path): Gam is not read and
    its matrix products are skipped."""
    for j in range(k_n):
        dy = py - qy[j]
        dz = pz - qz[j]
        for a in range(3):
            jac[j, a] = rb[i, a, 1] * dz - rb[i, a, 2] * dy
    # M = R [a]x : d v / d w
    for a in range(3):
        M[a, 0] = R[a, 1] * az - R[a, 2] * ay
        M[a, 1] = -R[a, 0] * az + R[a, 2] * ax
        M[a, 2] = R[a, 0] * ay - R[a, 1] * ax
    for j in range(k_n):
        gA[i, j] += jac[j, 0] * gam[0] + jac[j, 1] * gam[1] + jac[j, 2] * gam[2]
        # gt = Gam jac_j
        for a in range(3):
            if iso > 0.0:
                gt[a] = iso * jac[j, a]
            else:
                gt[a] = (Gam[a, 0] * jac[j, 0] + Gam[a, 1] * jac[j, 1]
                         + Gam[a, 2] * jac[j, 2])
        for m in range(j, k_n):
            dy2 = py - qy[m]
            dz2 = pz - qz[m]
            # gam . R_b (0, -dy', -dz'): the geometric (force x curvature) part
            geo = -(gam[0] * (rb[i, 0, 1] * dy2 + rb[i, 0, 2] * dz2)
                    + gam[1] * (rb[i, 1, 1] * dy2 + rb[i, 1, 2] * dz2)
                    + gam[2] * (rb[i, 2, 1] * dy2 + rb[i, 2, 2] * dz2))
            h = jac[m, 0] * gt[0] + jac[m, 1] * gt[1] + jac[m, 2] * gt[2] + geo
            A[i, j, m] += h
            if m != j:
                A[i, m, j] += h
        for b in range(3):
            B[i, j, b] -= gt[b]
            B[i, j, 3 + b] += gt[0] * M[0, b] + gt[1] * M[1, b] + gt[2] * M[2, b]
    for b in range(3):
        gC[b] -= gam[b]
        gC[3 + b] += M[0, b] * gam[0] + M[1, b] * gam[1] + M[2, b] * gam[2]
        lam[b] = R[0, b] * gam[0] + R[1, b] * gam[1] + R[2, b] * gam[2]
    la = lam[0] * ax + lam[1] * ay + lam[2] * az
    for b in range(3):
        for c in range(3):
            if iso > 0.0:
                if b == c:
                    C[b, c] += iso
                gm = iso * M[b, c]
            else:
                C[b, c] += Gam[b, c]
                # (Gam M)[b, c]
                gm = Gam[b, 0] * M[0, c] + Gam[b, 1] * M[1, c] + Gam[b, 2] * M[2, c]
            C[b, 3 + c] -= gm
            C[3 + c, b] -= gm
    for b in range(3):
        ab = ax if b == 0 else (ay if b == 1 else az)
        for c in range(3):
            ac = ax if c == 0 else (ay if c == 1 else az)
            mgm = 0.0
            if iso > 0.0:
                mgm = iso * (M[0, b] * M[0, c] + M[1, b] * M[1, c] + M[2, b] * M[2, c])
            else:
                for d in range(3):
                    mgm += M[d, b] * (Gam[d, 0] * M[0, c] + Gam[d, 1] * M[1, c]
                                      + Gam[d, 2] * M[2, c])
            geo = 0.5 * (lam[b] * ac + ab * lam[c])
            if b == c:
                geo -= la
            C[3 + b, 3 + c] += mgm - geo


@njit(cache=True, _nrt=False)
def _spin_rate(i, k_n, th, rl, R, rb, vk):
    """Spin s of the object relative to finger i's distal link about the contact normal N,
    since the start of the solve: s = N . (omega_O - omega_D), omega_O = vee(sym(R R0^T)),
    omega_D = -(sum theta - sum theta_0) x_F. Returns (s, ds/dtheta_k (the same for every
    joint of the finger), ds/dw_0, ds/dw_1, ds/dw_2); vk[3:6] is scratch."""
    nx, ny, nz = rl[i, RL_NORMAL], rl[i, RL_NORMAL + 1], rl[i, RL_NORMAL + 2]
    # W = R R0^T
    W = vk[3:6]
    for a in range(3):
        for b in range(3):
            W[a, b] = (R[a, 0] * rl[i, RL_ROT + 3 * b] + R[a, 1] * rl[i, RL_ROT + 3 * b + 1]
                       + R[a, 2] * rl[i, RL_ROT + 3 * b + 2])
    om0 = 0.5 * (W[2, 1] - W[1, 2])
    om1 = 0.5 * (W[0, 2] - W[2, 0])
    om2 = 0.5 * (W[1, 0] - W[0, 1])
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    cx = nx * rb[i, 0, 0] + ny * rb[i, 1, 0] + nz * rb[i, 2, 0]
    s = nx * om0 + ny * om1 + nz * om2 + (phi - rl[i, RL_PHI]) * cx
    # d omega / d w_b = vee(sym(R [e_b]x R0^T)); its projection on N
    jw0 = jw1 = jw2 = 0.0
    for b in range(3):
        # R [e_b]x: column c of [e_b]x is e_b x e_c
        Q = vk[3:6]  # scratch: R [e_b]x R0^T (W is no longer needed)
        for a in range(3):
            for c in range(3):
                t = 0.0
                for d in range(3):
                    # ([e_b]x)[d, f] = -eps(d, f, b): nonzero for d, f != b
                    for f in range(3):
                        if d == f or d == b or f == b:
                            continue
                        sgn = 1.0 if (d - f) % 3 == 1 else -1.0  # -eps(d, f, b)
                        t += R[a, d] * sgn * rl[i, RL_ROT + 3 * c + f]
                Q[a, c] = t
        jb = 0.5 * (nx * (Q[2, 1] - Q[1, 2]) + ny * (Q[0, 2] - Q[2, 0])
                    + nz * (Q[1, 0] - Q[0, 1]))
        if b == 0:
            jw0 = jb
        elif b == 1:
            jw1 = jb
        else:
            jw2 = jb
    return s, cx, jw0, jw1, jw2


@njit(cache=True, _nrt=False)
def _spin_apply(i, k_n, f1, f2, cx, jw0, jw1, jw2, gA, A, B, gC, C):
    """Accumulate an energy f(s) of the spin: gradient f'(s) J, Gauss-Newton Hessian
    f''(s) J J^T (J from `_spin_rate`)."""
    jw = (jw0, jw1, jw2)
    for k in range(k_n):
        gA[i, k] += f1 * cx
        for m in range(k_n):
            A[i, k, m] += f2 * cx * cx
        for b in range(3):
            B[i, k, 3 + b] += f2 * cx * jw[b]
    for b in range(3):
        gC[3 + b] += f1 * jw[b]
        for c in range(3):
            C[3 + b, 3 + c] += f2 * jw[b] * jw[c]


@njit(cache=True, _nrt=False)
def _evaluate(th, seg, nrm, anc, rl, p, R, stiff, kt, u,
              base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
              omass, ocom, grav, flags, prm,
              gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk):
    """Energy of one particle (Eq. 6, 7 compliant, 8 as penalty or rolling, limits, gravity)
    and its gradient/Hessian in arrow form. th (N, K); p (3,); R (3, 3); rl (N, 6) the
    rolling contacts' local centres of curvature in O and normals in the palm frame (read
    only with ROLLING). Returns the energy [J]."""
    n_f, k_n = th.shape
    kc = prm[P_KC]
    klim = prm[P_KLIM]
    gA[:] = 0.0
    gC[:] = 0.0
    A[:] = 0.0
    B[:] = 0.0
    C[:] = 0.0
    e = 0.0
    rb = base_rot
    gam, G, lam, gt = vk[1], vk[3:6], vk[2], vk[0]  # scratch rows, taken once
    for i in range(n_f):
        cfx, cfy, cfz = _finger_chain(th, seg, nrm, i, 1.0, pad_xy[i, 0], pad_xy[i, 1],
                                      pad_r[i], sphi, cphi, qy, qz)
        # Eq. 6: springs about the rest angles.
        if flags[SPRINGS] != 0:
            for k in range(k_n):
                d = th[i, k] - rest[i, k]
                e += 0.5 * stiff[i, k] * d * d
                gA[i, k] += stiff[i, k] * d
                A[i, k, k] += stiff[i, k]
        # Joint limits as stiff one-sided penalties (docs/METHOD.md 8.2).
        if flags[LIMITS] != 0:
            for k in range(k_n):
                d = 0.0
                if th[i, k] < lo[i, k]:
                    d = th[i, k] - lo[i, k]
                elif th[i, k] > hi[i, k]:
                    d = th[i, k] - hi[i, k]
                if d != 0.0:
                    e += 0.5 * klim * d * d
                    gA[i, k] += klim * d
                    A[i, k, k] += klim
        # Eq. 7, compliant: 1/2 k_t max(0, u - s)^2, s = sum r_k (theta_k - lo_k).
        if flags[TENDON] != 0:
            s = 0.0
            for k in range(k_n):
                s += radii[i, k] * (th[i, k] - lo[i, k])
            slack = u[i] - s
            if slack > 0.0:
                e += 0.5 * kt[i] * slack * slack
                for k in range(k_n):
                    gA[i, k] -= kt[i] * slack * radii[i, k]
                    for m in range(k_n):
                        A[i, k, m] += kt[i] * radii[i, k] * radii[i, m]
        # Gravity potential of the finger links: -m g . x_com.
        if flags[LINK_GRAVITY] != 0:
            gfx = rb[i, 0, 0] * grav[0] + rb[i, 1, 0] * grav[1] + rb[i, 2, 0] * grav[2]
            gfy = rb[i, 0, 1] * grav[0] + rb[i, 1, 1] * grav[1] + rb[i, 2, 1] * grav[2]
            gfz = rb[i, 0, 2] * grav[0] + rb[i, 1, 2] * grav[1] + rb[i, 2, 2] * grav[2]
            gb = grav[0] * base_pos[i, 0] + grav[1] * base_pos[i, 1] + grav[2] * base_pos[i, 2]
            for k in range(k_n):
                m_k = lmass[i, k]
                cy, cz = lcom[i, k, 1], lcom[i, k, 2]
                py = qy[k] + cy * cphi[k] + cz * sphi[k]
                pz = qz[k] - cy * sphi[k] + cz * cphi[k]
                e -= m_k * (gb + gfx * lcom[i, k, 0] + gfy * py + gfz * pz)
                for j in range(k + 1):
                    dy = py - qy[j]
                    dz = pz - qz[j]
                    # d x / d theta_j = (-x) cross (x - q_j) = (0, dz, -dy)
                    gA[i, j] -= m_k * (gfy * dz - gfz * dy)
                    for m in range(j, k + 1):
                        # second derivative about joint max(j, m): -(0, dy', dz')
                        dy2 = py - qy[m]
                        dz2 = pz - qz[m]
                        h = m_k * (gfy * dy2 + gfz * dz2)
                        A[i, j, m] += h
                        if m != j:
                            A[i, m, j] += h
        # Rolling (docs/METHOD.md 8.2): the pad sphere touches the object's local sphere (centre
        # rl[i, :3] in O, radius rl[i, RL_RHO]; one equation) and the previous contact points
        # do not slip tangentially to the normal rl[i, 3:] (two), as stiff penalties.
        if flags[CONTACTS] != 0 and flags[ROLLING] != 0:
            ax, ay, az = anc[i, 0], anc[i, 1], anc[i, 2]
            nx, ny, nz = rl[i, 3], rl[i, 4], rl[i, 5]
            v0, v1, v2 = _separation(base_pos, rb, i, cfx, cfy, cfz, p, R, ax, ay, az)
            vn = v0 * nx + v1 * ny + v2 * nz
            t0, t1, t2 = v0 - vn * nx, v1 - vn * ny, v2 - vn * nz
            tn2 = t0 * t0 + t1 * t1 + t2 * t2
            nv = (nx, ny, nz)
            tv = (t0, t1, t2)
            # Friction (docs/METHOD.md 8.2; `MotionConfig.slide_friction`, `spin_friction`). The
            # normal force N is the contact's at the start of the solve, updated while the
            # grasp wedges (`_update_normal_forces`). The slide is a Huber function of the
            # tangential stretch t: the stick spring while k_c |t| <= mu N, the slip's
            # dissipation mu N |t| beyond (the Moreau envelope of elastic stick and plastic
            # slip, so that one minimization is the incremental elasto-plastic step).
            mu = prm[P_SLIDE_FRICTION]
            mu_t = prm[P_SPIN_FRICTION]
            spin_on = prm[P_KSPIN] > 0.0 or mu_t > 0.0
            s_sp = cxs = j0 = j1 = j2 = 0.0
            f1 = f2 = 0.0
            if spin_on:
                s_sp, cxs, j0, j1, j2 = _spin_rate(i, k_n, th, rl, R, rb, vk)
            cap = mu * rl[i, RL_FORCE] if math.isfinite(mu) else math.inf
            if kc * kc * tn2 <= cap * cap:
                e += 0.5 * kc * tn2
                for a in range(3):
                    gam[a] = kc * tv[a]
                    for b in range(3):
                        G[a, b] = kc * ((1.0 if a == b else 0.0) - nv[a] * nv[b])
            else:
                tn = math.sqrt(tn2)
                e += cap * tn - 0.5 * cap * cap / kc
                h = cap / tn
                for a in range(3):
                    gam[a] = h * tv[a]
                    for b in range(3):
                        G[a, b] = h * ((1.0 if a == b else 0.0) - nv[a] * nv[b]
                                       - tv[a] * tv[b] / tn2)
            if mu_t > 0.0:
                # Torsional friction: tau_max |s|, tau_max = mu_t N, smoothed to
                # tau_max (sqrt(s^2 + eps^2) - eps) so that Newton sees a C2 energy. (An
                # elliptic cone coupling it with the slide, as MuJoCo's, was measured by
                # `vlr gap`: no better on average, and 3 of 30 wine glass solves failed.)
                tau = mu_t * rl[i, RL_FORCE]
                eps = prm[P_SPIN_EPS]
                r = math.sqrt(s_sp * s_sp + eps * eps)
                e += tau * (r - eps)
                f1 += tau * s_sp / r
                f2 += tau * eps * eps / (r * r * r)
            if spin_on:
                # The pad's elastic torsional stiffness (`MotionConfig.spin_stiffness`).
                ks = prm[P_KSPIN]
                e += 0.5 * ks * s_sp * s_sp
                f1 += ks * s_sp
                f2 += ks
            _pair(i, k_n, cfx, cfy, cfz, ax, ay, az, gam, G, 0.0, rb, R, qy, qz, jac, M,
                  lam, gt, gA, A, B, gC, C)
            # Pad centre (fixed in D) to the local centre of curvature (fixed in O).
            s_last, c_last = sphi[k_n - 1], cphi[k_n - 1]
            pcz = seg[i, k_n - 1]
            px = pad_xy[i, 0]
            py = qy[k_n - 1] + pad_xy[i, 1] * c_last + pcz * s_last
            pz = qz[k_n - 1] - pad_xy[i, 1] * s_last + pcz * c_last
            d0, d1, d2 = _separation(base_pos, rb, i, px, py, pz, p, R,
                                     rl[i, 0], rl[i, 1], rl[i, 2])
            dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            reach = rl[i, RL_RHO] + pad_r[i]
            g = dist - reach
            e += 0.5 * kc * g * g
            dv = (d0 / dist, d1 / dist, d2 / dist)
            sc = 1.0 - reach / dist
            for a in range(3):
                gam[a] = kc * g * dv[a]
                for b in range(3):
                    G[a, b] = kc * (sc * (1.0 if a == b else 0.0)
                                    + (reach / dist) * dv[a] * dv[b])
            _pair(i, k_n, px, py, pz, rl[i, 0], rl[i, 1], rl[i, 2], gam, G, 0.0, rb, R, qy,
                  qz, jac, M, lam, gt, gA, A, B, gC, C)
            if spin_on:
                _spin_apply(i, k_n, f1, f2, cxs, j0, j1, j2, gA, A, B, gC, C)
        # Eq. 8 as a stiff penalty: the contact (fixed in D) stays at its anchor (fixed in O).
        elif flags[CONTACTS] != 0:
            ax, ay, az = anc[i, 0], anc[i, 1], anc[i, 2]
            rr = 0.0
            for a in range(3):
                r_a = (base_pos[i, a] + rb[i, a, 0] * cfx + rb[i, a, 1] * cfy + rb[i, a, 2] * cfz
                       - p[a] - (R[a, 0] * ax + R[a, 1] * ay + R[a, 2] * az))
                rr += r_a * r_a
                gam[a] = kc * r_a
            e += 0.5 * kc * rr
            _pair(i, k_n, cfx, cfy, cfz, ax, ay, az, gam, G, kc, rb, R, qy, qz, jac, M,
                  lam, gt, gA, A, B, gC, C)
    # Gravity potential of the object: -m g . (p + R com).
    if flags[OBJECT_GRAVITY] != 0:
        cx, cy, cz = ocom[0], ocom[1], ocom[2]
        wx = p[0] + R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
        wy = p[1] + R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
        wz = p[2] + R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz
        e -= omass * (grav[0] * wx + grav[1] * wy + grav[2] * wz)
        gam = lam
        for b in range(3):
            gC[b] -= omass * grav[b]
            gam[b] = R[0, b] * grav[0] + R[1, b] * grav[1] + R[2, b] * grav[2]
        # d/dw: -m (com x gamma)
        gC[3] -= omass * (cy * gam[2] - cz * gam[1])
        gC[4] -= omass * (cz * gam[0] - cx * gam[2])
        gC[5] -= omass * (cx * gam[1] - cy * gam[0])
        gc = gam[0] * cx + gam[1] * cy + gam[2] * cz
        cv = (cx, cy, cz)
        for b in range(3):
            for c in range(3):
                h = 0.5 * (gam[b] * cv[c] + cv[b] * gam[c])
                if b == c:
                    h -= gc
                C[3 + b, 3 + c] -= omass * h
    return e


@njit(cache=True, _nrt=False)
def _normal_force(i, th, seg, nrm, rl, p, R, base_pos, base_rot, pad_xy, pad_r, prm,
                  sphi, cphi, qy, qz):
    """Contact i's normal force in the rolling term at the current configuration [N]: k_c
    times how far finger i's pad sphere sinks into the object's local sphere (rl[i, :3]),
    """
    k_n = th.shape[1]
    _finger_chain(th, seg, nrm, i, 1.0, pad_xy[i, 0], pad_xy[i, 1], pad_r[i], sphi, cphi,
                  qy, qz)
    s_last, c_last = sphi[k_n - 1], cphi[k_n - 1]
    pcz = seg[i, k_n - 1]
    py = qy[k_n - 1] + pad_xy[i, 1] * c_last + pcz * s_last
    pz = qz[k_n - 1] - pad_xy[i, 1] * s_last + pcz * c_last
    d0, d1, d2 = _separation(base_pos, base_rot, i, pad_xy[i, 0], py, pz, p, R,
                             rl[i, 0], rl[i, 1], rl[i, 2])
    g = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - (rl[i, RL_RHO] + pad_r[i])
    return prm[P_KC] * max(0.0, -g)


@njit(cache=True, _nrt=False)
def _update_normal_forces(th, seg, nrm, rl, p, R, base_pos, base_rot, pad_xy, pad_r, prm,
                          sphi, cphi, qy, qz):
    """Each contact's normal force at the current configuration into rl[:, RL_FORCE], so
    that the friction's limits follow the grasp as it wedges. Writes and returns True only
    if some force changed by more than 1 mN + 0.1% (else the solve converges undisturbed)."""
    n_f = th.shape[0]
    changed = False
    for i in range(n_f):
        n = _normal_force(i, th, seg, nrm, rl, p, R, base_pos, base_rot, pad_xy, pad_r, prm,
                          sphi, cphi, qy, qz)
        if abs(n - rl[i, RL_FORCE]) > 1e-3 + 1e-3 * n:
            changed = True
    if changed:
        for i in range(n_f):
            rl[i, RL_FORCE] = _normal_force(i, th, seg, nrm, rl, p, R, base_pos, base_rot,
                                            pad_xy, pad_r, prm, sphi, cphi, qy, qz)
    return changed


@njit(cache=True, _nrt=False)
def _chol(M, n):
    """In-place lower Cholesky of the leading n x n block; False if not positive definite."""
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= M[j, k] * M[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        M[j, j] = d
        for i in range(j + 1, n):
            t = M[i, j]
            for k in range(j):
                t -= M[i, k] * M[j, k]
            M[i, j] = t / d
    return True


@njit(cache=True, _nrt=False)
def _chol_solve(L, n, b):
    """Solve (L L^T) x = b in place for vector b."""
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * b[k]
        b[i] = t / L[i, i]
    for i in range(n - 1, -1, -1):
        t = b[i]
        for k in range(i + 1, n):
            t -= L[k, i] * b[k]
        b[i] = t / L[i, i]


@njit(cache=True, _nrt=False)
def _newton_step(gA, gC, A, B, C, mu, dth, dc, La, X, y, S, col):
    """Damped Newton step (H + mu D) d = -g by Schur complement on the arrow structure.

    D is Marquardt's diag(|H|) plus a small floor, so that damping is scale-free across
    radians and metres. Returns False if a block is not positive definite."""
    n_f, k_n = gA.shape
    for a in range(6):
        for b in range(6):
            S[a, b] = C[a, b]
        S[a, a] += mu * (abs(C[a, a]) + 1e-9)
        dc[a] = -gC[a]
    for i in range(n_f):
        if k_n == 2:
            # Two joints a finger (the Model O's): the block's inverse in closed form.
            a00 = A[i, 0, 0] + mu * (abs(A[i, 0, 0]) + 1e-9)
            a11 = A[i, 1, 1] + mu * (abs(A[i, 1, 1]) + 1e-9)
            a01 = A[i, 0, 1]
            det = a00 * a11 - a01 * a01
            if not (a00 > 0.0 and det > 0.0):
                return False
            i00, i01, i11 = a11 / det, -a01 / det, a00 / det
            y0 = -(i00 * gA[i, 0] + i01 * gA[i, 1])
            y1 = -(i01 * gA[i, 0] + i11 * gA[i, 1])
            y[i, 0], y[i, 1] = y0, y1
            for c in range(6):
                b0, b1 = B[i, 0, c], B[i, 1, c]
                X[i, 0, c] = i00 * b0 + i01 * b1
                X[i, 1, c] = i01 * b0 + i11 * b1
            for a in range(6):
                b0, b1 = B[i, 0, a], B[i, 1, a]
                dc[a] -= b0 * y0 + b1 * y1
                for b in range(6):
                    S[a, b] -= b0 * X[i, 0, b] + b1 * X[i, 1, b]
            continue
        for a in range(k_n):
            for b in range(k_n):
                La[a, b] = A[i, a, b]
            La[a, a] += mu * (abs(A[i, a, a]) + 1e-9)
        if not _chol(La, k_n):
            return False
        for a in range(k_n):
            y[i, a] = -gA[i, a]
        _chol_solve(La, k_n, y[i])
        for c in range(6):
            for a in range(k_n):
                col[a] = B[i, a, c]
            _chol_solve(La, k_n, col)
            for a in range(k_n):
                X[i, a, c] = col[a]
        # S -= B^T X ; rhs -= B^T y
        for a in range(6):
            t = 0.0
            for m in range(k_n):
                t += B[i, m, a] * y[i, m]
            dc[a] -= t
            for b in range(6):
                t = 0.0
                for m in range(k_n):
                    t += B[i, m, a] * X[i, m, b]
                S[a, b] -= t
    if not _chol(S, 6):
        return False
    _chol_solve(S, 6, dc)
    for i in range(n_f):
        for a in range(k_n):
            t = y[i, a]
            for c in range(6):
                t -= X[i, a, c] * dc[c]
            dth[i, a] = t
    return True


@njit(cache=True, _nrt=False)
def _rotate3(R, w0, w1, w2, out):
    """out = R exp([w]x) (Rodrigues), w = (w0, w1, w2)."""
    ang = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    e00, e01, e02, e10, e11, e12, e20, e21, e22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    if ang > 1e-300:
        kx, ky, kz = w0 / ang, w1 / ang, w2 / ang
        s, c = math.sin(ang), math.cos(ang)
        v = 1.0 - c
        e00 = c + kx * kx * v
        e01 = kx * ky * v - kz * s
        e02 = kx * kz * v + ky * s
        e10 = ky * kx * v + kz * s
        e11 = c + ky * ky * v
        e12 = ky * kz * v - kx * s
        e20 = kz * kx * v - ky * s
        e21 = kz * ky * v + kx * s
        e22 = c + kz * kz * v
    for a in range(3):
        r0, r1, r2 = R[a, 0], R[a, 1], R[a, 2]
        out[a, 0] = r0 * e00 + r1 * e10 + r2 * e20
        out[a, 1] = r0 * e01 + r1 * e11 + r2 * e21
        out[a, 2] = r0 * e02 + r1 * e12 + r2 * e22


@njit(cache=True, _nrt=False)
def _solve_one(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u,
               base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
               omass, ocom, grav, flags, prm, max_iter,
               gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk,
               th_t, p_t, R_t, dth, dc, La, X, y, S, col, th0, p0):
    """Damped Newton (Levenberg-Marquardt) for particle q, warm-started from its state.
    Updates theta[q], pos[q], rot[q] in place; returns (status, iterations). The object's
    mass and centre of mass are the particle's own (omass (P,), ocom (P, 3)): an unknown
    object is identified like an unknown spring."""
    n_f, k_n = theta.shape[1], theta.shape[2]
    th = theta[q]
    # The particle's rows, taken once: each row is a view, and each view costs two atomic
    # reference counts; taken per evaluation they were a sixth of an evaluation's time.
    sq, nq, aq, kq, tq = seg[q], nrm[q], anc[q], stiff[q], kt[q]
    om = omass[q]
    oc = ocom[q]
    rl = roll[q] if flags[ROLLING] != 0 else roll[0]
    lagged = flags[ROLLING] != 0
    p = pos[q]
    R = rot[q]
    for i in range(n_f):
        for k in range(k_n):
            th0[i, k] = th[i, k]
    for a in range(3):
        p0[a] = p[a]
    e = _evaluate(th, sq, nq, aq, rl, p, R, kq, tq, u,
                  base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                  om, oc, grav, flags, prm, gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk)
    if not math.isfinite(e):
        return NONFINITE, 0
    mu = prm[P_MU0]
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        if not _newton_step(gA, gC, A, B, C, mu, dth, dc, La, X, y, S, col):
            mu *= 10.0
            if mu > 1e12:
                break
            continue
        # Directional derivative, needed by the line search (buffers get overwritten).
        gd = 0.0
        for i in range(n_f):
            for k in range(k_n):
                gd += gA[i, k] * dth[i, k]
        for a in range(6):
            gd += gC[a] * dc[a]
        # Step limit: keep each Newton step inside the region where the model is smooth.
        big_th = 0.0
        for i in range(n_f):
            for k in range(k_n):
                big_th = max(big_th, abs(dth[i, k]))
        big_p = math.sqrt(dc[0] * dc[0] + dc[1] * dc[1] + dc[2] * dc[2])
        big_w = math.sqrt(dc[3] * dc[3] + dc[4] * dc[4] + dc[5] * dc[5])
        if not math.isfinite(big_th + big_p + big_w + gd):
            return NONFINITE, it
        t = 1.0
        if big_th > prm[P_MAX_DTH]:
            t = min(t, prm[P_MAX_DTH] / big_th)
        if big_w > prm[P_MAX_DTH]:
            t = min(t, prm[P_MAX_DTH] / big_w)
        if big_p > prm[P_MAX_DP]:
            t = min(t, prm[P_MAX_DP] / big_p)
        small = (big_th < prm[P_TOL_TH] and big_p < prm[P_TOL_P] and big_w < prm[P_TOL_TH])
        if small:
            # Under the tolerance: the step is taken as it is and the solve ends; evaluating
            # the energy there (a line search) would only confirm what its size says, at the
            # cost of a third of an action's evaluations.
            for i in range(n_f):
                for k in range(k_n):
                    th[i, k] += dth[i, k]
            for a in range(3):
                p[a] += dc[a]
            _rotate3(R, dc[3], dc[4], dc[5], R_t)
            for a in range(3):
                for b in range(3):
                    R[a, b] = R_t[a, b]
            converged = True
            break
        # Backtracking line search (Armijo, quadratic interpolation): the geometric
        # stiffness of a loaded grasp changes fast, so the quadratic model overshoots on
        # steps of a few degrees; halving LM damping alone took 10-30 iterations.
        accepted = False
        e_t = e
        tol_e = 1e-15 + 1e-13 * abs(e)
        for _ls in range(8):
            for i in range(n_f):
                for k in range(k_n):
                    th_t[i, k] = th[i, k] + t * dth[i, k]
            for a in range(3):
                p_t[a] = p[a] + t * dc[a]
            w0, w1, w2 = t * dc[3], t * dc[4], t * dc[5]
            _rotate3(R, w0, w1, w2, R_t)
            e_t = _evaluate(th_t, sq, nq, aq, rl, p_t, R_t, kq, tq, u,
                            base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy,
                            pad_r, om, oc, grav, flags, prm, gA, gC, A, B, C, sphi, cphi,
                            qy, qz, jac, M, vk)
            if math.isfinite(e_t) and e_t <= e + 1e-4 * t * gd + tol_e:
                accepted = True
                break
            if small:
                break
            denom = 2.0 * (e_t - e - gd * t)
            t_new = 0.5 * t
            if math.isfinite(e_t) and denom > 0.0:
                t_new = -gd * t * t / denom
            t = min(max(t_new, 0.1 * t), 0.5 * t)
        if accepted:
            for i in range(n_f):
                for k in range(k_n):
                    th[i, k] = th_t[i, k]
            for a in range(3):
                p[a] = p_t[a]
                for b in range(3):
                    R[a, b] = R_t[a, b]
            e = e_t
            if (lagged and it <= max_iter // 2 and math.isfinite(prm[P_SLIDE_FRICTION])
                    and _update_normal_forces(th, sq, nq, rl, p, R, base_pos,
                                              base_rot, pad_xy, pad_r, prm, sphi, cphi, qy,
                                              qz)):
                e = _evaluate(th, sq, nq, aq, rl, p, R, kq, tq, u,
                              base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy,
                              pad_r, om, oc, grav, flags, prm, gA, gC, A, B, C, sphi,
                              cphi, qy, qz, jac, M, vk)
            if t == 1.0:
                mu = max(mu * 0.1, 1e-12)
            if small or (t * big_th < prm[P_TOL_TH] and t * big_p < prm[P_TOL_P]
                         and t * big_w < prm[P_TOL_TH]):
                converged = True
                break
        else:
            if small:
                # Round-off regime: the step is below tolerance yet cannot lower the energy.
                converged = True
                break
            mu *= 10.0
            if mu > 1e12:
                break
            e = _evaluate(th, sq, nq, aq, rl, p, R, kq, tq, u,
                          base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                          om, oc, grav, flags, prm, gA, gC, A, B, C, sphi, cphi, qy, qz,
                          jac, M, vk)
    # Jump check: a change far beyond what the action can cause means another branch.
    big = 0.0
    for i in range(n_f):
        for k in range(k_n):
            big = max(big, abs(th[i, k] - th0[i, k]))
    dp = math.sqrt((p[0] - p0[0]) ** 2 + (p[1] - p0[1]) ** 2 + (p[2] - p0[2]) ** 2)
    if not (math.isfinite(big) and math.isfinite(dp) and math.isfinite(e)):
        return NONFINITE, it
    if not converged:
        return NO_CONVERGENCE, it
    if big > prm[P_JUMP_TH] or dp > prm[P_JUMP_P]:
        return JUMP, it
    return OK, it


@njit(parallel=True, cache=True, fastmath=False)
def solve_batch(theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u,
                base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                omass, ocom, grav, flags, prm, max_iter, active, status, iters):
    """Equilibrium (Eq. 9) of every active particle at tendon command u, in place; the
    object's mass omass (P,) and centre of mass ocom (P, 3) are per particle."""
    n_p, n_f, k_n = theta.shape
    n_chunks = min(n_p, 64)
    for ch in prange(n_chunks):
        # Scratch per chunk: allocating per particle would cost more than the solve.
        gA = np.empty((n_f, k_n))
        gC = np.empty(6)
        A = np.empty((n_f, k_n, k_n))
        B = np.empty((n_f, k_n, 6))
        C = np.empty((6, 6))
        sphi = np.empty(k_n)
        cphi = np.empty(k_n)
        qy = np.empty(k_n)
        qz = np.empty(k_n)
        jac = np.empty((k_n, 3))
        M = np.empty((3, 3))
        vk = np.empty((6, 3))
        th_t = np.empty((n_f, k_n))
        p_t = np.empty(3)
        R_t = np.empty((3, 3))
        dth = np.empty((n_f, k_n))
        dc = np.empty(6)
        La = np.empty((k_n, k_n))
        X = np.empty((n_f, k_n, 6))
        y = np.empty((n_f, k_n))
        S = np.empty((6, 6))
        col = np.empty(k_n)
        th0 = np.empty((n_f, k_n))
        p0 = np.empty(3)
        start = ch * n_p // n_chunks
        stop = (ch + 1) * n_p // n_chunks
        for q in range(start, stop):
            if not active[q]:
                status[q] = INACTIVE
                iters[q] = 0
                continue
            st, it = _solve_one(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u,
                                base_pos, base_rot, radii, rest, lo, hi, lmass, lcom,
                                pad_xy, pad_r, omass, ocom, grav, flags, prm, max_iter,
                                gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk,
                                th_t, p_t, R_t, dth, dc, La, X, y, S, col, th0, p0)
            status[q] = st
            iters[q] = it


@njit(cache=True)
def evaluate_one(th, seg, nrm, anc, rl, p, R, stiff, kt, u,
                 base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                 omass, ocom, grav, flags, prm, gA, gC, A, B, C):
    """Energy, gradient and Hessian blocks of one particle (for tests and diagnostics)."""
    k_n = th.shape[1]
    sphi = np.empty(k_n)
    cphi = np.empty(k_n)
    qy = np.empty(k_n)
    qz = np.empty(k_n)
    jac = np.empty((k_n, 3))
    M = np.empty((3, 3))
    vk = np.empty((6, 3))
    return _evaluate(th, seg, nrm, anc, rl, p, R, stiff, kt, u,
                     base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                     omass, ocom, grav, flags, prm, gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk)


# --------------------------------------------------------------------------- the action path
# A command change solved whole inside the kernel, particle by particle: the rolling substeps
# (the contacts rolled after each, `vlr.surface.roll_contacts` without friction) and the
# follow-up of a large move (`vlr.motion.MotionConfig.follow_substeps`), so that one call does
# what `vlr.motion.MotionModel._solve` and `_follow` do with NumPy between kernel calls.

SURF_PLANE, SURF_SPHERE, SURF_CYLINDER = 0, 1, 2
# Indices into the float surface vector `srf`: kind, radius, the kernel's radius (a plane's
# 10 m sphere), the cylinder's axis in O (3), 1/FLAT_CURVATURE.
S_KIND, S_RADIUS, S_KERNEL, S_AXIS, S_FLAT_RADIUS, N_SRF = 0, 1, 2, 3, 6, 7


@njit(cache=True, _nrt=False)
def _distal_rotation(rb, phi, out):
    """out = R_PD = base_rot @ plane_rotation(phi) (`vlr.kinematics.plane_rotation`)."""
    c, s = math.cos(phi), math.sin(phi)
    for a in range(3):
        out[a, 0] = rb[a, 0]
        out[a, 1] = rb[a, 1] * c - rb[a, 2] * s
        out[a, 2] = rb[a, 1] * s + rb[a, 2] * c


@njit(cache=True, _nrt=False)
def _pad_points(i, th, seg, nrm, base_pos, rb, pad_xy, pad_r, p, R, sphi, cphi, qy, qz,
                cen, con):
    """Finger i's pad centre `cen` and contact point `con` in the object frame O (3,)."""
    for which in range(2):
        fx, fy, fz = _finger_chain(th, seg, nrm, i, 0.0 if which == 0 else 1.0,
                                   pad_xy[i, 0], pad_xy[i, 1], pad_r[i], sphi, cphi, qy, qz)
        out = cen if which == 0 else con
        for b in range(3):
            t = 0.0
            for a in range(3):
                x = base_pos[i, a] + rb[a, 0] * fx + rb[a, 1] * fy + rb[a, 2] * fz - p[a]
                t += R[a, b] * x
            out[b] = t


@njit(cache=True, _nrt=False)
def _surface_normals(th, nrm, base_rot, R, RD, m):
    """m (N, 3): the object's outward normal at each contact, in O: minus the pad's
    (`vlr.surface.surface_normals`)."""
    n_f, k_n = th.shape
    for i in range(n_f):
        phi = 0.0
        for k in range(k_n):
            phi += th[i, k]
        _distal_rotation(base_rot[i], phi, RD)
        for b in range(3):
            t = 0.0
            for a in range(3):
                npa = RD[a, 0] * nrm[i, 0] + RD[a, 1] * nrm[i, 1] + RD[a, 2] * nrm[i, 2]
                t += R[a, b] * npa
            m[i, b] = -t


@njit(cache=True, _nrt=False)
def _rolling_frames(th, anc, R, m, rho_q, srf, has_rho, rl):
    """rl (N, N_RL): the rolling term's frames without friction (`MotionModel.rolling_frames`,
    forces 0): local centres a - rho m, the normals R m, the summed angles, R, rho."""
    n_f, k_n = th.shape
    for i in range(n_f):
        rk = rho_q[i] if has_rho else srf[S_KERNEL]
        for b in range(3):
            rl[i, RL_CENTRE + b] = anc[i, b] - rk * m[i, b]
            rl[i, RL_NORMAL + b] = R[b, 0] * m[i, 0] + R[b, 1] * m[i, 1] + R[b, 2] * m[i, 2]
        phi = 0.0
        for k in range(k_n):
            phi += th[i, k]
        rl[i, RL_PHI] = phi
        for a in range(3):
            for b in range(3):
                rl[i, RL_ROT + 3 * a + b] = R[a, b]
        rl[i, RL_FORCE] = 0.0
        rl[i, RL_RHO] = rk


@njit(cache=True, _nrt=False)
def _roll_contacts(th, seg, nrm, anc, p, R, m, rho_q, srf, has_rho, base_pos, base_rot,
                   pad_xy, pad_r, sphi, cphi, qy, qz, cen, con, RD):
    """Each contact moved to where its pad now touches the object's local surface, in place
    (`vlr.surface.roll_contacts` without friction; `m` the normals before the solve)."""
    n_f, k_n = th.shape
    kind = int(srf[S_KIND])
    for i in range(n_f):
        rb = base_rot[i]
        _pad_points(i, th, seg, nrm, base_pos, rb, pad_xy, pad_r, p, R, sphi, cphi, qy, qz,
                    cen, con)
        mx, my, mz = m[i, 0], m[i, 1], m[i, 2]
        d0, d1, d2 = con[0] - anc[i, 0], con[1] - anc[i, 1], con[2] - anc[i, 2]
        dn = d0 * mx + d1 * my + d2 * mz
        t0, t1, t2 = d0 - dn * mx, d1 - dn * my, d2 - dn * mz
        rk = rho_q[i] if has_rho else srf[S_KERNEL]
        g0 = cen[0] - (anc[i, 0] - rk * mx)
        g1 = cen[1] - (anc[i, 1] - rk * my)
        g2 = cen[2] - (anc[i, 2] - rk * mz)
        gap = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2) - (rk + pad_r[i])
        ox, oy, oz = mx, my, mz
        if not (kind == SURF_PLANE and not has_rho):
            r = rho_q[i] if has_rho else srf[S_RADIUS]
            if kind == SURF_CYLINDER:
                a0, a1, a2 = srf[S_AXIS], srf[S_AXIS + 1], srf[S_AXIS + 2]
                ma = mx * a0 + my * a1 + mz * a2
                s0, s1, s2 = mx - ma * a0, my - ma * a1, mz - ma * a2
                sl = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
                if sl > 0.5:  # on the side (else an end face: flat)
                    s0, s1, s2 = s0 / sl, s1 / sl, s2 / sl
                    e0 = cen[0] - (anc[i, 0] - r * s0)
                    e1 = cen[1] - (anc[i, 1] - r * s1)
                    e2 = cen[2] - (anc[i, 2] - r * s2)
                    ea = e0 * a0 + e1 * a1 + e2 * a2
                    e0, e1, e2 = e0 - ea * a0, e1 - ea * a1, e2 - ea * a2
                    el = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                    if el > 0.0:
                        ox, oy, oz = e0 / el, e1 / el, e2 / el
                    else:
                        ox, oy, oz = e0, e1, e2
            else:
                e0 = cen[0] - (anc[i, 0] - r * mx)
                e1 = cen[1] - (anc[i, 1] - r * my)
                e2 = cen[2] - (anc[i, 2] - r * mz)
                el = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                ox, oy, oz = e0 / el, e1 / el, e2 / el
            if has_rho and r >= srf[S_FLAT_RADIUS]:
                ox, oy, oz = mx, my, mz
        reach = pad_r[i] + gap
        anc[i, 0] = cen[0] - reach * ox - t0
        anc[i, 1] = cen[1] - reach * oy - t1
        anc[i, 2] = cen[2] - reach * oz - t2
        phi = 0.0
        for k in range(k_n):
            phi += th[i, k]
        _distal_rotation(rb, phi, RD)
        # n_palm = -R out; n_D = RD^T n_palm
        n0 = -(R[0, 0] * ox + R[0, 1] * oy + R[0, 2] * oz)
        n1 = -(R[1, 0] * ox + R[1, 1] * oy + R[1, 2] * oz)
        n2 = -(R[2, 0] * ox + R[2, 1] * oy + R[2, 2] * oz)
        v0 = RD[0, 0] * n0 + RD[1, 0] * n1 + RD[2, 0] * n2
        v1 = RD[0, 1] * n0 + RD[1, 1] * n1 + RD[2, 1] * n2
        v2 = RD[0, 2] * n0 + RD[1, 2] * n1 + RD[2, 2] * n2
        vl = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = v0 / vl, v1 / vl, v2 / vl


@njit(cache=True, _nrt=False)
def _path(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u_from, u_to, steps, rolling,
          predict, rho, has_rho, srf, base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy,
          pad_r, omass, ocom, grav, flags, prm, max_iter, sc):
    """Particle q from its state at u_from to u_to in `steps` equal solves, the contacts
    rolled after each (`rolling`); returns (status of the first failed solve or OK, the
    iterations spent). `sc` holds the scratch buffers (`_scratch`)."""
    (gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk, th_t, p_t, R_t, dth, dc, La, X, y, S,
     col, th0, p0, tgt, mbuf, RD, cen, con, th_prev, p_prev, R_prev) = sc
    n_f, k_n = theta.shape[1], theta.shape[2]
    rho_q = rho[q] if has_rho else rho[0]
    th, p, R = theta[q], pos[q], rot[q]
    total = 0
    for j in range(1, steps + 1):
        if steps == 1:
            for i in range(n_f):
                tgt[i] = u_to[i]
        else:
            frac = j / steps
            for i in range(n_f):
                tgt[i] = u_from[i] + (u_to[i] - u_from[i]) * frac
        # The rolling frames first: they hold what the substep starts from.
        if rolling:
            _surface_normals(theta[q], nrm[q], base_rot, rot[q], RD, mbuf)
            _rolling_frames(theta[q], anc[q], rot[q], mbuf, rho_q, srf, has_rho, roll[q])
        if j > 1 and predict:
            # Predictor: the substeps are equal command changes, so the last one's change of
            # the configuration is the next one's first guess (a secant step along the
            # path); Newton then corrects it, in one or two iterations where the path is
            # smooth. th_prev, p_prev, R_prev hold the last substep's start.
            for i in range(n_f):
                for k in range(k_n):
                    d = th[i, k] - th_prev[i, k]
                    th_prev[i, k] = th[i, k]
                    th[i, k] += d
            # The rotation's change, vee(sym(R_prev^T R)), small: applied again, R exp(w).
            w0 = w1 = w2 = 0.0
            for a in range(3):
                w0 += 0.5 * (R_prev[a, 2] * R[a, 1] - R_prev[a, 1] * R[a, 2])
                w1 += 0.5 * (R_prev[a, 0] * R[a, 2] - R_prev[a, 2] * R[a, 0])
                w2 += 0.5 * (R_prev[a, 1] * R[a, 0] - R_prev[a, 0] * R[a, 1])
            for a in range(3):
                d = p[a] - p_prev[a]
                p_prev[a] = p[a]
                p[a] += d
                for b in range(3):
                    R_prev[a, b] = R[a, b]
            _rotate3(R_prev, w0, w1, w2, R)
        else:
            for i in range(n_f):
                for k in range(k_n):
                    th_prev[i, k] = th[i, k]
            for a in range(3):
                p_prev[a] = p[a]
                for b in range(3):
                    R_prev[a, b] = R[a, b]
        st, it = _solve_one(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, tgt,
                            base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy,
                            pad_r, omass, ocom, grav, flags, prm, max_iter,
                            gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk,
                            th_t, p_t, R_t, dth, dc, La, X, y, S, col, th0, p0)
        total += it
        if st != OK:
            return st, total
        if rolling:
            _roll_contacts(theta[q], seg[q], nrm[q], anc[q], pos[q], rot[q], mbuf, rho_q, srf,
                           has_rho, base_pos, base_rot, pad_xy, pad_r, sphi, cphi, qy, qz,
                           cen, con, RD)
    return OK, total


@njit(cache=True)
def _scratch(n_f, k_n):
    """Per-chunk scratch of `_path` (allocating per particle would cost more than a solve)."""
    return (np.empty((n_f, k_n)), np.empty(6), np.empty((n_f, k_n, k_n)),
            np.empty((n_f, k_n, 6)), np.empty((6, 6)), np.empty(k_n), np.empty(k_n),
            np.empty(k_n), np.empty(k_n), np.empty((k_n, 3)), np.empty((3, 3)),
            np.empty((6, 3)), np.empty((n_f, k_n)), np.empty(3), np.empty((3, 3)),
            np.empty((n_f, k_n)), np.empty(6), np.empty((k_n, k_n)), np.empty((n_f, k_n, 6)),
            np.empty((n_f, k_n)), np.empty((6, 6)), np.empty(k_n), np.empty((n_f, k_n)),
            np.empty(3), np.empty(n_f), np.empty((n_f, 3)), np.empty((3, 3)),
            np.empty(3), np.empty(3), np.empty((n_f, k_n)), np.empty(3), np.empty((3, 3)))


@njit(parallel=True, cache=True)
def solve_path_batch(theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u_from, u_to,
                     substeps, follow, rolling, predict, rho, has_rho, srf,
                     base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                     omass, ocom, grav, flags, prm, max_iter, active, status, iters,
                     followed):
    """Every active particle from u_from to u_to (`_path` in `substeps` solves); one that
    fails by a jump or no convergence is solved again from its start in `follow` equal
    steps of `substeps` solves each, at twice the iterations (`MotionConfig.
    follow_substeps`; 0 or 1: not). In place: the state, `active` (False after a failure),
    `status` (the first attempt's failure if the follow-up fails too), `iters` and
    `followed` (the follow-up was tried)."""
    n_p, n_f, k_n = theta.shape
    n_chunks = min(n_p, 64)
    for ch in prange(n_chunks):
        sc = _scratch(n_f, k_n)
        th_s = np.empty((n_f, k_n))
        nrm_s = np.empty((n_f, 3))
        anc_s = np.empty((n_f, 3))
        p_s = np.empty(3)
        R_s = np.empty((3, 3))
        u_a = np.empty(n_f)
        u_b = np.empty(n_f)
        start = ch * n_p // n_chunks
        stop = (ch + 1) * n_p // n_chunks
        for q in range(start, stop):
            followed[q] = False
            if not active[q]:
                status[q] = INACTIVE
                iters[q] = 0
                continue
            if follow > 1:
                th_s[:] = theta[q]
                nrm_s[:] = nrm[q]
                anc_s[:] = anc[q]
                p_s[:] = pos[q]
                R_s[:] = rot[q]
            st, it = _path(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u_from, u_to,
                           substeps, rolling, predict, rho, has_rho, srf, base_pos, base_rot,
                           radii,
                           rest, lo, hi, lmass, lcom, pad_xy, pad_r, omass, ocom, grav, flags,
                           prm, max_iter, sc)
            if follow > 1 and (st == JUMP or st == NO_CONVERGENCE):
                followed[q] = True
                theta[q] = th_s
                nrm[q] = nrm_s
                anc[q] = anc_s
                pos[q] = p_s
                rot[q] = R_s
                u_a[:] = u_from
                ok = True
                for j in range(1, follow + 1):
                    frac = j / follow
                    for i in range(n_f):
                        u_b[i] = u_from[i] + (u_to[i] - u_from[i]) * frac
                    # No predictor here: a move that needs following is steep where a
                    # secant step overshoots onto another branch (a jump).
                    st2, it2 = _path(q, theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u_a,
                                     u_b, substeps, rolling, False, rho, has_rho, srf,
                                     base_pos,
                                     base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy,
                                     pad_r, omass, ocom, grav, flags, prm, 2 * max_iter, sc)
                    it += it2
                    if st2 != OK:
                        ok = False
                        break
                    u_a[:] = u_b
                if ok:
                    st = OK
            status[q] = st
            iters[q] = it
            active[q] = st == OK


@njit(parallel=True, cache=True)
def contact_points_batch(theta, seg, nrm, base_pos, base_rot, pad_xy, pad_r, out):
    """out (P, N, 3): every particle's contact points in the palm frame (Eq. 2;
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
                fx, fy, fz = _finger_chain(th, sg, nr, i, 1.0, pad_xy[i, 0], pad_xy[i, 1],
                                           pad_r[i], sphi, cphi, qy, qz)
                for a in range(3):
                    out[q, i, a] = (base_pos[i, a] + base_rot[i, a, 0] * fx
                                    + base_rot[i, a, 1] * fy + base_rot[i, a, 2] * fz)


@njit(parallel=True, cache=True)
def evaluate_batch(theta, seg, nrm, anc, roll, pos, rot, stiff, kt, u,
                   base_pos, base_rot, radii, rest, lo, hi, lmass, lcom, pad_xy, pad_r,
                   omass, ocom, grav, flags, prm, energy):
    """The energy, gradient and Hessian of every particle at its state (the energies into
    `energy`): what one Newton iteration evaluates, for `vlr bench --profile`."""
    n_p, n_f, k_n = theta.shape
    n_chunks = min(n_p, 64)
    for ch in prange(n_chunks):
        sc = _scratch(n_f, k_n)
        gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk = sc[:12]
        for q in range((ch * n_p) // n_chunks, ((ch + 1) * n_p) // n_chunks):
            rl = roll[q] if flags[ROLLING] != 0 else roll[0]
            energy[q] = _evaluate(theta[q], seg[q], nrm[q], anc[q], rl, pos[q], rot[q],
                                  stiff[q], kt[q], u, base_pos, base_rot, radii, rest, lo, hi,
                                  lmass, lcom, pad_xy, pad_r, omass[q], ocom[q], grav, flags,
                                  prm, gA, gC, A, B, C, sphi, cphi, qy, qz, jac, M, vk)

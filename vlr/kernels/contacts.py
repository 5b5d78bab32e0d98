"""The contacts (Eq. 8, docs/METHOD.md 8.2): pinned, or rolling exactly within one solve
with the pads' Coulomb friction.

**Rolling.** A pad is a sphere (centre k, fixed in the distal frame D; radius r) on the
object's local surface at the contact, a primitive fixed in O (`start_context`): a sphere of
radius rho about a centre o, a cylinder of radius rho about an axis through o, or a plane
through o. With k_O = R^T (k - p) the pad centre in O, the primitive gives in closed form the
object's outward normal m(k_O), the gap g(k_O) (negative where the pad presses in) and the
contact on the object, c_O = k_O - (g + r) m; the contact on the pad is c_D = k_D + r n_D,
n_D = -R_D^T R m (Montana's contact coordinates, eliminated). Rolling without slip says the
contact travels over both surfaces alike: the slip of one solve (an action) from x0 is the
midpoint rule's

    s = 1/2 (R + R0) (c_O - c_O0) - 1/2 (R_D + R_D0) (c_D - c_D0),

exact to O(h^3) per action (h the action's turn), so one solve replaces the rolling
substeps; s is measured in the tangent plane of the start's normal n0, from the contact's
stretch at the start t0: z = P(n0) (t0 + s).

**Energy** of one contact (compliant form): 1/2 k_c g^2 + psi(z), psi the Moreau envelope of
the pads' Coulomb friction with a stick zone of k_c (smoothed maximum dissipation, the
variational form of IPC's friction): 1/2 k_c |z|^2 while k_c |z| <= mu lambda_n, mu lambda_n
|z| - (mu lambda_n)^2 / 2 k_c beyond. The normal force lambda_n is held at the solve's
prediction (`vlr.kernels.solve`). mu = inf: the contacts roll and never slide.

**Derivatives.** The gradient is exact (the chain rule through k_O, m, R, R_D). The Hessian
is k_c J^T J (the stick) or the slide's, plus each constraint's curvature weighted by its
multiplier (primal-dual Newton, Tournier et al. 2015: the geometric stiffness uses the
force the step predicts, not k_c times the trial point's constraint, so that no force spike
cuts the step): the gap's exactly, the slip's as that of the contact's two material points
held together (the pinned contact's), which leaves out terms of the order of the action.

**Pinned.** The contact point of the pad (fixed in D) held to its anchor a (fixed in O):
1/2 k_c |x_D - (p + R a)|^2.

Each contact adds its energy, gradient and Hessian into the arrow blocks (`vlr.kernels.
arrow`), and its constraint values and Jacobian rows (`vals` (N, 4), `jac` (N, 4, K + 6):
the gap, then the stretch; the pinned contact's three offsets in the last three) for the
multipliers' update and the stored tangent.
"""

from __future__ import annotations

import math

from numba import njit

from vlr.kernels.chain import distal_point, distal_rotation, to_palm
from vlr.kernels.records import (
    CTX_CAP,
    CTX_CD0,
    CTX_CO0,
    CTX_DIR,
    CTX_KIND,
    CTX_N0,
    CTX_O,
    CTX_PHI0,
    CTX_PSI0,
    CTX_RHO,
    CTX_SPIN,
    CTX_T0,
    JOINTS,
    LAM_N,
    LAM_T,
    SURF_CYLINDER,
    SURF_PLANE,
    SURF_SPHERE,
)


@njit(cache=True, inline="always", _nrt=False)
def _primitive(kind, ctx, i, r, kx, ky, kz, KO):
    """The pad centre k_O = (kx, ky, kz) in O against contact i's primitive: the gap g, the
    outward normal m (3, in O), and KO (3, 3) = dm / dk_O. Returns (g, mx, my, mz, L)."""
    ox, oy, oz = ctx[i, CTX_O], ctx[i, CTX_O + 1], ctx[i, CTX_O + 2]
    ax, ay, az = ctx[i, CTX_DIR], ctx[i, CTX_DIR + 1], ctx[i, CTX_DIR + 2]
    dx, dy, dz = kx - ox, ky - oy, kz - oz
    if kind == SURF_PLANE:
        g = ax * dx + ay * dy + az * dz - r
        for a in range(3):
            for b in range(3):
                KO[a, b] = 0.0
        return g, ax, ay, az, 0.0
    if kind == SURF_CYLINDER:
        t = ax * dx + ay * dy + az * dz
        dx, dy, dz = dx - t * ax, dy - t * ay, dz - t * az
    L = math.sqrt(dx * dx + dy * dy + dz * dz)
    mx, my, mz = dx / L, dy / L, dz / L
    m = (mx, my, mz)
    av = (ax, ay, az)
    for a in range(3):
        for b in range(3):
            v = (1.0 if a == b else 0.0) - m[a] * m[b]
            if kind == SURF_CYLINDER:
                v -= av[a] * av[b]
            KO[a, b] = v / L
    return L - ctx[i, CTX_RHO] - r, mx, my, mz, L


@njit(cache=True, _nrt=False)
def start_context(x, body, hand, srf, cfg, i, sc):
    """Contact i's solve context at the particle's start x0 = x (`vlr.kernels.records`
    CTX_*, into sc.ctx) and its multipliers there (the forces the anchors' stretch holds:
    sc.lam (N, N_LAM)). sc's chain is filled for finger i at x0."""
    th, p, R = x
    seg, nrm, anc, rho = body.seg, body.nrm, body.anc, body.rho
    sphi, cphi, qy, qz = sc.sphi, sc.cphi, sc.qy, sc.qz
    ctx, lam, KO, RD = sc.ctx, sc.lam, sc.KO, sc.RD
    k_n = JOINTS
    r = hand.pad_r[i]
    kfx, kfy, kfz = distal_point(seg, i, k_n, (sphi, cphi, qy, qz),
                                 (hand.pad_xy[i, 0], hand.pad_xy[i, 1], 0.0))
    kx, ky, kz = to_palm(hand, i, kfx, kfy, kfz)
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    distal_rotation(hand, i, phi, RD)
    # The pad's outward normal in the palm, and the object's in O (m0 = -R^T n_P0).
    n0 = RD[0, 0] * nrm[i, 0] + RD[0, 1] * nrm[i, 1] + RD[0, 2] * nrm[i, 2]
    n1 = RD[1, 0] * nrm[i, 0] + RD[1, 1] * nrm[i, 1] + RD[1, 2] * nrm[i, 2]
    n2 = RD[2, 0] * nrm[i, 0] + RD[2, 1] * nrm[i, 1] + RD[2, 2] * nrm[i, 2]
    m0x = -(R[0, 0] * n0 + R[1, 0] * n1 + R[2, 0] * n2)
    m0y = -(R[0, 1] * n0 + R[1, 1] * n1 + R[2, 1] * n2)
    m0z = -(R[0, 2] * n0 + R[1, 2] * n1 + R[2, 2] * n2)
    rk = rho[i]
    kind = SURF_SPHERE
    ux, uy, uz = m0x, m0y, m0z   # the direction from the contact to o
    if rk >= srf.flat_radius:
        kind = SURF_PLANE
    elif srf.kind == SURF_CYLINDER and CYL_EXACT:
        a0, a1, a2 = srf.axis[0], srf.axis[1], srf.axis[2]
        t = m0x * a0 + m0y * a1 + m0z * a2
        sx, sy, sz = m0x - t * a0, m0y - t * a1, m0z - t * a2
        sl = math.sqrt(sx * sx + sy * sy + sz * sz)
        if sl > 0.5:  # on the side; else an end face: a plane
            kind = SURF_CYLINDER
            ux, uy, uz = sx / sl, sy / sl, sz / sl
            ctx[i, CTX_DIR], ctx[i, CTX_DIR + 1], ctx[i, CTX_DIR + 2] = a0, a1, a2
        else:
            kind = SURF_PLANE
    ctx[i, CTX_KIND] = kind
    ctx[i, CTX_RHO] = rk
    # k_O0, the pad centre in O
    vx, vy, vz = kx - p[0], ky - p[1], kz - p[2]
    kox = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz
    koy = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
    koz = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
    # The stretch the anchor holds, as the pinned contact reads it: t0 = P(n) R (c_pad -
    # a), c_pad = k_O - r m0 the pad's material contact (its normals), n = -n_P0.
    wx = kox - r * m0x - anc[i, 0]
    wy = koy - r * m0y - anc[i, 1]
    wz = koz - r * m0z - anc[i, 2]
    tx = R[0, 0] * wx + R[0, 1] * wy + R[0, 2] * wz
    ty = R[1, 0] * wx + R[1, 1] * wy + R[1, 2] * wz
    tz = R[2, 0] * wx + R[2, 1] * wy + R[2, 2] * wz
    tn = tx * n0 + ty * n1 + tz * n2
    tx, ty, tz = tx - tn * n0, ty - tn * n1, tz - tn * n2
    # The anchor less its stretch is a point of the surface (`rolled`): the primitive's
    # centre or axis is rho behind it, fixed in O whatever the stretch.
    bx = anc[i, 0] + (R[0, 0] * tx + R[1, 0] * ty + R[2, 0] * tz)
    by = anc[i, 1] + (R[0, 1] * tx + R[1, 1] * ty + R[2, 1] * tz)
    bz = anc[i, 2] + (R[0, 2] * tx + R[1, 2] * ty + R[2, 2] * tz)
    if kind == SURF_PLANE:
        ctx[i, CTX_O], ctx[i, CTX_O + 1], ctx[i, CTX_O + 2] = bx, by, bz
        ctx[i, CTX_DIR], ctx[i, CTX_DIR + 1], ctx[i, CTX_DIR + 2] = m0x, m0y, m0z
    else:
        # The centre or axis rho + r + g0 behind the pad centre along the primitive's
        # normal u, g0 = w . m0 the gap the normal stretch holds: on a sphere (u = m0) the
        # same point as rho behind b; on a cylinder a pad normal off the axis's normal plane
        # (a jittered contact) would otherwise read a penetration of r (1 - |P m0|).
        reach = rk + r + (wx * m0x + wy * m0y + wz * m0z)
        ctx[i, CTX_O] = kox - reach * ux
        ctx[i, CTX_O + 1] = koy - reach * uy
        ctx[i, CTX_O + 2] = koz - reach * uz
    # the primitive at k_O0, the contact on the object c_O0 and on the pad c_D0
    g, mx, my, mz, _ = _primitive(kind, ctx, i, r, kox, koy, koz, KO)
    ctx[i, CTX_CO0] = kox - (g + r) * mx
    ctx[i, CTX_CO0 + 1] = koy - (g + r) * my
    ctx[i, CTX_CO0 + 2] = koz - (g + r) * mz
    # the normal in the palm, R m; the pad's contact offset r n_D = -r R_D^T R m, in D
    npx = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
    npy = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
    npz = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
    for b in range(3):
        ctx[i, CTX_CD0 + b] = -r * (RD[0, b] * npx + RD[1, b] * npy + RD[2, b] * npz)
    ctx[i, CTX_PHI0] = phi
    ctx[i, CTX_N0], ctx[i, CTX_N0 + 1], ctx[i, CTX_N0 + 2] = npx, npy, npz
    # the stretch in the tangent plane of the start's normal, in O: a spring between the
    # two bodies' material points turns with them (`rolling` carries it by R)
    tn = tx * npx + ty * npy + tz * npz
    tx, ty, tz = tx - tn * npx, ty - tn * npy, tz - tn * npz
    for b in range(3):
        ctx[i, CTX_T0 + b] = R[0, b] * tx + R[1, b] * ty + R[2, b] * tz
    ctx[i, CTX_CAP] = math.inf
    ctx[i, CTX_SPIN] = 0.0
    ctx[i, CTX_PSI0] = 0.0
    lam[i, LAM_N] = cfg.kc * g
    for b in range(3):
        lam[i, LAM_T + b] = cfg.kc * (R[b, 0] * ctx[i, CTX_T0] + R[b, 1] * ctx[i, CTX_T0 + 1]
                                      + R[b, 2] * ctx[i, CTX_T0 + 2])


@njit(cache=True, inline="always", _nrt=False)
def _k_object(hand, i, k_n, kf, ko, R, q, jk):
    """jk (3, K + 6): d k_O / d(theta_i, dp, dw), k_O = R^T (k - p) the pad centre in O
    (ko), kf = (y, z) its y, z in F, q = (qy, qz) the chain's joints."""
    kfy, kfz = kf
    kox, koy, koz = ko
    qy, qz = q
    rb = hand.base_rot
    for j in range(k_n):
        dy = kfy - qy[j]
        dz = kfz - qz[j]
        # d k / d theta_j = B (0, dz, -dy) in the palm; in O, R^T of it
        ux = rb[i, 0, 1] * dz - rb[i, 0, 2] * dy
        uy = rb[i, 1, 1] * dz - rb[i, 1, 2] * dy
        uz = rb[i, 2, 1] * dz - rb[i, 2, 2] * dy
        for a in range(3):
            jk[a, j] = R[0, a] * ux + R[1, a] * uy + R[2, a] * uz
    for a in range(3):
        for b in range(3):
            jk[a, k_n + b] = -R[b, a]
    # d k_O / d w = [k_O]x
    jk[0, k_n + 3], jk[0, k_n + 4], jk[0, k_n + 5] = 0.0, -koz, koy
    jk[1, k_n + 3], jk[1, k_n + 4], jk[1, k_n + 5] = koz, 0.0, -kox
    jk[2, k_n + 3], jk[2, k_n + 4], jk[2, k_n + 5] = -koy, kox, 0.0


@njit(cache=True, inline="always", _nrt=False)
def _add_block(i, k_n, J, G, GJ, blocks):
    """Add J^T G J (G (3, 3) symmetric) into the arrow blocks (A, B, C) of finger i (the
    columns of J: theta_i (K), then the object's 6); GJ (3, K + 6) scratch, G J formed once
    rather than for every pair of columns."""
    A, B, C = blocks
    nc = k_n + 6
    for a in range(3):
        for c in range(nc):
            GJ[a, c] = G[a, 0] * J[0, c] + G[a, 1] * J[1, c] + G[a, 2] * J[2, c]
    for c1 in range(nc):
        j0, j1, j2 = J[0, c1], J[1, c1], J[2, c1]
        for c2 in range(c1, nc):
            _put(i, k_n, c1, c2, j0 * GJ[0, c2] + j1 * GJ[1, c2] + j2 * GJ[2, c2], A, B, C)


@njit(cache=True, inline="always", _nrt=False)
def _put(i, k_n, c1, c2, t, A, B, C):
    """Add t at (c1, c2) and (c2, c1), c1 <= c2, of finger i's 8 x 8 block."""
    if c2 < k_n:
        A[i, c1, c2] += t
        if c1 != c2:
            A[i, c2, c1] += t
    elif c1 < k_n:
        B[i, c1, c2 - k_n] += t
    else:
        C[c1 - k_n, c2 - k_n] += t
        if c1 != c2:
            C[c2 - k_n, c1 - k_n] += t


@njit(cache=True, inline="always", _nrt=False)
def _point_curvature(i, k_n, lv, f, q, hand, A):
    """The joints' second derivatives of a point fixed in finger i's distal frame, f = (fy,
    fz) in F, weighted by the palm vector l = lv: l . d2x / dtheta_j dtheta_m, into A; q =
    (qy, qz) the chain's joints."""
    lx, ly, lz = lv
    fy, fz = f
    qy, qz = q
    rb = hand.base_rot
    for j in range(k_n):
        for m in range(j, k_n):
            dy = fy - qy[m]
            dz = fz - qz[m]
            h = -(lx * (rb[i, 0, 1] * dy + rb[i, 0, 2] * dz)
                  + ly * (rb[i, 1, 1] * dy + rb[i, 1, 2] * dz)
                  + lz * (rb[i, 2, 1] * dy + rb[i, 2, 2] * dz))
            A[i, j, m] += h
            if m != j:
                A[i, m, j] += h


@njit(cache=True, inline="always", _nrt=False)
def _object_point_curvature(lv, cv, C):
    """-(l' . R d2(exp([w]x) c) / dw^2), l' = R^T l (lv), c (cv, in O): the rotation's
    second derivatives of a point fixed in O, into the object's block."""
    lc = lv[0] * cv[0] + lv[1] * cv[1] + lv[2] * cv[2]
    for b in range(3):
        for c in range(3):
            h = 0.5 * (lv[b] * cv[c] + cv[b] * lv[c])
            if b == c:
                h -= lc
            C[3 + b, 3 + c] -= h


# The friction's stick zone at least [m]: Newton crosses a stick zone of k_c's few
# micrometres only by tiny steps. Half the likelihood's scale (0.2 mm): against 20 um, `vlr
# gap`'s sliding rung took half the Newton steps with the same per-action gap
# (docs/DECISIONS.md).
STICK_ZONE = 1e-4
CYL_EXACT = True


@njit(cache=True, inline="always", _nrt=False)
def friction(zx, zy, zz, kc, mu, lam_n, G):
    """The stretch's energy psi(z), its force (3,) and its Hessian G (3, 3), with the pads'
    Coulomb friction mu lambda_n held: the smoothed maximum dissipation

        psi = mu lambda_n (sqrt(|z|^2 + eps^2) - eps),   eps = mu lambda_n / k_c,

    the stick's spring k_c near z = 0 and the slide's constant force mu lambda_n far out,
    smooth in between (the Huber function's kink at the cone stalls Newton). mu = inf: the
    stick alone, 1/2 k_c |z|^2. Returns (psi, fx, fy, fz)."""
    z2 = zx * zx + zy * zy + zz * zz
    if not (math.isfinite(mu) and math.isfinite(lam_n)):
        for a in range(3):
            for b in range(3):
                G[a, b] = kc if a == b else 0.0
        return 0.5 * kc * z2, kc * zx, kc * zy, kc * zz
    cap = mu * lam_n
    if not cap > 1e-9:  # no normal force: nothing holds the contact tangentially
        for a in range(3):
            for b in range(3):
                G[a, b] = 0.0
        return 0.0, 0.0, 0.0, 0.0
    eps = max(cap / kc, STICK_ZONE)
    rr = math.sqrt(z2 + eps * eps)
    h = cap / rr
    zv = (zx, zy, zz)
    for a in range(3):
        for b in range(3):
            G[a, b] = h * ((1.0 if a == b else 0.0) - zv[a] * zv[b] / (rr * rr))
    return cap * (rr - eps), h * zx, h * zy, h * zz


@njit(cache=True, inline="always", _nrt=False)
def rolling(x, body, hand, cfg, i, sc):
    """Contact i, rolling (module docstring), at the iterate x = (th, p, R) from the
    solve's start (sc.ctx, sc.R0): its energy, into sc's arrow blocks its gradient and
    Hessian, into sc.vals[i], sc.jac[i] its constraints (gap, stretch) and their rows."""
    th, p, R = x
    seg, R0, ctx, lam, vals, jac = body.seg, sc.R0, sc.ctx, sc.lam, sc.vals, sc.jac
    gA, gC, A, B, C = sc.gA, sc.gC, sc.A, sc.B, sc.C
    sphi, cphi, qy, qz = sc.sphi, sc.cphi, sc.qy, sc.qz
    jk, dm, jz, t3, KO, RD, RD0, MO, MD = (sc.jk, sc.dm, sc.jz, sc.t3, sc.KO, sc.RD, sc.RD0,
                                           sc.MO, sc.MD)
    k_n = JOINTS
    nc = k_n + 6
    kc = cfg.kc
    r = hand.pad_r[i]
    kind = int(ctx[i, CTX_KIND])
    kfx, kfy, kfz = distal_point(seg, i, k_n, (sphi, cphi, qy, qz),
                                 (hand.pad_xy[i, 0], hand.pad_xy[i, 1], 0.0))
    kx, ky, kz = to_palm(hand, i, kfx, kfy, kfz)
    vx, vy, vz = kx - p[0], ky - p[1], kz - p[2]
    kox = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz
    koy = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
    koz = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
    g, mx, my, mz, _ = _primitive(kind, ctx, i, r, kox, koy, koz, KO)
    m = (mx, my, mz)
    _k_object(hand, i, k_n, (kfy, kfz), (kox, koy, koz), R, (qy, qz), jk)
    # dm = KO jk; the gap's row dg = m . jk; dc_O = jk - m dg - (g + r) dm (into jk's place
    # is not possible: jk is needed below), kept in t3.
    for c in range(nc):
        dg = mx * jk[0, c] + my * jk[1, c] + mz * jk[2, c]
        jac[i, 0, c] = dg
        for a in range(3):
            dm[a, c] = KO[a, 0] * jk[0, c] + KO[a, 1] * jk[1, c] + KO[a, 2] * jk[2, c]
        for a in range(3):
            t3[a, c] = jk[a, c] - m[a] * dg - (g + r) * dm[a, c]
    vals[i, 0] = g
    cox = kox - (g + r) * mx
    coy = koy - (g + r) * my
    coz = koz - (g + r) * mz
    # The normal in the palm n_P = R m, the pad's contact offset r n_D in D.
    npx = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
    npy = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
    npz = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    distal_rotation(hand, i, phi, RD)
    distal_rotation(hand, i, ctx[i, CTX_PHI0], RD0)
    # Delta c_D in D: r n_D - r n_D0, n_D = -RD^T n_P
    ddx = -r * (RD[0, 0] * npx + RD[1, 0] * npy + RD[2, 0] * npz) - ctx[i, CTX_CD0]
    ddy = -r * (RD[0, 1] * npx + RD[1, 1] * npy + RD[2, 1] * npz) - ctx[i, CTX_CD0 + 1]
    ddz = -r * (RD[0, 2] * npx + RD[1, 2] * npy + RD[2, 2] * npz) - ctx[i, CTX_CD0 + 2]
    dox = cox - ctx[i, CTX_CO0]
    doy = coy - ctx[i, CTX_CO0 + 1]
    doz = coz - ctx[i, CTX_CO0 + 2]
    # MO = (R + R0) / 2; MD = I + RD0 RD^T (so that (RD + RD0) X = MD RD X).
    for a in range(3):
        for b in range(3):
            MO[a, b] = 0.5 * (R[a, b] + R0[a, b])
            MD[a, b] = (RD0[a, 0] * RD[b, 0] + RD0[a, 1] * RD[b, 1] + RD0[a, 2] * RD[b, 2]
                        + (1.0 if a == b else 0.0))
    # the slip s = MO dc_O - 1/2 (RD + RD0) dc_D, dc_D = (ddx, ddy, ddz) in D
    rdx = RD[0, 0] * ddx + RD[0, 1] * ddy + RD[0, 2] * ddz
    rdy = RD[1, 0] * ddx + RD[1, 1] * ddy + RD[1, 2] * ddz
    rdz = RD[2, 0] * ddx + RD[2, 1] * ddy + RD[2, 2] * ddz
    s = (MO[0, 0] * dox + MO[0, 1] * doy + MO[0, 2] * doz
         - 0.5 * (MD[0, 0] * rdx + MD[0, 1] * rdy + MD[0, 2] * rdz),
         MO[1, 0] * dox + MO[1, 1] * doy + MO[1, 2] * doz
         - 0.5 * (MD[1, 0] * rdx + MD[1, 1] * rdy + MD[1, 2] * rdz),
         MO[2, 0] * dox + MO[2, 1] * doy + MO[2, 2] * doz
         - 0.5 * (MD[2, 0] * rdx + MD[2, 1] * rdy + MD[2, 2] * rdz))
    n0x, n0y, n0z = ctx[i, CTX_N0], ctx[i, CTX_N0 + 1], ctx[i, CTX_N0 + 2]
    t0x, t0y, t0z = ctx[i, CTX_T0], ctx[i, CTX_T0 + 1], ctx[i, CTX_T0 + 2]
    zx = R[0, 0] * t0x + R[0, 1] * t0y + R[0, 2] * t0z + s[0]
    zy = R[1, 0] * t0x + R[1, 1] * t0y + R[1, 2] * t0z + s[1]
    zz = R[2, 0] * t0x + R[2, 1] * t0y + R[2, 2] * t0z + s[2]
    zn = zx * n0x + zy * n0y + zz * n0z
    zx, zy, zz = zx - zn * n0x, zy - zn * n0y, zz - zn * n0z
    vals[i, 1], vals[i, 2], vals[i, 3] = zx, zy, zz
    # The slip's rows, in the palm:
    #   R_D dn_D = (om x n_P) dphi + R [m]x dw - R dm,   om = -B e_x the joints' axis;
    #   ds = MO dc_O - 1/2 R [dc_O]x dw - 1/2 (om x R_D dc_D) dphi - r/2 MD (R_D dn_D).
    rb = hand.base_rot
    omx, omy, omz = -rb[i, 0, 0], -rb[i, 1, 0], -rb[i, 2, 0]
    wnx = omy * npz - omz * npy
    wny = omz * npx - omx * npz
    wnz = omx * npy - omy * npx
    wdx = omy * rdz - omz * rdy
    wdy = omz * rdx - omx * rdz
    wdz = omx * rdy - omy * rdx
    for c in range(nc):
        # R_D dn_D, column c
        e0 = -(R[0, 0] * dm[0, c] + R[0, 1] * dm[1, c] + R[0, 2] * dm[2, c])
        e1 = -(R[1, 0] * dm[0, c] + R[1, 1] * dm[1, c] + R[1, 2] * dm[2, c])
        e2 = -(R[2, 0] * dm[0, c] + R[2, 1] * dm[1, c] + R[2, 2] * dm[2, c])
        ds0 = MO[0, 0] * t3[0, c] + MO[0, 1] * t3[1, c] + MO[0, 2] * t3[2, c]
        ds1 = MO[1, 0] * t3[0, c] + MO[1, 1] * t3[1, c] + MO[1, 2] * t3[2, c]
        ds2 = MO[2, 0] * t3[0, c] + MO[2, 1] * t3[1, c] + MO[2, 2] * t3[2, c]
        if c < k_n:
            e0 += wnx
            e1 += wny
            e2 += wnz
            ds0 -= 0.5 * wdx
            ds1 -= 0.5 * wdy
            ds2 -= 0.5 * wdz
        elif c >= k_n + 3:
            b = c - k_n - 3
            # R (m x e_b) and -1/2 R (dc_O x e_b)
            if b == 0:
                ux, uy, uz = 0.0, mz, -my
                vx2, vy2, vz2 = 0.0, doz, -doy
            elif b == 1:
                ux, uy, uz = -mz, 0.0, mx
                vx2, vy2, vz2 = -doz, 0.0, dox
            else:
                ux, uy, uz = my, -mx, 0.0
                vx2, vy2, vz2 = doy, -dox, 0.0
            e0 += R[0, 0] * ux + R[0, 1] * uy + R[0, 2] * uz
            e1 += R[1, 0] * ux + R[1, 1] * uy + R[1, 2] * uz
            e2 += R[2, 0] * ux + R[2, 1] * uy + R[2, 2] * uz
            ds0 -= 0.5 * (R[0, 0] * vx2 + R[0, 1] * vy2 + R[0, 2] * vz2)
            ds1 -= 0.5 * (R[1, 0] * vx2 + R[1, 1] * vy2 + R[1, 2] * vz2)
            ds2 -= 0.5 * (R[2, 0] * vx2 + R[2, 1] * vy2 + R[2, 2] * vz2)
            # the carried stretch R t0_O: R (e_b x t0_O)
            if b == 0:
                ex, ey, ez = 0.0, -t0z, t0y
            elif b == 1:
                ex, ey, ez = t0z, 0.0, -t0x
            else:
                ex, ey, ez = -t0y, t0x, 0.0
            ds0 += R[0, 0] * ex + R[0, 1] * ey + R[0, 2] * ez
            ds1 += R[1, 0] * ex + R[1, 1] * ey + R[1, 2] * ez
            ds2 += R[2, 0] * ex + R[2, 1] * ey + R[2, 2] * ez
        ds0 -= 0.5 * r * (MD[0, 0] * e0 + MD[0, 1] * e1 + MD[0, 2] * e2)
        ds1 -= 0.5 * r * (MD[1, 0] * e0 + MD[1, 1] * e1 + MD[1, 2] * e2)
        ds2 -= 0.5 * r * (MD[2, 0] * e0 + MD[2, 1] * e1 + MD[2, 2] * e2)
        dn = ds0 * n0x + ds1 * n0y + ds2 * n0z
        jz[0, c] = ds0 - dn * n0x
        jz[1, c] = ds1 - dn * n0y
        jz[2, c] = ds2 - dn * n0z
        for a in range(3):
            jac[i, 1 + a, c] = jz[a, c]
    # Energy and gradient. The gap: 1/2 k_c g^2.
    sig = lam[i, LAM_N]
    e = 0.5 * kc * g * g
    for c in range(nc):
        gr = kc * g * jac[i, 0, c]
        if c < k_n:
            gA[i, c] += gr
        else:
            gC[c - k_n] += gr
    # The stretch: psi(z) and its Hessian in z, G (`friction`).
    G = MO  # scratch: MO is not needed past the slip's rows
    ez, fx, fy, fz = friction(zx, zy, zz, kc, cfg.friction, ctx[i, CTX_CAP], G)
    e += ez
    for c in range(nc):
        gr = jz[0, c] * fx + jz[1, c] * fy + jz[2, c] * fz
        if c < k_n:
            gA[i, c] += gr
        else:
            gC[c - k_n] += gr
    _add_block(i, k_n, jz, G, sc.gj, (A, B, C))
    # The constraints' curvature weighted by the multipliers (sigma, lambda): exact. With
    # mu_O = MO^T lambda, nu = lambda + Q lambda (Q = RD RD0^T), nu' = R^T nu, lambda' =
    # R^T lambda:  lambda . s = mu_O . c_O(k_O) + r/2 nu . R m(k_O) + r/2 lambda . RD n_D0
    # + a constant, so the terms through k_O go into one (gamma, Gamma).
    lx, ly, lz = lam[i, LAM_T], lam[i, LAM_T + 1], lam[i, LAM_T + 2]
    muo = _mt3(R, R0, lx, ly, lz)
    r0l = (RD0[0, 0] * lx + RD0[1, 0] * ly + RD0[2, 0] * lz,
           RD0[0, 1] * lx + RD0[1, 1] * ly + RD0[2, 1] * lz,
           RD0[0, 2] * lx + RD0[1, 2] * ly + RD0[2, 2] * lz)
    qlx = RD[0, 0] * r0l[0] + RD[0, 1] * r0l[1] + RD[0, 2] * r0l[2]
    qly = RD[1, 0] * r0l[0] + RD[1, 1] * r0l[1] + RD[1, 2] * r0l[2]
    qlz = RD[2, 0] * r0l[0] + RD[2, 1] * r0l[1] + RD[2, 2] * r0l[2]
    nvx, nvy, nvz = lx + qlx, ly + qly, lz + qlz
    nup = (R[0, 0] * nvx + R[1, 0] * nvy + R[2, 0] * nvz,
           R[0, 1] * nvx + R[1, 1] * nvy + R[2, 1] * nvz,
           R[0, 2] * nvx + R[1, 2] * nvy + R[2, 2] * nvz)
    lp = (R[0, 0] * lx + R[1, 0] * ly + R[2, 0] * lz,
          R[0, 1] * lx + R[1, 1] * ly + R[2, 1] * lz,
          R[0, 2] * lx + R[1, 2] * ly + R[2, 2] * lz)
    _surface_curvature(kind, ctx, i, (r, g, m), KO, (kc, sig, muo, nup), G)
    # gamma = sigma m + Q_O mu_O + r/2 KO nu', Q_O = I - m m^T - (g + r) KO
    mmu = m[0] * muo[0] + m[1] * muo[1] + m[2] * muo[2]
    gam0 = gam1 = gam2 = 0.0
    for a in range(3):
        kmu = KO[a, 0] * muo[0] + KO[a, 1] * muo[1] + KO[a, 2] * muo[2]
        knu = KO[a, 0] * nup[0] + KO[a, 1] * nup[1] + KO[a, 2] * nup[2]
        v = sig * m[a] + muo[a] - m[a] * mmu - (g + r) * kmu + 0.5 * r * knu
        if a == 0:
            gam0 = v
        elif a == 1:
            gam1 = v
        else:
            gam2 = v
    _add_block(i, k_n, jk, G, sc.gj, (A, B, C))
    _k_curvature(i, k_n, (gam0, gam1, gam2), (kfy, kfz), (kox, koy, koz), R, hand, sc)
    # R's own turn: 1/2 lambda' . d2(exp) (c_O - c_O0) + r/2 nu' . d2(exp) m
    _rotation_curvature(0.5, lp, (dox, doy, doz), C)
    _rotation_curvature(1.0, lp, (t0x, t0y, t0z), C)
    _rotation_curvature(0.5 * r, nup, (mx, my, mz), C)
    # R's turn by the rest: 1/2 (dc_O x lambda') + r/2 (dm x nu'), both orders; RD's turn
    # (Q's) by n_P's change: r/2 (om x Q lambda) . dn_P, both orders.
    zx2 = omy * qlz - omz * qly
    zy2 = omz * qlx - omx * qlz
    zz2 = omx * qly - omy * qlx
    for c in range(nc):
        x0 = (0.5 * (t3[1, c] * lp[2] - t3[2, c] * lp[1])
              + 0.5 * r * (dm[1, c] * nup[2] - dm[2, c] * nup[1]))
        x1 = (0.5 * (t3[2, c] * lp[0] - t3[0, c] * lp[2])
              + 0.5 * r * (dm[2, c] * nup[0] - dm[0, c] * nup[2]))
        x2 = (0.5 * (t3[0, c] * lp[1] - t3[1, c] * lp[0])
              + 0.5 * r * (dm[0, c] * nup[1] - dm[1, c] * nup[0]))
        xv = (x0, x1, x2)
        for b in range(3):
            cw = k_n + 3 + b
            if c == cw:
                _put(i, k_n, c, cw, 2.0 * xv[b], A, B, C)
            elif c < cw:
                _put(i, k_n, c, cw, xv[b], A, B, C)
            else:
                _put(i, k_n, cw, c, xv[b], A, B, C)
        # dn_P, column c: R dm (+ R (e_b x m) for the turn's columns)
        d0 = R[0, 0] * dm[0, c] + R[0, 1] * dm[1, c] + R[0, 2] * dm[2, c]
        d1 = R[1, 0] * dm[0, c] + R[1, 1] * dm[1, c] + R[1, 2] * dm[2, c]
        d2 = R[2, 0] * dm[0, c] + R[2, 1] * dm[1, c] + R[2, 2] * dm[2, c]
        if c >= k_n + 3:
            b = c - k_n - 3
            if b == 0:
                ux, uy, uz = 0.0, -mz, my
            elif b == 1:
                ux, uy, uz = mz, 0.0, -mx
            else:
                ux, uy, uz = -my, mx, 0.0
            d0 += R[0, 0] * ux + R[0, 1] * uy + R[0, 2] * uz
            d1 += R[1, 0] * ux + R[1, 1] * uy + R[1, 2] * uz
            d2 += R[2, 0] * ux + R[2, 1] * uy + R[2, 2] * uz
        y = 0.5 * r * (zx2 * d0 + zy2 * d1 + zz2 * d2)
        for j in range(k_n):
            if c == j:
                _put(i, k_n, j, c, 2.0 * y, A, B, C)
            elif c < j:
                _put(i, k_n, c, j, y, A, B, C)
            else:
                _put(i, k_n, j, c, y, A, B, C)
    # RD's (Q's) turn twice: r/2 (om x (om x Q lambda)) . n_P + 1/2 lambda . (om x (om x
    # RD c_D0)), the same for every pair of the finger's joints.
    c0, c1, c2 = ctx[i, CTX_CD0], ctx[i, CTX_CD0 + 1], ctx[i, CTX_CD0 + 2]
    cdx = RD[0, 0] * c0 + RD[0, 1] * c1 + RD[0, 2] * c2
    cdy = RD[1, 0] * c0 + RD[1, 1] * c1 + RD[1, 2] * c2
    cdz = RD[2, 0] * c0 + RD[2, 1] * c1 + RD[2, 2] * c2
    om = (omx, omy, omz)
    hqq = (0.5 * r * _double_turn(om, (qlx, qly, qlz), (npx, npy, npz))
           + 0.5 * _double_turn(om, (cdx, cdy, cdz), (lx, ly, lz)))
    for j in range(k_n):
        for k in range(k_n):
            A[i, j, k] += hqq
    return e


# The spin [rad] over which the torsional friction's |psi| is rounded off (Newton needs a
# smooth energy): the stick's stiffness is the limit over it.
SPIN_EPS = 5e-3


@njit(cache=True, inline="always", _nrt=False)
def spin(x, hand, i, sc):
    """Pad i's torsional friction over the solve (the pads' spin, rate-independent Coulomb
    friction as an incremental dissipation potential): mu_t lambda_n (sqrt(psi^2 + eps^2)
    - eps), psi the object's turn relative to the pad about the start's normal n0,

        psi = psi0 + n0 . vee_asym(R R0^T) - (n0 . om) (phi - phi0),

    vee_asym(M) = vee(M - M^T) / 2 (sin(angle) axis: within angle^3 / 6 of the turn),
    om the finger's joint axis in the palm, psi0 the spin the pad carries from its last
    action (ctx's CTX_PSI0: the stick's, `carried_spin`); its limit mu_t lambda_n (ctx's
    CTX_SPIN) held at the solve's predicted normal force. Adds its gradient and exact
    Hessian into sc's arrow blocks; returns its energy. x = (th, p, R) the iterate, sc.R0
    the start's rotation."""
    th, _, R = x
    R0, ctx, gA, gC, A, B, C = sc.R0, sc.ctx, sc.gA, sc.gC, sc.A, sc.B, sc.C
    cap = ctx[i, CTX_SPIN]
    k_n = JOINTS
    n0x, n0y, n0z = ctx[i, CTX_N0], ctx[i, CTX_N0 + 1], ctx[i, CTX_N0 + 2]
    rb = hand.base_rot
    cw = -(n0x * rb[i, 0, 0] + n0y * rb[i, 1, 0] + n0z * rb[i, 2, 0])  # n0 . om
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    # X = R0^T [n0]x R; psi_O = -tr(X) / 2
    nx = ((0.0, -n0z, n0y), (n0z, 0.0, -n0x), (-n0y, n0x, 0.0))
    x00 = x01 = x02 = x10 = x11 = x12 = x20 = x21 = x22 = 0.0
    for a in range(3):
        for b in range(3):
            v = 0.0
            for c in range(3):
                w = R0[0, a] * nx[0][c] + R0[1, a] * nx[1][c] + R0[2, a] * nx[2][c]
                v += w * R[c, b]
            if a == 0:
                if b == 0:
                    x00 = v
                elif b == 1:
                    x01 = v
                else:
                    x02 = v
            elif a == 1:
                if b == 0:
                    x10 = v
                elif b == 1:
                    x11 = v
                else:
                    x12 = v
            else:
                if b == 0:
                    x20 = v
                elif b == 1:
                    x21 = v
                else:
                    x22 = v
    X = ((x00, x01, x02), (x10, x11, x12), (x20, x21, x22))
    tr = x00 + x11 + x22
    psi = ctx[i, CTX_PSI0] - 0.5 * tr - cw * (phi - ctx[i, CTX_PHI0])
    rr = math.sqrt(psi * psi + SPIN_EPS * SPIN_EPS)
    e = cap * (rr - SPIN_EPS)
    f1 = cap * psi / rr
    f2 = cap * SPIN_EPS * SPIN_EPS / (rr * rr * rr)
    # d psi / d w (the body turn R exp([w]x)): vee(X - X^T) / 2
    gw = (0.5 * (x21 - x12), 0.5 * (x02 - x20), 0.5 * (x10 - x01))
    for k in range(k_n):
        gA[i, k] -= f1 * cw
        for m in range(k_n):
            A[i, k, m] += f2 * cw * cw
        for b in range(3):
            B[i, k, 3 + b] -= f2 * cw * gw[b]
    for a in range(3):
        gC[3 + a] += f1 * gw[a]
        for b in range(3):
            h = -0.5 * (0.5 * (X[a][b] + X[b][a]) - (tr if a == b else 0.0))
            C[3 + a, 3 + b] += f2 * gw[a] * gw[b] + f1 * h
    return e


# The torque a pad carries into its next action, at most this share of its limit: the
# sliding's excess is dissipated (a return mapping), so a spin that reverses turns the
# torque over within a few eps rather than unwinding the whole slide.
SPIN_CARRY = 0.95


@njit(cache=True, inline="always", _nrt=False)
def carried_spin(th, R, R0, hand, i, ctx):
    """Pad i's spin to carry into the next action: psi at the iterate (`spin_angle`), its
    part within the stick, |psi| <= eps c / sqrt(1 - c^2), c = SPIN_CARRY (where the
    smoothed torque reaches c times the limit)."""
    lim = SPIN_EPS * SPIN_CARRY / math.sqrt(1.0 - SPIN_CARRY * SPIN_CARRY)
    return max(-lim, min(lim, spin_angle(th, R, R0, hand, i, ctx)))


@njit(cache=True, inline="always", _nrt=False)
def spin_angle(th, R, R0, hand, i, ctx):
    """Pad i's spin psi at the iterate (`spin`'s), the carried one included [rad]."""
    k_n = JOINTS
    n0x, n0y, n0z = ctx[i, CTX_N0], ctx[i, CTX_N0 + 1], ctx[i, CTX_N0 + 2]
    rb = hand.base_rot
    cw = -(n0x * rb[i, 0, 0] + n0y * rb[i, 1, 0] + n0z * rb[i, 2, 0])
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    # n0 . vee_asym(R R0^T), M_ab = R_a . R0_b (rows)
    m21 = R[2, 0] * R0[1, 0] + R[2, 1] * R0[1, 1] + R[2, 2] * R0[1, 2]
    m12 = R[1, 0] * R0[2, 0] + R[1, 1] * R0[2, 1] + R[1, 2] * R0[2, 2]
    m02 = R[0, 0] * R0[2, 0] + R[0, 1] * R0[2, 1] + R[0, 2] * R0[2, 2]
    m20 = R[2, 0] * R0[0, 0] + R[2, 1] * R0[0, 1] + R[2, 2] * R0[0, 2]
    m10 = R[1, 0] * R0[0, 0] + R[1, 1] * R0[0, 1] + R[1, 2] * R0[0, 2]
    m01 = R[0, 0] * R0[1, 0] + R[0, 1] * R0[1, 1] + R[0, 2] * R0[1, 2]
    turn = 0.5 * (n0x * (m21 - m12) + n0y * (m02 - m20) + n0z * (m10 - m01))
    return ctx[i, CTX_PSI0] + turn - cw * (phi - ctx[i, CTX_PHI0])


@njit(cache=True, inline="always", _nrt=False)
def _mt3(R, R0, lx, ly, lz):
    """1/2 (R + R0)^T l."""
    return (0.5 * ((R[0, 0] + R0[0, 0]) * lx + (R[1, 0] + R0[1, 0]) * ly
                   + (R[2, 0] + R0[2, 0]) * lz),
            0.5 * ((R[0, 1] + R0[0, 1]) * lx + (R[1, 1] + R0[1, 1]) * ly
                   + (R[2, 1] + R0[2, 1]) * lz),
            0.5 * ((R[0, 2] + R0[0, 2]) * lx + (R[1, 2] + R0[1, 2]) * ly
                   + (R[2, 2] + R0[2, 2]) * lz))


@njit(cache=True, inline="always", _nrt=False)
def _double_turn(om, v, w):
    """(om x (om x v)) . w = (om . v)(om . w) - |om|^2 (v . w)."""
    ox, oy, oz = om
    vx, vy, vz = v
    wx, wy, wz = w
    return ((ox * vx + oy * vy + oz * vz) * (ox * wx + oy * wy + oz * wz)
            - (ox * ox + oy * oy + oz * oz) * (vx * wx + vy * wy + vz * wz))


@njit(cache=True, inline="always", _nrt=False)
def _rotation_curvature(w, lv, cv, C):
    """w times the Hessian in dw of l' . exp([dw]x) c (l' = lv, c = cv in O): 1/2 (l' c^T
    + c l'^T) - (l' . c) I, into the object's rotation block."""
    lc = lv[0] * cv[0] + lv[1] * cv[1] + lv[2] * cv[2]
    for b in range(3):
        for c in range(3):
            h = 0.5 * (lv[b] * cv[c] + cv[b] * lv[c])
            if b == c:
                h -= lc
            C[3 + b, 3 + c] += w * h


@njit(cache=True, inline="always", _nrt=False)
def _normal_curvature(kind, ctx, i, m, L, mu, out, w):
    """out += w * sum_a mu_a d2 m_a / dk_O^2 for the primitive's normal m(k_O): on a
    sphere -1/L^2 [mu m^T + m mu^T + (mu . m)(I - 3 m m^T)]; on a cylinder the same with
    mu and I projected across its axis; 0 on a plane."""
    if kind == SURF_PLANE:
        return
    ax, ay, az = ctx[i, CTX_DIR], ctx[i, CTX_DIR + 1], ctx[i, CTX_DIR + 2]
    av = (ax, ay, az)
    mu0, mu1, mu2 = mu[0], mu[1], mu[2]
    if kind == SURF_CYLINDER:
        t = mu0 * ax + mu1 * ay + mu2 * az
        mu0, mu1, mu2 = mu0 - t * ax, mu1 - t * ay, mu2 - t * az
    mv = (mu0, mu1, mu2)
    mm = mu0 * m[0] + mu1 * m[1] + mu2 * m[2]
    f = -w / (L * L)
    for a in range(3):
        for b in range(3):
            eye = 1.0 if a == b else 0.0
            if kind == SURF_CYLINDER:
                eye -= av[a] * av[b]
            out[a, b] += f * (mv[a] * m[b] + m[a] * mv[b] + mm * (eye - 3.0 * m[a] * m[b]))


@njit(cache=True, inline="always", _nrt=False)
def _surface_curvature(kind, ctx, i, geo, KO, weights, G):
    """G (3, 3) = k_c m m^T + sigma KO + Gamma_c(mu_O) + r/2 Gamma_m(nu'): the Hessian in
    k_O of the gap's energy and multiplier and of the slip's terms through k_O, with
    Gamma_c(mu) = -[m (KO mu)^T + (KO mu) m^T + (g + r) Gamma_m(mu) + (mu . m) KO] the
    curvature of mu . c_O; geo = (r, g, m), weights = (k_c, sigma, mu_O, nu')."""
    r, g, m = geo
    kc, sig, muo, nup = weights
    mmu = m[0] * muo[0] + m[1] * muo[1] + m[2] * muo[2]
    kmu = (KO[0, 0] * muo[0] + KO[0, 1] * muo[1] + KO[0, 2] * muo[2],
           KO[1, 0] * muo[0] + KO[1, 1] * muo[1] + KO[1, 2] * muo[2],
           KO[2, 0] * muo[0] + KO[2, 1] * muo[1] + KO[2, 2] * muo[2])
    for a in range(3):
        for b in range(3):
            G[a, b] = (kc * m[a] * m[b] + (sig - mmu) * KO[a, b]
                       - m[a] * kmu[b] - kmu[a] * m[b])
    L = ctx[i, CTX_RHO] + r + g
    _normal_curvature(kind, ctx, i, m, L, muo, G, -(g + r))
    _normal_curvature(kind, ctx, i, m, L, nup, G, 0.5 * r)


@njit(cache=True, inline="always", _nrt=False)
def _k_curvature(i, k_n, gv, kf, kv, R, hand, sc):
    """gamma . d2 k_O (gamma = gv in O; k_O = R^T (k - p) = kv, kf = (y, z) the pad
    centre's in F, R <- R exp([dw]x)): the joints' (the pad centre's curvature), joint and
    position by rotation (gamma x the column of d k_O, sc.jk), and rotation by rotation,
    into sc's arrow blocks."""
    gx, gy, gz = gv
    kox, koy, koz = kv
    qy, qz, jk, A, B, C = sc.qy, sc.qz, sc.jk, sc.A, sc.B, sc.C
    # joints: (R gamma) . d2 k / dtheta_j dtheta_m
    lx = R[0, 0] * gx + R[0, 1] * gy + R[0, 2] * gz
    ly = R[1, 0] * gx + R[1, 1] * gy + R[1, 2] * gz
    lz = R[2, 0] * gx + R[2, 1] * gy + R[2, 2] * gz
    _point_curvature(i, k_n, (lx, ly, lz), kf, (qy, qz), hand, A)
    # (theta_j or p_a) by w_b: (gamma x jk[:, col])_b
    for col in range(k_n + 3):
        ux, uy, uz = jk[0, col], jk[1, col], jk[2, col]
        cr = (gy * uz - gz * uy, gz * ux - gx * uz, gx * uy - gy * ux)
        for b in range(3):
            if col < k_n:
                B[i, col, 3 + b] += cr[b]
            else:
                C[col - k_n, 3 + b] += cr[b]
                C[3 + b, col - k_n] += cr[b]
    # w by w: 1/2 (gamma k^T + k gamma^T) - (gamma . k) I
    gk = gx * kox + gy * koy + gz * koz
    for b in range(3):
        for c in range(3):
            h = 0.5 * (gv[b] * kv[c] + kv[b] * gv[c])
            if b == c:
                h -= gk
            C[3 + b, 3 + c] += h


@njit(cache=True, inline="always", _nrt=False)
def pinned(x, body, hand, cfg, i, sc):
    """Contact i pinned (Eq. 8 as a stiff penalty): the pad's contact point (fixed in D)
    held to its anchor a (fixed in O), 1/2 k_c |x_D - (p + R a)|^2, at the iterate x =
    (th, p, R). Its energy; gradient and Hessian into sc's arrow blocks, the offset and its
    rows into sc.vals[i, 1:], sc.jac[i, 1:]."""
    th, p, R = x
    seg, nrm, anc = body.seg, body.nrm, body.anc
    lam, vals, jac, jv = sc.lam, sc.vals, sc.jac, sc.jk
    gA, gC, A, B, C = sc.gA, sc.gC, sc.A, sc.B, sc.C
    sphi, cphi, qy, qz = sc.sphi, sc.cphi, sc.qy, sc.qz
    k_n = JOINTS
    nc = k_n + 6
    kc = cfg.kc
    r = hand.pad_r[i]
    fx, fy, fz = distal_point(seg, i, k_n, (sphi, cphi, qy, qz),
                              (hand.pad_xy[i, 0] + r * nrm[i, 0],
                               hand.pad_xy[i, 1] + r * nrm[i, 1], r * nrm[i, 2]))
    xx, xy, xz = to_palm(hand, i, fx, fy, fz)
    ax, ay, az = anc[i, 0], anc[i, 1], anc[i, 2]
    v = (xx - p[0] - (R[0, 0] * ax + R[0, 1] * ay + R[0, 2] * az),
         xy - p[1] - (R[1, 0] * ax + R[1, 1] * ay + R[1, 2] * az),
         xz - p[2] - (R[2, 0] * ax + R[2, 1] * ay + R[2, 2] * az))
    rb = hand.base_rot
    for j in range(k_n):
        dy = fy - qy[j]
        dz = fz - qz[j]
        for a in range(3):
            jv[a, j] = rb[i, a, 1] * dz - rb[i, a, 2] * dy
    for a in range(3):
        for b in range(3):
            jv[a, k_n + b] = -1.0 if a == b else 0.0
    # d(-R exp([w]x) a)/dw = R [a]x
    for a in range(3):
        jv[a, k_n + 3] = R[a, 1] * az - R[a, 2] * ay
        jv[a, k_n + 4] = -R[a, 0] * az + R[a, 2] * ax
        jv[a, k_n + 5] = R[a, 0] * ay - R[a, 1] * ax
    vals[i, 0] = 0.0
    e = 0.0
    for a in range(3):
        vals[i, 1 + a] = v[a]
        e += 0.5 * kc * v[a] * v[a]
        for c in range(nc):
            jac[i, 0, c] = 0.0
            jac[i, 1 + a, c] = jv[a, c]
    for c in range(nc):
        gr = kc * (jv[0, c] * v[0] + jv[1, c] * v[1] + jv[2, c] * v[2])
        if c < k_n:
            gA[i, c] += gr
        else:
            gC[c - k_n] += gr
        for c2 in range(c, nc):
            t = kc * (jv[0, c] * jv[0, c2] + jv[1, c] * jv[1, c2] + jv[2, c] * jv[2, c2])
            _put(i, k_n, c, c2, t, A, B, C)
    lx, ly, lz = lam[i, LAM_T], lam[i, LAM_T + 1], lam[i, LAM_T + 2]
    _point_curvature(i, k_n, (lx, ly, lz), (fy, fz), (qy, qz), hand, A)
    l0 = R[0, 0] * lx + R[1, 0] * ly + R[2, 0] * lz
    l1 = R[0, 1] * lx + R[1, 1] * ly + R[2, 1] * lz
    l2 = R[0, 2] * lx + R[1, 2] * ly + R[2, 2] * lz
    _object_point_curvature((l0, l1, l2), (ax, ay, az), C)
    return e


@njit(cache=True, _nrt=False)
def rolled(x, body, hand, i, sc):
    """After a rolling solve ending at x = (th, p, R), contact i's new pad normal
    (body.nrm[i], in D) and anchor (body.anc[i], in O) where the pad now touches the
    primitive: the anchor is the contact on the object less the stretch (`sc.vals[i, 1:]`,
    palm), so that the next solve reads the same gap (the same local centre) and the same
    stretch: the forces carry over. The stick's stretch is a spring as stiff as the gap's
    (k_c both), carried whole whichever way the roll turned the normal; a sliding pad's
    (its limit held, `contacts.friction`) is the friction's tangential variable, tenths of
    a millimetre, carried in the tangent plane of the end's normal: its part along the
    normal would read as gap at the next start, newtons of normal force. sc's chain is
    filled for finger i at x."""
    th, p, R = x
    seg, nrm, anc = body.seg, body.nrm, body.anc
    ctx, vals, KO, RD = sc.ctx, sc.vals, sc.KO, sc.RD
    sphi, cphi, qy, qz = sc.sphi, sc.cphi, sc.qy, sc.qz
    k_n = JOINTS
    r = hand.pad_r[i]
    kind = int(ctx[i, CTX_KIND])
    kfx, kfy, kfz = distal_point(seg, i, k_n, (sphi, cphi, qy, qz),
                                 (hand.pad_xy[i, 0], hand.pad_xy[i, 1], 0.0))
    kx, ky, kz = to_palm(hand, i, kfx, kfy, kfz)
    vx, vy, vz = kx - p[0], ky - p[1], kz - p[2]
    kox = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz
    koy = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
    koz = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
    g, mx, my, mz, _ = _primitive(kind, ctx, i, r, kox, koy, koz, KO)
    npx = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
    npy = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
    npz = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
    zx, zy, zz = vals[i, 1], vals[i, 2], vals[i, 3]
    if math.isfinite(ctx[i, CTX_CAP]):
        zn = zx * npx + zy * npy + zz * npz
        zx, zy, zz = zx - zn * npx, zy - zn * npy, zz - zn * npz
    anc[i, 0] = kox - (g + r) * mx - (R[0, 0] * zx + R[1, 0] * zy + R[2, 0] * zz)
    anc[i, 1] = koy - (g + r) * my - (R[0, 1] * zx + R[1, 1] * zy + R[2, 1] * zz)
    anc[i, 2] = koz - (g + r) * mz - (R[0, 2] * zx + R[1, 2] * zy + R[2, 2] * zz)
    phi = 0.0
    for k in range(k_n):
        phi += th[i, k]
    distal_rotation(hand, i, phi, RD)
    for b in range(3):
        nrm[i, b] = -(RD[0, b] * npx + RD[1, b] * npy + RD[2, b] * npz)

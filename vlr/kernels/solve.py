"""One action per particle (Eq. 9): primal-dual Newton from the stored tangent, and the
batched entry points.

A particle at its equilibrium x0 under commands u0 carries its tangent S = dx*/du and
S_lam = dlambda/du (three back-substitutions at the end of its last solve). An action
u0 -> u1 then:

1. predicts x = x0 + S du and the contacts' forces lambda = lambda0 + S_lam du; the pads'
   friction limit mu lambda_n is held at this predicted normal force;
2. takes full primal-dual Newton steps (`vlr.kernels.contacts`: the constraints' curvature
   weighted by the multipliers, which each step updates to k_c (C + J d)), each step held
   to the step limits; the pads' torsional limit mu_t lambda_n follows the normal force
   from step to step;
3. stops when a step is under the tolerance (taken), or when a step shrank (|d_k| <
   |d_k-1|) and the next one, were the convergence quadratic at the rate the two show,
   would be a tenth of the tolerance (|d_k|^3 / |d_k-1|^2 < tol / 10, taken): no
   evaluation only to confirm. After the prediction, d_k-1 is the prediction's own step,
   whose error is second order in the action as a Newton step's is in its distance;
4. if a step grows instead, or a block is not positive definite, goes on with
   Levenberg-Marquardt damping and an Armijo line search on the energy (the particle is
   near a fold or a stop, or a settle's start far from its equilibrium), each step held to
   a trust radius, the last accepted step's length (three times it after a step taken
   whole);
5. a slipping contact (or a pad spinning past its stick) whose normal force ended more
   than 2% (and 10 mN) off its held limit is solved again from there with the limit
   updated, up to `FRICTION_ROUNDS` times;
6. moves the rolling contacts to where the pads now touch (`contacts.rolled`) and stores
   the new tangent.

A settle (a new hypothesis brought to equilibrium) is the same solve with u1 = u0. A
particle whose solve of an action fails by a jump or no convergence is solved again from
its start in `cfg.follow` equal steps of the action (a large but continuous move is
followed; a jump to another branch still fails); a settle has no such path (`vlr.motion`
sets cfg.follow to 0 for it). "Evaluations" count the energy, gradient and Hessian
evaluations, each with its arrow solve: a Newton-step equivalent.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from vlr.kernels.arrow import factor, solve
from vlr.kernels.chain import distal_point, finger_chain, hand_terms, object_gravity, to_palm
from vlr.kernels.contacts import (
    SPIN_EPS,
    STICK_ZONE,
    carried_spin,
    friction,
    pinned,
    rolled,
    rolling,
    spin,
    spin_angle,
    start_context,
)
from vlr.kernels.records import (
    CTX_CAP,
    CTX_PSI0,
    CTX_SPIN,
    INACTIVE,
    JOINTS,
    JUMP,
    LAM_N,
    LAM_T,
    N_CTX,
    N_LAM,
    NO_CONVERGENCE,
    NONFINITE,
    OK,
    Body,
    Model,
    Pose,
    Scratch,
)


@njit(cache=True)
def make_scratch(n_f, k_n):
    """Per-thread buffers of one particle's solve (allocating per particle would cost
    more than the solve)."""
    nc = k_n + 6
    return Scratch(np.empty((n_f, k_n)), np.empty(6), np.empty((n_f, k_n, k_n)),
                   np.empty((n_f, k_n, 6)), np.empty((6, 6)), np.empty((n_f, k_n, k_n)),
                   np.empty((n_f, k_n, 6)), np.empty((6, 6)), np.empty((k_n, k_n)),
                   np.empty((n_f, k_n)), np.empty((n_f, k_n)), np.empty(6),
                   np.empty(k_n), np.empty(k_n), np.empty(k_n), np.empty(k_n),
                   np.empty((3, nc)), np.empty((3, nc)), np.empty((3, nc)),
                   np.empty((3, nc)), np.empty((3, nc)), np.empty((3, 3)), np.empty((3, 3)),
                   np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((n_f, 4)),
                   np.empty((n_f, 4, nc)), np.empty((n_f, N_LAM)),
                   np.empty((n_f, N_LAM)), np.empty((n_f, N_CTX)),
                   np.empty((n_f, k_n)), np.empty(3), np.empty((3, 3)), np.empty((3, 3)),
                   np.empty((n_f, k_n)), np.empty(3), np.empty((n_f, k_n)),
                   np.empty((n_f, 3)), np.empty((n_f, 3)), np.empty(3), np.empty((3, 3)),
                   np.empty(n_f), np.empty(n_f), np.empty(n_f), np.empty(n_f))


# Rounds of the cone's active set after the first solve (`solve_one`).
FRICTION_ROUNDS = 3
# A contact pressing less than this [N] keeps stuck: the grasp's contacts never let go
# (Eq. 8), and one held by no friction would leave the object free to spin on it.
MIN_PRESS = 0.05


@njit(cache=True, inline="always", _nrt=False)
def rotate(R, w0, w1, w2, out):
    """out = R exp([w]x) (Rodrigues)."""
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
def evaluate(x, body, hand, cfg, sc):
    """Energy of one particle at x = (th, p, R) under the commands sc.u_b (Eq. 6, 7, 8, the
    stops and gravity); its gradient and Hessian into sc's arrow blocks, the contacts'
    constraints into sc.vals, sc.jac. The rolling contacts read sc.ctx (their start) and
    sc.R0."""
    th, seg = x.th, body.seg
    n_f = th.shape[0]
    sc.gA[:] = 0.0
    sc.gC[:] = 0.0
    sc.A[:] = 0.0
    sc.B[:] = 0.0
    sc.C[:] = 0.0
    e = 0.0
    for i in range(n_f):
        finger_chain(th, seg, i, JOINTS, sc.sphi, sc.cphi, sc.qy, sc.qz)
        e += hand_terms(th, body, hand, cfg, i, sc)
        if cfg.contacts:
            if cfg.rolling:
                e += rolling(x, body, hand, cfg, i, sc)
                if cfg.spin > 0.0:
                    e += spin(x, hand, i, sc)
            else:
                e += pinned(x, body, hand, cfg, i, sc)
    if cfg.object_gravity:
        e += object_gravity(x.p, x.R, body.mass, body.com, hand, sc.gC, sc.C)
    return e


@njit(cache=True, _nrt=False)
def _start(x, body, hand, srf, cfg, sc):
    """The solve's start x0 = x saved, each contact's context and its multipliers there."""
    th, p, R = x
    n_f, k_n = th.shape[0], JOINTS
    for i in range(n_f):
        for k in range(k_n):
            sc.th0[i, k] = th[i, k]
    for a in range(3):
        sc.p0[a] = p[a]
        for b in range(3):
            sc.R0[a, b] = R[a, b]
    if not cfg.contacts:
        return
    for i in range(n_f):
        finger_chain(th, body.seg, i, JOINTS, sc.sphi, sc.cphi, sc.qy, sc.qz)
        if cfg.rolling:
            start_context(x, body, hand, srf, cfg, i, sc)
        else:
            _pinned_offset(x, body, hand, cfg, i, sc)
    for i in range(n_f):
        for a in range(N_LAM):
            sc.lam0[i, a] = sc.lam[i, a]


@njit(cache=True, _nrt=False)
def _pinned_offset(x, body, hand, cfg, i, sc):
    """The pinned contact i's force at x0 = x, k_c (x_D - (p + R a)), into sc.lam."""
    th, p, R = x
    seg, nrm, anc = body.seg, body.nrm, body.anc
    r = hand.pad_r[i]
    fx, fy, fz = distal_point(seg, i, JOINTS, (sc.sphi, sc.cphi, sc.qy, sc.qz),
                              (hand.pad_xy[i, 0] + r * nrm[i, 0],
                               hand.pad_xy[i, 1] + r * nrm[i, 1], r * nrm[i, 2]))
    xx, xy, xz = to_palm(hand, i, fx, fy, fz)
    x = (xx, xy, xz)
    sc.lam[i, LAM_N] = 0.0
    for a in range(3):
        sc.lam[i, LAM_T + a] = cfg.kc * (x[a] - p[a] - (R[a, 0] * anc[i, 0]
                                                         + R[a, 1] * anc[i, 1]
                                                         + R[a, 2] * anc[i, 2]))


@njit(cache=True, _nrt=False)
def _predict(x, tangent, cfg, sc):
    """x = x0 + S du, lambda = lambda0 + S_lam du (the stored tangent, du = sc.du);
    returns the step's size in tolerance units (inf: no tangent yet, all zeros)."""
    th, p, R = x
    du = sc.du
    n_f, k_n = th.shape[0], JOINTS
    n_x = n_f * k_n + 6
    big_th = 0.0
    for i in range(n_f):
        for k in range(k_n):
            t = 0.0
            for c in range(n_f):
                t += tangent[i * k_n + k, c] * du[c]
            th[i, k] += t
            big_th = max(big_th, abs(t))
    d = sc.dc  # the object's predicted step
    for a in range(6):
        t = 0.0
        for c in range(n_f):
            t += tangent[n_f * k_n + a, c] * du[c]
        d[a] = t
    for a in range(3):
        p[a] += d[a]
    rotate(R, d[3], d[4], d[5], sc.Rt)
    for a in range(3):
        for b in range(3):
            R[a, b] = sc.Rt[a, b]
    for i in range(n_f):
        for a in range(N_LAM):
            t = 0.0
            for c in range(n_f):
                t += tangent[n_x + i * N_LAM + a, c] * du[c]
            sc.lam[i, a] += t
    size = max(big_th / cfg.tol_theta,
               math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / cfg.tol_pos,
               math.sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5]) / cfg.tol_theta)
    return size if size > 0.0 else math.inf


@njit(cache=True, _nrt=False)
def _hold_friction(cfg, sc, n_f):
    """The pads' friction limit (CTX_CAP) for the solve: a contact whose predicted
    tangential force is inside its cone starts stuck (no limit, inf); one outside it slides
    with the limit held at its predicted normal force, the tangential multiplier projected
    into the cone."""
    for i in range(n_f):
        lam_n = max(0.0, -sc.lam[i, LAM_N])
        sc.ctx[i, CTX_SPIN] = cfg.spin * lam_n
        lt = math.sqrt(sc.lam[i, LAM_T] ** 2 + sc.lam[i, LAM_T + 1] ** 2
                       + sc.lam[i, LAM_T + 2] ** 2)
        if not math.isfinite(cfg.friction) or lt <= cfg.friction * lam_n or lam_n < MIN_PRESS:
            sc.ctx[i, CTX_CAP] = math.inf
        else:
            sc.ctx[i, CTX_CAP] = lam_n
            _friction_force(sc.lam, i, cfg.kc, cfg.friction, lam_n, sc.KO)


@njit(cache=True, inline="always", _nrt=False)
def _friction_force(lam, i, kc, mu, lam_n, G):
    """The tangential multiplier k_c z (the stick's) made the friction's force at z
    (`contacts.friction`), in place."""
    _, fx, fy, fz = friction(lam[i, LAM_T] / kc, lam[i, LAM_T + 1] / kc,
                             lam[i, LAM_T + 2] / kc, kc, mu, lam_n, G)
    lam[i, LAM_T], lam[i, LAM_T + 1], lam[i, LAM_T + 2] = fx, fy, fz


@njit(cache=True, inline="always", _nrt=False)
def _step_size(sc, cfg, n_f, k_n):
    """The step's size in tolerance units: max(|dtheta|_inf / tol_theta, |dp| / tol_pos,
    |dw| / tol_theta); and its scale to the step limits (1: within them)."""
    big_th = 0.0
    for i in range(n_f):
        for k in range(k_n):
            big_th = max(big_th, abs(sc.dth[i, k]))
    dc = sc.dc
    big_p = math.sqrt(dc[0] * dc[0] + dc[1] * dc[1] + dc[2] * dc[2])
    big_w = math.sqrt(dc[3] * dc[3] + dc[4] * dc[4] + dc[5] * dc[5])
    size = max(big_th / cfg.tol_theta, big_p / cfg.tol_pos, big_w / cfg.tol_theta)
    t = 1.0
    if big_th > cfg.max_step_theta:
        t = min(t, cfg.max_step_theta / big_th)
    if big_w > cfg.max_step_theta:
        t = min(t, cfg.max_step_theta / big_w)
    if big_p > cfg.max_step_pos:
        t = min(t, cfg.max_step_pos / big_p)
    return size, t


@njit(cache=True, inline="always", _nrt=False)
def _take(x, sc, t):
    """x <- x + t d (the rotation by R exp([t dw]x))."""
    th, p, R = x
    n_f, k_n = th.shape[0], JOINTS
    for i in range(n_f):
        for k in range(k_n):
            th[i, k] += t * sc.dth[i, k]
    for a in range(3):
        p[a] += t * sc.dc[a]
    rotate(R, t * sc.dc[3], t * sc.dc[4], t * sc.dc[5], sc.Rt)
    for a in range(3):
        for b in range(3):
            R[a, b] = sc.Rt[a, b]


@njit(cache=True, inline="always", _nrt=False)
def _update_multipliers(cfg, sc, t, n_f, k_n):
    """lambda <- k_c (C + J t d) per contact (the tangential one into its cone)."""
    if not cfg.contacts:
        return
    nc = k_n + 6
    for i in range(n_f):
        for a in range(4):
            jd = 0.0
            for c in range(nc):
                dv = sc.dth[i, c] if c < k_n else sc.dc[c - k_n]
                jd += sc.jac[i, a, c] * dv
            sc.lam[i, a] = cfg.kc * (sc.vals[i, a] + t * jd)
        if cfg.rolling and math.isfinite(cfg.friction):
            _friction_force(sc.lam, i, cfg.kc, cfg.friction, sc.ctx[i, CTX_CAP], sc.KO)


@njit(cache=True, _nrt=False)
def _energy_at(x, t, body, hand, cfg, sc):
    """The energy (with its derivatives, into sc) at x + t d, the trial in sc.tht/pt/Rt."""
    th, p, R = x
    n_f, k_n = th.shape[0], JOINTS
    for i in range(n_f):
        for k in range(k_n):
            sc.tht[i, k] = th[i, k] + t * sc.dth[i, k]
    for a in range(3):
        sc.pt[a] = p[a] + t * sc.dc[a]
    rotate(R, t * sc.dc[3], t * sc.dc[4], t * sc.dc[5], sc.Rt)
    return evaluate(Pose(sc.tht, sc.pt, sc.Rt), body, hand, cfg, sc)


@njit(cache=True, inline="always", _nrt=False)
def _ran_away(x, cfg, sc):
    """The iterate left the jump limits (`solve_one`'s JUMP) from the solve's start. With
    the pads sliding, a hypothesis whose pads cannot hold the object slides away: stopped
    here, not after the rest of its evaluations (docs/DECISIONS.md, the pads' sliding)."""
    th, p, _ = x
    for i in range(th.shape[0]):
        for k in range(JOINTS):
            if abs(th[i, k] - sc.th0[i, k]) > cfg.jump_theta:
                return True
    dp = (p[0] - sc.p0[0]) ** 2 + (p[1] - sc.p0[1]) ** 2 + (p[2] - sc.p0[2]) ** 2
    return dp > cfg.jump_pos * cfg.jump_pos


@njit(cache=True, _nrt=False)
def newton(x, body, hand, cfg, sc, max_iter, prev):
    """Primal-dual Newton from the current x = (th, p, R) at the commands sc.u_b (module
    docstring, steps 2-4), in place; returns (converged, evaluations). sc.lam holds the
    multipliers to start from; `prev` is the size of the step that led here (the
    predictor's, in tolerance units; inf: none). The last factorisation is left in sc (for
    the tangent)."""
    th, p, R = x
    n_f, k_n = th.shape[0], JOINTS
    damped = False
    mu = cfg.mu0
    # The damped steps' trust radius (tolerance units): the last accepted step's length,
    # grown where a step was accepted whole, so that a line search does not start every
    # step at the step limit and spend an evaluation on the trial it rejects.
    radius = math.inf
    evals = 0
    e = evaluate(x, body, hand, cfg, sc)
    evals += 1
    while evals <= max_iter:
        if not math.isfinite(e):
            return False, evals
        if not damped:
            if not factor(sc.A, sc.B, sc.C, 0.0, sc.Ainv, sc.X, sc.S, sc.La):
                damped = True
        if damped:
            while not factor(sc.A, sc.B, sc.C, mu, sc.Ainv, sc.X, sc.S, sc.La):
                mu *= 10.0
                if mu > 1e12:
                    return False, evals
        solve(sc.gA, sc.gC, sc.B, (sc.Ainv, sc.X, sc.S), sc.dth, sc.dc, sc.y)
        size, t = _step_size(sc, cfg, n_f, k_n)
        if not math.isfinite(size):
            return False, evals
        if not damped and size > 2.0 * prev:
            # The steps grow: not in Newton's basin (a fold, a stop engaging).
            damped = True
            continue
        if size * t <= 1.0:
            _update_multipliers(cfg, sc, t, n_f, k_n)
            _take(x, sc, t)
            return True, evals
        if not damped:
            _update_multipliers(cfg, sc, t, n_f, k_n)
            _take(x, sc, t)
            if (t == 1.0 and prev < math.inf and size < prev
                    and size ** 3 < 0.1 * prev * prev):
                return True, evals
            prev = size
            if math.isfinite(cfg.friction) and _ran_away(x, cfg, sc):
                return False, evals
            if cfg.spin > 0.0:
                # The pads' torsional limit follows the normal force from step to step
                # (a lagged fixed point), so that the solve ends where the two agree.
                for i in range(n_f):
                    sc.ctx[i, CTX_SPIN] = cfg.spin * max(0.0, -sc.lam[i, LAM_N])
            e = evaluate(x, body, hand, cfg, sc)
            evals += 1
            continue
        # Damped: Levenberg-Marquardt with an Armijo line search on the energy.
        if size * t > radius:
            t = radius / size
        t_first = t
        gd = 0.0
        for i in range(n_f):
            for k in range(k_n):
                gd += sc.gA[i, k] * sc.dth[i, k]
        for a in range(6):
            gd += sc.gC[a] * sc.dc[a]
        _update_multipliers(cfg, sc, t, n_f, k_n)
        accepted = False
        e_t = e
        tol_e = 1e-15 + 1e-13 * abs(e)
        for _ls in range(8):
            e_t = _energy_at(x, t, body, hand, cfg, sc)
            evals += 1
            if math.isfinite(e_t) and e_t <= e + 1e-4 * t * gd + tol_e:
                accepted = True
                break
            denom = 2.0 * (e_t - e - gd * t)
            t_new = 0.5 * t
            if math.isfinite(e_t) and denom > 0.0:
                t_new = -gd * t * t / denom
            t = min(max(t_new, 0.1 * t), 0.5 * t)
            if evals > max_iter:
                break
        if accepted:
            for i in range(n_f):
                for k in range(k_n):
                    th[i, k] = sc.tht[i, k]
            for a in range(3):
                p[a] = sc.pt[a]
                for b in range(3):
                    R[a, b] = sc.Rt[a, b]
            e = e_t
            if math.isfinite(cfg.friction) and _ran_away(x, cfg, sc):
                return False, evals
            if t == 1.0:
                mu = max(mu * 0.1, 1e-12)
            if size * t <= 1.0:
                return True, evals
            prev = size * t
            radius = 3.0 * size * t if t == t_first else size * t
        else:
            radius = min(radius, size * t)
            mu *= 10.0
            if mu > 1e12:
                return False, evals
            e = evaluate(x, body, hand, cfg, sc)
            evals += 1
    return False, evals


@njit(cache=True, _nrt=False)
def _store_tangent(x, body, tangent, hand, cfg, sc):
    """The equilibrium's tangent from the last factorisation: H dx/du_c = d(-grad)/du_c,
    nonzero on finger c's joints where its tendon is taut (k_t r_ck), and the multipliers'
    dlambda/du = k_c J dx/du (a sliding contact's tangential force follows its normal
    force along its direction)."""
    th, kt = x.th, body.kt
    n_f, k_n = th.shape[0], JOINTS
    n_x = n_f * k_n + 6
    nc = k_n + 6
    for c in range(n_f):
        sc.gA[:] = 0.0
        sc.gC[:] = 0.0
        s = 0.0
        for k in range(k_n):
            s += hand.radii[c, k] * (th[c, k] - hand.lo[c, k])
        if cfg.tendon and sc.u_b[c] - s > 0.0:
            for k in range(k_n):
                sc.gA[c, k] = -kt[c] * hand.radii[c, k]
        solve(sc.gA, sc.gC, sc.B, (sc.Ainv, sc.X, sc.S), sc.dth, sc.dc, sc.y)
        for i in range(n_f):
            for k in range(k_n):
                tangent[i * k_n + k, c] = sc.dth[i, k]
        for a in range(6):
            tangent[n_f * k_n + a, c] = sc.dc[a]
        for i in range(n_f):
            for a in range(4):
                jd = 0.0
                if cfg.contacts:
                    for col in range(nc):
                        dv = sc.dth[i, col] if col < k_n else sc.dc[col - k_n]
                        jd += sc.jac[i, a, col] * dv
                tangent[n_x + i * 4 + a, c] = cfg.kc * jd
            if cfg.contacts and cfg.rolling and math.isfinite(cfg.friction):
                # the friction's force moves as its Hessian says: G J_z dx/du
                friction(sc.vals[i, 1], sc.vals[i, 2], sc.vals[i, 3], cfg.kc, cfg.friction,
                         sc.ctx[i, CTX_CAP], sc.KO)
                jz0 = tangent[n_x + i * 4 + LAM_T, c] / cfg.kc
                jz1 = tangent[n_x + i * 4 + LAM_T + 1, c] / cfg.kc
                jz2 = tangent[n_x + i * 4 + LAM_T + 2, c] / cfg.kc
                for a in range(3):
                    tangent[n_x + i * 4 + LAM_T + a, c] = (sc.KO[a, 0] * jz0 + sc.KO[a, 1] * jz1
                                                           + sc.KO[a, 2] * jz2)


@njit(cache=True, _nrt=False)
def solve_one(q, ps, model, u0, u1, predict, max_iter, sc):
    """Particle q from its equilibrium at u0 to its equilibrium at u1 (the module
    docstring's steps 1-6), in place; returns (status, evaluations)."""
    hand, cfg = model.hand, model.cfg
    x, body = _views(q, ps)
    th, p, R = x
    tangent = ps.tangent[q]
    n_f, k_n = th.shape[0], JOINTS
    _start(x, body, hand, model.surface, cfg, sc)
    if cfg.spin > 0.0:
        for i in range(n_f):
            sc.ctx[i, CTX_PSI0] = ps.spin[q, i]
    for c in range(n_f):
        sc.du[c] = u1[c] - u0[c]
        sc.u_b[c] = u1[c]
    prev = math.inf
    if predict:
        prev = _predict(x, tangent, cfg, sc)
        if math.isfinite(cfg.friction) and _ran_away(x, cfg, sc):
            # A slide's stored tangent (its sensitivity large) extrapolates past the jump
            # limits: the solve starts from x0 instead.
            for i in range(n_f):
                for k in range(k_n):
                    th[i, k] = sc.th0[i, k]
                for a in range(N_LAM):
                    sc.lam[i, a] = sc.lam0[i, a]
            for a in range(3):
                p[a] = sc.p0[a]
                for b in range(3):
                    R[a, b] = sc.R0[a, b]
            prev = math.inf
    rolling_friction = cfg.contacts and cfg.rolling
    if rolling_friction:
        _hold_friction(cfg, sc, n_f)
    ok, evals = newton(x, body, hand, cfg, sc, max_iter, prev)
    if rolling_friction and (math.isfinite(cfg.friction) or cfg.spin > 0.0):
        # Active set of the cone: a stuck contact whose force left its cone slides from
        # here, with the limit at its normal force; a sliding one (or a spinning pad) whose
        # normal force ended far from the limit held is solved again with the limit where
        # it ended, so that the solve's limits are its end's, whatever its start.
        for _round in range(FRICTION_ROUNDS):
            if not ok:
                break
            again = False
            if cfg.spin > 0.0:
                for i in range(n_f):
                    held = sc.ctx[i, CTX_SPIN] / cfg.spin
                    lam_n = max(0.0, -sc.lam[i, LAM_N])
                    if (abs(spin_angle(th, R, sc.R0, hand, i, sc.ctx)) > SPIN_EPS
                            and abs(lam_n - held) > 0.02 * held + 0.01):
                        again = True
                        sc.ctx[i, CTX_SPIN] = cfg.spin * lam_n
            for i in range(n_f):
                if not math.isfinite(cfg.friction):
                    break
                held = sc.ctx[i, CTX_CAP]
                lam_n = max(0.0, -sc.lam[i, LAM_N])
                lt = math.sqrt(sc.lam[i, LAM_T] ** 2 + sc.lam[i, LAM_T + 1] ** 2
                               + sc.lam[i, LAM_T + 2] ** 2)
                if not math.isfinite(held):
                    if lam_n >= MIN_PRESS and lt > cfg.friction * lam_n * (1.0 + 1e-3) + 1e-3:
                        again = True
                        sc.ctx[i, CTX_CAP] = lam_n
                elif (lt > 0.7 * cfg.friction * held
                      and abs(lam_n - held) > 0.02 * held + 0.01):
                    again = True
                    sc.ctx[i, CTX_CAP] = lam_n
            if not again:
                break
            for i in range(n_f):
                if math.isfinite(cfg.friction) and math.isfinite(sc.ctx[i, CTX_CAP]):
                    _friction_force(sc.lam, i, cfg.kc, cfg.friction, sc.ctx[i, CTX_CAP],
                                    sc.KO)
            ok, more = newton(x, body, hand, cfg, sc, max_iter, math.inf)
            evals += more
    big = 0.0
    for i in range(n_f):
        for k in range(k_n):
            big = max(big, abs(th[i, k] - sc.th0[i, k]))
    dp = math.sqrt((p[0] - sc.p0[0]) ** 2 + (p[1] - sc.p0[1]) ** 2 + (p[2] - sc.p0[2]) ** 2)
    if not (math.isfinite(big) and math.isfinite(dp)):
        return NONFINITE, evals
    if not ok:
        return NO_CONVERGENCE, evals
    if big > cfg.jump_theta or dp > cfg.jump_pos:
        return JUMP, evals
    _store_tangent(x, body, tangent, hand, cfg, sc)
    if rolling_friction and cfg.spin > 0.0:
        for i in range(n_f):
            ps.spin[q, i] = carried_spin(th, R, sc.R0, hand, i, sc.ctx)
    if rolling_friction:
        # The stretch each anchor carries on: the elastic part, the one whose force is the
        # contact's force now (`contacts.friction` inverted; the stick's lambda / k_c).
        for i in range(n_f):
            _carried_stretch(sc, i, cfg)
            finger_chain(th, body.seg, i, JOINTS, sc.sphi, sc.cphi, sc.qy, sc.qz)
            rolled(x, body, hand, i, sc)
    return OK, evals


@njit(cache=True, inline="always", _nrt=False)
def _views(q, ps):
    """Particle q's iterate and what its Newton steps hold fixed, as views of ps."""
    return (Pose(ps.theta[q], ps.pos[q], ps.rot[q]),
            Body(ps.seg[q], ps.nrm[q], ps.anc[q], ps.stiff[q], ps.kt[q], ps.mass[q],
                 ps.com[q], ps.rho[q]))


@njit(cache=True, _nrt=False)
def _carried_stretch(sc, i, cfg):
    """sc.vals[i, 1:] = the stretch z whose force (`contacts.friction`, the limit held at
    sc.ctx's normal force) is the tangential multiplier: lambda / k_c for the stick alone,
    else lambda eps / sqrt(cap^2 - |lambda|^2) (a force on the cone kept just inside it)."""
    kc = cfg.kc
    lx, ly, lz = sc.lam[i, LAM_T], sc.lam[i, LAM_T + 1], sc.lam[i, LAM_T + 2]
    f = 1.0 / kc
    if math.isfinite(cfg.friction) and math.isfinite(sc.ctx[i, CTX_CAP]):
        cap = cfg.friction * sc.ctx[i, CTX_CAP]
        if cap > 1e-9:
            eps = max(cap / kc, STICK_ZONE)
            l2 = min(lx * lx + ly * ly + lz * lz, (cap * (1.0 - 1e-6)) ** 2)
            f = eps / math.sqrt(cap * cap - l2)
        else:
            f = 0.0
    sc.vals[i, 1], sc.vals[i, 2], sc.vals[i, 3] = f * lx, f * ly, f * lz


@njit(cache=True, _nrt=False)
def _save(q, ps, sc):
    th, nrm, anc, p, R = ps.theta[q], ps.nrm[q], ps.anc[q], ps.pos[q], ps.rot[q]
    n_f, k_n = th.shape[0], JOINTS
    for i in range(n_f):
        for k in range(k_n):
            sc.th_s[i, k] = th[i, k]
        for a in range(3):
            sc.nrm_s[i, a] = nrm[i, a]
            sc.anc_s[i, a] = anc[i, a]
    for a in range(3):
        sc.p_s[a] = p[a]
        for b in range(3):
            sc.R_s[a, b] = R[a, b]


@njit(cache=True, _nrt=False)
def _restore(q, ps, sc):
    th, nrm, anc, p, R = ps.theta[q], ps.nrm[q], ps.anc[q], ps.pos[q], ps.rot[q]
    n_f, k_n = th.shape[0], JOINTS
    for i in range(n_f):
        for k in range(k_n):
            th[i, k] = sc.th_s[i, k]
        for a in range(3):
            nrm[i, a] = sc.nrm_s[i, a]
            anc[i, a] = sc.anc_s[i, a]
    for a in range(3):
        p[a] = sc.p_s[a]
        for b in range(3):
            R[a, b] = sc.R_s[a, b]


@njit(cache=True, _nrt=False)
def solve_path(q, ps, model, u0, u1, predict, sc):
    """`solve_one`, and on a jump or no convergence the follow-up from the start in
    cfg.follow equal steps at twice the iterations. Returns (status (the first attempt's
    if the follow-up fails too), evaluations, followed)."""
    follow = model.cfg.follow
    if follow > 1:
        _save(q, ps, sc)
    st, evals = solve_one(q, ps, model, u0, u1, predict, model.cfg.max_iter, sc)
    if follow <= 1 or not (st == JUMP or st == NO_CONVERGENCE):
        return st, evals, False
    if math.isfinite(model.cfg.friction):
        # With the pads sliding a failed action is a slide running away, which a finer
        # path does not hold either (at 6,000 particles the follow-ups took 40% of the
        # action's evaluations).
        return st, evals, False
    _restore(q, ps, sc)
    n_f = u0.shape[0]
    for j in range(1, follow + 1):
        for c in range(n_f):
            sc.u_from[c] = u0[c] + (u1[c] - u0[c]) * ((j - 1) / follow)
            sc.u_to[c] = u0[c] + (u1[c] - u0[c]) * (j / follow)
        st2, more = solve_one(q, ps, model, sc.u_from, sc.u_to, predict,
                              2 * model.cfg.max_iter, sc)
        evals += more
        if st2 != OK:
            return st, evals, True
    return OK, evals, True


@njit(parallel=True, cache=True)
def solve_batch(ps, hand, srf, cfg, u0, u1, predict, out):
    """Every valid particle from its equilibrium at u0 to its equilibrium at u1
    (`solve_path`), in place: the state, ps.valid (False after a failure) and `out`
    (`records.Outcome`: each particle's status, evaluations and whether the follow-up was
    tried). The hand, surface and settings come apart: a record of records does not pass
    into a prange body (numba 0.68), its parts do."""
    n_p, n_f = ps.theta.shape[0], ps.theta.shape[1]
    k_n = JOINTS
    n_chunks = min(n_p, 64)
    # A write into a record's array in a prange body is lost (numba 0.68: the parfor
    # copies the attribute); through a name of its own it is not.
    valid = ps.valid
    status, evals, followed = out.status, out.evals, out.followed
    for ch in prange(n_chunks):
        model = Model(hand, srf, cfg)
        sc = make_scratch(n_f, k_n)
        for q in range(ch * n_p // n_chunks, (ch + 1) * n_p // n_chunks):
            followed[q] = False
            if not valid[q]:
                status[q] = INACTIVE
                evals[q] = 0
                continue
            st, ev, fo = solve_path(q, ps, model, u0, u1, predict, sc)
            status[q] = st
            evals[q] = ev
            followed[q] = fo
            valid[q] = st == OK


@njit(cache=True)
def evaluate_at(q, ps, model, x, u, lam):
    """Particle q's energy at x = (th, p, R) under the commands u, from its start (its own
    state, x0); returns (energy, the scratch: its gradient and Hessian blocks gA, gC, A, B,
    C, its contacts' constraints and rows vals, jac). lam (N, N_LAM): the multipliers the
    Hessian's curvature terms weigh; NaN: the start's. The pads' friction limit is held at
    the start's normal force. For tests and diagnostics."""
    hand, cfg = model.hand, model.cfg
    n_f, k_n = x.th.shape[0], JOINTS
    sc = make_scratch(n_f, k_n)
    x0, body = _views(q, ps)
    _start(x0, body, hand, model.surface, cfg, sc)
    if cfg.contacts and cfg.rolling:
        _hold_friction(cfg, sc, n_f)
        for i in range(n_f):
            sc.ctx[i, CTX_PSI0] = ps.spin[q, i]
    for i in range(n_f):
        for a in range(N_LAM):
            if not math.isnan(lam[i, a]):
                sc.lam[i, a] = lam[i, a]
    for c in range(n_f):
        sc.u_b[c] = u[c]
    return evaluate(x, body, hand, cfg, sc), sc


@njit(parallel=True, cache=True)
def evaluate_batch(ps, hand, srf, cfg, u, energy):
    """Every particle's energy, gradient and Hessian at its own state (energies into
    `energy`): one Newton step's evaluation, for `vlr bench --profile`."""
    n_p, n_f = ps.theta.shape[0], ps.theta.shape[1]
    k_n = JOINTS
    n_chunks = min(n_p, 64)
    for ch in prange(n_chunks):
        sc = make_scratch(n_f, k_n)
        for c in range(n_f):
            sc.u_b[c] = u[c]
        for q in range(ch * n_p // n_chunks, (ch + 1) * n_p // n_chunks):
            energy[q] = _evaluate_own(q, ps, Model(hand, srf, cfg), sc)


@njit(cache=True, _nrt=False)
def _evaluate_own(q, ps, model, sc):
    """Particle q's energy (its derivatives into sc) at its own state, its solve's start."""
    x, body = _views(q, ps)
    _start(x, body, model.hand, model.surface, model.cfg, sc)
    return evaluate(x, body, model.hand, model.cfg, sc)

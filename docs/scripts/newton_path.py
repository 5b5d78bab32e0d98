"""Where the motion model's Newton iterations go (docs/RESULTS.md, section 3).

A one-off diagnostic, not part of the package: a 2,000-particle filter on the synthetic world
(seed 0) takes five actions; then one more action is solved for every particle, first by the
numba kernel (`MotionModel.solve`, iterations per particle and the error left after k
iterations), then by a plain-NumPy replica of the same damped Newton (same damping, step limits
and line search) on 150 particles, which logs what each iteration did: a failed Cholesky
factorisation (an indefinite Hessian: the damping goes up tenfold), an accepted step, a step
cut by the line search. Last, the median Newton iterations per action over 12 filter
iterations (3,000 particles) at the default convergence tolerance and at a looser one.

    MUJOCO_GL=egl python docs/scripts/newton_path.py
"""

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel
from vlr.motion import ObjectParams
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action


def main() -> None:
    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0, snap_theta=np.pi))
    u = world.grasp()
    pf = ParticleFilter(model, obj, FilterConfig(n_particles=2000, seed=0))
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(1)
    for _ in range(5):
        u = world.apply(random_action(rng, 3))
        pf.step(u, world.observe())
    u_new = u + random_action(rng, 3)
    base = pf.state.copy()
    cfg = pf.config.motion
    ref = base.copy()
    status, iters = pf.motion.solve(ref, u_new, replace(cfg, max_iter=200, follow_substeps=0))
    ok = status == 0
    move = np.degrees(np.abs(ref.theta - base.theta).max(axis=(1, 2)))[ok]
    print(f"kernel: Newton iterations per solve, median {np.median(iters[ok]):.0f} "
          f"(10-90%: {np.percentile(iters[ok], 10):.0f}-{np.percentile(iters[ok], 90):.0f}); "
          f"largest joint move, median {np.median(move):.1f} deg")
    for k in (1, 2, 4, 6, 8, 10, 14, 20):
        s = base.copy()
        pf.motion.solve(s, u_new, replace(cfg, max_iter=k, tol_theta=1e-30, tol_pos=1e-30,
                                          follow_substeps=0))
        d = np.degrees(np.abs(s.theta - ref.theta).max(axis=(1, 2)))[ok]
        print(f"  after {k:2d} iterations: error left, median {np.median(d):.2e} deg")

    stats = []
    for q in np.flatnonzero(ok)[:150]:
        stats.append(replica(pf.motion, base.copy(), q, u_new, cfg))
    failed, accepted, cut, indefinite = np.median(np.array(stats), axis=0)
    print(f"replica, per solve (median): failed factorisations {failed:.0f}, accepted steps "
          f"{accepted:.0f}, steps cut by the line search {cut:.0f}, steps on an indefinite "
          f"Hessian {indefinite:.0f}")
    share = np.mean(np.array(stats)[:, 3] > 0)
    print(f"particles whose path meets an indefinite Hessian: {share:.2f}")
    for tol in ((cfg.tol_theta, cfg.tol_pos), (1e-4, 1e-6)):
        its = tolerance_run(model, obj, replace(cfg, tol_theta=tol[0], tol_pos=tol[1]))
        print(f"tolerance {tol[0]:.0e} rad / {tol[1]:.0e} m: median Newton iterations per "
              f"action over 12 filter iterations, {its:.1f}")


def tolerance_run(model, obj, motion_cfg) -> float:
    """Median (over iterations) of the median action iterations, 3,000 particles."""
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0, snap_theta=np.pi))
    u = world.grasp()
    pf = ParticleFilter(model, obj, FilterConfig(n_particles=3000, seed=0, motion=motion_cfg))
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(1)
    its = []
    for _ in range(12):
        u = world.apply(random_action(rng, 3))
        pf.step(u, world.observe())
        its.append(pf.newton_iterations["action"])
    return float(np.median(its))


def replica(motion, s, q: int, u, cfg) -> tuple[int, int, int, int]:
    """The kernel's damped Newton for particle q (`vlr._energy_kernels._solve_one`), in NumPy
    on the dense Hessian, counting what happens."""
    th, p, rot = s.theta[q].copy(), s.pos[q].copy(), s.rot[q].copy()
    n = th.size
    mu = cfg.mu0
    failed = accepted = cut = indefinite = 0
    for _ in range(60):
        s.theta[q], s.pos[q], s.rot[q] = th, p, rot
        e, g, h = motion.evaluate(s, q, u)
        damped = h + mu * np.diag(np.abs(np.diag(h)) + 1e-9)
        try:
            np.linalg.cholesky(damped)
        except np.linalg.LinAlgError:
            failed += 1
            mu *= 10
            continue
        indefinite += np.linalg.eigvalsh(h)[0] < 0
        d = -np.linalg.solve(damped, g)
        dth, dp, dw = d[:n], d[n:n + 3], d[n + 3:]
        big_th, big_p, big_w = np.abs(dth).max(), np.linalg.norm(dp), np.linalg.norm(dw)
        t = min(1.0, cfg.max_step_theta / max(big_th, 1e-300),
                cfg.max_step_theta / max(big_w, 1e-300), cfg.max_step_pos / max(big_p, 1e-300))
        gd = g @ d
        for _ls in range(8):
            s.theta[q] = th + t * dth.reshape(th.shape)
            s.pos[q] = p + t * dp
            s.rot[q] = rot @ Rotation.from_rotvec(t * dw).as_matrix()
            e_t = motion.evaluate(s, q, u)[0]
            if e_t <= e + 1e-4 * t * gd + 1e-15 + 1e-13 * abs(e):
                break
            denom = 2 * (e_t - e - gd * t)
            t_new = -gd * t * t / denom if denom > 0 else 0.5 * t
            t = min(max(t_new, 0.1 * t), 0.5 * t)
        else:
            mu *= 10
            continue
        accepted += 1
        cut += t < 1
        th, p, rot = s.theta[q].copy(), s.pos[q].copy(), s.rot[q].copy()
        if t == 1.0:
            mu = max(mu * 0.1, 1e-12)
        if t * big_th < cfg.tol_theta and t * big_p < cfg.tol_pos:
            break
    return failed, accepted, cut, indefinite


if __name__ == "__main__":
    main()

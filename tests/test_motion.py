"""Motion model (Eq. 6-9): the kernels' energy, gradient and Hessian against a plain NumPy
reference, stationarity, one solve per action against its many-step limit, the stored
tangent, the pads' friction, observability, tendon slack, invalid solves."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from vlr.kernels.reference import reference_energy
from vlr.kinematics import Chain, HandModel, normals_from_angles, plane_rotation
from vlr.motion import (
    MotionConfig,
    MotionModel,
    ObjectParams,
    ParticleState,
    rotvec_to_matrix,
)
from vlr.spec import load_hand
from vlr.surface import LocalSurface

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
# The pinned-contact model (Eq. 8 as a penalty), and the rolling one (the default).
PIN = MotionConfig(rolling=False)
ROLL = MotionConfig()
THETA0 = (-0.3, 1.2)


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def grasp(model: HandModel, n: int = 1, tension: float = 5.0, theta=THETA0,
          config: MotionConfig | None = None, stiffness=None):
    """Settled grasp of n identical particles at u_0 = s(theta) + T/k_t, by default with
    pinned contacts."""
    config = config or PIN
    nf = model.n_fingers
    th = np.tile(np.asarray(theta, dtype=float), (nf, 1))
    normals = normals_from_angles(np.zeros(nf), np.zeros(nf))
    st = ParticleState.nominal(model, 1, th, normals, np.zeros(3), np.eye(3))
    if stiffness is not None:
        st.stiffness[...] = stiffness
    st.pos[0] = st.contacts(model)[0].mean(0) - [0.0, 0.0, 0.03]
    st.anchor_to_pose(model)
    u0 = model.tendon_takeup(th) + tension / model.tendon_stiffness
    mm = MotionModel(model, OBJ, config)
    settle = replace(config, max_iter=500, jump_theta=math.pi, jump_pos=1.0)
    status, _ = mm.solve(st, u0, settle)
    assert status[0] == 0
    return mm, st.take(np.zeros(n, dtype=int)), u0


def check_derivatives(mm, st, u0, x, e_rel=1e-10, hess_atol=1e-6):
    """The kernel's energy, gradient and (if hess_atol) Hessian of particle 0 at x = (theta,
    pos, rot), its solve started where the particle is, against central finite differences
    of the NumPy reference (the Hessian with the forces at x as its multipliers: the
    energy's own); returns the kernel's energy."""
    th, p, R = x

    def f(d):
        return reference_energy(mm, st, 0, u0, th + d[:6].reshape(3, 2), p + d[6:9],
                                R @ rotvec_to_matrix(d[9:]))

    e, g, H = mm.evaluate(st, 0, u0, th, p, R, multipliers="primal")
    assert e == pytest.approx(f(np.zeros(12)), rel=e_rel)
    h = 1e-7
    eye = np.eye(12)
    g_num = np.array([(f(h * eye[i]) - f(-h * eye[i])) / (2 * h) for i in range(12)])
    np.testing.assert_allclose(g, g_num, atol=1e-5 * np.abs(g).max() + 1e-6)
    if hess_atol:
        h = 1e-5
        H_num = np.array([[(f(h * (eye[i] + eye[j])) - f(h * (eye[i] - eye[j]))
                            - f(h * (eye[j] - eye[i])) + f(-h * (eye[i] + eye[j])))
                           / (4 * h * h) for j in range(12)] for i in range(12)])
        np.testing.assert_allclose(H, H_num, atol=hess_atol * np.abs(H).max())
    return e


def shaken(st: ParticleState, seed: int, theta: float, rot: float, pos: float = 0.0):
    """Particle 0's configuration moved off where it is by normal draws of these sizes
    [rad, rad, m]: (theta, pos, rot)."""
    rng = np.random.default_rng(seed)
    return (st.theta[0] + rng.normal(0, theta, st.theta[0].shape),
            st.pos[0] + rng.normal(0, pos, 3),
            st.rot[0] @ rotvec_to_matrix(rng.normal(0, rot, 3)))


def test_gradient_and_hessian_match_reference(modelo):
    mm, st, u0 = grasp(modelo, config=PIN)
    check_derivatives(mm, st, u0, shaken(st, 1, 0.02, 0.02))


SURFACES = [LocalSurface("sphere", 0.04), LocalSurface("plane"),
            # along z one contact of the test grasp is on the cylinder's end face: a plane
            LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0)),
            LocalSurface("cylinder", 0.016, (0.0, 0.0, 1.0)),
            LocalSurface("cylinder", 0.016, (0.6, 0.8, 0.0))]


@pytest.mark.parametrize("surface", SURFACES)
def test_rolling_gradient_and_hessian_match_reference(modelo, surface):
    """The rolling contact (the pad sphere on the primitive, the midpoint slip), its exact
    Hessian included, against finite differences of its NumPy reference."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL)
    check_derivatives(mm, st, u0, shaken(st, 3, 0.02, 0.02, 2e-4), hess_atol=2e-6)


@pytest.mark.parametrize("surface", SURFACES[:2])
def test_spin_friction_gradient_and_hessian_match_reference(modelo, surface):
    """The pads' torsional friction (the spin about the start's normal, its limit held at
    the start's normal force), turned far out of its stick zone: the kernel against the
    reference, each pad carrying a spin from a last action; spinning costs energy."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo, config=ROLL)
    st.spin = np.array([[0.004, -0.006, 0.002]])
    mm = MotionModel(modelo, obj, replace(ROLL, spin_friction=0.001))
    x = shaken(st, 5, 0.03, 0.05, 5e-4)
    e = check_derivatives(mm, st, u0, x, hess_atol=2e-6)
    free = MotionModel(modelo, obj, ROLL)
    assert e > free.evaluate(st, 0, u0, *x)[0] + 1e-4


@pytest.mark.parametrize("surface", SURFACES[:2])
def test_friction_gradient_and_hessian_match_reference(modelo, surface):
    """The pads' friction (the smoothed maximum dissipation, the normal force held at the
    start's): sliding contacts far out of their stick zone, the kernel against the
    reference."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo, config=ROLL)
    mm = MotionModel(modelo, obj, replace(ROLL, friction=0.3))
    x = shaken(st, 5, 0.03, 0.05, 5e-4)
    e = check_derivatives(mm, st, u0, x, hess_atol=2e-6)
    glued = MotionModel(modelo, obj, ROLL)
    assert e < glued.evaluate(st, 0, u0, *x)[0]  # sliding costs less than stretching


def test_equilibrium_is_stationary_and_matches_scipy(modelo):
    # A soft contact penalty keeps the plain reference minimiser well conditioned.
    cfg = replace(PIN, contact_stiffness=1e4)
    mm, st, u0 = grasp(modelo, n=3, config=cfg)
    rng = np.random.default_rng(2)
    u = u0 + rng.uniform(-3e-4, 3e-4, (3,))
    start = st.copy()
    status, _ = mm.solve(st, u)
    assert np.all(status == 0)
    q = 0
    _, g, _ = mm.evaluate(st, q, u)
    # Residual forces and torques under 0.1 mN (m): the last step, under the tolerance, is
    # taken without an evaluation to confirm it.
    assert np.abs(g).max() < 1e-4

    def f(x):
        return reference_energy(mm, start, q, u, start.theta[q] + x[:6].reshape(3, 2),
                                start.pos[q] + x[6:9] * 1e-3,
                                start.rot[q] @ rotvec_to_matrix(x[9:]))

    res = minimize(f, np.zeros(12), method="BFGS", options={"gtol": 1e-12, "maxiter": 5000})
    th_ref = start.theta[q] + res.x[:6].reshape(3, 2)
    np.testing.assert_allclose(st.theta[q], th_ref, atol=2e-4)
    np.testing.assert_allclose(st.pos[q], start.pos[q] + res.x[6:9] * 1e-3, atol=2e-6)


def _chain(mm, st, u0, u1, steps, cfg):
    """The action u0 -> u1 in `steps` equal solves, each rolled on from the last."""
    for j in range(steps):
        status, _ = mm.solve(st, u0 + (u1 - u0) * ((j + 1) / steps), cfg,
                             u_from=u0 + (u1 - u0) * (j / steps))
        assert np.all(status == 0)


@pytest.mark.parametrize("surface", SURFACES[:3])
def test_one_solve_lands_where_many_small_ones_do(modelo, surface):
    """An action is one solve: the contacts' slip is exact to third order in the action,
    so that 32 solves of a 32nd of it land within a few micrometres and hundredths of a
    degree of one (the force's lever is the rest: first order, measured in
    docs/DECISIONS.md), at a tight tolerance both."""
    from vlr.observation import rotation_angle

    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    mm = MotionModel(modelo, obj, ROLL)
    _, st, u0 = grasp(modelo, config=ROLL)
    mm.solve(st, u0)
    tight = replace(ROLL, tol_theta=1e-9, tol_pos=1e-10, max_iter=60, follow_substeps=0)
    u1 = u0 + np.array([4e-4, -3e-4, 2e-4])
    one, many = st.copy(), st.copy()
    _chain(mm, one, u0, u1, 1, tight)
    _chain(mm, many, u0, u1, 32, tight)
    moved = np.linalg.norm(one.pos[0] - st.pos[0])
    assert moved > 1e-3   # a millimetre's action
    assert np.linalg.norm(one.pos[0] - many.pos[0]) < 0.03 * moved
    assert np.degrees(rotation_angle(one.rot, many.rot))[0] < 0.05


def test_the_stored_tangent_is_the_equilibriums_derivative(modelo):
    """After a solve each particle carries dx/du (`ParticleState.tangent`): against central
    differences of the equilibrium in each command."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    mm = MotionModel(modelo, obj, ROLL)
    tight = replace(ROLL, tol_theta=1e-10, tol_pos=1e-11, max_iter=60)
    _, st, u0 = grasp(modelo, config=ROLL)
    mm.solve(st, u0, tight)
    h = 1e-6
    for c in range(3):
        du = np.zeros(3)
        du[c] = h
        a, b = st.copy(), st.copy()
        mm.solve(a, u0 + du, tight, u_from=u0)
        mm.solve(b, u0 - du, tight, u_from=u0)
        dtheta = (a.theta[0] - b.theta[0]).ravel() / (2 * h)
        np.testing.assert_allclose(st.tangent[0, :6, c], dtheta,
                                   atol=0.01 * np.abs(dtheta).max())
        np.testing.assert_allclose(st.tangent[0, 6:9, c], (a.pos[0] - b.pos[0]) / (2 * h),
                                   atol=0.01 * np.abs(dtheta).max() * 0.05)


def test_an_action_costs_a_few_newton_steps(modelo):
    """The stored tangent's prediction and Newton's quadratic convergence: a 0.3 mm action
    of a settled grasp in at most three evaluations."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    mm = MotionModel(modelo, obj, ROLL)
    _, st, u0 = grasp(modelo, config=ROLL)
    mm.solve(st, u0)
    u1 = u0 + np.array([3e-4, -2e-4, 1e-4])
    status, evals = mm.solve(st, u1, u_from=u0)
    assert status[0] == 0 and evals[0] <= 3


def test_friction_that_never_slides_is_the_glued_contact(modelo):
    """The pads' friction with a limit no force reaches (mu 1e6: its stick zone the stick's
    own k_c) moves the grasp as glued contacts do, action after action: the stretch each
    anchor carries on is the one the force says (`solve._carried_stretch`)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    MotionModel(modelo, obj, ROLL).solve(st, u0)
    ends = {}
    for mu in (1e6, None):
        s = st.copy()
        mm = MotionModel(modelo, obj, replace(ROLL, friction=mu))
        u = u0
        for du in ([2e-4, -1e-4, 1e-4], [-1e-4, 2e-4, 0.0]):
            status, _ = mm.solve(s, u + du, u_from=u)
            assert status[0] == 0, mu
            u = u + du
        ends[mu] = s
    np.testing.assert_allclose(ends[1e6].pos, ends[None].pos, atol=1e-7)
    np.testing.assert_allclose(ends[1e6].anchors, ends[None].anchors, atol=1e-7)


def test_stiffness_changes_equilibrium(modelo):
    # Observability (docs/METHOD.md 8.2): with series tendon compliance, spring rates matter.
    _, a, u0 = grasp(modelo)
    stiff = np.array(modelo.stiffness)
    stiff[0, 1] *= 2.0
    _, b, _ = grasp(modelo, stiffness=stiff)
    assert np.abs(a.theta - b.theta).max() > math.radians(0.5)


def test_tendon_slack_has_zero_tension(modelo):
    mm, st, u0 = grasp(modelo)
    slack_u = modelo.tendon_takeup(st.theta[0]) - 1e-3
    t = mm.tensions(st, slack_u)
    assert np.all(t == 0.0)
    assert np.all(mm.tensions(st, u0) > 0.0)


def test_failed_solve_is_flagged_not_nan(modelo):
    mm, st, u0 = grasp(modelo, n=4)
    st.theta[1] = np.nan
    st.theta[2, 0, 0] += 1.0  # far off: must settle beyond the jump limit
    status, _ = mm.solve(st, u0)
    assert status[0] == 0 and status[3] == 0
    assert status[1] != 0 and status[2] != 0
    assert not st.valid[1] and not st.valid[2]
    assert not mm.followed.any()  # a settle has no path to follow
    from vlr.observation import ObservationModel, PomObservation

    obs = PomObservation(st.pos[0], st.rot[0])
    ll = ObservationModel().log_likelihood(st, obs)
    assert np.isneginf(ll[1]) and np.isneginf(ll[2]) and np.isfinite(ll[0])


def test_two_finger_pinch():
    ch = Chain(lengths=(0.04,), pad_center=(0.0, 0.003, 0.025), pad_radius=0.01,
               pulley_radii=(0.008, 0.006), stiffness=(0.04, 0.03),
               rest_angles=(-0.7, -0.6), limits=((-0.35, 1.7), (0.0, 1.4)),
               link_masses=(0.015, 0.012), link_coms=((0, 0, 0.02), (0, 0, 0.015)))
    model = HandModel.from_chains(("a", "b"), (ch, ch), [[0, -0.03, 0.01], [0, 0.03, 0.01]],
                                  [math.pi / 2, -math.pi / 2], 2e4)
    mm, st, u0 = grasp(model, n=2, theta=(0.3, 0.6), config=PIN)
    _, g, _ = mm.evaluate(st, 0, u0)
    # At equilibrium: residual forces and torques under 0.1 mN (m), where the solve's step
    # tolerance leaves 0.03 mN.
    assert np.abs(g).max() < 1e-4
    status, _ = mm.solve(st, u0 + np.array([2e-4, -2e-4]))
    assert np.all(status == 0)
    assert np.all(np.isfinite(st.theta))


def test_a_three_joint_finger_is_refused_by_name():
    ch = Chain(lengths=(0.04, 0.03), pad_center=(0.0, 0.003, 0.025), pad_radius=0.01,
               pulley_radii=(0.008, 0.006, 0.005), stiffness=(0.04, 0.03, 0.02),
               rest_angles=(-0.7, -0.6, -0.5), limits=((-0.35, 1.7), (0.0, 1.4), (0.0, 1.2)),
               link_masses=(0.015, 0.012, 0.01),
               link_coms=((0, 0, 0.02), (0, 0, 0.015), (0, 0, 0.012)))
    model = HandModel.from_chains(("a", "b"), (ch, ch), [[0, -0.03, 0.01], [0, 0.03, 0.01]],
                                  [math.pi / 2, -math.pi / 2], 2e4)
    with pytest.raises(ValueError, match="fingers of 2 joints.*have 3"):
        MotionModel(model, OBJ, PIN)


def test_a_jittered_contact_on_a_cylinder_starts_at_its_own_gap(modelo):
    """A pad normal tilted off the cylinder's normal plane (the filter's jitter of a contact
    angle) starts a solve at the gap its contact's stretch holds, as on a sphere, not at a
    penetration of r (1 - cos tilt) (a 12 mm pad tilted 10 degrees: 0.18 mm, 180 N)."""
    axis = np.array([1.0, 0.0, 0.0])
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("cylinder", 0.016,
                                                                        tuple(axis)))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL)
    status, _ = mm.solve(st, u0, replace(ROLL, max_iter=200, jump_theta=1.0, jump_pos=0.05))
    assert status[0] == 0
    nan = np.full((modelo.n_fingers, 4), np.nan)

    def gaps():
        return mm._evaluate(st, 0, u0, st.theta[0], st.pos[0], st.rot[0], nan)[-1][:, 0]

    before = gaps()
    stretch = st.contact_residuals(modelo)
    rd = np.einsum("nab,nbc->nac", modelo.base_rot, plane_rotation(st.theta[0].sum(-1)))
    tilt = math.radians(10.0)
    for i in range(modelo.n_fingers):
        n = st.normals[0, i]
        a = rd[i].T @ st.rot[0] @ axis
        a = a - (a @ n) * n
        st.normals[0, i] = math.cos(tilt) * n + math.sin(tilt) * a / np.linalg.norm(a)
    st.anchor_to_pose(modelo, stretch)
    assert np.abs(gaps() - before).max() < 1e-5


def test_reanchoring_keeps_the_grasp_force(modelo):
    """Re-deriving the anchors at the current pose must keep each contact penalty's stretch:
    zeroing it drops the squeeze, and a particle at equilibrium is no longer there (the
    filter re-anchors every particle after jitter, so this was a bias of every iteration)."""
    mm, st, u0 = grasp(modelo, n=2)
    stretch = st.contact_residuals(modelo)
    assert np.abs(stretch).max() > 1e-6  # the grasp force is there
    kept = st.copy()
    kept.anchor_to_pose(modelo, stretch)
    np.testing.assert_allclose(kept.anchors, st.anchors, atol=1e-15)
    zeroed = st.copy()
    zeroed.anchor_to_pose(modelo)
    theta0 = zeroed.theta.copy()
    mm.solve(zeroed, u0)
    assert np.degrees(np.abs(zeroed.theta - theta0).max()) > 0.003  # it relaxes


@pytest.mark.parametrize("kw, message", [
    (dict(terms=("springs", "rolling")), "rolling contacts: rolling=True"),
    (dict(terms=("springs", "tendon")), "needs 'contacts'"),
    (dict(friction=0.0), "friction"), (dict(friction=-1.0), "friction"),
    (dict(follow_substeps=-1), "follow_substeps"),
    (dict(limit_stiffness=0.0), "limit_stiffness"), (dict(max_iter=0), "max_iter")])
def test_bad_motion_settings_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        MotionConfig(**kw)
    MotionConfig(terms=("springs", "tendon"), rolling=False)   # pinned needs no contacts


def test_a_per_call_config_gets_its_own_gravity(modelo):
    """`solve(config=...)` weighs the hand and the object as that config says, not as the
    model's own."""
    mm_down, st, u0 = grasp(modelo, config=PIN)
    weightless = replace(PIN, gravity=(0.0, 0.0, 0.0))
    mm_none = MotionModel(modelo, OBJ, weightless)
    free = dict(max_iter=500, jump_theta=math.pi, jump_pos=1.0)
    a, b, c = st.copy(), st.copy(), st.copy()
    assert mm_down.solve(a, u0 + 2e-4, replace(weightless, **free))[0][0] == 0
    assert mm_none.solve(b, u0 + 2e-4, replace(weightless, **free))[0][0] == 0
    assert mm_down.solve(c, u0 + 2e-4, replace(PIN, **free))[0][0] == 0
    np.testing.assert_array_equal(a.theta, b.theta)
    assert np.abs(a.theta - c.theta).max() > 1e-6


def test_a_particles_own_object_mass_and_centre_of_mass_match_reference(modelo):
    """The object's unknowns: each particle's own mass and centre of mass in the kernel's
    gravity term, against finite differences of the reference."""
    mm, st, u0 = grasp(modelo, config=ROLL)
    st.hold_object(OBJ)
    st.object_mass[0] = 0.31
    st.object_com[0] = (0.004, -0.006, 0.045)
    check_derivatives(mm, st, u0, shaken(st, 4, 0.02, 0.02, 2e-4), hess_atol=2e-6)


def test_a_heavier_particle_sinks_and_the_models_own_object_changes_nothing(modelo):
    mm, st, u0 = grasp(modelo, n=3, config=ROLL)
    own = st.copy()
    st.hold_object(OBJ)
    st.object_mass[2] = 2 * OBJ.mass
    u = u0 + 2e-4
    assert np.all(mm.solve(st, u, u_from=u0)[0] == 0)
    assert np.all(mm.solve(own, u, u_from=u0)[0] == 0)
    # Particle 0 holds the model's object as its own: the same numbers as without.
    np.testing.assert_array_equal(st.pos[0], own.pos[0])
    np.testing.assert_array_equal(st.theta[0], own.theta[0])
    g = np.asarray(mm.config.gravity) / np.linalg.norm(mm.config.gravity)
    assert (st.pos[2] - st.pos[0]) @ g > 1e-5   # the doubled weight sinks it by > 10 um
    copied = st.take(np.array([2, 0]))
    assert copied.object_mass.tolist() == [2 * OBJ.mass, OBJ.mass]
    with pytest.raises(ValueError, match="object_mass"):
        own.put(np.array([0]), copied.take(np.array([0])))


@pytest.mark.parametrize("surface, kappa", [
    (LocalSurface("sphere", 0.04), 60.0), (LocalSurface("plane"), 30.0),
    (LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0)), 20.0)])
def test_a_contacts_own_curvature_matches_reference(modelo, surface, kappa):
    """The curvature unknown: each contact's own radius of curvature, read by the kernel's
    rolling contact, against finite differences of the reference; a plane with a curvature
    is a sphere."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL)
    st.hold_surface(obj)
    st.surface_curvature[0, 1] = kappa
    np.testing.assert_allclose(mm.contact_rho(st)[0, 1], 1.0 / kappa)
    check_derivatives(mm, st, u0, shaken(st, 5, 0.02, 0.02, 2e-4), hess_atol=2e-6)


@pytest.mark.parametrize("surface", [LocalSurface("sphere", 0.04), LocalSurface("plane")])
def test_the_surfaces_own_curvature_changes_nothing_and_another_rolls_otherwise(modelo,
                                                                                surface):
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    mm, st, u0 = grasp(modelo, n=3, config=ROLL)
    mm = MotionModel(modelo, obj, ROLL)
    assert np.all(mm.solve(st, u0)[0] == 0)
    own = st.copy()
    st.hold_surface(obj)
    assert st.surface_curvature.tolist() == [[surface.curvature] * 3] * 3
    st.surface_curvature[2] = 50.0      # a 20 mm ball: its contacts roll further
    u = u0 + np.array([3e-4, -2e-4, 1e-4])
    assert np.all(mm.solve(st, u, u_from=u0)[0] == 0)
    assert np.all(mm.solve(own, u, u_from=u0)[0] == 0)
    # Particle 0 holds the surface's curvature as its own: the same numbers as without.
    for name in ("theta", "pos", "anchors", "normals"):
        np.testing.assert_array_equal(getattr(st, name)[0], getattr(own, name)[0])
    assert np.abs(st.anchors[2] - st.anchors[0]).max() > 1e-6
    assert st.take(np.array([2])).surface_curvature.tolist() == [[50.0] * 3]


def test_a_plane_bent_to_a_curvature_rolls_as_that_sphere(modelo):
    """A believed plane whose particles carry a curvature (the curvature unknown) moves
    exactly as the motion model of a sphere of that radius: the kernel's rolling contact
    takes the particle's own radius."""
    plane = MotionModel(modelo, ObjectParams(mass=OBJ.mass, com=OBJ.com), ROLL)
    ball = MotionModel(modelo, ObjectParams(mass=OBJ.mass, com=OBJ.com,
                                            surface=LocalSurface("sphere", 0.04)), ROLL)
    _, st, u0 = grasp(modelo, n=2, config=ROLL)
    assert np.all(ball.solve(st, u0)[0] == 0)
    bent = st.copy()
    bent.hold_surface(ObjectParams(mass=OBJ.mass, com=OBJ.com))
    bent.surface_curvature[:] = 25.0
    u = u0 + np.array([3e-4, -2e-4, 1e-4])
    assert np.all(ball.solve(st, u, u_from=u0)[0] == 0)
    assert np.all(plane.solve(bent, u, u_from=u0)[0] == 0)
    for name in ("theta", "pos", "anchors", "normals"):
        np.testing.assert_allclose(getattr(bent, name), getattr(st, name), atol=1e-12)


def test_resampling_in_place_is_taking_the_same_particles(modelo):
    """`ParticleState.resample` (in place, `vlr.kernels.resample`) gives what `take` does, for
    sorted indexes of every pattern: runs, skips, the first and the last repeated."""
    _, st, _ = grasp(modelo, 7)
    rng = np.random.default_rng(0)
    st.theta += rng.normal(0, 0.01, st.theta.shape)
    st.valid[3] = False
    st.tangent = rng.normal(size=(7, 4, 3))
    for idx in (np.array([0, 0, 2, 2, 2, 5, 6]), np.array([6] * 7), np.array([0] * 7),
                np.arange(7), np.sort(rng.integers(0, 7, 7))):
        want = st.take(idx)
        got = st.copy()
        got.resample(idx)
        for name in ("theta", "pos", "rot", "anchors", "valid", "tangent"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    with pytest.raises(ValueError, match="sorted"):
        st.copy().resample(np.array([1, 0, 2, 3, 4, 5, 6]))
    # An array that is a view of another (not the state's own) is copied, not written
    # through: the array it views keeps its rows.
    idx = np.array([0, 0, 2, 2, 2, 5, 6])
    viewed = st.copy()
    base = np.concatenate([viewed.theta.reshape(7, -1), np.zeros((7, 1))], axis=1)
    viewed.theta = base[:, :-1].reshape(viewed.theta.shape)
    before = base.copy()
    viewed.resample(idx)
    np.testing.assert_array_equal(viewed.theta, st.take(idx).theta)
    np.testing.assert_array_equal(base, before)


def test_a_sliding_grasp_ends_at_its_own_equilibrium(modelo):
    """After actions in which the pads slide, the particle is at equilibrium as the next
    solve reads it: an action of no command change leaves it where it is, its contacts'
    normal forces the same (`contacts.rolled` carries the stretch in the end's tangent
    plane; its part along the normal would read as gap: newtons at a slide's stretch).
    The test grasp holds its object with tangential forces up to 3x the normal ones, so
    mu 4 starts it inside the cone."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    MotionModel(modelo, obj, ROLL).solve(st, u0)
    mm = MotionModel(modelo, obj, replace(ROLL, friction=4.0))
    u = u0
    for du in ([1.8e-4, -0.9e-4, 0.6e-4], [-1.2e-4, 1.5e-4, -0.9e-4], [0.9e-4, -1.5e-4, 1.2e-4]):
        status, _ = mm.solve(st, u + du, u_from=u)
        assert status[0] == 0
        u = u + du
    # A stretch on the friction's scale (its stick zone, 0.1 mm), not the stick's (um).
    assert np.linalg.norm(st.contact_residuals(modelo)[0], axis=1).max() > 5e-5
    before = st.copy()
    forces = mm.contact_forces(st, 0, u, st.theta[0], st.pos[0], st.rot[0])
    status, _ = mm.solve(st, u, u_from=u)
    assert status[0] == 0
    assert np.abs(st.pos - before.pos).max() < 2e-5
    assert np.abs(st.theta - before.theta).max() < 1e-3
    after = mm.contact_forces(st, 0, u, st.theta[0], st.pos[0], st.rot[0])
    np.testing.assert_allclose(after[:, 0], forces[:, 0], atol=0.05)


def test_a_slide_that_runs_away_stops_early_and_is_not_followed(modelo):
    """With the pads sliding, an action whose pads cannot hold the object (mu 0.3 on the
    test grasp, whose tangential forces reach 3x the normal ones) fails once its iterate
    leaves the jump limits, before its evaluations run out, and is not followed up in finer
    steps (a slide running away holds on no path); the stick moves it in a few steps."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    MotionModel(modelo, obj, ROLL).solve(st, u0)
    u1 = u0 + np.array([1.8e-4, -0.9e-4, 0.6e-4])
    sliding = MotionModel(modelo, obj, replace(ROLL, friction=0.3))
    status, evals = sliding.solve(st.copy(), u1, u_from=u0)
    assert status[0] != 0 and evals[0] < ROLL.max_iter and not sliding.followed[0]
    status, evals = MotionModel(modelo, obj, ROLL).solve(st.copy(), u1, u_from=u0)
    assert status[0] == 0 and evals[0] <= 4

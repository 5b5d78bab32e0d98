"""Motion model (Eq. 6-9): vectorised solve vs a plain reference, stationarity, observability,
tendon slack, invalid solves."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from vlr import _energy_kernels as kern
from vlr.kinematics import Chain, HandModel, normals_from_angles
from vlr.motion import (
    MotionConfig,
    MotionModel,
    ObjectParams,
    PadFriction,
    ParticleState,
    reference_energy,
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


def shake(st: ParticleState, seed: int, theta: float, rot: float, pos: float = 0.0) -> None:
    """Move particle 0 off its equilibrium by normal draws of these sizes [rad, rad, m]."""
    rng = np.random.default_rng(seed)
    st.theta += rng.normal(0, theta, st.theta.shape)
    st.rot[0] = st.rot[0] @ rotvec_to_matrix(rng.normal(0, rot, 3))
    st.pos[0] += rng.normal(0, pos, 3)


def check_derivatives(mm, st, u0, roll=None, e_rel=1e-12, hess_atol=1e-6):
    """The kernel's energy, gradient and (if hess_atol) Hessian of particle 0 against
    central finite differences of the NumPy reference; returns the kernel's energy."""

    def f(x):
        return reference_energy(mm, st, 0, u0, st.theta[0] + x[:6].reshape(3, 2),
                                st.pos[0] + x[6:9], st.rot[0] @ rotvec_to_matrix(x[9:]),
                                roll)

    e, g, H = mm.evaluate(st, 0, u0, roll)
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


def test_gradient_and_hessian_match_reference(modelo):
    mm, st, u0 = grasp(modelo, config=PIN)
    rng = np.random.default_rng(1)
    st.theta += rng.normal(0, 0.02, st.theta.shape)
    st.rot[0] = st.rot[0] @ rotvec_to_matrix(rng.normal(0, 0.02, 3))
    check_derivatives(mm, st, u0)


@pytest.mark.parametrize("surface", [
    LocalSurface("sphere", 0.04), LocalSurface("plane"),
    # A cylinder's side is held to a sphere of its radius; along z one contact of the test
    # grasp is on an end face.
    LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0)),
    LocalSurface("cylinder", 0.016, (0.0, 0.0, 1.0)),
    LocalSurface("cylinder", 0.016, (0.6, 0.8, 0.0))])
def test_rolling_gradient_and_hessian_match_reference(modelo, surface):
    """The rolling term (pad sphere on the object's local sphere, no tangential slip of the
    previous contacts) against finite differences of its NumPy reference."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL)
    roll = mm.rolling_frames(st)[0]
    assert roll.shape == (3, kern.N_RL)
    np.testing.assert_allclose(roll[:, kern.RL_RHO], surface.kernel_radius)
    shake(st, 3, 0.02, 0.02, 2e-4)
    check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=2e-6)


def test_equilibrium_is_stationary_and_matches_scipy(modelo):
    # A soft contact penalty keeps the plain reference minimiser well conditioned.
    cfg = replace(PIN, contact_stiffness=1e4)
    mm, st, u0 = grasp(modelo, n=3, config=cfg)
    rng = np.random.default_rng(2)
    u = u0 + rng.uniform(-3e-4, 3e-4, (3,))
    start = st.copy()
    status, _ = mm.solve(st, u)
    assert np.all(status == 0)
    for q in range(1):
        _, g, _ = mm.evaluate(st, q, u)
        assert np.abs(g).max() < 1e-6

        def f(x, q=q):
            return reference_energy(mm, start, q, u, start.theta[q] + x[:6].reshape(3, 2),
                                    start.pos[q] + x[6:9] * 1e-3,
                                    start.rot[q] @ rotvec_to_matrix(x[9:]))

        res = minimize(f, np.zeros(12), method="BFGS", options={"gtol": 1e-12, "maxiter": 5000})
        th_ref = start.theta[q] + res.x[:6].reshape(3, 2)
        np.testing.assert_allclose(st.theta[q], th_ref, atol=2e-4)
        np.testing.assert_allclose(st.pos[q], start.pos[q] + res.x[6:9] * 1e-3, atol=2e-6)


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
    from vlr.observation import ObservationModel, PomObservation

    obs = PomObservation(st.pos[0], st.rot[0])
    ll = ObservationModel().log_likelihood(st, obs)
    assert np.isneginf(ll[1]) and np.isneginf(ll[2]) and np.isfinite(ll[0])


def test_three_joint_two_finger_pinch():
    ch = Chain(lengths=(0.04, 0.03), pad_center=(0.0, 0.003, 0.025), pad_radius=0.01,
               pulley_radii=(0.008, 0.006, 0.005), stiffness=(0.04, 0.03, 0.02),
               rest_angles=(-0.7, -0.6, -0.5), limits=((-0.35, 1.7), (0.0, 1.4), (0.0, 1.2)),
               link_masses=(0.015, 0.012, 0.01),
               link_coms=((0, 0, 0.02), (0, 0, 0.015), (0, 0, 0.012)))
    model = HandModel.from_chains(("a", "b"), (ch, ch), [[0, -0.03, 0.01], [0, 0.03, 0.01]],
                                  [math.pi / 2, -math.pi / 2], 2e4)
    mm, st, u0 = grasp(model, n=2, theta=(0.1, 0.4, 0.4), config=PIN)
    _, g, _ = mm.evaluate(st, 0, u0)
    # At equilibrium: residual forces and torques under 0.1 mN (m), where the solve's step
    # tolerance leaves 0.03 mN.
    assert np.abs(g).max() < 1e-4
    status, _ = mm.solve(st, u0 + np.array([2e-4, -2e-4]))
    assert np.all(status == 0)
    assert np.all(np.isfinite(st.theta))


def test_rolling_spin_gradient_matches_reference(modelo):
    """The pad's torsional stiffness (spin about the contact normal, `PadFriction`): exact
    energy and gradient (its Hessian is Gauss-Newton, so only the solver's speed depends on
    it)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL, friction=PadFriction(spin_stiffness=0.05))
    roll = mm.rolling_frames(st)[0]
    shake(st, 4, 0.03, 0.05)
    e = check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=None)
    assert e > MotionModel(modelo, obj, ROLL).evaluate(st, 0, u0, roll)[0]


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


# The sim's pads' friction (`vlr.sim.pads`): sliding mu 1, torsional mu_t 1 mm.
FRICTION = PadFriction(slide=1.0, spin=0.001)


def _cone_load(mm: MotionModel, st: ParticleState) -> np.ndarray:
    """(P, N) each contact's tangential force over mu times its normal force (rolling term)."""
    from vlr.surface import surface_normals

    m = surface_normals(mm.model, st.theta, st.normals, st.rot)
    c = np.einsum("pba,pnb->pna", st.rot, st.contacts(mm.model) - st.pos[:, None, :])
    d = c - st.anchors
    t = np.linalg.norm(d - np.sum(d * m, axis=-1, keepdims=True) * m, axis=-1)
    roll = mm.rolling_frames(st, m)
    n = mm.normal_forces(st, roll)
    return mm.config.contact_stiffness * t / (mm.friction.slide * np.maximum(n, 1e-12))


def test_friction_gradient_matches_reference(modelo):
    """Sliding friction (a Huber function of the tangential stretch: stick spring inside the
    cone, mu N |t| beyond) and torsional friction (smoothed mu_t N |s|): the kernel's energy
    and gradient against finite differences of the NumPy reference, with one contact
    sticking and the others slipping (the Hessian is Gauss-Newton)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL, friction=FRICTION)
    roll = mm.rolling_frames(st)[0]
    shake(st, 5, 0.03, 0.05, 5e-4)
    # The stretches carry 1.2-2.0 kN: the first contact's cone (5 kN) holds it, the others'
    # (0.05 N, 0.02 N) do not.
    roll[:, kern.RL_FORCE] = (5000.0, 0.05, 0.02)
    d = st.contacts(modelo)[0] - (st.pos[0] + st.anchors[0] @ st.rot[0].T)
    n = roll[:, 3:6]
    load = ROLL.contact_stiffness * np.linalg.norm(
        d - np.sum(d * n, axis=-1, keepdims=True) * n, axis=-1) / roll[:, kern.RL_FORCE]
    assert load[0] < 1.0 and np.all(load[1:] > 1.0)
    e = check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=None)
    glued = MotionModel(modelo, obj, ROLL)
    assert e < glued.evaluate(st, 0, u0, roll)[0]  # slipping costs less than stretching


def test_friction_keeps_every_contact_inside_its_cone(modelo):
    """After an action, every contact's tangential force is at most mu times its normal force
    (the return mapping); without friction, the same action leaves a contact far outside
    (the glued contact pulls sideways with a force the pad cannot hold). A weightless grasp:
    this test hand's grasps under gravity hang on their glued contacts, which friction
    rightly refuses. At `vlr gap`'s tolerances for friction (sim/gap.py): the stick and slip
    wedge while the normal forces update, which the filter's tolerances cut short."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    weightless = replace(ROLL, gravity=(0.0, 0.0, 0.0), tol_theta=1e-6, tol_pos=1e-7)
    _, st, u0 = grasp(modelo, config=weightless, theta=(0.3, 0.3))
    du = np.array([6e-4, -4e-4, 0.0])
    loads = {}
    for name, friction in (("friction", FRICTION), ("glued", None)):
        s = st.copy()
        status, _ = MotionModel(modelo, obj, weightless, friction).solve(s, u0 + du, u_from=u0)
        assert np.all(status == 0), name
        loads[name] = _cone_load(MotionModel(modelo, obj, weightless, FRICTION), s)
    assert loads["friction"].max() <= 1.0 + 1e-3
    assert loads["glued"].max() > 10.0


def test_a_settle_has_no_friction(modelo):
    """Friction needs a history: a settle (no `u_from`) is the frictionless model's."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    a, b = st.copy(), st.copy()
    MotionModel(modelo, obj, ROLL, FRICTION).solve(a, u0 + 2e-4)
    MotionModel(modelo, obj, ROLL).solve(b, u0 + 2e-4)
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.anchors, b.anchors)


@pytest.mark.parametrize("kw, message", [
    (dict(slide=0.0), "slide friction"), (dict(slide=-1.0), "slide friction"),
    (dict(spin=-1e-3), "spin friction"), (dict(spin=math.inf), "spin friction"),
    (dict(spin_stiffness=-1.0), "spin stiffness"), (dict(spin_smoothing=0.0), "spin smoothing")])
def test_bad_friction_settings_are_named(kw, message):
    with pytest.raises(ValueError, match=message):
        PadFriction(**kw)
    assert not PadFriction().on and PadFriction(slide=1.0).on and PadFriction(spin=1e-3).on


@pytest.mark.parametrize("kw, message", [
    (dict(terms=("springs", "rolling")), "rolling contacts: rolling=True"),
    (dict(terms=("springs", "tendon")), "needs 'contacts'"),
    (dict(rolling_substeps=0), "rolling_substeps"), (dict(follow_substeps=-1), "follow_substeps"),
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
    shake(st, 4, 0.02, 0.02, 2e-4)
    check_derivatives(mm, st, u0, mm.rolling_frames(st)[0], e_rel=1e-10, hess_atol=2e-6)


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
    """The curvature unknown: each contact's own radius of curvature in the rolling frames,
    read by the kernel's rolling term, against finite differences of the reference; a plane
    with a curvature is a sphere."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, ROLL)
    st.hold_surface(obj)
    st.surface_curvature[0, 1] = kappa
    roll = mm.rolling_frames(st)[0]
    np.testing.assert_allclose(roll[:, kern.RL_RHO],
                               [surface.kernel_radius, 1.0 / kappa, surface.kernel_radius])
    shake(st, 5, 0.02, 0.02, 2e-4)
    check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=2e-6)


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
    exactly as the motion model of a sphere of that radius: the kernel's rolling term and
    the contact update both take the particle's own radius."""
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

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
    ParticleState,
    reference_energy,
    rotvec_to_matrix,
)
from vlr.spec import load_hand
from vlr.surface import LocalSurface

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
# The pinned-contact model (Eq. 8 as a penalty), without rolling.
PIN = MotionConfig()
ROLL = MotionConfig().with_rolling()
THETA0 = (-0.3, 1.2)


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def grasp(model: HandModel, n: int = 1, tension: float = 5.0, theta=THETA0,
          config: MotionConfig | None = None, stiffness=None):
    """Settled grasp of n identical particles at u_0 = s(theta) + T/k_t."""
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
    settle = MotionConfig(**{**(config or MotionConfig()).__dict__, "max_iter": 500,
                             "jump_theta": math.pi, "jump_pos": 1.0})
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


@pytest.mark.parametrize("surface, exact", [
    (LocalSurface("sphere", 0.04), False), (LocalSurface("plane"), False),
    # The cylinder held to its axis; along z one contact of the test grasp is on an end face.
    (LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0)), True),
    (LocalSurface("cylinder", 0.016, (0.0, 0.0, 1.0)), True),
    (LocalSurface("cylinder", 0.016, (0.6, 0.8, 0.0)), True)])
def test_rolling_gradient_and_hessian_match_reference(modelo, surface, exact):
    """The rolling term (pad sphere on the object's local sphere or cylinder, no tangential
    slip of the previous contacts) against finite differences of its NumPy reference; for the
    cylinder that includes the Hessian terms of its axis turning with the object."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, replace(ROLL, exact_cylinder=exact))
    roll = mm.rolling_frames(st)[0]
    assert np.count_nonzero(roll[:, kern.RL_AXIS:kern.RL_AXIS + 3].any(axis=1)) == (
        0 if not exact else 2 if surface.axis[2] else 3)
    shake(st, 3, 0.02, 0.02, 2e-4)
    check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=2e-6)


def test_equilibrium_is_stationary_and_matches_scipy(modelo):
    # A soft contact penalty keeps the plain reference minimiser well conditioned.
    cfg = MotionConfig(terms=PIN.terms, contact_stiffness=1e4)
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
    # Observability (METHOD.md 8.2): with series tendon compliance, spring rates matter.
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


def test_model_error_that_grows_with_the_motion(modelo):
    """kappa > 0: a particle that predicts a large motion is judged with a wider scale. With
    the same 2 mm error it is more likely than one that predicted no motion; with no error
    it is less likely (the likelihood keeps its normalisation, so a wide tolerance is not
    free). kappa = 0 ignores the motion."""
    from vlr.observation import ObservationModel, PomObservation

    _, st, _ = grasp(modelo, n=2)
    st.pos[1] = st.pos[0]
    st.rot[1] = st.rot[0]
    moved = (np.array([0.0, 0.02]), np.array([0.0, 0.3]))        # 20 mm, 17 degrees
    model = ObservationModel(motion_fraction=0.1)
    far = PomObservation(st.pos[0] + np.array([0.002, 0.0, 0.0]), st.rot[0])
    near = PomObservation(st.pos[0], st.rot[0])
    ll_far = model.log_likelihood(st, far, moved)
    ll_near = model.log_likelihood(st, near, moved)
    assert ll_far[1] > ll_far[0] and ll_near[1] < ll_near[0]
    fixed = ObservationModel().log_likelihood(st, far, moved)
    assert fixed[0] == pytest.approx(fixed[1])
    assert ll_far[0] == pytest.approx(fixed[0])      # no motion: the fixed scales
    with pytest.raises(ValueError, match="motion_fraction -0.1"):
        ObservationModel(motion_fraction=-0.1)


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
    assert np.abs(g).max() < 1e-6
    status, _ = mm.solve(st, u0 + np.array([2e-4, -2e-4]))
    assert np.all(status == 0)
    assert np.all(np.isfinite(st.theta))


def test_rolling_spin_gradient_matches_reference(modelo):
    """The pad's torsional stiffness (spin about the contact normal): exact energy and
    gradient (its Hessian is Gauss-Newton, so only the solver's speed depends on it)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, replace(ROLL, spin_stiffness=0.05))
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


FRICTION = replace(ROLL, slide_friction=1.0, spin_friction=0.001)


def _cone_load(mm: MotionModel, st: ParticleState) -> np.ndarray:
    """(P, N) each contact's tangential force over mu times its normal force (rolling term)."""
    from vlr.surface import surface_normals

    m = surface_normals(mm.model, st.theta, st.normals, st.rot)
    c = np.einsum("pba,pnb->pna", st.rot, st.contacts(mm.model) - st.pos[:, None, :])
    d = c - st.anchors
    t = np.linalg.norm(d - np.sum(d * m, axis=-1, keepdims=True) * m, axis=-1)
    roll = mm.rolling_frames(st, m)
    n = mm.normal_forces(st, roll)
    return mm.config.contact_stiffness * t / (mm.config.slide_friction * np.maximum(n, 1e-12))


def test_friction_gradient_matches_reference(modelo):
    """Sliding friction (a Huber function of the tangential stretch: stick spring inside the
    cone, mu N |t| beyond) and torsional friction (smoothed mu_t N |s|): the kernel's energy
    and gradient against finite differences of the NumPy reference, with one contact
    sticking and the others slipping (the Hessian is Gauss-Newton)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, FRICTION)
    roll = mm.rolling_frames(st)[0]
    shake(st, 5, 0.03, 0.05, 5e-4)
    # The stretches carry 1.2-2.0 kN: the first contact's cone (5 kN) holds it, the others'
    # (0.05 N, 0.02 N) do not.
    roll[:, kern.RL_FORCE] = (5000.0, 0.05, 0.02)
    d = st.contacts(modelo)[0] - (st.pos[0] + st.anchors[0] @ st.rot[0].T)
    n = roll[:, 3:6]
    load = FRICTION.contact_stiffness * np.linalg.norm(
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
    rightly refuses."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    glued = replace(ROLL, gravity=(0.0, 0.0, 0.0))
    friction = replace(FRICTION, gravity=(0.0, 0.0, 0.0))
    _, st, u0 = grasp(modelo, config=glued, theta=(0.3, 0.3))
    du = np.array([6e-4, -4e-4, 0.0])
    loads = {}
    for name, cfg in (("friction", friction), ("glued", glued)):
        s = st.copy()
        status, _ = MotionModel(modelo, obj, cfg).solve(s, u0 + du, u_from=u0)
        assert np.all(status == 0), name
        loads[name] = _cone_load(MotionModel(modelo, obj, friction), s)
    assert loads["friction"].max() <= 1.0 + 1e-3
    assert loads["glued"].max() > 10.0


def test_a_settle_has_no_friction(modelo):
    """Friction needs a history: a settle (no `u_from`) is the frictionless model's."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    a, b = st.copy(), st.copy()
    MotionModel(modelo, obj, FRICTION).solve(a, u0 + 2e-4)
    MotionModel(modelo, obj, ROLL).solve(b, u0 + 2e-4)
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.anchors, b.anchors)


def test_a_stored_spin_torque_matches_reference(modelo):
    """`MotionConfig.spin_memory`: a pad's stored spin torque offsets its torsional friction
    curve (f'(0) is the stored torque): the kernel against the NumPy reference, with one
    pad inside its cone, one near its edge and one beyond (held at the clip)."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, replace(FRICTION, spin_memory=True))
    roll = mm.rolling_frames(st)[0]
    shake(st, 6, 5e-4, 5e-4, 1e-5)  # spins of about the smoothing, where the offset shows
    roll[:, kern.RL_FORCE] = (2.0, 1.0, 0.5)
    roll[:, kern.RL_SPIN_TORQUE] = (0.5e-3, -0.98e-3, 2e-3)  # N m; cones 2, 1, 0.5 mN m
    check_derivatives(mm, st, u0, roll, e_rel=1e-10, hess_atol=None)
    g = mm.evaluate(st, 0, u0, roll)[1]
    roll[:, kern.RL_SPIN_TORQUE] = 0.0
    # The stored torques (0.5-1 mN m) show in the gradient's rotational part.
    assert np.abs(g - mm.evaluate(st, 0, u0, roll)[1])[6:].max() > 2e-4


def test_spin_memory_makes_the_frictional_state_a_fixed_point(modelo):
    """Solved again and again at the command an action ended at, a grasp with spin memory
    stops moving after the first solve (which re-settles the pads' re-contact); without
    memory every solve drops the pads' spin torques again and the grasp keeps moving. Each
    stored torque lies inside its cone mu_t N."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    weightless = dict(gravity=(0.0, 0.0, 0.0))
    _, st, u0 = grasp(modelo, config=replace(ROLL, **weightless), theta=(0.3, 0.3))
    u1 = u0 + np.array([6e-4, -4e-4, 0.0])
    moved = {}
    for memory in (True, False):
        mm = MotionModel(modelo, obj, replace(FRICTION, spin_memory=memory, **weightless))
        s = st.copy()
        assert np.all(mm.solve(s, u1, u_from=u0)[0] == 0)
        if memory:
            cone = FRICTION.spin_friction * mm.normal_forces(s, mm.rolling_frames(s))
            assert np.abs(s.spin_torque).max() > 1e-5  # the pads hold torques
            assert np.all(np.abs(s.spin_torque) <= cone + 1e-12)
        else:
            assert not s.spin_torque.any()
        assert np.all(mm.solve(s, u1, u_from=u1)[0] == 0)
        before = s.theta.copy()
        assert np.all(mm.solve(s, u1, u_from=u1)[0] == 0)
        moved[memory] = np.degrees(np.abs(s.theta - before).max())
    assert moved[True] < 0.002 < 0.005 < moved[False], moved


def test_a_settle_zeroes_the_stored_spin_torques(modelo):
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    _, st, u0 = grasp(modelo, config=ROLL)
    mm = MotionModel(modelo, obj, replace(FRICTION, spin_memory=True))
    st.spin_torque[:] = 1e-4
    mm.solve(st, u0)
    assert not st.spin_torque.any()


@pytest.mark.parametrize("kw", [dict(slide_friction=0.0), dict(slide_friction=-1.0),
                                dict(spin_friction=-1e-3), dict(spin_smoothing=0.0)])
def test_bad_friction_settings_are_named(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        MotionConfig(**kw)


def test_cone_return_moves_the_glued_grasp_towards_the_frictional_one(modelo):
    """`MotionConfig.cone_return`: the glued solve, then each contact's stretch returned onto
    its cone and a glued settle. The settle loads the contacts again, less: one step lowers
    the worst contact's load (tangential force over mu N; 59 glued, 28 after the step when
    written) and moves the object part of the way to the frictional solve's place (about a
    third). A settle (no `u_from`) is unchanged."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=LocalSurface("sphere", 0.04))
    glued = replace(ROLL, gravity=(0.0, 0.0, 0.0))
    cone = replace(glued, cone_return=FRICTION.slide_friction)
    friction = replace(FRICTION, gravity=(0.0, 0.0, 0.0))
    _, st, u0 = grasp(modelo, config=glued, theta=(0.3, 0.3))
    du = np.array([6e-4, -4e-4, 0.0])
    gauge = MotionModel(modelo, obj, friction)
    out = {}
    for name, cfg in (("cone", cone), ("glued", glued), ("friction", friction)):
        s = st.copy()
        status, _ = MotionModel(modelo, obj, cfg).solve(s, u0 + du, u_from=u0)
        assert np.all(status == 0), name
        out[name] = (_cone_load(gauge, s).max(), s.pos[0].copy())
    assert out["glued"][0] > 10.0 and out["cone"][0] < 0.6 * out["glued"][0]
    to_friction = {k: np.linalg.norm(out[k][1] - out["friction"][1]) for k in ("cone", "glued")}
    assert to_friction["cone"] < 0.85 * to_friction["glued"], to_friction
    a, b = st.copy(), st.copy()
    MotionModel(modelo, obj, cone).solve(a, u0 + 2e-4)
    MotionModel(modelo, obj, glued).solve(b, u0 + 2e-4)
    np.testing.assert_array_equal(a.theta, b.theta)
    with pytest.raises(ValueError, match="cone_return"):
        replace(ROLL, cone_return=0.0)


def test_a_hypothesized_link_length_scales_the_links_mass_and_centre(modelo):
    """A particle whose left finger is 40 mm long with its pad 27 mm out (NF1's make, an
    unknown length) weighs its links like a hand built with that finger: masses and centres
    of mass along the link scaled with the lengths (`MotionConfig.link_scaling`). Without
    the scaling (the default) it keeps the Model O's links, and the two differ."""
    s = np.array([40 / 62, 27 / 32])
    left = modelo.chains[1]
    built = replace(left, lengths=(left.lengths[0] * s[0],),
                    pad_center=(*left.pad_center[:2], left.pad_center[2] * s[1]),
                    link_masses=tuple(m * f for m, f in zip(left.link_masses, s, strict=True)),
                    link_coms=tuple((c[0], c[1], c[2] * f)
                                    for c, f in zip(left.link_coms, s, strict=True)))
    nf1 = replace(modelo, chains=(modelo.chains[0], built, modelo.chains[2]))
    gravity_only = MotionConfig(terms=("link_gravity",), link_scaling=True)
    th = np.tile(np.array([-0.2, 0.9]), (3, 1))
    normals = normals_from_angles(np.zeros(3), np.zeros(3))

    def energy(model, segments, config):
        st = ParticleState.nominal(model, 1, th, normals, np.zeros(3), np.eye(3))
        if segments is not None:
            st.segments[0] = segments
        e, g, _ = MotionModel(model, OBJ, config).evaluate(st, 0, np.zeros(3))
        return e, g

    hypothesized = modelo.segments.copy()
    hypothesized[1] *= s
    e_built, g_built = energy(nf1, None, gravity_only)
    e_scaled, g_scaled = energy(modelo, hypothesized, gravity_only)
    assert e_scaled == pytest.approx(e_built, rel=1e-12)
    np.testing.assert_allclose(g_scaled, g_built, rtol=1e-10, atol=1e-15)
    e_fixed, _ = energy(modelo, hypothesized, replace(gravity_only, link_scaling=False))
    assert abs(e_fixed - e_built) > 0.1 * abs(e_built - energy(modelo, None, gravity_only)[0])
    # The NumPy reference scales alike (the kernel is tested against it).
    mm = MotionModel(modelo, OBJ, gravity_only)
    st = ParticleState.nominal(modelo, 1, th, normals, np.zeros(3), np.eye(3))
    st.segments[0] = hypothesized
    assert reference_energy(mm, st, 0, np.zeros(3), st.theta[0], st.pos[0],
                            st.rot[0]) == pytest.approx(e_scaled, rel=1e-12)


def test_a_per_call_config_gets_its_own_link_scaling(modelo):
    """`solve(config=...)` weighs the links as that config says, not as the model's own."""
    mm_off, st, u0 = grasp(modelo, config=PIN)
    st.segments[0, 1] *= 0.9                              # the left finger's lengths
    mm_on = MotionModel(modelo, OBJ, replace(PIN, link_scaling=True))
    free = dict(max_iter=500, jump_theta=math.pi, jump_pos=1.0)
    scaled = replace(PIN, link_scaling=True, **free)
    a, b, c = st.copy(), st.copy(), st.copy()
    assert mm_off.solve(a, u0, scaled)[0][0] == 0
    assert mm_on.solve(b, u0, scaled)[0][0] == 0
    assert mm_off.solve(c, u0, replace(PIN, **free))[0][0] == 0
    np.testing.assert_array_equal(a.theta, b.theta)
    assert np.abs(a.theta - c.theta).max() > 1e-6


def test_a_particles_own_object_mass_and_centre_of_mass_match_reference(modelo):
    """The object's unknowns (issue #5, term (b)): each particle's own mass and centre of
    mass in the kernel's gravity term, against finite differences of the reference."""
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


@pytest.mark.parametrize("surface, exact, kappa", [
    (LocalSurface("sphere", 0.04), False, 60.0), (LocalSurface("plane"), False, 30.0),
    (LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0)), True, 20.0)])
def test_a_contacts_own_curvature_matches_reference(modelo, surface, exact, kappa):
    """The curvature unknown (issue #5, term (b)): each contact's own radius of curvature in
    the rolling frames, read by the kernel's rolling term, against finite differences of the
    reference; a plane with a curvature is a sphere."""
    obj = ObjectParams(mass=OBJ.mass, com=OBJ.com, surface=surface)
    _, st, u0 = grasp(modelo)
    mm = MotionModel(modelo, obj, replace(ROLL, exact_cylinder=exact))
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

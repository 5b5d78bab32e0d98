"""The unscented Kalman filter (`vlr.ukf`): filterpy's UKF over the particle filter's state,
its motion model and its likelihood; the pose chart, the bounds, failed sigma points, and what
it refuses."""

import numpy as np
import pytest
from filterpy.kalman import UnscentedKalmanFilter
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.filter import FilterConfig, UnscentedConfig
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams
from vlr.observation import rotation_error
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action
from vlr.ukf import (
    UnscentedFilter,
    check_estimator,
    pose_add,
    pose_mean,
    pose_residual,
    pose_vector,
)

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def config(**kw) -> FilterConfig:
    """The UKF on the synthetic world's own model (pinned contacts, the pad prior)."""
    kw.setdefault("motion", MotionConfig(rolling=False))
    kw.setdefault("contact_prior", "pad")
    return FilterConfig(estimator="ukf", **kw)


def _run(model: HandModel, seed: int = 0, steps: int = 3, drop: tuple[int, ...] = (),
         **kw) -> tuple[UnscentedFilter, SyntheticWorld]:
    world = SyntheticWorld(model, OBJ, SyntheticConfig(seed=seed))
    u = world.grasp()
    f = UnscentedFilter(model, OBJ, config(**kw), seed)
    f.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(seed + 1)
    for i in range(steps):
        u = world.apply(random_action(rng, 3))
        f.step(u, None if i + 1 in drop else world.observe())
    return f, world


# --------------------------------------------------------------------------- the pose chart

def test_the_pose_residual_composes_rotations_and_pose_add_undoes_it():
    rng = np.random.default_rng(0)
    ra, rb = Rotation.random(5, random_state=1), Rotation.random(5, random_state=2)
    # One pair across the rotation vector's wrap at pi: a small turn apart.
    ra = Rotation.concatenate([ra, Rotation.from_rotvec([0, 0, np.pi - 0.01])])
    rb = Rotation.concatenate([rb, Rotation.from_rotvec([0, 0, -np.pi + 0.01])])
    a = pose_vector(rng.normal(size=(6, 3)), ra.as_matrix())
    b = pose_vector(rng.normal(size=(6, 3)), rb.as_matrix())
    d = pose_residual(a, b)
    np.testing.assert_allclose(d[:, :3], a[:, :3] - b[:, :3])
    np.testing.assert_allclose(d[:, 3:], rotation_error(ra.as_matrix(), rb.as_matrix()),
                               atol=1e-12)
    assert np.linalg.norm(d[-1, 3:]) == pytest.approx(0.02)
    back = pose_add(b, d)
    np.testing.assert_allclose(back[:, :3], a[:, :3])
    np.testing.assert_allclose(Rotation.from_rotvec(back[:, 3:]).as_matrix(), ra.as_matrix(),
                               atol=1e-12)


def test_the_mean_of_poses_respects_rotations():
    # Positive weights: scipy's mean of rotations (the chordal mean) agrees for a cluster.
    rng = np.random.default_rng(3)
    centre = Rotation.from_rotvec([0.3, -2.9, 0.4])    # near the wrap at pi
    spread = Rotation.from_rotvec(rng.normal(0, 0.05, (7, 3)))
    rots = spread * centre
    w = rng.random(7)
    w /= w.sum()
    z = pose_vector(rng.normal(size=(7, 3)), rots.as_matrix())
    m = pose_mean(z, w)
    np.testing.assert_allclose(m[:3], w @ z[:, :3])
    ref = rots.mean(weights=w)
    assert (Rotation.from_rotvec(m[3:]) * ref.inv()).magnitude() < 1e-4
    # The scaled sigma points' weights, negative at the centre: a symmetric set of turns
    # about a rotation has that rotation as its mean.
    from filterpy.kalman import MerweScaledSigmaPoints

    pts = MerweScaledSigmaPoints(3, 0.5, 2.0, 0.0)
    turns = pts.sigma_points(np.zeros(3), 0.01 * np.eye(3))
    sym = Rotation.from_rotvec(turns) * centre
    m = pose_mean(pose_vector(np.zeros((7, 3)), sym.as_matrix()), pts.Wm)
    assert (Rotation.from_rotvec(m[3:]) * centre.inv()).magnitude() < 1e-9


# --------------------------------------------------------------------------- the filter

def test_the_ukf_is_filterpys_and_moves_every_sigma_point_in_one_solve(modelo, monkeypatch):
    calls = []
    solve = MotionModel.solve

    def counted(self, state, u, config=None, u_from=None):
        calls.append((state.n, u_from is not None))
        return solve(self, state, u, config, u_from)

    monkeypatch.setattr(MotionModel, "solve", counted)
    f, _ = _run(modelo, steps=2)
    assert isinstance(f.kf, UnscentedKalmanFilter)
    d = len(f.dim_names)
    assert f.state.n == 2 * d + 1 == 25
    # The grasp: one settle from the observed pose and one at u_0 for the posterior's sigma
    # points; then per action one solve of the action and one settle, each of all of them
    # (the synthetic world's own solves are of its one true state).
    ours = [c for c in calls if c[0] != 1]
    assert ours == [(25, False), (25, False)] + [(25, True), (25, False)] * 2
    assert len(f.history) == 3 and all(np.isfinite(r.ci_deg) for r in f.history)


def test_same_seed_same_numbers(modelo):
    a, _ = _run(modelo, seed=4, unknowns=("stiffness:thumb.distal",))
    b, _ = _run(modelo, seed=4, unknowns=("stiffness:thumb.distal",))
    np.testing.assert_array_equal(a.kf.x, b.kf.x)
    np.testing.assert_array_equal(a.kf.P, b.kf.P)


def test_the_prior_has_the_particle_filters_moments(modelo):
    """The Gaussian prior: the guess and spreads of the joints and contacts, each unknown's
    uniform prior's mean and variance; a spring's of its logarithm (as the particle filter
    jitters it)."""
    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0))
    u = world.grasp()
    f = UnscentedFilter(modelo, OBJ, config(unknowns=("stiffness:thumb.distal",
                                                      "length:left.proximal")))
    mean, cov = f._prior(world.observe(), world.nominal.theta, world.nominal.contact)
    np.testing.assert_allclose(mean[:6], world.nominal.theta.ravel())
    np.testing.assert_allclose(mean[6:12], world.nominal.contact.ravel())
    np.testing.assert_allclose(np.diag(cov)[:6], f.config.theta_spread ** 2)
    spring, link = f.unknowns
    logs = np.log(np.linspace(*spring.prior, 2_000_001))
    assert mean[12] == pytest.approx(logs.mean(), rel=1e-6)
    assert cov[12, 12] == pytest.approx(logs.var(), rel=1e-4)
    assert mean[13] == pytest.approx(np.mean(link.prior))
    assert cov[13, 13] == pytest.approx((link.prior[1] - link.prior[0]) ** 2 / 12)
    rec = f.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    # The spring's estimate is in N m/rad, its interval about its median, within its prior.
    post = rec.posterior
    top = spring.prior[1] * (1 + 1e-12)   # exp(log(high)) may round up
    assert spring.prior[0] <= post.low[12] < post.median[12] < post.high[12] <= top
    assert post.high[12] == pytest.approx(spring.prior[1])   # the Gaussian reaches past it


def test_the_stops_are_the_models_and_the_priors_bound_the_unknowns(modelo):
    """A sigma point beyond a joint stop is settled back by the model's stop spring (not
    clipped: clipped sigma points move alike and the covariance collapses onto the stop); one
    outside an unknown's prior is clipped to it, and so is the mean."""
    f, _ = _run(modelo, steps=1, unknowns=("length:left.proximal",))
    lim = modelo.limits.reshape(-1, 2)
    wide = f.kf.P.copy()
    wide[:6, :6] = np.eye(6) * np.radians(8.0) ** 2
    wide[12, 12] = (0.05) ** 2    # far wider than the prior's 31-81 mm
    f.kf.P = wide
    sigmas = f.points.sigma_points(f.kf.x, f.kf.P)
    beyond = (sigmas[:, :6] < lim[:, 0]) | (sigmas[:, :6] > lim[:, 1])
    assert beyond.any()
    st = f._hypotheses(sigmas)
    lo, hi = f.unknowns[0].prior
    assert np.all((st.segments[:, 1, 0] >= lo) & (st.segments[:, 1, 0] <= hi))
    assert (st.segments[:, 1, 0] == lo).any() and (st.segments[:, 1, 0] == hi).any()
    th = st.theta.reshape(st.n, -1)
    np.testing.assert_allclose(th, sigmas[:, :6])       # not clipped
    f._project(st)
    th = st.theta.reshape(st.n, -1)[st.valid]
    sink = np.radians(0.5)   # the stop spring (100 N m/rad here) against the grasp
    assert np.all(th >= lim[:, 0] - sink) and np.all(th <= lim[:, 1] + sink)
    assert st.valid[np.flatnonzero(beyond.any(axis=1))].mean() > 0.5
    for rec in f.history:
        post = rec.posterior or rec.prior
        assert lo <= post.low[12] <= post.median[12] <= post.high[12] <= hi


def test_a_failed_sigma_point_takes_its_partners_reflection(modelo):
    f, _ = _run(modelo, steps=1)
    sigmas, state = f._sigmas, f.state.copy()
    d = len(f.dim_names)
    ok = np.zeros(state.n, dtype=np.int8)
    y_all, z_all, failed = f._moved(sigmas, state, ok)
    assert failed == 0
    status = ok.copy()
    status[3] = 3                # the third dimension's + point: its - point solved
    status[5] = status[5 + d] = 3  # both of the fifth's
    y, z, failed = f._moved(sigmas, state, status)
    assert failed == 3
    np.testing.assert_allclose(y[3], 2 * y[0] - y[3 + d])
    np.testing.assert_allclose(pose_residual(z[3], z[0]), -pose_residual(z[3 + d], z[0]),
                               atol=1e-12)
    np.testing.assert_allclose(y[5], y[0] + sigmas[5] - sigmas[0])   # carried, unmoved
    np.testing.assert_allclose(z[5], z[0])                            # learns nothing
    np.testing.assert_array_equal(np.delete(y, [3, 5, 5 + d], 0),
                                  np.delete(y_all, [3, 5, 5 + d], 0))


def test_every_sigma_point_failing_starts_again_from_the_last_estimate(modelo):
    """...its joints and contacts, the unknowns at their priors' centres (as the particle
    filter draws its prior again)."""
    f, world = _run(modelo, steps=1, unknowns=("stiffness:thumb.distal",))
    last = f.kf.x.copy()
    f.state.theta[...] = np.nan   # every solve fails
    u = world.apply(random_action(np.random.default_rng(0), 3))
    rec = f.step(u, world.observe())
    assert f.recoveries == 1 and np.isfinite(rec.ci_deg)
    assert np.abs(rec.prior.median[:6] - last[:6]).max() < np.radians(10)
    spring = f.unknowns[0]
    assert rec.prior.high[12] - rec.prior.low[12] > 0.5 * (spring.prior[1] - spring.prior[0])


def test_a_prior_that_does_not_settle_is_named(modelo, monkeypatch):
    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0))
    u = world.grasp()
    solve = MotionModel.solve

    def failing(self, state, *args, **kw):
        out = solve(self, state, *args, **kw)
        if state.n > 1:     # the filter's, not the world's own
            state.valid[:] = False
        return out

    monkeypatch.setattr(MotionModel, "solve", failing)
    f = UnscentedFilter(modelo, OBJ, config())
    with pytest.raises(FloatingPointError, match="none of the 25 sigma points of the prior"):
        f.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)


def test_a_prediction_only_step(modelo):
    f, _ = _run(modelo, steps=2, drop=(2,))
    assert f.history[2].posterior is None and f.history[1].posterior is not None
    assert np.isnan(f.history[1].ess) and f.history[1].n_invalid >= 0
    assert np.isfinite(f.kf.x).all() and f.state.valid.mean() > 0.5


def test_what_the_ukf_cannot_carry_is_refused_in_one_line(modelo):
    with pytest.raises(UserError, match="cannot carry a curvature") as err:
        check_estimator(config(unknowns=("curvature",)))
    assert "\n" not in str(err.value)
    with pytest.raises(UserError, match="loop.exploration active"):
        check_estimator(config(), "active")
    with pytest.raises(UserError, match="cannot carry a curvature"):
        UnscentedFilter(modelo, OBJ, config(unknowns=("curvature:thumb",)))
    check_estimator(config(unknowns=("stiffness:thumb.distal", "tendon", "mass", "com:x",
                                     "length:left.proximal")))
    check_estimator(FilterConfig(unknowns=("curvature",)), "active")   # the particle filter
    with pytest.raises(ValueError, match="alpha"):
        UnscentedConfig(alpha=0.0)
    with pytest.raises(ValueError, match="estimator"):
        FilterConfig(estimator="kalman")

"""The likelihood's turn term (`vlr.observation`: `grasp_turn`, `ObservationModel.sigma_turn`,
the setting `filter.observation.sigma_turn_deg`). `vlr gap` finds most of the model's
per-action pose error along the object's turn in its grip; the term gives that one direction
of the 6-D pose error its own scale. Checked here: the Sherman-Morrison form equals the dense
Gaussian, a pure turn costs little and the same error off the turn a lot, the axis runs from
the thumb, and each backend's default scale reaches the filter."""

import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.kernels.likelihood import rotvec_of
from vlr.observation import (
    ObservationConfig,
    ObservationModel,
    PomObservation,
    grasp_turn,
    rotation_error,
)
from vlr.settings import load_settings


def _model(sigma_pos: float = 5e-4, sigma_rot: float = np.radians(1.0),
           sigma_turn: float = 0.0, names=("thumb", "left", "right")) -> ObservationModel:
    """The likelihood at SI scales [m, rad], its turn axis from the finger named "thumb"."""
    config = ObservationConfig(sigma_pos_mm=sigma_pos * 1e3,
                               sigma_rot_deg=float(np.degrees(sigma_rot)),
                               sigma_turn_deg=float(np.degrees(sigma_turn)))
    return ObservationModel(config, types.SimpleNamespace(names=tuple(names)))


def _particles(n: int = 6, seed: int = 0) -> types.SimpleNamespace:
    rng = np.random.default_rng(seed)
    return types.SimpleNamespace(
        pos=rng.normal(size=(n, 3)) * 0.01,
        rot=Rotation.random(n, random_state=seed).as_matrix(),
        anchors=rng.normal(size=(n, 3, 3)) * 0.03,
        valid=np.ones(n, bool))


def test_turn_likelihood_is_the_dense_gaussian():
    st = _particles()
    obs = PomObservation(st.pos[0] + 3e-4,
                         Rotation.from_rotvec([0.01, 0.02, -0.01]).as_matrix() @ st.rot[0])
    om = _model(2e-4, 0.004, 0.012, names=("left", "thumb", "right"))
    assert om.opposed == 1
    assert (om.sigma_pos, om.sigma_rot, om.sigma_turn) == pytest.approx((2e-4, 0.004, 0.012))
    ll = om.log_likelihood(st, obs)
    v = grasp_turn(st.pos, st.rot, st.anchors, 1)
    d = np.diag(np.repeat([om.sigma_pos ** 2, om.sigma_rot ** 2], 3))
    for i in range(len(ll)):
        e = np.concatenate([st.pos[i] - obs.position,
                            rotation_error(st.rot[i], obs.rotation)])
        cov = d + om.sigma_turn ** 2 * np.outer(v[i], v[i])
        ref = (-0.5 * e @ np.linalg.solve(cov, e)
               - 0.5 * (np.linalg.slogdet(cov)[1] - np.linalg.slogdet(d)[1]))
        assert ll[i] == pytest.approx(ref, rel=1e-9)


def test_the_kernels_rotation_vector_is_scipys_at_every_angle():
    # Random rotations, tiny ones and ones a hair from a half turn (Shepperd's branches).
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi, 30), [0.0, 1e-12, 1e-7, 1e-3],
                             np.pi - np.array([1e-9, 1e-6, 1e-3]), rng.uniform(3.0, np.pi, 23)])
    mats = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()
    got = np.array([rotvec_of(m, np.eye(3)) for m in mats])
    ref = Rotation.from_matrix(mats).as_rotvec()
    # At a half turn the vector and its opposite are the same rotation.
    flip = np.linalg.norm(got + ref, axis=1) < np.linalg.norm(got - ref, axis=1)
    got[flip & (angles > 3.0)] *= -1
    np.testing.assert_allclose(got, ref, atol=1e-7)
    # Of a product R S^T, as the likelihood reads a pose error.
    others = Rotation.random(len(mats), random_state=4).as_matrix()
    got = np.array([rotvec_of(m, s) for m, s in zip(mats, others, strict=True)])
    ref = Rotation.from_matrix(mats @ others.transpose(0, 2, 1)).as_rotvec()
    np.testing.assert_allclose(got, ref, atol=1e-7)


def test_the_plain_likelihood_is_the_dense_gaussian_far_off_too():
    st = _particles(8, seed=4)
    obs = PomObservation(np.array([0.001, -0.002, 0.003]),
                         Rotation.random(random_state=9).as_matrix())
    om = _model(2e-4, 0.004)
    ll = om.log_likelihood(st, obs)
    e = np.concatenate([st.pos - obs.position, rotation_error(st.rot, obs.rotation[None])], axis=1)
    ref = -0.5 * ((e[:, :3] / 2e-4) ** 2).sum(1) - 0.5 * ((e[:, 3:] / 0.004) ** 2).sum(1)
    np.testing.assert_allclose(ll, ref, rtol=1e-9)


def test_a_failed_solve_gets_no_weight_not_an_error():
    st = _particles(3)
    st.valid[1:] = False
    st.rot[1] = np.nan
    st.rot[2] = 0.0
    obs = PomObservation(st.pos[0], st.rot[0])
    ll = _model(sigma_turn=0.01).log_likelihood(st, obs)
    assert np.isfinite(ll[0]) and np.isneginf(ll[1:]).all()
    # A row marked valid whose pose is not finite gets no weight either.
    st.valid[:] = True
    st.rot[2] = np.eye(3)
    st.pos[2] = np.nan
    ll = _model(sigma_turn=0.01).log_likelihood(st, obs)
    assert np.isfinite(ll[0]) and np.isneginf(ll[1:]).all()


def test_a_turn_costs_little_and_the_same_error_off_it_a_lot():
    st = _particles(1, seed=2)
    v = grasp_turn(st.pos, st.rot, st.anchors, 0)[0]
    turn = np.radians(0.8)
    # The observation is the particle turned by 0.8 degree about the grasp's axis: p moves
    # by turn * a x (p - c_o), R by exp(turn * a).
    along = PomObservation(st.pos[0] - turn * v[:3],
                           Rotation.from_rotvec(-turn * v[3:]).as_matrix() @ st.rot[0])
    # The same angle about a perpendicular axis through the POM.
    perp = np.cross(v[3:], [1.0, 0.0, 0.0])
    perp /= np.linalg.norm(perp)
    off = PomObservation(st.pos[0], Rotation.from_rotvec(-turn * perp).as_matrix() @ st.rot[0])
    om = _model(0.15e-3, np.radians(0.3), np.radians(0.8))
    ll_along, ll_off = om.log_likelihood(st, along)[0], om.log_likelihood(st, off)[0]
    # Along: about 0.5 (the quadratic) + 1.1 (the normalisation); off: 0.5 (0.8 / 0.3)^2.
    assert ll_along > -2.0 and ll_off < ll_along - 2.0
    flat = _model(0.15e-3, np.radians(0.3))
    assert flat.log_likelihood(st, along)[0] < ll_along - 3


def test_the_turn_axis_runs_from_the_thumb_to_the_others():
    pos, rot = np.zeros((1, 3)), np.eye(3)[None]
    contacts = np.array([[[0.0, -0.04, 0.04], [-0.02, 0.03, 0.04], [0.02, 0.03, 0.04]]])
    v = grasp_turn(pos, rot, contacts, 0)[0]
    np.testing.assert_allclose(v[3:], [0.0, 1.0, 0.0])
    # A turn about +y through a contact 40 mm above the POM moves the POM along -x.
    np.testing.assert_allclose(v[:3], [-0.04, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="opposed finger 3"):
        grasp_turn(pos, rot, contacts, 3)


def test_bad_turn_settings_are_named():
    with pytest.raises(ValueError, match="sigma_turn_deg -1"):
        ObservationConfig(sigma_turn_deg=-1.0)
    with pytest.raises(UserError, match="filter.observation.sigma_turn_deg: .*-0.5"):
        load_settings({"filter.observation.sigma_turn_deg": -0.5})
    with pytest.raises(UserError, match="filter.observation.sigma_turn_deg: 'wide'"):
        load_settings({"filter.observation.sigma_turn_deg": "wide"})
    # The axis runs from the finger named "thumb": a hand without one cannot take the term.
    with pytest.raises(ValueError, match="from a finger named 'thumb'"):
        _model(sigma_turn=np.radians(0.8), names=("a", "b", "c"))
    assert _model(names=("a", "b", "c")).sigma_turn == 0.0    # without the term, fine
    om = _model(sigma_turn=np.radians(0.8), names=("left", "thumb", "right"))
    assert (om.sigma_turn, om.opposed) == (pytest.approx(np.radians(0.8)), 1)
    assert _model(names=("left", "thumb", "right")).sigma_turn == 0.0


def test_the_turn_term_follows_the_backend():
    """The sim's default likelihood has the turn term at 1 deg; the synthetic world and the
    real hand have none; an explicit scale wins, and 0 turns it off."""
    from vlr.filter import ParticleFilter
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.spec import load_hand, load_object

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams.from_spec(load_object("apple"))

    def turn(backend: str, **dotted) -> tuple[float, int]:
        s = load_settings({"world.backend": backend, "filter.particles": 50}, dotted)
        om = ParticleFilter(model, obj, s.filter).obs_model
        return om.sigma_turn, om.opposed

    thumb = model.names.index("thumb")
    assert turn("sim") == (pytest.approx(np.radians(1.0)), thumb)
    assert turn("synthetic")[0] == 0.0 and turn("hardware")[0] == 0.0
    assert turn("sim", **{"filter.observation.sigma_turn_deg": 0})[0] == 0.0
    assert turn("synthetic", **{"filter.observation.sigma_turn_deg": 0.8})[0] == pytest.approx(
        np.radians(0.8))


def test_the_anchors_frames_are_each_others_inverse_and_numpys():
    from vlr.kernels.frames import object_points, palm_points

    rng = np.random.default_rng(5)
    a = rng.normal(size=(7, 3, 3)) * 0.03
    pos = rng.normal(size=(7, 3)) * 0.01
    rot = Rotation.random(7, random_state=5).as_matrix()
    x = palm_points(a, pos, rot)
    np.testing.assert_allclose(x, a @ np.swapaxes(rot, -1, -2) + pos[:, None, :], atol=1e-15)
    np.testing.assert_allclose(object_points(x, pos, rot), a, atol=1e-15)

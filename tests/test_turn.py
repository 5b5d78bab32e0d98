"""The likelihood's turn term (`vlr.observation`: `grasp_turn`, `ObservationModel.sigma_turn`;
issue #5). `vlr gap` finds most of the model's per-action pose error along the object's turn
in its grip; the term gives that one direction of the 6-D pose error its own scale. Checked
here: the Sherman-Morrison form equals the dense Gaussian, a pure turn costs little and the
same error off the turn a lot, the axis runs from the thumb, and the Cramér-Rao floor with
the term equals the dense computation."""

import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.observation import ObservationModel, PomObservation, grasp_turn, rotation_error
from vlr.trial import TrialSettings, _turn


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
    om = ObservationModel(sigma_pos=2e-4, sigma_rot=0.004, sigma_turn=0.012, opposed=1)
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


def test_a_failed_solve_gets_no_weight_not_an_error():
    st = _particles(3)
    st.valid[1:] = False
    st.rot[1] = np.nan
    st.rot[2] = 0.0
    obs = PomObservation(st.pos[0], st.rot[0])
    ll = ObservationModel(sigma_turn=0.01).log_likelihood(st, obs)
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
    om = ObservationModel(sigma_pos=0.15e-3, sigma_rot=np.radians(0.3),
                          sigma_turn=np.radians(0.8))
    ll_along, ll_off = om.log_likelihood(st, along)[0], om.log_likelihood(st, off)[0]
    # Along: about 0.5 (the quadratic) + 1.1 (the normalisation); off: 0.5 (0.8 / 0.3)^2.
    assert ll_along > -2.0 and ll_off < ll_along - 2.0
    flat = ObservationModel(sigma_pos=0.15e-3, sigma_rot=np.radians(0.3))
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
    with pytest.raises(ValueError, match="sigma_turn -1"):
        ObservationModel(sigma_turn=-1.0)
    with pytest.raises(ValueError, match="set one"):
        ObservationModel(sigma_turn=0.01, motion_fraction=0.1)
    with pytest.raises(UserError, match="sigma_turn_deg -0.5"):
        TrialSettings(sigma_turn_deg=-0.5)
    with pytest.raises(UserError, match="sigma_turn_deg 'wide'"):
        TrialSettings(sigma_turn_deg="wide")
    with pytest.raises(UserError, match="from the thumb"):
        _turn(TrialSettings(sigma_turn_deg=0.8), types.SimpleNamespace(names=("a", "b", "c")))
    hand = types.SimpleNamespace(names=("left", "thumb", "right"), finger_index=lambda n: 1)
    assert _turn(TrialSettings(sigma_turn_deg=0.8), hand) == {
        "sigma_turn": pytest.approx(np.radians(0.8)), "opposed": 1}
    assert _turn(TrialSettings(sigma_turn_deg=0), hand) == {}
    assert _turn(TrialSettings(backend="synthetic"), hand) == {}
    # The sim's default with rolling contacts (vlr.trial.ROLLING_TURN_SIGMA).
    assert _turn(TrialSettings(backend="sim"), hand) == {
        "sigma_turn": pytest.approx(np.radians(1.0)), "opposed": 1}

"""The hand's tendon tensions in the likelihood (`ObservationModel.sigma_tension`,
`TrialSettings.sigma_tension_n`; issue #5): the term's arithmetic, that it is only weighed
where the hand reads tensions, and that the sim reports them with every move."""

import types
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.observation import ObservationModel, PomObservation, TensionedObservation
from vlr.trial import TrialSettings, run_trial


def _particles(n: int = 5) -> types.SimpleNamespace:
    rng = np.random.default_rng(0)
    return types.SimpleNamespace(pos=rng.normal(size=(n, 3)) * 1e-4,
                                 rot=Rotation.random(n, random_state=0).as_matrix(),
                                 anchors=np.zeros((n, 3, 3)), valid=np.ones(n, bool))


def test_tension_term_is_independent_gaussians_on_the_tensions():
    st = _particles()
    pose = PomObservation(np.zeros(3), st.rot[0])
    observed = np.array([20.0, 12.0, 12.5])
    obs = TensionedObservation(pose.position, pose.rotation, observed)
    predicted = observed + np.array([[0, 0, 0], [0.5, 0, 0], [0, -1.0, 0.5], [2, 2, 2],
                                     [0, 0, 0]])
    om = ObservationModel(sigma_pos=2e-4, sigma_rot=0.007, sigma_tension=0.5)
    pose_only = ObservationModel(sigma_pos=2e-4, sigma_rot=0.007).log_likelihood(st, pose)
    ll = om.log_likelihood(st, obs, tensions=predicted)
    expected = pose_only - 0.5 * (((predicted - observed) / 0.5) ** 2).sum(axis=1)
    np.testing.assert_allclose(ll, expected)
    # Without the hand's reading, or without the particles' predictions, only the pose counts.
    np.testing.assert_allclose(om.log_likelihood(st, pose, tensions=predicted), pose_only)
    np.testing.assert_allclose(om.log_likelihood(st, obs), pose_only)
    # A failed solve (NaN tension) gets no weight.
    predicted[4] = np.nan
    assert om.log_likelihood(st, obs, tensions=predicted)[4] == -np.inf


def test_bad_tension_settings_are_named():
    with pytest.raises(ValueError, match="sigma_tension -1"):
        ObservationModel(sigma_tension=-1.0)
    with pytest.raises(UserError, match="sigma_tension_n -0.5"):
        TrialSettings(sigma_tension_n=-0.5)
    with pytest.raises(UserError, match="sigma_tension_n 'firm'"):
        TrialSettings(sigma_tension_n="firm")
    # The synthetic world and the real hand read no tensions: refused by name, before any
    # hand moves; and by the loop itself for a hand that reports none.
    with pytest.raises(UserError, match="synthetic world does not report"):
        TrialSettings(backend="synthetic", sigma_tension_n=0.5)
    from vlr.identify import IdentifyConfig, identify
    from vlr.trial import open_world

    w = open_world(TrialSettings(backend="synthetic", particles=50))
    cfg = IdentifyConfig(max_iterations=1, filter=replace(
        IdentifyConfig().filter, n_particles=50,
        observation=ObservationModel(sigma_tension=0.5)))
    with pytest.raises(UserError, match="does not report them"):
        identify(w.world, w.observer, w.model, w.obj, w.nominal, cfg)


def test_sim_trial_weighs_the_reported_tensions():
    from sim.backend import SimHand

    with SimHand(object="apple", seed=0) as hand:
        report = hand.grasp()
        assert report.tensions.shape == (3,) and np.all(report.tensions > 5.0)
        moved = hand.apply(np.array([3e-4, 0.0, 0.0]))
        np.testing.assert_allclose(moved.tensions, hand.static_tensions())
    r = run_trial(TrialSettings(backend="sim", object="apple", particles=500,
                                max_iterations=2, sigma_tension_n=0.5))
    assert r["iterations"] == 2 and np.isfinite(r["errors"]["proximal_deg_mean"])


def test_sim_tension_noise_is_seeded_and_only_in_the_reading():
    from sim.backend import SimHand, SimOptions
    from vlr.spec import SpecError

    def readings(seed: int, noise: float):
        with SimHand(object="apple", seed=seed,
                     options=SimOptions(tension_noise_n=noise)) as hand:
            hand.grasp()
            moved = hand.apply(np.array([3e-4, 0.0, 0.0]))
            return moved.tensions, hand.static_tensions()

    exact, spring = readings(0, 0.0)
    np.testing.assert_allclose(exact, spring)
    noisy, spring_noisy = readings(0, 0.5)
    np.testing.assert_allclose(spring_noisy, spring)  # the physics is untouched
    assert 0.01 < np.max(np.abs(noisy - spring)) < 3.0
    np.testing.assert_array_equal(readings(0, 0.5)[0], noisy)  # the same seed, the same
    # Another seed, other noise on the same physics (the seed moves only the sensors).
    assert not np.allclose(readings(1, 0.5)[0] - spring, noisy - spring)
    with pytest.raises(SpecError, match="tension_noise_n = -1"):
        SimOptions(tension_noise_n=-1.0)
    with pytest.raises(UserError, match="tension_noise_n is the sim's"):
        TrialSettings(backend="synthetic", tension_noise_n=0.5)
    with pytest.raises(UserError, match="tension_noise_n 'loud'"):
        TrialSettings(tension_noise_n="loud")

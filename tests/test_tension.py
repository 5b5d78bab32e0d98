"""The hand's tendon tensions in the likelihood (`ObservationModel.sigma_tension`, the setting
`filter.observation.sigma_tension_n`): the term's arithmetic, that it is only weighed where
the hand reads tensions, and that the sim reports them with every move."""

import types
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.observation import (
    ObservationConfig,
    ObservationModel,
    PomObservation,
    TensionedObservation,
)
from vlr.settings import load_settings


def _settings(backend: str, **dotted):
    return load_settings({"world.backend": backend},
                         {k.replace("__", "."): v for k, v in dotted.items()})


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
    scales = dict(sigma_pos_mm=0.2, sigma_rot_deg=float(np.degrees(0.007)))
    om = ObservationModel(ObservationConfig(**scales, sigma_tension_n=0.5))
    assert om.sigma_tension == 0.5 and om.sigma_pos == pytest.approx(2e-4)
    pose_only = ObservationModel(ObservationConfig(**scales)).log_likelihood(st, pose)
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
    with pytest.raises(ValueError, match="sigma_tension_n -1"):
        ObservationConfig(sigma_tension_n=-1.0)
    with pytest.raises(UserError, match="filter.observation.sigma_tension_n: .*-0.5"):
        _settings("sim", filter__observation__sigma_tension_n=-0.5)
    with pytest.raises(UserError, match="filter.observation.sigma_tension_n: 'firm'"):
        _settings("sim", filter__observation__sigma_tension_n="firm")
    # The synthetic world reads no tensions: refused by name, before any hand moves; and by
    # the loop itself for a hand that reports none.
    from vlr.identify import LoopConfig, identify
    from vlr.world import open_world

    with pytest.raises(UserError, match="sigma_tension_n: the synthetic world does not report"):
        open_world(_settings("synthetic", filter__observation__sigma_tension_n=0.5))
    s = _settings("synthetic", filter__particles=50)
    w = open_world(s)
    weighing = replace(s.filter, observation=replace(s.filter.observation,
                                                     sigma_tension_n=0.5))
    with pytest.raises(UserError, match="does not report them"):
        identify(w.world, w.observer, w.model, w.obj, w.nominal, weighing,
                 LoopConfig(max_iterations=1))


def test_a_hand_that_reads_no_tensions_is_refused_by_name():
    """`vlr.world.hand_world` refuses the tension term for a hand without readings (the
    real hand without a `tension` calibration) before the loop starts."""
    from vlr.world import hand_world

    class Deaf:
        reads_tensions = False
        object_spec = spec = None

    s = _settings("hardware", filter__observation__sigma_tension_n=0.5)
    model = types.SimpleNamespace(names=("thumb", "left", "right"))
    deaf = Deaf()
    deaf.spec = types.SimpleNamespace(name="modelo")
    deaf.object_spec = types.SimpleNamespace(name="apple", tag_id=0, tag_size=0.02)
    with pytest.raises(UserError, match="filter.observation.sigma_tension_n: this hardware "
                       "hand does not report"):
        hand_world(deaf, s, model, None, None, deaf.spec, deaf.object_spec)


def test_sim_trial_weighs_the_reported_tensions():
    from vlr.sim.backend import SimHand

    with SimHand(object="apple", seed=0) as hand:
        report = hand.grasp()
        assert report.tensions.shape == (3,) and np.all(report.tensions > 5.0)
        moved = hand.apply(np.array([3e-4, 0.0, 0.0]))
        np.testing.assert_allclose(moved.tensions, hand.static_tensions())
    from vlr.run import run_identification

    r = run_identification(_settings("sim", world__object="apple", filter__particles=500,
                                     loop__max_iterations=2,
                                     filter__observation__sigma_tension_n=0.5)).summary
    assert r["iterations"] == 2 and np.isfinite(r["errors"]["proximal_deg_mean"])
    assert r["settings"]["filter.observation.sigma_tension_n"] == 0.5


def test_sim_tension_noise_is_seeded_and_only_in_the_reading():
    from vlr.sim.backend import SimHand, SimOptions

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
    # The option is the sim's world's (`vlr.sim.backend.SimWorldOptions`), and reaches its hand.
    with pytest.raises(UserError, match="unknown setting 'world.options.tension_noise_n'"):
        _settings("synthetic", world__options__tension_noise_n=0.5)
    with pytest.raises(UserError, match="world.options.tension_noise_n: 'loud'"):
        _settings("sim", world__options__tension_noise_n="loud")
    from vlr.world import open_world

    w = open_world(_settings("sim", filter__particles=50, world__options__tension_noise_n=0.5))
    try:
        assert w.hand.options.tension_noise_n == 0.5
    finally:
        w.close()

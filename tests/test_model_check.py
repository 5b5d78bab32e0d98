"""The model check (`vlr.model_check`): the observation's surprise under the estimator's
predictive, calibrated where the observation is drawn from that predictive and large where
it is not; the trial's verdict; and that the check never moves the estimate."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel
from vlr.model_check import ModelCheckConfig, nis_surprise, predictive_surprise, verdict
from vlr.motion import MotionConfig, ObjectParams
from vlr.observation import ObservationConfig, ObservationModel, PomObservation
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def _cloud(rng, k=400):
    """K predicted poses about a grasp (1 mm, 2 deg apart) and anchors of three fingers."""
    pos = np.array([0.0, 0.0, 0.1]) + 1e-3 * rng.standard_normal((k, 3))
    rot = Rotation.from_rotvec(np.radians(2.0) * rng.standard_normal((k, 3))).as_matrix()
    anchors = np.array([[0.03, 0.0, 0.0], [-0.02, 0.02, 0.0], [-0.02, -0.02, 0.0]])
    return pos, rot, np.broadcast_to(anchors, (k, 3, 3)).copy()


@pytest.mark.parametrize("turn_deg", [0.0, 1.0])
def test_an_observation_drawn_from_the_predictive_scores_about_zero(turn_deg):
    """Observations drawn from the particles' predictive (a particle, then the likelihood's
    noise, the turn's included) score a mean surprise near 0 and never far above it; one
    a few of the likelihood's widths off the cloud scores high."""
    obs_model = ObservationModel(ObservationConfig(sigma_pos_mm=0.5, sigma_rot_deg=1.0,
                                                   sigma_turn_deg=turn_deg))
    rng = np.random.default_rng(0)
    pos, rot, anchors = _cloud(rng)
    z = []
    for _ in range(150):
        j = rng.integers(len(pos))
        p = pos[j] + obs_model.sigma_pos * rng.standard_normal(3)
        r = Rotation.from_rotvec(obs_model.sigma_rot * rng.standard_normal(3)).as_matrix() @ rot[j]
        z.append(predictive_surprise(pos, rot, anchors, obs_model, PomObservation(p, r), None,
                                     rng, 64))
    assert abs(np.mean(z)) < 0.25
    assert np.quantile(z, 0.95) < 2.5
    far = PomObservation(pos.mean(0) + [0.006, 0.0, 0.0], rot[0])
    assert predictive_surprise(pos, rot, anchors, obs_model, far, None, rng, 64) > 5.0


def test_the_tensions_enter_the_surprise():
    """A tension reading far from every particle's prediction is surprising even when the
    pose is not."""
    obs_model = ObservationModel(ObservationConfig(sigma_tension_n=0.5))
    rng = np.random.default_rng(1)
    pos, rot, anchors = _cloud(rng)
    t = 5.0 + 0.2 * rng.standard_normal((len(pos), 3))

    class Seen:
        position, rotation = pos[0], rot[0]
        tensions = np.array([5.0, 5.0, 5.0])

    calm = predictive_surprise(pos, rot, anchors, obs_model, Seen, t, rng, 64)
    Seen.tensions = np.array([9.0, 5.0, 5.0])
    assert predictive_surprise(pos, rot, anchors, obs_model, Seen, t, rng, 64) > calm + 5.0


def test_the_nis_score_of_chi2_draws_is_about_zero():
    rng = np.random.default_rng(2)
    z = [nis_surprise(x, 6) for x in rng.chisquare(6, 4000)]
    assert abs(np.mean(z)) < 0.05 and abs(np.std(z) - 1.0) < 0.05


def test_the_verdict():
    cfg = ModelCheckConfig(threshold=-1.0, burn_in=2, min_actions=3)
    calm = [5.0, 5.0, 5.0] + [-1.5] * 10
    out = verdict(calm, cfg)
    assert out["verdict"] == "consistent" and out["statistic"] == -1.5
    assert out["first_action_flagged"] is None and out["actions"] == 10
    # The running mean rises above -1 at action 8 (update 8) and stays there.
    late = [0.0] * 3 + [-1.5] * 5 + [3.0] * 5
    out = verdict(late, cfg)
    assert out["verdict"] == "inconsistent" and out["first_action_flagged"] == 8
    # Too few actions after the burn-in; frames the camera dropped are not counted.
    short = verdict([0.0, 0.0, 0.0, 1.0, float("nan"), 1.0], cfg)
    assert short["verdict"] == "undecided" and short["statistic"] is None
    assert short["surprise_by_iteration"][4] is None


def test_a_trial_that_weighs_tensions_takes_their_threshold():
    cfg = ModelCheckConfig(threshold=-1.25, threshold_tensions=-1.15, burn_in=0,
                           min_actions=3)
    between = [-1.2] * 5
    assert verdict(between, cfg)["verdict"] == "inconsistent"
    out = verdict(between, cfg, tensions=True)
    assert out["verdict"] == "consistent" and out["threshold"] == -1.15


def test_a_sim_trial_reading_tensions_reports_their_threshold():
    """`result.json`'s model check takes `threshold_tensions` when the likelihood weighs the
    sim's tensions, `threshold` when it does not (`vlr.results.summarize`)."""
    from vlr.run import run_identification
    from vlr.settings import load_settings

    base = {"world.backend": "sim", "world.object": "apple", "filter.particles": 300,
            "loop.max_iterations": 1, "filter.model_check.threshold": -1.3,
            "filter.model_check.threshold_tensions": -0.9}
    for sigma_t, want in ((0.0, -1.3), (0.5, -0.9)):
        run = run_identification(load_settings(
            {**base, "filter.observation.sigma_tension_n": sigma_t}))
        assert run.summary["model_check"]["threshold"] == want


@pytest.mark.parametrize("bad", [{"threshold": math.nan}, {"threshold_tensions": math.inf},
                                 {"burn_in": -1},
                                 {"min_actions": 0}, {"particles": 4}, {"replicates": 2}])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ModelCheckConfig(**bad)


def _trial(model, check: ModelCheckConfig, true_model=None, steps=6):
    world = SyntheticWorld(true_model or model, OBJ, SyntheticConfig(seed=0), nominal_model=model)
    u = world.grasp()
    cfg = FilterConfig(particles=600, motion=MotionConfig(rolling=False), contact_prior="pad",
                       observation=ObservationConfig(sigma_pos_mm=0.1, sigma_rot_deg=0.4),
                       model_check=check)
    f = ParticleFilter(model, OBJ, cfg, seed=0)
    f.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(1)
    for _ in range(steps):
        u = world.apply(random_action(rng, 3))
        f.step(u, world.observe())
    return f


def test_the_check_never_moves_the_estimate(modelo):
    """Its draws are its own: other check settings, the same particles."""
    a = _trial(modelo, ModelCheckConfig())
    b = _trial(modelo, ModelCheckConfig(particles=64, replicates=16))
    assert np.array_equal(a.pack(a.state), b.pack(b.state))
    sa = [r.surprise for r in a.history]
    assert np.isfinite(sa).all() and sa != [r.surprise for r in b.history]


def _synthetic_check(seed: int, particles: int, **layer) -> dict:
    """The model check of a 12-action trial in the synthetic world (its backend's own
    threshold), the apple held."""
    from vlr.run import run_identification
    from vlr.settings import load_settings

    settings = load_settings({"world.backend": "synthetic", "world.object": "apple",
                              "filter.particles": particles, "seed": seed,
                              "loop.max_iterations": 12, "loop.stop_on_convergence": False,
                              **layer})
    return run_identification(settings).summary["model_check"]


def test_the_known_hand_is_consistent():
    """The model the world is made of explains it: measured -1.07 / -1.16 / -1.05 against
    the synthetic world's threshold -0.23 (6,000 particles)."""
    for seed in range(3):
        check = _synthetic_check(seed, 6000)
        assert check["verdict"] == "consistent", (seed, check["statistic"])


def test_an_undeclared_finger_is_flagged():
    """NH1's links, the filter not told: measured 24 and 28 (3,000 particles), flagged from
    the first action a verdict is given at."""
    for seed in range(2):
        check = _synthetic_check(seed, 3000, **{"world.true_hand": "nh1"})
        assert check["verdict"] == "inconsistent", (seed, check["statistic"])
        assert check["first_action_flagged"] == 8


def test_the_cli_line():
    from vlr.commands.identify import format_model_check

    cfg = ModelCheckConfig(threshold=-1.0, burn_in=2, min_actions=3)
    assert "explains" in format_model_check(verdict([0.0] * 3 + [-1.5] * 5, cfg))
    line = format_model_check(verdict([0.0] * 3 + [1.0] * 5, cfg))
    assert "does NOT explain" in line and "from action 5 on" in line
    assert "undecided" in format_model_check(verdict([0.0] * 4, cfg))

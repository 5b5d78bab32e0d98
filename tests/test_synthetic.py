"""Synthetic world and the identification loop (Algorithm 1 on model-consistent data)."""

import numpy as np
import pytest

from vlr.filter import FilterConfig
from vlr.identify import LoopConfig, identify
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, ObjectParams
from vlr.observation import rotation_angle
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))


def filter_config(particles: int) -> FilterConfig:
    """A filter of the synthetic world's own model (pinned contacts), its prior about the
    pads' contacts, as the synthetic backend runs it."""
    return FilterConfig(particles=particles, motion=MotionConfig(rolling=False),
                        contact_prior="pad")


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def test_world_moves_and_observes_with_noise(modelo):
    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0))
    u0 = world.grasp()
    t0 = world.truth()
    obs = [world.observe() for _ in range(200)]
    pos = np.array([o.position for o in obs])
    assert np.std(pos - t0.position, axis=0) == pytest.approx([5e-5] * 3, rel=0.25)
    ang = rotation_angle(np.array([o.rotation for o in obs]), t0.rotation)
    assert 0.1 < np.degrees(np.median(ang)) < 0.5
    rng = np.random.default_rng(0)
    delta = random_action(rng, 3)
    assert np.all((np.abs(delta) >= 2e-4) & (np.abs(delta) <= 4e-4))
    u1 = world.apply(delta)
    np.testing.assert_allclose(u1, u0 + delta)
    assert np.linalg.norm(world.truth().position - t0.position) > 1e-6


def test_truth_is_used_only_for_scoring(modelo):
    """Identical runs with and without the truth callable: the filter never sees it."""
    def run(with_truth):
        world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=2))
        return identify(world, world.observe, modelo, OBJ, world.nominal, filter_config(300),
                        LoopConfig(max_iterations=2), seed=4,
                        truth=world.truth if with_truth else None)

    a, b = run(True), run(False)
    assert len(a.scores) == len(a.history) and not b.scores
    np.testing.assert_array_equal(a.history[-1].posterior.mean, b.history[-1].posterior.mean)


def nh1_world(probe_action: float) -> SyntheticWorld:
    """NH1 seed 2 as `vlr.world.open_world` builds it, with the given stability probe."""
    nh1 = HandModel.from_spec(load_hand("nh1"))
    nominal = HandModel.from_spec(load_hand("modelo"))
    return SyntheticWorld(nh1, OBJ, SyntheticConfig(seed=2, probe_action=probe_action),
                          nominal_model=nominal)


def test_a_snap_through_is_a_lost_grasp():
    """NH1, seed 2: the first truth drawn sits at a fold of the energy and a 0.3 mm action
    flips the thumb by over 60 degrees, in 16 steps as in one (64 too). Without the stability
    probe the world reports a lost grasp (a GraspError naming the joint), not a new
    configuration the filter cannot follow by construction."""
    from vlr.hand import GraspError

    world = nh1_world(probe_action=0.0)
    world.grasp()
    with pytest.raises(GraspError, match="thumb.1 turned .* in 16 steps"):
        world.apply(np.array([0.217e-3, 0.247e-3, -0.36e-3]))


def test_a_grasp_at_a_fold_is_drawn_again():
    """With the probe (the default) that truth is rejected and redrawn; the new one takes the
    largest actions (0.4 mm) without a snap."""
    world = nh1_world(probe_action=0.4e-3)
    world.grasp()
    assert world.regrasps >= 1
    start = world.truth().theta
    for signs in ([1, 1, -1], [-1, -1, 1], [1, -1, 1]):
        world.apply(0.4e-3 * np.array(signs, dtype=float))
        world.apply(-0.4e-3 * np.array(signs, dtype=float))
    assert np.degrees(np.abs(world.truth().theta - start).max()) < 14


def test_a_large_continuous_turn_is_followed_not_called_a_snap():
    """NH1 seed 1's left distal turns 16 degrees on one 0.33-0.38 mm action: more than the
    one-solve snap test, but continuous when the action is followed in steps."""
    from vlr.settings import load_settings
    from vlr.world import open_world

    w = open_world(load_settings({"world.backend": "synthetic", "seed": 1,
                                  "world.true_hand": "nh1",
                                  "filter.unknowns": ["length:left.proximal"]}))
    w.world.grasp()
    before = w.world.truth().theta
    w.world.apply(np.array([0.334e-3, 0.381e-3, 0.373e-3]))
    assert np.degrees(np.abs(w.world.truth().theta - before).max()) > 1


def test_the_filter_follows_what_the_world_calls_continuous(modelo):
    """Seed 0's second action turns the right distal joint 38 degrees, continuously (16 steps
    of at most 13 degrees; one solve does not converge). The filter's motion model follows
    it from the true configuration to the world's (`MotionConfig.follow_substeps`), where a
    one-solve jump test would drop the truth."""
    from vlr.motion import MotionModel

    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0))
    world.grasp()
    rng = np.random.default_rng(1)
    u1 = world.apply(random_action(rng, 3))
    start = world.state.copy()
    u2 = world.apply(random_action(rng, 3))
    assert np.degrees(np.abs(world.state.theta - start.theta).max()) > 30
    status, _ = MotionModel(modelo, OBJ, world.config.motion).solve(start, u2, u_from=u1)
    assert not world.config.motion.rolling   # the synthetic world's pinned contacts
    assert status[0] == 0
    np.testing.assert_allclose(start.theta, world.state.theta, atol=1e-9)


def rolling_toy_block_world() -> SyntheticWorld:
    """The toy block held by the thumb45 hand at the sim's grasp guess (-10, 15) degrees with
    rolling contacts and the sim's stops (17 N m/rad), seed 0."""
    from vlr.spec import load_object

    motion = MotionConfig(rolling=True, limit_stiffness=17.0)
    cfg = SyntheticConfig(seed=0, grasp_theta=tuple(np.radians([-10.0, 15.0])), motion=motion)
    return SyntheticWorld(HandModel.from_spec(load_hand("modelo_thumb45")),
                          ObjectParams.from_spec(load_object("toy_block")), cfg)


def truth_particle_gaps(actions: int = 21) -> tuple[np.ndarray, int]:
    """The POM position error [m] of the filter's own solve from the world's true state
    against the world's next state, action by action, and how many of the actions one solve
    (without `MotionConfig.follow_substeps`) does not make."""
    from dataclasses import replace

    from vlr.motion import MotionModel

    world = rolling_toy_block_world()
    model = MotionModel(world.model, world.motion.obj, world.config.motion)
    one_solve = MotionModel(world.model, world.motion.obj,
                            replace(world.config.motion, follow_substeps=0))
    world.grasp()
    rng = np.random.default_rng(100)
    gaps, followed = [], 0
    for _ in range(actions):
        particle, u = world.state.copy(), world.commands
        delta = random_action(rng, 3)
        status, _ = model.solve(particle, u + delta, u_from=u)
        assert status[0] == 0, f"action {len(gaps) + 1}: the truth's solve failed ({status[0]})"
        followed += int(one_solve.solve(world.state.copy(), u + delta, u_from=u)[0][0] != 0)
        world.apply(delta)
        gaps.append(np.linalg.norm(particle.pos[0] - world.state.pos[0]))
    return np.array(gaps), followed


def test_a_particle_at_the_truth_follows_the_world_exactly():
    """The world solves an action as a filter particle does (`SyntheticWorld.apply`), so the
    synthetic world has no model-world gap, even on a move the particle must follow in steps
    (one of these 21 actions of a rolling grasp does not converge in one solve)."""
    gaps, followed = truth_particle_gaps()
    assert gaps.max() < 1e-9
    assert followed >= 1


@pytest.mark.parametrize("kw", [{"max_regrasps": -1}, {"probe_action": -1e-3},
                                {"snap_theta": 0.0}])
def test_bad_world_settings_are_named(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        SyntheticConfig(**kw)


def test_a_grasp_guess_of_the_wrong_size_is_named(modelo):
    from vlr.synthetic import nominal_grasp

    with pytest.raises(ValueError, match=r"grasp_theta .*: give 2 angles .* or 6"):
        nominal_grasp(modelo, OBJ, SyntheticConfig(grasp_theta=(-0.2, 0.3, 0.1)))


def test_identification_stops_where_the_hand_reports_the_grasp_lost(modelo):
    """The VLR assumes a fingertip grasp (Eq. 8): once the hand says it is lost, the run
    stops before that action's update and says so."""
    from vlr.hand import ApplyReport

    class Dropping:
        def __init__(self, world, at):
            self.world, self.at, self.n = world, at, 0

        def grasp(self):
            return self.world.grasp()

        def apply(self, delta):
            self.n += 1
            u = self.world.apply(delta)
            return ApplyReport(commands=u, settled=True, grasp_held=self.n < self.at,
                               message="fingertips ['left'] lost contact")

    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0))
    cfg, loop = filter_config(300), LoopConfig(max_iterations=6)
    res = identify(Dropping(world, 3), world.observe, modelo, OBJ, world.nominal, cfg, loop)
    assert res.grasp_lost_at == 3 and "left" in res.grasp_message
    assert res.iterations == 2 and len(res.history) == 3  # the grasp's update and two actions
    held = identify(Dropping(SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=0)), 99),
                    world.observe, modelo, OBJ, world.nominal, cfg, loop)
    assert held.grasp_lost_at is None and held.iterations == 6


def test_a_heavy_believed_object_still_gives_a_settled_grasp_guess():
    """The guess's settle has no history, so the pads' sliding does not hold it: with it, the
    gelatin box believed twice its mass slid off its start and the run ended in a traceback."""
    from vlr import load_settings
    from vlr.spec import load_object
    from vlr.world import believed_object, grasp_guess

    settings = load_settings({"world.backend": "sim", "world.object": "gelatin_box",
                              "filter.object.mass": 0.194})
    assert settings.filter.motion.friction  # the sim's model slides
    model = HandModel.from_spec(load_hand(settings.world.hand))
    guess = grasp_guess(settings, model, believed_object(settings, load_object("gelatin_box")))
    assert np.all(np.isfinite(guess.theta))

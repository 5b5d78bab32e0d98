"""Active exploration (vlr.active): the spread score and the choice among candidates."""

import numpy as np
import pytest

from vlr.active import ActiveExploration, choose_action, expected_joint_sd, prediction_spread
from vlr.errors import UserError
from vlr.explore import ExplorationRange, random_action
from vlr.motion import rotvec_to_matrix
from vlr.trial import TrialSettings, run_trial


def test_spread_grows_with_disagreement_in_likelihood_units():
    rng = np.random.default_rng(0)
    rot = rotvec_to_matrix(rng.normal(0, 0.01, (50, 3)))
    pos = rng.normal(0, 1e-3, (50, 3))
    tight = prediction_spread(0.1 * pos, rot, 5e-4, 0.02)
    wide = prediction_spread(pos, rot, 5e-4, 0.02)
    assert 0 < tight < wide
    # A wider likelihood makes the same disagreement count for less.
    assert prediction_spread(pos, rot, 5e-3, 0.02) < wide
    assert prediction_spread(pos[:1], rot[:1], 5e-4, 0.02) == 0.0


class _FakeState:
    """Particles whose POM starts at the origin; `gain` sets how each reacts to tendon 0."""

    def __init__(self, gain):
        self.gain = gain
        self.valid = np.ones(len(gain), dtype=bool)
        self.pos = np.zeros((len(gain), 3))
        self.rot = np.broadcast_to(np.eye(3), (len(gain), 3, 3)).copy()

    def take(self, idx):
        return _FakeState(self.gain[idx])

    def copy(self):
        s = _FakeState(self.gain.copy())
        s.pos, s.rot = self.pos.copy(), self.rot.copy()
        return s


def _fake_filter(common_gain: float, sigma_pos: float):
    """A filter whose motion model moves particle p's POM along x by gain_p x delta_0 (they
    disagree) and along y by common_gain x delta_1 (they agree), gains 0.5-1.5."""

    class Motion:
        def solve(self, st, u, u_from=None):
            d = u - u_from
            st.pos[:, 0] = st.gain * d[0]
            st.pos[:, 1] = common_gain * d[1]

    class Obs:
        pass

    Obs.sigma_pos, Obs.sigma_rot, Obs.sigma_turn, Obs.opposed = sigma_pos, 0.02, 0.0, 0

    class Config:
        observation = Obs()

    class PF:
        state = _FakeState(np.linspace(0.5, 1.5, 100))
        motion = Motion()
        config = Config()

    return PF()


EXPLORE = ExplorationRange(low=1e-4, high=4e-4, band=4e-4)


def test_choice_is_the_candidate_with_the_widest_prediction():
    """Only tendon 0 makes the particles disagree: the largest |delta_0| spreads the most."""
    u = np.zeros(3)
    picked = choose_action(_fake_filter(0.0, 5e-4), np.random.default_rng(1), u, u, EXPLORE,
                           ActiveExploration(candidates=6, subset=50))
    cands_rng = np.random.default_rng(1)
    cands = [random_action(cands_rng, u, u, EXPLORE) for _ in range(6)]
    assert np.allclose(picked, max(cands, key=lambda d: abs(d[0])))


def test_model_error_discounts_a_large_common_motion():
    """Tendon 1 moves every particle by the same large amount, which the particles agree on
    but the model predicts worst. With a model error the choice weighs the disagreement
    against the motion."""
    pf = _fake_filter(20.0, 5e-5)
    u = np.zeros(3)
    rng = np.random.default_rng(4)   # as choose_action draws: the candidates, then the subset
    cands = [random_action(rng, u, u, EXPLORE) for _ in range(8)]
    gain = pf.state.gain[rng.choice(100, size=50, replace=False)]

    def expected(kappa):
        def score(d):
            moved = np.hypot(gain * d[0], 20.0 * d[1]).mean()
            return np.var(gain * d[0]) / (5e-5**2 + (kappa * moved) ** 2)
        return max(cands, key=score)

    picks = {k: choose_action(pf, np.random.default_rng(4), u, u, EXPLORE,
                              ActiveExploration(candidates=8, subset=50, model_error=k))
             for k in (0.0, 0.5)}
    assert np.allclose(picks[0.0], expected(0.0))
    assert np.allclose(picks[0.5], expected(0.5))
    assert not np.allclose(picks[0.0], picks[0.5])


@pytest.mark.parametrize("bad", [dict(candidates=0), dict(subset=1.5), dict(model_error=-0.1)])
def test_bad_active_settings(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ActiveExploration(**bad)


def test_active_identification_runs_end_to_end():
    r = run_trial(TrialSettings(backend="synthetic", particles=500, seed=0, max_iterations=3,
                                exploration="active"))
    assert r["iterations"] >= 1 and np.isfinite(r["errors"]["proximal_deg_mean"])


def test_expected_joint_sd_is_small_when_the_pose_tells_the_joints():
    rng = np.random.default_rng(0)
    n = 400
    rotvec = rng.normal(0, 0.02, (n, 3))
    rot = rotvec_to_matrix(rotvec)
    pos = rng.normal(0, 1e-3, (n, 3))
    told = np.concatenate([pos * 100, rotvec * 10], axis=1)  # the joints follow the pose
    untold = rng.normal(0, 0.05, (n, 6))                      # the joints do not
    prior = untold.std(axis=0, ddof=1).mean()
    sp, sr = 1e-5, 1e-4
    assert expected_joint_sd(told, pos, rot, sp, sr) < 0.02 * told.std(axis=0).mean()
    assert abs(expected_joint_sd(untold, pos, rot, sp, sr) - prior) < 0.1 * prior
    # A wide likelihood learns little: the posterior stays near the prior.
    wide = expected_joint_sd(told, pos, rot, 1.0, 10.0)
    assert abs(wide - told.std(axis=0, ddof=1).mean()) < 0.01 * wide


def test_active_variance_identification_runs_end_to_end():
    r = run_trial(TrialSettings(backend="synthetic", particles=500, seed=0, max_iterations=3,
                                exploration="active", active_criterion="variance"))
    assert r["iterations"] >= 1 and np.isfinite(r["errors"]["proximal_deg_mean"])
    with pytest.raises(UserError, match="criterion"):
        TrialSettings(exploration="active", active_criterion="entropy")


def test_the_force_screen_needs_rolling_and_runs_end_to_end():
    r = run_trial(TrialSettings(backend="synthetic", particles=300, seed=0, max_iterations=2,
                                rolling=True, exploration="active",
                                active_criterion="variance", active_min_force_n=0.05))
    assert r["iterations"] >= 1 and np.isfinite(r["errors"]["proximal_deg_mean"])
    with pytest.raises(UserError, match="rolling"):
        TrialSettings(backend="synthetic", rolling=False, active_min_force_n=0.05)
    with pytest.raises(ValueError, match="min_normal_force"):
        ActiveExploration(min_normal_force=-1.0)


def test_the_force_screen_passes_over_a_candidate_that_parts_a_contact(monkeypatch):
    """Candidates after which a finger's predicted normal force falls under the screen's are
    not taken, whatever their information; if all are, the one that keeps the most force."""
    import vlr.active as active
    from vlr.filter import ParticleFilter
    from vlr.trial import identify_config, open_world

    ts = TrialSettings(backend="synthetic", particles=200, seed=0, rolling=True)
    world = open_world(ts)
    pf = ParticleFilter(world.model, world.obj, identify_config(ts, world.model).filter)
    u = np.asarray(world.world.grasp(), float)
    pf.initialize(world.observer(), u, world.nominal.theta, world.nominal.contact)
    explore = ExplorationRange(2e-4, 4e-4, 4e-4)
    settings = ActiveExploration(candidates=3, subset=50, min_normal_force=0.05)
    draw = np.random.default_rng(5)  # the candidates choose_action draws from the same seed
    cands = [random_action(draw, u, u, explore) for _ in range(3)]

    def choose_with(forces: list[float]) -> np.ndarray:
        calls = iter(forces)
        monkeypatch.setattr(active, "_normal_forces",
                            lambda pf_, st: np.full((st.n, 3), next(calls)))
        return choose_action(pf, np.random.default_rng(5), u, u, explore, settings)

    np.testing.assert_allclose(choose_with([0.0, 0.01, 1.0]), cands[2])
    np.testing.assert_allclose(choose_with([0.0, 0.03, 0.01]), cands[1])  # all under: safest


def test_a_spread_along_the_turn_counts_for_little_with_the_turn_term():
    """`noise_covariance`'s turn term: outcomes that differ only along the turn direction
    v are worth little, outcomes off it as much as without the term."""
    rng = np.random.default_rng(1)
    v = np.array([0.0, 0.04, 0.0, 1.0, 0.0, 0.0])  # the POM's motion per radian of turn
    a = rng.normal(0, 0.01, 200)                    # radians of turn per particle
    along = a[:, None] * v
    off = np.zeros((200, 6))
    off[:, 2], off[:, 4] = 4e-4 * rng.standard_normal(200), 0.01 * rng.standard_normal(200)
    sp, sr, st = 2e-4, np.radians(0.4), np.radians(1.0)
    for y, cut in ((along, 0.2), (off, 0.99)):
        pos, rot = y[:, :3], rotvec_to_matrix(y[:, 3:])
        plain = prediction_spread(pos, rot, sp, sr)
        turned = prediction_spread(pos, rot, sp, sr, v, st)
        assert turned <= plain
        assert (turned < cut * plain) == (cut < 0.5)
    # The joints follow the turn only: the turn term leaves them near their prior spread.
    told = np.stack([a, -a], axis=1)
    pos, rot = along[:, :3], rotvec_to_matrix(along[:, 3:])
    prior = told.std(axis=0, ddof=1).mean()
    plain, turned = (expected_joint_sd(told, pos, rot, sp, sr),
                     expected_joint_sd(told, pos, rot, sp, sr, v, st))
    assert plain < 0.5 * prior and turned > 0.8 * prior, (plain / prior, turned / prior)


def test_active_choice_with_the_turn_term_runs_end_to_end():
    r = run_trial(TrialSettings(backend="synthetic", particles=500, seed=0, max_iterations=3,
                                exploration="active", active_criterion="variance",
                                sigma_turn_deg=1.0))
    assert r["iterations"] >= 1 and np.isfinite(r["errors"]["proximal_deg_mean"])

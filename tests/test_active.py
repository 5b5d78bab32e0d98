"""Active exploration (vlr.active): the spread score and the choice among candidates."""

import numpy as np
import pytest

from vlr.active import ActiveExploration, choose_action, prediction_spread
from vlr.errors import UserError
from vlr.explore import ExplorationRange, random_action
from vlr.motion import rotvec_to_matrix
from vlr.settings import load_settings


def _run(**dotted) -> dict:
    """A short synthetic identification's result.json (`vlr.run.run_identification`)."""
    from vlr.run import run_identification

    settings = load_settings({"world.backend": "synthetic", "filter.particles": 500,
                              "seed": 0, "loop.max_iterations": 3},
                             {k.replace("__", "."): v for k, v in dotted.items()})
    return run_identification(settings).summary


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

    class PF:
        state = _FakeState(np.linspace(0.5, 1.5, 100))
        motion = Motion()
        obs_model = Obs()

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


@pytest.mark.parametrize("bad", [dict(candidates=0), dict(subset=1.5), dict(subset=True)])
def test_bad_active_settings(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ActiveExploration(**bad)
    key = f"loop.active.{next(iter(bad))}"
    with pytest.raises(UserError, match=key):
        load_settings({key: next(iter(bad.values()))})


def test_active_identification_runs_end_to_end_and_chooses_its_own_actions():
    random = _run()
    active = _run(loop__exploration="active", loop__active__candidates=4,
                  loop__active__subset=64)
    assert active["iterations"] >= 1 and np.isfinite(active["errors"]["proximal_deg_mean"])
    assert active["settings"]["loop.exploration"] == "active"
    assert active["settings"]["loop.active.candidates"] == 4
    # the same grasp, then other actions than the seed's random stream
    assert active["commands_mm_by_iteration"][0] == random["commands_mm_by_iteration"][0]
    assert active["commands_mm_by_iteration"][1:] != random["commands_mm_by_iteration"][1:]


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


def test_active_choice_with_the_turn_term_runs_end_to_end():
    r = _run(loop__exploration="active", filter__observation__sigma_turn_deg=1.0)
    assert r["iterations"] >= 1 and np.isfinite(r["errors"]["proximal_deg_mean"])
    assert r["settings"]["filter.observation.sigma_turn_deg"] == 1.0

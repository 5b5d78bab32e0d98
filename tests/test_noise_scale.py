"""The size of the model's error as an unknown ("noise": `vlr.observation`, "The model error's
size"; `vlr.filter.parse_unknown`). Checked here: each particle's factor s makes its pose
likelihood the Gaussian with covariance s^2 Sigma (normalisation included, or a wide
tolerance would be free), s = 1 changes nothing, the spec and its prior are checked, and on
the synthetic world, whose observation noise is half the likelihood's scales, the filter
identifies a factor below 1 and scores nothing against it (it has no true value)."""

import math
import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.filter import NOISE_PRIOR, parse_unknown
from vlr.kinematics import HandModel
from vlr.observation import ObservationModel, PomObservation, grasp_turn, rotation_error
from vlr.spec import load_hand


def _particles(n: int = 5, seed: int = 0, noise=None) -> types.SimpleNamespace:
    rng = np.random.default_rng(seed)
    st = types.SimpleNamespace(pos=rng.normal(size=(n, 3)) * 3e-4,
                               rot=Rotation.random(n, random_state=seed).as_matrix(),
                               anchors=rng.normal(size=(n, 3, 3)) * 0.03,
                               valid=np.ones(n, bool))
    if noise is not None:
        st.noise = np.asarray(noise, dtype=float)
    return st


def _obs(st) -> PomObservation:
    return PomObservation(st.pos[0] + 2e-4,
                          Rotation.from_rotvec([0.004, -0.006, 0.002]).as_matrix() @ st.rot[0])


@pytest.mark.parametrize("turn", [0.0, 0.012])
def test_the_factor_scales_the_covariance_of_the_dense_gaussian(turn):
    s = np.array([0.25, 0.5, 1.0, 0.7, 0.3])
    st = _particles(noise=s)
    obs = _obs(st)
    om = ObservationModel(sigma_pos=2e-4, sigma_rot=0.004, sigma_turn=turn, opposed=1)
    ll = om.log_likelihood(st, obs)
    d = np.diag(np.repeat([om.sigma_pos ** 2, om.sigma_rot ** 2], 3))
    v = grasp_turn(st.pos, st.rot, st.anchors, 1)
    ref = []
    for i in range(len(ll)):
        if turn:
            e = np.concatenate([st.pos[i] - obs.position,
                                rotation_error(st.rot[i], obs.rotation)])
        else:  # the isotropic form weighs the position error and the rotation angle
            e = np.concatenate([st.pos[i] - obs.position,
                                [0.0, 0.0, np.linalg.norm(rotation_error(st.rot[i],
                                                                         obs.rotation))]])
        cov = s[i] ** 2 * (d + turn ** 2 * np.outer(v[i], v[i]))
        ref.append(-0.5 * e @ np.linalg.solve(cov, e)
                   - 0.5 * (np.linalg.slogdet(cov)[1] - np.linalg.slogdet(d)[1]))
    np.testing.assert_allclose(ll, ref, rtol=1e-9)


def test_a_factor_of_one_changes_nothing():
    om = ObservationModel(sigma_pos=2e-4, sigma_rot=0.004, sigma_turn=0.012)
    with_s = _particles(noise=np.ones(5))
    without = _particles()
    np.testing.assert_array_equal(om.log_likelihood(with_s, _obs(with_s)),
                                  om.log_likelihood(without, _obs(without)))


def test_the_noise_spec_and_its_prior():
    model = HandModel.from_spec(load_hand("modelo"))
    u = parse_unknown("noise", model)
    assert (u.kind, u.prior) == ("noise", NOISE_PRIOR)
    assert parse_unknown("noise", model, (0.5, 2.0)).prior == (0.5, 2.0)
    with pytest.raises(ValueError, match="takes no finger"):
        parse_unknown("noise:thumb", model)
    with pytest.raises(ValueError, match=r"noise prior \(0.0, 1.0\)"):
        parse_unknown("noise", model, (0.0, 1.0))


def test_the_synthetic_worlds_noise_is_identified_below_the_likelihoods_scales(tmp_path):
    """The synthetic world observes the POM with 0.05 mm / 0.2 degree of noise and weighs it
    at 0.1 mm / 0.4 degree (`vlr.trial.DEFAULT_SIGMA`): the particles that fit leave
    residuals under the scales, so the factor falls below 1. Without the normalisation it
    would not (a wider tolerance would cost nothing) and pile at the prior's top."""
    from vlr.trial import TrialSettings, run_trial

    summary = run_trial(TrialSettings(backend="synthetic", particles=2000, max_iterations=12,
                                      seed=0, unknowns=("noise",)), out=tmp_path)
    est = summary["unknown_estimates"]["noise"]
    assert est["high"] < 1.0 and est["median"] < 0.9
    # Nothing is scored against it: it has no true value.
    assert "noise" not in str(summary["errors"])
    hist = np.load(tmp_path / "history.npz")
    assert np.isnan(hist["truth_unknowns"][:, 0]).all()


def test_the_sweep_row_gives_the_identified_factor():
    from vlr.sweep import _row, summarize_rows

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"errors": {}, "unknown_estimates": {"noise": {"median": 0.42}}}}
    row = _row(rec)
    assert row["noise_scale"] == 0.42
    assert summarize_rows([row])[0]["noise scale"] == "0.42"
    del rec["result"]["unknown_estimates"]["noise"]
    assert "noise_scale" not in _row(rec)


def test_a_trials_noise_prior_reaches_the_filter_and_bad_ones_are_named():
    from vlr.errors import UserError
    from vlr.trial import TrialSettings, identify_config

    model = HandModel.from_spec(load_hand("modelo"))
    s = TrialSettings(backend="synthetic", unknowns=["noise"], noise_prior=[0.5, 1])
    assert identify_config(s, model).filter.priors == {"noise": (0.5, 1.0)}
    assert s.to_dict()["noise_prior"] == [0.5, 1.0]
    with pytest.raises(UserError, match="noise_prior"):
        TrialSettings(backend="synthetic", unknowns=["noise"], noise_prior=[0.0, 1.0])
    with pytest.raises(UserError, match="noise_prior"):
        TrialSettings(backend="synthetic", unknowns=["noise"], noise_prior=[0.5, math.inf])
    with pytest.raises(UserError, match="add it to unknowns"):
        TrialSettings(backend="synthetic", noise_prior=[0.5, 1.0])


def test_the_bound_refuses_the_noise_unknown():
    """`vlr crb` bounds the filter at its given scales; a sampled factor on them has no
    place in that linearisation, so it says so in one line."""
    from sim.crb import CrbSettings
    from vlr.errors import UserError
    from vlr.trial import TrialSettings

    with pytest.raises(UserError, match="unknown 'noise'"):
        CrbSettings(trial=TrialSettings(backend="sim", unknowns=("noise",)))

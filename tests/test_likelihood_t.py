"""The Student-t pose likelihood (`vlr.observation`, "Heavy tails"; `ObservationModel.dof`).
Checked here: with the turn term it is the multivariate t of the same scale matrix (SciPy's
density, up to one constant shared by all particles), a large nu gives back the Gaussian,
an outlying particle loses less to a good one than under the Gaussian, a frame far from
every particle leaves the weights spread where the Gaussian piles them on a few, and a bad
nu names itself."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import multivariate_t

from tests.test_noise_scale import _obs, _particles
from vlr.errors import UserError
from vlr.observation import ObservationModel, PomObservation, grasp_turn, rotation_error
from vlr.trial import TrialSettings

SIGMA = dict(sigma_pos=2e-4, sigma_rot=0.004, sigma_turn=0.012, opposed=1)


def test_it_is_the_multivariate_t_of_the_turns_scale_matrix():
    st, nu = _particles(n=6), 4.0
    obs = _obs(st)
    ll = ObservationModel(**SIGMA, dof=nu).log_likelihood(st, obs)
    d = np.diag(np.repeat([SIGMA["sigma_pos"] ** 2, SIGMA["sigma_rot"] ** 2], 3))
    v = grasp_turn(st.pos, st.rot, st.anchors, 1)
    ref = []
    for i in range(len(ll)):
        e = np.concatenate([st.pos[i] - obs.position, rotation_error(st.rot[i], obs.rotation)])
        shape = d + SIGMA["sigma_turn"] ** 2 * np.outer(v[i], v[i])
        ref.append(multivariate_t(np.zeros(6), shape, df=nu).logpdf(e))
    offset = ll - np.array(ref)
    np.testing.assert_allclose(offset, offset[0], rtol=0, atol=1e-9)


def test_a_large_nu_is_the_gaussian():
    st = _particles(n=6)
    obs = _obs(st)
    gauss = ObservationModel(**SIGMA).log_likelihood(st, obs)
    t = ObservationModel(**SIGMA, dof=1e15).log_likelihood(st, obs)
    np.testing.assert_allclose(t, gauss, rtol=1e-6)


def test_an_outlying_particle_loses_less_than_under_the_gaussian():
    st = _particles(n=2)
    st.rot[1] = st.rot[0]
    st.pos[1] = st.pos[0] + [10 * SIGMA["sigma_pos"], 0.0, 0.0]     # ten scales off
    obs = PomObservation(st.pos[0], st.rot[0])
    gap = {nu: np.subtract(*ObservationModel(**SIGMA, dof=nu).log_likelihood(st, obs))
           for nu in (0.0, 4.0)}
    assert gap[0.0] > 20 and 0 < gap[4.0] < gap[0.0] / 2


def test_a_bad_nu_is_named():
    with pytest.raises(ValueError, match="dof -1"):
        ObservationModel(dof=-1.0)
    with pytest.raises(UserError, match="likelihood_dof inf"):
        TrialSettings(backend="sim", likelihood_dof=float("inf"))


def test_an_outlying_frame_does_not_collapse_the_particle_set():
    """A frame far from every particle (a misdetected tag, say): under the Gaussian its
    weights pile on the few particles nearest to it, under the t they stay spread."""
    rng, n = np.random.default_rng(1), 2000
    st = _particles(n=n, seed=1)
    st.pos = rng.normal(size=(n, 3)) * SIGMA["sigma_pos"]
    st.rot = Rotation.from_rotvec(rng.normal(size=(n, 3)) * SIGMA["sigma_rot"]).as_matrix()
    outlier = PomObservation(np.array([20 * SIGMA["sigma_pos"], 0.0, 0.0]), np.eye(3))

    def ess_share(dof: float) -> float:
        ll = ObservationModel(**SIGMA, dof=dof).log_likelihood(st, outlier)
        w = np.exp(ll - ll.max())
        return float(w.sum() ** 2 / (w * w).sum() / n)

    assert ess_share(0.0) < 0.01 and ess_share(4.0) > 0.3

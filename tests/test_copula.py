"""Normal scores (`vlr.copula`) and the filter's Liu-West draw on them (`jitter_kernel`)."""

import numpy as np
import pytest
from scipy import stats

from vlr.copula import NormalScores, silverman_bandwidth
from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel
from vlr.motion import ObjectParams
from vlr.spec import load_hand


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def _sample(n: int = 20_000, seed: int = 0) -> np.ndarray:
    """A Gaussian, a half-normal (a joint cut at its stop at 0), a constant; resampled, so
    that most rows have copies, as after the filter's resampling."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.normal(1.0, 2.0, n), np.abs(rng.normal(0.0, 1.0, n)),
                         np.full(n, 0.3)])
    return x[rng.integers(0, n, n)]


def test_scores_go_back_to_the_values():
    x = _sample()
    scores = NormalScores.fit(x)
    np.testing.assert_allclose(scores.from_normal(scores.to_normal(x)), x, atol=1e-9)


def test_a_gaussian_column_scores_as_its_standardized_values():
    x = _sample()
    z = NormalScores.fit(x).to_normal(x)
    assert np.corrcoef(z[:, 0], x[:, 0])[0, 1] > 0.999
    assert abs(z[:, 0].mean()) < 0.02 and abs(z[:, 0].std() - 1.0) < 0.02
    # The half-normal's scores are near Gaussian (the CDF's smoothing leaves a little mass
    # below the cut, so its lowest scores are not as extreme as a Gaussian's: skew 0.2).
    assert stats.skew(x[:, 1]) > 0.9
    assert abs(stats.skew(z[:, 1])) < 0.25 * stats.skew(x[:, 1])


def test_a_constant_column_stays_constant():
    x = _sample()
    scores = NormalScores.fit(x)
    assert scores.constant.tolist() == [False, False, True]
    z = scores.to_normal(x)
    assert np.all(z[:, 2] == 0.0)
    assert np.all(scores.from_normal(z + 1.0)[:, 2] == 0.3)


def test_silverman_bandwidth():
    x = np.random.default_rng(1).normal(0.0, 2.0, (10_000, 1))
    assert silverman_bandwidth(x)[0] == pytest.approx(0.9 * 2.0 * 10_000 ** -0.2, rel=0.05)


def test_fit_names_a_bad_array():
    with pytest.raises(ValueError, match=r"\(P >= 2, D\)"):
        NormalScores.fit(np.zeros(5))


def _draws(modelo, kernel: str, steps: int, x: np.ndarray, cut: int | None = 1) -> np.ndarray:
    """`steps` of the filter's kernel on `x`, each followed by the stop at 0 holding the
    column `cut` (as the settle does), with no likelihood between them."""
    pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                        FilterConfig(n_particles=len(x), seed=3, jitter_kernel=kernel))
    for _ in range(steps):
        x, _ = pf._kernel(x)
        if cut is not None:
            x[:, cut] = np.maximum(x[:, cut], 0.0)
    return x


def test_the_copula_kernel_keeps_a_cut_marginal_where_the_gaussian_moves_it(modelo):
    """The Gaussian kernel makes the half-normal Gaussian over repeated draws: its median
    moves towards its mean (0.80) and past it with the stop's clipping (0.68 -> 0.83); on normal
    scores the median stays. Both keep the Gaussian column's mean and spread."""
    x = _sample()
    med0 = np.median(x[:, 1])
    gauss = _draws(modelo, "gaussian", 10, x.copy())
    copula = _draws(modelo, "copula", 10, x.copy())
    moved_gauss = np.median(gauss[:, 1]) - med0
    moved_copula = np.median(copula[:, 1]) - med0
    assert moved_gauss > 0.12
    assert abs(moved_copula) < 0.35 * moved_gauss
    for y in (gauss, copula):
        assert y[:, 0].mean() == pytest.approx(1.0, abs=0.1)
        assert y[:, 0].std() == pytest.approx(2.0, rel=0.15)
        assert np.all(y[:, 2] == pytest.approx(0.3, abs=1e-6))


def test_forty_draws_keep_the_spread_and_the_cut_marginals_median(modelo):
    """vlr/copula.py's docstring: over 40 draws with no likelihood and no stop the scores'
    kernel does not widen a Gaussian marginal (1.980 -> 1.985) and keeps a half-normal's
    median (0.68 -> 0.69), where the values' kernel moves it to its mean (0.80)."""
    x = _sample()
    gauss = _draws(modelo, "gaussian", 40, x.copy(), cut=None)
    copula = _draws(modelo, "copula", 40, x.copy(), cut=None)
    assert copula[:, 0].std() == pytest.approx(x[:, 0].std(), rel=0.01)
    assert abs(np.median(copula[:, 1]) - np.median(x[:, 1])) < 0.03
    assert np.median(gauss[:, 1]) == pytest.approx(x[:, 1].mean(), abs=0.02)


def test_the_copula_kernel_keeps_correlations(modelo):
    rng = np.random.default_rng(4)
    a = rng.normal(size=20_000)
    x = np.column_stack([a, 0.8 * a + 0.6 * rng.normal(size=20_000)])
    y = _draws(modelo, "copula", 5, x, cut=None)
    assert np.corrcoef(y[:, 0], y[:, 1])[0, 1] == pytest.approx(0.8, abs=0.05)


def test_the_cli_offers_the_filters_kernels():
    from vlr import filter as vf
    from vlr.commands import identify

    assert identify.JITTER_KERNELS == vf.JITTER_KERNELS


def test_a_bad_jitter_kernel_is_named():
    with pytest.raises(ValueError, match="jitter_kernel 'box'"):
        FilterConfig(jitter_kernel="box")


def test_identify_takes_the_copula_kernel(tmp_path, capsys):
    """`vlr identify --jitter-kernel copula` runs the filter with it and says so; a kernel
    it does not know is one clear line."""
    import json

    from vlr.cli import main

    rc = main(["identify", "--backend", "synthetic", "--particles", "300", "--max-iterations",
               "3", "--jitter-kernel", "copula", "--out", str(tmp_path)])
    assert rc == 0
    assert "normal scores (copula)" in capsys.readouterr().out
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["settings"]["jitter_kernel"] == "copula"
    with pytest.raises(SystemExit):
        main(["identify", "--backend", "synthetic", "--jitter-kernel", "box", "--out",
              str(tmp_path / "bad")])
    assert "invalid choice: 'box'" in capsys.readouterr().err


def test_copula_joints_draws_the_joints_on_scores_and_the_rest_on_values(modelo):
    """"copula-joints": a joint column cut at its stop keeps its median, as with "copula";
    a skewed column past the joints (a contact or unknown) is drawn on its values, so its
    median moves to its mean, as with "gaussian"."""
    rng = np.random.default_rng(5)
    n = 20_000
    n_th = modelo.n_fingers * modelo.n_joints
    x = rng.normal(size=(n, n_th + 1))
    x[:, 0] = np.abs(x[:, 0])           # a joint cut at its stop
    x[:, -1] = np.abs(x[:, -1])         # an unknown of the same shape
    x = x[rng.integers(0, n, n)]
    y = x.copy()
    pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                        FilterConfig(n_particles=n, seed=3, jitter_kernel="copula-joints"))
    for _ in range(10):
        y, _ = pf._kernel(y)
        y[:, 0] = np.maximum(y[:, 0], 0.0)
    med0 = np.median(x[:, 0])
    assert abs(np.median(y[:, 0]) - med0) < 0.05
    assert np.median(y[:, -1]) - np.median(x[:, -1]) > 0.08


@pytest.mark.parametrize("kernel, joint_on_scores", [("copula-scales", False),
                                                     ("copula-joints-scales", True)])
def test_scale_kernels_draw_a_spring_on_its_scores(modelo, kernel, joint_on_scores):
    """"copula-scales" draws a scale unknown (a spring) on its normal scores, so its skewed
    marginal keeps its median, and the joints on their values (their medians drift to the
    mean); "copula-joints-scales" keeps both."""
    rng = np.random.default_rng(6)
    n = 20_000
    pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                        FilterConfig(n_particles=n, seed=3, jitter_kernel=kernel,
                                     unknowns=("stiffness:thumb.distal",)))
    n_th = modelo.n_fingers * modelo.n_joints
    lo, hi = pf.unknowns[0].prior
    x = rng.normal(size=(n, n_th + 2))
    x[:, 0] = np.abs(x[:, 0])                           # a joint cut at its stop
    x[:, -1] = lo + 0.1 * (hi - lo) * (1.0 + np.abs(x[:, -1]))   # a spring skewed up
    x = x[rng.integers(0, n, n)]
    y = x.copy()
    for _ in range(10):
        y, _ = pf._kernel(y)
        y[:, 0] = np.maximum(y[:, 0], 0.0)
    spring_shift = (np.median(y[:, -1]) - np.median(x[:, -1])) / (0.1 * (hi - lo))
    assert abs(spring_shift) < 0.05
    joint_shift = np.median(y[:, 0]) - np.median(x[:, 0])
    assert (abs(joint_shift) < 0.05) if joint_on_scores else (joint_shift > 0.08)


def test_the_scores_mask_names_the_columns(modelo):
    """Which columns each kernel draws on scores: none, all, the joints, the scale unknowns
    (a spring, not a link length), both."""
    n_th = modelo.n_fingers * modelo.n_joints
    unknowns = ("stiffness:thumb.distal", "length:left.proximal")
    masks = {}
    for kernel in ("gaussian", "copula", "copula-joints", "copula-scales",
                   "copula-joints-scales"):
        pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                            FilterConfig(n_particles=10, jitter_kernel=kernel,
                                         unknowns=unknowns))
        masks[kernel] = pf._score_columns(np.zeros((4, n_th + 3 + 2)))
    assert not masks["gaussian"].any() and masks["copula"].all()
    assert masks["copula-joints"].sum() == n_th and masks["copula-joints"][:n_th].all()
    assert list(np.flatnonzero(masks["copula-scales"])) == [n_th + 3]
    assert list(np.flatnonzero(masks["copula-joints-scales"])) == list(range(n_th)) + [n_th + 3]


@pytest.mark.parametrize("kernel", ["copula-scales", "log-scales", "log-springs"])
def test_a_row_without_a_scale_unknown_draws_as_the_gaussian_kernel(modelo, kernel):
    """A row without a scale unknown (the known hand, link lengths) draws with the scale
    unknowns' kernels exactly as with "gaussian": same random stream, same numbers."""
    rng = np.random.default_rng(8)
    x = rng.normal(size=(500, modelo.n_fingers * modelo.n_joints + 6 + 1))
    draws = []
    for k in ("gaussian", kernel):
        pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                            FilterConfig(n_particles=500, seed=4, jitter_kernel=k,
                                         unknowns=("length:left.proximal",)))
        draws.append(pf._kernel(x.copy())[0])
    np.testing.assert_array_equal(draws[0], draws[1])


@pytest.mark.parametrize("kernel", ["copula", "copula-joints"])
def test_the_column_mask_draws_as_the_kernels_did(modelo, kernel):
    """The mask (`_score_columns`) replaced one branch per kernel: "copula" was the
    Liu-West draw on every column's scores, "copula-joints" on the joints' scores with the
    rest's values. Those formulas, written out, give the same numbers to the bit, so the
    committed sweeps' draws are unchanged."""
    from vlr.filter import _liu_west

    rng = np.random.default_rng(9)
    n_th = modelo.n_fingers * modelo.n_joints
    x = rng.normal(size=(2000, n_th + 7))
    x[:, 0] = np.abs(x[:, 0])
    cfg = FilterConfig(n_particles=2000, seed=11, jitter_kernel=kernel)
    got = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)), cfg)._kernel(x)[0]
    h = cfg.jitter_h
    a = np.sqrt(1.0 - h * h)
    draw = np.random.default_rng(11)
    cols = slice(None) if kernel == "copula" else slice(0, n_th)
    scores = NormalScores.fit(x[:, cols])
    y = x.copy()
    y[:, cols] = scores.to_normal(x[:, cols])
    want = _liu_west(y, a, h, draw)
    want[:, cols] = scores.from_normal(want[:, cols])
    np.testing.assert_array_equal(got, want)


def test_log_scales_keeps_a_log_normal_springs_median(modelo):
    """"log-scales" draws a scale unknown on its logarithm: a log-normal spring (its median
    below its mean) keeps its median, where the values' kernel moves it up towards the
    mean; the joints stay on their values (the same draw as "gaussian" there)."""
    rng = np.random.default_rng(10)
    n = 20_000
    n_th = modelo.n_fingers * modelo.n_joints
    unknowns = ("stiffness:thumb.distal",)
    x = rng.normal(size=(n, n_th + 2))
    x[:, -1] = 0.03 * np.exp(0.3 * x[:, -1])            # median 0.03, mean 0.0314
    got = {}
    for kernel in ("gaussian", "log-scales"):
        pf = ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                            FilterConfig(n_particles=n, seed=3, jitter_kernel=kernel,
                                         unknowns=unknowns))
        lo, hi = pf.unknowns[0].prior
        assert lo < 0.03 * np.exp(-1.2) and hi > 0.03 * np.exp(1.2)
        y = x.copy()
        for _ in range(10):
            y, _ = pf._kernel(y)
        got[kernel] = y
    med0 = np.median(x[:, -1])
    assert abs(np.median(got["log-scales"][:, -1]) / med0 - 1.0) < 0.01
    assert np.median(got["gaussian"][:, -1]) / med0 - 1.0 > 0.03
    assert np.std(np.log(got["log-scales"][:, -1])) == pytest.approx(0.3, rel=0.03)
    assert not ParticleFilter(modelo, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                              FilterConfig(n_particles=10, jitter_kernel="log-scales",
                                           unknowns=unknowns))._score_columns(x).any()


def test_log_springs_draws_the_spring_on_its_log_and_the_mass_on_its_values(modelo):
    """"log-springs" (the default): over ten draws a log-normal spring keeps its median, as
    with "log-scales", and a log-normal object's mass has its median moved up towards its
    mean, as with "gaussian"; "log-scales" keeps both."""
    rng = np.random.default_rng(13)
    n = 20_000
    n_th = modelo.n_fingers * modelo.n_joints
    x = rng.normal(size=(n, n_th + 2 + 2))
    x[:, -2] = 0.03 * np.exp(0.3 * rng.normal(size=n))      # the spring
    x[:, -1] = 0.07 * np.exp(0.3 * rng.normal(size=n))      # the mass
    shift = {}
    for kernel in ("gaussian", "log-scales", "log-springs"):
        pf = ParticleFilter(modelo, ObjectParams(mass=0.07, com=(0.0, 0.0, 0.0)),
                            FilterConfig(n_particles=n, seed=5, jitter_kernel=kernel,
                                         unknowns=("stiffness:thumb.distal", "mass")))
        y = x.copy()
        for _ in range(10):
            y, _ = pf._kernel(y)
        shift[kernel] = np.median(y[:, -2:], axis=0) / np.median(x[:, -2:], axis=0) - 1.0
    assert FilterConfig().jitter_kernel == "log-springs"
    assert np.all(shift["gaussian"] > 0.03)
    assert np.all(np.abs(shift["log-scales"]) < 0.01)
    assert abs(shift["log-springs"][0]) < 0.01 and shift["log-springs"][1] > 0.03

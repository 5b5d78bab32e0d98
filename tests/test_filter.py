"""Particle filter pieces (Algorithm 1): resampler, tempering, ESS, seeding, the unknowns."""

import numpy as np
import pytest

from vlr.filter import (
    FilterConfig,
    ParticleFilter,
    Summary,
    effective_sample_size,
    interval_width_deg,
    systematic_resample,
    temper,
)
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, ObjectParams
from vlr.spec import load_hand
from vlr.surface import LocalSurface
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action
from vlr.unknowns import CURVATURE_PRIOR_TOP, draw_prior, parse_unknown

OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))


def config(particles: int, **kw) -> FilterConfig:
    """A filter of the synthetic world's own model (`vlr.synthetic.SyntheticConfig`: pinned
    contacts) with its prior about the pads' contacts, as the synthetic backend runs it."""
    kw.setdefault("motion", MotionConfig(rolling=False))
    kw.setdefault("contact_prior", "pad")
    return FilterConfig(particles=particles, **kw)


@pytest.fixture
def fp_resampling():
    """filterpy's resampling module, the oracle."""
    import filterpy.monte_carlo.resampling as filterpy

    return filterpy


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


@pytest.mark.parametrize("offset", [0.0, 0.37, 0.999999])
def test_resampler_agrees_with_filterpy(monkeypatch, offset, fp_resampling):
    rng = np.random.default_rng(3)
    w = rng.random(500)
    w /= w.sum()
    monkeypatch.setattr(fp_resampling, "random", lambda: offset)
    expected = fp_resampling.systematic_resample(w)
    np.testing.assert_array_equal(systematic_resample(w, offset=offset), expected)


def test_resampler_never_indexes_past_the_end(monkeypatch, fp_resampling):
    w = np.full(1000, 1.0 / 1000) * (1 - 1e-9)  # cumulative sum ends below 1
    idx = systematic_resample(w, offset=0.9999999999)
    assert idx.shape == (1000,) and idx.max() == 999
    monkeypatch.setattr(fp_resampling, "random", lambda: 0.9999999999)
    with pytest.raises(IndexError):  # the bug the guard removes
        fp_resampling.systematic_resample(w)
    w = np.zeros(10)
    w[3] = 1.0
    assert np.all(systematic_resample(w, np.random.default_rng(0)) == 3)


def test_tempering_keeps_ess():
    ll = -0.5 * (np.linspace(0, 40, 1000) ** 2)
    w, beta = temper(ll, 0.5)
    assert 0 < beta < 1
    assert effective_sample_size(w) >= 0.5 * 1000 * 0.999
    ll[::2] = -np.inf
    w, _ = temper(ll, 0.3)
    assert np.all(w[::2] == 0) and np.all(np.isfinite(w))


def test_interval_width():
    x = np.random.default_rng(0).normal(0, np.radians(1), (20000, 6))
    assert interval_width_deg(x) == pytest.approx(2 * 1.96, rel=0.05)


def test_summary_median_of_a_set_piled_on_a_stop():
    # A joint on its stop: half the particles at the stop, the rest spread past it. The
    # median stays on the stop; the mean is pulled off it.
    rng = np.random.default_rng(0)
    x = np.concatenate([np.zeros(5000), rng.uniform(0.0, 0.3, 4000)])[:, None]
    s = Summary.of(x)
    assert s.median[0] == 0.0 and s.mean[0] > 0.05
    # Weights give the same answers as the set they stand for.
    w = np.r_[np.full(5000, 2.0), np.ones(4000)]
    sw = Summary.of(x, w)
    assert sw.median[0] == 0.0
    np.testing.assert_allclose(sw.mean, (w @ x) / w.sum())
    heavy = Summary.of(x, np.r_[np.full(5000, 0.1), np.ones(4000)])
    assert 0.0 < heavy.median[0] < heavy.high[0]


def test_parse_unknown(modelo):
    u = parse_unknown("stiffness:thumb.distal", modelo)
    assert (u.kind, u.finger, u.joint) == ("stiffness", 0, 1)
    u = parse_unknown("length:left.proximal", modelo, (0.03, 0.07))
    assert (u.kind, u.finger, u.joint, u.prior) == ("length", 1, 0, (0.03, 0.07))
    with pytest.raises(ValueError):
        parse_unknown("mass:thumb", modelo)


def test_parse_the_objects_unknowns(modelo):
    u = parse_unknown("mass", modelo, obj=OBJ)
    assert (u.kind, u.finger, u.joint) == ("mass", -1, -1)
    assert u.prior == pytest.approx((0.25 * OBJ.mass, 4.0 * OBJ.mass))
    u = parse_unknown("com:z", modelo, obj=OBJ)
    assert (u.kind, u.joint) == ("com", 2)
    assert u.prior == pytest.approx((OBJ.com[2] - 0.015, OBJ.com[2] + 0.015))
    assert parse_unknown("mass", modelo, (0.05, 0.2), OBJ).prior == (0.05, 0.2)
    for spec, message in (("mass", "need the object believed"),):
        with pytest.raises(ValueError, match=message):
            parse_unknown(spec, modelo)
    for spec, prior, message in (("mass:thumb", None, "takes no finger"),
                                 ("com:w", None, "com:x, com:y or com:z"),
                                 ("com", None, "com:x, com:y or com:z"),
                                 ("mass", (0.0, 0.2), "0 < low"),
                                 ("com:x", (0.01, -0.01), "low <= high")):
        with pytest.raises(ValueError, match=message):
            parse_unknown(spec, modelo, prior, OBJ)


def test_parse_the_curvature(modelo):
    ball = ObjectParams(mass=0.07, com=(0.0, 0.0, 0.04), surface=LocalSurface("sphere", 0.01))
    u = parse_unknown("curvature", modelo, obj=ball)
    assert (u.kind, u.finger, u.prior) == ("curvature", -1, pytest.approx((0.0, 200.0)))
    u = parse_unknown("curvature:left", modelo, obj=OBJ)     # a plane: up to a 20 mm ball
    assert (u.finger, u.prior) == (1, (0.0, CURVATURE_PRIOR_TOP))
    with pytest.raises(ValueError, match="needs the object believed"):
        parse_unknown("curvature", modelo)
    for spec, prior, message in (("curvature:pinky", None, "pinky"),
                                 ("curvature", (-1.0, 20.0), "0 <= low")):
        with pytest.raises(ValueError, match=message):
            parse_unknown(spec, modelo, prior, OBJ)


@pytest.mark.parametrize("specs, message", [
    (("mass", "mass"), "'mass' is given twice"),
    (("curvature", "curvature:thumb"), "the same parameter"),
    (("tendon:left", "tendon"), "the same parameter")])
def test_one_parameter_sampled_twice_is_refused(modelo, specs, message):
    with pytest.raises(ValueError, match=message):
        ParticleFilter(modelo, OBJ, config(10, unknowns=specs))


def test_a_fingers_curvature_is_sampled_at_its_contact_alone(modelo):
    pf = _run(modelo, 3, unknowns=("curvature:thumb",))
    k = pf.state.surface_curvature
    assert np.all((0.0 <= k[:, 0]) & (k[:, 0] <= CURVATURE_PRIOR_TOP)) and k[:, 0].std() > 0
    assert np.all(k[:, 1:] == 0.0)   # the believed plane's at the other contacts


def test_the_objects_unknowns_are_sampled_within_their_priors(modelo):
    pf = _run(modelo, 3, unknowns=("mass", "com:x"))
    names = pf.dim_names
    x = pf.pack(pf.state)
    for spec in ("mass", "com:x"):
        u = next(u for u in pf.unknowns if u.spec == spec)
        col = x[:, names.index(spec)]
        assert np.all((u.prior[0] <= col) & (col <= u.prior[1]))
        assert col.std() > 0   # sampled, not the believed value for every particle
    assert pf.state.object_com[:, 1:].tolist() == [list(OBJ.com[1:])] * pf.state.n


def _run(modelo, seed, steps=2, unknowns=(), **kw):
    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=1))
    u = world.grasp()
    pf = ParticleFilter(modelo, OBJ, config(300, unknowns=unknowns, **kw), seed)
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(5)
    for k in range(steps):
        u = world.apply(random_action(rng, 3))
        pf.step(u, world.observe() if k % 2 == 0 else None)
    return pf


def test_same_seed_same_numbers(modelo):
    a = _run(modelo, 7, unknowns=("stiffness:thumb.distal",))
    b = _run(modelo, 7, unknowns=("stiffness:thumb.distal",))
    np.testing.assert_array_equal(a.pack(a.state), b.pack(b.state))
    c = _run(modelo, 8, unknowns=("stiffness:thumb.distal",))
    assert not np.array_equal(a.pack(a.state), c.pack(c.state))


def test_the_spreads_are_given_in_degrees():
    cfg = FilterConfig(theta_spread_deg=10.0, contact_spread_deg=5.0)
    assert cfg.theta_spread == pytest.approx(np.radians(10.0))
    assert cfg.contact_spread == pytest.approx(np.radians(5.0))
    assert FilterConfig().contact_spread == pytest.approx(0.15)
    for kw, name in ((dict(theta_spread_deg=0.0), "theta_spread_deg"),
                     (dict(contact_spread_deg=91.0), "contact_spread_deg"),
                     (dict(particles=5), "particles")):
        with pytest.raises(ValueError, match=name):
            FilterConfig(**kw)


def test_prediction_only_step_and_records(modelo):
    pf = _run(modelo, 1, steps=2)
    assert len(pf.history) == 3
    assert pf.history[2].posterior is None  # second action had no observation
    assert pf.history[1].posterior is not None and pf.history[1].ess > 0
    x = pf.pack(pf.state)
    assert np.all(np.isfinite(x))
    assert len(pf.dim_names) == x.shape[1] == 12


def test_filter_recovers_when_every_particle_fails():
    """All solves failing must not end the run with no particle: the prior is resampled about
    the last estimate at the current command."""
    from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0))
    u = world.grasp()
    pf = ParticleFilter(model, obj, config(300))
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    pf.state.theta[...] = np.nan  # every solve fails
    u = world.apply(random_action(np.random.default_rng(0), 3))
    rec = pf.step(u, world.observe())
    assert pf.recoveries == 1
    assert pf.state.valid.mean() > 0.5 and np.isfinite(rec.ci_deg)


def test_a_prior_that_does_not_settle_is_drawn_again_then_named(monkeypatch):
    """A draw of which no particle settles at the grasp command is drawn again (a small
    filter's unlucky draw is not a lost grasp); a prior that never settles is one error
    that says what failed, not a bare zero-likelihood error from the weights."""
    from vlr.motion import MotionModel

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0))
    u = world.grasp()
    solve = MotionModel.solve
    failures = {"left": 1}

    def unlucky(self, state, *args, **kw):
        out = solve(self, state, *args, **kw)
        if failures["left"] > 0:
            failures["left"] -= 1
            state.valid[:] = False
        return out

    monkeypatch.setattr(MotionModel, "solve", unlucky)
    pf = ParticleFilter(model, obj, config(200))
    rec = pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    assert pf.prior_redraws == 1 and pf.state.valid.all() and rec.ess > 0
    failures["left"] = 10
    pf = ParticleFilter(model, obj, config(200))
    with pytest.raises(FloatingPointError, match="none of the 200 prior particles settled"):
        pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)


def test_a_particle_at_the_truth_stays_there(modelo):
    """The truth, planted as one particle, must come through an update exactly: resampling
    keeps the first copy of each parent un-jittered, and re-anchoring keeps its grasp force
    (without it a particle at the truth moves 0.5 degrees per update)."""
    world = SyntheticWorld(modelo, OBJ, SyntheticConfig(seed=2))
    u = world.grasp()
    pf = ParticleFilter(modelo, OBJ, config(400))
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    for name in ("theta", "normals", "anchors", "pos", "rot", "segments", "stiffness",
                 "tendon", "valid", "tangent"):   # the tangent: the action's predictor
        getattr(pf.state, name)[:50] = getattr(world.state, name)[0]
    u = world.apply(random_action(np.random.default_rng(1), 3))
    pf.step(u, world.observe())
    distance = np.abs(pf.pack(pf.state) - pf.pack(world.state)[0]).max(axis=1)
    assert distance.min() < 1e-9


def test_the_prior_of_an_unknown_is_uniform_over_its_range(modelo):
    """A spring's default prior is 0.25-4x the nominal, drawn uniformly: its median is at
    2.125x the nominal, every draw within the range."""
    spring = parse_unknown("stiffness:thumb.distal", modelo)
    nominal = modelo.stiffness[modelo.finger_index("thumb"), modelo.joint_index("distal")]
    draws = draw_prior(np.random.default_rng(0), spring, 20000)
    assert np.all((spring.prior[0] <= draws) & (draws <= spring.prior[1]))
    assert np.median(draws) == pytest.approx(2.125 * nominal, rel=0.05)
    np.testing.assert_array_equal(draws, draw_prior(np.random.default_rng(0), spring, 20000))

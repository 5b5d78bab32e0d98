"""vlr.trial: what a trial's world is made of, and settings that make no sense refused."""

import math
from pathlib import Path

import pytest

import models
from vlr.errors import UserError
from vlr.trial import TrialSettings, open_world


def test_truth_settings_are_refused_where_the_world_cannot_take_them():
    with pytest.raises(UserError, match="true_stiffness"):
        TrialSettings(backend="sim", true_stiffness={"thumb.distal": 0.045})
    with pytest.raises(UserError, match="true_hand"):
        TrialSettings(backend="hardware", true_hand="nh1")


def test_the_sim_is_built_with_the_true_hand_and_the_filter_keeps_the_nominal_one():
    """NH1 in the sim: the left finger is NF1 (40 mm proximal link) in the simulated hand
    and in the scoring truth; the filter's model is still the Model O's (62 mm)."""
    w = open_world(TrialSettings(backend="sim", hand="modelo", true_hand="nh1", particles=100,
                                 unknowns=("length:left.proximal",)))
    try:
        left = w.model.names.index("left")
        assert w.model.segments[left, 0] == pytest.approx(0.062)
        assert w.hand_spec.name == "modelo"
        assert w.world.true_spec.mount("left").finger.proximal_length == pytest.approx(0.040)
        w.world.grasp()
        assert w.truth().segments[left, 0] == pytest.approx(0.040)
    finally:
        w.close()


def test_the_filter_models_the_object_the_hardware_config_names():
    """The config (apple) decides what is in the hand, not --object's value."""
    config = models.ROOT.parent / "hardware" / "example_sim_config.yaml"
    w = open_world(TrialSettings(backend="hardware", object="wine_glass", particles=100,
                                 config=str(config)))
    try:
        assert w.object_spec.name == "apple"
        assert w.obj.mass == pytest.approx(w.object_spec.mass)
    finally:
        w.close()


def test_a_nominal_guess_per_finger():
    """K angles guess every finger alike; N x K guess each finger (a thumb wrapped round a
    thin shaft); any other count is one error naming the counts."""
    import numpy as np

    alike = open_world(TrialSettings(backend="synthetic", nominal_theta_deg=(-10, 15)))
    wrapped = open_world(TrialSettings(backend="synthetic",
                                       nominal_theta_deg=(-10, 70, -10, 15, -10, 15)))
    thumb = alike.model.names.index("thumb")
    assert np.degrees(wrapped.nominal.theta[thumb, 1]) > 50
    assert np.degrees(alike.nominal.theta[thumb, 1]) < 40
    with pytest.raises(UserError, match="give 2 angles .* or 6"):
        open_world(TrialSettings(backend="synthetic", nominal_theta_deg=(-10, 15, 3)))


def test_motion_scaled_model_error_runs_a_trial_and_refuses_a_negative_fraction():
    from vlr.trial import run_trial

    summary = run_trial(TrialSettings(backend="synthetic", particles=300, max_iterations=2,
                                      sigma_motion=0.1))
    assert summary["settings"]["sigma_motion"] == 0.1 and summary["iterations"] == 2
    assert summary["rolling"] is False    # the synthetic world's default, as it was run
    assert summary["sigma"] == [0.1, 0.4]
    # the guess in effect, where the settings say None (the synthetic world's generic one)
    assert summary["settings"]["nominal_theta_deg"] is None
    assert summary["grasp_guess"] == {"nominal_theta_deg": None, "prior_spread_deg": 3.0,
                                      "contact_spread_deg": pytest.approx(8.594, abs=1e-3),
                                      "contact_prior": "pad"}
    with pytest.raises(UserError, match="sigma_motion -1"):
        TrialSettings(sigma_motion=-1.0)
    with pytest.raises(UserError, match="sigma_motion 'big'"):
        TrialSettings(sigma_motion="big")


def test_pad_friction_reaches_the_filter_and_needs_rolling():
    from vlr.trial import identify_config

    s = TrialSettings(backend="synthetic", particles=50, rolling=True, slide_friction=1.0,
                      spin_friction=0.001, spin_memory=True)
    world = open_world(s)
    try:
        motion = identify_config(s, world.model).filter.motion
    finally:
        world.close()
    assert motion.rolling and motion.slide_friction == 1.0 and motion.spin_friction == 0.001
    assert motion.spin_memory and not TrialSettings(rolling=True).motion_config().spin_memory
    with pytest.raises(UserError, match="spin_memory .*set spin_friction too"):
        TrialSettings(rolling=True, spin_memory=True)
    with pytest.raises(UserError, match="spin_memory 'yes'"):
        TrialSettings(rolling=True, spin_friction=0.001, spin_memory="yes")
    assert math.isinf(TrialSettings(rolling=True).motion_config().slide_friction)
    assert TrialSettings(rolling=True, exact_cylinder=True).motion_config().exact_cylinder
    assert not TrialSettings(rolling=True).motion_config().exact_cylinder
    with pytest.raises(UserError, match="exact_cylinder 1"):
        TrialSettings(rolling=True, exact_cylinder=1)
    with pytest.raises(UserError, match="exact_cylinder .*set rolling too"):
        TrialSettings(backend="synthetic", exact_cylinder=True)
    with pytest.raises(UserError, match="set rolling too"):
        TrialSettings(backend="synthetic", slide_friction=1.0)
    with pytest.raises(UserError, match="set rolling too"):
        TrialSettings(rolling=False, slide_friction=1.0)
    with pytest.raises(UserError, match="slide_friction 0"):
        TrialSettings(rolling=True, slide_friction=0)
    with pytest.raises(UserError, match="spin_friction 0.5"):
        TrialSettings(rolling=True, spin_friction=0.5)


def test_rolling_contacts_by_default_on_the_sim_and_pinned_on_the_synthetic_world():
    """docs/RESULTS.md 5: rolling measured better in the sim, overconfident on the synthetic
    world; an explicit setting wins."""
    assert TrialSettings(backend="sim").motion_config().rolling
    assert TrialSettings(backend="hardware", config="x.yaml").motion_config().rolling
    assert not TrialSettings(backend="synthetic").motion_config().rolling
    assert not TrialSettings(backend="sim", rolling=False).motion_config().rolling
    assert TrialSettings(backend="synthetic", rolling=True).motion_config().rolling
    with pytest.raises(UserError, match="rolling 'yes'"):
        TrialSettings(rolling="yes")


def test_joint_stops_follow_the_backend_and_an_explicit_one_wins():
    """The sim's model stops are as soft as its distal MuJoCo limits (17 N m/rad, measured
    better over the whole table, docs/RESULTS.md 5); the synthetic world and the real hand
    keep the model's 100."""
    from vlr.motion import MotionConfig

    assert TrialSettings(backend="sim").motion_config().limit_stiffness == 17.0
    assert TrialSettings(backend="sim").limit_stiffness_in_effect == 17.0
    for other in (TrialSettings(backend="synthetic"),
                  TrialSettings(backend="hardware", config="x.yaml")):
        assert other.motion_config().limit_stiffness == MotionConfig.limit_stiffness == 100.0
    assert TrialSettings(backend="sim",
                         limit_stiffness=100.0).motion_config().limit_stiffness == 100.0


def test_the_sim_moves_as_the_hardware_backend_does_and_an_explicit_ramp_wins():
    """The sim's trials ramp each command change over the hardware backend's default move
    (docs/RESULTS.md 5, session 30); a trial may say otherwise, on the sim only."""
    from hardware.config import MotionConfig as HardwareMotion

    hw = HardwareMotion(spool_radius=0.005, max_step=1e-3, range=(0.0, 0.01))
    assert TrialSettings(backend="sim").ramp_time_in_effect == pytest.approx(
        hw.ramp_steps * hw.ramp_period)
    assert TrialSettings(backend="sim", ramp_time=0.05).ramp_time_in_effect == 0.05
    assert TrialSettings(backend="synthetic").ramp_time_in_effect is None
    w = open_world(TrialSettings(backend="sim", particles=100, ramp_time=0.07))
    try:
        assert w.world.options.ramp_time == 0.07
    finally:
        w.close()
    for bad in (dict(backend="synthetic", ramp_time=0.1), dict(backend="sim", ramp_time=0.0),
                dict(backend="sim", ramp_time=5.0), dict(backend="sim", ramp_time="slow")):
        with pytest.raises(UserError, match="ramp_time"):
            TrialSettings(**bad)


def test_the_grasp_guess_follows_the_backend_and_an_explicit_one_wins():
    """The sim's default guess is the one its identification rows use (-10, 15) +- 10
    degrees (the generic guess identified the sim apple 12 degrees off); the synthetic world
    grasps at the generic guess and keeps it, as the real hand does until measured."""
    assert TrialSettings(backend="sim").grasp_guess == ((-10.0, 15.0), 10.0)
    assert TrialSettings(backend="synthetic").grasp_guess == (None, 3.0)
    assert TrialSettings(backend="hardware", config="x.yaml").grasp_guess == (None, 3.0)
    assert TrialSettings(backend="sim", nominal_theta_deg=(-5, 20),
                         prior_spread_deg=4.0).grasp_guess == ((-5.0, 20.0), 4.0)
    assert TrialSettings(backend="synthetic", prior_spread_deg=7.0).grasp_guess == (None, 7.0)
    with pytest.raises(UserError, match="prior_spread_deg -1"):
        TrialSettings(prior_spread_deg=-1)
    # the synthetic world's prior is drawn about the generic guess with a 3-degree spread
    world = open_world(TrialSettings(backend="synthetic"))
    generic = open_world(TrialSettings(backend="synthetic", nominal_theta_deg=(-17.19, 68.75)))
    assert abs(world.nominal.theta - generic.nominal.theta).max() < 1e-3


def test_likelihood_scales_follow_the_backend_and_the_contact_model(tmp_path):
    # The sim's rolling filter takes ROLLING_TURN_SIGMA (base scales and the turn term) when
    # no scale is given; pinned and the real hand keep DEFAULT_SIGMA; explicit scales win,
    # and scales given without a turn keep none (the meaning they had before the turn term).
    sim = TrialSettings(backend="sim")
    assert (sim.sigma, sim.turn_deg) == ((0.2, 0.4), 1.0)
    assert (TrialSettings(backend="sim", rolling=False).sigma, TrialSettings(
        backend="sim", rolling=False).turn_deg) == ((0.5, 1.0), 0.0)
    assert TrialSettings(backend="hardware").sigma == (0.5, 1.0)
    assert TrialSettings(backend="hardware").turn_deg == 0.0
    assert TrialSettings(backend="synthetic").turn_deg == 0.0
    given = TrialSettings(backend="sim", sigma_pos_mm=0.2)
    assert (given.sigma, given.turn_deg) == ((0.2, 0.7), 0.0)
    off = TrialSettings(backend="sim", sigma_turn_deg=0)
    assert (off.sigma, off.turn_deg) == ((0.35, 0.7), 0.0)
    only_turn = TrialSettings(backend="sim", sigma_turn_deg=0.8)
    assert (only_turn.sigma, only_turn.turn_deg) == ((0.2, 0.4), 0.8)
    assert TrialSettings(backend="sim", sigma_motion=0.2).turn_deg == 0.0
    # A hand without a thumb has no turn axis: no default turn, the scales without it.
    hand = (Path(__file__).parents[1] / "models/hands/modelo.yaml").read_text()
    spec = tmp_path / "thumbless.yaml"
    spec.write_text(hand.replace("name: modelo", "name: thumbless")
                    .replace("slot: thumb", "slot: opposer")
                    .replace("finger: modelo", f"finger: {Path(__file__).parents[1]}"
                             "/models/fingers/modelo.yaml"))
    thumbless = TrialSettings(backend="sim", hand=str(spec))
    assert (thumbless.sigma, thumbless.turn_deg) == ((0.35, 0.7), 0.0)


def test_contact_stiffness_anneal_stages_link_scaling_and_priors_reach_the_filter():
    from vlr.filter import FilterConfig
    from vlr.kinematics import HandModel
    from vlr.motion import MotionConfig
    from vlr.spec import load_hand
    from vlr.trial import identify_config

    model = HandModel.from_spec(load_hand("modelo"))
    default = identify_config(TrialSettings(backend="synthetic", particles=50), model).filter
    assert default.motion.contact_stiffness == MotionConfig.contact_stiffness
    assert default.anneal_stages == 1
    cfg = identify_config(TrialSettings(backend="synthetic", particles=50,
                                        contact_stiffness=2e4, anneal_stages=4), model).filter
    assert cfg.motion.contact_stiffness == 2e4 and cfg.anneal_stages == 4
    assert default.motion.limit_stiffness == MotionConfig.limit_stiffness
    assert identify_config(TrialSettings(backend="synthetic", particles=50,
                                         limit_stiffness=17.0),
                           model).filter.motion.limit_stiffness == 17.0
    assert default.motion.cone_return == float("inf")
    cone = identify_config(TrialSettings(backend="synthetic", particles=50, rolling=True,
                                         cone_return=1.0), model).filter
    assert cone.motion.cone_return == 1.0
    assert not default.motion.link_scaling
    scaled = identify_config(TrialSettings(backend="synthetic", particles=50,
                                           link_scaling=True), model).filter
    assert scaled.motion.link_scaling
    assert default.jitter_h == FilterConfig.jitter_h
    narrow = identify_config(TrialSettings(backend="synthetic", particles=50, jitter_h=0.1),
                             model).filter
    assert narrow.jitter_h == 0.1
    assert default.ess_fraction == FilterConfig.ess_fraction
    assert identify_config(TrialSettings(backend="synthetic", particles=50, ess_fraction=0.5),
                           model).filter.ess_fraction == 0.5
    assert default.jitter_kernel == "log-springs" == FilterConfig.jitter_kernel
    assert identify_config(TrialSettings(backend="synthetic", particles=50,
                                         jitter_kernel="copula"),
                           model).filter.jitter_kernel == "copula"
    assert default.contact_spread == FilterConfig.contact_spread
    wide = identify_config(TrialSettings(backend="synthetic", particles=50,
                                         contact_spread_deg=35.0), model).filter
    assert wide.contact_spread == pytest.approx(math.radians(35.0))
    assert default.contact_prior == "pad"                      # the synthetic world's
    assert TrialSettings(backend="sim").contact_prior_in_effect == "surface"
    assert TrialSettings(backend="hardware").contact_prior_in_effect == "surface"
    assert identify_config(TrialSettings(backend="sim", particles=50, contact_prior="pad"),
                           model).filter.contact_prior == "pad"
    for bad, match in ((dict(contact_prior="face"), "contact_prior 'face'"),
                       (dict(contact_spread_deg=0.0), "contact_spread_deg 0.0"),
                       (dict(contact_spread_deg=120.0), "contact_spread_deg 120.0"),
                       (dict(contact_spread_deg="wide"), "contact_spread_deg 'wide'"),
(dict(link_scaling="yes"), "link_scaling 'yes'"),
                       (dict(jitter_h=1.0), "jitter_h 1.0"),
                       (dict(jitter_h="wide"), "jitter_h 'wide'"),
                       (dict(ess_fraction=1.0), "ess_fraction 1.0"),
                       (dict(ess_fraction="half"), "ess_fraction 'half'"),
                       (dict(jitter_kernel="box"), "jitter_kernel 'box'"),
                       (dict(contact_stiffness=0.0), "contact_stiffness 0.0"),
                       (dict(contact_stiffness="soft"), "contact_stiffness 'soft'"),
                       (dict(limit_stiffness=-1.0), "limit_stiffness -1.0"),
                       (dict(limit_stiffness="hard"), "limit_stiffness 'hard'"),
                       (dict(anneal_stages=0), "anneal_stages 0"),
                       (dict(cone_return=0.0, rolling=True), "cone_return 0.0"),
                       (dict(cone_return=1.0, rolling=False), "rolling"),
                       (dict(cone_return=1.0, rolling=True, slide_friction=1.0),
                        "one or the other"),
                       (dict(anneal_stages=2.5), "anneal_stages 2.5")):
        with pytest.raises(UserError, match=match):
            TrialSettings(**bad)


def test_the_action_range_reaches_the_identification_and_bad_ones_are_named():
    from vlr.identify import IdentifyConfig
    from vlr.kinematics import HandModel
    from vlr.spec import load_hand
    from vlr.trial import identify_config

    model = HandModel.from_spec(load_hand("modelo"))
    default = identify_config(TrialSettings(backend="synthetic", particles=50), model)
    assert (default.action_range, default.action_band) == (IdentifyConfig.action_range,
                                                           IdentifyConfig.action_band)
    wide = identify_config(TrialSettings(backend="synthetic", particles=50,
                                         action_range_mm=[0.3, 0.6], action_band_mm=0.8),
                           model)
    assert wide.action_range == pytest.approx((0.3e-3, 0.6e-3))
    assert wide.action_band == pytest.approx(0.8e-3)
    assert TrialSettings(action_range_mm=[0.3, 0.6]).to_dict()["action_range_mm"] == [0.3, 0.6]
    for bad, match in ((dict(action_range_mm=[0.4, 0.2]), "action_range_mm"),
                       (dict(action_range_mm=[0.2, 3.0]), "action_range_mm"),
                       (dict(action_range_mm=0.3), "action_range_mm"),
                       (dict(action_band_mm=-1.0), "action_band_mm")):
        with pytest.raises(UserError, match=match):
            TrialSettings(**bad)


def test_the_prior_shape_reaches_the_filter_and_a_bad_one_is_named():
    from vlr.kinematics import HandModel
    from vlr.spec import load_hand
    from vlr.trial import identify_config

    model = HandModel.from_spec(load_hand("modelo"))
    assert identify_config(TrialSettings(backend="synthetic", particles=50),
                           model).filter.prior_shape == "uniform"
    assert identify_config(TrialSettings(backend="synthetic", particles=50,
                                         prior_shape="log-uniform"),
                           model).filter.prior_shape == "log-uniform"
    with pytest.raises(UserError, match="prior_shape 'cubic'"):
        TrialSettings(prior_shape="cubic")

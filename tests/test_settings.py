"""The settings tree (`vlr.settings`): one loader, each backend's defaults (`vlr.backends`),
the world it opens (`vlr.world`), and settings that make no sense refused as one `UserError`
naming the key."""

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.extras import needs_hardware
from vlr import models
from vlr.cli import main
from vlr.errors import UserError
from vlr.filter import FilterConfig
from vlr.identify import LoopConfig
from vlr.motion import MotionConfig
from vlr.observation import ObservationConfig
from vlr.settings import Settings, apply_layer, load_settings, settings_help
from vlr.world import open_world

ROOT = Path(__file__).resolve().parents[1]


def _load(backend: str, **dotted) -> Settings:
    return load_settings({"world.backend": backend}, dotted)


def _one_line_error(layer: dict, key: str) -> str:
    with pytest.raises(UserError) as err:
        load_settings(layer)
    text = str(err.value)
    assert key in text and "\n" not in text, text
    return text


# --------------------------------------------------------------------------- the loader

def test_dotted_and_nested_layers_are_the_same_tree_and_later_layers_win():
    dotted = load_settings({"world.backend": "synthetic", "filter.particles": 500,
                            "filter.motion.contact_stiffness": 2e4, "loop.max_iterations": 3,
                            "seed": 4})
    nested = load_settings({"world": {"backend": "synthetic"},
                            "filter": {"particles": 500, "motion": {"contact_stiffness": 2e4}},
                            "loop": {"max_iterations": 3}, "seed": 4})
    assert dotted == nested
    assert (dotted.filter.particles, dotted.loop.max_iterations, dotted.seed) == (500, 3, 4)
    assert dotted.filter.motion.contact_stiffness == 2e4
    later = load_settings({"filter.particles": 500}, {"filter": {"particles": 700}})
    assert later.filter.particles == 700
    # apply_layer replaces keys of an existing tree and leaves the others alone
    moved = apply_layer(dotted, {"filter.jitter_h": 0.2, "loop.action_band_mm": 0.8})
    assert (moved.filter.jitter_h, moved.loop.action_band_mm) == (0.2, 0.8)
    assert moved.filter.particles == 500 and moved.filter.motion == dotted.filter.motion
    assert dotted.with_(**{"filter.particles": 600}).filter.particles == 600


def test_the_flat_tree_loads_back_to_the_same_settings():
    """`Settings.flat()` is what result.json and a sweep's trial record store: loaded again
    (`vlr crb --replay`), it is the tree that ran, on every backend."""
    for backend, extra in (("sim", {"world.options.tension_noise_n": 0.25}),
                           ("synthetic", {"world.options.true_stiffness": {"thumb.distal": 0.045},
                                          "filter.unknowns": ["stiffness:thumb.distal"],
                                          "filter.priors": {"stiffness:thumb.distal":
                                                            [0.01, 0.1]}}),
                           ("hardware", {"world.options.config": "x.yaml",
                                         "filter.object.com": [0.0, 0.0, 0.01]})):
        s = load_settings({"world.backend": backend, "filter.guess_theta_deg": [-5, 20]}, extra)
        flat = s.flat()
        assert all(isinstance(k, str) and not isinstance(v, tuple) for k, v in flat.items())
        assert load_settings(flat) == s
        assert flat["world.backend"] == backend and flat["filter.guess_theta_deg"] == [-5, 20]


def test_a_wrong_type_and_an_unknown_key_are_one_error_naming_the_key():
    text = _one_line_error({"filter.particles": "many"}, "filter.particles")
    assert "'many' is not an integer" in text
    text = _one_line_error({"filter.particlez": 500}, "filter.particlez")
    assert "filter.particles" in text           # the keys it knows, to correct the typo
    _one_line_error({"filter": {"motion": {"rolling": "yes"}}}, "filter.motion.rolling")
    _one_line_error({"loop.max_iterations": "3"}, "loop.max_iterations")
    _one_line_error({"filter.observation.sigma_pos_mm": "x"}, "filter.observation.sigma_pos_mm")
    text = _one_line_error({"filter.guess_theta_deg": 3}, "filter.guess_theta_deg")
    assert text.endswith("3 is not a list of numbers or none"), text
    text = _one_line_error({"loop.action_range_mm": 0.3}, "loop.action_range_mm")
    assert text.endswith("0.3 is not a list of 2 numbers"), text
    _one_line_error({"world.backend": "nowhere"}, "world.backend 'nowhere'")
    _one_line_error({"filter.particles.count": 3}, "filter.particles")  # no sub-keys
    _one_line_error({"filter": 5}, "filter")


def test_a_number_written_with_an_exponent_is_a_number():
    """YAML 1.1 reads `1e5` (no dot, no sign) as a string: in a settings file and as `--set
    KEY=1e5` it is still the number."""
    s = load_settings({"filter.motion.contact_stiffness": "1e5"},
                      yaml.safe_load("filter: {observation: {sigma_pos_mm: 2e-1}}"))
    assert s.filter.motion.contact_stiffness == 1e5
    assert s.filter.observation.sigma_pos_mm == 0.2
    _one_line_error({"filter.motion.contact_stiffness": "1e5x"}, "filter.motion.contact_stiffness")


@pytest.mark.parametrize("key, value, match", [
    ("filter.contact_prior", "face", "'face'"),
    ("filter.contact_spread_deg", 0.0, "0.0"),
    ("filter.contact_spread_deg", 120.0, "120.0"),
    ("filter.contact_spread_deg", "wide", "'wide'"),
    ("filter.theta_spread_deg", -1, "-1"),
    ("filter.jitter_h", 1.0, "1.0"),
    ("filter.jitter_h", "wide", "'wide'"),
    ("filter.ess_fraction", 1.0, "1.0"),
    ("filter.ess_fraction", "half", "'half'"),
    ("filter.priors", {"mass": [0.2, 0.1]}, "0.2"),
    ("filter.object.mass", -1, "-1"),
    ("filter.motion.contact_stiffness", 0.0, "0.0"),
    ("filter.motion.contact_stiffness", "soft", "'soft'"),
    ("filter.motion.limit_stiffness", -1.0, "-1.0"),
    ("filter.motion.limit_stiffness", "hard", "'hard'"),
    ("filter.observation.sigma_turn_deg", -0.5, "-0.5"),
    ("filter.observation.sigma_turn_deg", "wide", "'wide'"),
    ("filter.observation.sigma_tension_n", -0.5, "-0.5"),
    ("filter.observation.sigma_tension_n", "firm", "'firm'"),
    ("loop.action_range_mm", [0.4, 0.2], "0.4"),
    ("loop.action_range_mm", [0.2, 3.0], "3.0"),
    ("loop.action_range_mm", 0.3, "0.3"),
    ("loop.action_band_mm", -1.0, "-1.0"),
    ("loop.exploration", "greedy", "'greedy'"),
    ("loop.active.candidates", 0, "0"),
    ("loop.active.subset", 1.5, "1.5"),
    ("world.options.ramp_time", 0.0, "0.0"),
    ("world.options.ramp_time", 5.0, "5.0"),
    ("world.options.ramp_time", "slow", "'slow'"),
    ("world.options.tension_noise_n", -1.0, "-1"),
    ("world.options.tension_noise_n", "loud", "'loud'"),
])
def test_a_value_a_component_refuses_is_one_error_naming_the_key(key, value, match):
    text = _one_line_error({"world.backend": "sim", key: value}, key)
    assert match in text, text


# Every option deleted with the settings tree (docs/DECISIONS.md has what each measured), as
# a sweep file or `vlr identify --set` would give it: (backend, key, YAML value, named).
REMOVED = [
    ("sim", "filter.likelihood_dof", "4", None),
    ("sim", "filter.observation.likelihood_dof", "4", None),
    ("sim", "filter.jitter_kernel", "copula", None),
    ("sim", "filter.jitter_kernel", "log-scales", None),
    ("sim", "filter.anneal_stages", "4", None),
    ("sim", "filter.unknowns", "[noise]", "noise"),
    ("sim", "filter.noise_prior", "[0.5, 2.0]", None),
    ("sim", "filter.unknown_warmup", "3", None),
    ("sim", "filter.unknown_discount", "0.5", None),
    ("sim", "filter.sigma_motion", "0.1", None),
    ("sim", "filter.observation.sigma_motion", "0.1", None),
    ("sim", "filter.observation.motion_fraction", "0.1", None),
    ("sim", "filter.motion.cone_return", "1.0", None),
    ("sim", "filter.motion.spin_memory", "true", None),
    ("sim", "filter.motion.link_scaling", "true", None),
    ("sim", "filter.motion.exact_cylinder", "true", None),
    ("sim", "filter.motion.slide_friction", "1.0", None),
    ("sim", "filter.motion.spin_stiffness", "0.1", None),
    ("sim", "filter.motion.spin_smoothing", "0.1", None),
    ("sim", "filter.motion.with_rolling", "true", None),
    ("sim", "filter.prior_shape", "log-uniform", None),
    ("sim", "loop.active.criterion", "variance", None),
    ("sim", "loop.active.model_error", "0.5", None),
    ("sim", "loop.active.min_normal_force", "0.05", None),
    ("sim", "loop.active.min_force_n", "0.05", None),
    ("synthetic", "world.options.solve", "loose", None),
    ("synthetic", "world.options.synthetic_solve", "loose", None),
    # the flat names of the former settings, as an old sweep file has them
    ("sim", "jitter_kernel", "gaussian", None),
    ("sim", "sigma_motion", "0.1", None),
    ("sim", "active_criterion", "variance", None),
    ("synthetic", "synthetic_solve", "loose", None),
]


@pytest.mark.parametrize("backend, key, value, named", REMOVED,
                         ids=[f"{r[1]}={r[2]}" for r in REMOVED])
def test_every_removed_option_is_refused_by_name(tmp_path, capsys, backend, key, value, named):
    """In a sweep file's settings and as `vlr identify --set`: one UserError, one line,
    naming the option, and nothing run."""
    from vlr.sweep import expand, load_sweep

    named = named or key
    sweep = tmp_path / "s.yaml"
    sweep.write_text(f"out: {tmp_path / 'runs'}\n"
                     f"settings: {{world.backend: {backend}, {key}: {value}}}\n")
    with pytest.raises(UserError) as err:
        expand(load_sweep(sweep))
    assert named in str(err.value) and "\n" not in str(err.value), str(err.value)
    out = tmp_path / "identify"
    assert main(["identify", "--backend", backend, "--set", f"{key}={value}", "--out",
                 str(out), "--quiet"]) == 2
    stderr = capsys.readouterr().err.strip()
    assert len(stderr.splitlines()) == 1 and named in stderr, stderr
    assert not out.exists() and not (tmp_path / "runs").exists()


# --------------------------------------------------------------------------- vlr identify

def test_identify_set_with_a_bad_value_exits_2_with_one_line(tmp_path, capsys):
    out = tmp_path / "bad"
    assert main(["identify", "--backend", "synthetic", "--set", "filter.particles=abc",
                 "--out", str(out), "--quiet"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "filter.particles" in lines[0] and "'abc'" in lines[0], lines
    assert not out.exists()
    # a --set without '=' is named too
    assert main(["identify", "--set", "filter.particles", "--out", str(out), "--quiet"]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err


def test_identify_flags_set_and_settings_file_layer_in_order(tmp_path):
    """The backend's defaults, then the --settings file, then the flags, then each --set."""
    import argparse

    from vlr.cli import build_parser
    from vlr.commands.identify import settings_from_args

    path = tmp_path / "s.yaml"
    path.write_text("filter: {particles: 900, jitter_h: 0.3}\nloop.max_iterations: 7\n")
    parser = build_parser()
    args = parser.parse_args(["identify", "--backend", "synthetic", "--settings", str(path),
                              "--particles", "800", "--unknown", "mass",
                              "--set", "filter.jitter_h=0.2", "--set", "seed=5"])
    assert isinstance(args, argparse.Namespace)
    s = settings_from_args(args)
    assert (s.world.backend, s.filter.particles, s.filter.jitter_h) == ("synthetic", 800, 0.2)
    assert (s.loop.max_iterations, s.seed, s.filter.unknowns) == (7, 5, ("mass",))
    assert s.filter.motion.rolling is False       # the synthetic backend's default stays


def test_identify_help_is_short_and_lists_every_setting(capsys):
    with pytest.raises(SystemExit) as done:
        main(["identify", "--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    head, sep, tail = text.partition("\nsettings (--set KEY=VALUE")
    assert sep, text[-400:]
    options = set()
    for line in head.splitlines():
        m = re.match(r"^\s{2}(-[\w-]+)(?:,\s*(--[\w-]+))?", line)
        if m:
            options.add(m.group(2) or m.group(1))
    assert "--set" in options and "--backend" in options
    flags = options - {"--set", "--help", "-h"}
    assert len(flags) <= 16, sorted(flags)  # the rest is in the settings tree
    listed = {line.split()[0] for line in tail.splitlines()[1:] if line.strip()}
    assert listed == set(load_settings({"world.backend": "sim"}).flat())
    assert "filter.observation.sigma_tension_n" in listed and "loop.active.subset" in listed


def test_settings_help_gives_each_key_with_its_value():
    lines = settings_help(_load("synthetic")).splitlines()
    by_key = {line.split()[0]: line.split(None, 1)[1] for line in lines}
    assert by_key["filter.motion.rolling"] == "False"
    assert by_key["filter.contact_prior"] == "'pad'"


# --------------------------------------------------------------------------- backend defaults

def test_the_sims_defaults():
    """What was measured best on the sim (docs/DECISIONS.md): rolling contacts, 0.2 mm /
    0.4 deg with a 1-deg turn, the model's stops at 17 N m/rad, the guess (-10, 15) +- 10
    deg, commands ramped over 0.1 s, the surface contact prior."""
    s = _load("sim")
    assert s.filter.motion.rolling is True
    assert s.filter.observation == ObservationConfig(sigma_pos_mm=0.2, sigma_rot_deg=0.4,
                                                     sigma_turn_deg=1.0, sigma_tension_n=0.0)
    assert s.filter.motion.limit_stiffness == 17.0
    assert (s.filter.guess_theta_deg, s.filter.theta_spread_deg) == ((-10.0, 15.0), 10.0)
    assert s.filter.contact_prior == "surface"
    assert s.world.options == {"ramp_time": 0.1, "tension_noise_n": 0.0}
    assert load_settings() == s      # the sim is the default backend


def test_the_synthetic_worlds_defaults():
    """The world is the filter's model: pinned contacts, 0.1 mm / 0.4 deg without the turn,
    the pad contact prior, the generic guess with the dataclass's 3-deg spread."""
    s = _load("synthetic")
    assert s.filter.motion.rolling is False
    assert s.filter.observation == ObservationConfig(sigma_pos_mm=0.1, sigma_rot_deg=0.4,
                                                     sigma_turn_deg=0.0, sigma_tension_n=0.0)
    assert s.filter.contact_prior == "pad"
    assert (s.filter.guess_theta_deg, s.filter.theta_spread_deg) == (None, 3.0)
    assert s.filter.motion.limit_stiffness == MotionConfig.limit_stiffness == 100.0
    assert s.world.options == {"true_stiffness": {}}


def test_the_real_hands_defaults_are_the_dataclasses():
    s = _load("hardware")
    assert s.filter == FilterConfig() and s.loop == LoopConfig()
    assert s.filter.motion.rolling is True and s.filter.contact_prior == "surface"
    assert s.filter.observation == ObservationConfig(sigma_pos_mm=0.5, sigma_rot_deg=1.0)
    assert s.world.options == {"config": None}


def test_an_explicit_setting_wins_over_the_backends_default():
    assert not _load("sim", **{"filter.motion.rolling": False}).filter.motion.rolling
    assert _load("synthetic", **{"filter.motion.rolling": True}).filter.motion.rolling
    assert _load("sim", **{"filter.motion.limit_stiffness": 100.0}
                 ).filter.motion.limit_stiffness == 100.0
    assert _load("hardware", **{"filter.motion.limit_stiffness": 17.0}
                 ).filter.motion.limit_stiffness == 17.0
    guess = _load("sim", **{"filter.guess_theta_deg": [-5, 20], "filter.theta_spread_deg": 4})
    assert (guess.filter.guess_theta_deg, guess.filter.theta_spread_deg) == ((-5.0, 20.0), 4.0)
    assert _load("synthetic", **{"filter.theta_spread_deg": 7.0}).filter.theta_spread_deg == 7.0
    assert _load("sim", **{"filter.contact_prior": "pad"}).filter.contact_prior == "pad"
    # one scale given, the backend's other scales stay
    ob = _load("sim", **{"filter.observation.sigma_pos_mm": 0.3}).filter.observation
    assert (ob.sigma_pos_mm, ob.sigma_rot_deg, ob.sigma_turn_deg) == (0.3, 0.4, 1.0)
    assert _load("sim", **{"filter.observation.sigma_turn_deg": 0}
                 ).filter.observation.sigma_turn_deg == 0.0
    assert _load("sim", **{"world.options.ramp_time": 0.05}).world.options["ramp_time"] == 0.05


def test_the_sim_moves_as_the_hardware_backend_does():
    """The sim's identification ramps each command change over the hardware backend's
    default move (docs/DECISIONS.md); a trial may say otherwise, on the sim only."""
    from vlr.hardware.config import TendonMotion as HardwareMotion

    hw = HardwareMotion(spool_radius=0.005, max_step=1e-3, range=(0.0, 0.01))
    assert _load("sim").world.options["ramp_time"] == pytest.approx(
        hw.ramp_steps * hw.ramp_period)
    _one_line_error({"world.backend": "synthetic", "world.options.ramp_time": 0.1},
                    "world.options.ramp_time")
    w = open_world(_load("sim", **{"filter.particles": 100, "world.options.ramp_time": 0.07}))
    try:
        assert w.world.options.ramp_time == 0.07
    finally:
        w.close()


def test_world_options_belong_to_their_backend():
    _one_line_error({"world.backend": "sim",
                     "world.options.true_stiffness": {"thumb.distal": 0.045}},
                    "world.options.true_stiffness")
    _one_line_error({"world.backend": "hardware", "world.options.tension_noise_n": 0.5},
                    "world.options.tension_noise_n")
    _one_line_error({"world.backend": "synthetic", "world.options.tension_noise_n": 0.5},
                    "world.options.tension_noise_n")
    _one_line_error({"world.backend": "hardware", "world.true_hand": "nh1"}, "world.true_hand")
    _one_line_error({"world.backend": "synthetic",
                     "world.options.true_stiffness": {"thumb.distal": "stiff"}},
                    "world.options.true_stiffness.thumb.distal")
    # a later layer's backend decides whose options and defaults apply
    s = load_settings({"world.backend": "sim"}, {"world.backend": "synthetic"})
    assert s.world.options == {"true_stiffness": {}} and not s.filter.motion.rolling


# --------------------------------------------------------------------------- the world

def test_the_settings_reach_the_filter():
    """The tree's filter is the filter's configuration: its motion model, likelihood
    scales (SI in `ObservationModel`), jitter, tempering and contact prior."""
    from vlr.filter import ParticleFilter
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.spec import load_hand, load_object

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams.from_spec(load_object("apple"))
    s = _load("synthetic", **{"filter.particles": 50, "filter.motion.contact_stiffness": 2e4,
                              "filter.motion.limit_stiffness": 17.0, "filter.jitter_h": 0.1,
                              "filter.ess_fraction": 0.5, "filter.contact_spread_deg": 35.0,
                              "filter.observation.sigma_turn_deg": 0.8})
    pf = ParticleFilter(model, obj, s.filter, s.seed)
    assert pf.motion.config.contact_stiffness == 2e4
    assert pf.motion.config.limit_stiffness == 17.0
    assert not pf.motion.config.rolling
    assert (pf.config.jitter_h, pf.config.ess_fraction) == (0.1, 0.5)
    assert pf.config.contact_spread == pytest.approx(math.radians(35.0))
    assert pf.config.contact_prior == "pad"
    assert (pf.obs_model.sigma_pos, pf.obs_model.sigma_rot) == pytest.approx(
        (0.1e-3, math.radians(0.4)))
    assert pf.obs_model.sigma_turn == pytest.approx(math.radians(0.8))
    assert pf.obs_model.opposed == model.names.index("thumb")
    default = ParticleFilter(model, obj, _load("synthetic", **{"filter.particles": 50}).filter)
    assert default.motion.config.contact_stiffness == MotionConfig.contact_stiffness
    assert default.config.jitter_h == FilterConfig.jitter_h
    assert default.config.ess_fraction == FilterConfig.ess_fraction
    assert default.config.contact_spread == pytest.approx(math.radians(
        FilterConfig.contact_spread_deg))


def test_a_synthetic_run_records_the_settings_it_ran_with():
    from vlr.run import run_identification

    run = run_identification(_load("synthetic", **{"filter.particles": 300,
                                                   "loop.max_iterations": 2}))
    s = run.summary["settings"]
    assert run.summary["iterations"] == 2
    assert s == run.settings.flat()
    assert s["filter.motion.rolling"] is False        # the synthetic world's, as it ran
    assert (s["filter.observation.sigma_pos_mm"], s["filter.observation.sigma_rot_deg"],
            s["filter.observation.sigma_turn_deg"]) == (0.1, 0.4, 0.0)
    # the guess in effect: None, the synthetic world's generic one, with its spreads
    assert s["filter.guess_theta_deg"] is None and s["filter.theta_spread_deg"] == 3.0
    assert s["filter.contact_spread_deg"] == pytest.approx(8.594, abs=1e-3)
    assert s["filter.contact_prior"] == "pad"
    assert s["world.options"] == {"true_stiffness": {}}


def test_the_action_range_reaches_the_identification():
    """Each tendon's change is as large as `loop.action_range_mm` says."""
    from vlr.run import run_identification

    s = _load("synthetic", **{"filter.particles": 100, "loop.max_iterations": 3,
                              "loop.action_range_mm": [0.3, 0.6], "loop.action_band_mm": 0.8})
    assert s.loop.action_range_mm == (0.3, 0.6) and s.flat()["loop.action_range_mm"] == [0.3, 0.6]
    run = run_identification(s)
    steps = np.abs(np.diff(run.summary["commands_mm_by_iteration"], axis=0))
    assert steps.shape == (3, 3)
    assert np.all((steps > 0.3 - 1e-6) & (steps < 0.6 + 1e-6)), steps


def test_the_sim_is_built_with_the_true_hand_and_the_filter_keeps_the_nominal_one():
    """NH1 in the sim: the left finger is NF1 (40 mm proximal link) in the simulated hand
    and in the scoring truth; the filter's model is still the Model O's (62 mm)."""
    w = open_world(_load("sim", **{"world.hand": "modelo", "world.true_hand": "nh1",
                                   "filter.particles": 100,
                                   "filter.unknowns": ["length:left.proximal"]}))
    try:
        left = w.model.names.index("left")
        assert w.model.segments[left, 0] == pytest.approx(0.062)
        assert w.hand_spec.name == "modelo"
        assert w.world.true_spec.mount("left").finger.proximal_length == pytest.approx(0.040)
        w.world.grasp()
        assert w.truth().segments[left, 0] == pytest.approx(0.040)
    finally:
        w.close()


@needs_hardware
def test_the_filter_models_the_object_the_hardware_config_names():
    """The config (apple) decides what is in the hand, not world.object's value."""
    config = models.ROOT.parent / "hardware" / "example_sim_config.yaml"
    w = open_world(_load("hardware", **{"world.object": "wine_glass", "filter.particles": 100,
                                        "world.options.config": str(config)}))
    try:
        assert w.object_spec.name == "apple"
        assert w.obj.mass == pytest.approx(w.object_spec.mass)
    finally:
        w.close()


def test_a_nominal_guess_per_finger():
    """K angles guess every finger alike; N x K guess each finger (a thumb wrapped round a
    thin shaft); any other count is one error naming the counts."""
    alike = open_world(_load("synthetic", **{"filter.guess_theta_deg": [-10, 15]}))
    wrapped = open_world(_load("synthetic",
                               **{"filter.guess_theta_deg": [-10, 70, -10, 15, -10, 15]}))
    thumb = alike.model.names.index("thumb")
    assert np.degrees(wrapped.nominal.theta[thumb, 1]) > 50
    assert np.degrees(alike.nominal.theta[thumb, 1]) < 40
    with pytest.raises(UserError, match=r"filter.guess_theta_deg .*give 2 angles .* or 6"):
        open_world(_load("synthetic", **{"filter.guess_theta_deg": [-10, 15, 3]}))


def test_the_synthetic_prior_is_drawn_about_the_generic_guess():
    world = open_world(_load("synthetic"))
    generic = open_world(_load("synthetic", **{"filter.guess_theta_deg": [-17.19, 68.75]}))
    assert abs(world.nominal.theta - generic.nominal.theta).max() < 1e-3


def test_a_hand_without_a_thumb_has_no_turn_axis(tmp_path):
    """The turn term's axis runs from the thumb: a hand without one is refused by name
    before any world opens, unless the term is off."""
    hand = (ROOT / "models" / "hands" / "modelo.yaml").read_text()
    spec = tmp_path / "thumbless.yaml"
    spec.write_text(hand.replace("name: modelo", "name: thumbless")
                    .replace("slot: thumb", "slot: opposer")
                    .replace("finger: modelo", f"finger: {ROOT / 'models/fingers/modelo.yaml'}"))
    with pytest.raises(UserError, match="filter.observation.sigma_turn_deg 1.*thumb"):
        open_world(_load("sim", **{"world.hand": str(spec)}))
    with pytest.raises(UserError, match="filter.observation.sigma_turn_deg 0.8.*thumb"):
        open_world(_load("synthetic", **{"world.hand": str(spec),
                                         "filter.observation.sigma_turn_deg": 0.8}))
    w = open_world(_load("synthetic", **{"world.hand": str(spec)}))   # no turn term: fine
    assert "thumb" not in w.model.names


def test_bad_unknowns_and_priors_are_named_before_a_world_opens():
    with pytest.raises(UserError, match="pinky"):
        open_world(_load("synthetic", **{"filter.unknowns": ["stiffness:pinky.distal"]}))
    with pytest.raises(UserError, match="filter.priors: 'mass' is not among the unknowns"):
        open_world(_load("synthetic", **{"filter.priors": {"mass": [0.05, 0.1]}}))


def test_the_tree_is_frozen_dataclasses():
    s = load_settings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.seed = 3
    with pytest.raises(UserError, match="seed"):
        load_settings({"seed": -1})

"""`vlr identify` end to end: files written, bad input refused with a clear message."""

import json

import numpy as np
import pytest

from tests.extras import needs_hardware
from vlr.cli import main


def test_identify_synthetic_writes_result_history_and_plot(tmp_path):
    out = tmp_path / "run"
    rc = main(["identify", "--backend", "synthetic", "--particles", "1500",
               "--max-iterations", "3", "--seed", "1", "--out", str(out), "--quiet"])
    assert rc == 0
    result = json.loads((out / "result.json").read_text())
    for key in ("converged", "iterations", "coverage", "timing"):
        assert key in result
    assert result["iterations"] == 3
    # Every setting in effect is recorded (the synthetic world's likelihood has no turn term).
    s = result["settings"]
    assert (s["filter.observation.sigma_pos_mm"], s["filter.observation.sigma_rot_deg"],
            s["filter.observation.sigma_turn_deg"]) == (0.1, 0.4, 0.0)
    assert (s["world.backend"], s["filter.particles"], s["loop.max_iterations"], s["seed"]) == (
        "synthetic", 1500, 3, 1)
    assert {"proximal_deg_mean", "distal_deg_mean", "contact_mm_mean"} <= set(result["errors"])
    hist = np.load(out / "history.npz")
    assert hist["mean"].shape[0] == 4  # the initial update plus three actions
    # The plotted truth agrees with the scored error of the final iteration.
    final_err = np.degrees(np.abs(hist["mean"][-1, :6] - hist["truth_theta"][-1]))
    np.testing.assert_allclose(final_err, hist["theta_error_deg"][-1], atol=1e-9)
    np.testing.assert_allclose(result["errors"]["joint_deg_mean"], final_err.mean(), atol=1e-9)
    assert (out / "convergence.png").stat().st_size > 1000
    # The tolerant coverage counts a truth at most 0.1 degree outside its interval.
    low, high = hist["low"][-1, :6], hist["high"][-1, :6]
    miss = np.degrees(np.maximum(np.maximum(low - hist["truth_theta"][-1],
                                            hist["truth_theta"][-1] - high), 0.0))
    np.testing.assert_allclose(list(result["miss_deg"].values()), miss, atol=1e-9)
    assert result["coverage_tolerant"] == np.mean(miss <= 0.1)
    assert result["coverage_tolerant"] >= result["coverage"]
    np.testing.assert_allclose(result["ci_deg_by_iteration"], hist["ci_deg"], atol=1e-4)
    np.testing.assert_allclose(result["proximal_deg_by_iteration"][-1],
                               result["errors"]["proximal_deg_mean"], atol=1e-4)
    # The reported estimates are the set that was scored (the last posterior).
    est = result["estimates"]
    np.testing.assert_allclose([e["low"] for e in est.values()], low, atol=1e-12)
    np.testing.assert_allclose([e["high"] for e in est.values()], high, atol=1e-12)
    # The posterior median is scored beside the mean, from the same set.
    np.testing.assert_allclose([e["median"] for e in est.values()], hist["median"][-1, :6],
                               atol=1e-12)
    med_err = np.degrees(np.abs(hist["median"][-1, :6] - hist["truth_theta"][-1]))
    np.testing.assert_allclose(result["errors_median"]["joint_deg_mean"], med_err.mean(),
                               atol=1e-9)
    np.testing.assert_allclose(result["proximal_median_deg_by_iteration"][-1],
                               result["errors_median"]["proximal_deg_mean"], atol=1e-4)
    np.testing.assert_allclose(result["joint_median_deg_by_iteration"][-1],
                               result["errors_median"]["joint_deg_mean"], atol=1e-4)


def test_identify_records_each_unknowns_error_per_iteration(tmp_path):
    out = tmp_path / "stiff"
    rc = main(["identify", "--backend", "synthetic", "--particles", "1500",
               "--max-iterations", "2", "--seed", "2", "--unknown", "stiffness:thumb.distal",
               "--set", "world.options.true_stiffness={thumb.distal: 0.045}", "--out", str(out),
               "--quiet"])
    assert rc == 0
    result = json.loads((out / "result.json").read_text())
    path = result["unknown_error_by_iteration"]["stiffness:thumb.distal"]
    assert len(path) == 3      # the grasp's update and two actions
    np.testing.assert_allclose(path[-1], result["errors"]["stiffness"]["thumb.distal"],
                               rtol=1e-3)
    hist = np.load(out / "history.npz")
    np.testing.assert_allclose(path, np.abs(hist["mean"][:, -1] - 0.045), rtol=1e-3)
    med = result["unknown_error_median_by_iteration"]["stiffness:thumb.distal"]
    np.testing.assert_allclose(med, np.abs(hist["median"][:, -1] - 0.045), rtol=1e-3)
    # convergence.png plots the unknown beside the joints, against its truth
    np.testing.assert_allclose(hist["truth_unknowns"], 0.045, rtol=1e-9)
    assert (out / "convergence.png").stat().st_size > 1000


def _gelatin_box(out, *options: str) -> tuple[dict, dict]:
    """A short synthetic trial on the gelatin box (97 g, its centre of mass 16 mm above the
    tag): its result.json and history.npz."""
    rc = main(["identify", "--backend", "synthetic", "--object", "gelatin_box", "--seed", "2",
               *options, "--out", str(out), "--quiet"])
    assert rc == 0
    return json.loads((out / "result.json").read_text()), np.load(out / "history.npz")


def _refused(tmp_path, *options: str) -> None:
    """Bad input: exit code 2 and no result folder."""
    rc = main(["identify", "--backend", "synthetic", *options, "--out",
               str(tmp_path / "bad"), "--quiet"])
    assert rc == 2 and not (tmp_path / "bad").exists()


def test_identify_scores_the_objects_unknowns(tmp_path):
    result, hist = _gelatin_box(tmp_path / "mass", "--particles", "1500", "--max-iterations",
                                "2", "--unknown", "mass", "--unknown", "com:z")
    # the gelatin box's spec: 97 g, its centre of mass 16 mm above the tag
    np.testing.assert_allclose(hist["truth_unknowns"], [[0.097, 0.016]] * 3, rtol=1e-9)
    np.testing.assert_allclose(result["errors"]["object_mass_g"],
                               1e3 * abs(hist["mean"][-1, -2] - 0.097), rtol=1e-6)
    np.testing.assert_allclose(result["errors"]["object_com_mm"]["z"],
                               1e3 * abs(hist["mean"][-1, -1] - 0.016), rtol=1e-6)
    # the signed path of each estimate, its last the final median
    path = result["unknown_median_by_iteration"]["mass"]
    assert len(path) == 3 and path[-1] == pytest.approx(
        result["unknown_estimates"]["mass"]["median"], rel=1e-4)
    _refused(tmp_path, "--unknown", "com:w")


def test_a_believed_mass_moves_the_mass_prior_and_not_the_world(tmp_path):
    _, hist = _gelatin_box(tmp_path / "believed", "--particles", "1000", "--max-iterations",
                           "1", "--unknown", "mass", "--set", "filter.object.mass=0.2")
    np.testing.assert_allclose(hist["truth_unknowns"], 0.097, rtol=1e-9)  # the spec's
    assert 0.05 <= hist["low"][0, -1] and hist["high"][0, -1] <= 0.8    # 0.25-4x 0.2 kg
    assert hist["high"][0, -1] > 0.4    # the prior about the believed 0.2, not the spec's
    _refused(tmp_path, "--set", "filter.object.mass=-1")


def test_a_believed_centre_of_mass_moves_the_com_prior_and_not_the_world(tmp_path):
    result, hist = _gelatin_box(tmp_path / "com", "--particles", "1000", "--max-iterations",
                                "1", "--unknown", "com:x", "--set",
                                "filter.object.com=[0.01, 0, 0.016]")
    np.testing.assert_allclose(hist["truth_unknowns"], 0.0, atol=1e-12)   # the spec's x
    assert -0.005 <= hist["low"][0, -1] and hist["high"][0, -1] <= 0.025  # 0.01 +- 0.015
    assert result["settings"]["filter.object.com"] == [0.01, 0.0, 0.016]
    _refused(tmp_path, "--set", "filter.object.com=[0, .nan, 0]")
    _refused(tmp_path, "--set", "filter.object.com=[0, 0]")


def test_identify_scores_the_curvature_and_a_believed_one_moves_its_prior(tmp_path):
    result, hist = _gelatin_box(tmp_path / "k", "--particles", "1000", "--max-iterations",
                                "1", "--unknown", "curvature", "--set",
                                "filter.object.curvature=40")
    np.testing.assert_allclose(hist["truth_unknowns"], 0.0)   # the world's box stays flat
    assert 0.0 <= hist["low"][0, -1] and 60.0 < hist["high"][0, -1] <= 80.0  # 0..2 x 40 /m
    np.testing.assert_allclose(result["errors"]["curvature_per_m"]["all"],
                               abs(hist["mean"][-1, -1]), rtol=1e-6)
    assert result["settings"]["filter.object.curvature"] == 40.0
    _refused(tmp_path, "--set", "filter.object.curvature=-1")


def test_a_prior_of_ones_own_bounds_an_unknown(tmp_path):
    result, hist = _gelatin_box(tmp_path / "p", "--particles", "1000", "--max-iterations", "1",
                                "--unknown", "mass", "--set", "filter.priors={mass: [0.05, 0.15]}")
    assert 0.05 <= hist["low"][0, -1] and hist["high"][0, -1] <= 0.15
    assert result["settings"]["filter.priors"] == {"mass": [0.05, 0.15]}
    for bad in ("{mass: [0.2, 0.1]}", "{mass: [0, 1]}", "{com:x: [0, 1]}", "{mass: [a, b]}",
                "{mass: 0.1}"):
        _refused(tmp_path, "--unknown", "mass", "--set", f"filter.priors={bad}")


def test_identify_sim_runs_from_rendered_frames(tmp_path):
    out = tmp_path / "sim"
    rc = main(["identify", "--backend", "sim", "--object", "gelatin_box", "--particles",
               "1000", "--max-iterations", "2", "--out", str(out), "--quiet"])
    assert rc == 0
    result = json.loads((out / "result.json").read_text())
    assert result["backend"] == "sim" and "errors" in result


def test_identify_with_the_ukf_writes_the_same_outputs(tmp_path, capsys):
    """`--estimator ukf`: the unscented Kalman filter on the same model, the same files,
    its sigma points as the hypotheses."""
    out = tmp_path / "ukf"
    rc = main(["identify", "--backend", "synthetic", "--estimator", "ukf", "--max-iterations",
               "3", "--seed", "1", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "unscented Kalman filter, 25 sigma points" in capsys.readouterr().out
    result = json.loads((out / "result.json").read_text())
    assert (result["estimator"], result["hypotheses"], result["particles"]) == ("ukf", 25, None)
    assert result["settings"]["filter.estimator"] == "ukf"
    assert {"proximal_deg_mean", "contact_mm_mean"} <= set(result["errors"])
    assert 0 <= result["coverage"] <= 1 and len(result["ci_deg_by_iteration"]) == 4
    assert result["timing"]["filter_s"] > 0
    hist = np.load(out / "history.npz")
    est = result["estimates"]
    np.testing.assert_allclose([e["low"] for e in est.values()], hist["low"][-1, :6])
    # The 95% interval is the Gaussian's: the criterion is its mean width.
    width = np.degrees(hist["high"][-1, :6] - hist["low"][-1, :6]).mean()
    np.testing.assert_allclose(result["ci_deg_by_iteration"][-1], width, atol=1e-3)
    for name in ("convergence.png", "particles.png"):
        assert (out / name).stat().st_size > 1000


def test_what_the_ukf_cannot_do_is_refused_in_one_line(tmp_path, capsys):
    for extra, named in ((["--unknown", "curvature"], "filter.unknowns 'curvature'"),
                         (["--set", "loop.exploration=active"], "loop.exploration active")):
        rc = main(["identify", "--backend", "synthetic", "--estimator", "ukf", *extra,
                   "--out", str(tmp_path), "--quiet"])
        err = capsys.readouterr().err
        assert rc == 2 and named in err and "filter.estimator: pf" in err
        assert len(err.strip().splitlines()) == 1
    rc = main(["identify", "--backend", "synthetic", "--set", "filter.estimator=kalman",
               "--out", str(tmp_path), "--quiet"])
    assert rc == 2 and "filter.estimator: 'kalman' is not one of pf, ukf" in (
        capsys.readouterr().err)
    assert not (tmp_path / "result.json").exists()


def test_identify_bad_input_is_one_clear_line(tmp_path, capsys):
    rc = main(["identify", "--backend", "synthetic", "--unknown", "stiffness:pinky.distal",
               "--out", str(tmp_path), "--quiet"])
    assert rc == 2
    assert "pinky" in capsys.readouterr().err
    rc = main(["identify", "--backend", "synthetic", "--set", "filter.jitter_h=1.5", "--out",
               str(tmp_path), "--quiet"])
    assert rc == 2
    assert "filter.jitter_h: jitter_h 1.5" in capsys.readouterr().err
    rc = main(["identify", "--backend", "nowhere", "--out", str(tmp_path), "--quiet"])
    assert rc == 2
    assert "world.backend 'nowhere': unknown" in capsys.readouterr().err
    assert not (tmp_path / "result.json").exists()


@needs_hardware
def test_identify_hardware_backend_against_emulated_motors_and_sim(tmp_path):
    """The whole hardware path: SDK packets on a pty, emulated XM430s driving the MuJoCo hand,
    its rendered frames through the fake camera, into the same filter."""
    from vlr import models

    config = models.ROOT.parent / "hardware" / "example_sim_config.yaml"
    out = tmp_path / "hw"
    rc = main(["identify", "--backend", "hardware", "--config", str(config), "--object",
               "apple", "--particles", "800", "--max-iterations", "2", "--out", str(out),
               "--quiet"])
    assert rc == 0
    result = json.loads((out / "result.json").read_text())
    assert result["backend"] == "hardware" and "errors" not in result  # no truth on hardware
    assert "truth_theta" not in np.load(out / "history.npz")


def test_identify_gives_up_clearly_when_the_tag_is_never_seen():
    from vlr.filter import FilterConfig
    from vlr.hand import GraspError
    from vlr.identify import LoopConfig, identify
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.spec import load_hand, load_object
    from vlr.synthetic import SyntheticConfig, SyntheticWorld, nominal_grasp

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams.from_spec(load_object("apple"))
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0))
    with pytest.raises(GraspError, match="not seen in 30 frames"):
        identify(world, lambda: None, model, obj, nominal_grasp(model, obj, SyntheticConfig()),
                 FilterConfig(particles=100), LoopConfig())


def test_identify_shows_each_unknown_in_its_unit():
    from vlr.commands.identify import format_table
    from vlr.identify import Estimate

    unknowns = {"mass": Estimate(0.068, 0.025, 0.098, 0.070),
                "length:left.proximal": Estimate(0.04, 0.031, 0.05, 0.041),
                "tendon": Estimate(18000.0, 15000.0, 21600.0, 18100.0),
                "curvature": Estimate(22.0, 12.0, 31.0, 21.5)}
    result = type("R", (), {"grasp_lost_at": None, "theta": {}, "unknowns": unknowns})()
    summary = {"converged": False, "iterations": 0, "converged_at": None,
               "timing": {"filter_s_per_iteration_median": 0.1}}
    lines = format_table(result, summary, None).splitlines()
    assert any(line.startswith("mass") and line.endswith("[25 .. 98] g") for line in lines)
    assert any(line.startswith("length:left.proximal") and "(median 41)" in line
               and line.endswith(" mm") for line in lines)
    assert any(line.startswith("tendon") and "(median 18.1)" in line
               and line.endswith("[15 .. 21.6] N/mm") for line in lines)
    assert any(line.startswith("curvature") and line.endswith("[12 .. 31] 1/m")
               for line in lines)


def test_identify_says_the_likelihood_and_the_contact_prior_in_effect():
    from vlr.commands.identify import format_table
    from vlr.settings import load_settings

    result = type("R", (), {"grasp_lost_at": None, "theta": {}, "unknowns": {}})()

    def table(backend: str, **dotted) -> list[str]:
        settings = load_settings({"world.backend": backend},
                                 {k.replace("__", "."): v for k, v in dotted.items()})
        summary = {"converged": False, "iterations": 0, "converged_at": None,
                   "timing": {"filter_s_per_iteration_median": 0.1},
                   "settings": settings.flat()}
        return format_table(result, summary, None).splitlines()

    sim = table("sim")
    assert "likelihood: 0.2 mm / 0.4 deg + a 1 deg turn in the grip" in sim
    assert ("contacts: rolling; joint stops 17 N m/rad; contact prior surface, 8.6 deg spread"
            in sim)
    assert not any(line.startswith("tensions") for line in sim)
    synthetic = table("synthetic")
    assert "likelihood: 0.1 mm / 0.4 deg" in synthetic
    assert ("contacts: pinned; joint stops 100 N m/rad; contact prior pad, 8.6 deg spread"
            in synthetic)
    tensions = table("sim", filter__observation__sigma_tension_n=0.5,
                     world__options__tension_noise_n=0.25)
    assert "tensions weighed at 0.5 N (the sim's readings 0.25 N noisy)" in tensions
    assert "tensions weighed at 0.5 N" in table("sim", filter__observation__sigma_tension_n=0.5)


def test_every_identify_option_is_documented():
    """docs/IDENTIFY.md is the README's reference for `vlr identify`: an option added to the
    parser and left out of it fails here."""
    import argparse
    import pathlib
    import re

    from vlr.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = {s for a in sub.choices["identify"]._actions for s in a.option_strings
               if s.startswith("--") and s != "--help"}
    doc = (pathlib.Path(__file__).parents[1] / "docs" / "IDENTIFY.md").read_text()
    missing = sorted(o for o in options if not re.search(re.escape(o) + r"(?![\w-])", doc))
    assert not missing, f"docs/IDENTIFY.md does not mention {missing}"


def test_identify_says_when_the_grasp_prior_missed_the_truth(tmp_path, capsys):
    # The synthetic toy block grasps with its thumb's distal joint near 64 degrees; the sim's
    # guess (-10, 15) with the synthetic world's 3-degree spread starts 50 degrees off it.
    # Scored against the truth, the run says so.
    common = ["identify", "--backend", "synthetic", "--object", "toy_block", "--hand",
              "modelo_thumb45", "--particles", "1000", "--max-iterations", "1", "--seed", "0"]
    assert main(common + ["--out", str(tmp_path / "own")]) == 0
    own = json.loads((tmp_path / "own" / "result.json").read_text())
    assert own["prior_coverage"] == 1.0
    assert "missed the grasp" not in capsys.readouterr().out
    assert main(common + ["--out", str(tmp_path / "off"),
                          "--set", "filter.guess_theta_deg=[-10, 15]"]) == 0
    off = json.loads((tmp_path / "off" / "result.json").read_text())
    assert off["prior_coverage"] <= 0.5
    assert "missed the grasp" in capsys.readouterr().out


@pytest.mark.parametrize("where", ["a file", "under a file"])
def test_a_bad_out_is_one_line_before_the_run(tmp_path, capsys, monkeypatch, where):
    import vlr.run

    def never(*a, **k):
        raise AssertionError("the identification ran")

    monkeypatch.setattr(vlr.run, "run_identification", never)
    blocker = tmp_path / "taken"
    blocker.write_text("")
    out = blocker if where == "a file" else blocker / "sub"
    rc = main(["identify", "--backend", "synthetic", "--out", str(out), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and "is a file" in err[0], err


@pytest.mark.parametrize("content", [None, b"\xff\xfe seeds", b"seed: 1\nseed: 2\n"],
                         ids=["a folder", "not UTF-8", "a key twice"])
def test_a_bad_settings_file_is_one_line(tmp_path, capsys, content):
    path = tmp_path / "settings.yaml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    rc = main(["identify", "--backend", "synthetic", "--settings", str(path), "--out",
               str(tmp_path / "o"), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0], err
    assert not (tmp_path / "o" / "result.json").exists()


def test_a_run_killed_while_writing_leaves_no_finished_folder(tmp_path, monkeypatch):
    """result.json marks a finished run: a rerun into the folder removes the old one first
    and writes its own last, so a kill between the files leaves no result.json."""
    import vlr.results

    args = ["identify", "--backend", "synthetic", "--particles", "200", "--max-iterations",
            "1", "--quiet", "--out", str(tmp_path)]
    assert main(args) == 0
    assert (tmp_path / "result.json").exists()

    def killed(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(vlr.results, "_plot", killed)   # after history.npz, before the rest
    assert main(args) == 130
    assert (tmp_path / "history.npz").exists() and not (tmp_path / "result.json").exists()


def test_help_piped_into_a_reader_that_stops_early_is_quiet():
    # `vlr identify --help | head`: the reader has closed the pipe; no traceback on stderr.
    # The read end is closed before the child starts, so every write meets a broken pipe.
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([sys.executable, "-c", "from vlr.cli import main; "
                               "import sys; sys.exit(main(['identify', '--help']))"],
                              stdout=write_end, stderr=subprocess.PIPE, timeout=120)
    finally:
        os.close(write_end)
    err = proc.stderr.decode()
    assert proc.returncode == 1, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err

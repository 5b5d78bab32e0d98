"""`vlr model-check-calibrate`: the model check's thresholds by the rule, from results on
disk; bad input is one clear line and no file."""

import json

import numpy as np
import pytest

from vlr.cli import main
from vlr.model_check import threshold_by_rule
from vlr.settings import load_settings, read_yaml_mapping

SCALES = {"world.backend": "sim", "filter.observation.sigma_pos_mm": 0.2,
          "filter.observation.sigma_rot_deg": 0.4, "filter.observation.sigma_turn_deg": 1.0}
CAMERA = [-1.60, -1.55, -1.50, -1.62, -1.58, -1.40]
TENSIONS = [-1.70, -1.65, -1.52, -1.61, -1.66, -1.58]


def _result(stat, tension_n=0.0, obj="apple", **scales):
    return {"object": obj, "model_check": {"statistic": stat},
            "settings": {**SCALES, "filter.observation.sigma_tension_n": tension_n, **scales}}


def _identify_runs(root, stats, tension_n=0.0):
    """`vlr identify` output folders, one result.json each."""
    paths = []
    for i, s in enumerate(stats):
        d = root / f"run{tension_n}-{i}"
        d.mkdir()
        obj = ("apple", "mug")[i % 2]
        (d / "result.json").write_text(json.dumps(_result(s, tension_n, obj)))
        paths.append(str(d))
    return paths


def _objects(stats):
    return [("apple", "mug")[i % 2] for i in range(len(stats))]


def test_the_rule_counts_the_objects_spread_and_not_a_lost_track():
    """The median plus three times the spread between the objects' medians and about them."""
    objects = ["apple"] * 5 + ["mug"] * 5
    stats = [-1.6, -1.5, -1.55, -1.52, -1.58, -1.3, -1.2, -1.25, -1.22, -1.28]
    s_b = np.std([-1.55, -1.25], ddof=1)
    s_w = 1.4826 * np.median(np.abs(np.array(stats) - np.repeat([-1.55, -1.25], 5)))
    want = np.median(stats) + 3 * np.hypot(s_b, s_w)
    assert threshold_by_rule(objects, stats) == pytest.approx(want)
    # A trial that lost track (the synthetic world's wine glass reads 37-95) moves it little.
    lost = threshold_by_rule(objects, stats[:-1] + [95.0])
    assert abs(lost - want) < 0.1
    with pytest.raises(ValueError, match="at least 5"):
        threshold_by_rule(objects[:4], stats[:4])
    with pytest.raises(ValueError, match="two objects"):
        threshold_by_rule(["apple"] * 5, stats[:5])


def test_an_object_with_too_few_decided_trials_is_left_out_and_named(tmp_path, capsys):
    """One short trial is no object's median (with the tensions read the wine glass converges
    within a few actions and gets a verdict on one trial in ten): its object is left out."""
    objects = ["apple"] * 5 + ["mug"] * 5 + ["glass"] * 2
    stats = [-1.6, -1.5, -1.55, -1.52, -1.58, -1.3, -1.2, -1.25, -1.22, -1.28, 0.5, -0.7]
    assert threshold_by_rule(objects, stats) == threshold_by_rule(objects[:10], stats[:10])
    with pytest.raises(ValueError, match="two objects"):
        threshold_by_rule(objects[:5] + objects[10:], stats[:5] + stats[10:])
    runs = _identify_runs(tmp_path, CAMERA)
    d = tmp_path / "glass"
    d.mkdir()
    (d / "result.json").write_text(json.dumps(_result(-0.8, obj="glass")))
    assert main(["model-check-calibrate", *runs, str(d)]) == 0
    out = capsys.readouterr().out
    assert "camera: 6 trials on 2 objects" in out
    assert "left out: glass (1 decided trial, fewer than 3)" in out


def test_thresholds_per_kind_are_printed_and_written_as_settings(tmp_path, capsys):
    runs = _identify_runs(tmp_path, CAMERA) + _identify_runs(tmp_path, TENSIONS, 0.56)
    out = tmp_path / "check.yaml"
    assert main(["model-check-calibrate", *runs, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    want = round(threshold_by_rule(_objects(CAMERA), CAMERA), 2)
    want_t = round(threshold_by_rule(_objects(TENSIONS), TENSIONS), 2)
    assert "camera: 6 trials on 2 objects" in printed and f"threshold={want:.2f}" in printed
    assert "camera and tensions (0.56 N): 6 trials" in printed
    assert f"threshold_tensions={want_t:.2f}" in printed
    # The file is a settings file `vlr identify --settings` reads.
    s = load_settings(read_yaml_mapping(str(out), "--settings"))
    assert s.filter.model_check.threshold == pytest.approx(want)
    assert s.filter.model_check.threshold_tensions == pytest.approx(want_t)


def test_a_sweeps_trials_of_one_group_and_only_finished_ones(tmp_path, capsys):
    trials = tmp_path / "sweep" / "trials"
    trials.mkdir(parents=True)
    for i, s in enumerate(CAMERA):
        obj = ("apple", "mug")[i % 2]
        rec = {"status": "ok", "group": "known hand", "case": f"object {i}",
               "settings": _result(s)["settings"],
               "result": {"object": obj, "model_check": {"statistic": s}}}
        (trials / f"k{i}.json").write_text(json.dumps(rec))
    (trials / "wrong.json").write_text(json.dumps(
        {"status": "ok", "group": "wrong model", "case": "undeclared finger",
         "settings": _result(0.0)["settings"], "result": {"model_check": {"statistic": 0.0}}}))
    (trials / "failed.json").write_text(json.dumps(
        {"status": "failed", "group": "known hand", "case": "object 9", "error": "x"}))
    assert main(["model-check-calibrate", str(tmp_path / "sweep"), "--group",
                 "known hand"]) == 0
    want = round(threshold_by_rule(_objects(CAMERA), CAMERA), 2)
    assert f"threshold={want:.2f}" in capsys.readouterr().out


@pytest.mark.parametrize("case, message", [
    ("mixed", "filter.observation.sigma_pos_mm = 0.2"),
    ("mixed tension scales", "filter.observation.sigma_tension_n = 0.3"),
    ("few", "4 decided trials on 2 object(s) for threshold"),
    ("missing", "no such file or folder"),
    ("not a result", "no model_check and settings"),
    ("bad statistic", "model_check.statistic = 'x' is not a number"),
])
def test_bad_input_is_one_line_and_no_file(tmp_path, capsys, case, message):
    runs = _identify_runs(tmp_path, CAMERA[:4] if case == "few" else CAMERA)
    if case == "mixed":
        (tmp_path / "run0.0-0" / "result.json").write_text(
            json.dumps(_result(-1.5, **{"filter.observation.sigma_pos_mm": 0.4})))
    elif case == "mixed tension scales":
        runs += _identify_runs(tmp_path, TENSIONS, 0.56)
        (tmp_path / "run0.56-1" / "result.json").write_text(json.dumps(_result(-1.5, 0.3)))
    elif case == "missing":
        runs.append(str(tmp_path / "nowhere"))
    elif case == "bad statistic":
        (tmp_path / "run0.0-2" / "result.json").write_text(json.dumps(_result("x")))
    elif case == "not a result":
        (tmp_path / "other.json").write_text(json.dumps({"x": 1}))
        runs.append(str(tmp_path / "other.json"))
    out = tmp_path / "check.yaml"
    assert main(["model-check-calibrate", *runs, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err
    assert not out.exists()

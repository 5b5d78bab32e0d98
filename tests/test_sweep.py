"""`vlr sweep`: a sweep file expands to trials, streams one file per trial, resumes without
repeating finished trials, and rebuilds the same tables from those files. The tiny sweep
(`sweep_file`) is tests/conftest.py's."""

import json
from pathlib import Path

import pytest

from vlr.cli import main
from vlr.errors import UserError
from vlr.sweep import Trial, expand, load_sweep, parse_seeds, run_one
from vlr.trial import TrialSettings


def test_sweep_file_expands_to_cases_times_seeds(sweep_file):
    spec = load_sweep(sweep_file)
    trials = expand(spec)
    assert [(t.case, t.settings.seed) for t in trials] == [
        ("known hand", 0), ("known hand", 1), ("stiffness", 0), ("stiffness", 1)]
    assert len({t.id for t in trials}) == 4
    assert parse_seeds("0-2,7") == (0, 1, 2, 7)


def test_sweep_runs_resumes_and_never_repeats_a_finished_trial(sweep_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(sweep_file), "--quiet"]) == 0
    files = sorted((out / "trials").glob("*.json"))
    assert len(files) == 4
    table = (out / "table.csv").read_text().splitlines()
    assert len(table) == 5 and table[0].startswith("case,")
    summary = (out / "summary.md").read_text()
    assert "| known hand |" in summary and "| stiffness |" in summary
    # A rerun without --resume refuses to mix runs; with --resume it runs nothing.
    assert main(["sweep", str(sweep_file), "--quiet"]) == 2
    stamps = {f.name: f.stat().st_mtime_ns for f in files}
    # An interrupted sweep: one trial never finished.
    files[0].unlink()
    capsys.readouterr()
    assert main(["sweep", str(sweep_file), "--quiet", "--resume"]) == 0
    assert "1 to run" in capsys.readouterr().out
    for f in files[1:]:
        assert f.stat().st_mtime_ns == stamps[f.name]
    assert len((out / "table.csv").read_text().splitlines()) == 5
    # The table is rebuilt from the files alone.
    before = (out / "summary.csv").read_text()
    assert main(["sweep", str(sweep_file), "--table-only"]) == 0
    assert (out / "summary.csv").read_text() == before
    # A record broken by hand is one error naming its file, not a traceback.
    files[1].write_text('{"id": "half a rec')
    capsys.readouterr()
    assert main(["sweep", str(sweep_file), "--table-only"]) == 2
    assert f"{files[1]} is not valid JSON" in capsys.readouterr().err
    assert (out / "summary.csv").read_text() == before


def test_same_seed_same_numbers(tmp_path):
    t = Trial("x", TrialSettings(backend="synthetic", particles=200, max_iterations=2, seed=3))
    a = run_one(t, tmp_path / "a")["result"]
    b = run_one(t, tmp_path / "b")["result"]
    assert a["errors"] == b["errors"] and a["estimates"] == b["estimates"]


def test_a_failed_trial_is_recorded_and_the_sweep_goes_on(tmp_path):
    t = Trial("bad", TrialSettings(backend="synthetic", object="no_such_object",
                                   particles=200, max_iterations=1))
    rec = run_one(t, tmp_path)
    assert rec["status"] == "error" and "no_such_object" in rec["error"]
    saved = json.loads((tmp_path / "trials" / f"{t.id}.json").read_text())
    assert saved["status"] == "error"


def test_a_trial_record_names_the_commit_it_ran_at(tmp_path):
    """The record carries the checkout's commit (`vlr.provenance`), so a table's figures
    name their code; outside a git checkout it is None."""
    import subprocess

    t = Trial("bad", TrialSettings(backend="synthetic", object="no_such_object",
                                   particles=200, max_iterations=1))
    code = run_one(t, tmp_path)["code"]
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():
        assert code is None
        return
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert code["commit"] == head and isinstance(code["dirty"], bool)
    from vlr.sweep import _row

    assert _row({"case": "c", "status": "ok", "settings": {}, "result": {},
                 "code": {"commit": "0123456789abcdef", "dirty": True}})["commit"] == \
        "0123456789ab+dirty"


def test_bad_sweep_files_name_the_problem(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("seeds: 0\nout: x\nsettings: {particlez: 10}\n")
    with pytest.raises(UserError, match="particlez"):
        expand(load_sweep(p))
    p.write_text("seeds: 0\nout: x\ngird: {object: [apple]}\n")
    with pytest.raises(UserError, match="gird"):
        load_sweep(p)
    with pytest.raises(UserError, match="not found"):
        load_sweep(tmp_path / "missing.yaml")


@pytest.mark.parametrize("text, match", [
    ("seeds: [a]", "seeds"), ("seeds: [1.5]", "seeds"), ("seeds: true", "seeds"),
    ("cases: 3", "cases must be a list"), ("cases: [3]", "cases must be a list"),
    ("settings: 5", "settings must be a mapping"),
    ("grid: {object: apple}", "grid must map"), ("grid: {object: []}", "grid must map"),
    ("grid: {seed: [1, 2]}", "top-level seeds"),
    ("settings: {particles: many}", "particles 'many' must be an integer"),
    ("settings: {max_iterations: '3'}", "max_iterations"),
    ("settings: {sigma_pos_mm: x}", "sigma_pos_mm"),
    ("settings: {true_stiffness: [1]}", "true_stiffness"),
    ("settings: {nominal_theta_deg: 3}", "nominal_theta_deg"),
    ("grid: {object: [apple, no_such_object]}", "no_such_object"),
    ("settings: {unknowns: [stiffness:thumb.nope]}", "thumb.nope"),
])
def test_bad_types_in_a_sweep_file_are_one_user_error(tmp_path, text, match):
    p = tmp_path / "s.yaml"
    p.write_text(f"out: {tmp_path / 'out'}\n{text}\n")
    with pytest.raises(UserError, match=match):
        expand(load_sweep(p))


def test_a_sweep_that_never_starts_leaves_no_files(sweep_file, tmp_path, monkeypatch):
    import vlr.executors

    def refuse(*a, **k):
        raise UserError("no workers")

    monkeypatch.setattr(vlr.executors, "run_local", refuse)
    assert main(["sweep", str(sweep_file), "--quiet"]) == 2
    assert not (tmp_path / "out").exists()


def test_a_record_that_cannot_be_written_leaves_no_file(tmp_path):
    from vlr.io import write_json_atomic

    with pytest.raises(TypeError):
        write_json_atomic(tmp_path / "r.json", {"x": object()})
    assert list(tmp_path.iterdir()) == []


def test_records_are_strict_json(tmp_path):
    """A NaN (a gap ratio over no motion, an error with no truth) is written as null: strict
    readers (JavaScript, jq) reject Python's default `NaN`."""
    import numpy as np

    from vlr.io import write_json_atomic

    write_json_atomic(tmp_path / "r.json", {"a": float("nan"), "b": [np.float64(np.inf), 1.5],
                                            "c": np.array([np.nan, 2.0])})
    text = (tmp_path / "r.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"a": None, "b": [None, 1.5], "c": [None, 2.0]}


def test_a_trial_with_a_spec_file_path_has_a_flat_file_name():
    from vlr.sweep import Trial, TrialSettings

    named = Trial("c", TrialSettings(hand="modelo", object="apple", seed=3))
    assert named.id.startswith("c_apple_modelo_s3_")  # names keep the ids of old sweeps
    path = Trial("c", TrialSettings(hand="/tmp/hands/my hand.yaml", object="apple"))
    assert "/" not in path.id and " " not in path.id
    assert "-tmp-hands-my-hand.yaml" in path.id


def test_the_row_reads_the_error_after_the_papers_15_actions():
    from vlr.sweep import PAPER_ITERATIONS, _row

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"proximal_deg_by_iteration": [float(i) for i in range(21)]}}
    assert _row(rec)["proximal_deg_at_15"] == float(PAPER_ITERATIONS) == 15.0
    rec["result"]["proximal_deg_by_iteration"] = [2.0] * 10 + [1.0]  # 10 actions, no more
    assert _row(rec)["proximal_deg_at_15"] is None
    rec["result"]["converged"] = True     # it stopped there on convergence: its final error
    assert _row(rec)["proximal_deg_at_15"] == 1.0


def test_the_row_reads_the_interval_at_15_actions_and_at_the_end():
    from vlr.sweep import _row

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"ci_deg_by_iteration": [30.0 - i for i in range(21)]}}
    assert (_row(rec)["ci_deg_at_15"], _row(rec)["ci_deg"]) == (15.0, 10.0)
    rec["result"]["ci_deg_by_iteration"] = [30.0, 1.5]  # converged after one action
    assert (_row(rec)["ci_deg_at_15"], _row(rec)["ci_deg"]) == (None, 1.5)


def test_the_row_gives_the_papers_joints_figure():
    from vlr.sweep import _row, summarize_rows

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"errors": {"proximal_deg_mean": 1.0, "distal_deg_mean": 3.0}}}
    assert _row(rec)["joints_deg"] == 2.0       # an older record: two-joint fingers
    rec["result"]["errors"]["joint_deg_mean"] = 2.5
    row = _row(rec)
    assert row["joints_deg"] == 2.5             # the trial's own mean over every joint
    assert summarize_rows([row])[0]["joints [deg]"] == "2.50"


def test_the_row_compares_the_proximal_links_alone_with_the_paper():
    from vlr.sweep import _row, summarize_rows

    errors = {"link_length_mm": {"left": 4.0, "right": 3.0},
              "link_length_mm_by_joint": {"left.proximal": 1.0, "left.distal": 7.0,
                                          "right.proximal": 5.0, "right.distal": 1.0}}
    rec = {"case": "c", "status": "ok", "settings": {}, "result": {"errors": errors}}
    row = _row(rec)
    assert row["proximal_link_mm"] == 3.0       # (1 + 5) / 2, the distal offsets left out
    assert row["length_mm.left"] == 4.0         # the mean over both is still there
    assert summarize_rows([row])[0]["proximal link error [mm]"] == "3.00"
    rec["result"]["errors"] = {"link_length_mm_by_joint": {"left.distal": 2.0}}
    assert "proximal_link_mm" not in _row(rec)


def test_the_row_gives_the_posterior_medians_figures_beside_the_means():
    from vlr.sweep import PAPER_ITERATIONS, _row, summarize_rows

    median = {"proximal_deg_mean": 0.5, "joint_deg_mean": 1.5,
              "link_length_mm_by_joint": {"left.proximal": 2.0, "left.distal": 9.0},
              "stiffness": {"thumb.distal": 0.002}}
    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"errors": {"joint_deg_mean": 2.5}, "errors_median": median,
                      "proximal_median_deg_by_iteration": list(range(20))}}
    row = _row(rec)
    assert (row["joints_deg"], row["joints_deg_median"]) == (2.5, 1.5)
    assert row["proximal_link_mm_median"] == 2.0
    assert row["proximal_deg_median_at_15"] == PAPER_ITERATIONS
    s = summarize_rows([row])[0]
    assert s["joints, median [deg]"] == "1.50"
    assert s["stiffness_median.thumb.distal error [N m/rad]"] == "0.0020"
    # A record from before the median was scored has no median columns.
    del rec["result"]["errors_median"]
    assert "joints_deg_median" not in _row(rec)


def test_the_row_gives_the_objects_unknowns_in_grams_and_millimetres():
    from vlr.sweep import _row, summarize_rows

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"errors": {"object_mass_g": 12.5, "object_com_mm": {"z": 3.0}},
                      "errors_median": {"object_mass_g": 10.0},
                      "unknown_estimates": {
                          "mass": {"mean": 0.06, "median": 0.058, "low": 0.023, "high": 0.096},
                          "com:z": {"mean": 0.04, "median": 0.041, "low": 0.03, "high": 0.05},
                          "stiffness:thumb.distal": {"median": 0.04},
                          "tendon": {"median": 18000.0, "low": 15000.0, "high": 21600.0}}}}
    row = _row(rec)
    assert (row["object_mass_g"], row["object_com_mm.z"]) == (12.5, 3.0)
    assert row["object_mass_g_median"] == 10.0
    # the estimates themselves, whose sign and interval the errors lose
    assert (row["mass_g.median"], row["mass_g.low"], row["mass_g.high"]) == pytest.approx(
        (58.0, 23.0, 96.0))
    assert row["com_z_mm.median"] == pytest.approx(41.0)
    assert row["spring_thumb.distal.median"] == pytest.approx(0.04)
    assert (row["tendon_all_n_per_m.low"], row["tendon_all_n_per_m.high"]) == (15000.0, 21600.0)
    assert not any(k.startswith("stiffness:") for k in row)
    s = summarize_rows([row])[0]
    assert s["object_mass_g error [g]"] == "12.50"
    assert s["object_mass_g_median error [g]"] == "10.00"
    assert s["object_com_mm.z error [mm]"] == "3.00"


def test_the_row_gives_the_curvature_in_per_metre():
    from vlr.sweep import _row, summarize_rows

    rec = {"case": "c", "status": "ok", "settings": {},
           "result": {"errors": {"curvature_per_m": {"all": 4.5}},
                      "unknown_estimates": {
                          "curvature": {"median": 22.0, "low": 12.0, "high": 31.0}}}}
    row = _row(rec)
    assert row["curvature_per_m.all"] == 4.5
    assert (row["curvature_all.median"], row["curvature_all.low"]) == (22.0, 12.0)
    assert summarize_rows([row])[0]["curvature_per_m.all error [1/m]"] == "4.50"


def test_a_grid_setting_splits_the_summary_instead_of_being_averaged(tmp_path):
    from vlr.sweep import varying_settings, write_tables

    def rec(seed, h, err):
        return {"case": "apple", "status": "ok",
                "settings": {"object": "apple", "seed": seed, "jitter_h": h,
                             "nominal_theta_deg": [-10, 15]},
                "result": {"errors": {"proximal_deg_mean": err}}}

    records = [rec(0, 0.4, 1.0), rec(1, 0.4, 3.0), rec(0, 0.1, 10.0), rec(1, 0.1, 20.0)]
    assert varying_settings(records) == ["jitter_h"]   # the seed is not a grid key
    other = {**records[1], "settings": {**records[1]["settings"], "object": "wine_glass"}}
    assert varying_settings(records + [other]) == ["jitter_h"]  # object has its column
    write_tables(tmp_path, records)
    summary = (tmp_path / "summary.csv").read_text().splitlines()
    assert len(summary) == 3 and "jitter_h" in summary[0]
    assert any(",0.4," in line and "2.00 ± 1.41" in line for line in summary)
    assert any(",0.1," in line and "15.00 ± 7.07" in line for line in summary)
    assert "jitter_h" in (tmp_path / "table.csv").read_text().splitlines()[0]


def test_the_summary_counts_lost_grasps():
    from vlr.sweep import _row, summarize_rows

    recs = [{"case": "c", "status": "ok", "settings": {"seed": s},
             "result": {"grasp_lost_at": lost}} for s, lost in ((0, None), (1, 3), (2, None))]
    rows = [_row(r) for r in recs]
    assert [r["grasp_lost_at"] for r in rows] == [None, 3, None]
    assert summarize_rows(rows)[0]["grasps lost"] == "1/3"


def test_every_documented_sweep_file_still_expands(monkeypatch):
    """docs/RESULTS.md quotes `vlr sweep docs/sweeps/X.yaml` for its tables: each file must
    still name valid settings, objects, hands and unknowns, and its Run: line itself."""
    import models

    monkeypatch.chdir(models.ROOT.parent)  # the files' paths are the repository root's
    sweeps = sorted(Path("docs", "sweeps").glob("*.yaml"))
    assert len(sweeps) > 30
    for path in sweeps:
        trials = expand(load_sweep(path))
        assert trials, path.name
        runs = [line for line in path.read_text().splitlines() if line.startswith("# Run: vlr ")]
        assert runs and all(f" docs/sweeps/{path.name} " in f"{line} " for line in runs), (
            f"{path.name}: its '# Run: vlr ...' line is missing or names another file")


def test_a_changed_default_keeps_the_ids_of_the_files_that_pin_it():
    """The Liu-West draw's default became "log-springs" in session 41; the files measured
    before pin "gaussian", and their trials keep the ids they were run under (computed at
    ef18412), so `--resume` and `--table-only` still find them. A setting other than the
    former default is hashed as before."""
    from vlr.sweep import Trial

    def trial(**kw):
        return Trial("spring", TrialSettings(backend="sim", object="toy_block", seed=2,
                                             unknowns=("stiffness:thumb.distal",), **kw))

    assert trial(jitter_kernel="gaussian").id == "spring_toy_block_modelo_s2_a7901dbd"
    assert trial(jitter_kernel="copula").id == "spring_toy_block_modelo_s2_df085b96"
    assert trial().id != trial(jitter_kernel="gaussian").id


def test_a_backends_changed_default_keeps_every_backends_ids():
    """The synthetic world's action solve became "model" in session 42: a synthetic trial
    that pins the former "loose" keeps the id it had at 8f0f879, one at the new default
    gets a new id, and a sim trial, which has no such solve, keeps its id."""
    from vlr.sweep import Trial

    def synthetic(**kw):
        return Trial("spring", TrialSettings(backend="synthetic", object="toy_block", seed=2,
                                             rolling=True, jitter_kernel="gaussian",
                                             unknowns=("stiffness:thumb.distal",), **kw))

    assert synthetic(synthetic_solve="loose").id == "spring_toy_block_modelo_s2_b69bed29"
    assert synthetic().id != synthetic(synthetic_solve="loose").id
    sim = Trial("spring", TrialSettings(backend="sim", object="toy_block", seed=2,
                                        unknowns=("stiffness:thumb.distal",),
                                        jitter_kernel="gaussian"))
    assert sim.id == "spring_toy_block_modelo_s2_a7901dbd"
    with pytest.raises(UserError, match="synthetic_solve 'loose' is the synthetic world's"):
        TrialSettings(backend="sim", synthetic_solve="loose")
    with pytest.raises(UserError, match="synthetic_solve 'exact'"):
        TrialSettings(backend="synthetic", synthetic_solve="exact")

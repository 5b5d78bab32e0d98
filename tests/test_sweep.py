"""`vlr sweep`: a sweep file expands to trials, streams one file per trial, resumes without
repeating finished trials, and rebuilds the same tables from those files. The tiny sweep
(`sweep_file`) is tests/conftest.py's."""

import csv
import json
from pathlib import Path

import pytest

from vlr.cli import main
from vlr.errors import UserError
from vlr.settings import load_settings
from vlr.sweep import Trial, expand, load_sweep, parse_seeds, run_one


def _settings(**dotted):
    """A settings tree from dotted keys given as keywords with '__' for '.'."""
    return load_settings({k.replace("__", "."): v for k, v in dotted.items()})


def test_sweep_file_expands_to_cases_times_seeds(sweep_file):
    spec = load_sweep(sweep_file)
    trials = expand(spec)
    assert [(t.case, t.settings.seed) for t in trials] == [
        ("known hand", 0), ("known hand", 1), ("stiffness", 0), ("stiffness", 1)]
    assert len({t.id for t in trials}) == 4
    assert parse_seeds("0-2,7") == (0, 1, 2, 7)
    # the file's dotted keys, the case's on top of the common settings
    known, stiff = trials[0].settings, trials[2].settings
    assert (known.world.backend, known.filter.particles, known.loop.max_iterations) == (
        "synthetic", 200, 2)
    assert known.filter.unknowns == () and known.world.options == {"true_stiffness": {}}
    assert stiff.filter.unknowns == ("stiffness:thumb.distal",)
    assert stiff.world.options == {"true_stiffness": {"thumb.distal": 0.045}}
    assert stiff.filter.particles == 200


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
    t = Trial("x", _settings(world__backend="synthetic", filter__particles=200,
                             loop__max_iterations=2, seed=3))
    a = run_one(t, tmp_path / "a")["result"]
    b = run_one(t, tmp_path / "b")["result"]
    assert a["errors"] == b["errors"] and a["estimates"] == b["estimates"]


def test_a_failed_trial_is_recorded_and_the_sweep_goes_on(tmp_path):
    t = Trial("bad", _settings(world__backend="synthetic", world__object="no_such_object",
                               filter__particles=200, loop__max_iterations=1))
    rec = run_one(t, tmp_path)
    assert rec["status"] == "error" and "no_such_object" in rec["error"]
    saved = json.loads((tmp_path / "trials" / f"{t.id}.json").read_text())
    assert saved["status"] == "error"
    # the record keeps every setting in effect, flat and dotted
    assert saved["settings"] == t.settings.flat()
    assert saved["settings"]["world.object"] == "no_such_object"


def test_a_trial_record_names_the_commit_it_ran_at(tmp_path):
    """The record carries the checkout's commit (`vlr.provenance`), so a table's figures
    name their code; outside a git checkout it is None."""
    import subprocess

    t = Trial("bad", _settings(world__backend="synthetic", world__object="no_such_object",
                               filter__particles=200, loop__max_iterations=1))
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
    p.write_text("seeds: 0\nout: x\nsettings: {filter.particlez: 10}\n")
    with pytest.raises(UserError, match="filter.particlez"):
        expand(load_sweep(p))
    p.write_text("seeds: 0\nout: x\ngird: {world.object: [apple]}\n")
    with pytest.raises(UserError, match="gird"):
        load_sweep(p)
    with pytest.raises(UserError, match="no such file"):
        load_sweep(tmp_path / "missing.yaml")


@pytest.mark.parametrize("text, match", [
    ("seeds: [a]", "seeds"), ("seeds: [1.5]", "seeds"), ("seeds: true", "seeds"),
    ("cases: 3", "cases must be a list"), ("cases: [3]", "cases must be a list"),
    ("settings: 5", "settings must be a mapping"),
    ("grid: {world.object: apple}", "grid must map"),
    ("grid: {world.object: []}", "grid must map"),
    ("grid: {seed: [1, 2]}", "top-level seeds"),
    ("settings: {filter.particles: many}", "filter.particles: 'many' is not an integer"),
    ("settings: {filter: {particles: many}}", "filter.particles: 'many' is not an integer"),
    ("settings: {loop.max_iterations: '3'}", "loop.max_iterations"),
    ("settings: {filter.observation.sigma_pos_mm: x}", "filter.observation.sigma_pos_mm"),
    ("settings: {world.backend: synthetic, world.options.true_stiffness: [1]}",
     "world.options.true_stiffness"),
    ("settings: {filter.guess_theta_deg: 3}", "filter.guess_theta_deg"),
    ("settings: {particles: 200}", "unknown setting 'particles'"),
    ("cases: [{name: a, filter.jitter_h: 1.5}]", "case 'a': filter.jitter_h"),
    ("grid: {filter.jitter_h: [0.2, wide]}", "filter.jitter_h: 'wide'"),
    ("grid: {world.object: [apple, no_such_object]}", "no_such_object"),
    ("settings: {filter.unknowns: [stiffness:thumb.nope]}", "thumb.nope"),
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
    # The output folder is made (and checked writable) before the first trial; no tables.
    assert [p for p in (tmp_path / "out").rglob("*")] == []


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
    named = Trial("c", _settings(world__hand="modelo", world__object="apple", seed=3))
    assert named.id.startswith("c_apple_modelo_s3_")
    path = Trial("c", _settings(world__hand="/tmp/hands/my hand.yaml", world__object="apple"))
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
                "settings": {"world.object": "apple", "seed": seed, "filter.jitter_h": h,
                             "filter.guess_theta_deg": [-10, 15]},
                "result": {"object": "apple", "errors": {"proximal_deg_mean": err}}}

    records = [rec(0, 0.4, 1.0), rec(1, 0.4, 3.0), rec(0, 0.1, 10.0), rec(1, 0.1, 20.0)]
    assert varying_settings(records) == ["filter.jitter_h"]   # the seed is not a grid key
    other = {**records[1],
             "settings": {**records[1]["settings"], "world.object": "wine_glass"}}
    assert varying_settings(records + [other]) == ["filter.jitter_h"]  # object has its column
    write_tables(tmp_path, records)
    summary = (tmp_path / "summary.csv").read_text().splitlines()
    assert len(summary) == 3 and "filter.jitter_h" in summary[0]
    assert any(",0.4," in line and "2.00 ± 1.41" in line for line in summary)
    assert any(",0.1," in line and "15.00 ± 7.07" in line for line in summary)
    assert "filter.jitter_h" in (tmp_path / "table.csv").read_text().splitlines()[0]


def test_the_summary_counts_lost_grasps():
    from vlr.sweep import _row, summarize_rows

    recs = [{"case": "c", "status": "ok", "settings": {"seed": s},
             "result": {"grasp_lost_at": lost}} for s, lost in ((0, None), (1, 3), (2, None))]
    rows = [_row(r) for r in recs]
    assert [r["grasp_lost_at"] for r in rows] == [None, 3, None]
    assert summarize_rows(rows)[0]["grasps lost"] == "1/3"


def test_the_tables_carry_the_model_check():
    """Each trial's verdict, statistic and first action flagged; the summary the share
    flagged of the trials given a verdict, and the statistic's mean."""
    from vlr.sweep import _row, summarize_rows

    checks = [("consistent", -1.5, None), ("inconsistent", -0.5, 8), ("undecided", None, None)]
    recs = [{"case": "c", "status": "ok", "settings": {"seed": s},
             "result": {"model_check": {"verdict": v, "statistic": st,
                                        "first_action_flagged": first}}}
            for s, (v, st, first) in enumerate(checks)]
    rows = [_row(r) for r in recs]
    assert [r["model_check"] for r in rows] == ["consistent", "inconsistent", "undecided"]
    assert rows[1]["model_check_from"] == 8
    summary = summarize_rows(rows)[0]
    assert summary["model check flagged"] == "1/2"
    assert summary["model check statistic"] == "-1.00 ± 0.71"


def test_every_documented_sweep_file_still_expands(monkeypatch):
    """docs/RESULTS.md quotes `vlr sweep docs/sweeps/X.yaml` for its tables: each file must
    still name valid settings, objects, hands and unknowns; a '# Run: vlr ...' line, where a
    file has one, names the file itself."""
    root = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(root)  # the files' paths are the repository root's
    sweeps = sorted((root / "docs" / "sweeps").rglob("*.yaml"))
    assert sweeps
    for path in sweeps:
        trials = expand(load_sweep(path))
        assert trials, path.name
        name = path.relative_to(root).as_posix()
        runs = [line for line in path.read_text().splitlines() if line.startswith("# Run: vlr ")]
        assert all(f" {name} " in f"{line} " for line in runs), (
            f"{name}: its '# Run: vlr ...' line names another file")


def test_a_trials_id_hashes_every_setting_in_effect():
    """A trial run under other settings is a new trial, never a finished one to skip: any
    setting changes the id, down to a backend's world option. A setting given at its
    backend's default is the same trial as one left to the default, however it is written."""
    base = {"world.backend": "sim", "world.object": "toy_block", "seed": 2,
            "filter.unknowns": ["stiffness:thumb.distal"]}

    def trial(case="spring", **dotted):
        return Trial(case, load_settings(base, {k.replace("__", "."): v
                                                for k, v in dotted.items()}))

    ref = trial().id
    assert ref.startswith("spring_toy_block_modelo_s2_")
    assert trial(filter__motion__limit_stiffness=17.0).id == ref     # the sim's default
    nested = Trial("spring", load_settings(base, {"filter": {"motion": {"limit_stiffness":
                                                                           17.0}}}))
    assert nested.id == ref
    changed = {trial(filter__motion__limit_stiffness=100.0).id,
               trial(filter__motion__contact_stiffness=2e4).id,
               trial(filter__observation__sigma_turn_deg=0.5).id,
               trial(filter__jitter_h=0.2).id,
               trial(loop__action_band_mm=0.8).id,
               trial(world__options__ramp_time=0.05).id,
               trial(filter__motion__rolling=False).id,
               trial(case="other").id.replace("other_", "spring_")}
    assert len(changed) == 8 and ref not in changed
    # the seed is in the name, not the hash
    assert trial(seed=3).id == ref.replace("_s2_", "_s3_")
    # the synthetic world's own option is hashed as every other setting
    synthetic = {"world.backend": "synthetic", "filter.unknowns": ["stiffness:thumb.distal"]}
    a = Trial("s", load_settings(synthetic, {"world.options.true_stiffness":
                                             {"thumb.distal": 0.045}}))
    b = Trial("s", load_settings(synthetic, {"world.options.true_stiffness":
                                             {"thumb.distal": 0.05}}))
    assert a.id != b.id


def test_the_estimator_is_a_sweep_key_and_a_column(tmp_path):
    """`filter.estimator` sweeps like any setting; the table and the summary split by it, the
    UKF's rows without particles, every row with the filter's seconds per trial."""
    path = tmp_path / "est.yaml"
    path.write_text(f"""\
name: estimators
out: {tmp_path / 'out'}
seeds: 0
settings: {{world.backend: synthetic, filter.particles: 200, loop.max_iterations: 2}}
grid: {{filter.estimator: [pf, ukf]}}
""")
    assert main(["sweep", str(path), "--quiet"]) == 0
    with open(tmp_path / "out" / "table.csv") as fh:
        rows = list(csv.DictReader(fh))
    by = {r["estimator"]: r for r in rows}
    assert set(by) == {"pf", "ukf"} and all(r["status"] == "ok" for r in rows)
    assert (by["pf"]["particles"], by["ukf"]["particles"]) == ("200", "")
    assert all(float(r["s_per_trial"]) > 0 for r in rows)
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "| estimator |" in summary and "filter s/trial" in summary
    assert "| ukf |" in summary and "| pf |" in summary
    # Bad combinations are refused before any trial runs.
    path.write_text(path.read_text().replace("grid:", "settings2:").replace(
        "settings2: {filter.estimator: [pf, ukf]}",
        "cases: [{name: c, filter.estimator: ukf, filter.unknowns: [curvature]}]"))
    with pytest.raises(UserError, match="case 'c': filter.unknowns 'curvature'"):
        expand(load_sweep(path))


def test_a_reversed_seed_range_says_it_is_reversed():
    with pytest.raises(UserError, match=r"range '4-0' is reversed; write 0-4"):
        parse_seeds("4-0")
    with pytest.raises(UserError, match=r"range '9-7' is reversed"):
        parse_seeds("0,9-7")


def test_a_huge_seed_range_fails_at_once_naming_the_limit(tmp_path, capsys):
    import time

    from vlr.sweep import MAX_SEEDS

    t0 = time.perf_counter()
    with pytest.raises(UserError, match=f"more than the limit of {MAX_SEEDS:,}"):
        parse_seeds("0-100000000")
    with pytest.raises(UserError, match="limit"):
        parse_seeds(list(range(MAX_SEEDS + 1)))
    assert len(parse_seeds(f"0-{MAX_SEEDS - 1}")) == MAX_SEEDS
    assert main(["sweep", "--backend", "synthetic", "--seeds", "0-100000000",
                 "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert time.perf_counter() - t0 < 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'0-100000000'" in err[0] and "10,000" in err[0]
    assert not (tmp_path / "o").exists()

"""`vlr bench`: medians per particle count into a JSON file; bad counts are one clear line."""

import json

from vlr.cli import main


def test_bench_writes_median_seconds_per_particle_count(tmp_path):
    out = tmp_path / "bench.json"
    assert main(["bench", "--particles", "200", "400", "--repeats", "1", "--json",
                 str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["contacts"] == "rolling"  # what `vlr identify` runs on the sim and hardware
    seconds = data["seconds_per_iteration"]
    assert set(seconds) == {"200", "400"}
    assert all(0 < v < 60 for v in seconds.values())
    assert data["medians"]["200"]["total"] == seconds["200"]
    assert data["threads"] >= 1


def test_bench_times_the_pinned_model_on_request(tmp_path):
    runs = {}
    for contacts in ("pinned", "rolling"):
        out = tmp_path / f"{contacts}.json"
        assert main(["bench", "--particles", "2000", "--repeats", "1", "--contacts", contacts,
                     "--json", str(out)]) == 0
        runs[contacts] = json.loads(out.read_text())
    assert runs["pinned"]["contacts"] == "pinned"
    # One solve per action for either contact model (vlr/kernels/), from the stored tangent:
    # at most 3 Newton steps rolling (3 measured), the pinned model no more (1 measured). The
    # median of 2,000 particles' first action: 200 read 3 or 4 from one setting to the next.
    rolling, pinned = (runs[c]["medians"]["2000"]["newton_action"] for c in ("rolling", "pinned"))
    assert runs["rolling"]["contacts"] == "rolling"
    assert 0 < pinned <= rolling <= 3


def test_bench_rejects_bad_counts(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "--particles", "0", "--json", str(out)]) == 2
    assert main(["bench", "--repeats", "0", "--json", str(out)]) == 2
    assert main(["bench", "--threads", "0", "--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--particles 0" in err and "--repeats 0" in err and "Traceback" not in err
    assert not out.exists()


def test_bench_times_the_settings_it_is_given(tmp_path, capsys):
    """`--set` reaches the filter the bench times: one evaluation a solve and no follow-up
    leave an action at most its friction rounds' four evaluations (`vlr.kernels.solve`),
    where the defaults' 99th percentile takes more (14 measured)."""
    runs = {}
    for name, sets in (("default", []), ("capped", ["--set", "filter.motion.max_iter=1",
                                                     "--set", "filter.motion.follow_substeps=0",
                                                     "--set", "world.object=wine_glass"])):
        out = tmp_path / f"{name}.json"
        assert main(["bench", "--particles", "200", "--repeats", "1", "--profile", *sets,
                     "--json", str(out)]) == 0
        runs[name] = json.loads(out.read_text())
        holding = capsys.readouterr().out.splitlines()[0]
        assert ("wine_glass" in holding) == (name == "capped"), holding
    assert runs["capped"]["settings"] == {"filter.motion.max_iter": 1,
                                          "filter.motion.follow_substeps": 0,
                                          "world.object": "wine_glass"}
    assert runs["capped"]["medians"]["200"]["action_p99"] <= 4
    assert runs["default"]["medians"]["200"]["action_p99"] > 4
    # A key the bench sets itself, or one that does not exist, is one line and no file.
    out = tmp_path / "bad.json"
    assert main(["bench", "--set", "filter.particles=5", "--json", str(out)]) == 2
    assert main(["bench", "--set", "filter.motion.nope=1", "--json", str(out)]) == 2
    # ... and a real setting the bench would silently ignore (the sim's options, the loop's
    # length) is refused too, not timed as if it had acted.
    assert main(["bench", "--set", "world.options.ramp_time=0.2", "--json", str(out)]) == 2
    assert main(["bench", "--set", "loop.max_iterations=5", "--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--set filter.particles" in err and "filter.motion.nope" in err
    assert "--set world.options.ramp_time: vlr bench does not use it" in err
    assert "--set loop.max_iterations: vlr bench does not use it" in err
    assert "Traceback" not in err and not out.exists()

"""`vlr bench`: medians per particle count into a JSON file; bad counts are one clear line."""

import json

from vlr.cli import main


def test_bench_writes_median_seconds_per_particle_count(tmp_path):
    out = tmp_path / "bench.json"
    assert main(["bench", "--particles", "200", "400", "--repeats", "1", "--json",
                 str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data) == {"200", "400"}
    assert all(0 < v < 60 for v in data.values())


def test_bench_rejects_bad_counts(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "--particles", "0", "--json", str(out)]) == 2
    assert main(["bench", "--repeats", "0", "--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--particles 0" in err and "--repeats 0" in err and "Traceback" not in err
    assert not out.exists()

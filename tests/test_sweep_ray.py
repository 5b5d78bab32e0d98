"""`vlr sweep --executor ray`: the same sweep on a local Ray instance and on the local pool
gives the same table; an interrupted Ray sweep resumes without recomputing finished trials;
without Ray the executor says how to install it.

Starting Ray costs seconds and most of a GB here, so the tests share ONE local instance
(module fixture); the CLI reuses an instance that is already up and leaves it running."""

import csv
import sys

import pytest

from tests.extras import needs_cluster
from vlr.cli import main

# Columns that measure time, not results: they differ from run to run.
TIMING = {"s_per_iteration", "s/iteration", "s_per_trial", "filter s/trial", "wall_s",
          "elapsed_s"}


@pytest.fixture(scope="module")
def ray_instance():
    ray = pytest.importorskip("ray")
    # address="local": our own instance, whatever `ray start` cluster this machine has.
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    yield ray
    ray.shutdown()


def _table(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def test_ray_and_local_pool_give_the_same_table(ray_instance, sweep_file, tmp_path):
    a, b = tmp_path / "ray", tmp_path / "local"
    assert main(["sweep", str(sweep_file), "--out", str(a), "--executor", "ray",
                 "--quiet"]) == 0
    assert ray_instance.is_initialized()  # the CLI leaves an instance it did not start
    assert main(["sweep", str(sweep_file), "--out", str(b), "--quiet"]) == 0
    ray_rows, local_rows = _table(a / "table.csv"), _table(b / "table.csv")
    assert len(ray_rows) == 4 and all(r["status"] == "ok" for r in ray_rows)
    assert ray_rows == local_rows
    assert _table(a / "summary.csv") == _table(b / "summary.csv")


def test_interrupted_ray_sweep_resumes_without_recomputing(ray_instance, sweep_file,
                                                           tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(sweep_file), "--out", str(out), "--executor", "ray",
                 "--quiet"]) == 0
    files = sorted((out / "trials").glob("*.json"))
    assert len(files) == 4
    # Killed midway: two trials never finished.
    for f in files[:2]:
        f.unlink()
    stamps = {f.name: f.stat().st_mtime_ns for f in files[2:]}
    capsys.readouterr()
    assert main(["sweep", str(sweep_file), "--out", str(out), "--executor", "ray",
                 "--quiet", "--resume"]) == 0
    assert "2 to run" in capsys.readouterr().out
    assert all(f.exists() for f in files)
    for f in files[2:]:
        assert f.stat().st_mtime_ns == stamps[f.name]
    assert len(_table(out / "table.csv")) == 4


def test_without_ray_the_executor_says_how_to_install_it(sweep_file, tmp_path, capsys,
                                                          monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"), "--executor",
                 "ray", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install -e '.[cluster]'" in err[0]
    assert not (tmp_path / "o" / "trials").exists()


def test_address_needs_the_ray_executor(sweep_file, tmp_path):
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"),
                 "--address", "ray://head:10001", "--quiet"]) == 2


@needs_cluster
@pytest.mark.parametrize("address", ["127.0.0.1:{port}", "ray://127.0.0.1:{port}", "head"])
def test_an_unreachable_ray_address_is_named_at_once(sweep_file, tmp_path, capsys, address):
    import socket
    import time

    with socket.socket() as s:                  # a port that nobody serves once closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = address.format(port=port)
    t0 = time.perf_counter()
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"), "--executor", "ray",
                 "--address", address, "--quiet"]) == 2
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and repr(address) in err[0]
    assert not (tmp_path / "o" / "trials").exists()

"""`vlr sweep --executor ray`: the same sweep on a local Ray instance and on the local pool
gives the same table; an interrupted Ray sweep resumes without recomputing finished trials;
without Ray the executor says how to install it.

Starting Ray costs seconds and most of a GB here, so the tests share ONE local instance
(module fixture); the CLI reuses an instance that is already up and leaves it running."""

import csv
import signal
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
    # Ray's driver takes SIGTERM for itself; the tests after these expect the default back.
    before = signal.getsignal(signal.SIGTERM)
    # address="local": our own instance, whatever `ray start` cluster this machine has.
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    yield ray
    ray.shutdown()
    signal.signal(signal.SIGTERM, before)


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


# A sweep whose "slow" trial runs long enough to be killed once both quick ones are done.
KILL_SWEEP = """\
name: worker death
seeds: 0
settings: {world.backend: synthetic, filter.particles: 200, loop.max_iterations: 2}
cases:
  - {name: quick, world.object: apple}
  - {name: quick, world.object: wine_glass}
  - {name: slow, filter.particles: 60000, loop.max_iterations: 60, loop.min_iterations: 60}
"""


def _kill_the_slow_worker(out, found, give_up):
    """Once both quick trials' records exist, SIGKILL the Ray worker running a trial (the
    slow one: Ray titles a busy worker `ray::<function>`)."""
    import os
    import signal
    import time

    import psutil

    while time.monotonic() < give_up:
        quick = list((out / "trials").glob("quick_*.json"))
        if len(quick) == 2:
            for p in psutil.Process().children(recursive=True):
                try:
                    title = p.cmdline()
                except psutil.Error:
                    continue
                if title and title[0].startswith("ray::_ray_trial"):
                    os.kill(p.pid, signal.SIGKILL)
                    found.append(p.pid)
                    return
        time.sleep(0.2)


def test_a_killed_ray_worker_is_a_failed_trial_and_the_sweep_goes_on(ray_instance, tmp_path,
                                                                     capsys):
    import json
    import threading
    import time

    from vlr.sweep import expand, load_sweep, pending

    path, out = tmp_path / "kill.yaml", tmp_path / "out"
    path.write_text(KILL_SWEEP + f"out: {out}\n")
    trials = expand(load_sweep(path))
    slow = next(t for t in trials if t.case == "slow")
    killed: list[int] = []
    killer = threading.Thread(target=_kill_the_slow_worker,
                              args=(out, killed, time.monotonic() + 60), daemon=True)
    killer.start()
    # The sweep ends (one failed trial: exit 1) instead of stopping at the death.
    assert main(["sweep", str(path), "--executor", "ray", "--quiet"]) == 1
    killer.join()
    assert killed, "no Ray worker was found running the slow trial"
    records = {p.stem: json.loads(p.read_text()) for p in (out / "trials").glob("*.json")}
    assert len(records) == 3
    assert [r["status"] for r in records.values()].count("ok") == 2
    dead = records[slow.id]
    assert dead["status"] == "error" and "WorkerCrashedError" in dead["error"]
    assert "\n" not in dead["error"]
    assert dead["settings"] == slow.settings.flat() and dead["case"] == "slow"
    assert "code" in dead and "group" in dead
    # The tables list it; --resume leaves it, --retry-failed would run it again.
    assert len(_table(out / "table.csv")) == 3
    assert "Failed trials" in (out / "summary.md").read_text()
    assert f"trial {slow.id} failed: WorkerCrashedError" in capsys.readouterr().out
    assert pending(trials, out) == []
    assert pending(trials, out, retry_failed=True) == [slow]

"""A sweep that is stopped, killed or cut short: SIGINT and SIGTERM stop a local pool at
once, its workers with it, and `--resume` finishes to the table of an uninterrupted run; a
record cut mid-write, or an atomic write's leftover temporary file, does not block a resume.

The signal tests run `vlr sweep` as a process: a signal is a whole-process matter."""

import csv
import json
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest

from vlr.cli import main
from vlr.sweep import expand, load_sweep, pending

# Six trials of a second or so: with two workers, several are still to come at the first
# record.
POOL_SWEEP = """\
name: stopped
seeds: 0-5
settings: {world.backend: synthetic, filter.particles: 3000, loop.max_iterations: 10,
           loop.min_iterations: 10}
"""

# Columns that are not results: times, and the commit (others may commit while this runs).
NOT_RESULTS = {"s_per_iteration", "s/iteration", "s_per_trial", "filter s/trial", "commit"}


def _table(path):
    with open(path, newline="") as f:
        return [{k: v for k, v in r.items() if k not in NOT_RESULTS} for r in csv.DictReader(f)]


@pytest.fixture(scope="module")
def pool_sweep(tmp_path_factory):
    """The sweep file, and the table of its uninterrupted run (in this process: a seed fixes
    a trial's numbers whichever process runs it)."""
    root = tmp_path_factory.mktemp("pool")
    path = root / "sweep.yaml"
    path.write_text(POOL_SWEEP + f"out: {root / 'whole'}\n")
    assert main(["sweep", str(path), "--quiet"]) == 0
    return path, _table(root / "whole" / "table.csv")


def _vlr(*args):
    return subprocess.Popen([sys.executable, "-m", "vlr.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _children(proc):
    """The sweep's processes, and among them the pool's workers (spawned: `spawn_main`; the
    others are multiprocessing's resource tracker)."""
    children = psutil.Process(proc.pid).children(recursive=True)
    return children, [p for p in children if "spawn_main" in " ".join(_cmdline(p))]


def _cmdline(p) -> list[str]:
    try:
        return p.cmdline()
    except psutil.Error:   # gone, or a zombie (a short-lived helper process)
        return []


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_a_local_pool_and_resume_finishes_it(pool_sweep, tmp_path, sig, code):
    path, whole = pool_sweep
    out = tmp_path / "out"
    proc = _vlr("sweep", str(path), "--out", str(out), "--workers", "2", "--quiet")
    deadline = time.monotonic() + 60
    while not list((out / "trials").glob("[!.]*.json")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    workers, pool = _children(proc)
    assert len(pool) == 2
    t0 = time.monotonic()
    os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=30)
    stopped = time.monotonic() - t0
    assert proc.returncode == code, err
    assert stopped < 10, f"took {stopped:.1f} s to stop"
    assert err.strip().splitlines()[-1] == "vlr sweep: interrupted"
    # The workers went with it: none left computing or blocked.
    _, alive = psutil.wait_procs(workers, timeout=5)
    assert alive == []
    done = [p for p in (out / "trials").glob("*.json") if not p.name.startswith(".")]
    assert 1 <= len(done) < 6
    assert all(json.loads(p.read_text())["status"] == "ok" for p in done)
    # The table of what finished; resumed, that of an uninterrupted run.
    assert len(_table(out / "table.csv")) == len(done)
    resumed = _vlr("sweep", str(path), "--out", str(out), "--workers", "2", "--quiet",
                   "--resume")
    stdout, err = resumed.communicate(timeout=60)
    assert resumed.returncode == 0, err
    assert f"{len(done)} already done, {6 - len(done)} to run" in stdout
    assert _table(out / "table.csv") == whole


def test_a_pool_worker_exits_when_its_sweep_is_killed(pool_sweep, tmp_path):
    """SIGKILL cannot be handled: the workers notice their parent is gone and exit instead
    of computing trials nobody collects."""
    path, _ = pool_sweep
    out = tmp_path / "out"
    proc = _vlr("sweep", str(path), "--out", str(out), "--workers", "2", "--quiet")
    deadline = time.monotonic() + 60
    while not list((out / "trials").glob("[!.]*.json")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    workers, pool = _children(proc)
    assert len(pool) == 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=10)
    _, alive = psutil.wait_procs(workers, timeout=5)
    assert alive == []


def test_a_truncated_record_is_run_again_with_a_warning(sweep_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(sweep_file), "--quiet"]) == 0
    trials = expand(load_sweep(sweep_file))
    whole = _table(out / "table.csv")
    cut = out / "trials" / f"{trials[1].id}.json"
    text = cut.read_text()
    cut.write_text(text[: len(text) // 2])
    assert pending(trials, out) == [trials[1]]
    assert pending(trials, out, retry_failed=True) == [trials[1]]
    for flags in (["--resume"], ["--resume", "--retry-failed"]):
        cut.write_text(text[: len(text) // 2])
        capsys.readouterr()
        assert main(["sweep", str(sweep_file), "--quiet", *flags]) == 0
        captured = capsys.readouterr()
        assert "3 already done, 1 to run" in captured.out
        warning = [line for line in captured.err.splitlines() if str(cut) in line]
        assert len(warning) == 1 and "running that trial again" in warning[0]
        assert json.loads(cut.read_text())["status"] == "ok"
        assert _table(out / "table.csv") == whole


def test_leftover_temporary_files_do_not_confuse_a_resume(sweep_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(sweep_file), "--quiet"]) == 0
    trials = expand(load_sweep(sweep_file))
    (out / "trials" / f"{trials[0].id}.json").unlink()
    # What a kill mid-write leaves: the records' and the tables' temporary files.
    leftovers = [out / "trials" / f".{trials[0].id}.k3_x9abc.json",
                 out / "trials" / f".{trials[2].id}.Qw_12345.json", out / ".table.ab12cd_3.csv",
                 out / ".summary.zz99yy88.md"]
    for p in leftovers:
        p.write_text('{"id": "half')
    keep = out / "notes.txt"
    keep.write_text("mine")
    capsys.readouterr()
    assert main(["sweep", str(sweep_file), "--quiet", "--resume"]) == 0
    assert "3 already done, 1 to run" in capsys.readouterr().out
    assert not any(p.exists() for p in leftovers) and keep.exists()
    assert len((out / "table.csv").read_text().splitlines()) == 5
    from vlr.sweep import collect

    assert len(collect(out)) == 4


@pytest.mark.parametrize("make", ["file", "under a file"])
def test_a_bad_out_is_one_line_before_any_trial(sweep_file, tmp_path, capsys, make):
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    out = blocker if make == "file" else blocker / "out"
    t0 = time.perf_counter()
    assert main(["sweep", str(sweep_file), "--out", str(out), "--quiet"]) == 2
    assert time.perf_counter() - t0 < 5
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and str(out) in err[0]


def test_a_dead_pool_worker_ends_the_sweep_in_one_line(pool_sweep, tmp_path):
    path, _ = pool_sweep
    out = tmp_path / "out"
    proc = _vlr("sweep", str(path), "--out", str(out), "--workers", "2", "--quiet")
    deadline = time.monotonic() + 60
    while not list((out / "trials").glob("[!.]*.json")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    workers, pool = _children(proc)
    os.kill(pool[0].pid, signal.SIGKILL)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 2, err
    assert err.strip().splitlines()[-1].startswith("vlr sweep: error: a worker of the local "
                                                   "pool died")
    _, alive = psutil.wait_procs(workers, timeout=5)
    assert alive == []
    done = [p for p in (out / "trials").glob("*.json") if not p.name.startswith(".")]
    assert all(json.loads(p.read_text())["status"] == "ok" for p in done)


def test_a_signal_stops_vlr_task_seeds_and_its_workers(tmp_path):
    """`vlr task --seeds --workers 2` runs on the same pool: SIGTERM ends it at once, its
    workers with it."""
    proc = _vlr("task", "maze", "--seeds", "0-3", "--workers", "2", "--particles", "300",
                "--identify-iterations", "2", "--out", str(tmp_path / "out"), "--quiet")
    deadline = time.monotonic() + 60
    while len(_children(proc)[1]) < 2:
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    workers, _ = _children(proc)
    t0 = time.monotonic()
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert time.monotonic() - t0 < 10
    assert err.strip().splitlines()[-1] == "vlr task: interrupted"
    _, alive = psutil.wait_procs(workers, timeout=5)
    assert alive == []

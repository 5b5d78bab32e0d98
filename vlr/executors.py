"""Where a sweep's trials run: a local process pool (`run_local`) or a Ray cluster
(`run_ray`). Both call `vlr.sweep.run_one` once per trial, so each finished trial lands in
OUT/trials/<id>.json as it finishes and `--resume` works the same whichever ran it.

Ray is optional (`pip install -e .[cluster]`); it is imported only by `run_ray`.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlr.errors import UserError

if TYPE_CHECKING:
    from vlr.sweep import Trial

__all__ = ["EXECUTORS", "run_local", "run_ray", "import_ray", "check_reachable"]

EXECUTORS = ("local", "ray")

OnDone = Callable[[dict[str, Any]], None]


def check_reachable(address: str, timeout: float = 5.0) -> None:
    """A Ray address that no socket answers is one UserError now: `ray.init` on a plain
    HOST:PORT that nobody serves waits for minutes before it fails. "auto" and "local"
    are Ray's own and are left to it."""
    if address in ("auto", "local"):
        return
    host, sep, port = address.split("://", 1)[-1].rpartition(":")
    if not (sep and host and port.isdigit()):
        raise UserError(f"Ray address {address!r}: expected HOST:PORT, ray://HOST:PORT or "
                        "auto")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise UserError(f"cannot reach the Ray cluster at {address!r}: {exc}") from None


# --------------------------------------------------------------------------- local pool

def run_local(trials: list[Trial], out: Path, workers: int | None, on_done: OnDone,
              keep_files: bool = False) -> None:
    """Run trials on a local process pool (`workers` processes; 1 or None runs them in this
    process). Each worker gets an equal share of the cores for numba's threads."""
    from vlr.sweep import run_one

    workers = workers or 1
    if workers <= 1:
        for t in trials:
            on_done(run_one(t, out, keep_files))
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    threads = max(1, (os.cpu_count() or 1) // workers)
    # spawn, not fork: forking a process whose numba threads already ran is unsafe.
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                             initargs=(threads,),
                             mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(run_one, t, out, keep_files) for t in trials]
        for f in as_completed(futures):
            on_done(f.result())


def _init_worker(threads: int) -> None:
    os.environ["NUMBA_NUM_THREADS"] = str(threads)


# --------------------------------------------------------------------------- Ray

RAY_MISSING = ("--executor ray needs Ray, an optional extra: pip install -e '.[cluster]' "
               "(or pip install 'ray>=2.40,<2.61')")


def import_ray():
    """The `ray` module, or a UserError saying how to install it."""
    try:
        import ray
    except ImportError:
        raise UserError(RAY_MISSING) from None
    return ray


def _ray_trial(trial: Trial, out: str, keep_files: bool, threads: int) -> dict[str, Any]:
    """One trial on a Ray worker: `vlr.sweep.run_one` with numba limited to `threads`.

    The worker writes the record itself when OUT is on a filesystem it shares with the
    driver; if it cannot write there, the driver writes the returned record."""
    import numba

    from vlr.io import write_json_atomic
    from vlr.sweep import run_one, trial_path

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    record = run_one(trial, Path(out), keep_files, write=False)
    try:
        write_json_atomic(trial_path(Path(out), trial), record)
    except OSError:
        pass  # not our filesystem: the driver writes it
    return record


def run_ray(trials: list[Trial], out: Path, workers: int | None, on_done: OnDone,
            keep_files: bool = False, address: str | None = None,
            working_dir: str | Path | None = None) -> None:
    """Run trials as Ray tasks, one task (1 CPU) per trial.

    Connects to `address` (or RAY_ADDRESS) if given, else starts a local instance with
    `workers` CPUs (default: all cores) and shuts it down at the end. On a cluster, `workers`
    (if given) caps the trials in flight. A task that dies (worker crash, node lost) is
    recorded as a failed trial and the sweep goes on, as with the local pool.

    `working_dir` (a checkout of this repository) is shipped to the workers with the tasks
    (Ray's runtime_env working_dir), for clusters whose nodes have the dependencies but not
    this code; otherwise each node needs the package installed (docs/SWEEPS.md)."""
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address:
        check_reachable(address)
    ray = import_ray()
    if not trials:
        return
    from vlr.io import write_json_atomic
    from vlr.sweep import trial_path

    out = Path(out).resolve()
    # The job's runtime_env (Ray ships a working_dir at the job level only, in ray.init).
    runtime_env: dict[str, Any] = {}
    if working_dir:
        runtime_env["working_dir"] = str(Path(working_dir).resolve())
        runtime_env["excludes"] = [".git", ".venv", "runs", "**/__pycache__"]
    if address and os.environ.get("NUMBA_CACHE_DIR"):
        # Workers on other machines use the driver's numba cache folder (on a shared
        # filesystem): the kernels compile once, not once per node.
        runtime_env["env_vars"] = {"NUMBA_CACHE_DIR": os.environ["NUMBA_CACHE_DIR"]}
    started = False
    if ray.is_initialized():
        if working_dir:
            raise UserError("--working-dir: Ray is already initialized in this process; "
                            "its runtime_env cannot change")
    else:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": True}
        if runtime_env:
            kwargs["runtime_env"] = runtime_env
        if address:
            try:
                ray.init(address=address, **kwargs)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                raise UserError(f"cannot connect to the Ray cluster at {address!r}: "
                                f"{exc}") from None
        else:
            # A local instance: workers share this machine's filesystem and environment
            # (numba cache in vlr/__pycache__, NUMBA_CACHE_DIR, MUJOCO_GL): no runtime_env.
            # address="local": a new instance even if a `ray start` cluster (or its stale
            # /tmp/ray/ray_current_cluster) is on this machine.
            ray.init(address="local", num_cpus=workers or os.cpu_count() or 1, **kwargs)
        started = True
    try:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        local = not address
        # As the local pool: concurrent trials share the cores for numba's threads. On a
        # cluster each task holds one CPU, so one numba thread.
        threads = max(1, (os.cpu_count() or 1) // (workers or cpus)) if local else 1
        task = ray.remote(num_cpus=1, max_retries=0)(_ray_trial)
        limit = len(trials) if (local or not workers) else workers
        queue = list(trials)
        running: dict[Any, Trial] = {}
        while queue or running:
            while queue and len(running) < limit:
                t = queue.pop(0)
                running[task.remote(t, str(out), keep_files, threads)] = t
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                t = running.pop(ref)
                try:
                    record = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - the task died: a failed trial
                    record = {"id": t.id, "case": t.case, "settings": t.settings.to_dict(),
                              "status": "error", "error": f"{type(exc).__name__}: "
                              f"{str(exc).strip().splitlines()[0] if str(exc) else ''}"}
                    write_json_atomic(trial_path(out, t), record)
                if not trial_path(out, t).exists():
                    write_json_atomic(trial_path(out, t), record)
                on_done(record)
    finally:
        if started:
            ray.shutdown()

"""Where a sweep's trials run: a local process pool (`run_local`) or a Ray cluster
(`run_ray`). Both call `vlr.sweep.run_one` once per trial, so each finished trial lands in
OUT/trials/<id>.json as it finishes and `--resume` works the same whichever ran it.

A sweep stops on SIGINT or SIGTERM (`stop_on_signals`): no trial starts after the signal,
the trials in flight are abandoned (local workers terminated, Ray tasks cancelled), the
finished ones stay on disk for `--resume`, and the CLI exits 128 + the signal's number.

Ray is optional (`pip install -e .[cluster]`); it is imported only by `run_ray`.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vlr.errors import Interrupted, UserError
from vlr.memory import keep_freed_memory

if TYPE_CHECKING:
    from vlr.sweep import Trial

__all__ = ["EXECUTORS", "run_local", "run_ray", "import_ray", "check_reachable",
           "stop_on_signals"]

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


# --------------------------------------------------------------------------- stopping

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """SIGINT and SIGTERM raise `Interrupted` in the main thread while the block runs.

    SIGTERM's default action would end this process at once and leave a pool's workers
    computing, then blocked on a queue nobody reads; as an exception it goes through the
    executors' clean-up (workers terminated, Ray tasks cancelled) and the CLI's exit code
    143. After the first signal both are ignored until the block ends, so that a second
    Ctrl-C cannot cut that clean-up short. Outside the main thread (signals cannot be
    handled there) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: object) -> None:
        for sig in _STOP_SIGNALS:
            signal.signal(sig, signal.SIG_IGN)
        raise Interrupted(signum)

    old = {sig: signal.signal(sig, stop) for sig in _STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


# --------------------------------------------------------------------------- local pool

def run_local(trials: list[Trial], out: Path, workers: int | None, on_done: OnDone,
              keep_files: bool = False) -> None:
    """Run trials on a local process pool (`workers` processes; 1 or None runs them in this
    process). Each worker gets an equal share of the cores for numba's threads.

    An exception here (`Interrupted` from `stop_on_signals`, Ctrl-C) terminates the
    workers, so that no trial runs on after it: the trials in flight are lost, to be run by
    `--resume`."""
    from vlr.sweep import run_one

    workers = workers or 1
    if workers <= 1:
        for t in trials:
            on_done(run_one(t, out, keep_files))
        return
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    try:
        with process_pool(workers) as pool:
            futures = [pool.submit(run_one, t, out, keep_files) for t in trials]
            for f in as_completed(futures):
                on_done(f.result())
    except BrokenProcessPool:
        # The executor fails every trial it held, not just the dead worker's: none of them
        # is a failed trial, all of them are for --resume.
        raise UserError("a worker of the local pool died (killed, or out of memory); the "
                        "trials not finished run with --resume") from None


@contextlib.contextmanager
def process_pool(workers: int) -> Iterator[Any]:
    """A local pool of `workers` spawned processes, each with an equal share of the cores
    for numba's threads (`_init_worker`), for `vlr sweep` and `vlr task --seeds`. When the
    block raises (`Interrupted` from `stop_on_signals`, Ctrl-C, a dead worker) the workers
    are terminated, so that no trial runs on after it."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    threads = max(1, (os.cpu_count() or 1) // workers)
    # spawn, not fork: forking a process whose numba threads already ran is unsafe.
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                               initargs=(threads, os.getpid()),
                               mp_context=multiprocessing.get_context("spawn"))
    try:
        yield pool
    except BaseException:
        _stop_pool(pool)
        raise
    pool.shutdown()


def _stop_pool(pool: Any, grace: float = 2.0) -> None:
    """Terminate a ProcessPoolExecutor's workers (SIGTERM, then SIGKILL after `grace`
    seconds) and drop its queued trials. `shutdown(cancel_futures=True)` alone would let
    every worker finish the trial it holds and start the one queued for it; Python 3.11's
    executor has no public way to end its workers (3.14's `terminate_workers`)."""
    processes = list(getattr(pool, "_processes", {}).values())
    for p in processes:
        with contextlib.suppress(OSError):
            p.terminate()
    deadline = time.monotonic() + grace
    for p in processes:
        p.join(max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            with contextlib.suppress(OSError):
                p.kill()
            p.join(1.0)
    pool.shutdown(wait=True, cancel_futures=True)


def _init_worker(threads: int, parent: int) -> None:
    """A pool worker: its share of numba's threads; SIGINT ignored (a Ctrl-C reaches the
    whole process group, and the main process decides: it terminates the workers); and a
    watch on the main process, so that a worker whose sweep was killed (SIGKILL, out of
    memory) exits instead of computing a trial nobody collects, then waiting forever."""
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    keep_freed_memory()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True,
                     name="vlr-parent-watch").start()


def _exit_with_parent(parent: int, period: float = 0.5) -> None:
    while os.getppid() == parent:
        time.sleep(period)
    os._exit(1)


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
    keep_freed_memory()
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
    from vlr.sweep import failure_record, trial_path

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
                _init_ray(ray, address=address, **kwargs)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                raise UserError(f"cannot connect to the Ray cluster at {address!r}: "
                                f"{exc}") from None
        else:
            # A local instance: workers share this machine's filesystem and environment
            # (numba cache in vlr/__pycache__, NUMBA_CACHE_DIR, MUJOCO_GL): no runtime_env.
            # address="local": a new instance even if a `ray start` cluster (or its stale
            # /tmp/ray/ray_current_cluster) is on this machine.
            _init_ray(ray, address="local", num_cpus=workers or os.cpu_count() or 1, **kwargs)
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
        try:
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
                        record = failure_record(t, _ray_error(exc))
                        write_json_atomic(trial_path(out, t), record)
                    if not trial_path(out, t).exists():
                        write_json_atomic(trial_path(out, t), record)
                    on_done(record)
        except BaseException:
            # Stopped (a signal, Ctrl-C): the tasks in flight would run on, on a cluster,
            # after this driver has gone.
            for ref in running:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            raise
    finally:
        if started:
            ray.shutdown()


def _init_ray(ray: Any, **kwargs: Any) -> None:
    """`ray.init`, keeping this process's SIGINT and SIGTERM handlers: Ray's driver installs
    its own SIGTERM handler (a bare `sys.exit`) over the sweep's stop (`stop_on_signals`), and
    leaves it behind after `ray.shutdown`."""
    main = threading.current_thread() is threading.main_thread()
    old = {sig: signal.getsignal(sig) for sig in _STOP_SIGNALS} if main else {}
    try:
        ray.init(**kwargs)
    finally:
        for sig, handler in old.items():
            if handler is not None:
                signal.signal(sig, handler)


def _ray_error(exc: Exception) -> str:
    """A dead task's error in one line: Ray's messages run to paragraphs of advice."""
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0] if text else ''}".rstrip(": ")

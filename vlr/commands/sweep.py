"""`vlr sweep`: many identification trials on a local process pool or a Ray cluster, one
table at the end.

    vlr sweep docs/sweeps/synthetic.yaml               # a sweep file (vlr.sweep)
    vlr sweep --backend sim --object apple wine_glass --seeds 0-4 --particles 60000 --out DIR
    vlr sweep FILE --resume                            # skip trials already finished
    vlr sweep FILE --executor ray --address ray://HEAD:10001   # one Ray task per trial

Every finished trial lands in OUT/trials/<id>.json at once (written atomically), so a sweep
interrupted at any point resumes with --resume without repeating one. The tables
(OUT/table.csv per trial, OUT/summary.csv and OUT/summary.md per case: mean ± sd over seeds)
are rebuilt from those files, also by `vlr sweep FILE --table-only`.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from vlr.errors import UserError

_LOG = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="run many identification trials and tabulate them",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", nargs="?", help="sweep YAML file (else the flags define it)")
    p.add_argument("--out", help="output folder (overrides the file's)")
    p.add_argument("--backend", default="sim", help="synthetic | sim | hardware")
    p.add_argument("--object", nargs="+", default=["apple"], help="objects (grid)")
    p.add_argument("--hand", nargs="+", default=["modelo"], help="nominal hands (grid)")
    p.add_argument("--true-hand", help="synthetic world or sim: the hand the world is built with")
    p.add_argument("--unknown", action="append", default=[], help="as in vlr identify")
    p.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 0,2,5 (default 0-4)")
    p.add_argument("--particles", type=int, default=60_000)
    p.add_argument("--max-iterations", type=int, default=40)
    p.add_argument("--workers", type=int, default=None,
                   help="local: processes in the pool (default 1; each gets cores/workers "
                   "numba threads); ray: CPUs of a local instance (default all cores), or "
                   "the trials in flight on a cluster (default all)")
    p.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="local process pool (default) or one Ray task per trial "
                   "(pip install -e '.[cluster]')")
    p.add_argument("--address", help="with --executor ray: the cluster, e.g. "
                   "ray://HEAD:10001 (default: RAY_ADDRESS, else a local Ray instance)")
    p.add_argument("--working-dir", help="with --executor ray: ship this checkout to the "
                   "workers (Ray runtime_env working_dir) instead of installing it on each "
                   "node")
    p.add_argument("--resume", action="store_true",
                   help="keep finished trials in OUT and run only the others")
    p.add_argument("--retry-failed", action="store_true",
                   help="with --resume: also rerun trials that failed")
    p.add_argument("--keep-files", action="store_true",
                   help="keep each trial's history.npz and convergence.png")
    p.add_argument("--table-only", action="store_true",
                   help="rebuild the tables from OUT/trials without running anything")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _spec(args: argparse.Namespace):
    from vlr.sweep import SweepSpec, load_sweep, parse_seeds

    if args.file:
        return load_sweep(args.file, args.out)
    settings = {"world.backend": args.backend, "filter.particles": args.particles,
                "loop.max_iterations": args.max_iterations,
                "filter.unknowns": list(args.unknown)}
    if args.true_hand:
        settings["world.true_hand"] = args.true_hand
    return SweepSpec(name="sweep", out=Path(args.out or "runs/sweep"),
                     seeds=parse_seeds(args.seeds), settings=settings, cases=({},),
                     grid={"world.object": list(args.object), "world.hand": list(args.hand)})


def run(args: argparse.Namespace) -> int:
    from vlr.executors import import_ray, run_local, run_ray, stop_on_signals
    from vlr.io import check_output_dir
    from vlr.sweep import collect, expand, pending, remove_temp_files, write_tables

    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers {args.workers} must be >= 1")
    if (args.address or args.working_dir) and args.executor != "ray":
        raise UserError("--address and --working-dir are for Ray: add --executor ray")
    if args.working_dir and not Path(args.working_dir, "vlr").is_dir():
        raise UserError(f"--working-dir {args.working_dir!r} is not a checkout of this "
                        "repository (no vlr/ in it)")
    if args.executor == "ray" and not args.table_only:
        import_ray()  # fail before any work if Ray is missing
    spec = _spec(args)
    trials = expand(spec)
    out = spec.out
    done_before = [t for t in trials if (out / "trials" / f"{t.id}.json").exists()]
    if args.table_only:
        records = collect(out, trials)
        paths = write_tables(out, records, spec.name)
        print(paths["summary_md"].read_text())
        return 0
    if done_before and not args.resume:
        raise UserError(f"{out} already holds {len(done_before)} finished trial(s) of this "
                        "sweep: pass --resume to finish it, or choose another --out")
    # A bad --out (a file, under a file, unwritable) is one line now, not after a trial.
    check_output_dir(out)
    if removed := remove_temp_files(out):
        _LOG.info("removed %d temporary file(s) of writes a kill interrupted in %s",
                  removed, out)
    todo = pending(trials, out, retry_failed=args.retry_failed)
    print(f"sweep {spec.name!r}: {len(trials)} trials, {len(trials) - len(todo)} already "
          f"done, {len(todo)} to run -> {out}", flush=True)
    from vlr.logs import progress_bar

    bar = progress_bar(args.quiet, total=len(todo), desc="sweep", unit="trial")
    failed = 0
    t0 = time.perf_counter()

    def on_done(rec: dict) -> None:
        nonlocal failed
        _LOG.debug("trial %s: %s", rec["id"], rec["status"])
        if rec["status"] != "ok":
            failed += 1
            msg = f"trial {rec['id']} failed: {rec['error']}"
            (bar.write if bar is not None else print)(msg)
        if bar is not None:
            bar.update(1)

    finished = False
    # Signals stop the trials (vlr.executors.stop_on_signals) and stay held off while the
    # tables of what finished are written.
    with stop_on_signals():
        try:
            if args.executor == "ray":
                run_ray(todo, out, args.workers, on_done, keep_files=args.keep_files,
                        address=args.address, working_dir=args.working_dir)
            else:
                run_local(todo, out, args.workers, on_done, keep_files=args.keep_files)
            finished = True
        finally:
            if bar is not None:
                bar.close()
            records = collect(out, trials, skip_unreadable=True)
            # An interrupted sweep keeps the table of what finished; one that never started
            # (a bad --address) leaves no empty tables behind.
            if finished or records:
                paths = write_tables(out, records, spec.name)
    print(paths["summary_md"].read_text())
    print(f"{len(todo)} trial(s) in {time.perf_counter() - t0:.0f} s, {failed} failed; wrote "
          f"{paths['table']}, {paths['summary_csv']}, {paths['summary_md']}")
    return 1 if failed else 0

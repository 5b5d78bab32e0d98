"""`vlr task handwriting|maze|cups`: run the VLR baseline controller, or your own policy, on a
task environment.

Writes into --out: `result.json` (the task metrics under `errors`, plus settings and timing)
and `task.png` (the traced letters over the targets, the marble's path in the maze), both
atomically. Arguments, environment options and the output folder are checked before the
(minutes-long) run, so that a bad one ends in one line, not a traceback after the run.

`--seeds 0-4` runs the task once per seed, each into OUT/seed-N (`--workers` of them at
once, in processes), then writes OUT/summary.md (mean and SD over seeds of the headline
figures, beside the paper's) and OUT/summary.csv (one row per seed): five seeds per task
from one command.

`--policy MODULE:NAME` (or `FILE.py:NAME`, whose folder goes on the import path as a
script's does) runs your policy instead of the baseline, with the same seeds, metrics,
pictures and summary, so that the two compare row for row. NAME is a factory called once
per episode, after the identification in reset, with the unwrapped environment (its filter
`pf`, `commands`, `moves`, `observation` and `target`, as the baseline reads them); it
returns the policy, a callable from the observation to the action (the three tendon changes
[m]), as `env.unwrapped.baseline()` does. An action that is not three finite numbers ends
the run with one line naming the policy, the step and the value.

The environments live in the `vlr.tasks` package, which plugs in through the `vlr.tasks`
entry-point group (pyproject.toml), as backends do: the core never imports `vlr.tasks`,
`vlr.sim` or `vlr.hardware` itself. Each task's entry point names its dense id
(`vlr/HandwritingDense-v2`, ...): the progress bar shows minus the reward, the distance to
the target; the metrics do not depend on the reward.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import math
import os
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from vlr.errors import UserError

TASK_GROUP = "vlr.tasks"


def _tasks() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=TASK_GROUP)}


def env_options(env_id: str) -> dict[str, object]:
    """The environment's own arguments (`--option KEY=VALUE`) and their defaults: the
    keyword parameters of its class's constructor and of the bases it hands **kwargs on to
    (`inspect`; gymnasium's registry names the class), with the id's own (its spec's
    kwargs: the dense ids' `reward_type`)."""
    import inspect

    import gymnasium as gym
    from gymnasium.envs.registration import load_env_creator

    spec = gym.spec(env_id)
    entry = spec.entry_point
    cls = load_env_creator(entry) if isinstance(entry, str) else entry
    out: dict[str, object] = {}
    for klass in getattr(cls, "__mro__", (cls,)):
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        params = inspect.signature(init).parameters.values()
        for prm in params:
            if prm.name not in ("self", "backend", "render_mode") and prm.kind in (
                    prm.POSITIONAL_OR_KEYWORD, prm.KEYWORD_ONLY):
                out.setdefault(prm.name, prm.default)
        if not any(prm.kind == prm.VAR_KEYWORD for prm in params):
            break
    out.update({k: v for k, v in spec.kwargs.items() if k in out})
    return out


class _HelpWithOptions(argparse.Action):
    """--help, then, with a task named before it, that task's options and their defaults
    (built only when asked for: it imports the environments)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help=None):  # noqa: A002 (argparse's name)
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        parser.print_help()
        name = getattr(namespace, "name", None)
        found = _tasks()
        if name in found:
            env_id = found[name].load()
            print(f"\n{name}'s options ({env_id}; --option KEY=VALUE), with their defaults:")
            for key, value in env_options(env_id).items():
                print(f"  {key} = {value!r}")
        else:
            print("\n`vlr task NAME --help` lists that task's options (--option KEY=VALUE).")
        parser.exit()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("task", add_help=False,
                       help="run the VLR baseline controller on a manipulation task "
                       "(handwriting, marble maze, cup stacking)")
    p.add_argument("-h", "--help", action=_HelpWithOptions,
                   help="show this help and, after a task's name, its options")
    p.add_argument("name", help="handwriting | maze | cups")
    p.add_argument("--backend", default="sim", help="sim | hardware")
    p.add_argument("--config", help="hardware backend: the hardware YAML file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", metavar="SEEDS",
                   help="run several seeds (e.g. 0-4 or 0,2,5), each into OUT/seed-N, then "
                   "write OUT/summary.md and OUT/summary.csv (mean and SD over seeds)")
    p.add_argument("--workers", type=int, default=1,
                   help="with --seeds: seeds run at once, one process each (default 1)")
    p.add_argument("--particles", type=int,
                   help="particles of the identification in reset (default: the task's)")
    p.add_argument("--identify-iterations", type=int,
                   help="its exploratory moves (default: the task's)")
    p.add_argument("--method", choices=("dls", "transpose"),
                   help="control step (default: the task's)")
    p.add_argument("--no-secant", action="store_true",
                   help="the VLR's Jacobian alone, without the camera-fitted correction")
    p.add_argument("--reversal-shrink", type=float, default=None, metavar="F",
                   help="scale a tendon's steps by F each time its step reverses sign "
                   "(vlr.controller.ControllerConfig.reversal_shrink; default: the task's)")
    p.add_argument("--alpha", type=float, default=None,
                   help="Eq. 12's rotation weight (mm per degree) on the full rows "
                   "(default: the task's; cups 0.7: docs/TASKS.md; the paper's 9.5 "
                   "has no units)")
    p.add_argument("--jacobian-particles", type=int, default=None, metavar="N",
                   help="posterior particles the VLR's Jacobian (Eq. 10) is averaged over "
                   "(vlr.controller.ControllerConfig.jacobian_particles; default: the task's)")
    p.add_argument("--controller", action="append", default=[], metavar="KEY=VALUE",
                   help="a field of the baseline's controller config "
                   "(vlr.controller.ControllerConfig), e.g. secant_updates=True")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an environment argument, e.g. word=SCI or letter_height=0.002")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the identification in reset, as `vlr identify --set` "
                   "(e.g. filter.observation.sigma_turn_deg=0.5)")
    p.add_argument("--policy", metavar="MODULE:NAME",
                   help="your policy instead of the baseline: NAME(env) returns a callable "
                   "observation -> action (module path, or FILE.py:NAME; docs/TASKS.md)")
    p.add_argument("--out", default=None, help="output folder (default runs/task-NAME)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def parse_options(items: list[str], flag: str = "--option") -> dict:
    """KEY=VALUE items to a dict, each value a Python literal where it parses as one (else
    the string); UserError naming `flag` and the item that has no "=" or no key."""
    import ast

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UserError(f"{flag} {item!r}: expected KEY=VALUE")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key] = value
    return out


@dataclass(frozen=True)
class SeedRun:
    """One checked `vlr task` run: what a worker process needs (picklable)."""

    name: str
    env_id: str
    kwargs: dict
    changes: dict
    options: dict
    seed: int
    out: Path
    quiet: bool
    policy: str | None = None   # MODULE:NAME or /abs/FILE.py:NAME; None: the baseline


def run(args: argparse.Namespace) -> int:
    from vlr.sweep import parse_seeds

    seeds = parse_seeds(args.seeds) if args.seeds is not None else None
    if seeds is not None and len(set(seeds)) != len(seeds):
        raise UserError(f"--seeds {args.seeds!r}: a seed appears twice")
    if isinstance(args.workers, bool) or args.workers < 1:
        raise UserError(f"--workers {args.workers} must be >= 1")
    if args.workers > 1 and seeds is None:
        raise UserError("--workers runs several --seeds at once; give --seeds too")
    if args.workers > 1 and args.backend == "hardware":
        raise UserError("--workers with --backend hardware: there is one hand; run the seeds "
                        "one after another (--workers 1)")
    name, env_id, kwargs, changes, options = _checked(args)
    policy = _checked_policy(args.policy, changes)
    out = Path(args.out or f"runs/task-{args.name}")
    _check_out(out)
    if seeds is None:
        result = run_seed(SeedRun(name, env_id, kwargs, changes, options, args.seed, out,
                                  args.quiet, policy))
        print(summary_line(result))
        print(f"wrote {out / 'result.json'}, {out / 'task.png'}")
        return 0
    runs = [SeedRun(name, env_id, kwargs, changes, options, s, out / f"seed-{s}",
                    args.quiet or args.workers > 1, policy) for s in seeds]
    return _run_seeds(runs, out, args.workers)


def _checked(args: argparse.Namespace) -> tuple[str, str, dict, dict, dict]:
    """Every argument checked, and the environment made once to check its options."""
    import gymnasium as gym

    found = _tasks()
    if args.name not in found:
        raise UserError(f"unknown task {args.name!r}; available: {', '.join(sorted(found))}")
    if args.backend not in ("sim", "hardware"):
        raise UserError(f"--backend {args.backend!r}: use sim or hardware")
    if args.backend == "hardware" and not args.config:
        raise UserError("--backend hardware needs --config FILE")
    if args.particles is not None and args.particles < 10:
        raise UserError(f"--particles {args.particles} must be >= 10")
    if args.identify_iterations is not None and args.identify_iterations < 0:
        raise UserError(f"--identify-iterations {args.identify_iterations} must be >= 0")
    if args.seed < 0:
        raise UserError(f"--seed {args.seed} must be >= 0")
    options = parse_options(args.option)
    env_id = found[args.name].load()      # importing the tasks package registers the envs
    if env_id not in gym.registry:
        raise UserError(f"task {args.name!r} ({env_id}) is not available in this version")
    known = env_options(env_id)
    for key in options:
        if key not in known:
            import difflib

            close = difflib.get_close_matches(key, known, n=3)
            hint = (f"did you mean {' or '.join(close)}?" if close
                    else f"one of {', '.join(sorted(known))}.")
            raise UserError(f"--option {key!r} is not an option of {args.name}: {hint} "
                            f"(`vlr task {args.name} --help` lists them)")
    given = {"particles": args.particles, "identify_iterations": args.identify_iterations}
    kwargs = {"backend": args.backend, **{k: v for k, v in given.items() if v is not None},
              **options}
    if args.set:
        from vlr.settings import parse_assignment

        kwargs["settings"] = {**kwargs.get("settings", {}),
                              **dict(parse_assignment(t) for t in args.set)}
    if args.config:
        kwargs["hardware_config"] = args.config
    try:   # checks the arguments; the backend opens in reset
        env = gym.make(env_id, **kwargs)
        task_config = env.unwrapped.controller_config
        env.close()
    except (TypeError, ValueError) as exc:   # an unknown or bad environment argument
        raise UserError(f"--option: {exc}") from None
    changes = {}
    if args.method:
        changes["method"] = args.method
    if args.no_secant:
        changes["secant"] = False
    if args.reversal_shrink is not None:
        if not 0 < args.reversal_shrink <= 1:
            raise UserError(f"--reversal-shrink {args.reversal_shrink} must be in (0, 1]")
        changes["reversal_shrink"] = args.reversal_shrink
    if args.alpha is not None:
        if not (math.isfinite(args.alpha) and args.alpha > 0):
            raise UserError(f"--alpha {args.alpha} must be a positive number")
        changes["alpha"] = args.alpha
    if args.jacobian_particles is not None:
        if args.jacobian_particles < 1:
            raise UserError(f"--jacobian-particles {args.jacobian_particles} must be >= 1")
        changes["jacobian_particles"] = args.jacobian_particles
    if args.controller:
        known = {f.name for f in dataclasses.fields(task_config)}
        for key, value in parse_options(args.controller, "--controller").items():
            if key not in known:
                raise UserError(f"--controller {key!r}: not a controller setting (one of "
                                f"{', '.join(sorted(known))})")
            # A value of another type than the task's (secant_updates=yes, a string) would
            # be taken as it is, and a string is true.
            now = getattr(task_config, key)
            ok = (isinstance(value, bool) if isinstance(now, bool) else
                  isinstance(value, int | float) and not isinstance(value, bool)
                  if isinstance(now, int | float) else isinstance(value, type(now)))
            if not ok:
                raise UserError(f"--controller {key}={value!r}: expected a "
                                f"{type(now).__name__}, like the task's {now!r}")
            changes[key] = value
    try:   # the task's controller with every change must build
        dataclasses.replace(task_config, **changes)
    except (TypeError, ValueError) as exc:
        raise UserError(f"controller settings: {exc}") from None
    return args.name, env_id, kwargs, changes, options


def _checked_policy(spec: str | None, changes: dict) -> str | None:
    """`--policy` checked (it loads, and names a callable) and made absolute where it names
    a file, so that worker processes find it too; None for the baseline. The baseline's
    controller flags do not apply to another policy: given with one, they are refused."""
    if spec is None:
        return None
    if changes:
        raise UserError(f"--policy {spec!r} replaces the baseline controller, so its settings "
                        f"({', '.join(sorted(changes))}) do not apply: leave them out")
    where, sep, attr = spec.rpartition(":")
    if not sep or not where or not attr:
        raise UserError(f"--policy {spec!r}: expected MODULE:NAME or FILE.py:NAME")
    if where.endswith(".py"):
        path = Path(where).expanduser().resolve()
        if not path.is_file():
            raise UserError(f"--policy {spec!r}: no file {str(path)!r}")
        spec = f"{path}:{attr}"
    load_policy_factory(spec)
    return spec


@functools.cache
def load_policy_factory(spec: str):
    """The factory `spec` (MODULE:NAME or FILE.py:NAME) names, imported once per process; a
    file's folder goes on the import path first, as for a script, so that it may import its
    neighbours. UserError naming the spec when it does not import, has no such name, or
    names something that is not callable."""
    import importlib
    import importlib.util
    import sys

    where, _, attr = spec.rpartition(":")
    try:
        if where.endswith(".py"):
            folder = str(Path(where).parent)
            if folder not in sys.path:
                sys.path.insert(0, folder)
            mod_spec = importlib.util.spec_from_file_location(
                f"vlr_user_policy_{Path(where).stem}", where)
            module = importlib.util.module_from_spec(mod_spec)
            mod_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(where)
    except Exception as exc:   # noqa: BLE001 - the user's module: say what failed, in one line
        raise UserError(f"--policy {spec!r}: importing {where!r} failed "
                        f"({type(exc).__name__}: {exc})") from None
    factory = getattr(module, attr, None)
    if factory is None:
        raise UserError(f"--policy {spec!r}: {where!r} has no {attr!r}")
    if not callable(factory):
        raise UserError(f"--policy {spec!r}: {attr!r} is not callable (a "
                        f"{type(factory).__name__}); it must be a factory taking the "
                        "environment")
    return factory


def _checked_action(action, spec: str, step: int):
    """The policy's action as three finite floats (each tendon's change as a share of the
    env's max_step, in [-1, 1]); UserError naming the policy, the step and the value
    otherwise (not a reshape error from inside the environment)."""
    import numpy as np

    try:
        a = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise UserError(f"--policy {spec!r} returned {action!r} at step {step}: an action is "
                        "the three tendon changes as shares of max_step, finite numbers in "
                        "[-1, 1]")
    return a


def _check_out(out: Path) -> None:
    """The run takes minutes: a folder that cannot be written fails now, not after it."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        if not os.access(out, os.W_OK):
            raise PermissionError(f"{str(out)!r} is not writable")
    except OSError as exc:
        raise UserError(f"--out {str(out)!r}: {exc.strerror or exc}") from None


def run_seed(job: SeedRun) -> dict:
    """Reset (identification), run the baseline policy (or `job.policy`) to the episode's
    end, write `result.json` and `task.png` into `job.out`; return the result."""
    import gymnasium as gym

    from vlr.io import write_json_atomic

    if job.env_id not in gym.registry:   # a fresh worker process: register the tasks
        _tasks()[job.name].load()
    env = gym.make(job.env_id, **job.kwargs)
    job.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    bar = None
    try:
        obs, info = env.reset(seed=job.seed)
        if info["identification_failed"]:
            raise UserError(f"the identification in reset failed "
                            f"({info['identification_failed']}); try more --particles")
        t_identified = time.perf_counter()
        if job.policy is None:
            policy = env.unwrapped.baseline(**job.changes)   # the policy ships with the env
        else:
            policy = load_policy_factory(job.policy)(env.unwrapped)
            if not callable(policy):
                raise UserError(f"--policy {job.policy!r}: the factory returned "
                                f"{policy!r}, not a policy (a callable observation -> "
                                "action)")
        from vlr.logs import progress_bar

        bar = progress_bar(job.quiet, desc=job.name, unit="move")
        steps = 0
        while True:
            action = policy(obs)
            if job.policy is not None:
                action = _checked_action(action, job.policy, steps)
            obs, reward, terminated, truncated, info = env.step(action)
            steps += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(error=f"{-reward:.3f}")
            if terminated or truncated:
                break
        if bar is not None:
            bar.close()
        task = env.unwrapped
        result = {"task": job.name, "env": job.env_id, "backend": job.kwargs["backend"],
                  "seed": job.seed, "particles": task.particles,
                  "options": job.options,
                  "policy": job.policy or "baseline",
                  **({"controller": dataclasses.asdict(policy.config)}
                     if job.policy is None else {}),
                  **task.metrics(),
                  "identification": _identification(task.identification,
                                                    task.model_check),
                  "steps": steps,
                  "timing": {"identify_s": t_identified - t0,
                             "wall_s": time.perf_counter() - t0}}
        write_json_atomic(job.out / "result.json", result)   # the numbers, then the picture
        task.picture(job.out / "task.png")
    finally:
        env.close()
    return result


def _run_seeds(runs: list[SeedRun], out: Path, workers: int) -> int:
    """Each seed in turn (or `workers` at once), then the summary. A seed that fails is
    named in the summary and the exit status, and the others still run."""
    from vlr.io import write_text_atomic
    from vlr.task_report import summary_csv, summary_markdown

    results: list[dict] = []
    failed: dict[int, str] = {}

    def done(job: SeedRun, result: dict | None, exc: BaseException | None) -> None:
        if exc is not None:
            failed[job.seed] = f"{type(exc).__name__}: {exc}"
            print(f"{job.name} seed {job.seed}: FAILED ({failed[job.seed]})")
            return
        results.append(result)
        print(summary_line(result), flush=True)

    if workers <= 1:
        for job in runs:
            try:
                done(job, run_seed(job), None)
            except Exception as exc:   # noqa: BLE001 - one seed's failure is reported
                done(job, None, exc)
    else:
        from concurrent.futures import as_completed

        from vlr.executors import process_pool, stop_on_signals

        # A signal stops every seed at once, its workers with it (vlr.executors).
        with stop_on_signals(), process_pool(min(workers, len(runs))) as pool:
            futures = {pool.submit(run_seed, job): job for job in runs}
            for f in as_completed(futures):
                exc = f.exception()
                done(futures[f], None if exc else f.result(), exc)
    title = (f"vlr task {runs[0].name}, seeds {','.join(str(j.seed) for j in runs)}, "
             f"policy {runs[0].policy or 'baseline'}")
    write_text_atomic(out / "summary.md", summary_markdown(results, failed, title))
    if results:
        write_text_atomic(out / "summary.csv", summary_csv(results))
    print(summary_markdown(results, failed), end="")
    print(f"wrote {out / 'summary.md'}" + (f", {out / 'summary.csv'}" if results else ""))
    return 1 if failed else 0


def _identification(result, check: dict | None) -> dict:
    if result is None:
        return {"failed": True}
    out = {"iterations": int(result.iterations), "converged": bool(result.converged)}
    if check is not None:
        out["model_check"] = {k: v for k, v in check.items() if k != "surprise_by_iteration"}
    return out


def summary_line(result: dict) -> str:
    """One line of the headline figures."""
    e = result.get("errors", {})
    parts = [f"{k} {v:.3f}" for k, v in e.items() if isinstance(v, float)]
    for key in ("solved", "cups_stacked"):
        if key in result:
            parts.append(f"{key} {result[key]}")
    return f"{result['task']} seed {result['seed']}: " + ", ".join(parts)

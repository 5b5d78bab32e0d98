"""`vlr task handwriting|maze`: run the VLR baseline controller on a task environment.

Writes into --out: `result.json` (the task metrics under `errors`, plus settings and timing)
and `task.png` (the traced letters over the targets, the marble's path in the maze), both
atomically. Arguments, environment options and the output folder are checked before the
(minutes-long) run, so that a bad one ends in one line, not a traceback after the run.

The environments live in the `tasks` package, which plugs in through the `vlr.tasks`
entry-point group (pyproject.toml), as backends do: `vlr` never imports `tasks`, `sim` or
`hardware` itself.
"""

from __future__ import annotations

import argparse
import os
import time
from importlib.metadata import entry_points
from pathlib import Path

from vlr.errors import UserError

TASK_GROUP = "vlr.tasks"


def _tasks() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=TASK_GROUP)}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("task", help="run the VLR baseline controller on a manipulation task "
                       "(handwriting, marble maze, cup stacking)")
    p.add_argument("name", help="handwriting | maze | cups")
    p.add_argument("--backend", default="sim", help="sim | hardware")
    p.add_argument("--config", help="hardware backend: the hardware YAML file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--particles", type=int, default=5000,
                   help="particles of the identification in reset")
    p.add_argument("--identify-iterations", type=int, default=15)
    p.add_argument("--method", choices=("dls", "transpose"),
                   help="control step (default: the task's)")
    p.add_argument("--no-secant", action="store_true",
                   help="the VLR's Jacobian alone, without the camera-fitted correction")
    p.add_argument("--reversal-shrink", type=float, default=None, metavar="F",
                   help="scale a tendon's steps by F each time its step reverses sign "
                   "(vlr.controller.ControllerConfig.reversal_shrink; default: the task's)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an environment argument, e.g. word=SCI or letter_height=0.002")
    p.add_argument("--out", default=None, help="output folder (default runs/task-NAME)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _parse_options(items: list[str]) -> dict:
    import ast

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UserError(f"--option {item!r}: expected KEY=VALUE")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key] = value
    return out


def run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from vlr.io import write_json_atomic

    found = _tasks()
    if args.name not in found:
        raise UserError(f"unknown task {args.name!r}; available: {', '.join(sorted(found))}")
    if args.backend not in ("sim", "hardware"):
        raise UserError(f"--backend {args.backend!r}: use sim or hardware")
    if args.backend == "hardware" and not args.config:
        raise UserError("--backend hardware needs --config FILE")
    if args.particles < 10:
        raise UserError(f"--particles {args.particles} must be >= 10")
    if args.identify_iterations < 0:
        raise UserError(f"--identify-iterations {args.identify_iterations} must be >= 0")
    if args.seed < 0:
        raise UserError(f"--seed {args.seed} must be >= 0")
    options = _parse_options(args.option)
    env_id = found[args.name].load()      # importing the tasks package registers the envs
    if env_id not in gym.registry:
        raise UserError(f"task {args.name!r} ({env_id}) is not available in this version")
    kwargs = {"backend": args.backend, "particles": args.particles,
              "identify_iterations": args.identify_iterations, **options}
    if args.config:
        kwargs["hardware_config"] = args.config
    out = Path(args.out or f"runs/task-{args.name}")
    try:   # checks the arguments; the backend opens in reset
        env = gym.make(env_id, **kwargs)
    except (TypeError, ValueError) as exc:   # an unknown or bad environment argument
        raise UserError(f"--option: {exc}") from None
    try:   # the run takes minutes: a folder that cannot be written fails now, not after it
        out.mkdir(parents=True, exist_ok=True)
        if not os.access(out, os.W_OK):
            raise PermissionError(f"{str(out)!r} is not writable")
    except OSError as exc:
        env.close()
        raise UserError(f"--out {str(out)!r}: {exc.strerror or exc}") from None
    changes = {}
    if args.method:
        changes["method"] = args.method
    if args.no_secant:
        changes["secant"] = False
    if args.reversal_shrink is not None:
        if not 0 < args.reversal_shrink <= 1:
            raise UserError(f"--reversal-shrink {args.reversal_shrink} must be in (0, 1]")
        changes["reversal_shrink"] = args.reversal_shrink
    t0 = time.perf_counter()
    bar = None
    try:
        try:
            obs, info = env.reset(seed=args.seed)
        except FloatingPointError as exc:
            raise UserError(f"the identification in reset failed ({exc}); try more "
                            "--particles") from None
        t_identified = time.perf_counter()
        policy = env.unwrapped.baseline(**changes)   # the policy ships with the env
        if not args.quiet:
            from tqdm import tqdm

            bar = tqdm(desc=args.name, unit="move")
        steps = 0
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            steps += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(error=f"{-reward:.3f}")
            if terminated or truncated:
                break
        if bar is not None:
            bar.close()
        task = env.unwrapped
        result = {"task": args.name, "env": env_id, "backend": args.backend, "seed": args.seed,
                  "particles": args.particles, "options": options,
                  "controller": {"method": policy.config.method,
                                 "rows": policy.config.rows, "alpha": policy.config.alpha,
                                 "secant": policy.config.secant,
                                 "reversal_shrink": policy.config.reversal_shrink},
                  **task.metrics(),
                  "identification": _identification(task.identification),
                  "steps": steps,
                  "timing": {"identify_s": t_identified - t0,
                             "wall_s": time.perf_counter() - t0}}
        write_json_atomic(out / "result.json", result)   # the numbers first, then the picture
        task.picture(out / "task.png")
    finally:
        env.close()
    print(summary_line(result))
    print(f"wrote {out / 'result.json'}, {out / 'task.png'}")
    return 0


def _identification(result) -> dict:
    if result is None:
        return {"failed": True}
    return {"iterations": int(result.iterations), "converged": bool(result.converged)}


def summary_line(result: dict) -> str:
    """One line of the headline figures."""
    e = result.get("errors", {})
    parts = [f"{k} {v:.3f}" for k, v in e.items() if isinstance(v, float)]
    for key in ("solved", "cups_stacked"):
        if key in result:
            parts.append(f"{key} {result[key]}")
    return f"{result['task']} seed {result['seed']}: " + ", ".join(parts)

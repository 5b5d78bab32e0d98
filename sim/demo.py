"""`vlr demo`: the main job in miniature: the sim grasps an object, explores with random
tendon changes, and the particle filter self-identifies the joint angles and the pad contacts
from the commands and the camera's frames alone; the estimates, with their 95% intervals,
are printed beside the sim's truth (scoring only: the filter never sees it).

It runs the same identification as `vlr identify` (`vlr.run.run_identification` on the
settings tree of `vlr.settings.load_settings`), at the embedded defaults except for a budget
of seconds: a few thousand particles and a handful of actions.
"""

from __future__ import annotations

import argparse
import textwrap
import time
from pathlib import Path

import numpy as np

from vlr.errors import UserError

# Small enough for seconds on two cores (about 6 s here once `vlr.precompile` has compiled
# the kernels), large enough that the apple's proximal joints land within a degree or so of
# the truth.
DEMO_PARTICLES = 6000
DEMO_ACTIONS = 10

NEXT_COMMANDS = (
    ("vlr identify --object apple --out runs/apple",
     "the full identification: 60,000 particles, result files, plots"),
    ("vlr identify --object toy_block --true-hand modelo_thumb45 "
     "--unknown stiffness:thumb.distal", "a replaced spring identified too"),
    ("vlr task handwriting --seed 0 --out runs/task-handwriting",
     "the identified hand writes; maze and cups too"),
    ("vlr sweep --object apple wine_glass --seeds 0-1 --particles 6000 --out runs/sweep",
     "many trials, one table"),
    ("vlr bench", "one filter iteration timed at 6k / 60k / 600k particles"),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job in miniature: the sim grasps an object and "
                       "self-identifies it in seconds; estimates beside the truth",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--object", default="apple", help="object name or spec file (default apple)")
    p.add_argument("--hand", default="modelo", help="hand name or spec file (default modelo)")
    p.add_argument("--seed", type=int, default=0, help="seeds the sim, the filter and the "
                   "actions (default 0)")
    p.add_argument("--particles", type=int, default=DEMO_PARTICLES,
                   help=f"P (default {DEMO_PARTICLES})")
    p.add_argument("--actions", type=int, default=DEMO_ACTIONS,
                   help=f"exploratory actions after the grasp (default {DEMO_ACTIONS})")
    p.add_argument("--out", help="also write the result files here (as vlr identify does)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vlr.io import check_output_dir
    from vlr.run import run_identification
    from vlr.settings import load_settings

    if args.actions < 0:
        raise UserError(f"--actions {args.actions} must be >= 0")
    if args.out:
        check_output_dir(args.out)
    settings = load_settings({"world.backend": "sim", "world.object": args.object,
                              "world.hand": args.hand, "filter.particles": args.particles,
                              "loop.max_iterations": args.actions, "seed": args.seed})
    print(textwrap.fill(
        f"vlr demo: the sim grasps the {args.object} with the {args.hand} hand and makes up to "
        f"{args.actions} random tendon changes; a particle filter of {args.particles} "
        f"particles identifies the grasp from the commands and the palm camera's frames "
        f"alone (seed {args.seed}) ...", width=92), flush=True)
    t0 = time.perf_counter()
    ident = run_identification(settings)
    wall = time.perf_counter() - t0
    print()
    print(format_demo(ident, wall))
    if args.out:
        ident.write(args.out)
        print(f"\nwrote {Path(args.out) / 'result.json'}, {Path(args.out) / 'history.npz'}, "
              f"{Path(args.out) / 'convergence.png'}")
    print("\n" + format_next())
    return 0


def format_demo(ident, wall: float) -> str:
    """The demo's report: joints and contacts, estimate beside truth, then the errors."""
    result, summary, model = ident.result, ident.summary, ident.model
    head = (f"identified {summary['hand']} holding {summary['object']} after "
            f"{result.iterations} actions in {wall:.1f} s "
            f"(converged: {'yes' if result.converged else 'no'})")
    if result.grasp_lost_at is not None:
        head += (f"; stopped when the grasp was lost after action {result.grasp_lost_at} "
                 f"({result.grasp_message or 'no reason given'})")
    lines = [head, ""]
    truth = ident.truths[-1] if ident.truths else None
    lines += _joint_rows(result, model, truth)
    lines.append("")
    lines += _contact_rows(result, model, truth)
    err = summary.get("errors_median")
    if err is not None:
        contact = summary.get("errors", {}).get("contact_mm_mean", float("nan"))
        lines += ["", f"mean errors vs truth: proximal {err['proximal_deg_mean']:.2f} deg, "
                  f"distal {err['distal_deg_mean']:.2f} deg (medians), contact point "
                  f"{contact:.2f} mm;",
                  f"{summary['coverage']:.0%} of the true joints inside their 95% intervals"]
    if summary.get("model_check"):
        from vlr.commands.identify import format_model_check

        lines += [format_model_check(summary["model_check"])]
    return "\n".join(lines)


def _joint_rows(result, model, truth) -> list[str]:
    """Joint angles [deg]: truth, posterior median, 95% interval, whether it holds the truth."""
    true_theta = None if truth is None else np.degrees(np.asarray(truth.theta)).reshape(
        model.n_fingers, model.n_joints)
    rows = [f"{'joint':14s} {'truth':>8s} {'estimate':>9s} {'95% interval':>19s}  [deg]"]
    for i, f in enumerate(model.names):
        for k in range(model.n_joints):
            e = result.theta[f"{f}.{k}"]
            name = f"{f} {'proximal' if k == 0 else 'distal'}"
            t = true_theta[i, k] if true_theta is not None else None
            rows.append(_row(name, t, np.degrees(e.median), np.degrees(e.low),
                             np.degrees(e.high)))
    return rows


def _contact_rows(result, model, truth) -> list[str]:
    """Each pad contact as its distance from the distal joint (the distal link of the
    virtual linkage, Eq. 2) [mm], the one contact figure with a 95% interval."""
    true_len = None
    if truth is not None:
        from vlr.kinematics import contact_in_distal

        c = contact_in_distal(model, np.asarray(truth.normals)[None],
                              np.asarray(truth.segments)[None])[0]
        true_len = np.linalg.norm(c[:, 1:], axis=-1) * 1e3
    rows = [f"{'contact':14s} {'truth':>8s} {'estimate':>9s} {'95% interval':>19s}  "
            "[mm from the distal joint]"]
    for i, f in enumerate(model.names):
        e = result.distal_virtual_length[f]
        t = true_len[i] if true_len is not None else None
        rows.append(_row(f, t, 1e3 * e.median, 1e3 * e.low, 1e3 * e.high))
    return rows


def _row(name: str, truth: float | None, est: float, low: float, high: float) -> str:
    t = f"{truth:8.2f}" if truth is not None else f"{'-':>8s}"
    inside = "" if truth is None else ("  in" if low <= truth <= high else "  out")
    return f"{name:14s} {t} {est:9.2f} {low:8.2f} .. {high:7.2f}{inside}"


def format_next() -> str:
    """The commands to try next."""
    return "next:\n" + "\n".join(f"  {cmd}\n      {what}" for cmd, what in NEXT_COMMANDS)

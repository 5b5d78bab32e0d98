"""`vlr demo`: the headless sim demo (build the hand, grasp, explore, print ground truth)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from vlr.errors import UserError
from vlr.explore import ExplorationRange, random_action


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="headless sim demo: grasp an object, make random "
                       "exploratory tendon moves, print the ground truth")
    p.add_argument("--object", default="apple", help="object name or spec file (default apple)")
    p.add_argument("--hand", default="modelo", help="hand name or spec file (default modelo)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--actions", type=int, default=20)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sim.backend import SimHand
    if args.actions < 0:
        raise UserError(f"--actions {args.actions} must be >= 0")
    t0 = time.perf_counter()
    with SimHand(object=args.object, hand=args.hand, seed=args.seed) as hand:
        hand.grasp()
        print(f"Grasped {hand.object_spec.name} with {hand.spec.name} "
              f"({', '.join(hand.slots)}); seed {args.seed}.\n")
        explore = ExplorationRange.for_stiffness(hand.spec.tendon_stiffness)
        rng = np.random.default_rng(args.seed)
        center = hand.commands
        rows = [_row(0, np.zeros(len(hand.slots)), hand, "grasp")]
        for k in range(1, args.actions + 1):
            delta = random_action(rng, hand.commands, center, explore)
            report = hand.apply(delta)
            rows.append(_row(k, delta, hand, "held" if report.grasp_held else report.message))
        print(_table(rows, hand.slots))
        held = sum(r["status"] == "held" for r in rows[1:])
        print(f"\n{held}/{args.actions} actions kept the fingertip grasp; "
              f"{time.perf_counter() - t0:.1f} s.")
    return 0


def _row(k: int, delta: np.ndarray, hand, status: str) -> dict:
    t = hand.truth()
    return {"k": k, "delta": delta, "truth": t, "status": status}


def _table(rows: list[dict], slots: tuple[str, ...]) -> str:
    """Per action: tendon change, per-finger joint angles, tension, contact, and the POM."""
    head = ["#", "dl [mm] " + "/".join(s[0].upper() for s in slots)]
    for s in slots:
        head.append(f"{s}: prox/dist [deg]  T [N]  contact(D) y,z [mm]")
    head.append("POM x,y,z [mm]")
    lines = ["  ".join(head)]
    for r in rows:
        t = r["truth"]
        cells = [f"{r['k']:2d}", " ".join(f"{d * 1e3:+.2f}" for d in r["delta"])]
        for s in slots:
            f = t.fingers[s]
            deg = np.degrees(f.angles)
            c = f.contact_distal * 1e3
            cells.append(f"{deg[0]:6.2f}/{deg[1]:6.2f}  {f.tension:5.1f}  "
                         f"{c[1]:5.1f},{c[2]:5.1f} {f.contact_region[:3]}")
        p = t.pom_position * 1e3
        cells.append(f"{p[0]:6.2f},{p[1]:6.2f},{p[2]:6.2f}  {r['status']}")
        lines.append("  ".join(cells))
    return "\n".join(lines)

"""Check that a hand holds an object through a trial's exploration: the sim grasps it, then
makes random tendon actions as `vlr identify` does (`vlr.explore.random_action`, the
identification's defaults: 0.2-0.4 mm within 0.4 mm of the grasp command, 0.1 s moves), and
the palm camera must see the tag after the grasp. A spec file of a new object, finger or
hand is checked with it before it joins a sweep.

It also says where the grasp leaves the filter's model, which touches the object with each
finger's pad alone (docs/METHOD.md 8.2): the finger-states (a finger after an action) that
carry more than a tenth of their normal force off the pad, on a link (`OFF_PAD_SHARE`). A
grasp held that way is not refused, but its identification carries that model error.

Usage: python -m vlr.models.check_grasps [--actions 50] [--seeds 0-4] HAND:OBJECT [HAND:OBJECT ...]
(HAND and OBJECT: names in models/ or spec file paths). Prints one line per pair and exits 1
if any grasp failed, slipped or lost its tag.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

import numpy as np

from vlr.explore import ExplorationRange, random_action
from vlr.identify import LoopConfig

__all__ = ["HoldReport", "check_hold", "main", "OFF_PAD_SHARE"]

#: A finger-state's share of its normal force off the pad above which it is counted.
OFF_PAD_SHARE = 0.1


@dataclass(frozen=True)
class HoldReport:
    """One hand-object pair over its seeds."""

    hand: str
    obj: str
    seeds: int
    held: int                    # seeds whose grasp held through every action
    tag_seen: int                # seeds whose camera saw the tag after the grasp
    move_mm: float               # median POM travel over an action [mm]
    largest_mm: float            # the largest [mm]
    messages: tuple[str, ...]    # why a seed failed
    off_pad: int = 0             # finger-states with more than OFF_PAD_SHARE off the pad
    finger_states: int = 0       # finger-states touching the object

    @property
    def ok(self) -> bool:
        return self.held == self.seeds and self.tag_seen == self.seeds


def check_hold(hand: str, obj: str, seeds: list[int], actions: int = 50) -> HoldReport:
    """Grasp `obj` with `hand` and make `actions` random actions for each seed (the seed
    drives the actions as `vlr identify`'s does: `seed + 1`)."""
    from vlr.sim.backend import GraspError, SimHand, SimOptions, SimWorldOptions
    from vlr.sim.truth import contact_summary

    from vlr.perception.pipeline import observe

    loop = LoopConfig()
    lo, hi = (v * 1e-3 for v in loop.action_range_mm)
    explore = ExplorationRange(low=lo, high=hi, band=max(loop.action_band_mm * 1e-3, hi))
    held = seen = 0
    moves: list[float] = []
    messages: list[str] = []
    off_pad = states = 0
    for seed in seeds:
        with SimHand(obj, hand=hand, seed=seed,
                     options=SimOptions(ramp_time=SimWorldOptions.ramp_time)) as h:
            try:
                h.grasp()
            except GraspError as exc:
                messages.append(f"seed {seed}: {exc}")
                continue
            spec = h.object_spec
            frame = h.grab_frame()
            if frame is not None and observe(frame.image, h.calibration, spec.tag_id,
                                             spec.tag_size) is not None:
                seen += 1
            else:
                messages.append(f"seed {seed}: the tag was not seen after the grasp")
            rng = np.random.default_rng(seed + 1)
            center = h.commands
            ok = True
            for k in range(actions):
                before = h.truth().pom_position
                report = h.apply(random_action(rng, h.commands, center, explore))
                moves.append(float(np.linalg.norm(h.truth().pom_position - before)) * 1e3)
                for points in contact_summary(h).points.values():
                    total = sum(f for _, f, _ in points)
                    if total > 0:
                        states += 1
                        off = sum(f for _, f, region in points if region != "pad")
                        off_pad += off > OFF_PAD_SHARE * total
                if not report.grasp_held:
                    messages.append(f"seed {seed}: lost at action {k + 1}: {report.message}")
                    ok = False
                    break
            held += ok
    return HoldReport(hand, obj, len(seeds), held, seen,
                      float(np.median(moves)) if moves else 0.0,
                      max(moves, default=0.0), tuple(messages), off_pad, states)


def _seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    try:
        return list(range(int(a), int(b or a) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds {text!r}: expected N or N-M") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m vlr.models.check_grasps", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="+", metavar="HAND:OBJECT")
    ap.add_argument("--actions", type=int, default=50)
    ap.add_argument("--seeds", type=_seeds, default=list(range(5)))
    args = ap.parse_args(argv)
    if args.actions < 1:
        ap.error(f"--actions {args.actions}: must be at least 1")
    for p in args.pairs:
        if p.count(":") != 1:
            ap.error(f"pair {p!r}: expected HAND:OBJECT")
    from vlr.spec import load_hand, load_object

    pairs = [p.split(":") for p in args.pairs]
    for hand, obj in pairs:
        try:
            load_hand(hand), load_object(obj)
        except ValueError as exc:   # a spec file's error: one line
            ap.error(str(exc))
    failed = 0
    for hand, obj in pairs:
        r = check_hold(hand, obj, args.seeds, args.actions)
        failed += not r.ok
        print(f"{hand}:{obj}: held {r.held}/{r.seeds}, tag seen {r.tag_seen}/{r.seeds}, "
              f"POM move per action {r.move_mm:.2f} mm (median), {r.largest_mm:.2f} (largest)"
              + (f"; off the pads in {r.off_pad} of {r.finger_states} finger-states (a "
                 "contact the filter's model does not have)" if r.off_pad else "")
              + "".join(f"\n  {m}" for m in r.messages), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""`vlr tension-calibrate`: fit the hand's present-current-to-tension map against a load cell.

The real hand reports tendon tensions (for `vlr identify --set
filter.observation.sigma_tension_n=N`) through the config's `tension` section, T = newton_per_ma
x (direction x current - zero_ma) (`hardware.config.TensionConfig`). This command measures both
numbers: with the object grasped, it pulls every tendon through a list of commands about the
grasp; after each move settles it reads each finger motor's present current, and you type the
tension a load cell in each line shows. One slope for all motors (the same XM430 on the same
spool) and one zero per motor are fitted by least squares; the residuals' RMS is the reading's
error, the smallest `filter.observation.sigma_tension_n` to give the filter. The result is
printed as the config's `tension` section, and with `--out` written to a YAML file (atomically).

    vlr tension-calibrate --config my_hand.yaml --pulls-mm -0.2 0 0.2 0.4 0.6 --out tension.yaml
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from vlr.hardware.config import TensionConfig

from vlr.io import read_line

#: Tendon commands about the grasp at which the currents are read [mm] (default).
DEFAULT_PULLS_MM = (-0.2, 0.0, 0.2, 0.4, 0.6)


@dataclass(frozen=True)
class TensionSample:
    """One settled reading: the commands [m], each finger motor's present current signed by
    its pulling direction [mA], and the load cells' tensions [N], in hand slot order."""

    commands: np.ndarray
    currents_ma: np.ndarray
    tensions_n: np.ndarray


@dataclass(frozen=True)
class TensionFit:
    """The fitted map and how well it reads: `config` (the `tension` section), the residuals
    [N] per sample and finger, and their RMS per finger and over all."""

    config: TensionConfig
    residuals_n: np.ndarray
    rms_by_finger_n: np.ndarray
    rms_n: float


class CalibrationInputError(ValueError):
    """Readings that cannot give a map (too few, no spread, a slope that is not positive)."""


def fit_tension(samples: Sequence[TensionSample],
                names: Sequence[str] | None = None) -> TensionFit:
    """Least squares of T_ij = a I_ij - b_j over samples i and fingers j: one slope a
    (`newton_per_ma`), one offset per finger (`zero_ma` = b_j / a). `names` (the hand's
    fingers, in the readings' order) name a finger in an error; by default its index."""
    if len(samples) < 2:
        raise CalibrationInputError(f"{len(samples)} reading(s): the fit needs at least 2 per "
                                    "finger, at different tensions")
    current = np.array([s.currents_ma for s in samples], dtype=float)    # (S, N)
    tension = np.array([s.tensions_n for s in samples], dtype=float)
    if current.shape != tension.shape or current.ndim != 2:
        raise CalibrationInputError(f"currents {current.shape} and tensions {tension.shape} "
                                    "must be one per finger in every reading")
    if not (np.all(np.isfinite(current)) and np.all(np.isfinite(tension))):
        raise CalibrationInputError("a reading is not a finite number")
    n_samples, n_fingers = current.shape
    spread = np.ptp(tension, axis=0)
    if np.any(spread <= 0.0):
        bad = int(np.argmin(spread))
        who = names[bad] if names is not None and len(names) == n_fingers else bad
        raise CalibrationInputError(f"finger {who}'s tension is {tension[0, bad]:g} N in every "
                                    "reading: pull through commands that change it")
    design = np.zeros((n_samples * n_fingers, 1 + n_fingers))
    design[:, 0] = current.ravel()
    for j in range(n_fingers):
        design[j::n_fingers, 1 + j] = -1.0
    coef, *_ = np.linalg.lstsq(design, tension.ravel(), rcond=None)
    slope = float(coef[0])
    if not slope > 0.0:
        raise CalibrationInputError(f"fitted newton_per_ma {slope:.4g} N/mA is not positive: "
                                    "do the currents rise with the tension (the motors' "
                                    "direction in the config)?")
    residuals = (design @ coef - tension.ravel()).reshape(n_samples, n_fingers)
    config = TensionConfig(newton_per_ma=slope,
                           zero_ma=tuple(float(b / slope) for b in coef[1:]))
    return TensionFit(config=config, residuals_n=residuals,
                      rms_by_finger_n=np.sqrt(np.mean(residuals**2, axis=0)),
                      rms_n=float(np.sqrt(np.mean(residuals**2))))


#: The first pull is approached from this much lower [m], so that every reading comes
#: after a pull: a servo's gear friction makes its current depend on the way it last moved.
APPROACH = 1e-4


def collect_samples(hand, pulls: Sequence[float],
                    read_tensions: Callable[[np.ndarray], np.ndarray]) -> list[TensionSample]:
    """Grasp, then for each pull p [m], in rising order, move every tendon to grasp + p (in
    steps the hand allows; the first from `APPROACH` below), let it settle, read the present
    currents and ask `read_tensions(commands)` for the load cells' tensions [N]; back to the
    grasp command at the end."""
    hand.grasp()
    base = hand.commands
    pulls = sorted(pulls)
    _move_to(hand, base + pulls[0] - APPROACH)
    samples = []
    for p in pulls:
        _move_to(hand, base + p)
        currents = hand.pulling_currents
        samples.append(TensionSample(commands=hand.commands, currents_ma=currents,
                                     tensions_n=np.asarray(read_tensions(hand.commands),
                                                           dtype=float)))
    _move_to(hand, base)
    return samples


def _move_to(hand, target: np.ndarray) -> None:
    step = hand.config.motion.max_step
    while np.any(np.abs(target - hand.commands) > 1e-9):
        hand.apply(np.clip(target - hand.commands, -step, step))


def prompt_tensions(names: Sequence[str], ask: Callable[[str], str] | None = None
                    ) -> Callable[[np.ndarray], np.ndarray]:
    """A reader that asks the user for the load cells' tensions, one line per reading
    (`ask`: how to ask; default the terminal, `vlr.io.read_line`)."""

    def read(commands: np.ndarray) -> np.ndarray:
        mm = ", ".join(f"{u * 1e3:.2f}" for u in commands)
        while True:
            try:
                text = (ask or read_line)(f"commands [{mm}] mm; tensions on the "
                                          f"{', '.join(names)} lines [N]: ")
            except EOFError:
                raise CalibrationInputError("no load-cell reading given (input ended): "
                                            "the calibration needs one per pull") from None
            try:
                values = [float(v) for v in text.replace(",", " ").split()]
            except ValueError:
                values = []
            if len(values) == len(names) and all(math.isfinite(v) for v in values):
                return np.array(values)
            print(f"  give {len(names)} numbers, e.g. '12.1 9.8 10.4'", file=sys.stderr)

    return read


def tension_yaml(fit: TensionFit) -> str:
    """The config's `tension` section of a fit, with its measured error as a comment."""
    zeros = ", ".join(f"{z:.1f}" for z in fit.config.zero_ma)
    return (f"# vlr tension-calibrate: residual RMS {fit.rms_n:.3f} N "
            f"(per finger {', '.join(f'{r:.3f}' for r in fit.rms_by_finger_n)}); "
            f"give filter.observation.sigma_tension_n at least that\n"
            f"tension:\n  newton_per_ma: {fit.config.newton_per_ma:.5f}\n"
            f"  zero_ma: [{zeros}]\n")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `tension-calibrate` subcommand (entry point group vlr.commands)."""
    p = subparsers.add_parser("tension-calibrate",
                              help="fit the hand's present current to tendon tension map "
                                   "against a load cell", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", required=True, help="hardware config YAML")
    p.add_argument("--pulls-mm", type=float, nargs="+", default=list(DEFAULT_PULLS_MM),
                   help="tendon commands about the grasp at which to read [mm] (default: "
                        f"{' '.join(str(v) for v in DEFAULT_PULLS_MM)})")
    p.add_argument("--out", default=None, help="write the tension section to this YAML file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from vlr.hardware.backend import open_hand
    from vlr.hardware.config import load_config

    from vlr.errors import UserError
    from vlr.io import write_text_atomic

    if len(set(args.pulls_mm)) < 2:
        raise UserError(f"--pulls-mm {args.pulls_mm}: give at least two different pulls")
    if args.out and Path(args.out).is_dir():
        raise UserError(f"--out {args.out} is a folder: give the YAML file to write")
    # Checked before the hand opens: opening it already winds the motors (the taut probe).
    cfg = load_config(args.config)
    limit = cfg.motion.range
    base = np.asarray(cfg.grasp.commands)
    for p in args.pulls_mm:
        # (The lowest is approached from APPROACH below: that must be in range too.)
        u = base + p * 1e-3 - (APPROACH if p == min(args.pulls_mm) else 0.0)
        if np.any(u < limit[0]) or np.any(u > limit[1]):
            raise UserError(f"--pulls-mm {p}: commands {np.round(u * 1e3, 2).tolist()} mm "
                            f"leave motion.range {[v * 1e3 for v in limit]} mm")
    try:
        with open_hand(config=args.config) as hand:
            names = list(hand.spec.finger_names)
            samples = collect_samples(hand, [p * 1e-3 for p in args.pulls_mm],
                                      prompt_tensions(names))
        fit = fit_tension(samples, names)
    except CalibrationInputError as exc:
        raise UserError(str(exc)) from None
    print(f"{'commands [mm]':>24} " + " ".join(f"{n + ' [mA / N / fit]':>28}" for n in names))
    for s, r in zip(samples, fit.residuals_n, strict=True):
        cells = [f"{i:8.1f} / {t:6.2f} / {t + e:6.2f}"
                 for i, t, e in zip(s.currents_ma, s.tensions_n, r, strict=True)]
        print(f"{', '.join(f'{u * 1e3:.2f}' for u in s.commands):>24} "
              + " ".join(f"{c:>28}" for c in cells))
    text = tension_yaml(fit)
    print(text, end="")
    if args.out:
        write_text_atomic(args.out, text)
        print(f"wrote {args.out}: paste its tension section into {args.config}")
    return 0

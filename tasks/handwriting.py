"""Handwriting (docs/METHOD.md 6): the POM under the apple traces the waypoints of a word.

Each letter is traced in place, centred on the POM's pose after identification (the home
pose, from the camera), in the palm's x-y plane at the home height: position-only control
(the Jacobian's position rows). The target advances to the next waypoint once the camera
puts the POM within `tolerance` of it, or after `steps_per_waypoint` moves; the error
recorded for a waypoint is the distance between the POM and the waypoint when the target
leaves it (ground truth in the sim, the camera on hardware). The first waypoint of each
letter is the pen-down move from the previous letter's end and is not scored.

Letter size: the paper's letters are at most 12 mm on the real hand. In our sim the apple's
fingertip grasp moves the POM about 5 mm per mm of tendon, and releasing a side finger's
tendon by 0.4-0.6 mm from the grasp command loses its fingertip (`command_band`), so the
reachable patch is a few millimetres across: letters default to 2 mm (3 mm letters run into
the band's edge; docs/TASKS.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from vlr.tasks.base import HandTaskEnv, save_figure
from vlr.tasks.letters import letter_waypoints

from vlr.controller import ControllerConfig

__all__ = ["Waypoint", "HandwritingEnv"]


@dataclass(frozen=True)
class Waypoint:
    """A target of the word: letter index, position offset from home (2,) [m], scored."""

    letter: int
    offset: np.ndarray
    scored: bool


class HandwritingEnv(HandTaskEnv):
    """`vlr/Handwriting-v2` (sparse), `vlr/HandwritingDense-v2`: the POM writes `word`
    (default "SCIENCE") under the apple.

    Args (besides `HandTaskEnv`'s):
        word: letters to write (from `tasks.letters.STROKES`).
        letter_height: letter height [m] (width 0.7 of it).
        spacing: largest distance between consecutive waypoints of a letter [m].
        tolerance: the target advances when the camera error is below this [m].
        steps_per_waypoint: ... or after this many moves.
    """

    object_name = "apple"
    # Per-move secant updates on (moves of 0.05 mm and more): after a snap of the grasp the
    # camera's Jacobian from identification no longer holds (docs/TASKS.md). A tendon whose
    # step reverses takes half steps (stick-slip chatter; measured: 0.12 to 0.09 mm over five
    # seeds, every seed lower or equal).
    controller_config = ControllerConfig(rows="position", method="dls", secant=True,
                                         secant_updates=True, secant_min_step=0.05e-3,
                                         tolerance_pos=0.1e-3, reversal_shrink=0.5)

    def __init__(self, backend: str = "sim", render_mode: str | None = None, *,
                 word: str = "SCIENCE", letter_height: float = 2e-3, spacing: float = 1.5e-3,
                 tolerance: float = 0.1e-3, steps_per_waypoint: int = 12,
                 **kwargs: Any) -> None:
        super().__init__(backend, render_mode, **kwargs)
        if not isinstance(word, str) or not word:
            raise ValueError(f"word {word!r} must be a non-empty string")
        if letter_height <= 0 or spacing <= 0 or tolerance <= 0 or steps_per_waypoint < 1:
            raise ValueError("letter_height, spacing, tolerance and steps_per_waypoint must be "
                             "positive")
        self.word = word.upper()
        self.letter_height = float(letter_height)
        self.tolerance = float(tolerance)
        self.steps_per_waypoint = int(steps_per_waypoint)
        self.waypoints: list[Waypoint] = []
        for i, ch in enumerate(self.word):
            pts = letter_waypoints(ch, self.letter_height, spacing)
            self.waypoints += [Waypoint(i, p, k > 0) for k, p in enumerate(pts)]
        self.home: np.ndarray | None = None

    # ------------------------------------------------------------------ task hooks
    def _start_task(self) -> None:
        self.home = np.asarray(self.observation.position, dtype=float).copy()
        self.index = 0
        self.steps_here = 0
        self.records: list[dict[str, Any]] = []   # one per waypoint left
        self.path: list[dict[str, Any]] = []      # one per move: letter, camera and true POM
        self._log_path()

    def _target(self) -> tuple[np.ndarray, None]:
        i = min(self.index, len(self.waypoints) - 1)
        w = self.waypoints[i]
        return self.home + np.array([w.offset[0], w.offset[1], 0.0]), None

    def _camera_error(self) -> float:
        pos, _ = self._target()
        return float(np.linalg.norm(np.asarray(self.observation.position) - pos))

    def _task_step(self) -> bool:
        self.steps_here += 1
        self._log_path()
        err = self._camera_error()
        if err <= self.tolerance or self.steps_here >= self.steps_per_waypoint:
            self._leave_waypoint(err)
        return self.index >= len(self.waypoints)

    def _goal_reached(self, pos_mm, rot_deg):
        return pos_mm <= self.tolerance * 1e3

    def _leave_waypoint(self, camera_error: float) -> None:
        w = self.waypoints[self.index]
        pos, _ = self._target()
        rec = {"letter": w.letter, "scored": w.scored, "steps": self.steps_here,
               "camera_error_mm": camera_error * 1e3, "reached": camera_error <= self.tolerance}
        if self.has_truth:
            rec["true_error_mm"] = float(np.linalg.norm(self.hand.truth().pom_position - pos)
                                         * 1e3)
        self.records.append(rec)
        self.index += 1
        self.steps_here = 0

    def _log_path(self) -> None:
        w = self.waypoints[min(self.index, len(self.waypoints) - 1)]
        entry = {"letter": w.letter, "camera": np.asarray(self.observation.position) - self.home}
        if self.has_truth:
            entry["truth"] = self.hand.truth().pom_position - self.home
        self.path.append(entry)

    def _task_info(self) -> dict[str, Any]:
        return {"waypoint": int(self.index), "n_waypoints": len(self.waypoints),
                "position_error_mm": self._camera_error() * 1e3 if self.index < len(
                    self.waypoints) else 0.0}

    # ------------------------------------------------------------------ results
    def metrics(self) -> dict[str, Any]:
        """errors.position_mm_mean / _sd over the scored waypoints (ground truth in the sim,
        the camera on hardware), per letter, and the camera's own figures."""
        scored = [r for r in self.records if r["scored"]]
        key = "true_error_mm" if self.has_truth else "camera_error_mm"
        e = np.array([r[key] for r in scored]) if scored else np.array([np.nan])
        cam = np.array([r["camera_error_mm"] for r in scored]) if scored else np.array([np.nan])
        per_letter = {}
        for i, ch in enumerate(self.word):
            v = [r[key] for r in scored if r["letter"] == i]
            per_letter[f"{i}:{ch}"] = float(np.mean(v)) if v else float("nan")
        return {"errors": {"position_mm_mean": float(np.mean(e)),
                           "position_mm_sd": float(np.std(e)),
                           "position_mm_max": float(np.max(e)),
                           "source": "ground truth" if self.has_truth else "camera",
                           "camera_position_mm_mean": float(np.mean(cam)),
                           "per_letter_mm": per_letter},
                "waypoints": len(self.waypoints), "waypoints_scored": len(scored),
                "waypoints_reached": int(sum(r["reached"] for r in scored)),
                "word": self.word, "letter_height_mm": self.letter_height * 1e3,
                "moves": int(sum(r["steps"] for r in self.records)),
                "grasp_lost": self.grasp_lost, "filter_lost": self.filter_lost}

    def picture(self, path) -> None:
        """The traced letters (true POM path in the sim, camera path on hardware) over the
        target waypoints, one panel per letter."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        n = len(self.word)
        fig, axes = plt.subplots(1, n, figsize=(1.9 * n, 2.6), squeeze=False)
        key = "truth" if self.has_truth else "camera"
        h = self.letter_height * 1e3
        for i, ch in enumerate(self.word):
            ax = axes[0, i]
            tgt = np.array([w.offset for w in self.waypoints if w.letter == i]) * 1e3
            ax.plot(tgt[:, 0], tgt[:, 1], "-", color="0.8", lw=4, zorder=1)
            ax.plot(tgt[:, 0], tgt[:, 1], "o", color="0.5", ms=4, zorder=2,
                    label="waypoints")
            pts = np.array([p[key] for p in self.path if p["letter"] == i]) * 1e3
            if len(pts):
                ax.plot(pts[:, 0], pts[:, 1], "-", color="tab:red", lw=1.2, zorder=3,
                        label="POM")
            errs = [r.get("true_error_mm", r["camera_error_mm"]) for r in self.records
                    if r["letter"] == i and r["scored"]]
            ax.set_title(f"{ch}: {np.mean(errs):.2f} mm" if errs else ch, fontsize=9)
            m = 0.5 * h + 0.5
            ax.set_xlim(-m, m)
            ax.set_ylim(-m, m)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.set_ylabel("palm y [mm]", fontsize=8)
                ax.legend(fontsize=6, loc="lower left")
            ax.set_xlabel("palm x [mm]", fontsize=8)
        fig.suptitle(f"Handwriting '{self.word}', {h:.1f} mm letters ({key} POM path)",
                     fontsize=10)
        fig.tight_layout()
        save_figure(fig, path)


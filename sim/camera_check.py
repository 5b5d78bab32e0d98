"""`vlr camera`: rendered-frame perception accuracy against ground truth, and its timing.

Over a grasp and N random exploratory actions per object, each frame is rendered, the tag
detected (vlr.perception.observe), and the POM pose compared with the simulator's truth.
Reports the detection rate, the error distribution (median, 95th percentile, max) and the
render and detect time per frame (medians).
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.explore import ExplorationRange, random_action
from vlr.io import check_output_file
from vlr.perception import observe


@dataclass(frozen=True)
class CameraReport:
    frames: int
    detected: int
    position_mm: np.ndarray      # per detected frame
    orientation_deg: np.ndarray
    render_s: np.ndarray
    detect_s: np.ndarray

    @property
    def detection_rate(self) -> float:
        return self.detected / max(self.frames, 1)

    def summary(self) -> dict:
        def dist(a: np.ndarray) -> dict:
            if a.size == 0:
                return {"median": None, "p95": None, "max": None}
            return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
                    "max": float(a.max())}

        return {"frames": self.frames, "detection_rate": self.detection_rate,
                "position_mm": dist(self.position_mm),
                "orientation_deg": dist(self.orientation_deg),
                "render_ms_median": float(np.median(self.render_s) * 1e3),
                "detect_ms_median": float(np.median(self.detect_s) * 1e3)}


def camera_trial(obj: str, *, actions: int = 50, seed: int = 0, width: int = 640,
                 height: int = 480, effects=None, hand: str = "modelo") -> CameraReport:
    """Grasp `obj`, explore `actions` times, and score every rendered frame's detection."""
    from vlr.sim.backend import SimHand, SimOptions

    opts = SimOptions(width=width, height=height, effects=effects)
    pos, ori, rt, dtimes = [], [], [], []
    frames = 0
    with SimHand(obj, hand=hand, seed=seed, options=opts) as h:
        h.grasp()
        rng = np.random.default_rng(seed)
        explore = ExplorationRange.for_stiffness(h.spec.tendon_stiffness)
        center = h.commands
        spec = h.object_spec
        for k in range(actions + 1):
            if k:
                h.apply(random_action(rng, h.commands, center, explore))
            t0 = time.perf_counter()
            frame = h.grab_frame()
            t1 = time.perf_counter()
            frames += 1
            if frame is None:
                continue
            o = observe(frame.image, h.calibration, spec.tag_id, spec.tag_size)
            t2 = time.perf_counter()
            rt.append(t1 - t0)
            dtimes.append(t2 - t1)
            if o is None:
                continue
            truth = h.truth()
            pos.append(np.linalg.norm(o.position - truth.pom_position) * 1e3)
            rel = Rotation.from_matrix(o.rotation).inv() * Rotation.from_matrix(truth.pom_rotation)
            ori.append(np.degrees(rel.magnitude()))
    return CameraReport(frames=frames, detected=len(pos), position_mm=np.array(pos),
                        orientation_deg=np.array(ori), render_s=np.array(rt),
                        detect_s=np.array(dtimes))


def merge(reports: list[CameraReport]) -> CameraReport:
    return CameraReport(frames=sum(r.frames for r in reports),
                        detected=sum(r.detected for r in reports),
                        position_mm=np.concatenate([r.position_mm for r in reports]),
                        orientation_deg=np.concatenate([r.orientation_deg for r in reports]),
                        render_s=np.concatenate([r.render_s for r in reports]),
                        detect_s=np.concatenate([r.detect_s for r in reports]))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("camera", help="rendered-frame tag pose accuracy and render/detect "
                       "time per frame, against sim ground truth")
    p.add_argument("--objects", default="apple,wine_glass,toy_block,flat_screwdriver,"
                   "gelatin_box", help="comma-separated object names")
    p.add_argument("--actions", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--size", default="640x480", help="WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--noise", type=float, default=0.0, help="pixel noise std [grey levels]")
    p.add_argument("--json", help="write the summary to this file")
    p.set_defaults(func=run)


def _dist(d: dict, digits: int) -> str:
    if d["median"] is None:
        return "n/a (no detection)"
    return " ".join(f"{k} {d[k]:.{digits}f}" for k in ("median", "p95", "max"))


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UserError(f"--size {text!r} must look like 640x480") from None
    if w < 64 or h < 48:
        raise UserError(f"--size {text!r} is too small (at least 64x48)")
    return w, h


def run(args: argparse.Namespace) -> int:
    from vlr.spec import load_object

    width, height = _size(args.size)
    if args.actions < 0:
        raise UserError(f"--actions {args.actions} must be >= 0")
    if not math.isfinite(args.noise) or args.noise < 0:
        raise UserError(f"--noise {args.noise} must be a finite number >= 0")
    if args.json:
        check_output_file(args.json, "--json")
    objects = [o.strip() for o in args.objects.split(",") if o.strip()]
    if not objects:
        raise UserError(f"--objects {args.objects!r} names no object")
    for obj in objects:  # every name checked before minutes of rendering
        load_object(obj)
    effects = None
    if args.noise:
        from vlr.sim.camera_effects import CameraEffects

        effects = CameraEffects(noise_std=args.noise)
    reports = []
    for obj in objects:
        r = camera_trial(obj, actions=args.actions, seed=args.seed, width=width,
                         height=height, effects=effects)
        s = r.summary()
        print(f"{obj:18s} detected {r.detected}/{r.frames}  position mm "
              f"{_dist(s['position_mm'], 4)}  orientation deg {_dist(s['orientation_deg'], 3)}")
        reports.append(r)
    total = merge(reports).summary()
    print(f"all: detection {total['detection_rate']:.3f}; render {total['render_ms_median']:.1f}"
          f" ms, detect {total['detect_ms_median']:.1f} ms per frame (medians)")
    if args.json:
        from vlr.io import write_json_atomic

        write_json_atomic(args.json, {"size": [width, height], "noise": args.noise, **total})
    return 0

"""The MuJoCo backend: a simulated Model O that grasps, takes tendon commands and renders.

`SimHand` implements `vlr.hand.Hand` (tendon moves, settling, camera frames). Ground truth is
a separate, sim-only accessor (`SimHand.truth()`), used to score the estimator, never fed to it.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace

os.environ.setdefault("MUJOCO_GL", "egl")
# Mesa's llvmpipe renders on threads of its own, which a fork() does not copy: a process
# forked after a frame was rendered (gymnasium's AsyncVectorEnv, Stable-Baselines3's
# SubprocVecEnv) waits for them for ever. On the caller's thread it is fork-safe.
os.environ.setdefault("LP_NUM_THREADS", "0")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from vlr.sim.model import build_scene, compile_scene  # noqa: E402
from vlr.sim.truth import GroundTruth, read_truth  # noqa: E402

from vlr.hand import ApplyReport, CommandError, Frame, GraspError, check_delta  # noqa: E402
from vlr.spec import (  # noqa: E402
    FingerSpec,
    HandSpec,
    ObjectSpec,
    SpecError,
    load_hand,
    load_object,
    with_finger,
)

# A scene builder: (true hand, object, width=, height=, fovy_deg=) -> the MJCF root
# (`sim.model.build_scene` and its signature); task scenes (sim/scenes.py) pass their own.
SceneBuilder = Callable[..., object]

MAX_STEP = 0.002        # m per apply(): beyond this the ramp is no longer an exploratory action
COMMAND_RANGE = (-0.002, 0.040)   # m of spool pull from the open-hand zero


@dataclass(frozen=True)
class SimOptions:
    """Settings of a simulated trial (units in brackets).

    Attributes:
        width, height, fovy_deg: palm camera image size [px] and vertical field of view [deg].
        effects: camera degradations (sim.camera_effects.CameraEffects) or None for ideal.
        grasp_tension: target tendon tension at grasp [N] for (thumb, others): the thumb
            needs about twice the force of each opposing finger (docs/METHOD.md 8.2).
        close_speed: tendon pull rate while closing [m/s].
        ramp_time: duration over which an apply() ramps the command [s]. `vlr identify`'s
            sim trials take 0.1 s, the hardware backend's default move
            (`SimWorldOptions`); 50 ms here is the tasks' move.
        settle_time_max: bound on the quasi-static wait after a ramp [s].
        settle_qvel: joint speed below which the hand counts as settled [rad/s].
        settle_objvel: object speed below which it counts as settled [m/s].
        settle_window: consecutive quiet steps required.
        overrides: true physical parameters differing from the nominal spec, as
            {"<slot>.<joint>.stiffness": N m/rad} (the hand then has an unknown spring).
        tension_noise_n: standard deviation of each tendon tension the hand reports with a
            move (`ApplyReport.tensions`) [N]; 0 reports the series spring's exact tension.
            A servo's current reads through its gearbox; an XM430's current unit is about
            0.5 N of tension on a 10 mm spool (hardware/README.md). Drawn from a stream of
            its own, so the camera's degradations stay the same numbers.
    """

    width: int = 640
    height: int = 480
    fovy_deg: float = 60.0
    effects: object | None = None
    grasp_tension: tuple[float, float] = (22.0, 12.0)
    close_speed: float = 0.02
    ramp_time: float = 0.05
    settle_time_max: float = 2.0
    settle_qvel: float = 2e-3
    settle_objvel: float = 2e-4
    settle_window: int = 30
    overrides: dict[str, float] = field(default_factory=dict)
    tension_noise_n: float = 0.0

    def __post_init__(self) -> None:
        noise = self.tension_noise_n
        if (isinstance(noise, bool) or not isinstance(noise, (int, float))
                or not (np.isfinite(noise) and noise >= 0)):
            raise SpecError(f"SimOptions.tension_noise_n = {noise!r} must be a number >= 0 [N]")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 16 <= v <= 8192:
                raise SpecError(f"SimOptions.{name} = {v!r} must be an integer in [16, 8192] "
                                "[px]")
        if not (isinstance(self.fovy_deg, (int, float)) and 0 < self.fovy_deg < 180):
            raise SpecError(f"SimOptions.fovy_deg = {self.fovy_deg!r} must be in (0, 180)")


def apply_overrides(hand: HandSpec, overrides: dict[str, float]) -> HandSpec:
    """The true hand: `hand` with overridden parameters ("thumb.distal.stiffness": 0.05)."""
    for key, value in overrides.items():
        parts = key.split(".")
        if len(parts) != 3 or parts[1] not in ("proximal", "distal") or parts[2] != "stiffness":
            raise SpecError(f"override {key!r}: expected '<slot>.<proximal|distal>.stiffness'")
        if not np.isfinite(value) or value <= 0:
            raise SpecError(f"override {key!r} = {value!r} must be a positive number")
        finger: FingerSpec = hand.mount(parts[0]).finger
        k = list(finger.stiffness)
        k[0 if parts[1] == "proximal" else 1] = float(value)
        hand = with_finger(hand, parts[0], replace(finger, stiffness=tuple(k)))
    return hand


class SimHand:
    """A simulated Model O holding an object, seen by its palm camera.

    Deterministic for a seed: the seed drives only the camera degradations (noise, drops);
    physics is deterministic given the commands.

    Args:
        object, hand: specs (names, paths or loaded specs).
        seed: camera-degradation seed.
        options: sim settings.
        scene: the scene builder (default `sim.model.build_scene`); task scenes pass theirs
            (`sim.scenes`: the maze, the cups).
        held: the held object's name prefix in the scene: body `<held>/object`, free joint
            `<held>/object_free/`, helper weld `<held>_hold` ("object" in `build_scene`).
    """

    def __init__(self, object: str | ObjectSpec = "apple", hand: str | HandSpec = "modelo",
                 seed: int = 0, options: SimOptions | None = None,
                 scene: SceneBuilder | None = None, held: str = "object") -> None:
        self.options = options or SimOptions()
        self._nominal = hand if isinstance(hand, HandSpec) else load_hand(hand)
        self._object = object if isinstance(object, ObjectSpec) else load_object(object)
        self._true = apply_overrides(self._nominal, self.options.overrides)
        opts = self.options
        builder = scene or build_scene
        built = compile_scene(builder(self._true, self._object, width=opts.width,
                                      height=opts.height, fovy_deg=opts.fovy_deg))
        self.model = built.model
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(seed)
        self._tension_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1,)))
        self.seed = seed
        self._slots = self._true.finger_names
        m = self.model
        self._act = np.array([m.actuator(f"{s}_tendon_act").id for s in self._slots])
        self._tendon = np.array([m.tendon(f"{s}/tendon").id for s in self._slots])
        self._qadr = np.array([[m.joint(f"{s}/proximal").qposadr[0],
                                m.joint(f"{s}/distal").qposadr[0]] for s in self._slots])
        self._dadr = np.array([[m.joint(f"{s}/proximal").dofadr[0],
                                m.joint(f"{s}/distal").dofadr[0]] for s in self._slots])
        self._bind_object(held)
        # Tendon length at the open stops: the zero of the command u (vlr/spec.py).
        # The fixed tendon's length is -(r_p q_p + r_d q_d) (sim/model.py).
        self._l_open = np.array([-np.dot(m.finger.pulley_radii, m.finger.open_angles)
                                 for m in self._true.mounts])
        self._u = np.zeros(len(self._slots))
        # The offscreen renderers (EGL contexts) by view, made by `sim.camera`.
        self.renderers: dict[object, mujoco.Renderer] = {}
        self._calibration = None
        self._grasped = False
        self._reset_state()

    # ----------------------------------------------------------------- Hand interface
    @property
    def spec(self) -> HandSpec:
        return self._nominal

    @property
    def object_spec(self) -> ObjectSpec:
        return self._object

    @property
    def commands(self) -> np.ndarray:
        return self._u.copy()

    @property
    def calibration(self):
        if self._calibration is None:
            from vlr.sim.camera import calibration_of

            cal = calibration_of(self.model, self.data, self.options.width,
                                 self.options.height)
            distortion = getattr(self.options.effects, "distortion", None)
            if distortion is not None:  # the lens distorts; a calibration would measure it
                cal = replace(cal, dist=np.asarray(distortion, dtype=float))
            self._calibration = cal
        return self._calibration

    def grasp(self) -> ApplyReport:
        """Close the tendons on the held object until each reaches its grasp tension,
        release the helper weld, settle, and check the fingertip grasp (GraspError if none).
        """
        self._reset_state()
        target = self._close_to_tension()
        self._settle()
        self.data.eq_active[self._weld] = 0
        settled = self._settle()
        topped = self._top_up_tensions(target)
        settled = settled if topped is None else topped
        held, message = self._grasp_status()
        from vlr.sim.truth import contact_summary

        on_links = [s for s, pts in contact_summary(self).points.items()
                    if any(r == "proximal_link" for _, _, r in pts)]
        if held and on_links:
            held, message = False, f"the object rests on the proximal links of {on_links}"
        if not held:
            raise GraspError(f"{self._object.name}: no stable fingertip grasp after release: "
                             f"{message}")
        self._grasped = True
        return ApplyReport(commands=self.commands, settled=settled, grasp_held=True,
                           tensions=self.read_tensions())

    def _close_to_tension(self) -> np.ndarray:
        """Close each tendon at `close_speed` until its static tension reaches the grasp
        tension (thumb, others); GraspError if one never does. Returns the targets [N]."""
        opts = self.options
        target = np.array([opts.grasp_tension[0] if s == "thumb" else opts.grasp_tension[1]
                           for s in self._slots])
        dt = self.model.opt.timestep
        du = opts.close_speed * dt
        done = np.zeros(len(self._slots), bool)
        for _ in range(int(3.0 / dt)):
            done |= self.static_tensions() >= target
            if done.all():
                break
            self._u = np.where(done, self._u, self._u + du)
            if np.any(self._u > COMMAND_RANGE[1]):
                break
            self._set_ctrl(self._u)
            mujoco.mj_step(self.model, self.data)
        if not done.all():
            names = [s for s, d in zip(self._slots, done, strict=True) if not d]
            raise GraspError(f"{self._object.name}: fingers {names} never reached their grasp "
                             f"tension (commands {np.round(self._u * 1e3, 2).tolist()} mm)")
        return target

    def _top_up_tensions(self, target: np.ndarray) -> bool | None:
        """Fingers keep wrapping after the first touch, which relaxes the line: top the
        tensions up to `target`, as a current-controlled grasp on the real hand would.
        Returns whether the last settle was quiet (None if nothing was needed)."""
        settled = None
        for _ in range(6):
            short = target - self.static_tensions()
            if np.all(np.abs(short) < 0.05 * target):
                break
            step = np.clip(short / self._true.tendon_stiffness, -MAX_STEP, MAX_STEP)
            self._ramp_to(self._u + step)
            settled = self._settle()
        return settled

    def apply(self, delta: np.ndarray) -> ApplyReport:
        """Ramp the tendon commands by `delta` [m] (one per finger), then settle."""
        d = check_delta(delta, len(self._slots), MAX_STEP)
        target = self._u + d
        if np.any(target < COMMAND_RANGE[0]) or np.any(target > COMMAND_RANGE[1]):
            raise CommandError(f"tendon commands {np.round(target * 1e3, 3).tolist()} mm leave "
                               f"the range {[c * 1e3 for c in COMMAND_RANGE]} mm")
        self._ramp_to(target)
        settled = self._settle()
        held, message = self._grasp_status()
        return ApplyReport(commands=self.commands, settled=settled, grasp_held=held,
                           message=message, tensions=self.read_tensions())

    def grab_frame(self) -> Frame | None:
        """Render the palm camera (with the configured degradations), or None if dropped."""
        from vlr.sim.camera import render_palm_camera

        image = render_palm_camera(self)
        if image is None:
            return None
        return Frame(image=image, stamp=float(self.data.time))

    def close(self) -> None:
        """Free the offscreen renderers (EGL contexts) now, not at interpreter exit."""
        for r in self.renderers.values():
            r.close()
        self.renderers.clear()

    def __enter__(self) -> SimHand:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------------- sim-only
    def truth(self) -> GroundTruth:
        """Ground truth for scoring (joint angles, contacts, POM pose, tensions, parameters)."""
        return read_truth(self)

    def scoring_truth(self):
        """Ground truth in the estimator's terms, for scoring only (`scoring_truth`)."""
        return scoring_truth(self)

    def tensions(self) -> np.ndarray:
        """Tendon tensions [N] (positive = pulling)."""
        return -self.data.actuator_force[self._act].copy()

    @property
    def reads_tensions(self) -> bool:
        """Every move reports the tendon tensions (`static_tensions`)."""
        return True

    def read_tensions(self) -> np.ndarray:
        """The tendon tensions as the hand reads them with a move [N]: `static_tensions`
        with `SimOptions.tension_noise_n` of Gaussian noise (never below 0)."""
        exact = self.static_tensions()
        if self.options.tension_noise_n == 0:
            return exact
        noise = self._tension_rng.normal(0.0, self.options.tension_noise_n, exact.shape)
        return np.maximum(exact + noise, 0.0)

    def static_tensions(self) -> np.ndarray:
        """Tendon tensions of the series spring alone, k_t max(0, u - s) [N]: the servo's
        damping adds transients while moving; this is what a current reading settles to."""
        stretch = self._u - (self._l_open - self.data.ten_length[self._tendon])
        return self._true.tendon_stiffness * np.maximum(stretch, 0.0)

    @property
    def true_spec(self) -> HandSpec:
        return self._true

    @property
    def slots(self) -> tuple[str, ...]:
        return self._slots

    # ----------------------------------------------------------------- internals
    def _bind_object(self, held: str) -> None:
        """Point the hand at the held object `held` (name prefix, class docstring): the
        grasp, settling, grasp checks and ground truth follow it."""
        m = self.model
        self._obj_body = m.body(f"{held}/object").id
        self._obj_dof = m.joint(f"{held}/object_free/").dofadr[0]
        self._weld = m.equality(f"{held}_hold").id

    def _reset_state(self) -> None:
        mujoco.mj_resetData(self.model, self.data)
        for i, m in enumerate(self._true.mounts):
            self.data.qpos[self._qadr[i]] = m.finger.open_angles
        self.data.eq_active[self._weld] = 1
        self._u = np.zeros(len(self._slots))
        self._set_ctrl(self._u)
        mujoco.mj_forward(self.model, self.data)
        self._grasped = False

    def _set_ctrl(self, u: np.ndarray) -> None:
        self.data.ctrl[self._act] = self._l_open - u

    def _ramp_to(self, target: np.ndarray) -> None:
        """Move the commands linearly to `target` over `ramp_time`, as a servo profile."""
        start = self._u.copy()
        n = max(1, int(round(self.options.ramp_time / self.model.opt.timestep)))
        for k in range(1, n + 1):
            self._set_ctrl(start + (target - start) * (k / n))
            mujoco.mj_step(self.model, self.data)
        self._u = np.asarray(target, dtype=float).copy()

    def _settle(self) -> bool:
        """Step until quasi-static (joint and object speeds under thresholds for a window)."""
        opts = self.options
        quiet = 0
        dt = self.model.opt.timestep
        for _ in range(int(opts.settle_time_max / dt)):
            mujoco.mj_step(self.model, self.data)
            qv = np.abs(self.data.qvel[self._dadr]).max()
            ov = np.abs(self.data.qvel[self._obj_dof:self._obj_dof + 3]).max()
            quiet = quiet + 1 if (qv < opts.settle_qvel and ov < opts.settle_objvel) else 0
            if quiet >= opts.settle_window:
                return True
        return False

    def _grasp_status(self) -> tuple[bool, str]:
        from vlr.sim.truth import contact_summary

        summary = contact_summary(self)
        problems = []
        lost = [s for s in self._slots if not summary.fingertip_touch[s]]
        if lost:
            problems.append(f"fingertips {lost} lost contact")
        if summary.palm_touch:
            problems.append("object touches the palm")
        z = self.data.xpos[self._obj_body][2]
        if z < 0.0:
            problems.append(f"object dropped (POM at z = {z * 1e3:.1f} mm)")
        return (not problems), "; ".join(problems)


def open_hand(*, object: str = "apple", hand: str = "modelo", seed: int = 0,
              **options) -> SimHand:
    """The sim's hand factory (`vlr.backends.open_hand("sim", ...)`): `options` are
    `SimOptions` fields."""
    return SimHand(object=object, hand=hand, seed=seed, options=SimOptions(**options))


@dataclass(frozen=True)
class SimWorldOptions:
    """The sim's `world.options` for an identification (`vlr.backends`).

    Attributes:
        ramp_time: how long the sim takes to make each command change [s]
            (`SimOptions.ramp_time`): the hardware backend's default move, 5 goal positions
            20 ms apart (`hardware.config.TendonMotion`), so that the sim moves as the real
            hand is moved. At 50 ms the fingers, whose springs and damping settle in about
            as long, lag the command, and a contact can slide where the quasi-static model
            rolls (docs/DECISIONS.md).
        tension_noise_n: the standard deviation of the sim's tension readings [N]
            (`SimOptions.tension_noise_n`); 0: exact (the series spring's).
    """

    ramp_time: float = 0.1
    tension_noise_n: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.ramp_time) and 0 < self.ramp_time <= 2.0):
            raise ValueError(f"ramp_time {self.ramp_time} s must be in (0, 2]")
        if not (np.isfinite(self.tension_noise_n) and self.tension_noise_n >= 0):
            raise ValueError(f"tension_noise_n {self.tension_noise_n} N must be >= 0")


def _backend():
    from vlr.sim.pads import FILTER_SLIDE_FRICTION, TORSION_FRICTION

    from vlr.backends import Backend

    # What each default measured, and against what: docs/DECISIONS.md. Rolling contacts and
    # the surface contact prior are the dataclasses' own defaults (the real hand's too).
    return Backend(
        name="sim", options=SimWorldOptions, open_hand=open_hand,
        defaults={"filter.observation.sigma_pos_mm": 0.2,
                  "filter.observation.sigma_rot_deg": 0.4,
                  "filter.observation.sigma_turn_deg": 1.0,
                  "filter.motion.limit_stiffness": 17.0,
                  "filter.motion.friction": FILTER_SLIDE_FRICTION,
                  "filter.motion.spin_friction": TORSION_FRICTION,
                  "filter.guess_theta_deg": [-10.0, 15.0],
                  "filter.theta_spread_deg": 10.0})


BACKEND = _backend()


def scoring_truth(hand: SimHand):
    """The sim's truth in the estimator's terms (vlr.synthetic.Truth), for SCORING only:
    joint angles, pad contact angles and normals, segments (link lengths and the pad centre's
    z offset), stiffness, tendon stiffness, the POM pose, the object's mass and centre of
    mass as the simulator holds them (its body's inertial, in O) and its surface's curvature
    (`_true_curvature`)."""
    from vlr.kinematics import angles_from_normals
    from vlr.synthetic import Truth

    t = hand.truth()
    fingers = [hand.true_spec.mount(s).finger for s in hand.slots]
    theta = np.array([t.fingers[s].angles for s in hand.slots])
    normals = []
    for s, f in zip(hand.slots, fingers, strict=True):
        n = t.fingers[s].contact_distal - np.asarray(f.pad_center)
        norm = np.linalg.norm(n)
        normals.append(n / norm if np.isfinite(norm) and norm > 0 else np.full(3, np.nan))
    normals = np.array(normals)
    a, b = angles_from_normals(normals)
    return Truth(theta=theta, contact=np.stack([a, b], -1), normals=normals,
                 segments=np.array([[f.proximal_length, f.pad_center[2]] for f in fingers]),
                 stiffness=np.array([f.stiffness for f in fingers]),
                 tendon=np.full(len(fingers), hand.true_spec.tendon_stiffness),
                 position=t.pom_position, rotation=t.pom_rotation,
                 object_mass=float(hand.model.body_mass[hand._obj_body]),
                 object_com=np.array(hand.model.body_ipos[hand._obj_body], dtype=float),
                 surface_curvature=_true_curvature(hand.object_spec))


def _true_curvature(spec) -> float | None:
    """The curvature of the object the sim built at its contacts [1/m]: its primitive's
    (a box's faces flat, a sphere's or a cylinder's side 1 / radius), None for a mesh."""
    from vlr.surface import LocalSurface

    return None if spec.shape == "mesh" else LocalSurface.from_spec(spec).curvature

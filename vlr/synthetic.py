"""A model-consistent synthetic world for identification (docs/METHOD.md 8.1: "on data that
follows the model" the filter must converge).

The world IS the motion model (Eq. 6-9) with one particle, the truth, whose parameters may
differ from the nominal hand (a replaced spring, a replacement finger). It moves tendons like a
`Hand` (`grasp`, `apply`, `commands`) and returns observations directly: its POM pose plus
Gaussian noise (0.05 mm, 0.2 degree, the camera's accuracy in docs/METHOD.md 8.2), since the sim
camera is not part of this world. Ground truth is available through `truth()` for scoring
only.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from vlr.hand import GraspError
from vlr.kinematics import HandModel, normals_from_angles
from vlr.motion import (
    STATUS,
    MotionConfig,
    MotionModel,
    ObjectParams,
    ParticleState,
    rotvec_to_matrix,
)
from vlr.observation import PomObservation

__all__ = ["SyntheticConfig", "NominalGrasp", "Truth", "SyntheticWorld", "nominal_grasp",
           "random_action", "SyntheticOptions", "BACKEND"]


@dataclass(frozen=True)
class SyntheticConfig:
    """Settings of the synthetic world (units in brackets).

    Attributes:
        seed: seed of the world's own Generator (truth offsets and observation noise).
        noise_pos: observation noise std per axis [m].
        noise_rot: observation rotation noise std per axis [rad].
        grasp_theta: (K,) joint angles of the nominal grasp guess, every finger alike, or
            (N K,) finger by finger [rad]; the
            default (-0.3, 1.2) puts the Model O pads on a ~36 mm wide object.
        grasp_contact: (alpha, beta) of the nominal pad contact [rad].
        pom_depth: POM (tag) below the contacts' centroid [m].
        grasp_tension: tendon tension at the grasp command u_0 [N].
        theta_offset: std of the truth's joint-angle offset from the nominal guess [rad].
        contact_offset: std of the truth's contact-angle offset [rad].
        motion: motion-model settings of the world.
        snap_theta: a joint turning more than this in one action is a snap-through [rad]:
            the grasp sat at a fold of the energy and jumped to another branch (measured:
            NH1 seed 2's true grasp flipped its thumb 64 degrees on a 0.3 mm action, and did
            so even with the action split into 64 steps). A larger turn in one solve is
            followed in `motion.follow_substeps` steps before it is called a snap
            (`SyntheticWorld.apply`).
            The world reports a snap as a lost grasp, as a real hand's would be (docs/METHOD.md 7:
            the contacts must stay stable).
        probe_action: a drawn truth is probed with each tendon alone pulled and released by
            this much (2 N actions) [m]; one that snaps is a grasp at a fold, and the world
            grasps again (as an experimenter re-places an object that does not sit stably).
            0 turns the probe off. The default is the largest exploratory action. Probing
            every sign combination instead (2^N actions) flagged most NH1 draws (all of
            seed 1's first six), among them draws that then ran to convergence without a
            snap (NH1 seed 1's first draw: 49 actions).
        max_regrasps: draws before `grasp` gives up with a GraspError.
    """

    seed: int = 0
    noise_pos: float = 0.05e-3
    noise_rot: float = float(np.radians(0.2))
    grasp_theta: tuple[float, ...] = (-0.3, 1.2)
    grasp_contact: tuple[float, float] = (0.0, 0.0)
    pom_depth: float = 0.03
    grasp_tension: float = 5.0
    theta_offset: float = float(np.radians(1.5))
    contact_offset: float = 0.08
    motion: MotionConfig = MotionConfig(rolling=False)
    snap_theta: float = 0.25
    probe_action: float = 0.4e-3
    max_regrasps: int = 10

    def __post_init__(self) -> None:
        if not self.snap_theta > 0:
            raise ValueError(f"snap_theta {self.snap_theta!r} rad must be > 0")
        if not (np.isfinite(self.probe_action) and self.probe_action >= 0):
            raise ValueError(f"probe_action {self.probe_action!r} m must be >= 0 (0: off)")
        if not (isinstance(self.max_regrasps, int) and self.max_regrasps >= 0):
            raise ValueError(f"max_regrasps {self.max_regrasps!r} must be an integer >= 0")


@dataclass(frozen=True)
class NominalGrasp:
    """The user's nominal guess of the grasp: joint angles (N, K) [rad], contact angles (N, 2)
    [rad], and the grasp command u_0 (N,) [m]."""

    theta: np.ndarray
    contact: np.ndarray
    command: np.ndarray


@dataclass(frozen=True)
class Truth:
    """Ground truth of the synthetic world, for scoring only (never for the filter)."""

    theta: np.ndarray
    contact: np.ndarray
    normals: np.ndarray
    segments: np.ndarray
    stiffness: np.ndarray
    tendon: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    object_mass: float | None = None       # [kg]
    object_com: np.ndarray | None = None   # (3,) in O [m]
    # The local curvature 1 / rho of the object's surface at the contacts [1/m] (0: flat);
    # None where the world's shape does not say (a mesh).
    surface_curvature: float | None = None


def nominal_grasp(model: HandModel, obj: ObjectParams, config: SyntheticConfig) -> NominalGrasp:
    """Nominal grasp guess from the hand's nominal geometry (what a user can compute).

    Every finger starts at `config.grasp_theta` with its contact at `grasp_contact`, the POM
    `pom_depth` below the contacts; the command is u_0 = s(theta) + T / k_t (Eq. 7,
    compliant); the guess is the nominal model's equilibrium there (Eq. 9). Settling matters:
    the starting angles are far from equilibrium (the spring preload curls one finger and
    straightens the others), and a prior centred off-equilibrium loses most particles."""
    nf = model.n_fingers
    guess = np.asarray(config.grasp_theta, dtype=float)
    if guess.size not in (model.n_joints, nf * model.n_joints):
        raise ValueError(f"grasp_theta {np.round(guess, 4).tolist()}: give {model.n_joints} "
                         f"angles (every finger alike) or {nf * model.n_joints} [rad]")
    theta = (guess.reshape(nf, model.n_joints) if guess.size == nf * model.n_joints
             else np.tile(guess, (nf, 1)))
    contact = np.tile(np.asarray(config.grasp_contact, dtype=float), (nf, 1))
    u0 = model.tendon_takeup(theta) + config.grasp_tension / model.tendon_stiffness
    st = ParticleState.nominal(model, 1, theta, normals_from_angles(contact[:, 0], contact[:, 1]),
                               np.zeros(3), np.eye(3))
    st.pos[0] = st.contacts(model)[0].mean(axis=0) - np.array([0.0, 0.0, config.pom_depth])
    st.anchor_to_pose(model)
    # A settle has no history, so the pads' spin and sliding do not hold it (as the filter's
    # own settles: `vlr.filter`); with them, a heavy object's guess slides off its start.
    settle = replace(config.motion, max_iter=500, jump_theta=np.pi, jump_pos=1.0,
                     friction=None, spin_friction=0.0)
    status, _ = MotionModel(model, obj, config.motion).solve(st, u0, settle)
    if status[0] != 0:
        raise GraspError(
            f"the nominal grasp from {np.round(np.degrees(theta), 1).tolist()} deg does not "
            f"settle in the model ({STATUS.get(int(status[0]), status[0])}; the object "
            f"{obj.mass * 1e3:.0f} g): check the guess (filter.guess_theta_deg) and the object "
            f"believed (filter.object)")
    return NominalGrasp(st.theta[0].copy(), contact, u0)


def random_action(rng: np.random.Generator, n_fingers: int,
                  magnitude: tuple[float, float] = (0.2e-3, 0.4e-3)) -> np.ndarray:
    """Exploratory action (docs/METHOD.md 3, 8.1): per finger a tendon change of random sign and a
    magnitude uniform in `magnitude` [m] (0.2-0.4 mm: 4-8 N at 20 N/mm)."""
    mag = rng.uniform(magnitude[0], magnitude[1], n_fingers)
    return mag * rng.choice([-1.0, 1.0], n_fingers)


class SyntheticWorld:
    """The truth as one motion-model particle (module docstring).

    Args:
        true_model: the real hand (may differ from the nominal: `vlr.spec.with_finger`).
        obj: object mass and centre of mass.
        config: world settings.
        nominal_model: the hand the user believes in (for the nominal grasp guess); defaults
            to `true_model`.
        stiffness_overrides: {(finger, joint): k} true spring rates differing from the spec.
        tendon_stiffness: true series tendon stiffness [N/m] (default: the spec's).
    """

    def __init__(self, true_model: HandModel, obj: ObjectParams,
                 config: SyntheticConfig | None = None,
                 nominal_model: HandModel | None = None,
                 stiffness_overrides: dict[tuple[int, int], float] | None = None,
                 tendon_stiffness: float | None = None) -> None:
        self.config = config or SyntheticConfig()
        self.model = true_model
        self.nominal_model = nominal_model or true_model
        self.motion = MotionModel(true_model, obj, self.config.motion)
        self.rng = np.random.default_rng(self.config.seed)
        self._stiffness_overrides = dict(stiffness_overrides or {})
        self._tendon = tendon_stiffness
        self.nominal = nominal_grasp(self.nominal_model, obj, self.config)
        self.state: ParticleState | None = None
        self.regrasps = 0
        self._commands = np.zeros(true_model.n_fingers)

    @property
    def commands(self) -> np.ndarray:
        return self._commands.copy()

    def grasp(self) -> np.ndarray:
        """Place the truth near the nominal grasp (random offsets) and settle at u_0; a truth
        that snaps under a probe action is drawn again (`SyntheticConfig.probe_action`).

        Returns the commands u_0 (N,) [m]."""
        cfg = self.config
        for attempt in range(cfg.max_regrasps + 1):
            self.state = self._draw()
            self._commands = self.nominal.command.copy()
            fold = self._probe()
            if fold is None:
                self.regrasps = attempt
                return self.commands
        self.state = None
        raise GraspError(f"no stable synthetic grasp in {cfg.max_regrasps + 1} draws "
                         f"(seed {cfg.seed}); the last one: {fold}")

    def _draw(self) -> ParticleState:
        """One truth: the nominal guess plus random offsets, settled at u_0."""
        cfg, m, rng = self.config, self.model, self.rng
        nf = m.n_fingers
        theta = self.nominal.theta + rng.normal(0.0, cfg.theta_offset, self.nominal.theta.shape)
        ab = self.nominal.contact + rng.normal(0.0, cfg.contact_offset, (nf, 2))
        normals = normals_from_angles(ab[:, 0], ab[:, 1])
        st = ParticleState.nominal(m, 1, theta, normals, np.zeros(3), np.eye(3))
        for (i, k), v in self._stiffness_overrides.items():
            st.stiffness[:, i, k] = v
        if self._tendon is not None:
            st.tendon[:] = self._tendon
        c = st.contacts(m)[0]
        st.pos[0] = c.mean(axis=0) - np.array([0.0, 0.0, cfg.pom_depth])
        st.rot[0] = rotvec_to_matrix(rng.normal(0.0, 0.05, 3))
        st.anchor_to_pose(m)
        settle = replace(cfg.motion, max_iter=500, jump_theta=np.pi, jump_pos=1.0)
        status, _ = self.motion.solve(st, self.nominal.command, settle)
        if status[0] != 0:
            raise RuntimeError(f"synthetic grasp did not settle (status {status[0]})")
        return st

    def _probe(self) -> str | None:
        """Why the current truth is at a fold (the first probe action that snaps or loses
        it), or None if every probe action moves it continuously."""
        a = self.config.probe_action
        if a <= 0:
            return None
        n = self.model.n_fingers
        for probe in np.concatenate([a * np.eye(n), -a * np.eye(n)]):
            try:
                self._move(probe)
            except GraspError as e:
                return str(e)
        return None

    def apply(self, delta: np.ndarray) -> np.ndarray:
        """Change the tendon commands by `delta` (N,) [m] and settle; returns the commands.

        The action is first solved as a filter particle solves it (`MotionModel.solve` from
        the previous commands, a large move followed in `motion.follow_substeps` steps), so a
        particle started at the truth predicts the world's next pose exactly. Where that
        fails, it is solved without the jump limits, as follows. A joint turning more than
        `snap_theta` in one solve may still be a continuous move of a compliant grasp: the
        action is then followed in `motion.follow_substeps` equal steps, the filter's own test
        (`vlr.motion.MotionConfig.follow_substeps`), and a path whose every step stays under
        `snap_theta` is accepted (its end: the configuration continuity reaches). A path that
        still jumps is a snap-through."""
        if self.state is None:
            raise RuntimeError("grasp() first")
        self.state = self._move(delta)
        self._commands = self._commands + np.asarray(delta, dtype=float)
        return self.commands

    def _move(self, delta: np.ndarray) -> ParticleState:
        """The truth after the action `delta` (`apply`), or a GraspError; commits nothing."""
        delta = np.asarray(delta, dtype=float)
        trial = self.state.copy()
        status, _ = self.motion.solve(trial, self._commands + delta, u_from=self._commands)
        if status[0] == 0:  # each step held to the model's jump limits: no snap
            return trial
        trial, turn = self._follow(delta, 1)
        steps = self.config.motion.follow_substeps
        if turn.max() > self.config.snap_theta and steps > 1:
            trial, turn = self._follow(delta, steps)
        if turn.max() > self.config.snap_theta:
            i, k = np.unravel_index(np.argmax(turn), turn.shape)
            raise GraspError(
                f"the synthetic grasp snapped through: joint {self.model.names[i]}.{k} "
                f"turned {np.degrees(turn[i, k]):.0f} degrees on the action "
                f"{np.round(delta * 1e3, 3).tolist()} mm"
                f"{f', in {steps} steps as in one' if steps > 1 else ''} "
                f"(snap_theta {np.degrees(self.config.snap_theta):.0f} degrees)")
        return trial

    def _follow(self, delta: np.ndarray, steps: int) -> tuple[ParticleState, np.ndarray]:
        """The truth after the action made in `steps` equal solves, and the largest turn of
        each joint in any one of them (N, K) [rad]."""
        trial = self.state.copy()
        # The world is not limited to small moves: only a failed solve loses the grasp.
        cfg = replace(self.config.motion, max_iter=300, jump_theta=np.pi, jump_pos=1.0)
        turn = np.zeros_like(trial.theta[0])
        u = self._commands.copy()
        for j in range(1, steps + 1):
            target = self._commands + delta * (j / steps)
            before = trial.theta[0].copy()
            status, _ = self.motion.solve(trial, target, cfg, u_from=u)
            if status[0] != 0:
                raise GraspError(f"synthetic world lost the grasp (status {status[0]})")
            turn = np.maximum(turn, np.abs(trial.theta[0] - before))
            u = target
        return trial, turn

    def observe(self) -> PomObservation:
        """The POM pose plus Gaussian noise (docs/METHOD.md 8.2 camera accuracy)."""
        cfg = self.config
        pos = self.state.pos[0] + self.rng.normal(0.0, cfg.noise_pos, 3)
        rot = self.state.rot[0] @ rotvec_to_matrix(self.rng.normal(0.0, cfg.noise_rot, 3))
        return PomObservation(position=pos, rotation=rot)

    def truth(self) -> Truth:
        """Ground truth, for scoring only."""
        from vlr.kinematics import angles_from_normals

        st = self.state
        a, b = angles_from_normals(st.normals[0])
        return Truth(theta=st.theta[0].copy(), contact=np.stack([a, b], -1),
                     normals=st.normals[0].copy(), segments=st.segments[0].copy(),
                     stiffness=st.stiffness[0].copy(), tendon=st.tendon[0].copy(),
                     position=st.pos[0].copy(), rotation=st.rot[0].copy(),
                     object_mass=float(self.motion.obj.mass),
                     object_com=np.asarray(self.motion.obj.com, dtype=float).copy(),
                     surface_curvature=self.motion.obj.surface.curvature)


# --------------------------------------------------------------------------- the backend

# An unknown spring whose true rate is not given is drawn from this range of its nominal rate,
# with the trial's seed (a replaced spring is not the nominal one).
TRUE_STIFFNESS_RANGE = (0.5, 2.0)


@dataclass(frozen=True)
class SyntheticOptions:
    """The synthetic world's `world.options`.

    Attributes:
        true_stiffness: {"finger.joint": k [N m/rad]} the world's true spring rates; an
            unknown spring not named here is drawn from `TRUE_STIFFNESS_RANGE` times its
            nominal rate, with the seed.
    """

    true_stiffness: dict[str, float] = field(default_factory=dict)


def _true_stiffness(options: SyntheticOptions, unknowns, model: HandModel,
                    seed: int) -> dict[tuple[int, int], float]:
    """{(finger, joint): k} of the world: given values, else seeded draws."""
    from vlr.errors import UserError

    out: dict[tuple[int, int], float] = {}
    rng = np.random.default_rng([seed, 7919])
    for key, value in options.true_stiffness.items():
        f, _, j = key.partition(".")
        try:
            out[(model.finger_index(f), model.joint_index(j))] = float(value)
        except (KeyError, ValueError) as exc:
            raise UserError(f"world.options.true_stiffness {key!r}: {exc}") from None
    for spec in unknowns:
        kind, _, rest = spec.partition(":")
        if kind != "stiffness":
            continue
        f, _, j = rest.partition(".")
        key = (model.finger_index(f), model.joint_index(j))
        if key not in out:
            out[key] = float(model.stiffness[key] * rng.uniform(*TRUE_STIFFNESS_RANGE))
    return out


def _open_world(settings, options: SyntheticOptions, model, obj, nominal, hand_spec, obj_spec):
    """The synthetic world of `settings` (`vlr.backends.Backend.open_world`): the filter's
    own motion model with one particle, the truth, holding the object as its spec has it
    (whatever the filter believes), built with `world.true_hand` where given."""
    from vlr.errors import UserError
    from vlr.spec import load_hand
    from vlr.world import World

    if settings.filter.observation.sigma_tension_n:
        raise UserError("filter.observation.sigma_tension_n: the synthetic world does not "
                        "report tendon tensions: set it to 0")
    true_model = (HandModel.from_spec(load_hand(settings.world.true_hand))
                  if settings.world.true_hand else model)
    world_cfg = SyntheticConfig(seed=settings.seed, motion=settings.filter.motion)
    world = SyntheticWorld(true_model, ObjectParams.from_spec(obj_spec), world_cfg,
                           nominal_model=model,
                           stiffness_overrides=_true_stiffness(
                               options, settings.filter.unknowns, true_model, settings.seed))
    return World(world, world.observe, world.truth, model, obj, nominal, hand_spec, obj_spec)


def _backend():
    from vlr.backends import Backend

    # The world IS the filter's model, so only the camera's noise (0.05 mm, 0.2 degree)
    # counts, with a factor 2 margin; pinned contacts, whose filter is not overconfident
    # here; the generic grasp guess, at which the world grasps (docs/DECISIONS.md). The
    # model check's threshold goes with these scales: `vlr.model_check.threshold_by_rule`
    # over the known hand on the paper's four objects (median -1.01, the objects' and the
    # seeds' spreads 0.18 and 0.19, 40 trials at 6,000 particles; docs/RESULTS.md 10).
    return Backend(
        name="synthetic", options=SyntheticOptions, open_world=_open_world,
        defaults={"filter.motion.rolling": False,
                  "filter.observation.sigma_pos_mm": 0.1,
                  "filter.observation.sigma_rot_deg": 0.4,
                  "filter.contact_prior": "pad",
                  "filter.model_check.threshold": -0.23})


BACKEND = _backend()

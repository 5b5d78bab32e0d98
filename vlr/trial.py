"""One identification trial, defined by plain settings: what `vlr identify` and `vlr sweep` run.

A trial opens a world (the synthetic world of `vlr.synthetic`, or a backend registered under
`vlr.backends`: sim, hardware), runs the self-identification loop (`vlr.identify`) on the
nominal hand, scores it against ground truth where the world has one (scoring only) and
returns the `result.json` summary (`vlr.results.summarize`).

Settings are a frozen dataclass with a dict form, so that sweeps can write them next to each
result and rebuild the table from files alone.
"""

from __future__ import annotations

import functools
import math
import numbers
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from vlr.errors import UserError

__all__ = ["TrialSettings", "World", "TrialRun", "open_world", "identify_trial", "run_trial",
           "DEFAULT_SIGMA", "ROLLING_SIGMA", "ROLLING_TURN_SIGMA", "LIMIT_STIFFNESS_DEFAULT"]

# Likelihood scales (sigma_pos [mm], sigma_rot [deg]) per backend (vlr.observation). The
# synthetic world IS the model, so only its observation noise (0.05 mm, 0.2 deg) counts, with a
# factor 2 margin; the sim and the real hand add the model-world gap (METHOD.md 8.1).
DEFAULT_SIGMA = {"synthetic": (0.1, 0.4), "sim": (0.5, 1.0), "hardware": (0.5, 1.0)}

# With rolling contacts the sim's model-world gap is about half the pinned one (per action,
# docs/RESULTS.md 5), so its likelihood can be narrower. Measured in the sim (10,000
# particles, 30 actions, seeds 0-2, docs/sweeps/sim-sigma.yaml): over the apple, gelatin box
# and wine glass the proximal error halves from 0.73 to 0.35 degrees at 0.35 mm / 0.7 deg,
# with the same coverage (0.85); 0.25 / 0.5 loses coverage (0.80), 0.15 / 0.3 more (0.63).
# The real hand's gap is not measured, so it keeps the wider scales.
ROLLING_SIGMA = {"sim": (0.35, 0.7)}

# With the likelihood's turn term (vlr.observation, session 16) the base scales cover only
# what the rolling model gets wrong off the object's turn in its grip, and the turn has its
# own scale: (sigma_pos [mm], sigma_rot [deg], sigma_turn [deg]). The sim's default since
# session 17, when no scale is given and the hand has a thumb. Measured in the sim (60,000
# particles, 20 actions, 5 seeds, docs/sweeps/sim-60k-turn.yaml): the known hand's proximal
# error 0.68 against 0.90 degrees at ROLLING_SIGMA, coverage within 0.1 degree the same
# (0.93), the thumb's distal stiffness 0.0029 against 0.0038 N m/rad, NH2's and NH3's
# replaced links 0.89 and 1.41 against 2.87 and 2.99 mm; NH1 loses (proximal joints 2.43
# against 1.92 degrees) and the NH rows' coverage is lower (docs/RESULTS.md 5).
ROLLING_TURN_SIGMA = {"sim": (0.2, 0.4, 1.0)}

# The motion model's joint stops [N m/rad] per backend, when a trial does not say
# (`limit_stiffness`); other backends keep `vlr.motion.MotionConfig`'s 100. The sim's stops
# are MuJoCo soft limits whose stiffness scales with the link's inertia: about 18 N m/rad at
# the distal joints, where the grasps rest on them, and 120 at the proximal ones
# (models/README.md; docs/scripts/sim_stop_stiffness.py). Measured in the sim from rendered
# frames (60,000 particles, 20 actions, 5 seeds, all eight rows of the paper's table,
# docs/sweeps/sim-60k-surface-stops.yaml against sim-60k-surface.yaml, posterior median):
# strict coverage 0.97 against 0.88, NH2's link 2.96 against 3.22 mm, every NH joint figure
# and the spring (0.0035 against 0.0037) lower, the known hand 0.54 against 0.50 degrees;
# held out at 10,000 particles (seeds 5-9) the known hand 0.75 against 0.80 (docs/RESULTS.md
# 5, session 27). The real hand's stops are hard plastic of unknown stiffness: it keeps 100.
LIMIT_STIFFNESS_DEFAULT = {"sim": 17.0}

# How long the sim takes to make each command change [s] (`sim.backend.SimOptions.ramp_time`),
# when a trial does not say (`ramp_time`): the hardware backend's default move, 5 goal
# positions 20 ms apart (`hardware.config.MotionConfig`), so that the sim moves as the real
# hand is moved. At SimOptions' 50 ms the fingers, whose springs and damping settle in about
# as long, lag the command, and a contact can slide where the quasi-static model rolls: the
# gelatin box's seed-2 action 3 (`vlr gap --ramp-time`, docs/RESULTS.md 5, session 30).
RAMP_TIME_DEFAULT = {"sim": 0.1}

# Synthetic world: an unknown spring whose true rate is not given is drawn from this range of
# its nominal rate, with the trial's seed (a replaced spring is not the nominal one).
TRUE_STIFFNESS_RANGE = (0.5, 2.0)


# Rolling contacts by default, per backend (`TrialSettings.rolling` None). The sim at 10,000
# particles, 5 seeds: 1.06 degrees over the paper's four objects against 1.22 pinned, the toy
# block 0.59 against 6.08 (docs/RESULTS.md 5). The synthetic world keeps pinned contacts: a
# rolling filter there is overconfident (coverage 0.37-0.72). The real hand's contacts roll
# as the sim's do; other backends default to rolling too.
ROLLING_DEFAULT = {"synthetic": False, "sim": True, "hardware": True}

# What the filter draws the pad contacts about when a trial does not say (`contact_prior`).
# The pad's inner face is 33 degrees from the sim's contacts on the apple and the wine glass
# (out of the side fingers' planes) and 89 on the screwdriver's wrapped thumb, where the
# prior's 8.6-degree spread does not reach; "surface" draws them where each particle's pads
# would touch an object of the local surface's shape (from the sim's true joint angles: its
# true contacts within 2 degrees). Measured in the sim from rendered frames (10,000
# particles, 20 actions, seeds 0-2, docs/sweeps/sim-surface-prior.yaml against the random
# cases of sim-active-turn.yaml): over the apple, wine glass, gelatin box and screwdriver the
# proximal error 0.50 against 0.94 degrees, the contacts 1.1 against 3.9 mm, coverage within
# 0.1 degree 1.00 against 0.88 (docs/RESULTS.md 5, "The contact prior"). The real hand's
# objects are as known as the sim's; the synthetic world's truth is drawn about the pad's
# inner face, which is right there.
CONTACT_PRIOR_DEFAULT = {"synthetic": "pad", "sim": "surface", "hardware": "surface"}

# The grasp guess (joint angles [deg], every finger alike) and the prior's spread [deg] when
# a trial gives none, per backend. The synthetic world grasps at the generic guess
# (`vlr.synthetic.SyntheticConfig.grasp_theta`, None here), so that guess is right there. The
# sim's fingertip grasps are not wrapped: from the generic guess (-17, 69) `vlr identify
# --backend sim --object apple` (3000 particles, 10 actions, seed 0) ended 11.7 / 13.5
# degrees off with coverage 0.17; from (-10, 15) +- 10, the guess of every sim row of
# docs/RESULTS.md, 0.97 / 1.83 with 0.83. The real hand keeps the generic guess until one is
# measured there: give yours with --nominal-theta-deg.
GUESS_DEFAULT: dict[str, tuple[tuple[float, ...] | None, float]] = {
    "synthetic": (None, 3.0), "sim": ((-10.0, 15.0), 10.0), "hardware": (None, 3.0)}


@dataclass(frozen=True)
class TrialSettings:
    """Everything that defines one trial (units in brackets).

    Attributes:
        backend: "synthetic", "sim" or "hardware" (any registered backend).
        object: object name or YAML path.
        hand: the hand the user believes in (nominal).
        true_hand: synthetic world or sim: the hand the world is built with when it differs
            from `hand` (e.g. nh1: replaced fingers the filter does not know); the filter
            keeps `hand` and identifies the `unknowns`. Not for hardware: the real hand is
            what it is.
        particles: P.
        seed: seeds the world, the filter and the actions.
        unknowns: extra unknowns ("stiffness:thumb.distal", "length:left.proximal", ...).
        true_stiffness: synthetic only: {"finger.joint": k [N m/rad]} true spring rates.
        max_iterations: action budget; min_iterations: no convergence stop before this.
        sigma_pos_mm, sigma_rot_deg: likelihood scales; None takes the backend's default
            (`sigma`): with rolling contacts `ROLLING_TURN_SIGMA`'s base when the turn term
            is in effect, else `ROLLING_SIGMA`, where the backend has them; else
            `DEFAULT_SIGMA`.
        sigma_motion: the likelihood's model error as a fraction of each particle's
            predicted motion over the action (`vlr.observation`, kappa); 0 = fixed scales.
        sigma_turn_deg: the likelihood's model error of the object's turn in its grip about
            the grasp's axis, thumb to the other contacts [deg] (`vlr.observation`, s); 0 =
            no turn term. Needs a hand with a "thumb" finger. None: the backend's default
            (`turn_deg`): `ROLLING_TURN_SIGMA`'s turn with rolling contacts when neither base
            scale nor sigma_motion is given and the hand has a thumb, else none; so scales
            given alone keep the meaning they had before the turn term.
        likelihood_dof: nu, the pose error's Student-t degrees of freedom
            (`vlr.observation.ObservationModel.dof`, "Heavy tails"); 0 = Gaussian.
        sigma_tension_n: weigh the hand's tendon tensions in the likelihood with this scale
            [N] (`vlr.observation`, s_T); 0 = not weighed. The sim reports them; the real
            hand when its config has a `tension` calibration (hardware/README.md).
        tension_noise_n: sim only: the standard deviation of the sim's tension readings [N]
            (`sim.backend.SimOptions.tension_noise_n`); 0: exact (the series spring's).
        nominal_theta_deg: the user's guess of the grasp's joint angles [deg] (what one sees
            looking at the hand): K angles for every finger alike, or N x K, finger by
            finger in the hand's order (a thumb that wraps a thin object); None: the
            backend's default (`GUESS_DEFAULT`: the sim (-10, 15); the synthetic world and
            the real hand the generic guess, vlr.synthetic.SyntheticConfig.grasp_theta).
            The prior is the nominal hand's equilibrium from there, in the filter's own
            motion model (vlr.synthetic.nominal_grasp).
        prior_spread_deg: prior std of the joint angles about the nominal grasp [deg];
            None: the backend's default (`GUESS_DEFAULT`: the sim 10, the others 3).
        contact_spread_deg: prior std of each pad contact's two angles (alpha in the
            finger's plane, beta out of it) about the pad's inner face [deg]
            (`vlr.filter.FilterConfig.contact_spread`); None: the filter's default (8.6).
        contact_prior: what the contact angles are drawn about: "pad" (the pad's inner
            face) or "surface" (where each particle's pads would touch an object of the
            local surface's shape, `vlr.filter.FilterConfig.contact_prior`); None: the
            backend's default (`CONTACT_PRIOR_DEFAULT`).
        rolling: rolling contacts in the filter's motion model (vlr.surface; measured by
            `vlr gap`, docs/RESULTS.md), and in the synthetic world's, which is that model.
            None: the backend's default (`ROLLING_DEFAULT`): rolling on the sim and the real
            hand, where it was measured better (docs/RESULTS.md 5, "Rolling in the sim"),
            pinned on the synthetic world, where a rolling filter is still overconfident.
        slide_friction, spin_friction: with rolling, the pads' sliding friction coefficient
            (None: contacts never slide) and torsional friction coefficient [m] (0: free
            spin) in the filter's motion model (`vlr.motion.MotionConfig`). They are the
            pads' material, known like their radius: the sim's are 1.0 and 0.001
            (`sim.pads`).
        spin_memory: with spin_friction, each particle's pads keep their spin torques from
            one action to the next (`vlr.motion.MotionConfig.spin_memory`).
        exact_cylinder: with rolling on a cylinder, the pads are held to its axis, not to a
            sphere of its radius (`vlr.motion.MotionConfig.exact_cylinder`).
        exploration: "random" actions (the paper) or "active" (vlr.active).
        active_model_error: with active exploration, the model's expected error as a
            fraction of each candidate's predicted motion (`ActiveExploration.model_error`).
        active_criterion: with active exploration, what makes a candidate informative:
            "spread" or "variance" (`vlr.active`).
        active_min_force_n: with active exploration, pass over a candidate after which a
            finger's predicted normal force falls under this [N]
            (`ActiveExploration.min_normal_force`); 0: no screen. Needs rolling.
        action_range_mm: (low, high) magnitude of each tendon's exploratory change [mm]
            (`vlr.explore`); None: the identification's 0.2-0.4 mm (4-8 N at 20 N/mm).
        action_band_mm: commands stay within this of the grasp command [mm]; None: the
            identification's 0.4 mm (and at least the range's high end).
        contact_stiffness: the motion model's contact penalty k_c [N/m]
            (`vlr.motion.MotionConfig`); None: its default.
        limit_stiffness: the motion model's joint stops [N m/rad]
            (`vlr.motion.MotionConfig`); None: the backend's default
            (`LIMIT_STIFFNESS_DEFAULT`, the sim's 17), else the model's 100.
        ramp_time: sim only: how long the sim takes to make each command change [s]
            (`sim.backend.SimOptions.ramp_time`); None: `RAMP_TIME_DEFAULT` (0.1 s, the
            hardware backend's default move).
        cone_return: with rolling, the sliding friction coefficient of the return map
            between solves (`vlr.motion.MotionConfig.cone_return`); None: off. Not with
            slide_friction or spin_friction (the friction in the energy already slides).
        ess_fraction: the share of the particles tempering keeps as the effective sample
            size of an update (`vlr.filter.FilterConfig.ess_fraction`); None: its default.
        jitter_h: the filter's Liu-West bandwidth (`vlr.filter.FilterConfig.jitter_h`);
            None: its default.
        jitter_kernel: "log-springs" (the default), "log-scales", "gaussian", "copula",
            "copula-joints", "copula-scales" or "copula-joints-scales", the space of the
            filter's Liu-West draw (`vlr.filter.FilterConfig.jitter_kernel`).
        synthetic_solve: synthetic only: how the world solves an action
            (`vlr.synthetic.SyntheticConfig.solve`): "model" (the default since session 42,
            as a filter particle does) or "loose" (before: 300 Newton iterations without
            jump limits, which can end elsewhere than the particle's path).
        priors: {unknown spec: [low, high]} the uniform prior of an unknown in its SI unit
            (e.g. {"stiffness:thumb.distal": [0.01, 0.08]} N m/rad); an unknown not named
            keeps its default (`vlr.filter.parse_unknown`). Each must be among `unknowns`.
        prior_shape: "uniform" or "log-uniform": how a spring's, the tendon's and the
            object's mass's priors are drawn (`vlr.filter.FilterConfig.prior_shape`).
        unknown_warmup: updates during which the unknowns are drawn afresh from their prior
            (`vlr.filter.FilterConfig.unknown_warmup`); 0: off.
        unknown_discount: the discount factor of the unknowns' artificial evolution, in
            (0, 1] (`vlr.filter.FilterConfig.unknown_discount`); 1: off.
        noise_prior: [low, high] of the "noise" unknown's uniform prior (a factor on the
            likelihood's pose scales); None: `vlr.filter.NOISE_PRIOR`. Needs "noise" among
            the unknowns.
        link_scaling: a link of unknown length weighs as the nominal link scaled to its
            length (`vlr.motion.MotionConfig.link_scaling`); False: the nominal weights.
        object_mass: the object's mass the filter believes [kg]; None: its spec's. The
            world keeps the spec's: a wrong guess to measure, and with the "mass" unknown
            the centre of its prior (`vlr.filter.MASS_PRIOR_FACTORS`).
        object_com: the object's centre of mass the filter believes, [x, y, z] in O [m];
            None: its spec's. The world keeps the spec's; with a "com:AXIS" unknown the
            believed coordinate is the centre of its prior (`vlr.filter.COM_PRIOR_HALF_WIDTH`).
        object_curvature: the local curvature of the object's surface at the contacts the
            filter believes [1/m] (0: flat; `vlr.surface.LocalSurface.with_curvature`);
            None: its spec's shape's. The world keeps the spec's; with a "curvature" unknown
            the prior runs from 0 to the larger of twice it and
            `vlr.filter.CURVATURE_PRIOR_TOP`.
        anneal_stages: the filter's most weighting stages per observation
            (`vlr.filter.FilterConfig.anneal_stages`); 1: a tempered likelihood's rest is
            dropped.
        config: hardware only: the hardware YAML file.
    """

    backend: str = "sim"
    object: str = "apple"
    hand: str = "modelo"
    true_hand: str | None = None
    particles: int = 60_000
    seed: int = 0
    unknowns: tuple[str, ...] = ()
    true_stiffness: dict[str, float] = field(default_factory=dict)
    max_iterations: int = 40
    min_iterations: int = 0
    sigma_pos_mm: float | None = None
    sigma_rot_deg: float | None = None
    sigma_motion: float = 0.0
    sigma_turn_deg: float | None = None
    likelihood_dof: float = 0.0
    sigma_tension_n: float = 0.0
    tension_noise_n: float = 0.0
    nominal_theta_deg: tuple[float, ...] | None = None
    prior_spread_deg: float | None = None
    contact_spread_deg: float | None = None
    contact_prior: str | None = None
    rolling: bool | None = None
    slide_friction: float | None = None
    spin_friction: float = 0.0
    spin_memory: bool = False
    exact_cylinder: bool = False
    exploration: str = "random"
    active_model_error: float = 0.0
    active_criterion: str = "spread"
    active_min_force_n: float = 0.0
    action_range_mm: tuple[float, float] | None = None
    action_band_mm: float | None = None
    anneal_stages: int = 1
    contact_stiffness: float | None = None
    limit_stiffness: float | None = None
    ramp_time: float | None = None
    cone_return: float | None = None
    link_scaling: bool = False
    jitter_h: float | None = None
    ess_fraction: float | None = None
    jitter_kernel: str = "log-springs"
    synthetic_solve: str = "model"
    noise_prior: tuple[float, float] | None = None
    priors: dict[str, tuple[float, float]] = field(default_factory=dict)
    prior_shape: str = "uniform"
    unknown_warmup: int = 0
    unknown_discount: float = 1.0
    object_mass: float | None = None
    object_com: tuple[float, float, float] | None = None
    object_curvature: float | None = None
    config: str | None = None

    def __post_init__(self) -> None:
        self._check_types()
        if self.seed < 0:
            raise UserError(f"seed {self.seed} must be >= 0")
        if self.particles < 10:
            raise UserError(f"particles {self.particles} must be >= 10")
        if self.max_iterations < 1:
            raise UserError(f"max_iterations {self.max_iterations} must be >= 1")
        if not 1 <= self.anneal_stages <= 50:
            raise UserError(f"anneal_stages {self.anneal_stages} must be in [1, 50]")
        if not 0 <= self.min_iterations <= self.max_iterations:
            raise UserError(f"min_iterations {self.min_iterations} must be in "
                            f"[0, max_iterations={self.max_iterations}]")
        for name in ("sigma_pos_mm", "sigma_rot_deg"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise UserError(f"{name} {v} must be > 0")
        if not self.sigma_motion >= 0:
            raise UserError(f"sigma_motion {self.sigma_motion} must be >= 0")
        if self.sigma_turn_deg is not None and not (math.isfinite(self.sigma_turn_deg)
                                                    and self.sigma_turn_deg >= 0):
            raise UserError(f"sigma_turn_deg {self.sigma_turn_deg} must be >= 0")
        if not (math.isfinite(self.likelihood_dof) and self.likelihood_dof >= 0):
            raise UserError(f"likelihood_dof {self.likelihood_dof} must be >= 0 "
                            "(0: a Gaussian likelihood)")
        if not (math.isfinite(self.sigma_tension_n) and self.sigma_tension_n >= 0):
            raise UserError(f"sigma_tension_n {self.sigma_tension_n} must be >= 0")
        if self.sigma_tension_n and self.backend == "synthetic":
            raise UserError("sigma_tension_n: the synthetic world does not report tendon "
                            "tensions: set it to 0")
        if not (math.isfinite(self.tension_noise_n) and self.tension_noise_n >= 0):
            raise UserError(f"tension_noise_n {self.tension_noise_n} must be >= 0")
        if self.tension_noise_n and self.backend != "sim":
            raise UserError(f"tension_noise_n is the sim's: the {self.backend} hand's "
                            "tensions are what they are: set it to 0")
        if self.ramp_time is not None:
            if self.backend != "sim":
                raise UserError(f"ramp_time is the sim's: the {self.backend} hand moves as its "
                                "backend does (hardware: motion.ramp_steps x ramp_period): "
                                "leave it out")
            if not (math.isfinite(self.ramp_time) and 0 < self.ramp_time <= 2.0):
                raise UserError(f"ramp_time {self.ramp_time} s must be in (0, 2]")
        if self.sigma_turn_deg and self.sigma_motion > 0:
            raise UserError("sigma_turn_deg and sigma_motion model the same error: set one")
        if self.synthetic_solve != "model" and self.backend != "synthetic":
            raise UserError(f"synthetic_solve {self.synthetic_solve!r} is the synthetic "
                            f"world's: the {self.backend} world solves nothing")
        if self.true_stiffness and self.backend != "synthetic":
            raise UserError("true_stiffness is for the synthetic world only: in the sim, "
                            "give a true_hand whose finger has the other spring (e.g. "
                            "modelo_thumb45); the real hand is what it is")
        if self.true_hand and self.backend not in ("synthetic", "sim"):
            raise UserError(f"true_hand is for the synthetic world and the sim only: the "
                            f"{self.backend} hand is what it is")
        if self.slide_friction is not None and not self.slide_friction > 0:
            raise UserError(f"slide_friction {self.slide_friction} must be > 0 (or none: "
                            "contacts never slide)")
        if not 0 <= self.spin_friction <= 0.01:
            raise UserError(f"spin_friction {self.spin_friction} m must be in [0, 0.01]")
        if self.spin_memory and not self.spin_friction:
            raise UserError("spin_memory keeps the pads' torsional friction torques: set "
                            "spin_friction too")
        if (self.slide_friction is not None or self.spin_friction) and not self.uses_rolling:
            raise UserError("slide_friction and spin_friction act on rolling contacts: set "
                            "rolling too")
        if self.cone_return is not None:
            if not (math.isfinite(self.cone_return) and self.cone_return > 0):
                raise UserError(f"cone_return {self.cone_return} must be > 0 (or none: off)")
            if not self.uses_rolling:
                raise UserError("cone_return acts on rolling contacts: set rolling too")
            if self.slide_friction is not None or self.spin_friction:
                raise UserError("cone_return is the cheap stand-in for slide_friction and "
                                "spin_friction: set one or the other")
        if self.contact_stiffness is not None and not (
                math.isfinite(self.contact_stiffness) and self.contact_stiffness > 0):
            raise UserError(f"contact_stiffness {self.contact_stiffness} N/m must be > 0")
        if self.object_mass is not None and not (
                math.isfinite(self.object_mass) and self.object_mass > 0):
            raise UserError(f"object_mass {self.object_mass} kg must be finite and > 0")
        if self.object_curvature is not None and not (
                math.isfinite(self.object_curvature) and self.object_curvature >= 0):
            raise UserError(f"object_curvature {self.object_curvature} 1/m must be finite and "
                            ">= 0 (0: flat)")
        if self.limit_stiffness is not None and not (
                math.isfinite(self.limit_stiffness) and self.limit_stiffness > 0):
            raise UserError(f"limit_stiffness {self.limit_stiffness} N m/rad must be > 0")
        if self.prior_spread_deg is not None and not self.prior_spread_deg > 0:
            raise UserError(f"prior_spread_deg {self.prior_spread_deg} must be > 0")
        if self.contact_spread_deg is not None and not 0 < self.contact_spread_deg <= 90:
            raise UserError(f"contact_spread_deg {self.contact_spread_deg} must be in (0, 90]")
        object.__setattr__(self, "unknowns", tuple(self.unknowns))
        if self.nominal_theta_deg is not None:
            object.__setattr__(self, "nominal_theta_deg",
                               tuple(float(v) for v in self.nominal_theta_deg))
        if self.action_range_mm is not None:
            lo, hi = (float(v) for v in self.action_range_mm)
            if not 0 < lo <= hi <= 2.0:
                raise UserError(f"action_range_mm {list(self.action_range_mm)} must be [low, "
                                "high] with 0 < low <= high <= 2 (larger moves drop objects)")
            object.__setattr__(self, "action_range_mm", (lo, hi))
        if self.action_band_mm is not None and not (
                math.isfinite(self.action_band_mm) and self.action_band_mm > 0):
            raise UserError(f"action_band_mm {self.action_band_mm} must be > 0")

    def _check_types(self) -> None:
        """A setting of the wrong type (a sweep file's `particles: many`) is one UserError
        naming it, before any comparison or world can trip over it."""
        def bad(name: str, want: str) -> UserError:
            return UserError(f"{name} {getattr(self, name)!r} must be {want}")

        def is_int(v: Any) -> bool:
            return isinstance(v, numbers.Integral) and not isinstance(v, bool)

        def is_real(v: Any) -> bool:
            return isinstance(v, numbers.Real) and not isinstance(v, bool)

        for name in ("backend", "object", "hand"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise bad(name, "a name")
        for name in ("true_hand", "config"):
            if getattr(self, name) is not None and not isinstance(getattr(self, name), str):
                raise bad(name, "a name or path")
        for name in ("particles", "seed", "max_iterations", "min_iterations", "anneal_stages"):
            if not is_int(getattr(self, name)):
                raise bad(name, "an integer")
        for name in ("sigma_pos_mm", "sigma_rot_deg", "prior_spread_deg", "contact_spread_deg",
                     "sigma_motion",
                     "sigma_turn_deg", "likelihood_dof", "sigma_tension_n", "tension_noise_n",
                     "slide_friction", "spin_friction", "active_model_error",
                     "active_min_force_n",
                     "contact_stiffness", "limit_stiffness", "ramp_time", "cone_return",
                     "object_mass", "object_curvature"):
            v = getattr(self, name)
            if not (is_real(v) or (v is None and name in ("sigma_pos_mm", "sigma_rot_deg",
                                                          "sigma_turn_deg",
                                                          "prior_spread_deg",
                                                          "contact_spread_deg",
                                                          "slide_friction",
                                                          "contact_stiffness",
                                                          "limit_stiffness",
                                                          "ramp_time",
                                                          "cone_return",
                                                          "object_mass",
                                                          "object_curvature"))):
                raise bad(name, "a number")
        if self.noise_prior is not None:
            if (not isinstance(self.noise_prior, list | tuple) or len(self.noise_prior) != 2
                    or not all(is_real(v) for v in self.noise_prior)
                    or not 0 < self.noise_prior[0] <= self.noise_prior[1] < math.inf):
                raise bad("noise_prior", "[low, high] with 0 < low <= high, both finite")
            if "noise" not in self.unknowns:
                raise bad("noise_prior", "a prior of the 'noise' unknown: add it to unknowns")
            object.__setattr__(self, "noise_prior", tuple(float(v) for v in self.noise_prior))
        if not isinstance(self.priors, dict):
            raise bad("priors", "a mapping like {stiffness:thumb.distal: [0.01, 0.08]}")
        for spec, prior in self.priors.items():
            if spec not in self.unknowns:
                raise UserError(f"priors: {spec!r} is not among the unknowns {list(self.unknowns)}")
            if (not isinstance(prior, list | tuple) or len(prior) != 2
                    or not all(is_real(v) and math.isfinite(v) for v in prior)
                    or not prior[0] <= prior[1]):
                raise UserError(f"priors: {spec!r} {prior!r} must be [low, high] with low <= "
                                "high, both finite")
        from vlr.filter import JITTER_KERNELS, PRIOR_SHAPES
        from vlr.synthetic import WORLD_SOLVES
        if self.prior_shape not in PRIOR_SHAPES:
            raise bad("prior_shape", f"one of {', '.join(PRIOR_SHAPES)}")
        if not (is_int(self.unknown_warmup) and self.unknown_warmup >= 0):
            raise bad("unknown_warmup", "an integer >= 0")
        if not (is_real(self.unknown_discount) and 0.0 < self.unknown_discount <= 1.0):
            raise bad("unknown_discount", "a number in (0, 1]")
        if "noise" in self.priors and self.noise_prior is not None:
            raise bad("noise_prior", "given once: it is also in priors")
        object.__setattr__(self, "priors", {k: (float(a), float(b))
                                            for k, (a, b) in self.priors.items()})
        if self.object_com is not None:
            if (not isinstance(self.object_com, list | tuple) or len(self.object_com) != 3
                    or not all(is_real(v) and math.isfinite(v) for v in self.object_com)):
                raise bad("object_com", "[x, y, z] in the object frame [m], finite")
            object.__setattr__(self, "object_com", tuple(float(v) for v in self.object_com))
        if self.jitter_h is not None and not (is_real(self.jitter_h)
                                              and 0 <= self.jitter_h < 1):
            raise bad("jitter_h", "a number in [0, 1) (or none: the filter's default)")
        if self.ess_fraction is not None and not (is_real(self.ess_fraction)
                                                  and 0 <= self.ess_fraction < 1):
            raise bad("ess_fraction", "a number in [0, 1) (0: no tempering; or none: the "
                      "filter's default)")
        if self.jitter_kernel not in JITTER_KERNELS:
            raise bad("jitter_kernel", " or ".join(JITTER_KERNELS))
        if self.synthetic_solve not in WORLD_SOLVES:
            raise bad("synthetic_solve", " or ".join(WORLD_SOLVES))
        for name in ("link_scaling", "spin_memory", "exact_cylinder"):
            if not isinstance(getattr(self, name), bool):
                raise bad(name, "true or false")
        if not isinstance(self.rolling, bool | None):
            raise bad("rolling", "true or false (or none: the backend's default)")
        if self.exploration not in ("random", "active"):
            raise UserError(f"exploration {self.exploration!r}: expected random or active")
        if self.contact_prior not in (None, "pad", "surface"):
            raise UserError(f"contact_prior {self.contact_prior!r}: expected pad or surface")
        if not 0 <= self.active_model_error < 10:
            raise UserError(f"active_model_error {self.active_model_error} must be in [0, 10)")
        if not 0 <= self.active_min_force_n < 100:
            raise UserError(f"active_min_force_n {self.active_min_force_n} must be in "
                            "[0, 100)")
        if self.exact_cylinder and not self.uses_rolling:
            raise UserError("exact_cylinder holds the rolling contacts' pads to a cylinder's "
                            "axis: set rolling too")
        if self.active_min_force_n and not self.uses_rolling:
            raise UserError("active_min_force_n screens the rolling contacts' normal forces: "
                            "set rolling too")
        from vlr.active import CRITERIA

        if self.active_criterion not in CRITERIA:
            raise UserError(f"active_criterion {self.active_criterion!r}: expected one of "
                            f"{', '.join(CRITERIA)}")
        if isinstance(self.unknowns, str):  # one unknown, not a list of its letters
            object.__setattr__(self, "unknowns", (self.unknowns,))
        if (not isinstance(self.unknowns, list | tuple)
                or not all(isinstance(u, str) for u in self.unknowns)):
            raise bad("unknowns", "a list like [stiffness:thumb.distal]")
        if (not isinstance(self.true_stiffness, dict)
                or not all(isinstance(k, str) and is_real(v)
                           for k, v in self.true_stiffness.items())):
            raise bad("true_stiffness", "a mapping like {thumb.distal: 0.045}")
        if self.action_range_mm is not None and (
                not isinstance(self.action_range_mm, list | tuple)
                or len(self.action_range_mm) != 2
                or not all(is_real(v) for v in self.action_range_mm)):
            raise bad("action_range_mm", "[low, high] in mm")
        if self.action_band_mm is not None and not is_real(self.action_band_mm):
            raise bad("action_band_mm", "a number [mm]")
        if self.nominal_theta_deg is not None and (
                not isinstance(self.nominal_theta_deg, list | tuple)
                or not all(is_real(v) for v in self.nominal_theta_deg)):
            raise bad("nominal_theta_deg", "a list of angles [deg], one per joint (or one "
                      "per joint of every finger)")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrialSettings:
        """Settings from a dict (a sweep file's entry); unknown keys are named in the error."""
        known = {f.name for f in fields(cls)}
        bad = sorted(str(k) for k in set(d) - known)
        if bad:
            raise UserError(f"unknown trial setting(s) {bad}; known: {sorted(known)}")
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["unknowns"] = list(self.unknowns)
        if self.nominal_theta_deg is not None:
            d["nominal_theta_deg"] = list(self.nominal_theta_deg)
        if self.action_range_mm is not None:
            d["action_range_mm"] = list(self.action_range_mm)
        if self.noise_prior is not None:
            d["noise_prior"] = list(self.noise_prior)
        d["priors"] = {k: list(v) for k, v in self.priors.items()}
        if self.object_com is not None:
            d["object_com"] = list(self.object_com)
        return d

    @property
    def turn_deg(self) -> float:
        """The likelihood's turn scale [deg] in effect (`sigma_turn_deg`; 0 = none)."""
        if self.sigma_turn_deg is not None:
            return float(self.sigma_turn_deg)
        if (self.uses_rolling and self.backend in ROLLING_TURN_SIGMA
                and self.sigma_pos_mm is None and self.sigma_rot_deg is None
                and not self.sigma_motion and _has_thumb(self.hand)):
            return ROLLING_TURN_SIGMA[self.backend][2]
        return 0.0

    @property
    def sigma(self) -> tuple[float, float]:
        """(sigma_pos [mm], sigma_rot [deg]) in effect."""
        pos, rot = DEFAULT_SIGMA.get(self.backend, DEFAULT_SIGMA["sim"])
        if self.uses_rolling and self.backend in ROLLING_SIGMA:
            pos, rot = ROLLING_SIGMA[self.backend]
            if (self.backend in ROLLING_TURN_SIGMA and self.turn_deg
                    and self.sigma_pos_mm is None and self.sigma_rot_deg is None):
                pos, rot = ROLLING_TURN_SIGMA[self.backend][:2]
        return (self.sigma_pos_mm or pos, self.sigma_rot_deg or rot)

    @property
    def grasp_guess(self) -> tuple[tuple[float, ...] | None, float]:
        """The grasp guess [deg] (None: the generic one) and the prior's spread [deg] in
        effect: `nominal_theta_deg` and `prior_spread_deg`, or the backend's default
        (`GUESS_DEFAULT`)."""
        guess, spread = GUESS_DEFAULT.get(self.backend, (None, 3.0))
        if self.nominal_theta_deg is not None:
            guess = self.nominal_theta_deg
        return guess, spread if self.prior_spread_deg is None else self.prior_spread_deg

    @property
    def contact_prior_in_effect(self) -> str:
        """The contact prior in effect: `contact_prior`, or the backend's default."""
        if self.contact_prior is not None:
            return self.contact_prior
        return CONTACT_PRIOR_DEFAULT.get(self.backend, "pad")

    def believed_object(self, spec):
        """The object the filter believes (`vlr.motion.ObjectParams`): the spec's, with
        `object_mass`, `object_com` and `object_curvature` in place of its own where given."""
        from vlr.motion import ObjectParams

        obj = ObjectParams.from_spec(spec)
        if self.object_mass is not None:
            obj = replace(obj, mass=float(self.object_mass))
        if self.object_com is not None:
            obj = replace(obj, com=tuple(self.object_com))
        if self.object_curvature is not None:
            obj = replace(obj, surface=obj.surface.with_curvature(float(self.object_curvature)))
        return obj

    @property
    def limit_stiffness_in_effect(self) -> float:
        """The motion model's joint stops [N m/rad] in effect: `limit_stiffness`, or the
        backend's default, or `vlr.motion.MotionConfig`'s."""
        from vlr.motion import MotionConfig

        if self.limit_stiffness is not None:
            return float(self.limit_stiffness)
        return LIMIT_STIFFNESS_DEFAULT.get(self.backend, MotionConfig.limit_stiffness)

    @property
    def ramp_time_in_effect(self) -> float | None:
        """The sim's ramp per command change [s] in effect: `ramp_time`, or the backend's
        default (`RAMP_TIME_DEFAULT`); None for a backend that is not the sim."""
        if self.ramp_time is not None:
            return float(self.ramp_time)
        return RAMP_TIME_DEFAULT.get(self.backend)

    @property
    def uses_rolling(self) -> bool:
        """Rolling contacts in effect: `rolling`, or the backend's default."""
        if self.rolling is not None:
            return self.rolling
        return ROLLING_DEFAULT.get(self.backend, True)

    def motion_config(self):
        """The filter's motion model settings (`vlr.motion.MotionConfig`)."""
        from vlr.motion import MotionConfig

        cfg = MotionConfig().with_rolling(self.uses_rolling)
        if self.contact_stiffness is not None:
            cfg = replace(cfg, contact_stiffness=float(self.contact_stiffness))
        cfg = replace(cfg, limit_stiffness=self.limit_stiffness_in_effect)
        if self.cone_return is not None:
            cfg = replace(cfg, cone_return=float(self.cone_return))
        if self.link_scaling:
            cfg = replace(cfg, link_scaling=True)
        return replace(cfg, slide_friction=(math.inf if self.slide_friction is None
                                            else float(self.slide_friction)),
                       spin_friction=float(self.spin_friction),
                       spin_memory=self.spin_memory, exact_cylinder=self.exact_cylinder)


@dataclass
class World:
    """An opened trial world: what `vlr.identify.identify` needs, plus scoring and cleanup."""

    world: Any
    observer: Callable[[], Any]
    truth: Callable[[], Any] | None
    model: Any
    obj: Any
    nominal: Any
    hand_spec: Any
    object_spec: Any
    hand: Any = None  # the backend's Hand, closed by close()

    def close(self) -> None:
        if self.hand is not None:
            self.hand.close()


def _true_stiffness(settings: TrialSettings, model) -> dict[tuple[int, int], float]:
    """{(finger, joint): k} of the synthetic world: given values, else seeded draws."""
    out: dict[tuple[int, int], float] = {}
    rng = np.random.default_rng([settings.seed, 7919])
    for key, value in settings.true_stiffness.items():
        f, _, j = key.partition(".")
        try:
            out[(model.finger_index(f), model.joint_index(j))] = float(value)
        except (KeyError, ValueError) as exc:
            raise UserError(f"true_stiffness {key!r}: {exc}") from None
    for spec in settings.unknowns:
        kind, _, rest = spec.partition(":")
        if kind != "stiffness":
            continue
        f, _, j = rest.partition(".")
        key = (model.finger_index(f), model.joint_index(j))
        if key not in out:
            out[key] = float(model.stiffness[key] * rng.uniform(*TRUE_STIFFNESS_RANGE))
    return out


def open_world(settings: TrialSettings) -> World:
    """Open the trial's world (module docstring). The caller closes it."""
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.spec import load_hand, load_object
    from vlr.synthetic import SyntheticConfig, SyntheticWorld, nominal_grasp

    hand_spec = load_hand(settings.hand)
    obj_spec = load_object(settings.object)
    model = HandModel.from_spec(hand_spec)
    obj = settings.believed_object(obj_spec)
    check_unknowns(settings, model, obj)  # before a backend opens (and must be closed)
    # The nominal guess is the filter's own model's equilibrium: with rolling contacts the
    # pads roll while the grasp settles, and the distal joints settle 25-30 degrees from the
    # pinned equilibrium (measured, synthetic seed 0): a pinned guess would centre the
    # prior there, away from every rolling grasp.
    motion = settings.motion_config()
    guess = SyntheticConfig(motion=motion)
    theta_deg = settings.grasp_guess[0]
    if theta_deg is not None:
        n = len(theta_deg)
        if n not in (model.n_joints, model.n_fingers * model.n_joints):
            raise UserError(f"nominal_theta_deg {list(theta_deg)}: give "
                            f"{model.n_joints} angles (every finger alike) or "
                            f"{model.n_fingers * model.n_joints} (fingers "
                            f"{', '.join(model.names)}, {model.n_joints} each)")
        guess = SyntheticConfig(grasp_theta=tuple(np.radians(theta_deg)), motion=motion)
    nominal = nominal_grasp(model, obj, guess)
    if settings.backend == "synthetic":
        true_model = (HandModel.from_spec(load_hand(settings.true_hand))
                      if settings.true_hand else model)
        world_cfg = SyntheticConfig(seed=settings.seed, motion=motion,
                                    solve=settings.synthetic_solve)
        # The world holds the object as its spec has it, whatever the filter believes.
        world = SyntheticWorld(true_model, ObjectParams.from_spec(obj_spec), world_cfg,
                               nominal_model=model,
                               stiffness_overrides=_true_stiffness(settings, true_model))
        return World(world, world.observe, world.truth, model, obj, nominal, hand_spec,
                     obj_spec)
    from vlr.cli import open_backend
    from vlr.perception import observe

    options = {"config": settings.config} if settings.config else {}
    if settings.tension_noise_n:
        options["tension_noise_n"] = settings.tension_noise_n
    if settings.ramp_time_in_effect is not None:
        options["ramp_time"] = settings.ramp_time_in_effect
    # The sim may be built with another hand than the filter's (true_hand: replaced fingers
    # or springs that the filter identifies as unknowns); the filter keeps `hand_spec`.
    hand = open_backend(settings.backend, object=settings.object,
                        hand=settings.true_hand or settings.hand, seed=settings.seed, **options)
    spec = hand.object_spec
    if not settings.true_hand and (hand.spec.name, spec.name) != (hand_spec.name,
                                                                   obj_spec.name):
        # The backend decides what is there (the hardware config names its object and
        # hand): the filter's model must be that, not the command line's defaults.
        hand_spec = hand.spec
        model = HandModel.from_spec(hand_spec)
        obj = settings.believed_object(spec)
        check_unknowns(settings, model, obj)
        nominal = nominal_grasp(model, obj, guess)

    def observer():
        frame = hand.grab_frame()
        if frame is None:
            return None
        return observe(frame.image, hand.calibration, spec.tag_id, spec.tag_size)

    if settings.sigma_tension_n and not getattr(hand, "reads_tensions", False):
        hand.close()  # before the hand moves
        raise UserError(f"sigma_tension_n: this {settings.backend} hand does not report "
                        "tendon tensions (hardware: give its config a `tension` section, "
                        "hardware/README.md): set it to 0")
    truth = getattr(hand, "scoring_truth", None)  # sim only; never given to the filter
    return World(hand, observer, truth, model, obj, nominal, hand_spec, spec, hand)


def check_unknowns(settings: TrialSettings, model, obj=None) -> None:
    """Bad unknown specs become one UserError naming the spec. Without `obj` (the object
    believed) the object's unknowns ("mass", "com:z") are checked for their form only."""
    from vlr.filter import check_unknown_set, parse_unknown
    from vlr.motion import ObjectParams

    try:
        check_unknown_set(settings.unknowns)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    obj = obj or ObjectParams(mass=1.0, com=(0.0, 0.0, 0.0))  # the form only: no priors kept
    for u in settings.unknowns:
        try:
            parse_unknown(u, model, settings.priors.get(u), obj=obj)
        except (ValueError, KeyError) as exc:
            raise UserError(f"unknown {u!r}: {exc}") from None


@functools.lru_cache(maxsize=64)
def _has_thumb(hand: str) -> bool:
    """Whether the hand (a name or a spec file) has a finger slot named "thumb", the turn
    term's axis; a hand that cannot be read counts as having one (opening it names the
    problem later)."""
    from vlr.spec import load_hand

    try:
        return "thumb" in load_hand(hand).finger_names
    except Exception:  # noqa: BLE001 (the trial's own open reports a bad hand)
        return True


def _turn(settings: TrialSettings, model) -> dict:
    """The likelihood's turn term (`ObservationModel.sigma_turn`, `opposed`): the thumb
    opposes the others."""
    if not settings.turn_deg:
        return {}
    if "thumb" not in model.names:
        raise UserError(f"sigma_turn_deg: the turn's axis runs from the thumb, and the hand's "
                        f"fingers are {list(model.names)}")
    return {"sigma_turn": math.radians(settings.turn_deg),
            "opposed": model.finger_index("thumb")}


def identify_config(settings: TrialSettings, model):
    """The `IdentifyConfig` of a trial; bad unknown specs become a UserError."""
    from vlr.active import ActiveExploration
    from vlr.filter import FilterConfig
    from vlr.identify import IdentifyConfig
    from vlr.observation import ObservationModel

    check_unknowns(settings, model)
    sp, sr = settings.sigma
    # Rolling contacts or pinned: `TrialSettings.uses_rolling` (a default per backend).
    fcfg = FilterConfig(n_particles=settings.particles, seed=settings.seed,
                        motion=settings.motion_config(),
                        unknowns=settings.unknowns,
                        priors={**settings.priors,
                                **({} if settings.noise_prior is None
                                   else {"noise": settings.noise_prior})},
                        prior_shape=settings.prior_shape,
                        unknown_warmup=settings.unknown_warmup,
                        unknown_discount=settings.unknown_discount,
                        theta_spread=float(np.radians(settings.grasp_guess[1])),
                        anneal_stages=settings.anneal_stages,
                        contact_prior=settings.contact_prior_in_effect,
                        **({} if settings.contact_spread_deg is None
                           else {"contact_spread": math.radians(settings.contact_spread_deg)}),
                        **({} if settings.jitter_h is None
                           else {"jitter_h": float(settings.jitter_h)}),
                        **({} if settings.ess_fraction is None
                           else {"ess_fraction": float(settings.ess_fraction)}),
                        jitter_kernel=settings.jitter_kernel,
                        observation=ObservationModel(sigma_pos=sp * 1e-3,
                                                     sigma_rot=float(np.radians(sr)),
                                                     motion_fraction=settings.sigma_motion,
                                                     sigma_tension=settings.sigma_tension_n,
                                                     dof=float(settings.likelihood_dof),
                                                     **_turn(settings, model)))
    actions = {}
    if settings.action_range_mm is not None:
        actions["action_range"] = tuple(v * 1e-3 for v in settings.action_range_mm)
    if settings.action_band_mm is not None:
        actions["action_band"] = settings.action_band_mm * 1e-3
    return IdentifyConfig(max_iterations=settings.max_iterations, **actions,
                          min_iterations=settings.min_iterations, filter=fcfg,
                          exploration=settings.exploration,
                          active=ActiveExploration(model_error=float(settings.active_model_error),
                                                  criterion=settings.active_criterion,
                                                  min_normal_force=float(
                                                      settings.active_min_force_n)))


@dataclass
class TrialRun:
    """What one trial produced: the `result.json` summary and, for pictures and tables, the
    filter's result (`vlr.identify.IdentifyResult`), the nominal model and the truths scored
    at each iteration (scoring only)."""

    summary: dict[str, Any]
    result: Any
    model: Any
    truths: list


def identify_trial(settings: TrialSettings, progress: Callable | None = None,
                   watch: Callable | None = None,
                   observe_through: Callable[[World], Callable] | None = None) -> TrialRun:
    """Open the trial's world, run the identification loop, close the world, score.

    `observe_through(world)` may return another observer to use (the live view wraps the
    camera's with one that also draws it)."""
    from vlr.identify import identify
    from vlr.results import summarize

    t0 = time.perf_counter()
    w = open_world(settings)
    try:
        cfg = identify_config(settings, w.model)
        truths: list = []
        scorer = None
        if w.truth is not None:
            def scorer():  # scoring only; the filter never sees this
                truths.append(w.truth())
                return truths[-1]
        observer = w.observer if observe_through is None else observe_through(w)
        result = identify(w.world, observer, w.model, w.obj, w.nominal, cfg, truth=scorer,
                          progress=progress, watch=watch)
    finally:
        w.close()
    args = SimpleNamespace(backend=settings.backend, object=settings.object,
                           hand=settings.hand, particles=settings.particles,
                           seed=settings.seed, unknown=list(settings.unknowns))
    summary = summarize(result, w.model, args, time.perf_counter() - t0,
                        truths[-1] if truths else None)
    summary["settings"] = settings.to_dict()
    summary["rolling"] = settings.uses_rolling   # in effect (`rolling` None: the backend's)
    summary["sigma"] = list(settings.sigma)       # in effect, [mm, deg]
    summary["sigma_turn_deg"] = settings.turn_deg  # in effect, [deg]; 0 = no turn term
    summary["limit_stiffness"] = settings.limit_stiffness_in_effect  # in effect [N m/rad]
    if settings.ramp_time_in_effect is not None:
        summary["ramp_time"] = settings.ramp_time_in_effect      # in effect [s], the sim's
    guess, spread = settings.grasp_guess          # in effect (None: the backend's default)
    summary["grasp_guess"] = {"nominal_theta_deg": None if guess is None else list(guess),
                              "prior_spread_deg": float(spread),
                              "contact_spread_deg": math.degrees(cfg.filter.contact_spread),
                              "contact_prior": cfg.filter.contact_prior}
    if hasattr(w.world, "regrasps"):  # synthetic: truths drawn again for sitting at a fold
        summary["world_regrasps"] = int(w.world.regrasps)
    return TrialRun(summary, result, w.model, truths)


def run_trial(settings: TrialSettings, out: Path | None = None,
              progress: Callable | None = None, watch: Callable | None = None) -> dict:
    """Run one trial (`identify_trial`); write its files into `out` if given; return the
    result summary."""
    from vlr.results import write_outputs

    run = identify_trial(settings, progress, watch)
    if out is not None:
        write_outputs(Path(out), run.result, run.summary, run.model, run.truths)
    return run.summary

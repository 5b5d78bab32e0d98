"""The world of one identification, opened from the settings tree (`vlr.settings`).

`open_world` loads the specs, builds the filter's model of the hand and of the object it
believes, computes the grasp guess the prior is drawn about (`nominal_grasp`), and opens the
backend's world (`vlr.backends`): a backend of hands (the sim, the real hand) through
`hand_world`, which observes the POM through the camera (`vlr.perception`), or a world of its
own (the synthetic one). Ground truth, where the world has one, is for scoring only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from vlr.errors import UserError

__all__ = ["World", "open_world", "hand_world", "check_unknowns", "check_estimator",
           "grasp_guess"]


@dataclass
class World:
    """An opened world: what `vlr.identify.identify` needs, plus scoring and cleanup.

    Attributes:
        world: moves the tendons (`vlr.identify.ActingWorld`).
        observer: returns the camera's POM pose, or None when the tag is not seen.
        truth: the world's ground truth, for SCORING only (None on the real hand).
        model, obj: the filter's hand model and the object it believes.
        nominal: the grasp guess (`vlr.synthetic.NominalGrasp`).
        hand_spec, object_spec: the specs (for views and plots).
        hand: the backend's Hand, closed by `close` (None for the synthetic world).
    """

    world: Any
    observer: Callable[[], Any]
    truth: Callable[[], Any] | None
    model: Any
    obj: Any
    nominal: Any
    hand_spec: Any
    object_spec: Any
    hand: Any = None

    def close(self) -> None:
        if self.hand is not None:
            self.hand.close()


def believed_object(settings, spec):
    """The object the filter believes (`vlr.motion.ObjectParams`): the spec's, with
    `filter.object`'s mass, centre of mass and curvature in place where given."""
    from vlr.motion import ObjectParams

    obj = ObjectParams.from_spec(spec)
    belief = settings.filter.object
    if belief.mass is not None:
        obj = dataclasses.replace(obj, mass=float(belief.mass))
    if belief.com is not None:
        obj = dataclasses.replace(obj, com=tuple(belief.com))
    if belief.curvature is not None:
        obj = dataclasses.replace(obj, surface=obj.surface.with_curvature(belief.curvature))
    return obj


def check_unknowns(settings, model, obj=None) -> None:
    """Bad unknown specs become one UserError naming the spec. Without `obj` (the object
    believed) the object's unknowns ("mass", "com:z") are checked for their form only."""
    from vlr.motion import ObjectParams
    from vlr.unknowns import check_unknown_set, parse_unknown

    unknowns = settings.filter.unknowns
    try:
        check_unknown_set(unknowns)
    except ValueError as exc:
        raise UserError(f"filter.unknowns: {exc}") from None
    for spec in settings.filter.priors:
        if spec not in unknowns:
            raise UserError(f"filter.priors: {spec!r} is not among the unknowns "
                            f"{list(unknowns)}")
    obj = obj or ObjectParams(mass=1.0, com=(0.0, 0.0, 0.0))  # the form only
    for u in unknowns:
        try:
            parse_unknown(u, model, settings.filter.priors.get(u), obj=obj)
        except (ValueError, KeyError) as exc:
            raise UserError(f"filter.unknowns {u!r}: {exc}") from None


def check_estimator(settings) -> None:
    """What `filter.estimator` cannot do is one UserError before a world opens: the unscented
    Kalman filter with an unknown it does not carry or with active exploration
    (`vlr.ukf.check_estimator`; imported only for the UKF)."""
    if settings.filter.estimator == "ukf":
        from vlr.ukf import check_estimator as check

        check(settings.filter, settings.loop.exploration)


def grasp_guess(settings, model, obj):
    """The grasp guess the prior is drawn about (`vlr.synthetic.nominal_grasp`): the nominal
    hand's equilibrium from `filter.guess_theta_deg`, in the filter's own motion model."""
    from vlr.synthetic import SyntheticConfig, nominal_grasp

    motion = settings.filter.motion
    theta_deg = settings.filter.guess_theta_deg
    if theta_deg is None:
        return nominal_grasp(model, obj, SyntheticConfig(motion=motion))
    n = len(theta_deg)
    if n not in (model.n_joints, model.n_fingers * model.n_joints):
        raise UserError(f"filter.guess_theta_deg {list(theta_deg)}: give {model.n_joints} "
                        f"angles (every finger alike) or {model.n_fingers * model.n_joints} "
                        f"(fingers {', '.join(model.names)}, {model.n_joints} each)")
    guess = SyntheticConfig(grasp_theta=tuple(np.radians(theta_deg)), motion=motion)
    return nominal_grasp(model, obj, guess)


def _check_turn(settings, model) -> None:
    turn = settings.filter.observation.sigma_turn_deg
    if turn and "thumb" not in model.names:
        raise UserError(f"filter.observation.sigma_turn_deg {turn:g}: the turn's axis runs "
                        f"from a finger named 'thumb', and the hand's fingers are "
                        f"{list(model.names)}: set it to 0")


def open_world(settings) -> World:
    """Open the world of `settings` (module docstring). The caller closes it."""
    from vlr.backends import get_backend
    from vlr.kinematics import HandModel
    from vlr.spec import load_hand, load_object

    backend = get_backend(settings.world.backend)
    options = backend.world_options(settings)
    hand_spec = load_hand(settings.world.hand)
    obj_spec = load_object(settings.world.object)
    if settings.world.true_hand:
        load_hand(settings.world.true_hand)
    model = HandModel.from_spec(hand_spec)
    obj = believed_object(settings, obj_spec)
    check_unknowns(settings, model, obj)  # before a backend opens (and must be closed)
    check_estimator(settings)
    _check_turn(settings, model)
    nominal = grasp_guess(settings, model, obj)
    if backend.open_world is not None:
        return backend.open_world(settings, options, model, obj, nominal, hand_spec, obj_spec)
    w = settings.world
    hand = backend.open_hand(object=w.object, hand=w.true_hand or w.hand, seed=settings.seed,
                             **dataclasses.asdict(options))
    try:
        return hand_world(hand, settings, model, obj, nominal, hand_spec, obj_spec)
    except BaseException:
        hand.close()
        raise


def hand_world(hand, settings, model=None, obj=None, nominal=None, hand_spec=None,
               obj_spec=None) -> World:
    """The world around an open `vlr.hand.Hand`: the camera's POM pose as the observer, the
    sim's truth for scoring. The backend decides what is there (the real hand's config names
    its hand and object): where that is not what the settings name, the filter's model is
    the backend's."""
    from vlr.kinematics import HandModel
    from vlr.perception import observe

    spec = hand.object_spec
    if (model is None or (not settings.world.true_hand
                          and (hand.spec.name, spec.name) != (hand_spec.name, obj_spec.name))):
        hand_spec = hand.spec
        model = HandModel.from_spec(hand_spec)
        obj = believed_object(settings, spec)
        check_unknowns(settings, model, obj)
        _check_turn(settings, model)
        nominal = grasp_guess(settings, model, obj)

    def observer():
        frame = hand.grab_frame()
        if frame is None:
            return None
        return observe(frame.image, hand.calibration, spec.tag_id, spec.tag_size)

    if settings.filter.observation.sigma_tension_n and not getattr(hand, "reads_tensions",
                                                                   False):
        raise UserError(f"filter.observation.sigma_tension_n: this {settings.world.backend} "
                        "hand does not report tendon tensions (hardware: give its config a "
                        "`tension` section, hardware/README.md): set it to 0")
    truth = getattr(hand, "scoring_truth", None)  # sim only; never given to the filter
    return World(hand, observer, truth, model, obj, nominal, hand_spec, spec, hand)

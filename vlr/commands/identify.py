"""`vlr identify`: self-identification on any backend (Algorithm 1), with result files.

Writes into --out: `result.json` (errors against ground truth where the backend has one,
coverage, timing), `history.npz` (per-iteration posterior means, 95% bounds, ESS, and the
truth when known), `convergence.png` (per proximal joint: estimate, 95% band and truth
against iteration, like the paper's Fig. 4C) and `particles.png` (the particle cloud at a few
iterations, `vlr.plots`). `--view` serves a live 3D view of the hypotheses and `--view-html`
saves its final scene as a standalone page (`vlr.view`, docs/VIEW.md); neither costs
anything unless asked for.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

# `vlr.filter.JITTER_KERNELS`, spelt out so that the CLI starts without importing the filter
# (0.6 s); tests/test_copula.py checks that the two agree.
JITTER_KERNELS = ("gaussian", "copula", "copula-joints", "copula-scales",
                  "copula-joints-scales", "log-scales", "log-springs")
# `vlr.synthetic.WORLD_SOLVES`, spelt out for the same reason (tests/test_synthetic.py).
WORLD_SOLVES = ("model", "loose")

# Below this share of true joints inside the grasp prior's intervals (scored against the
# sim's or the synthetic world's truth), the run's table says the guess missed the grasp.
PRIOR_COVERAGE_WARN = 0.5


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="self-identify the hand-object system (joint angles, "
                       "contacts, unknown stiffness or link lengths)")
    p.add_argument("--backend", default="sim", help="sim | synthetic | hardware")
    p.add_argument("--object", default="apple")
    p.add_argument("--hand", default="modelo", help="the hand the user believes in (nominal)")
    p.add_argument("--true-hand", help="synthetic world or sim: the hand the world is built "
                   "with, if not --hand (e.g. nh1); the filter keeps --hand")
    p.add_argument("--particles", type=int, default=60_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--unknown", action="append", default=[],
                   help="extra unknown, e.g. stiffness:thumb.distal, length:left.proximal, "
                   "the object's mass, a coordinate of its centre of mass (com:z) or its "
                   "surface's curvature at the contacts (curvature, curvature:thumb); "
                   "'noise' identifies the size of the model's error (a factor on the "
                   "likelihood's pose scales, vlr.observation)")
    p.add_argument("--max-iterations", type=int, default=40)
    p.add_argument("--min-iterations", type=int, default=0,
                   help="do not stop on convergence before this many actions")
    p.add_argument("--true-stiffness", action="append", default=[], type=_assignment,
                   metavar="FINGER.JOINT=K", help="synthetic world only: a true spring rate "
                   "[N m/rad]; an unknown stiffness without one is drawn (vlr.trial)")
    p.add_argument("--sigma-pos-mm", type=float, help="likelihood position scale [mm] "
                   "(default per backend and contact model: vlr.trial.DEFAULT_SIGMA, "
                   "ROLLING_SIGMA, ROLLING_TURN_SIGMA)")
    p.add_argument("--sigma-rot-deg", type=float, help="likelihood rotation scale [deg]")
    p.add_argument("--sigma-motion", type=float, default=0.0,
                   help="likelihood model error as a fraction of each particle's predicted "
                        "motion over the action (0: fixed scales)")
    p.add_argument("--sigma-tension", type=float, default=0.0, metavar="N",
                   help="weigh the hand's tendon tensions in the likelihood with this scale "
                   "[N] (0: not weighed; the sim reports them, the real hand with a `tension` "
                   "calibration in its config)")
    p.add_argument("--tension-noise", type=float, default=0.0, metavar="N",
                   help="sim only: the standard deviation of its tension readings [N] "
                   "(default 0: the series spring's exact tension)")
    p.add_argument("--sigma-turn", type=float, default=None, metavar="DEG",
                   help="likelihood model error of the object's turn in its grip, about the "
                   "axis from the thumb to the other contacts [deg] (0: none); the base "
                   "scales then cover what is left (vlr gap's 'rest'). Default: 1.0 in the "
                   "sim with rolling contacts when no scale is given, with base scales 0.2 "
                   "mm / 0.4 deg (vlr.trial.ROLLING_TURN_SIGMA); else none")
    p.add_argument("--likelihood-dof", type=float, default=0.0, metavar="NU",
                   help="the pose error's Student-t degrees of freedom: heavy tails, so that "
                   "an action the model gets badly wrong costs a particle log q, not q "
                   "(default 0: Gaussian)")
    p.add_argument("--nominal-theta-deg", type=float, nargs="+", metavar="DEG",
                   help="your guess of the grasp's joint angles: one per joint (every finger "
                   "alike), or one per joint of every finger in the hand's order (default: "
                   "the backend's, vlr.trial.GUESS_DEFAULT: -10 15 on the sim)")
    p.add_argument("--prior-spread-deg", type=float, default=None,
                   help="prior std of the joint angles about the nominal grasp [deg] "
                   "(default: the backend's: 10 on the sim, 3 otherwise)")
    p.add_argument("--contact-spread-deg", type=float, default=None,
                   help="prior std of each pad contact's two angles about the pad's inner "
                   "face [deg] (default 8.6, vlr.filter.FilterConfig.contact_spread)")
    p.add_argument("--contact-prior", choices=("pad", "surface"), default=None,
                   help="draw the pad contacts about the pad's inner face, or where each "
                   "particle's pads would touch an object of the local surface's shape "
                   "(default: the backend's, vlr.trial.CONTACT_PRIOR_DEFAULT)")
    p.add_argument("--rolling", action=argparse.BooleanOptionalAction, default=None,
                   help="rolling contacts in the filter's motion model, or pinned ones with "
                   "--no-rolling (default: the backend's, vlr.trial.ROLLING_DEFAULT: rolling on "
                   "sim and hardware, pinned on synthetic; docs/RESULTS.md section 5)")
    p.add_argument("--slide-friction", type=float, default=None, metavar="MU",
                   help="with rolling contacts: the pads' sliding friction coefficient "
                   "(default: contacts never slide; the sim's pads have 1.0)")
    p.add_argument("--spin-friction", type=float, default=0.0, metavar="MU_T",
                   help="with rolling contacts: the pads' torsional friction coefficient [m] "
                   "(default 0: free spin; the sim's pads have 0.001)")
    p.add_argument("--spin-memory", action="store_true",
                   help="with --spin-friction: each particle's pads keep their spin torques "
                   "from one action to the next (default: each action starts them at 0)")
    p.add_argument("--exact-cylinder", action="store_true",
                   help="with rolling contacts on a cylinder (the wine glass, the screwdriver):"
                   " hold the pads to its axis (default: to a sphere of its radius)")
    p.add_argument("--exploration", choices=("random", "active"), default="random",
                   help="random actions (the paper) or active: the candidate whose predicted "
                   "POM poses disagree most across the particles")
    p.add_argument("--active-model-error", type=float, default=0.0, metavar="KAPPA",
                   help="with --exploration active: weigh the disagreement against the "
                   "model's expected error, KAPPA x each candidate's predicted motion")
    p.add_argument("--active-criterion", choices=("spread", "variance"), default="spread",
                   help="with --exploration active: the candidate whose predicted poses "
                   "spread most (default), or the one that leaves the joint angles the "
                   "smallest expected posterior spread")
    p.add_argument("--active-min-force", type=float, default=0.0, metavar="N",
                   help="with --exploration active and rolling contacts: pass over a "
                   "candidate after which a finger's predicted normal force falls under N "
                   "newtons (default 0: no screen)")
    p.add_argument("--action-range-mm", type=float, nargs=2, default=None,
                   metavar=("LOW", "HIGH"), help="magnitude of each tendon's random "
                   "exploratory change [mm] (default 0.2 0.4: 4-8 N at 20 N/mm)")
    p.add_argument("--action-band-mm", type=float, default=None, metavar="B",
                   help="commands stay within B mm of the grasp command (default 0.4)")
    p.add_argument("--object-mass", type=float, default=None, metavar="KG",
                   help="the object's mass the filter believes [kg] (default: its spec's; "
                   "the sim keeps the spec's): a wrong guess, or with --unknown mass its "
                   "prior's centre")
    p.add_argument("--object-com", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="the object's centre of mass the filter believes, in its frame O [m] "
                   "(default: its spec's; the sim keeps the spec's)")
    p.add_argument("--object-curvature", type=float, default=None, metavar="K",
                   help="the local curvature 1/rho of the object's surface the filter believes "
                   "[1/m] (0: flat; default: its spec's shape's; the sim keeps the spec's): a "
                   "wrong guess; with --unknown curvature its prior is 0 to the larger of "
                   "twice K and 50")
    p.add_argument("--contact-stiffness", type=float, default=None, metavar="K_C",
                   help="the motion model's contact penalty [N/m] (default 1e6)")
    p.add_argument("--limit-stiffness", type=float, default=None, metavar="K_LIM",
                   help="the motion model's joint stops [N m/rad] (default: the sim's 17, "
                   "the real hand's 100)")
    p.add_argument("--ramp-time", type=float, default=None, metavar="S",
                   help="sim only: how long the sim takes to make each command change [s] "
                   "(default 0.1, the hardware backend's default move)")
    p.add_argument("--cone-return", type=float, default=None, metavar="MU",
                   help="with rolling contacts: after each action return the contacts' "
                   "stretch onto the friction cone MU N and settle again (a cheap stand-in "
                   "for --slide-friction; default off; the sim's pads have 1.0)")
    p.add_argument("--prior", action="append", default=[], type=_prior,
                   metavar="SPEC=LOW,HIGH", help="the uniform prior of an --unknown in its SI "
                   "unit, e.g. stiffness:thumb.distal=0.01,0.08 [N m/rad] (repeatable; "
                   "default per kind: vlr.filter.parse_unknown)")
    p.add_argument("--prior-shape", choices=("uniform", "log-uniform"), default="uniform",
                   help="how a spring's, the tendon's and the object's mass's priors are "
                   "drawn: uniform, or uniform in the logarithm (median at the nominal for "
                   "the default priors; default uniform)")
    p.add_argument("--unknown-warmup", type=int, default=0, metavar="N",
                   help="draw the unknowns afresh from their prior after each of the first N "
                   "updates (the grasp's and N-1 actions), while the joints are still spread "
                   "(default 0: off)")
    p.add_argument("--unknown-discount", type=float, default=1.0, metavar="DELTA",
                   help="discount factor in (0, 1] of the unknowns' artificial evolution: "
                   "their spread grows by 1/sqrt(DELTA) at each jitter, so old observations "
                   "fade over about 1/(1 - DELTA) actions (default 1: off)")
    p.add_argument("--noise-prior", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="with --unknown noise: the uniform prior of the factor on the "
                   "likelihood's pose scales (default 0.25 1)")
    p.add_argument("--jitter-h", type=float, default=None, metavar="H",
                   help="the filter's Liu-West bandwidth, in [0, 1) (default 0.4; "
                   "RESULTS.md section 5: narrower converges, confidently wrong)")
    p.add_argument("--ess-fraction", type=float, default=None, metavar="F",
                   help="tempering keeps the effective sample size of an update at this "
                   "share of the particles or more, in [0, 1) (default 0.1; 0: no tempering)")
    p.add_argument("--synthetic-solve", choices=WORLD_SOLVES, default="model",
                   help="with --backend synthetic: how the world solves an action: as a "
                   "filter particle does (model, the default), or in one 300-iteration solve "
                   "without jump limits (loose, before session 42)")
    p.add_argument("--jitter-kernel", choices=JITTER_KERNELS, default="log-springs",
                   help="where the Liu-West draw is made: the springs (a joint's, the "
                   "tendon's) on their logarithms and the rest as they are (log-springs, the "
                   "default); the object's mass on its logarithm too (log-scales); every "
                   "dimension as it is (gaussian); each "
                   "one's normal scores (copula), which keeps a joint's posterior cut at its "
                   "stop from drifting off it; or the joint angles' scores alone "
                   "(copula-joints), the scale unknowns' (copula-scales), or both "
                   "(copula-joints-scales)")
    p.add_argument("--link-scaling", action="store_true",
                   help="a link of unknown length weighs as the nominal link scaled to its "
                   "length (default: the nominal weights)")
    p.add_argument("--anneal-stages", type=int, default=1, metavar="N",
                   help="the filter's most weighting stages per observation: a likelihood "
                   "that tempering held back is applied in resample-move stages (default 1: "
                   "its rest is dropped)")
    p.add_argument("--config", help="hardware backend: the hardware YAML file")
    p.add_argument("--out", default="runs/identify", help="output folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--view", action="store_true", help="serve a live 3D view of the particle "
                   "filter (meshcat; prints its URL)")
    p.add_argument("--view-html", metavar="FILE", help="save the final 3D scene as a "
                   "standalone HTML page")
    p.add_argument("--cloud-at", type=_iterations, metavar="I,J,...",
                   help="iterations drawn in particles.png (default: 4 from first to last)")
    p.set_defaults(func=run)


def _assignment(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return key.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: use FINGER.JOINT=VALUE, e.g. thumb.distal=0.045") from None


def _prior(text: str) -> tuple[str, tuple[float, float]]:
    spec, sep, bounds = text.partition("=")
    try:
        low, high = (float(v) for v in bounds.split(","))
        if not sep or not spec.strip():
            raise ValueError
        return spec.strip(), (low, high)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: use SPEC=LOW,HIGH, e.g. stiffness:thumb.distal=0.01,0.08") from None


def _iterations(text: str) -> list[int]:
    try:
        its = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a list of iterations, e.g. 0,5,10") from None
    if not its or min(its) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: give iterations >= 0, e.g. 0,5,10")
    return its


def _open_view(args: argparse.Namespace, model, hand_spec, obj_spec, truth):
    """The live view (`vlr.view`), only when asked for: meshcat is not even imported else."""
    from vlr.view import FilterView

    view = FilterView(model, obj=obj_spec, seed=args.seed, truth=truth,
                      palm_radius=hand_spec.palm_radius,
                      palm_thickness=hand_spec.palm_thickness)
    if args.view:
        print(f"view: {view.url}", flush=True)
    return view


def _finish_view(view, args: argparse.Namespace) -> None:
    import sys

    if args.view_html:
        print(f"wrote {view.save_html(args.view_html)}")
    if args.view and sys.stdin.isatty():  # keep serving the final scene until the user is done
        input("view: press Enter to stop the viewer ")


def run(args: argparse.Namespace) -> int:
    from vlr.errors import UserError
    from vlr.plots import CloudRecorder, particle_cloud
    from vlr.results import write_outputs
    from vlr.trial import TrialSettings, identify_trial

    specs = [spec for spec, _ in args.prior]
    if twice := sorted({spec for spec in specs if specs.count(spec) > 1}):
        raise UserError(f"--prior {twice[0]} is given twice: give each unknown's prior once")
    out = Path(args.out)
    settings = TrialSettings(
        backend=args.backend, object=args.object, hand=args.hand, true_hand=args.true_hand,
        particles=args.particles, seed=args.seed, unknowns=tuple(args.unknown),
        true_stiffness=dict(args.true_stiffness), max_iterations=args.max_iterations,
        min_iterations=args.min_iterations, sigma_pos_mm=args.sigma_pos_mm,
        sigma_rot_deg=args.sigma_rot_deg, sigma_motion=args.sigma_motion,
        sigma_turn_deg=args.sigma_turn, likelihood_dof=args.likelihood_dof,
        sigma_tension_n=args.sigma_tension,
        tension_noise_n=args.tension_noise, config=args.config,
        nominal_theta_deg=args.nominal_theta_deg, prior_spread_deg=args.prior_spread_deg,
        contact_spread_deg=args.contact_spread_deg, contact_prior=args.contact_prior,
        rolling=args.rolling,
        slide_friction=args.slide_friction,
        spin_friction=args.spin_friction, spin_memory=args.spin_memory,
        exact_cylinder=args.exact_cylinder,
        exploration=args.exploration,
        active_model_error=args.active_model_error,
        active_criterion=args.active_criterion, active_min_force_n=args.active_min_force,
        anneal_stages=args.anneal_stages,
        contact_stiffness=args.contact_stiffness, limit_stiffness=args.limit_stiffness,
        object_mass=args.object_mass, object_com=args.object_com,
        object_curvature=args.object_curvature,
        ramp_time=args.ramp_time, cone_return=args.cone_return,
        link_scaling=args.link_scaling, jitter_h=args.jitter_h,
        ess_fraction=args.ess_fraction,
        jitter_kernel=args.jitter_kernel, synthetic_solve=args.synthetic_solve,
        noise_prior=args.noise_prior,
        priors=dict(args.prior), prior_shape=args.prior_shape,
        unknown_warmup=args.unknown_warmup, unknown_discount=args.unknown_discount,
        action_range_mm=args.action_range_mm, action_band_mm=args.action_band_mm)
    bar = None

    def progress(rec) -> None:
        # The bar starts with the filter, so that a world that fails to open (a bad
        # hardware config) prints its one-line error alone.
        nonlocal bar
        if args.quiet:
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=args.max_iterations, desc="identify", unit="it")
        bar.set_postfix(ci_deg=f"{rec.ci_deg:.2f}", ess=f"{rec.ess:.0f}")
        if rec.iteration:
            bar.update(1)

    cloud = CloudRecorder(seed=args.seed)  # a small sample per iteration, for particles.png
    watchers: list = [cloud]

    def watch(pf, rec) -> None:
        for w in watchers:
            w(pf, rec)

    view = None

    def observe_through(w):
        nonlocal view
        if not (args.view or args.view_html):
            return w.observer
        view = _open_view(args, w.model, w.hand_spec, w.object_spec, w.truth)
        watchers.append(view)
        return view.observing(w.observer)

    try:
        try:
            run = identify_trial(settings, progress, watch, observe_through)
        finally:
            if bar is not None:
                bar.close()
        result, summary, model, truths = run.result, run.summary, run.model, run.truths
        write_outputs(out, result, summary, model, truths)
        truth_at = ({r.iteration: t.theta for r, t in zip(result.history, truths, strict=True)}
                    if truths else None)
        particle_cloud(out / "particles.png", cloud.snapshots, model.names,
                       [i for i in args.cloud_at or () if i in cloud.snapshots] or None,
                       truth_at)
        print(format_table(result, summary, model))
        print(f"\nwrote {out / 'result.json'}, {out / 'history.npz'}, "
              f"{out / 'convergence.png'}, {out / 'particles.png'}")
        if view is not None:  # after the results are safe on disk
            _finish_view(view, args)
    finally:
        if view is not None:
            view.close()  # always stop the meshcat server
    return 0


def format_table(result, summary: dict, model) -> str:
    from vlr.results import unknown_units

    lines = [f"converged: {summary['converged']} after {summary['iterations']} iterations "
             f"(criterion met at {summary['converged_at']})", "",
             f"{'joint':16s} {'mean [deg]':>11s} {'median [deg]':>13s} "
             f"{'95% interval [deg]':>22s}"]
    if result.grasp_lost_at is not None:
        lines[1:1] = [f"stopped: the hand reported the grasp lost after action "
                      f"{result.grasp_lost_at} ({result.grasp_message or 'no reason given'})"]
    for name, e in result.theta.items():
        lines.append(f"{name:16s} {np.degrees(e.mean):11.2f} {np.degrees(e.median):13.2f} "
                     f"{np.degrees(e.low):10.2f} .. {np.degrees(e.high):7.2f}")
    for name, e in result.unknowns.items():
        k, _, unit = unknown_units(name)
        lines.append(f"{name:24s} {k * e.mean:.5g} (median {k * e.median:.5g})  "
                     f"[{k * e.low:.5g} .. {k * e.high:.5g}] {unit}".rstrip())
    if "errors" in summary:
        err = summary["errors"]
        lines.append("")
        lines.append(f"errors vs truth: proximal {err['proximal_deg_mean']:.2f} deg, distal "
                     f"{err['distal_deg_mean']:.2f} deg, contact "
                     f"{err.get('contact_mm_mean', float('nan')):.2f} mm; coverage "
                     f"{summary['coverage']:.2f} (within 0.1 deg: "
                     f"{summary.get('coverage_tolerant', float('nan')):.2f})")
        if summary.get("prior_coverage") is not None:
            share = summary["prior_coverage"]
            lines.append(f"the grasp prior's 95% intervals held {share:.0%} of the true "
                         "joints" + ("" if share >= PRIOR_COVERAGE_WARN else
                                     ": the guess (--nominal-theta-deg) or its spread "
                                     "(--prior-spread-deg) missed the grasp, and the answer "
                                     "leans on it"))
    lines.append(f"filter: {summary['timing']['filter_s_per_iteration_median']:.3f} s per "
                 "iteration (median)"
                 + {"gaussian": ", the jitter drawn on every dimension's values (gaussian)",
                    "log-scales": ", the jitter drawn on the scale unknowns' logarithms "
                                  "(log-scales)",
                    "copula": ", the jitter drawn on normal scores (copula)",
                    "copula-joints": ", the jitter drawn on the joints' normal scores "
                                     "(copula-joints)",
                    "copula-scales": ", the jitter drawn on the scale unknowns' normal "
                                     "scores (copula-scales)",
                    "copula-joints-scales": ", the jitter drawn on the joints' and the "
                                            "scale unknowns' normal scores "
                                            "(copula-joints-scales)"}.get(
                        summary.get("settings", {}).get("jitter_kernel"), ""))
    if summary.get("sigma"):
        turn = summary.get("sigma_turn_deg") or 0.0
        lines.append(f"likelihood: {summary['sigma'][0]:g} mm / {summary['sigma'][1]:g} deg"
                     + (f" + a {turn:g} deg turn in the grip" if turn else ""))
        settings = summary.get("settings", {})
        if settings.get("likelihood_dof"):
            lines.append(f"pose errors: Student t, {settings['likelihood_dof']:g} degrees of "
                         "freedom")
        if settings.get("sigma_tension_n"):
            noise = settings.get("tension_noise_n") or 0.0
            lines.append(f"tensions weighed at {settings['sigma_tension_n']:g} N"
                         + (f" (the sim's readings {noise:g} N noisy)" if noise else ""))
    if summary.get("limit_stiffness"):
        lines.append(f"joint stops: {summary['limit_stiffness']:g} N m/rad")
    if summary.get("ramp_time"):
        lines.append(f"the sim's command changes: ramped over {summary['ramp_time']:g} s")
    guess = summary.get("grasp_guess", {})
    if guess.get("contact_prior"):
        where = {"surface": "where the pads would touch the object's surface",
                 "pad": "about the pads' inner faces"}.get(guess["contact_prior"], "")
        lines.append(f"contact prior: {guess['contact_prior']} ({where}), "
                     f"{guess.get('contact_spread_deg', float('nan')):.1f} deg spread")
    return "\n".join(lines)

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

import numpy as np

# Below this share of true joints inside the grasp prior's intervals (scored against the
# sim's or the synthetic world's truth), the run's table says the guess missed the grasp.
PRIOR_COVERAGE_WARN = 0.5


class _HelpWithSettings(argparse.Action):
    """--help, then every --set key with its value on the chosen backend (`vlr.settings`):
    built only when asked for, since it imports the filter."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help=None):  # noqa: A002 (argparse's name)
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from vlr.settings import load_settings, settings_help

        backend = getattr(namespace, "backend", None) or "sim"
        parser.print_help()
        print(f"\nsettings (--set KEY=VALUE, or a --settings file), at the {backend} "
              f"backend's defaults (--backend X --help for another's):")
        print(settings_help(load_settings({"world.backend": backend})))
        parser.exit()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", add_help=False,
                       help="self-identify the hand-object system (joint angles, contacts, "
                       "unknown springs, link lengths, the object's mass)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-h", "--help", action=_HelpWithSettings,
                   help="show this help and every setting with its default")
    p.add_argument("--backend", help="sim (default) | synthetic | hardware "
                   "(world.backend)")
    p.add_argument("--object", help="object name or spec file (world.object; default apple)")
    p.add_argument("--hand", help="the hand the filter believes in (world.hand; default "
                   "modelo)")
    p.add_argument("--true-hand", help="sim or synthetic: the hand the world is built with, "
                   "e.g. nh1 (world.true_hand)")
    p.add_argument("--estimator", choices=("pf", "ukf"), help="pf: the particle filter "
                   "(default); ukf: the unscented Kalman filter on the same model "
                   "(filter.estimator)")
    p.add_argument("--particles", type=int, help="P (filter.particles; default 60000)")
    p.add_argument("--seed", type=int, help="seeds the world, the filter and the actions "
                   "(default 0)")
    p.add_argument("--unknown", action="append", default=[], metavar="SPEC",
                   help="an unknown to identify, repeatable (filter.unknowns): "
                   "stiffness:thumb.distal, length:left.proximal, tendon, mass, com:z, "
                   "curvature, ...")
    p.add_argument("--max-iterations", type=int, help="action budget (loop.max_iterations; "
                   "default 40)")
    p.add_argument("--config", help="hardware: the hand's YAML file (world.options.config)")
    p.add_argument("--settings", metavar="FILE", help="a YAML file of settings, nested or "
                   "dotted, as a sweep file's settings:")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any setting, e.g. --set filter.observation.sigma_tension_n=0.5 "
                   "(repeatable; the keys and defaults: --help)")
    p.add_argument("--out", default="runs/identify", help="output folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--view", action="store_true", help="serve a live 3D view of the particle "
                   "filter (meshcat; prints its URL; on 127.0.0.1 unless --view-host)")
    p.add_argument("--view-host", default="127.0.0.1", metavar="HOST",
                   help="the address the view's server listens on, e.g. 0.0.0.0 to serve it "
                   "to other machines, without authentication (default 127.0.0.1)")
    p.add_argument("--view-html", metavar="FILE", help="save the final 3D scene as a "
                   "standalone HTML page")
    p.set_defaults(func=run)


def settings_from_args(args: argparse.Namespace):
    """The settings tree of `vlr identify`'s arguments: the backend's defaults, the
    --settings file, the flags, then each --set (`vlr.settings.load_settings`)."""
    from vlr.settings import load_settings, parse_assignment, read_yaml_mapping

    file_layer = read_yaml_mapping(args.settings, "--settings") if args.settings else {}
    flags = {"world.backend": args.backend, "world.object": args.object,
             "world.hand": args.hand, "world.true_hand": args.true_hand,
             "filter.estimator": args.estimator, "filter.particles": args.particles,
             "seed": args.seed,
             "loop.max_iterations": args.max_iterations,
             "world.options.config": args.config}
    flags = {k: v for k, v in flags.items() if v is not None}
    if args.unknown:
        flags["filter.unknowns"] = list(args.unknown)
    sets = dict(parse_assignment(text) for text in args.set)
    return load_settings(file_layer, flags, sets)


def _open_view(args: argparse.Namespace, seed: int, model, hand_spec, obj_spec, truth):
    """The live view (`vlr.view`), only when asked for: meshcat is not even imported else."""
    import ipaddress

    from vlr.view import FilterView

    view = FilterView(model, obj=obj_spec, seed=seed, truth=truth,
                      palm_radius=hand_spec.palm_radius,
                      palm_thickness=hand_spec.palm_thickness, host=args.view_host)
    if args.view:
        print(f"view: {view.url}", flush=True)
        if not ipaddress.ip_address(view.host).is_loopback:
            print(f"view: listening on {view.host} (--view-host), reachable from the network "
                  "with no authentication", flush=True)
    return view


def _finish_view(view, args: argparse.Namespace) -> None:
    import sys

    if args.view_html:
        print(f"wrote {view.save_html(args.view_html)}")
    if args.view and sys.stdin.isatty():  # keep serving the final scene until the user is done
        input("view: press Enter to stop the viewer ")


def run(args: argparse.Namespace) -> int:
    from vlr.io import check_output_dir, check_output_file
    from vlr.plots import CloudRecorder, particle_cloud
    from vlr.run import run_identification

    settings = settings_from_args(args)
    # A bad --out or --view-html is one line now, not a traceback after the whole run.
    out = check_output_dir(args.out)
    if args.view_html:
        check_output_file(args.view_html, "--view-html")
    seed = settings.seed
    bar = None
    total = settings.loop.max_iterations

    def progress(rec) -> None:
        # The bar starts with the filter, so that a world that fails to open (a bad
        # hardware config) prints its one-line error alone.
        nonlocal bar
        if bar is None:
            from vlr.logs import progress_bar

            bar = progress_bar(args.quiet, total=total, desc="identify", unit="it")
        bar.set_postfix(ci_deg=f"{rec.ci_deg:.2f}", ess=f"{rec.ess:.0f}")
        if rec.iteration:
            bar.update(1)

    cloud = CloudRecorder(seed=seed)  # a small sample per iteration, for particles.png
    watchers: list = [cloud]

    def watch(pf, rec) -> None:
        for w in watchers:
            w(pf, rec)

    view = None

    def observe_through(w):
        nonlocal view
        if not (args.view or args.view_html):
            return w.observer
        view = _open_view(args, seed, w.model, w.hand_spec, w.object_spec, w.truth)
        watchers.append(view)
        return view.observing(w.observer)

    try:
        try:
            run = run_identification(settings, progress=progress, watch=watch,
                                     observe_through=observe_through)
        finally:
            if bar is not None:
                bar.close()
        run.write(out)
        result, summary, model, truths = run.result, run.summary, run.model, run.truths
        truth_at = ({r.iteration: t.theta for r, t in zip(result.history, truths, strict=True)}
                    if truths else None)
        what = ("sigma points" if settings.filter.estimator == "ukf" else "particle cloud")
        particle_cloud(out / "particles.png", cloud.snapshots, model.names, None, truth_at,
                       title=what)
        print(format_table(result, summary, model))
        print(f"\nwrote {out / 'result.json'}, {out / 'history.npz'}, "
              f"{out / 'convergence.png'}, {out / 'particles.png'}")
        if view is not None:  # after the results are safe on disk
            _finish_view(view, args)
    finally:
        if view is not None:
            view.close()  # always stop the meshcat server
    return 0


def format_model_check(check: dict) -> str:
    """The model check's one line (`vlr.model_check`)."""
    if check["verdict"] == "undecided":
        return (f"model check: undecided ({check['actions']} actions after the first "
                f"{check['burn_in']}, too few)")
    figure = (f"surprise {check['statistic']:.2f} over {check['actions']} actions, "
              f"threshold {check['threshold']:.2f}")
    if check["verdict"] == "consistent":
        return f"model check: the model explains the observations ({figure})"
    return (f"model check: the model does NOT explain the observations from action "
            f"{check['first_action_flagged']} on ({figure}): the intervals may miss the truth "
            f"(the remedy, wider likelihood scales: docs/IDENTIFY.md)")


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
                                     ": the guess (filter.guess_theta_deg) or its spread "
                                     "(filter.theta_spread_deg) missed the grasp, and the "
                                     "answer leans on it"))
    if summary.get("model_check"):
        lines.append(format_model_check(summary["model_check"]))
    lines.append(f"filter: {summary['timing']['filter_s_per_iteration_median']:.3f} s per "
                 "iteration (median)")
    if summary.get("estimator") == "ukf":
        lines[-1] = (f"filter: unscented Kalman filter, {summary['hypotheses']} sigma points, "
                     f"{summary['timing']['filter_s_per_iteration_median']:.3f} s per "
                     "iteration (median)")
    s = summary.get("settings", {})
    if s:
        turn = s.get("filter.observation.sigma_turn_deg") or 0.0
        lines.append(f"likelihood: {s['filter.observation.sigma_pos_mm']:g} mm / "
                     f"{s['filter.observation.sigma_rot_deg']:g} deg"
                     + (f" + a {turn:g} deg turn in the grip" if turn else ""))
        if s.get("filter.observation.sigma_tension_n"):
            noise = s.get("world.options", {}).get("tension_noise_n") or 0.0
            lines.append(f"tensions weighed at {s['filter.observation.sigma_tension_n']:g} N"
                         + (f" (the sim's readings {noise:g} N noisy)" if noise else ""))
        lines.append(f"contacts: {'rolling' if s['filter.motion.rolling'] else 'pinned'}; "
                     f"joint stops {s['filter.motion.limit_stiffness']:g} N m/rad; contact "
                     f"prior {s['filter.contact_prior']}, "
                     f"{s['filter.contact_spread_deg']:.1f} deg spread")
    return "\n".join(lines)

"""A joint cut at its stop under the filter's jitter, in one dimension (docs/RESULTS.md
section 5, session 39).

A one-off illustration, not part of the package. One static parameter (a distal joint's
angle, the stop at 0, the truth 2 degrees above it), a prior N(15, 10) cut at the stop, and
20 weak observations (each N(truth, 12) degrees: after 20 the posterior's sd is about 2.7,
as the sim's near-stop distal joints' are). Each step weighs, resamples (systematic) and
jitters the particles, then holds them at the stop, as the filter's settle does. Over
common data per trial it compares the posterior median's lean (median minus truth) with no
jitter (the exact posterior, up to resampling), with the Liu-West kernel on the values (the
filter's default) and on normal scores (`vlr.copula`, `--jitter-kernel copula`).

    python docs/scripts/stop_kernel_toy.py [--trials 40] [--particles 10000]
    python docs/scripts/stop_kernel_toy.py --timing     # the filter's draw, each kernel
"""

import argparse
import time

import numpy as np
from scipy import stats

from vlr.copula import NormalScores
from vlr.filter import JITTER_KERNELS, FilterConfig, ParticleFilter, systematic_resample
from vlr.kinematics import HandModel
from vlr.motion import ObjectParams
from vlr.spec import load_hand

H = 0.4  # the filter's jitter_h
A = np.sqrt(1.0 - H * H)


def liu_west(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return A * x + (1.0 - A) * x.mean() + H * x.std() * rng.standard_normal(len(x))


def on_scores(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    scores = NormalScores.fit(x[:, None])
    return scores.from_normal(liu_west(scores.to_normal(x[:, None])[:, 0], rng)[:, None])[:, 0]


def none(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return x


def timing(dims: int = 19, repeats: int = 5) -> None:
    """Median seconds of one filter draw (`ParticleFilter._kernel`) per kernel, on a
    correlated Gaussian set of `dims` columns (the known hand's 18 and one unknown, a
    spring: the one column `copula-scales` draws on its scores)."""
    model = HandModel.from_spec(load_hand("modelo"))
    rng = np.random.default_rng(0)
    for n in (10_000, 60_000):
        x = rng.normal(size=(n, dims)) @ rng.normal(size=(dims, dims))
        line = []
        for kernel in JITTER_KERNELS:
            pf = ParticleFilter(model, ObjectParams(mass=0.1, com=(0.0, 0.0, 0.0)),
                                FilterConfig(n_particles=n, jitter_kernel=kernel,
                                             unknowns=("stiffness:thumb.distal",)))
            ts = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                pf._kernel(x)
                ts.append(time.perf_counter() - t0)
            line.append(f"{kernel} {np.median(ts):.3f} s")
        print(f"{n} particles, {dims} dimensions, one draw (median of {repeats}): "
              + ", ".join(line))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--truth", type=float, default=2.0, help="degrees above the stop")
    ap.add_argument("--sigma", type=float, default=12.0, help="one observation's sd [deg]")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--timing", action="store_true", help="time the filter's draw instead")
    args = ap.parse_args()
    if args.timing:
        timing()
        return
    if args.trials < 1 or args.particles < 2 or args.steps < 1 or args.sigma <= 0:
        raise SystemExit("error: --trials, --steps >= 1, --particles >= 2, --sigma > 0")
    kernels = {"no jitter (the exact posterior)": none, "Liu-West on the values": liu_west,
               "Liu-West on normal scores": on_scores}
    data = np.random.default_rng(123)
    leans: dict[str, list[float]] = {k: [] for k in kernels}
    for _ in range(args.trials):
        ys = args.truth + data.normal(0.0, args.sigma, args.steps)
        x0 = np.maximum(data.normal(15.0, 10.0, args.particles), 0.0)
        for name, kernel in kernels.items():
            rng = np.random.default_rng(7)
            x = x0.copy()
            for y in ys:
                w = stats.norm.logpdf(y, x, args.sigma)
                w = np.exp(w - w.max())
                x = x[systematic_resample(w / w.sum(), rng)]
                x = np.maximum(kernel(x, rng), 0.0)
            leans[name].append(float(np.median(x) - args.truth))
    print(f"{args.trials} trials, truth {args.truth} deg above the stop, {args.steps} "
          f"observations of sd {args.sigma} deg, {args.particles} particles")
    for name, v in leans.items():
        v = np.array(v)
        se = v.std(ddof=1) / np.sqrt(len(v))
        print(f"{name}: median's lean {v.mean():+.2f} deg (se {se:.2f}), "
              f"mean |error| {np.abs(v).mean():.2f}")


if __name__ == "__main__":
    main()

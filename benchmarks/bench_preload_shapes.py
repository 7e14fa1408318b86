"""Cost of a preload with centerlines (issue 19): the shape tables over preloads, same process.

Run:  python benchmarks/bench_preload_shapes.py [--repeat 3] [--frames 22]

The simulated twig (three heights, ``--frames`` engaged frames per push) with 12 and 25 mm cut from the
start of two pushes. Its likelihood is built with the preload on the forces only (the reference: the
fit's `use_shapes=False`) and with the preload on forces and centerlines; the script prints the median
build time of each over ``--repeat`` builds, its ratio to the reference, and the time of one
log-likelihood evaluation over 64 walkers (median of 50) of each.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np
from bench_forward import _median_time as median_time  # noqa: E402  (benchmarks/ is the script's path)

import bayesrod
from bayesrod.dataset.simulate import started_loaded
from bayesrod.inference.likelihood import build_likelihood
from bayesrod.inference.priors import load_prior


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--frames", type=int, default=22)
    args = ap.parse_args()
    ds = started_loaded(
        bayesrod.simulate("twig", seed=3, config_overrides={"n_frames_engaged": args.frames}), (0.012, 0, 0.025)
    )
    pr = load_prior("woody")
    cases = {"preload, forces only (reference)": False, "preload with centerlines": True}
    liks, ref = {}, None
    for name, shapes in cases.items():
        t = median_time(
            lambda s=shapes, n=name: liks.__setitem__(n, build_likelihood(ds, pr, use_shapes=s, preload=True)),
            args.repeat,
        )
        ref = ref or t
        print(f"build {name:>34}: {t:7.2f} s  ({t / ref:5.1f}x)")
    rng = np.random.default_rng(0)
    W = 64
    for name, lik in liks.items():
        par = {"EI0": np.full(W, 2.63), "p": rng.uniform(0.3, 0.6, W), "sigma_force_N": np.full(W, 0.03)}
        par.update({"shape_sd_scale": np.ones(W), "sigma_shape_m": np.full(W, 1e-3)})
        par.update({n: rng.uniform(0.0, 0.03, W) for n in lik.preload_names})
        ts = [median_time(lambda lik=lik, par=par: lik.log_likelihood(par), 1) for _ in range(50)]
        print(f"log-likelihood, 64 walkers, {name:>34}: {1000 * statistics.median(ts):7.2f} ms")


if __name__ == "__main__":
    main()

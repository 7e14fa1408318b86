"""Cost of the nuisance tables (issue 19): a sampled stem length and contact-height errors, same process.

Run:  python benchmarks/bench_nuisance_tables.py [--repeat 3]

The likelihood of a three-height forces-only dataset (the simulated twig, heights 0.36,
0.48, 0.60 m) is built plain (the reference), with a sampled length, with height errors,
and with both; the script prints the median build time of each over ``--repeat`` builds
and its ratio to the plain build. It also prints the time of one log-likelihood
evaluation over 64 walkers (median of 50) for the plain and the full-nuisance model.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np
from bench_forward import _median_time as median_time  # noqa: E402  (benchmarks/ is the script's path)

import bayesrod
from bayesrod.inference.likelihood import build_likelihood
from bayesrod.inference.priors import load_prior


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    ds = bayesrod.simulate("twig", seed=1, heights_m=[0.36, 0.48, 0.60], config_overrides={"n_frames_engaged": 2})
    pr = load_prior("woody")
    cases = {
        "plain (reference)": {},
        "length unknown": {"length": "unknown"},
        "height sd 3 mm": {"height_sd_m": 0.003},
        "length + height": {"length": "unknown", "height_sd_m": 0.003},
    }
    ref = None
    liks = {}
    for name, kw in cases.items():
        t = median_time(
            lambda kw=kw, name=name: liks.__setitem__(name, build_likelihood(ds, pr, use_shapes=False, **kw)),
            args.repeat,
        )
        ref = ref or t
        print(f"build {name:>20}: {t:7.2f} s  ({t / ref:5.1f}x)")
    rng = np.random.default_rng(0)
    for name in ("plain (reference)", "length + height"):
        lik = liks[name]
        W = 64
        par = {"EI0": np.full(W, 2.63), "p": rng.uniform(0.3, 0.6, W), "sigma_force_N": np.full(W, 0.01)}
        if name != "plain (reference)":
            par["length_m"] = rng.uniform(0.7, 0.9, W)
            par.update({n: rng.normal(0, 0.003, W) for n in lik.height_names})
        ts = [median_time(lambda lik=lik, par=par: lik.log_likelihood(par), 1) for _ in range(50)]
        print(f"log-likelihood, 64 walkers, {name:>20}: {1000 * statistics.median(ts):7.2f} ms")


if __name__ == "__main__":
    main()

"""Cost of pooling the conditions' noise correlations in ``fit_group`` (issue 23), same process.

Run:  python benchmarks/bench_group_pool.py [--repeat 41]

A four-condition two-height series (the twig, intact and three cuts, AR(1) force noise rho 0.9), 224 walkers
near the start point: ``GroupPosterior.log_prob`` and ``log_prior`` with one correlation per condition (the
reference) and pooled (the default since session 47), interleaved; medians over ``--repeat`` evaluations and
their ratio.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import bayesrod
from bayesrod.inference.group import GroupLikelihood, GroupPosterior, start_point
from bayesrod.inference.priors import load_prior
from bayesrod.physics import k_x


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=41)
    a = ap.parse_args()
    kx = float(k_x(0.55, 2.63, 0.43, 0.8))

    def kb(r):
        return kx * 0.55**2 * r / (1 - r)

    conds = {"intact": math.inf, "cut1": kb(0.88), "cut2": kb(0.64), "cut3": kb(0.49)}
    dss = bayesrod.simulate_group(
        "twig",
        conditions=conds,
        heights_m=[0.45, 0.65],
        seed=1,
        noise_rho=0.9,
        config_overrides={"n_frames_engaged": 2},
    )
    specs = {d.extra["condition"]: d for d in dss}
    pr = load_prior("woody")
    own = GroupLikelihood(specs, pr)
    posts = {"per condition": GroupPosterior(own)}
    posts["pooled"] = GroupPosterior(GroupLikelihood(specs, pr, pooled=("rho_force",), _liks=own.liks))
    t0 = start_point(posts["per condition"])
    theta = t0 + 1e-3 * np.random.default_rng(0).standard_normal((224, t0.size))
    times = {(k, f): [] for k in posts for f in ("log_prob", "log_prior")}
    for _ in range(a.repeat):
        for k, post in posts.items():
            for f in ("log_prob", "log_prior"):
                t = time.perf_counter()
                getattr(post, f)(theta)
                times[k, f].append(time.perf_counter() - t)
    med = {key: float(np.median(v)) for key, v in times.items()}
    for f in ("log_prob", "log_prior"):
        ref, new = med["per condition", f], med["pooled", f]
        print(f"{f} of 224 walkers: per condition {1e3 * ref:.2f} ms, pooled {1e3 * new:.2f} ms, ratio {new / ref:.2f}")


if __name__ == "__main__":
    main()

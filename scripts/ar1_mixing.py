"""How the AR(1) noise's sampling coordinates change a fit's mixing (docs/inference.md, correlated noise).

Each simulated two-height twig with AR(1) force noise is fitted twice with the same seed: with the noise
sampled by its marginal sd (log sigma, rho; the coordinates before 2026-11-26) and by its innovation sd
(log sigma sqrt(1 - rho^2), rho; the current ones). The target density is the same; printed per fit: steps
run, R-hat max, bulk ESS min, wall time and the 90% intervals.

    python scripts/ar1_mixing.py --seeds 3,5,7
"""

from __future__ import annotations

import argparse
import time

import bayesrod
from bayesrod.inference.priors import ParameterSpace


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="3,5,7")
    ap.add_argument("--heights", default="0.45,0.6", help="contact heights [m] of the simulated twig")
    ap.add_argument("--noise-rho", type=float, default=0.9)
    ap.add_argument("--max-steps", type=int, default=8000)
    args = ap.parse_args(argv)
    heights = [float(v) for v in args.heights.split(",")]
    current = ParameterSpace.noise_pairs
    print("| seed | coordinates | steps | R-hat max | ESS min | time [s] | EI0 [q05, q95] | p [q05, q95] | rho |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in (int(v) for v in args.seeds.split(",")):
        ds = bayesrod.simulate("twig", seed=seed, noise_rho=args.noise_rho, heights_m=heights)
        for label, pairs in (("marginal sd", lambda self: []), ("innovation sd", current)):
            ParameterSpace.noise_pairs = pairs
            try:
                t = time.perf_counter()
                post = bayesrod.fit(
                    ds, seed=seed, progress=False, use_shapes=False, force_noise="ar1", max_steps=args.max_steps
                )
                dt = time.perf_counter() - t
            finally:
                ParameterSpace.noise_pairs = current
            d = post.doc
            c = d["convergence"]
            q = {k: d["parameters"][k] for k in ("EI0", "p", "rho_force")}
            iv = {k: f"[{v['q05']:.4f}, {v['q95']:.4f}]" for k, v in q.items()}
            print(
                f"| {seed} | {label} | {d['sampler']['steps']} | {c['rhat_max']:.4f} | {c['ess_bulk_min']:.0f} | "
                f"{dt:.1f} | {iv['EI0']} | {iv['p']} | {iv['rho_force']} |",
                flush=True,
            )


if __name__ == "__main__":
    main()

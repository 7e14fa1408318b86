"""How much emcee 3.1.6's biased DESnookerMove changed a fit's intervals (docs/inference.md, Sampling).

The same dataset is fitted twice with the same seed: with the samplers' mix as it was before 2026-11-25
(80% DEMove, 20% emcee's DESnookerMove) and as it is (80% DEMove, 20% bayesrod's corrected snooker).
Printed: each parameter's median and 90% interval from both, and the ratio of the interval widths.
Forces only at one height by default (the most skewed posterior of the common cases); ``--heights``
takes a comma list.

    python scripts/snooker_effect.py --seeds 1,2,3 --heights 0.5
    python scripts/snooker_effect.py --seeds 3 --heights 0.45,0.6 --noise-rho 0.9 --force-noise ar1 --max-steps 6000
"""

from __future__ import annotations

import argparse

import emcee
import numpy as np

import bayesrod
import bayesrod.inference.moves as moves


def emcee_moves() -> list:
    """The samplers' mix before 2026-11-25: emcee's own (biased) DESnookerMove."""
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--heights", default="0.5", help="contact heights [m] of the simulated twig")
    ap.add_argument("--preset", default="twig")
    ap.add_argument("--noise-rho", type=float, default=0.0, help="the simulated force noise's AR(1) correlation")
    ap.add_argument("--force-noise", choices=["iid", "ar1"], default="iid", help="the fit's force noise")
    ap.add_argument("--max-steps", type=int, default=8000)
    ap.add_argument("--fit-seed", type=int, default=None, help="the fits' seed (default: the dataset's)")
    args = ap.parse_args(argv)
    corrected = moves.default_moves
    heights = [float(v) for v in args.heights.split(",")]
    print("| seed | parameter | biased: median [q05, q95] | corrected: median [q05, q95] | width ratio |")
    print("|---|---|---|---|---|")
    for seed in (int(v) for v in args.seeds.split(",")):
        ds = bayesrod.simulate(args.preset, seed=seed, noise_rho=args.noise_rho, heights_m=heights)
        out = {}
        for name, mv in (("biased", emcee_moves), ("corrected", corrected)):
            moves.default_moves = mv
            try:
                post = bayesrod.fit(
                    ds,
                    seed=seed if args.fit_seed is None else args.fit_seed,
                    progress=False,
                    use_shapes=False,
                    force_noise=args.force_noise,
                    max_steps=args.max_steps,
                )
            finally:
                moves.default_moves = corrected
            out[name] = post.doc["parameters"] | {"R-hat": post.doc["convergence"]["rhat_max"]}
        print(f"| {seed} | R-hat | {out['biased']['R-hat']:.4f} | {out['corrected']['R-hat']:.4f} | |")
        for par in ("EI0", "p", "sigma_force_N", "rho_force"):
            if par not in out["biased"]:
                continue
            a, b = out["biased"][par], out["corrected"][par]
            ratio = (b["q95"] - b["q05"]) / (a["q95"] - a["q05"])
            print(
                f"| {seed} | {par} | {a['median']:.4g} [{a['q05']:.4g}, {a['q95']:.4g}] | "
                f"{b['median']:.4g} [{b['q05']:.4g}, {b['q95']:.4g}] | {ratio:.3f} |",
                flush=True,
            )


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()

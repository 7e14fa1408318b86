"""Misrecorded contact heights in the diagnosis (docs/diagnose.md, "Contact heights known to a few mm").

Three pushes recorded at 0.30, 0.45 and 0.60 m whose forces are the physics (``force_from_displacement``)
at heights off by ``--errors`` mm, with AR(1) force noise (rho 0.9, marginal sd 4 mN), forces only;
diagnosed with the heights held (``height_sd_m`` 0) and with their errors fitted (``--sd``).

Usage::

    python scripts/diagnose_height_error.py --errors 6,-5,4 --sd 0.003 --workers 2
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bayesrod
from bayesrod.dataset.simulate import ar1_noise
from bayesrod.inference.diagnose import ForwardModel, diagnose
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import force_from_displacement

EI0, P, L = 2.63, 0.43, 0.80
HEIGHTS = (0.30, 0.45, 0.60)


def dataset(errors_m, sigma=0.004, rho=0.9, n=60, seed=0) -> bayesrod.Dataset:
    rng = np.random.default_rng(seed)
    D, F = [], []
    for h, dh in zip(HEIGHTS, errors_m, strict=True):
        d = np.linspace(0.0, 0.15 * h / 0.4, n)
        F.append(force_from_displacement(d, h + dh, EI0, P, L).force_N + ar1_noise(rng, sigma, rho, n))
        D.append(d)
    return bayesrod.Dataset.from_arrays(length_m=L, height_m=list(HEIGHTS), displacement_m=D, force_N=F)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--errors", default="6,-5,4", help="true minus recorded height per push [mm]")
    ap.add_argument("--sd", type=float, default=0.003, help="the diagnosis' height_sd_m [m]")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    errors = [float(v) / 1000 for v in args.errors.split(",")]
    data = prepare_data(dataset(errors), use_shapes=False)
    print("| height_sd_m | added | unexplained | EI0 | p | height errors [mm] | held-out before -> after [N] | s |")
    for sd in (0.0, args.sd):
        t0 = time.perf_counter()
        r = diagnose(ForwardModel(data, L, height_sd_m=sd), workers=args.workers)
        f = r["fitted"]
        dh = ", ".join(f"{1000 * v:+.1f}" for v in f.get("height_error_m", []))
        b, a = r["before"]["heldout_force_rmse_N"], r["after"]["heldout_force_rmse_N"]
        print(
            f"| {sd:g} | {', '.join(r['added_effects']) or 'none'} | {r['unexplained_structure']} | "
            f"{f['EI0']:.4g} | {f['p']:.3g} | {dh} | {b:.3g} -> {a:.3g} | {time.perf_counter() - t0:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()

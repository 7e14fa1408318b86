"""The stem-length table axis against exact solves: the MLE shift it adds, in Laplace sds (issue 21).

    python scripts/table_length_shift.py [--factors 1,1.02,1.04] [--workers 2]

A fit told that the stem length is unknown (``length="unknown"``) reads its forces from geometry tables with a
length axis (``LENGTH_NODES`` nodes uniform in log L over the length prior, ``GEOMETRY_N_F`` solves per curve),
not from the plain tables. Here scripts/table_accuracy.py's noise-free twig (three heights, every force an exact
solve at the true length L, each push taken to its slip) is declared ``factor`` x L long for each factor given,
which moves the nodes of the default length prior (uniform from the larger of L_declared / 1.5 and 1.05 x the
highest contact to 1.5 L_declared) past the truth: each line says where the truth falls, in node steps. The table
likelihood is maximised over (log EI0, p, L) with the force sd held at 0.03 N
(:func:`bayesrod.api.calibration.mle_shift`, as for the effect axes) and its shift from the truth divided by the
Laplace sd. Forces only (the geometry tables are). Prints one line per factor; writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from bayesrod.api._common import as_dataset
from bayesrod.api.calibration import mle_shift
from bayesrod.api.data import simulate
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference import likelihood as LK
from bayesrod.inference.priors import load_prior


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", default="1,1.02,1.04", help="declared length over the true one, comma separated")
    ap.add_argument("--workers", type=int, default=1, help="processes building the tables (the same tables)")
    a = ap.parse_args(argv)
    ds = as_dataset(simulate("twig", seed=1, noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0)))
    truth = {"EI0": ds.extra["truth"]["EI0"], "p": ds.extra["truth"]["p"], "length_m": ds.length_m}
    for factor in (float(x) for x in a.factors.split(",")):
        t = time.perf_counter()
        told = dataclasses.replace(ds, length_m=ds.length_m * factor)
        with LK.table_workers(a.workers, progress=True):
            lik = LK.build_likelihood(told, load_prior("woody"), (), use_shapes=False, length="unknown")
        g = np.log(lik.L_grid)
        at = (np.log(ds.length_m) - g[0]) / (g[1] - g[0])  # the truth's place on the axis, in node steps
        out = mle_shift(lik, truth)
        nodes = f"{lik.L_grid.size} nodes {lik.L_grid[0]:.4f}-{lik.L_grid[-1]:.4f} m"
        sd = np.array2string(out["laplace_sd"], precision=3)
        print(
            f"length {told.length_m:.4f} m declared for {ds.length_m} m ({nodes}, the truth at node {at:.2f}): "
            f"shift [sd] of log EI0, p, length: {np.round(out['shift_in_sd'], 3).tolist()} (Laplace sd {sd}); "
            f"{time.perf_counter() - t:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()

"""How much do correlated centerline errors inflate the variance of the p-score? (docs/vision.md)

    bayesrod extract SIMULATED_WITH_FRAMES --out EXTRACTED
    python scripts/shape_score_blocks.py EXTRACTED

At the posterior mode of the plain model, the per-point contributions to the
score of p (standardised shape residual x d x_pred / d p) are summed over
blocks of 1, 2, 4, 8, 11 and 22 consecutive frames of a push; the sum of the
squared block sums over the independent-point information H is the variance
inflation J/H (about 1 for independent points). Printed beside the separable
estimate 1 / shape_weight that ``bayesrod fit`` uses.
"""

from __future__ import annotations

import argparse

import numpy as np

from bayesrod.dataset import read_dataset
from bayesrod.inference.likelihood import LogPosterior, RodLikelihood, effective_shape_weight
from bayesrod.inference.priors import load_prior
from bayesrod.inference.sampler import find_start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    args = ap.parse_args()
    lik = RodLikelihood(read_dataset(args.dataset))
    if lik.sd_obs is None:
        raise SystemExit("shape_score_blocks: expected centerlines with sd_m (from bayesrod extract)")
    post = LogPosterior(lik, load_prior(None))
    theta = find_start(post, np.random.default_rng(0))
    mode = {k: float(v[0]) for k, v in post.to_natural(theta[None]).items()}
    r = lik.residuals({k: np.atleast_1d(v) for k, v in mode.items()})["shape"][0] / lik.sd_obs
    h = 1e-3
    # minus the residual's derivative in p: the model's normal offset moves opposite to the residual
    up, down = (lik.shape_offsets(np.array([mode["p"] + s])) for s in (h, -h))
    d = -(up - down)[0] / (2 * h) / lik.sd_obs
    g, H = r * d, np.sum(d**2) * np.mean(r**2)
    print(f"mode: EI0 {mode['EI0']:.4g}, p {mode['p']:.4g}")
    for size in (1, 2, 4, 8, 11, 22):
        key = lik.point_push * 100000 + lik.point_frame // size
        sums = np.array([g[key == k].sum() for k in np.unique(key)])
        print(f"blocks of {size:2d} frames ({sums.size:3d} blocks): J/H = {np.sum(sums**2) / H:.3g}")
    w = effective_shape_weight(lik, mode)
    print(f"separable estimate: 1 / weight = {1 / w['weight']:.3g} (tau {w['tau_along']:.3g} x {w['tau_frames']:.3g})")


if __name__ == "__main__":
    main()

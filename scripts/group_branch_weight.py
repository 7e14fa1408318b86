"""Is the soft-intact branch of fit_group weighted as the posterior says? (issue 23, docs/validation.md)

Run:  python scripts/group_branch_weight.py 7 4      # replicates of scripts/group_study.py (two heights)
      python scripts/group_branch_weight.py 1 2 4 --heights 0.55 [--jump 8]   # one height

Each replicate is simulated and fitted as group_study.py does (fit_group, prior woody, AR(1) noise,
5000 steps at most, seed = replicate). The intact condition's draws are read as v: u on the soft side
(u = 0.005 z for the sampled z > 0) and U_MAX z on the clamp (z in [-1, 0] -> v in [-0.9, 0]). Under
the prior (1/2 on the clamp, u uniform on (0, 0.9]) v is uniform on [-0.9, 0.9]; its posterior density
is flat on [-0.9, 0] and continuous at 0, so if the sampler
weighs the soft branch (v > 0) right, the density of the draws just above 0 matches the density just
below it. Printed: both densities over windows of 0.002-0.02, the soft fraction, EI0 on each branch, and
the 95% quantile of EI0 from the clamp draws alone.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import group_study as G

import bayesrod
from bayesrod.inference.group import U_MAX, clamp_or_u

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("replicates", nargs="+", type=int)
ap.add_argument("--heights", default="0.45,0.65", help="contact heights [m], comma separated (group_study's)")
ap.add_argument("--max-steps", type=int, default=5000)
ap.add_argument("--target-ess", type=int, default=200)
ap.add_argument(
    "--jump",
    type=float,
    default=0.0,
    help="experiment (session 29, not in the library): add, at weight 0.1, a Metropolis-Hastings move that swaps "
    "one condition's z between the clamp [-1, 0] and the soft arm (0, JUMP], uniform on each side",
)
args = ap.parse_args()
heights = [float(h) for h in args.heights.split(",")]


def use_jump_move(dss, reach: float) -> None:
    """Replace the samplers' moves by DE 0.7, snooker 0.2 and the clamp/soft swap 0.1 (see --jump)."""
    from emcee.moves import DEMove, MHMove

    import bayesrod.inference.moves as M
    from bayesrod.inference.group import Z_CLAMP, GroupLikelihood, GroupPosterior
    from bayesrod.inference.priors import load_prior

    post = GroupPosterior(GroupLikelihood({d.extra["condition"]: d for d in dss}, load_prior("woody")))
    zidx = np.array(post._z_idx)

    def swap(x, random):
        n = x.shape[0]
        q = x.copy()
        j = zidx[random.randint(len(zidx), size=n)]
        z = x[np.arange(n), j]
        clamp = z <= 0
        within = clamp | (z <= reach)
        new = np.where(clamp, random.uniform(0, reach, n), random.uniform(-Z_CLAMP, 0, n))
        q[np.arange(n), j] = np.where(within, new, z)
        # log q(x | x') - log q(x' | x): uniform on each side
        lf = np.where(clamp, np.log(reach / Z_CLAMP), np.log(Z_CLAMP / reach))
        return q, np.where(within, lf, 0.0)

    M.default_moves = lambda: [(DEMove(), 0.7), (M.SnookerMove(), 0.2), (MHMove(swap), 0.1)]


for rep in args.replicates:
    dss, EI0, _, _ = G.replicate_data(rep, "base", heights, stride=1)  # the replicates as session 36 read them
    if args.jump > 0:
        use_jump_move(dss, args.jump)
    g = bayesrod.fit_group(
        list(dss),
        prior="woody",
        progress=False,
        target_ess=args.target_ess,
        max_steps=args.max_steps,
        seed=rep,
        sharing=False,
    )
    z = np.asarray(g.samples["z_base__intact"])
    v = np.where(z > 0, clamp_or_u(z), U_MAX * z)
    e = np.asarray(g.samples["EI0"])
    q05, q95 = np.quantile(e, [0.05, 0.95])
    print(f"rep {rep} (heights {heights}): R-hat max {g.doc['convergence']['rhat_max']:.3f}")
    print(f"rep {rep}: EI0 true {EI0:.4f} interval [{q05:.4f}, {q95:.4f}] covered {q05 <= EI0 <= q95}; n {v.size}")
    print(f"  P(v > 0) = {np.mean(v > 0):.4f}")
    for w in (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02):
        below = np.mean((v > -w) & (v <= 0)) / w
        above = np.mean((v > 0) & (v < w)) / w
        print(f"  density of v on [-{w}, 0]: {below:.3f}, on (0, {w}): {above:.3f}")
    print(f"  density of v on [-0.9, 0] (flat): {np.mean(v <= 0) / 0.9:.3f}")
    if (v > 0).any():
        soft = np.quantile(v[v > 0], [0.5, 0.9, 1])
        print(f"  EI0 median clamp {np.median(e[v <= 0]):.4f}, soft {np.median(e[v > 0]):.4f}; soft v quantiles {soft}")
    print(f"  EI0 q95 of the clamp draws alone {np.quantile(e[v <= 0], 0.95):.4f}", flush=True)

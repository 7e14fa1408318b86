"""Per-condition load-cell offsets sampled or marginalised: how fast a one-height group posterior mixes (issue 23).

    python scripts/brace_root_tables.py --out tables
    bayesrod import table tables/stalk7_*.csv --out ds --time "Time (s)" --force-column "Load (N)" \\
        --displacement "Position (mm)" --displacement-unit mm --metadata tables/meta.csv
    python scripts/group_offset_marginal.py ds --offsets sampled        # as fit-group --force-offsets does
    python scripts/group_offset_marginal.py ds --offsets marginalised   # each offset integrated out exactly

Both fit the same posterior of the stem and the anchorage (default prior, AR(1) noise, the one-height
coordinates of `fit_group`) for exactly ``--steps`` steps from the same start and seed, and print ArviZ's rank
R-hat and bulk ESS per sampled coordinate (walkers as chains) and the 90% intervals. Marginalised: each
condition's offset, N(0, sd 5% of its peak force) as in `GroupLikelihood`, is integrated out of the AR(1)
likelihood in closed form (`shared_error_loglik` with a constant column), so it is not a sampled coordinate.
About 2.5 minutes of one core each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bayesrod.api._common import as_dataset
from bayesrod.inference.group import GroupLikelihood, GroupPosterior, base_compliance, clamp_or_u, start_point
from bayesrod.inference.likelihood import shared_error_loglik
from bayesrod.inference.priors import load_prior
from bayesrod.inference.sampler import diagnostics, run_ensembles


def marginalise_offsets(lik: GroupLikelihood) -> None:
    """Replace each condition's force likelihood by its integral over a N(0, (5% of the peak)^2) offset."""
    for L1 in lik.liks.values():
        if L1.slip or L1.force_noise != "ar1":
            raise ValueError("expected AR(1) force noise without the slip term")
        sd = 0.05 * float(np.max(np.abs(L1.F_obs)))

        def ll(params, L1=L1, sd=sd):
            r = L1.residuals(params)["force"]
            s = np.atleast_1d(params["sigma_force_N"])[:, None]
            rho = np.atleast_1d(params["rho_force"])[:, None]
            return shared_error_loglik(r, s, rho, L1.F_first, [np.full(r.shape, sd)])

        L1.log_likelihood = ll


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, help="a folder of one stem's datasets (one per condition)")
    ap.add_argument("--offsets", choices=("sampled", "marginalised"), required=True)
    ap.add_argument("--steps", type=int, default=6000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    dss = [as_dataset(d) for d in sorted(p for p in a.datasets.iterdir() if (p / "specimen.json").is_file())]
    sampled = a.offsets == "sampled"
    lik = GroupLikelihood({d.extra["condition"]: d for d in dss}, load_prior("default"), force_offsets=sampled)
    if not sampled:
        marginalise_offsets(lik)
    post = GroupPosterior(lik)
    theta0 = post.settle_base_coordinates(start_point(post))
    t0 = time.process_time()
    res = run_ensembles(
        post, theta0, seed=a.seed, progress=False, max_steps=a.steps, min_steps=a.steps, target_ess=1e12
    )
    print(f"{a.offsets}: {res.n_steps} steps, {time.process_time() - t0:.0f} s of CPU")
    d = diagnostics(res.chain, post.names)
    for n in post.names:
        print(f"{n:28s} R-hat {d['rhat'][n]:.3f}  bulk ESS {d['ess_bulk'][n]:.0f}")
    nat = post.to_natural(res.chain.reshape(-1, post.ndim))
    for n in ("EI0", "p"):
        print(n, np.round(np.quantile(nat[n], [0.05, 0.5, 0.95]), 4))
    for c in lik.conditions:
        per = lik.condition_params(nat, c)
        C = base_compliance(clamp_or_u(nat[lik.local[c]["z_base"]]), per["EI0"], lik.liks[c].L)
        print(f"base compliance {c}", np.round(np.quantile(C, [0.05, 0.5, 0.95]), 7))


if __name__ == "__main__":
    main()

"""Per-condition load-cell offsets sampled or marginalised: how fast a one-height group posterior mixes (issue 23).

    python scripts/brace_root_tables.py --out tables
    bayesrod import table tables/stalk7_*.csv --out ds --time "Time (s)" --force-column "Load (N)" \\
        --displacement "Position (mm)" --displacement-unit mm --metadata tables/meta.csv
    python scripts/group_offset_marginal.py ds --offsets sampled        # as fit-group had it before session 35
    python scripts/group_offset_marginal.py ds --offsets marginalised   # integrated out, as fit-group does now

Both fit the same posterior of the stem and the anchorage (default prior, AR(1) noise, the one-height
coordinates of `fit_group`) for exactly ``--steps`` steps from the same start (`start_point` of the integrated
model; the sampled offsets at their conditional means there) and seed, and print ArviZ's rank
R-hat and bulk ESS per sampled coordinate (walkers as chains) and the 90% intervals. Marginalised: each
condition's offset, N(0, sd 5% of its peak force), is integrated out of the AR(1) likelihood in closed form
(`GroupLikelihood(force_offsets=True)`, `RodLikelihood.offset_prior_sd`); sampled: it is a coordinate.
About 2.5 minutes of one core each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bayesrod.api._common import as_dataset
from bayesrod.inference.group import (
    OFFSET_PRIOR_PEAK,
    GroupLikelihood,
    GroupPosterior,
    base_compliance,
    clamp_or_u,
    condition_name,
    start_point,
)
from bayesrod.inference.priors import ParamPrior, load_prior
from bayesrod.inference.sampler import diagnostics, run_ensembles


class SampledOffsets(GroupLikelihood):
    """The group likelihood with each condition's offset a sampled parameter (as fit_group had it before
    session 35): ``force_offset_N__<condition>``, prior N(0, sd OFFSET_PRIOR_PEAK x the peak force), after the
    condition's other nuisances."""

    def __init__(self, specs, prior):
        super().__init__(specs, prior)
        for c in self.conditions:
            name = condition_name("force_offset_N", c)
            sd = OFFSET_PRIOR_PEAK * float(np.max(np.abs(self.liks[c].F_obs)))
            self.local[c]["force_offset"] = name
            self.priors[name] = ParamPrior(name, "normal", (0.0, sd), "N")
        stem = list(self.shared)
        self.names = stem + [n for c in self.conditions for n in self.local[c].values() if n not in stem]

    def condition_params(self, params: dict, c: str) -> dict:
        return {**super().condition_params(params, c), "force_offset": params[self.local[c]["force_offset"]]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, help="a folder of one stem's datasets (one per condition)")
    ap.add_argument("--offsets", choices=("sampled", "marginalised"), required=True)
    ap.add_argument("--steps", type=int, default=6000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    dss = [as_dataset(d) for d in sorted(p for p in a.datasets.iterdir() if (p / "specimen.json").is_file())]
    specs, prior = {d.extra["condition"]: d for d in dss}, load_prior("default")
    marginal = GroupLikelihood(specs, prior, force_offsets=True)  # what fit_group --force-offsets samples
    start = GroupPosterior(marginal)
    theta0 = start_point(start)
    if a.offsets == "marginalised":
        post = start
    else:  # the same start, each offset at its conditional mean there
        post = GroupPosterior(SampledOffsets(specs, prior))
        nat = start.to_natural(theta0)
        for c in marginal.conditions:
            mean = marginal.liks[c].offset_posterior(marginal.condition_params(nat, c))[0]
            nat[post.likelihood.local[c]["force_offset"]] = mean
        theta0 = post.to_sample(nat)[0]
    theta0 = post.settle_base_coordinates(theta0)
    t0 = time.process_time()
    res = run_ensembles(
        post, theta0, seed=a.seed, progress=False, max_steps=a.steps, min_steps=a.steps, target_ess=1e12
    )
    print(f"{a.offsets}: {res.n_steps} steps, {time.process_time() - t0:.0f} s of CPU")
    d = diagnostics(res.chain, post.names, n_ensembles=res.n_ensembles)
    for n in post.names:
        print(f"{n:28s} R-hat {d['rhat'][n]:.4f} (walkers {d['rhat_walkers'][n]:.3f})  bulk ESS {d['ess_bulk'][n]:.0f}")
    nat = post.to_natural(res.chain.reshape(-1, post.ndim))
    for n in ("EI0", "p"):
        print(n, np.round(np.quantile(nat[n], [0.05, 0.5, 0.95]), 4))
    lik = post.likelihood
    for c in lik.conditions:
        per = lik.condition_params(nat, c)
        C = base_compliance(clamp_or_u(nat[lik.local[c]["z_base"]]), per["EI0"], lik.liks[c].L)
        print(f"base compliance {c}", np.round(np.quantile(C, [0.05, 0.5, 0.95]), 7))


if __name__ == "__main__":
    main()

"""How much of the noise correlation is the prior's: power-scaling sensitivity on group fits (issue 23).

    python scripts/correlation_sensitivity.py [--cases 5:0.55:1 1:0.55:1 0:0.45,0.65:4]

Each case ``rep:heights:stride`` is ``scripts/group_study.py``'s replicate ``rep`` (the anchorage changed,
rho 0.9, simulate_group's seed rep x stride; stride 1 is the seeding before session 51) fitted as
``fit_group`` fits it (pooled correlations, seed rep). Printed per case: each condition's rho interval, the
sensitivities summary.json reports (``identifiability.correlation_prior_sensitivity``: the correlations'
prior as a density in rho) and, on the same draws, the sensitivity of rho to the parts of that prior: the
factor 1/(1 - rho^2) (the normal on atanh(rho) written in rho), the population about the centre, the
centre's prior (both as densities in atanh(rho)), and the file's arcsine per condition (the unpooled prior).
About 4 minutes a case on one core.
"""

from __future__ import annotations

import argparse

import numpy as np
from group_study import replicate_data

from bayesrod.api.group import correlation_sensitivity, sensitivity_draws
from bayesrod.inference.group import POOL_SPREAD, GroupLikelihood, GroupPosterior, start_point
from bayesrod.inference.priors import load_prior
from bayesrod.inference.sampler import run_ensembles
from bayesrod.inference.summary import prior_sensitivity


def _num(v: dict | None, side: str) -> str:
    """A sensitivity to 3 decimals, or null (none reported: a clamp's compliance with too few soft draws)."""
    return "null" if v is None or v.get(side) is None else f"{v[side]:.3f}"


def one(rep: int, heights: list[float], stride: int) -> None:
    dss, *_ = replicate_data(rep, "base", heights, 0.9, stride)
    lik = GroupLikelihood({d.extra["condition"]: d for d in dss}, load_prior("woody"), pooled=("rho_force",))
    post = GroupPosterior(lik)
    theta0 = post.settle_base_coordinates(start_point(post))
    res = run_ensembles(post, theta0, seed=rep, progress=False, max_steps=5000, target_ess=400)
    sens = correlation_sensitivity(post, res.chain, res.log_prob)
    print(f"replicate {rep}, heights {heights}, seed stride {stride}:")
    nat, ll, lp_rho = sensitivity_draws(post, res.chain, res.log_prob)  # the draws the numbers above read
    names = [lik.local[c]["rho_force"] for c in lik.conditions]
    rho = np.stack([nat[n] for n in names])
    for c, r in zip(lik.conditions, rho, strict=True):
        q = np.quantile(r, [0.05, 0.5, 0.95])
        print(f"  rho {c:7s} {q[1]:.3f} [{q[0]:.3f}, {q[2]:.3f}]")
    for q in ("rho_force", "sigma_force_N", "base_compliance_rad_per_Nm"):
        for side in ("prior", "likelihood"):  # a clamp with too few soft draws reports null (summary.json's null)
            cells = " ".join(f"{c} {_num(v, side)}" for c, v in sens[q].items())
            print(f"  {q if side == 'prior' else '':27s} {side}", cells)
    print(f"  EI0 prior {sens['EI0']['prior']:.3f} likelihood {sens['EI0']['likelihood']:.3f}")
    z = np.arctanh(rho)
    jac = -np.sum(np.log1p(-(rho**2)), axis=0)
    pop = -np.sum((z - z.mean(axis=0)) ** 2, axis=0) / (2 * POOL_SPREAD**2)
    parts = {
        "1/(1 - rho^2)": jac,
        "population (z)": pop,
        "centre (z)": lp_rho - jac - pop,
        "own arcsine": sum(lik.priors[n].logpdf_sample(nat[n]) for n in names),
    }
    for part, comp in parts.items():
        s = prior_sensitivity(dict(zip(lik.conditions, rho, strict=True)), comp, ll)
        print(f"  rho's sensitivity to {part:15s}", " ".join(f"{c} {v['prior']:.3f}" for c, v in s.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["5:0.55:1", "1:0.55:1", "0:0.45,0.65:4"])
    a = ap.parse_args()
    for case in a.cases:
        rep, heights, stride = case.split(":")
        one(int(rep), [float(h) for h in heights.split(",")], int(stride))


if __name__ == "__main__":
    main()

"""Simulation-based calibration of ``bayesrod.fit_group`` (issue 23): truths drawn from the fit's own prior.

    python scripts/group_sbc.py --replicates 40 --workers 2 --out group-sbc [--heights 0.55]

scripts/group_study.py draws its stems from a population of its own (EI0 log-normal around 2.63, the
published brace-root ratios), so its coverage is frequentist: where the data hardly separate stem and
anchorage (one height) the posterior's width is the prior's, and truths bunched in a corner of that prior are
covered more often than 90%. Here each replicate draws everything the joint posterior samples from the prior
the fit uses (scripts/sbc_prior.json, the woody prior with the force noise at half-normal 0.08 N, and the
built-in correlation prior), so the 90% intervals must cover 90% and the ranks be uniform if the posterior is
right:

* EI0 and p of the stem (the twig's L = 0.8 m, pushed at ``--heights``);
* per condition (intact, cut1, cut2, cut3 by name only): the base is a rigid clamp with probability 1/2,
  else u = c / (1 + c) uniform on (0, 0.9], c = EI0 C / L (the group prior: docs/inference.md);
* per condition the force noise's AR(1) correlation from the pooled population: a centre m with tanh m from
  the correlation prior (arcsine on (-0.5, 0.995)), each condition's atanh(rho) ~ N(m, 0.25); a draw with a
  correlation outside the prior's support is drawn again; and its sd: an innovation sd from the prior's
  half-normal, the marginal sd innovation / sqrt(1 - rho^2) (the sd prior is the innovation sd's since session
  53; runs before drew the marginal sd from the half-normal).

The data are bayesrod's simulator's (the fast forward solve at every sample, not the fit's tables), forces
only. For EI0, p and each condition's base compliance, noise sd and correlation: the rank of the truth among
99 draws spread over the chain (ties, as at a clamp's zero, broken at random) and whether the 90% interval
of summary.json covers it. Writes group_sbc.csv (resumable) and group_sbc.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _study import calibration_stats, run_pending  # noqa: E402

import bayesrod  # noqa: E402
from bayesrod.dataset.simulate import NoiseModel  # noqa: E402
from bayesrod.inference.group import POOL_SPREAD, U_MAX  # noqa: E402
from bayesrod.inference.priors import NUISANCE_DEFAULTS, load_prior, marginal_force_sd  # noqa: E402

PRIOR = str(Path(__file__).with_name("sbc_prior.json"))
L = 0.8
CONDITIONS = ("intact", "cut1", "cut2", "cut3")
N_RANK = 99
PARAMS = ["EI0", "p"] + [f"{k}__{c}" for k in ("C", "sigma", "rho") for c in CONDITIONS]
FIELDS = ["seed", "heights", "rhat", "seconds", "error"]
FIELDS += [f"{k}_{s}" for k in PARAMS for s in ("true", "q05", "median", "q95", "rank", "covered")]
FIELDS += ["steps", "converged", "rhat_walkers"]  # since session 57 (rhat: the ensembles as chains from then)


def draw(seed: int) -> dict:
    """The replicate's truths: EI0, p, and per condition the base compliance C [rad/(N m)] (0: a clamp),
    the force noise's sd [N] and correlation."""
    rng = np.random.default_rng(70_000 + seed)
    pr = load_prior(PRIOR)
    EI0 = float(pr.get("EI0").draw(rng, 1)[0])
    t = {"EI0": EI0, "p": float(pr.get("p").draw(rng, 1)[0])}
    lo, hi = NUISANCE_DEFAULTS["rho_force"].args
    while True:
        m = math.atanh(float(NUISANCE_DEFAULTS["rho_force"].draw(rng, 1)[0]))
        rho = np.tanh(m + POOL_SPREAD * rng.standard_normal(len(CONDITIONS)))
        if np.all((rho > lo) & (rho < hi)):
            break
    for i, c in enumerate(CONDITIONS):
        clamp = rng.uniform() < 0.5
        u = float(rng.uniform(0.0, U_MAX))
        cc = u / (1.0 - u)  # c = EI0 C / L
        t[f"C__{c}"] = 0.0 if clamp else cc * L / EI0
        # the sd prior is the innovation sd's under AR(1) (since session 53; runs before drew the marginal sd)
        t[f"sigma__{c}"] = float(marginal_force_sd(pr.get("sigma_force_N").draw(rng, 1)[0], rho[i]))
        t[f"rho__{c}"] = float(rho[i])
    return t


def datasets(seed: int, truth: dict, heights) -> list:
    """One simulated dataset per condition (forces only; two engaged frames, unused)."""
    out = []
    for i, c in enumerate(CONDITIONS):
        C = truth[f"C__{c}"]
        noise = NoiseModel(force_sd_N=truth[f"sigma__{c}"], force_rho=truth[f"rho__{c}"])
        stem = {"EI0": truth["EI0"], "p": truth["p"], "length_m": L, "heights_m": list(heights)}
        stem["specimen"] = f"gsbc-{seed}-{c}"
        ds = bayesrod.simulate(
            stem,
            seed=10 * seed + i,
            effects={"base_compliance": 1.0 / C} if C > 0 else None,
            noise_model=noise,
            config_overrides={"n_frames_engaged": 2},
        )
        out.append(replace(ds, extra={**ds.extra, "stem_id": f"gsbc-{seed}", "condition": c}))
    return out


def _rank(draws: np.ndarray, truth: float, rng) -> int:
    """Rank of ``truth`` among ``draws``, ties broken at random (a clamp's zero against draws at zero)."""
    below = int(np.sum(draws < truth))
    ties = int(np.sum(draws == truth))
    return below + int(rng.integers(0, ties + 1))


def one(job) -> dict:
    seed, heights = job
    row = {"seed": seed, "heights": " ".join(f"{h:g}" for h in heights)}
    t0 = time.perf_counter()
    truth = draw(seed)
    try:
        g = bayesrod.fit_group(
            datasets(seed, truth, heights), prior=PRIOR, progress=False, sharing=False, seed=seed, target_ess=400
        )
    except Exception as e:  # recorded, never dropped
        return row | {"error": f"{type(e).__name__}: {e}", "seconds": round(time.perf_counter() - t0, 1)}
    d, s = g.doc, g.samples
    n = next(iter(s.values())).size
    pick = np.linspace(0, n - 1, N_RANK).round().astype(int)
    rng = np.random.default_rng(seed)
    for k in PARAMS:
        if "__" in k:
            kind, c = k.split("__")
            name = {"C": "base_compliance_rad_per_Nm", "sigma": "sigma_force_N", "rho": "rho_force"}[kind]
            draws = s[f"{name}__{c}"]
            q = d["conditions"][c]["base_compliance_rad_per_Nm"] if kind == "C" else None
        else:
            draws, q = s[k], d["shared"][k]
        q05, q50, q95 = np.quantile(draws, [0.05, 0.5, 0.95]) if q is None else (q["q05"], q["median"], q["q95"])
        row |= {
            f"{k}_true": truth[k],
            f"{k}_q05": float(q05),
            f"{k}_median": float(q50),
            f"{k}_q95": float(q95),
            f"{k}_rank": _rank(draws[pick], truth[k], rng),
            f"{k}_covered": int(q05 <= truth[k] <= q95),
        }
    row["rhat"] = d["convergence"]["rhat_max"]
    row["rhat_walkers"] = d["convergence"].get("rhat_walkers_max", "")
    row["steps"], row["converged"] = d["sampler"]["steps"], int(d["convergence"]["converged"])
    row["seconds"] = round(time.perf_counter() - t0, 1)
    row["error"] = ""
    return row


def table(rows: list[dict]) -> str:
    """Coverage, misses, mean rank and the rank histogram's chi-square per parameter kind, over the replicates
    that fitted (:func:`_study.calibration_stats`, as scripts/sbc_geometry.py)."""
    ok = [r for r in rows if not r.get("error")]
    out = [
        f"{len(ok)} replicates fitted ({len(rows) - len(ok)} refused or failed)\n",
        "| parameter | n | 90% covered | binomial 95% range | misses: truth above / below | "
        f"mean rank (uniform {N_RANK / 2:g}) +- se | rank chi2 p (10 bins) |",
        "|---|---|---|---|---|---|---|",
    ]
    kinds = {"EI0": ["EI0"], "p": ["p"]}
    kinds |= {f"{k} (4 conditions)": [f"{k}__{c}" for c in CONDITIONS] for k in ("C", "sigma", "rho")}
    kinds |= {"C, soft bases only": None}
    for label, keys in kinds.items():
        if keys is None:
            cols = [(r, f"C__{c}") for r in ok for c in CONDITIONS if float(r[f"C__{c}_true"]) > 0]
        else:
            cols = [(r, k) for r in ok for k in keys]
        if not cols:
            continue
        c = calibration_stats([int(r[f"{k}_covered"]) for r, k in cols], [int(r[f"{k}_rank"]) for r, k in cols], N_RANK)
        out.append(
            f"| {label} | {c['n']} | {round(c['coverage'] * c['n'])}/{c['n']} ({c['coverage']:.2f}) | "
            f"{c['lo']:.2f}-{c['hi']:.2f} | {c['above']} / {c['below']} | {c['mean_rank']:.1f} +- {c['se']:.1f} | "
            f"{c['chi2_p']:.2f} |"
        )
    rh = np.array([float(r["rhat"]) for r in ok]) if ok else np.array([])
    if rh.size:
        out.append(f"\nR-hat max: median {np.median(rh):.3f}, above 1.01 in {int(np.sum(rh > 1.01))} of {rh.size}")
    told = [r for r in ok if r.get("converged") not in (None, "")]  # rows since session 57 carry it
    if told:
        steps = np.median([float(r["steps"]) for r in told])
        out.append(
            f"converged (summary.json) in {sum(int(r['converged']) for r in told)} of {len(told)}, median "
            f"{steps:.0f} steps"
        )
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--replicates", type=int, default=40)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--heights", default="0.55", help="contact heights [m], comma separated (L = 0.8 m)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    heights = tuple(float(x) for x in args.heights.split(","))
    args.out.mkdir(parents=True, exist_ok=True)
    csv = args.out / "group_sbc.csv"
    jobs = [(s, heights) for s in range(args.first_seed, args.first_seed + args.replicates)]
    key = lambda r: (int(r["seed"]), tuple(float(x) for x in r["heights"].split()))  # noqa: E731
    for row in run_pending(csv, FIELDS, jobs, one, done_key=key, workers=args.workers):
        print(f"seed {row['seed']}: {row.get('error') or 'ok'} ({row['seconds']} s)", flush=True)
    from bayesrod.dataset.io import read_rows

    text = table(read_rows(csv))
    (args.out / "group_sbc.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

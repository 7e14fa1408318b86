"""How large the force-noise draws of an SBC's seeds came out, before any fit: a control for the noise sd's ranks.

    python scripts/sbc_noise_draws.py --first-seed 0 --replicates 120
    python scripts/sbc_noise_draws.py --first-seed 1 --replicates 80 --step 2 --effects yield
    python scripts/sbc_noise_draws.py --projection --effects base_compliance,rest_curvature,force_offset,base_tilt \
        --rows docs/results/sbc_geometry_seeds0-119_session72.csv

For each seed, the case of ``scripts/sbc_geometry.py`` (the same draws: ``draw_case``, ``simulate_case``) is
simulated (no fit, no reference solve: the noise is the simulator's either way) and the engaged samples' noise
is compared with the sd the case drew: u = (sum of squared noise / sd^2 - n) / sqrt(2 n), a chi-square of n
degrees of freedom standardised, so mean 0 and sd 1 over seeds whose draws are what they should be. A seed set
whose draws came out small (u's mean below 0 by several standard errors) makes the noise sd's SBC ranks lean
high (the truth above most posterior draws) with a posterior that is right: the lean is in the data. Prints u's
mean +- standard error over all seeds and by number of heights; writes nothing.

``--projection``: where the draws pushed the stem's parameters instead. The same noise is projected on the
directions of the case's own noise-free forces (the simulator's fast model, finite differences at the truth) in
log EI0 and p, and in the case's effect where it has one (profiled out: the marginal shift of log EI0 and p):
z = the least-squares shift of the noise alone over its sd, N(0, 1) per seed for iid noise and a linear model,
and chi2 = the joint shift's Mahalanobis distance, chi-square with 2 degrees of freedom. A forces-only
posterior that is right misses its truth where |z| came out large, on the side of z (z < 0: the truth above
the posterior, a high rank): ``--rows`` joins an SBC rows CSV (its ranks and coverage) so that each miss can be
read against its data (``--case-seed N``: every seed draws its noise on seed N's case, a control of the
generator: its z should then be N(0, 1) over seeds). Centerlines are not projected (a seed with them can be
pulled either way by its frames); ``--projection-fit`` projects them too: the fit's own likelihood (tables,
centerlines at their reported sd, weight 1) is maximised from the truth with the noise sds held at the truth
(``bayesrod.api.calibration.mle_shift``), and z is that maximum's shift in its Laplace sds (the effect profiled
out); slower (a table build per seed).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from sbc_geometry import ALL_EFFECTS, CASE_SHAPE_SD_M, EFFECTS, N_RANK, PRIOR, draw_case, engaged_forces, simulate_case  # noqa: E402


def simulated(seed: int, effects: tuple, case_seed: int | None = None) -> tuple[dict, object] | None:
    """(case, dataset) of a seed as its SBC replicate simulates it (before the reference re-solve, which keeps the
    noise); None where the case cannot be simulated (a height its rest shape never crosses, as the SBC records).
    ``case_seed``: that seed's case with ``seed``'s noise draws (None: the seed's own case)."""
    case = draw_case(seed if case_seed is None else case_seed, effects)
    try:
        return case, simulate_case(seed, case, frames=None if case["shapes"] else 2)
    except ValueError:
        return None


def engaged_observed(ds) -> np.ndarray:
    """The recorded forces [N] of a simulated dataset's engaged samples, pushes concatenated."""
    _, sim = ds.simulation
    pairs = zip(ds.pushes, sim, strict=True)
    return np.concatenate([np.asarray(push.force.force_N, float)[sp.engaged] for push, sp in pairs])


def noise_draw(seed: int, effects: tuple) -> tuple[int, int, float] | None:
    """(number of heights, engaged samples n, standardised chi-square u) of one seed's force noise; None
    where the case cannot be simulated."""
    found = simulated(seed, effects)
    if found is None:
        return None
    case, ds = found
    cfg, sim = ds.simulation
    noise = engaged_observed(ds) - np.concatenate([engaged_forces(sp, cfg) for sp in sim])
    e = noise / case["sigma_force_N"]
    n = e.size
    return len(case["heights_m"]), n, float((np.sum(e**2) - n) / np.sqrt(2.0 * n))


#: relative finite-difference step of the projection's directions (log EI0, p, the effect's field)
PROJECTION_STEP = 1e-6


def _effect_field(cfg) -> str | None:
    """The one switched-on field of the simulator's :class:`~bayesrod.physics.effects.Effects` (None: none)."""
    neutral = type(cfg.effects)()
    on = [f.name for f in fields(neutral) if getattr(cfg.effects, f.name) != getattr(neutral, f.name)]
    return on[0] if on else None


def noise_projection(seed: int, effects: tuple, case_seed: int | None = None) -> dict | None:
    """A seed's force noise projected on its forces' parameter directions (``--projection``); None where the
    case cannot be simulated. Samples whose perturbed force is past the branch's end (nan) are left out.
    ``case_seed``: as :func:`simulated`."""
    found = simulated(seed, effects, case_seed)
    if found is None:
        return None
    case, ds = found
    cfg, sim = ds.simulation
    field = _effect_field(cfg)
    x0 = [np.log(cfg.EI0), cfg.p] + ([getattr(cfg.effects, field)] if field else [])

    def forces(x) -> np.ndarray:
        eff = replace(cfg.effects, **{field: float(x[2])}) if field else cfg.effects
        c = replace(cfg, EI0=float(np.exp(x[0])), p=float(x[1]), effects=eff)
        return np.concatenate([engaged_forces(sp, c) for sp in sim])

    x0 = np.array(x0, float)
    e = engaged_observed(ds) - forces(x0)
    steps = PROJECTION_STEP * np.maximum(np.abs(x0), 1.0)
    steps[:2] = PROJECTION_STEP
    cols = [(forces(x0 + h * u) - forces(x0 - h * u)) / (2 * h) for h, u in zip(steps, np.eye(x0.size), strict=True)]
    J = np.stack(cols, axis=1)
    ok = np.all(np.isfinite(J), axis=1)
    J, e = J[ok], e[ok]
    A = J.T @ J
    shift = np.linalg.solve(A, J.T @ e)
    cov = np.linalg.inv(A) * case["sigma_force_N"] ** 2
    z = shift[:2] / np.sqrt(np.diag(cov)[:2])
    chi2 = float(shift[:2] @ np.linalg.solve(cov[:2, :2], shift[:2]))
    return {
        "seed": seed,
        "effect": case["effect"] or "none",
        "n_heights": len(case["heights_m"]),
        "shapes": case["shapes"],
        "n": int(e.size),
        "n_left_out": int((~ok).sum()),
        "z_EI0": float(z[0]),
        "z_p": float(z[1]),
        "chi2": chi2,
    }


def fit_projection(seed: int, effects: tuple, case_seed: int | None = None) -> dict | None:
    """:func:`noise_projection` by the fit's own likelihood, centerlines included (``--projection-fit``)."""
    from bayesrod.api._common import as_dataset
    from bayesrod.api.calibration import mle_shift
    from bayesrod.inference.likelihood import build_likelihood
    from bayesrod.inference.priors import load_prior

    found = simulated(seed, effects, case_seed)
    if found is None:
        return None
    case, ds = found
    try:
        data = as_dataset(ds)
    except ValueError:  # DatasetError is one: a push that never loaded the stem, as the SBC records
        return None
    effect = case["effect"]
    lik = build_likelihood(data, load_prior(PRIOR), (effect,) if effect else (), use_shapes=case["shapes"])
    truth = {"EI0": case["EI0"], "p": case["p"], **({effect: case["effect_value"]} if effect else {})}
    shift = mle_shift(lik, truth, noise=(case["sigma_force_N"], CASE_SHAPE_SD_M))
    z = shift["shift_in_sd"]
    return {
        "seed": seed,
        "effect": effect or "none",
        "n_heights": len(case["heights_m"]),
        "shapes": case["shapes"],
        "n": int(lik.n_points),  # centerline points
        "z_EI0": float(z[0]),
        "z_p": float(z[1]),
        "chi2": float("nan"),  # mle_shift gives the marginal sds only
    }


PROJECTION_HEADER = "seed effect heights shapes n z_EI0 z_p chi2"


def projection_row(r: dict, sbc_rows: dict) -> str:
    """One seed's line of the projection table (with its SBC ranks where ``sbc_rows`` has the seed)."""
    line = f"{r['seed']:4d} {r['effect']:15s} {r['n_heights']} {'yes' if r['shapes'] else 'no ':3s} {r['n']:4d}"
    line += f" {r['z_EI0']:+.2f} {r['z_p']:+.2f} {r['chi2']:6.2f}"
    if r.get("n_left_out"):
        line += f" ({r['n_left_out']} samples left out: past the branch's end when perturbed)"
    s = sbc_rows.get(r["seed"])
    if s and s.get("EI0_rank"):
        line += f"  {s['EI0_rank']:>3s} {s['p_rank']:>3s} ({s['EI0_covered']}, {s['p_covered']})"
    return line


def projection_summary(rows: list[dict], sbc_rows: dict, with_centerlines: bool = False) -> None:
    """Print the summary of the seeds' projections ``rows`` (and, with ``sbc_rows``, their ranks against -z).

    ``with_centerlines``: the z of ``rows`` project the centerlines too (``--projection-fit``), so the seeds with
    them are read against their ranks as well."""
    from scipy import stats

    c = np.array([r["chi2"] for r in rows])
    if np.isfinite(c).all():
        q90, q99 = stats.chi2.ppf([0.9, 0.99], 2)
        print(
            f"{c.size} seeds: chi2 mean {c.mean():.2f} (2 expected, se {2 / np.sqrt(c.size):.2f}); above its 90% "
            f"point {np.mean(c > q90):.3f}, its 99% point {np.mean(c > q99):.3f}"
        )
    groups = {"forces only": [not r["shapes"] for r in rows], "with centerlines": [r["shapes"] for r in rows]}
    splits = dict(groups)
    splits["one height, forces only"] = [r["n_heights"] == 1 and not r["shapes"] for r in rows]
    splits |= {f"effect {e}": [r["effect"] == e for r in rows] for e in dict.fromkeys(r["effect"] for r in rows)}
    for label, sel in splits.items():
        z = np.array([(r["z_EI0"], r["z_p"]) for r, k in zip(rows, sel, strict=True) if k])
        if z.size:
            se = 1 / np.sqrt(len(z))
            big = np.sum(np.abs(z) > stats.norm.ppf(0.95), axis=0)  # outside a right posterior's 90% interval
            print(
                f"{label}: {len(z)} seeds, mean z EI0 {z[:, 0].mean():+.2f}, p {z[:, 1].mean():+.2f} (+- {se:.2f}); "
                f"|z| > 1.645: EI0 {big[0]}, p {big[1]} ({0.1 * len(z):.1f} expected)"
            )
    if not sbc_rows:
        return
    read = {"forces only": groups["forces only"]}
    if with_centerlines:
        read |= {"with centerlines": groups["with centerlines"], "all": [True] * len(rows)}
    for label, sel in read.items():
        for k in ("EI0", "p"):
            # a right posterior (the prior's share small) puts the truth at its quantile Phi(-z): the rank's normal
            # score against -z has slope 1; a posterior too wide by a factor c has slope 1/c, too narrow c
            pts = [
                (-r[f"z_{k}"], stats.norm.ppf((float(sbc_rows[r["seed"]][f"{k}_rank"]) + 0.5) / (N_RANK + 1)))
                for r, use in zip(rows, sel, strict=True)
                if use and sbc_rows.get(r["seed"], {}).get(f"{k}_rank")
            ]
            if len(pts) > 2:
                x, y = np.array(pts).T
                fit = stats.linregress(x, y)
                rho = stats.spearmanr(x, y).statistic
                print(
                    f"{label}, {k}: the rank's normal score = {fit.slope:.2f} (+- {fit.stderr:.2f}) x (-z) "
                    f"{fit.intercept:+.2f}, residual sd {np.std(y - fit.intercept - fit.slope * x, ddof=2):.2f}, "
                    f"Spearman {rho:+.2f} ({len(pts)} seeds; slope 1: the posterior's width right)"
                )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--replicates", type=int, default=120, help="seeds first-seed .. first-seed + replicates - 1")
    ap.add_argument("--step", type=int, default=1, help="every step-th seed (2 with --effects yield: its odd seeds)")
    ap.add_argument(
        "--effects",
        default=",".join(EFFECTS[1:]),
        help="the effect cycle after 'none', as sbc_geometry.py's --effects (it decides which seeds are "
        "forces only; contact_friction's cases are simulated like any other)",
    )
    ap.add_argument("--projection", action="store_true", help="project the noise on log EI0 and p (see above)")
    ap.add_argument(
        "--projection-fit", action="store_true", help="project by the fit's likelihood, centerlines included"
    )
    ap.add_argument(
        "--case-seed",
        type=int,
        default=None,
        help="with --projection[-fit]: every seed simulates this seed's case (its stem, heights, effect) with its own "
        "noise draws: a control of the generator on one case",
    )
    ap.add_argument("--rows", default=None, help="with --projection: an SBC rows CSV to read the ranks from")
    args = ap.parse_args(argv)
    effects = (None, *[e for e in args.effects.split(",") if e])
    bad = [e for e in effects[1:] if e not in ALL_EFFECTS]
    if bad:
        ap.error(f"--effects: expected names among {', '.join(ALL_EFFECTS[1:])}, got {', '.join(bad)}")
    seeds = range(args.first_seed, args.first_seed + args.replicates, args.step)
    if args.projection or args.projection_fit:
        import csv

        sbc_rows = {}
        if args.rows:
            with open(args.rows, newline="") as fh:
                sbc_rows = {int(r["seed"]): r for r in csv.DictReader(fh)}
        project = fit_projection if args.projection_fit else noise_projection
        found = []
        print(PROJECTION_HEADER + ("  EI0_rank p_rank (covered)" if sbc_rows else ""), flush=True)
        for s in seeds:
            r = project(s, effects, args.case_seed)
            if r is not None:
                found.append(r)
                print(projection_row(r, sbc_rows), flush=True)
        if not found:
            raise SystemExit("no seed could be simulated")
        projection_summary(found, sbc_rows, with_centerlines=args.projection_fit)
        return
    rows = [r for r in (noise_draw(s, effects) for s in seeds) if r is not None]
    if not rows:
        raise SystemExit("no seed could be simulated")
    heights, n, u = (np.array(c, float) for c in zip(*rows, strict=True))

    def line(sel, label):
        k = int(sel.sum())
        if k:
            se = u[sel].std(ddof=1) / np.sqrt(k) if k > 1 else float("nan")
            print(f"{label}: {k} seeds, median {np.median(n[sel]):.0f} samples, u {u[sel].mean():+.3f} +- {se:.3f}")

    print(f"seeds {seeds.start}-{seeds.stop - 1} (step {args.step}), {len(rows)} simulated; u is 0 +- 1 per seed")
    line(np.ones(u.size, bool), "all")
    for h in (1, 2, 3):
        line(heights == h, f"{h} height(s)")


if __name__ == "__main__":
    main()

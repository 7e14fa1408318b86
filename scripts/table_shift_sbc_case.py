"""How far the likelihood tables move the MLE on one SBC case, noise-free (issue 21).

    python scripts/table_shift_sbc_case.py --seed 47 [--n-effect 145] [--fast] [--forces-only]

scripts/table_accuracy.py checks the tables on the twig at moderate effect values. This takes one case of
scripts/sbc_geometry.py (its stem, heights, effect and value; the fixed robot step) without noise:
forces and centerlines solved again by the reference solver (``--fast``: the simulator's own), so the
exact model's MLE is the truth. The table likelihood is maximised over (log EI0, p, the effect) with
the noise at the case's force sd and 1.5 mm, and its shift from the truth is printed in Laplace sds,
with the log likelihood at the truth and at the maximum. ``--n-effect``: nodes on the effect's table
axis (default: the fit's).
"""

from __future__ import annotations

import argparse

import numpy as np
import sbc_geometry as S
from scipy.optimize import minimize

from bayesrod import simulate
from bayesrod.api._common import as_dataset
from bayesrod.api.calibration import _hessian
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference.likelihood import build_likelihood
from bayesrod.inference.priors import load_prior


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=47)
    ap.add_argument("--effects", default="base_compliance,rest_curvature,force_offset,base_tilt")
    ap.add_argument("--n-effect", type=int, default=None)
    ap.add_argument("--fast", action="store_true", help="keep the simulator's solves (no reference re-solve)")
    ap.add_argument("--forces-only", action="store_true")
    a = ap.parse_args(argv)
    case = S.draw_case(a.seed, (None, *a.effects.split(",")))
    effect = case["effect"]
    noise = NoiseModel(force_sd_N=0.0, shape_sd_m=0.0, shape_sd_reported_m=0.0015)
    stem = {k: case[k] for k in ("EI0", "p", "length_m", "heights_m")} | {"specimen": f"table-{a.seed}"}
    ds = simulate(
        stem,
        seed=a.seed,
        noise_model=noise,
        effects={effect: case["effect_value"]} if effect else {},
        config_overrides={"robot_step_m": 0.01 * case["length_m"]},
    )
    if not a.fast:
        ds, _, _ = S.reference_dataset(ds, case | {"shapes": True})
    prior = load_prior(str(S.PRIOR))
    lik = build_likelihood(
        as_dataset(ds), prior, (effect,) if effect else (), use_shapes=not a.forces_only, n_effect=a.n_effect
    )
    fixed = {"sigma_force_N": max(case["sigma_force_N"], 1e-3), "sigma_shape_m": 0.0015, "shape_sd_scale": 1.0}

    def loglik(x) -> float:
        params = {"EI0": np.exp(x[:1]), "p": x[1:2], **{k: np.array([v]) for k, v in fixed.items()}}
        if effect:
            params[effect] = x[2:3]
        return float(lik.log_likelihood(params)[0]) if lik.in_table(params)[0] else -np.inf

    x0 = np.array([np.log(case["EI0"]), case["p"]] + ([case["effect_value"]] if effect else []))
    res = minimize(lambda x: -loglik(x), x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-10})
    sd = np.sqrt(np.diag(np.linalg.inv(-_hessian(loglik, res.x, np.full(x0.size, 1e-4)))))
    axis = 0 if lik.axis is None else lik.axis.grid.size
    print(f"seed {a.seed}: {case['effect'] or 'no effect'}, {len(case['heights_m'])} heights, p {case['p']:.4f}")
    print(f"  effect axis nodes {axis}; log likelihood at the truth {loglik(x0):.2f}, at the maximum {-res.fun:.2f}")
    names = ["log EI0", "p"] + ([effect] if effect else [])
    for n, t, m, s in zip(names, x0, res.x, sd, strict=True):
        print(f"  {n}: truth {t:.5f}, table MLE {m:.5f}, Laplace sd {s:.5f}, shift {(m - t) / s:+.2f} sd")


if __name__ == "__main__":
    main()

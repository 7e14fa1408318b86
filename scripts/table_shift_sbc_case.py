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

import sbc_geometry as S

from bayesrod.api.calibration import table_shift_on
from bayesrod.dataset.simulate import NoiseModel
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
    ds = S.simulate_case(a.seed, case, prefix="table", noise=noise)
    if not a.fast:
        ds, _, _ = S.reference_dataset(ds, case | {"shapes": True})
    out = table_shift_on(
        ds,
        load_prior(str(S.PRIOR)),
        {"EI0": case["EI0"], "p": case["p"], **({effect: case["effect_value"]} if effect else {})},
        noise=(max(case["sigma_force_N"], 1e-3), 0.0015),
        use_shapes=not a.forces_only,
        n_effect=a.n_effect,
    )
    print(f"seed {a.seed}: {effect or 'no effect'}, {len(case['heights_m'])} heights, p {case['p']:.4f}")
    print(
        f"  effect axis nodes {out['effect_nodes']}; log likelihood at the truth {out['loglik_truth']:.2f}, "
        f"at the maximum {out['loglik_max']:.2f}"
    )
    for n, t, m, s, z in zip(*(out[k] for k in ("names", "truth", "mle", "laplace_sd", "shift_in_sd")), strict=True):
        print(f"  {n}: truth {t:.5f}, table MLE {m:.5f}, Laplace sd {s:.5f}, shift {z:+.2f} sd")


if __name__ == "__main__":
    main()

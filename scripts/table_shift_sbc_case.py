"""How far the likelihood tables move the MLE on one SBC case, noise-free (issue 21).

    python scripts/table_shift_sbc_case.py --seed 47 [--n-effect 145] [--fast] [--forces-only] [--zoom] [--noisy]

scripts/table_accuracy.py checks the tables on the twig at moderate effect values. This takes one case of
scripts/sbc_geometry.py (its stem, heights, effect and value; the fixed robot step) without noise:
forces and centerlines solved again by the reference solver (``--fast``: the simulator's own), so the
exact model's MLE is the truth. The table likelihood is maximised over (log EI0, p, the effect) with
the noise at the case's force sd and 1.5 mm, and its shift from the truth is printed in Laplace sds,
with the log likelihood at the truth and at the maximum. ``--n-effect``: nodes on the effect's table
axis (default: the fit's). ``--zoom``: then also on the axes (the effect's, p's) a fit narrows around its
start where the tables there are too coarse (``bayesrod.api.fitting.zoom_decision`` at the truth, the fit's rule:
the worst of the checks there and with the effect and p between nodes; a second table build).
``--noisy``: the case with its own noise draws (the SBC replicate's data, ``--effects`` as its run), the noise sds
held at the case's: the shift is then the noise's, not the tables' (docs/validation.md, session 73: seed 95), and
with centerlines their estimated weight n_eff/n and standardised residual rms at the truth are printed too.
"""

from __future__ import annotations

import argparse

import numpy as np
import sbc_geometry as S

from bayesrod.api._common import as_dataset
from bayesrod.api.calibration import mle_shift
from bayesrod.api.fitting import zoom_decision
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference.likelihood import build_likelihood, effective_shape_weight
from bayesrod.inference.priors import load_prior


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=47)
    ap.add_argument("--effects", default="base_compliance,rest_curvature,force_offset,base_tilt")
    ap.add_argument("--n-effect", type=int, default=None)
    ap.add_argument("--fast", action="store_true", help="keep the simulator's solves (no reference re-solve)")
    ap.add_argument("--forces-only", action="store_true")
    ap.add_argument("--zoom", action="store_true", help="also the narrowed effect axis a fit would sample on")
    ap.add_argument("--noisy", action="store_true", help="keep the case's own noise draws (the replicate's data)")
    a = ap.parse_args(argv)
    case = S.draw_case(a.seed, (None, *a.effects.split(",")))
    effect = case["effect"]
    if a.noisy:
        ds = S.simulate_case(a.seed, case, prefix="table", frames=None if case["shapes"] else 2)
    else:
        noise = NoiseModel(force_sd_N=0.0, shape_sd_m=0.0, shape_sd_reported_m=S.CASE_SHAPE_SD_M)
        ds = S.simulate_case(a.seed, case, prefix="table", noise=noise)
    if not a.fast:
        ds, _, _ = S.reference_dataset(ds, case | {"shapes": True})
    truth = {"EI0": case["EI0"], "p": case["p"], **({effect: case["effect_value"]} if effect else {})}
    # the noise sds held fixed (noise-free data: at least 1e-3 N, a scale for the Laplace sds)
    held = (case["sigma_force_N"] if a.noisy else max(case["sigma_force_N"], 1e-3), S.CASE_SHAPE_SD_M)
    fitted = (effect,) if effect else ()
    prior = load_prior(str(S.PRIOR))
    lik = build_likelihood(as_dataset(ds), prior, fitted, use_shapes=not a.forces_only, n_effect=a.n_effect)
    print(f"seed {a.seed}: {effect or 'no effect'}, {len(case['heights_m'])} heights, p {case['p']:.4f}")
    show(mle_shift(lik, truth, noise=held))
    if a.noisy and lik.n_points:
        point = truth | {"sigma_force_N": held[0], "sigma_shape_m": held[1], "shape_sd_scale": 1.0}
        w = effective_shape_weight(lik, point)
        r = lik.residuals({k: np.atleast_1d(v) for k, v in point.items()})["shape"][0] / held[1]
        rms = float(np.sqrt(np.mean(r**2)))
        print(f"  centerlines at the truth: {lik.n_points} points, weight n_eff/n {w['weight']:.3f}", end="")
        print(f" (tau along {w['tau_along']:.2f}, across frames {w['tau_frames']:.2f}), standardised rms {rms:.4f}")
    if a.zoom:
        point = truth | {"sigma_force_N": held[0], "sigma_shape_m": held[1], "shape_sd_scale": 1.0}
        _, check, windows = zoom_decision(lik, point)  # the fit's rule, at the truth
        worst = max(abs(v) for v in check["shift_in_sd"].values()) if check else float("nan")
        if not any(windows.values()):
            print(f"  zoom: none (the check at the truth: {worst:.2f} sd; a window would span over 0.8 of an axis)")
        else:
            print(f"  zoom (the worst check at the truth and with the effect and p between nodes: {worst:.2f} sd):")
            if windows["effect_window"]:
                lo, hi = windows["effect_window"]
                print(f"  u in [{lo:.5g}, {hi:.5g}] ({lik.axis.grid.size} nodes; was [{lik.axis.grid[0]:.4g}, ", end="")
                print(f"{lik.axis.grid[-1]:.4g}])")
            if windows["p_window"]:
                lo, hi = windows["p_window"]
                was = f"{lik.p_grid[0]:.4g}, {lik.p_grid[-1]:.4g}"
                print(f"  p in [{lo:.6g}, {hi:.6g}] ({lik.p_grid.size} nodes; was [{was}])")
            options = {k: w for k, w in windows.items() if w}
            if windows["effect_window"]:
                options["n_effect"] = int(lik.axis.grid.size)
            zoomed = build_likelihood(as_dataset(ds), prior, fitted, use_shapes=not a.forces_only, **options)
            show(mle_shift(zoomed, truth, noise=held))


def show(out: dict) -> None:
    """Print one mle_shift result."""
    print(
        f"  effect axis nodes {out['effect_nodes']}; log likelihood at the truth {out['loglik_truth']:.2f}, "
        f"at the maximum {out['loglik_max']:.2f}"
    )
    for n, t, m, s, z in zip(*(out[k] for k in ("names", "truth", "mle", "laplace_sd", "shift_in_sd")), strict=True):
        print(f"  {n}: truth {t:.5f}, table MLE {m:.5f}, Laplace sd {s:.3g}, shift {z:+.2f} sd", flush=True)


if __name__ == "__main__":
    main()

"""The structure test on plain fits: per-push blocks against the block pooled over pushes.

    python scripts/structure_power.py [--clean 50] [--noise-rho 0.9]

Simulated twigs (3 heights x 60 force samples, forces only, AR(1) force noise), each fitted with the
plain rod (``Diagnoser.fit_plain``, the first fit of ``bayesrod diagnose``); prints, per case, the fitted
noise correlation, the smallest per-push p-value, the pooled p-value and the verdict, then the clean
rates. Clean seeds 100.. as in scripts/diagnose_study.py; effect cases at the study's seeds and sizes
and at weaker ones. About 5 s per case on one core. Results: docs/validation.md, "The structure test
pooled over pushes".
"""

from __future__ import annotations

import argparse

import numpy as np

import bayesrod
from bayesrod.inference.diagnose import Diagnoser, ForwardModel
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects

EFFECT_CASES = [
    ("base_compliance", 8.0, 11),
    ("base_compliance", 8.0, 12),
    ("base_compliance", 16.0, 13),
    ("rest_curvature", 0.15, 11),
    ("force_offset", 0.05, 11),
    ("yield", 3.0, 200),
]


def one(effect, value, seed, rho):
    eff = Effects.from_mapping({effect: value} if effect else {})
    spec = bayesrod.simulate(
        "twig", seed=seed, effects=eff, noise_rho=rho, config_overrides={"specimen": "s", "n_frames_engaged": 8}
    )
    dg = Diagnoser(ForwardModel(prepare_data(spec, use_shapes=False), spec.length_m))
    fit = dg.fit_plain()
    st = dg.structure(fit)
    *pushes, pooled = st["blocks"]
    return fit.rho_force, min(b["p_value"] for b in pushes), pooled["p_value"], st["unexplained_structure"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clean", type=int, default=50)
    ap.add_argument("--noise-rho", type=float, default=0.9)
    args = ap.parse_args()
    print("| case | seed | fitted rho | smallest per-push p | pooled p | unexplained |")
    print("|---|---|---|---|---|---|")
    clean = []
    cases = [(None, 0.0, 100 + s) for s in range(args.clean)] + EFFECT_CASES
    for effect, value, seed in cases:
        rho, p_push, p_pool, flag = one(effect, value, seed, args.noise_rho)
        name = f"{effect} {value:g}" if effect else "clean"
        print(f"| {name} | {seed} | {rho:.3f} | {p_push:.2g} | {p_pool:.2g} | {'yes' if flag else 'no'} |", flush=True)
        if effect is None:
            clean.append((p_push, p_pool, flag))
    if clean:
        c = np.array(clean, float)
        print(
            f"\nclean: {int(c[:, 2].sum())}/{len(c)} unexplained; pooled p < 0.01 in {int((c[:, 1] < 0.01).sum())}; "
            f"smallest pooled p {c[:, 1].min():.2g}, smallest per-push p {c[:, 0].min():.2g}"
        )


if __name__ == "__main__":
    main()

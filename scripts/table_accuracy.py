"""How far the likelihood tables move the maximum-likelihood estimate, in posterior standard deviations.

    python scripts/table_accuracy.py --out docs/results/table_accuracy.csv

The fit never solves the elastica at a walker's parameters: it interpolates tables (4-point Lagrange
in p, cubic in the effect's axis; docs/inference.md). Here each case is a *noise-free* simulated twig
(three heights; every recorded force and centerline an exact solve), so the exact model's MLE is the
truth itself. The table likelihood is maximised over (log EI0, p[, the effect]) with the noise levels
held at the preset's (force sd 0.03 N, centerline sd 1.5 mm), and its shift from the truth is divided by
the Laplace sd (finite-difference Hessian of the same log likelihood at its maximum): the bias the
tables add, in units of the posterior's own width. Cases: the plain rod and each tabled effect
(base_compliance, rest_curvature, base_tilt, contact_friction), forces only and forces + shapes.
Issue 21 asks for |shift| <= 0.05 sd.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bayesrod.api.calibration import table_shift
from bayesrod.dataset.io import append_rows

CASES = [
    ("plain", None, 0.0),
    ("base_compliance", "base_compliance", 20.0),
    ("rest_curvature", "rest_curvature", 0.3),
    ("base_tilt", "base_tilt", 0.05),
    ("contact_friction", "contact_friction", 0.3),
]
FIELDS = ["case", "shapes", "effect_nodes", "parameter", "truth", "mle", "laplace_sd", "shift_in_sd", "seconds"]


def case_rows(name: str, effect: str | None, value: float, shapes: bool, n_effect: int | None = None) -> list[dict]:
    t0 = time.perf_counter()
    out = table_shift(effect, value, use_shapes=shapes, n_effect=n_effect)
    seconds = time.perf_counter() - t0
    return [
        {
            "case": name,
            "effect_nodes": out["effect_nodes"],
            "shapes": shapes,
            "parameter": n,
            "truth": out["truth"][i],
            "mle": out["mle"][i],
            "laplace_sd": out["laplace_sd"][i],
            "shift_in_sd": out["shift_in_sd"][i],
            "seconds": seconds,
        }
        for i, n in enumerate(out["names"])
    ]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("table_accuracy.csv"))
    ap.add_argument("--only", nargs="*", help="case names (default: all)")
    ap.add_argument("--forces-only", action="store_true", help="skip the forces + shapes cases")
    ap.add_argument("--n-effect", type=int, help="nodes on the effect axis (default: the fit's)")
    args = ap.parse_args(argv)
    rows = []
    for shapes in (False,) if args.forces_only else (False, True):
        for name, effect, value in CASES:
            if args.only and name not in args.only:
                continue
            new = case_rows(name, effect, value, shapes, args.n_effect)
            rows += new
            for r in new:
                print(
                    f"{r['case']:17s} shapes={str(r['shapes']):5s} {r['parameter']:17s} "
                    f"shift {r['shift_in_sd']:+.3f} sd (sd {r['laplace_sd']:.3g}, {r['seconds']:.0f} s)",
                    flush=True,
                )
    tmp = args.out.with_suffix(".tmp")
    tmp.unlink(missing_ok=True)
    list(append_rows(tmp, FIELDS, rows, new_file=True))
    tmp.replace(args.out)
    worst = max(abs(r["shift_in_sd"]) for r in rows)
    print(f"largest |shift| {worst:.3f} sd; wrote {args.out}")


if __name__ == "__main__":
    main()

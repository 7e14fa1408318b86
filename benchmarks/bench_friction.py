"""Friction and self-weight solves: the fast path against the reference solver, and the force tables' cost.

Run:  python benchmarks/bench_friction.py [--repeat 5] [--tables]

With friction or self-weight the base moment is found by a bracketed search (docs/model.md, "Friction and
weight: the base moment"). Printed, per effect (mu = 0.2, mu = -0.2, weight w0 = 0.5):

* one displacement sweep (40 displacements, 0.01 to 0.8 L, at eta = 0.625, p = 0.43) by the fast path:
  median seconds of ``--repeat``, the marches, and how many displacements slipped;
* the same displacements by the reference solver (one ``solve_ivp`` shooting per trial, ``brentq``; the
  reference run in the same process), three of them (0.01, 0.17, 0.33 L): seconds per displacement, the ratio
  to the fast path's, and the largest relative difference of the forces where both hold;
* with ``--tables``: one build of the likelihood's force tables (3 heights x 61 taper exponents x 160
  forces; minutes), the end displacement of the table at eta 0.4 and p 0.5.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_root_search import _time as time_force_solves

from bayesrod.inference import likelihood as LK
from bayesrod.physics import elastica
from bayesrod.physics import reference as R

EFFECTS = {"friction up (mu 0.2)": {"mu": 0.2}, "friction down (mu -0.2)": {"mu": -0.2}, "weight (w0 0.5)": {"w0": 0.5}}
ETA, P = 0.625, 0.43
D = np.linspace(0.01, 0.8, 40)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--tables", action="store_true", help="also build the force tables (minutes per effect)")
    a = ap.parse_args(argv)
    for name, eff in EFFECTS.items():
        # the root-search benchmark's timer (as shipped: its NEWTON_BATCH), with the effects as 4th argument
        t_fast, marches, f_fast = time_force_solves((D, ETA, P, eff), a.repeat, elastica.NEWTON_BATCH)
        idx = np.array([0, 8, 16])  # 0.01, 0.17, 0.33 L (a slip costs the reference minutes)
        t = time.perf_counter()
        ref = np.array([R.solve_displacement(float(D[i]), ETA, P, eff)["f"] for i in idx])
        t_ref = (time.perf_counter() - t) / idx.size
        both = np.isfinite(ref) & np.isfinite(f_fast[idx])
        diff = float(np.max(np.abs(f_fast[idx][both] / ref[both] - 1.0))) if both.any() else float("nan")
        agree = int(np.sum(np.isfinite(ref) == np.isfinite(f_fast[idx])))
        print(
            f"{name}: fast sweep of {D.size} {t_fast:.2f} s (median of {a.repeat}), {marches} marches, "
            f"{int(np.isnan(f_fast).sum())} slipped; reference {t_ref:.2f} s per displacement, "
            f"ratio reference / fast per displacement {t_ref / (t_fast / D.size):.0f}; "
            f"max |rel diff| {diff:.1e}, slip agrees at {agree} of {idx.size}"
        )
        if a.tables:
            LK._CURVE_CACHE.clear()
            t = time.perf_counter()
            curves = LK.ForceCurves.batch(np.array([0.4, 0.6, 0.8]), np.linspace(0.0, 1.5, 61), 160, eff)
            took = time.perf_counter() - t
            print(f"    force tables: {took:.1f} s; branch end at eta 0.4, p 0.5: {curves[0].d_end[20]:.4f}")


if __name__ == "__main__":
    main()

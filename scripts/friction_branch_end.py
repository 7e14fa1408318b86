"""Friction stems up to their branch's end: which forces hold, by the fast path and by the reference solver.

Near the end of a friction branch the contact nears the tip at the friction angle atan(1 / mu) and the base
moment's residual becomes too steep for round-off; before session 50 both solvers left holes there (forces that
hold, returned as slipped). This script prints, for the dense friction stems of ``scripts/mutant_sweep.py``
(``NEAR_TIP``: 100-200 forces each, near the tip and across the branch's end):

* the forces each solver holds, those only one holds, and the largest difference of the base moment where both
  hold (``--reference`` runs ``bayesrod.physics.reference.solve_force`` force by force: about 25 minutes on one
  core; ``--reference-cache FILE`` keeps its answers in a JSON file and reads them back on the next run);
* with ``--steps``, the fast path at several step counts (default 48, 96, 192, 384) on the two stems whose branch
  ends inside their range: how many forces hold and the last one (the branch's end should not move with the step
  count beyond the coarse last step's error), and the pattern (1 held, . not).

Usage::

    python scripts/friction_branch_end.py --reference --reference-cache ref.json
    python scripts/friction_branch_end.py --steps 48,96,192,384
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from mutant_sweep import NEAR_TIP

from bayesrod.physics.elastica import contact_from_force_nd
from bayesrod.physics.reference import solve_force


def fast(f, eta, p, eff, n_steps=None):
    """The fast path's held forces and base moments (NaN where not held)."""
    kw = {} if n_steps is None else {"n_steps": n_steps}
    a = contact_from_force_nd(f, eta, p, eff, **kw)
    hold = np.asarray(a["found"]) & ~np.asarray(a["yielded"])
    return hold, np.where(hold, a["m0"], np.nan)


def reference(f, eta, p, eff):
    rows = [solve_force(float(x), eta, p, eff) for x in f]
    return np.array([bool(r.get("found")) for r in rows]), np.array([r.get("m0", np.nan) for r in rows], float)


def pattern(hold) -> str:
    return "".join("1" if h else "." for h in hold)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reference", action="store_true", help="compare with the reference solver (slow)")
    ap.add_argument("--reference-cache", type=Path, help="JSON file of the reference's answers (read, or written)")
    ap.add_argument("--steps", help="comma list of step counts for the fast path alone")
    args = ap.parse_args(argv)
    if args.reference:
        cache = {}
        if args.reference_cache and args.reference_cache.exists():
            cache = json.loads(args.reference_cache.read_text())
        print("| stem | eta, p, mu | forces | reference holds | fast path holds | fast only | reference only |"
              " largest dm0 where both hold |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|")
        patterns = []
        for name, eta, p, eff, f in NEAR_TIP:
            if name not in cache:
                r_hold, r_m0 = reference(f, eta, p, eff)
                cache[name] = {"found": r_hold.tolist(), "m0": [None if np.isnan(x) else x for x in r_m0]}
                if args.reference_cache:
                    tmp = args.reference_cache.with_suffix(".tmp")
                    tmp.write_text(json.dumps(cache))
                    tmp.replace(args.reference_cache)
            r_hold = np.array(cache[name]["found"])
            r_m0 = np.array([np.nan if x is None else x for x in cache[name]["m0"]], float)
            a_hold, a_m0 = fast(f, eta, p, eff)
            both = a_hold & r_hold
            dm = float(np.max(np.abs(a_m0[both] - r_m0[both]))) if both.any() else float("nan")
            print(f"| {name} | {eta}, {p}, {eff['mu']} | {f.size} | {r_hold.sum()} | {a_hold.sum()} |"
                  f" {np.sum(a_hold & ~r_hold)} | {np.sum(r_hold & ~a_hold)} | {dm:.1e} |", flush=True)  # fmt: skip
            patterns.append((name, pattern(r_hold), pattern(a_hold)))
        for name, r, a in patterns:
            print(f"\n{name}\n  reference {r}\n  fast      {a}")
    if args.steps:
        steps = [int(s) for s in args.steps.split(",")]
        for name, eta, p, eff, f in NEAR_TIP:
            if name not in ("friction_fold", "friction_fold_high"):
                continue
            print(f"\n{name} (eta {eta}, p {p}, mu {eff['mu']}; forces {f[0]:g}-{f[-1]:g}, {f.size})")
            for n in steps:
                hold, _ = fast(f, eta, p, eff, n)
                last = f[np.flatnonzero(hold).max()] if hold.any() else float("nan")
                print(f"  {n:4d} steps: {hold.sum():3d} held, last {last:.4f}  {pattern(hold)}", flush=True)


if __name__ == "__main__":
    main()

"""How far apart the conditions' pooled noise correlations come out, on the stored group runs (issue 23).

    python scripts/pool_spread_check.py

fit-group warns when the sd (ddof 1) of the conditions' posterior-median Fisher z = atanh(rho_force) exceeds
the pool's spread (``POOL_SPREAD``; summary.json's ``pooled.rho_force.conditions_spread_fisher_z``). This
reads two stored studies and prints, per run, the medians and that sd over the spread: equal correlations
(``docs/results/group_noise_draws_rep1_pooled_rho.jsonl``, 16 noise draws of four conditions at rho 0.9, the
three cuts' medians stored) and
correlations that differ by condition (``docs/results/group_study_rho_by_condition_pooled_session50.csv``, 12
replicates of rho 0.3/0.6/0.9/0.97 for intact/cut1/cut2/cut3; ``scripts/group_study.py --rho``). Last, how
many of each would be warned. Reads only; about a second.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from bayesrod.inference.group import POOL_SPREAD, correlation_spread

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def main() -> None:
    warned = {}
    for l in (RESULTS / "group_noise_draws_rep1_pooled_rho.jsonl").read_text().splitlines():
        r = json.loads(l)
        rhos = [r[k]["rho_force"] for k in sorted(r) if k.startswith("noise_")]
        x = correlation_spread(rhos) / POOL_SPREAD
        warned.setdefault("equal rho 0.9", []).append(x > 1)
        print(f"equal    draw {r['draw']:2d}  rho {np.round(rhos, 3)}  spread / pool {x:.2f}")
    for r in csv.DictReader((RESULTS / "group_study_rho_by_condition_pooled_session50.csv").read_text().splitlines()):
        conds = [k[4:-4] for k in r if k.startswith("rho_") and k.endswith("_med")]
        rhos = [float(r[f"rho_{c}_med"]) for c in conds]
        x = correlation_spread(rhos) / POOL_SPREAD
        warned.setdefault("rho 0.3/0.6/0.9/0.97", []).append(x > 1)
        print(f"differ   rep  {int(r['rep']):2d}  rho {np.round(rhos, 3)}  spread / pool {x:.2f}")
    for k, v in warned.items():
        print(f"{k}: warned {sum(v)} of {len(v)}")


if __name__ == "__main__":
    main()

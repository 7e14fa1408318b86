"""Where the likelihood's slip term puts a push's slip, against where the simulator stopped it (issue 21).

For each one-height, forces-only SBC case of ``scripts/sbc_geometry.py`` (the seeds of a CSV it wrote), at the
case's true parameters: the simulator's slip (the end of its loading branch, ``_loading_branch``: the largest
contact displacement that ``force_from_displacement`` solves), the slip displacement the likelihood's table
gives (``RodLikelihood.slip_displacement_m``: the branch end of ``ForceCurves``, the largest force with
contact), the start of the model's slip range (``slip_displacement_m(..., early=True)``: where the force
first comes within ``SLIP_FORCE_REL`` of the end's), the data's window (lo, hi] and the term's softening tau.
Their difference over tau says how far the slip term pulls p, ``p_shift`` by how much (the difference over the
table's dD_s/dp), and ``sim_in_model_range`` whether the simulator's slip lies in the model's range.

Usage::

    python scripts/sbc_geometry.py --replicates 240 --first-seed 240 --only one-height-forces --slip --out DIR ...
    python scripts/slip_table_check.py DIR/sbc_geometry.csv --out slip_check.csv [--part 0 --parts 2]

About 3 s per case on an idle core (two cases in 6.5 s with the imports; each case builds its tables).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

import sbc_geometry as S  # noqa: E402

from bayesrod.dataset.simulate import _loading_branch  # noqa: E402
from bayesrod.inference.likelihood import build_likelihood  # noqa: E402
from bayesrod.inference.priors import load_prior  # noqa: E402

#: the effects the SBC runs of docs/validation.md cycled through (its --effects, after 'none')
EFFECTS = S.EFFECTS_BEFORE_FRICTION


def check(seed: int, prior) -> dict:
    case = S.draw_case(seed, EFFECTS)
    ds = S.simulate_case(seed, case, frames=2, step_l=0.01)
    cfg, _ = ds.simulation
    h = case["heights_m"][0]
    D_sim = float(_loading_branch(cfg, h)[0][-1])
    effects = (case["effect"],) if case["effect"] else ()
    lik = build_likelihood(ds, prior, effects, use_shapes=False, slip=True)
    truth = {k: np.array([case[k]]) for k in ("EI0", "p", "sigma_force_N")}
    if case["effect"]:
        truth[case["effect"]] = np.array([case["effect_value"]])
    D_tab = float(lik.slip_displacement_m(truth)[0, 0])
    D_early = float(lik.slip_displacement_m(truth, early=True)[0, 0])
    lo, hi, tau = float(lik.slip_lo_m[0]), float(lik.slip_hi_m[0]), float(lik.slip_scale_m[0])
    dp = 1e-3
    slope = (float(lik.slip_displacement_m({**truth, "p": truth["p"] + dp})[0, 0]) - D_tab) / dp
    return {
        "seed": seed,
        "effect": case["effect"] or "none",
        "p": case["p"],
        "D_sim_m": D_sim,
        "D_table_m": D_tab,
        "window_lo_m": lo,
        "window_hi_m": hi,
        "tau_m": tau,
        "D_table_early_m": D_early,
        "table_minus_sim_over_tau": (D_tab - D_sim) / tau,
        # the slip term asks only that [D_early, D_table] meet the window: the simulator's slip must lie in it
        "sim_in_model_range": bool(D_early - 1e-9 <= D_sim <= D_tab + 1e-9),
        "model_range_over_tau": (D_tab - D_early) / tau,
        "sim_in_window": bool(lo < D_sim <= hi),
        "p_shift": (D_tab - D_sim) / slope if slope else float("nan"),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("csv", type=Path, help="an sbc_geometry.csv of one-height, forces-only cases")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--part", type=int, default=0)
    ap.add_argument("--parts", type=int, default=1)
    args = ap.parse_args(argv)
    rows = pd.read_csv(args.csv)
    seeds = [int(s) for s in rows[rows.error.isna()].seed]
    prior = load_prior(S.PRIOR)
    out = []
    for i, seed in enumerate(seeds):
        if i % args.parts == args.part:
            out.append(check(seed, prior))
            print(out[-1], flush=True)
    d = pd.DataFrame(out)
    tmp = args.out.with_suffix(".tmp")
    d.to_csv(tmp, index=False)
    tmp.replace(args.out)
    err = d.table_minus_sim_over_tau
    big = int((err.abs() > 1).sum())
    print(f"{len(d)} cases: |table - simulator| over tau, median {err.abs().median():.2f}, above 1 in {big}")
    width = d.model_range_over_tau
    print(
        f"the simulator's slip inside the model's range [early, end] in {int(d.sim_in_model_range.sum())}/{len(d)}; "
        f"range over tau median {width.median():.2f}, max {width.max():.2f}"
    )


if __name__ == "__main__":
    main()

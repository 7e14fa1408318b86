"""Can the data tell two candidate effects apart? Each candidate alone, on the diagnosis study's datasets.

    python scripts/diagnose_alternatives.py --effect rest_curvature --candidates rest_curvature,base_tilt \
        --seeds 20,21,23,24 [--shapes]

For each seed: the twig of scripts/diagnose_study.py (three heights, AR(1) force noise rho 0.9, the
effect at its study size, forces only unless ``--shapes``), diagnosed once per candidate with only that
candidate in the catalog. Printed per candidate: whether it was added, its likelihood-ratio statistic
against the plain rod, the true held-out force RMSE after (leave one height out, refitted), and its
fitted values. Two candidates whose statistics differ by less than diagnose's ``ALTERNATIVE_LR`` are
alternatives these data do not tell apart (docs/diagnose.md).
"""

from __future__ import annotations

import argparse
import json

from diagnose_study import EFFECTS

import bayesrod
from bayesrod.inference.diagnose import ForwardModel, diagnose
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="rest_curvature", choices=sorted(EFFECTS))
    ap.add_argument("--candidates", default="rest_curvature,base_tilt")
    ap.add_argument("--seeds", default="20,21,23,24")
    ap.add_argument("--shapes", action="store_true", help="fit the centerlines too")
    a = ap.parse_args()
    for seed in (int(s) for s in a.seeds.split(",")):
        spec = bayesrod.simulate(
            "twig",
            seed=seed,
            effects=Effects.from_mapping({a.effect: EFFECTS[a.effect]}),
            noise_rho=0.9,
            config_overrides={"specimen": f"diag-{a.effect}-{seed}", "n_frames_engaged": 8},
        )
        model = ForwardModel(prepare_data(spec, use_shapes=a.shapes), spec.length_m)
        out = []
        for c in a.candidates.split(","):
            r = diagnose(model, candidates=[c])
            row = next(t for t in r["candidates"] if t["effect"] == c and t["round"] == 1)
            fitted = {k: round(float(v), 4) for k, v in r["fitted"].items()}
            out.append(
                f"{c}: added {bool(r['added_effects'])}, LR {row.get('lr_statistic', float('nan')):.2f}, held-out "
                f"{r['before']['heldout_force_rmse_N']:.3f} -> {r['after']['heldout_force_rmse_N']:.3f} N, "
                f"{json.dumps(fitted)}"
            )
        print(f"seed {seed}: " + "; ".join(out), flush=True)


if __name__ == "__main__":
    main()

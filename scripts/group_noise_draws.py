"""One stem, many noise draws: is a joint posterior as wide as its median scatters? (issue 23)

    python scripts/group_noise_draws.py --rep 1 --draws 16 --out draws.jsonl [--shared EI0,p]
        [--pooled auto|rho_force|'']

Replicate ``--rep`` of scripts/group_study.py (two heights, 0.45 and 0.65 m; intact and three cuts; AR(1)
force noise, rho 0.9) with its stem and anchorage held, simulated again under ``--draws`` fresh noise draws
(``simulate_group`` seeds 5000, 5004, 5008, ...: draw s from 5000 + 4 s, so no two draws share a
condition's noise; ``--seed-stride 1`` gives the overlapping seeds 5000, 5001, ... of the runs before session
51), each fitted as the study fits (``fit_group``, prior ``woody``, 5000 steps at most, target ESS 200; no
sharing check). Appends one JSON line per draw to ``--out``
(resumable: draws already there are skipped): the shared EI0 and p and each cut's base compliance
``{median, q05, q95}``, each condition's noise medians, R-hat and the truth. Then prints, per quantity, the
sd of the posterior medians over the draws, the mean posterior sd (90% half-width / 1.645), their ratio
(1 when the intervals are as wide as the medians scatter), z rms and the 90% coverage. About 3-5 minutes
per draw on one core.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from group_study import RATIOS, SEED_STRIDE, stem

import bayesrod


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rep", type=int, default=1)
    ap.add_argument("--draws", type=int, default=16)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--shared", default="EI0,p", help="fit_group's shared (comma list)")
    ap.add_argument("--pooled", default="auto", help="fit_group's pooled (comma list, '' for none; default auto)")
    ap.add_argument("--seed-stride", type=int, default=SEED_STRIDE, help="draw s from seed 5000 + stride x s")
    a = ap.parse_args(argv)
    shared = tuple(x for x in a.shared.split(",") if x)
    pooled = "auto" if a.pooled == "auto" else tuple(x for x in a.pooled.split(",") if x)
    EI0, p, conds, truth_c = stem(a.rep)
    truth = {"EI0": EI0, "p": p, **truth_c}
    done = {json.loads(x)["draw"] for x in a.out.read_text().splitlines()} if a.out.exists() else set()
    for s in range(a.draws):
        if s in done:
            continue
        t0 = time.time()
        dss = bayesrod.simulate_group(
            "twig",
            conditions=conds,
            seed=5000 + a.seed_stride * s,
            heights_m=(0.45, 0.65),
            noise_rho=0.9,
            config_overrides={"n_frames_engaged": 2, "EI0": EI0, "p": p},
        )
        g = bayesrod.fit_group(
            list(dss),
            prior="woody",
            progress=False,
            target_ess=200,
            max_steps=5000,
            seed=s,
            sharing=False,
            shared=shared,
            pooled=pooled,
        )
        d = g.to_dict()
        row = {"draw": s, "EI0": d["shared"]["EI0"], "p": d["shared"]["p"], "rhat": d["convergence"]["rhat_max"]}
        row |= {"truth": truth, "seconds": time.time() - t0}
        for c in RATIOS:
            row[c] = d["conditions"][c]["base_compliance_rad_per_Nm"]
            row[f"noise_{c}"] = {k: d["conditions"][c][k]["median"] for k in ("sigma_force_N", "rho_force")}
        with a.out.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(f"draw {s}: {row['seconds']:.0f} s, R-hat {row['rhat']:.3f}", flush=True)
    rows = [json.loads(x) for x in a.out.read_text().splitlines()]
    print("| quantity | draws | sd of medians | mean posterior sd | ratio | z rms | 90% covered |")
    print("|---|---|---|---|---|---|---|")
    for q in ("EI0", *RATIOS):
        med = np.array([r[q]["median"] for r in rows])
        sd = np.array([(r[q]["q95"] - r[q]["q05"]) / 2 / 1.645 for r in rows])
        z = (med - truth[q]) / sd
        print(
            f"| {q} | {len(rows)} | {med.std(ddof=1):.3g} | {sd.mean():.3g} | {sd.mean() / med.std(ddof=1):.2f} | "
            f"{np.sqrt(np.mean(z**2)):.2f} | {int(np.sum(np.abs(z) <= 1.645))}/{len(rows)} |"
        )


if __name__ == "__main__":
    main()

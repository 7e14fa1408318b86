"""EI0 and p of every blueberry cane with the cane length fixed at the guess and marginalised (issue 19).

    bayesrod import blueberry ../shared/data/blueberry-canes --out blueberry --length-m 1.6
    python scripts/fit_blueberry_length.py blueberry --out blueberry-length [--workers 2]

Two force-only fits per cane with AR(1) force noise (prior ``woody``): the length held at
the importer's 1.6 m guess (``length="known"``) and sampled (``length="unknown"``, prior
uniform on [L/1.5, 1.5 L] above the highest contact, docs/priors.md). Writes
blueberry_length.csv (resumable: canes done are skipped) and blueberry_length.md, the table
of docs/validation.md: 90% intervals of EI0 and p both ways, the ratio of the interval
widths (log EI0; p), the length's posterior, each fit's model check and wall time.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.io import append_rows, read_rows

FIELDS = ["cane", "heights"]
for _m in ("known", "unknown"):
    FIELDS += [f"EI0_{_m}", f"EI0_q05_{_m}", f"EI0_q95_{_m}", f"p_{_m}", f"p_q05_{_m}", f"p_q95_{_m}"]
    FIELDS += [f"check_{_m}", f"seconds_{_m}"]
FIELDS += ["L", "L_q05", "L_q95"]


def one(job) -> dict:
    ds, ess = job
    row = {"cane": Path(ds).name}
    for mode in ("known", "unknown"):
        t0 = time.perf_counter()
        post = bayesrod.fit(
            ds, prior="woody", use_shapes=False, force_noise="ar1", length=mode, progress=False, target_ess=ess
        )
        s = post.summary()
        row["heights"] = " ".join(f"{h:g}" for h in post.to_dict()["data"]["heights_m"])
        for name in ("EI0", "p"):
            row[f"{name}_{mode}"] = s.loc[name, "median"]
            row[f"{name}_q05_{mode}"] = s.loc[name, "q05"]
            row[f"{name}_q95_{mode}"] = s.loc[name, "q95"]
        row[f"check_{mode}"] = post.to_dict()["model_check"]["verdict"]
        row[f"seconds_{mode}"] = round(time.perf_counter() - t0, 1)
        if mode == "unknown":
            row["L"], row["L_q05"], row["L_q95"] = (s.loc["length_m", k] for k in ("median", "q05", "q95"))
    return row


def table(rows) -> str:
    out = [
        "| cane | EI0 [N m^2], L fixed 1.6 m | EI0, L sampled | width ratio log EI0 | p, L fixed | p, L sampled "
        "| width ratio p | L [m] | check fixed / sampled | s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    rw_e, rw_p = [], []
    for r in sorted(rows, key=lambda r: r["cane"]):
        f = {k: float(v) for k, v in r.items() if k not in ("cane", "heights") and not k.startswith("check")}
        we = np.log(f["EI0_q95_unknown"] / f["EI0_q05_unknown"]) / np.log(f["EI0_q95_known"] / f["EI0_q05_known"])
        wp = (f["p_q95_unknown"] - f["p_q05_unknown"]) / (f["p_q95_known"] - f["p_q05_known"])
        rw_e.append(we)
        rw_p.append(wp)
        out.append(
            f"| {r['cane']} | {f['EI0_known']:.3g} [{f['EI0_q05_known']:.3g}, {f['EI0_q95_known']:.3g}] "
            f"| {f['EI0_unknown']:.3g} [{f['EI0_q05_unknown']:.3g}, {f['EI0_q95_unknown']:.3g}] | {we:.2f} "
            f"| {f['p_known']:.2f} [{f['p_q05_known']:.2f}, {f['p_q95_known']:.2f}] "
            f"| {f['p_unknown']:.2f} [{f['p_q05_unknown']:.2f}, {f['p_q95_unknown']:.2f}] | {wp:.2f} "
            f"| {f['L']:.2f} [{f['L_q05']:.2f}, {f['L_q95']:.2f}] | {r['check_known']} / {r['check_unknown']} "
            f"| {f['seconds_known']:.0f} + {f['seconds_unknown']:.0f} |"
        )
    out.append(
        f"| **median of {len(rows)}** | | | {np.median(rw_e):.2f} | | | {np.median(rw_p):.2f} | | "
        f"| {np.median([float(r['seconds_known']) for r in rows]):.0f} + "
        f"{np.median([float(r['seconds_unknown']) for r in rows]):.0f} |"
    )
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="folder of imported cane datasets")
    ap.add_argument("--out", default="blueberry-length")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--target-ess", type=float, default=400.0)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "blueberry_length.csv"
    done = {r["cane"] for r in read_rows(csv)}
    canes = sorted(p for p in Path(args.root).iterdir() if (p / "specimen.json").is_file())
    jobs = [(str(p), args.target_ess) for p in canes if p.name not in done]
    with ProcessPoolExecutor(args.workers) as ex:
        for r in append_rows(csv, FIELDS, ex.map(one, jobs), new_file=not done):
            print(f"{r['cane']}: EI0 {r['EI0_known']:.3g} (L fixed) / {r['EI0_unknown']:.3g} (L sampled)", flush=True)
    text = table(read_rows(csv))
    (out / "blueberry_length.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

"""`bayesrod diagnose` on every imported blueberry cane: the before/after table of docs/validation.md.

    bayesrod import blueberry ../shared/data/blueberry-canes --out blueberry --length-m 1.6
    python scripts/diagnose_blueberry.py blueberry --out blueberry-diagnose [--workers 2] [--length unknown]

Runs the whole loop (every catalog effect; forces only: the canes have no
centerlines) on each cane, the assumed cane length held (``--length unknown`` fits it in every
model; the importer marks it approximate), writing ``OUT/<cane>/`` (diagnose.json, figures,
report.html), blueberry_diagnose.csv (resumable) and blueberry_diagnose.md.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.io import append_rows, read_rows

FIELDS = ["cane", "heights", "added", "fitted", "force_before", "force_after", "heldout_before", "heldout_after"]
FIELDS += ["unexplained", "structured_blocks_after", "top_round1", "lag1_before", "lag1_after", "rho_after"]
FIELDS += ["heldout_p", "seconds", "length_m"]


def one(job) -> dict:
    ds, out, length = job
    t0 = time.perf_counter()
    res = bayesrod.diagnose(ds, use_shapes=False, length=length)
    seconds = time.perf_counter() - t0
    res.save(out, overwrite=True)
    doc = res.to_dict()
    b, a = doc["before"], doc["after"]
    r1 = sorted((c for c in doc["candidates"] if c["round"] == 1), key=lambda c: -c["statistic"])[:3]
    return {
        "cane": Path(ds).name,
        "heights": " ".join(f"{p['height_m']:g}" for p in b["per_push"]),
        "added": ",".join(doc["added_effects"]),
        "fitted": json.dumps({k: np.round(v, 4).tolist() for k, v in doc["fitted"].items()}),
        "force_before": b["force_rmse_N"],
        "force_after": a["force_rmse_N"],
        "heldout_before": b["heldout_force_rmse_N"],
        "heldout_after": a["heldout_force_rmse_N"],
        "unexplained": int(doc["unexplained_structure"]),
        "structured_blocks_after": sum(s["structured"] for s in doc["structure_after"]),
        "top_round1": " ".join(f"{c['effect']}:{c['statistic']:.3g}" for c in r1),
        "lag1_before": b["residual_lag1"],
        "lag1_after": a["residual_lag1"],
        "rho_after": doc["noise"]["rho_force"],
        "heldout_p": " ".join(f"{c['heldout_p_value']:.3g}" for c in doc["candidates"] if c["selected"]),
        "seconds": round(seconds, 1),
        "length_m": doc["fitted"].get("length_m", doc["length_m"]),
    }


def table(rows) -> str:
    out = [
        "| cane | effects added | force RMSE before -> after [N] | held-out force RMSE before -> after [N] | "
        "change | bootstrap p | residual lag-1 before -> after | EI0 [N m^2], p, L [m] (MAP) | "
        "unexplained structure | s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    hb, ha, fb, fa = [], [], [], []
    for r in sorted(rows, key=lambda r: r["cane"]):
        b, a = float(r["heldout_before"]), float(r["heldout_after"])
        fit = json.loads(r["fitted"])
        hb.append(b)
        ha.append(a)
        fb.append(float(r["force_before"]))
        fa.append(float(r["force_after"]))
        out.append(
            f"| {r['cane']} | {r['added'] or 'none'} | {float(r['force_before']):.3f} -> {float(r['force_after']):.3f} "
            f"| {b:.3f} -> {a:.3f} | {100 * (a - b) / b:+.0f}% | {r['heldout_p'] or '-'} "
            f"| {float(r['lag1_before']):.2f} -> {float(r['lag1_after']):.2f} "
            f"| {fit['EI0']:.3g}, {fit['p']:.2f}, {float(r.get('length_m') or 0):.3g} "
            f"| {'yes' if int(r['unexplained']) else 'no'} | {r['seconds']} |"
        )
    counts: dict[str, int] = {}
    for r in rows:
        for e in filter(None, r["added"].split(",")):
            counts[e] = counts.get(e, 0) + 1
    out += [
        f"| **all {len(rows)} canes** | "
        + (", ".join(f"{e} ({n})" for e, n in sorted(counts.items(), key=lambda x: -x[1])) or "none")
        + f" | median {np.median(fb):.3f} -> {np.median(fa):.3f} | median {np.median(hb):.3f} -> {np.median(ha):.3f} "
        f"| {100 * (np.median(ha) - np.median(hb)) / np.median(hb):+.0f}% (of medians) | | | | "
        f"{sum(int(r['unexplained']) for r in rows)}/{len(rows)} "
        f"| median {np.median([float(r['seconds']) for r in rows]):.0f} |",
    ]
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="folder of imported cane datasets")
    ap.add_argument("--out", default="blueberry-diagnose")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--length", default="known", choices=["known", "unknown", "auto"], help="as bayesrod diagnose")
    ap.add_argument("--shard", default="0/1", help="I/N: every N-th cane from the I-th (parallel runs, a CSV each)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    i, n = (int(v) for v in args.shard.split("/"))
    csv = out / ("blueberry_diagnose.csv" if n == 1 else f"blueberry_diagnose.{i}.csv")
    done = {r["cane"] for r in read_rows(csv)}
    canes = sorted(p for p in Path(args.root).iterdir() if (p / "specimen.json").is_file())[i::n]
    jobs = [(str(p), str(out / p.name), args.length) for p in canes if p.name not in done]
    with ProcessPoolExecutor(args.workers) as ex:
        for r in append_rows(csv, FIELDS, ex.map(one, jobs), new_file=not done):
            print(f"{r['cane']}: added [{r['added']}] held-out {r['heldout_before']:.3f} -> {r['heldout_after']:.3f}")
    rows = [r for f in sorted(out.glob("blueberry_diagnose*.csv")) for r in read_rows(f)]
    text = table(rows)
    (out / "blueberry_diagnose.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

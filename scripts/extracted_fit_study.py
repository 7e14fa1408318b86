"""Are intervals from extracted centerlines calibrated? (issue 4: the correlated error model)

    python scripts/extracted_fit_study.py --out extracted-study [--preset twig] [--seeds 11:21] [--workers 1]
        [--arm leading|trailing]

Per seed: simulate a dataset with RGB-D frames (``bayesrod simulate --frames``),
extract its centerlines (``bayesrod extract``), and fit forces and extracted
shapes twice: with the shape likelihood weighted by the measured n_eff / n
(``--shape-weight auto``, the default) and with every point independent
(``--shape-weight 1``). Records the 90% intervals of EI0 and p and whether
they cover the truth. Writes extracted_fit_study.csv (resumable) and prints
the coverage table.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import bayesrod
from bayesrod.cli import main as cli
from bayesrod.dataset.io import append_rows, read_rows

FIELDS = ["case", "preset", "seed", "weight", "shape_weight", "tau_along", "tau_frames", "n_points"]
FIELDS += [f"{n}_{q}" for n in ("EI0", "p") for q in ("truth", "median", "q05", "q95", "covered")]


def one(job) -> list[dict]:
    preset, seed, arm = job
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bayesrod.simulate(preset, seed=seed).save(tmp / "sim", frames=True, arm=arm)
        cli(["extract", str(tmp / "sim"), "--out", str(tmp / "ext"), "--quiet"])
        for weight in ("auto", "1"):
            out = tmp / f"fit-{weight}"
            cli(["fit", str(tmp / "ext"), "--out", str(out), "--quiet", "--seed", str(seed), "--shape-weight", weight])
            s = json.loads((out / "summary.json").read_text())
            corr = s["data"].get("shape_correlation") or {}
            row = {
                "case": f"{preset}-{seed}-{weight}",
                "preset": preset,
                "seed": seed,
                "weight": weight,
                "shape_weight": s["data"]["shape_weight"],
                "tau_along": corr.get("tau_along", ""),
                "tau_frames": corr.get("tau_frames", ""),
                "n_points": s["data"]["n_shape_points"],
            }
            for n in ("EI0", "p"):
                q, t = s["parameters"][n], s["truth"][n]
                row |= {f"{n}_truth": t, f"{n}_median": q["median"], f"{n}_q05": q["q05"], f"{n}_q95": q["q95"]}
                row[f"{n}_covered"] = int(q["q05"] <= t <= q["q95"])
            rows.append(row)
    return rows


def table(rows) -> str:
    out = ["| preset | shape weight | replicates | mean weight | EI0 covered | p covered | mean 90% width of p |"]
    out.append("|---|---|---|---|---|---|---|")
    for preset in sorted({r["preset"] for r in rows}):
        for w in ("auto", "1"):
            rs = [r for r in rows if r["preset"] == preset and r["weight"] == w]
            if not rs:
                continue
            mw = sum(float(r["shape_weight"]) for r in rs) / len(rs)
            width = sum(float(r["p_q95"]) - float(r["p_q05"]) for r in rs) / len(rs)
            ce = sum(int(r["EI0_covered"]) for r in rs)
            cp = sum(int(r["p_covered"]) for r in rs)
            out.append(f"| {preset} | {w} | {len(rs)} | {mw:.3g} | {ce}/{len(rs)} | {cp}/{len(rs)} | {width:.4f} |")
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="extracted-study")
    ap.add_argument("--preset", default="twig", choices=["twig", "grass"])
    ap.add_argument("--seeds", default="11:21", metavar="START:STOP")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--arm", default="leading", choices=["trailing", "leading"], help="where the probe's bar is")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "extracted_fit_study.csv"
    done = {int(r["seed"]) for r in read_rows(csv) if r["preset"] == args.preset}
    a, b = map(int, args.seeds.split(":"))
    jobs = [(args.preset, s, args.arm) for s in range(a, b) if s not in done]

    def rows():
        with ProcessPoolExecutor(args.workers) as ex:
            for rs in ex.map(one, jobs):
                yield from rs

    for r in append_rows(csv, FIELDS, rows(), new_file=not csv.is_file()):
        print(
            f"{r['case']}: weight {r['shape_weight']:.3g}, p {r['p_median']:.4f} [{r['p_q05']:.4f}, "
            f"{r['p_q95']:.4f}] truth {r['p_truth']}",
            flush=True,
        )
    text = table(read_rows(csv))
    (out / "extracted_fit_study.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

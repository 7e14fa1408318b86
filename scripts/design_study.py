"""Does `bayesrod design` pick better heights than even or random ones? (issue 7)

    python scripts/design_study.py --specimens 20 --out design-study [--workers 2]

Each specimen is a random stem (half twig-like, half grass-like: EI0 log-sd 0.3
around the preset, p and L uniform over a plausible range), pushed first at
h1 = 0.55 L, with pushes stopped at a fixed contact displacement (twig 100 mm,
grass 80 mm) and the sensor range [0.05, 8] N. From the force-only fit of that
push, two more pushes are chosen by four strategies, and the final force-only
fit on all three pushes is scored by the width of its 90% interval on p:

* design   -- sequential: fit -> design -> push -> fit -> design -> push -> fit
* even     -- the feasible candidates nearest one third and two thirds of the feasible range
* extremes -- the lowest and highest feasible candidates
* random   -- two distinct feasible candidates drawn at random

Feasibility (sensor range, slip) for the baselines is the one `design` computed
from the first fit. Candidates: 0.10 L to 0.90 L in 17 steps. Writes
design_study.csv (resumable) and design_study.md (the table in docs/validation.md).
"""

from __future__ import annotations

import argparse
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from bayesrod.api.calibration import fit_for_calibration
from bayesrod.dataset.io import append_rows, read_rows
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated
from bayesrod.inference.design import PushPlan, design_heights

STRATEGIES = ("design", "even", "extremes", "random")
FIELDS = ["specimen", "kind", "EI0_true", "p_true", "length_m", "h1"]
for _s in STRATEGIES:
    FIELDS += [f"{_s}_h2", f"{_s}_h3", f"{_s}_p_width", f"{_s}_EI0_relwidth", f"{_s}_p_covered"]
FIELDS += ["p_width_after_one"]

RANGE = (0.05, 8.0)


def truth(k: int) -> dict:
    rng = np.random.default_rng(7000 + k)
    if k % 2 == 0:
        return dict(
            kind="twig",
            EI0=2.63 * np.exp(0.3 * rng.standard_normal()),
            p=rng.uniform(0.25, 0.8),
            length_m=rng.uniform(0.7, 0.9),
            cap=0.10,
        )
    return dict(
        kind="grass",
        EI0=0.112 * np.exp(0.3 * rng.standard_normal()),
        p=rng.uniform(1.2, 2.0),
        length_m=rng.uniform(0.4, 0.55),
        cap=0.08,
    )


def fit(tr: dict, heights, k: int, tmp: Path) -> dict:
    """Simulate the pushes at ``heights`` (the first push is the same whatever follows) and fit forces only."""
    cfg = SimConfig.from_preset(
        tr["kind"],
        seed=k,
        EI0=tr["EI0"],
        p=tr["p"],
        length_m=tr["length_m"],
        heights_m=tuple(heights),
        max_contact_displacement_m=tr["cap"],
        force_range_N=RANGE,
        n_frames_engaged=2,
        specimen=f"design-{k}",
    )
    ds = Path(tempfile.mkdtemp(dir=tmp))
    write_simulated(cfg, simulate(cfg), ds)
    f = fit_for_calibration(ds, "default", seed=k, use_shapes=False, target_ess=600, n_rank=4000)
    return {name: f[name]["draws"] for name in f["names"]} | {"_q": {n: f[n]["q"] for n in ("EI0", "p")}}


def design(samples: dict, tr: dict, cand) -> dict:
    plan = PushPlan(tr["cap"], 60, RANGE)
    s = {k: v for k, v in samples.items() if not k.startswith("_")}
    return design_heights(s, tr["length_m"], cand, plan, seed=0)


def one(k: int) -> dict:
    tr = truth(k)
    L = tr["length_m"]
    cand = np.linspace(0.10, 0.90, 17) * L
    h1 = 0.55 * L
    row = {"specimen": k, "kind": tr["kind"], "EI0_true": tr["EI0"], "p_true": tr["p"], "length_m": L, "h1": h1}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        s1 = fit(tr, [h1], k, tmp)
        q = s1["_q"]["p"]
        row["p_width_after_one"] = q[2] - q[0]
        d1 = design(s1, tr, cand)
        feas = np.array([c["height_m"] for c in d1["candidates"] if c["feasible"]])
        if feas.size < 2:
            raise RuntimeError(f"specimen {k}: fewer than 2 feasible heights")
        h2 = d1["recommended_height_m"]
        s2 = fit(tr, [h1, h2], k, tmp)
        h3 = design(s2, tr, cand)["recommended_height_m"]
        a, b = feas.min(), feas.max()
        choice = {
            "design": (h2, h3),
            "even": tuple(feas[np.argmin(np.abs(feas - t))] for t in (a + (b - a) / 3, a + 2 * (b - a) / 3)),
            "extremes": (a, b),
            "random": tuple(np.random.default_rng(k).choice(feas, size=2, replace=False)),
        }
        for name, (x2, x3) in choice.items():
            s = fit(tr, [h1, x2, x3], k, tmp)
            qp, qe = s["_q"]["p"], s["_q"]["EI0"]
            row.update(
                {
                    f"{name}_h2": x2,
                    f"{name}_h3": x3,
                    f"{name}_p_width": qp[2] - qp[0],
                    f"{name}_EI0_relwidth": (qe[2] - qe[0]) / qe[1],
                    f"{name}_p_covered": int(qp[0] <= tr["p"] <= qp[2]),
                }
            )
    return row


def table(rows) -> str:
    w = {s: np.array([float(r[f"{s}_p_width"]) for r in rows]) for s in STRATEGIES}
    e = {s: np.array([float(r[f"{s}_EI0_relwidth"]) for r in rows]) for s in STRATEGIES}
    cov = {s: np.array([int(r[f"{s}_p_covered"]) for r in rows]) for s in STRATEGIES}
    one_w = np.array([float(r["p_width_after_one"]) for r in rows])
    out = [
        f"{len(rows)} simulated specimens; 90% interval on p after the first push: mean width {one_w.mean():.3f}.",
        "",
        "| two further pushes | mean width of 90% interval on p | median | design narrower in | "
        "mean rel. width on EI0 | 90% interval covers p |",
        "|---|---|---|---|---|---|",
    ]
    for s in STRATEGIES:
        better = "" if s == "design" else f"{int(np.sum(w['design'] < w[s]))}/{len(rows)}"
        out.append(
            f"| {s} | {w[s].mean():.4f} | {np.median(w[s]):.4f} | {better} | {e[s].mean():.4f} | "
            f"{cov[s].sum()}/{len(rows)} |"
        )
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--specimens", type=int, default=20)
    ap.add_argument("--out", default="design-study")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "design_study.csv"
    done = read_rows(csv)
    todo = [k for k in range(args.specimens) if str(k) not in {r["specimen"] for r in done}]
    with ProcessPoolExecutor(args.workers) as ex:
        for r in append_rows(csv, FIELDS, ex.map(one, todo), new_file=not done):
            print(
                f"specimen {r['specimen']} ({r['kind']}): design {r['design_h2']:.3f}, {r['design_h3']:.3f} m; "
                f"p widths design {r['design_p_width']:.4f} even {r['even_p_width']:.4f} "
                f"random {r['random_p_width']:.4f}",
                flush=True,
            )
    rows = read_rows(csv)
    text = table(rows)
    (out / "design_study.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

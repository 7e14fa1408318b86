"""Bayesian posterior median against the seed's two-stage estimate, over simulated datasets.

    python scripts/compare_two_stage.py --seeds 8 --out two-stage-results
    python scripts/compare_two_stage.py --seeds 8 --two-stage-only   # the seed's estimate alone, ~4 min

For each preset (twig, grass) and seed: simulate with default noise, run the
seed's deterministic pipeline (direct estimator -> p_fit -> EI0_fit) and the
Bayesian fit (default prior, forces and shapes), and record both estimates,
the absolute errors and whether the 90% interval covers the truth. Writes
compare.csv and compare.md (the table in docs/validation.md). Resumable.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from bayesrod.api.calibration import fit_for_calibration
from bayesrod.dataset import read_dataset
from bayesrod.dataset.io import append_rows, read_rows
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated
from bayesrod.inference.direct import two_stage_fit

FIELDS = ["preset", "seed", "EI0_true", "p_true", "ts_EI0", "ts_p", "bayes_EI0", "bayes_p"]
FIELDS += ["bayes_EI0_q05", "bayes_EI0_q95", "bayes_p_q05", "bayes_p_q95", "rhat_max"]


def _simulated(preset: str, seed: int, tmp: str):
    """Simulate a dataset into ``tmp``; return its config and the seed's two-stage estimate."""
    cfg = SimConfig.from_preset(preset, seed=seed)
    write_simulated(cfg, simulate(cfg), Path(tmp))
    return cfg, two_stage_fit(read_dataset(tmp))


def one(preset: str, seed: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        cfg, ts = _simulated(preset, seed, tmp)
        fit = fit_for_calibration(Path(tmp), "default", seed=seed, target_ess=1000)
    return {
        "preset": preset,
        "seed": seed,
        "EI0_true": cfg.EI0,
        "p_true": cfg.p,
        "ts_EI0": ts.EI0,
        "ts_p": ts.p,
        "bayes_EI0": fit["EI0"]["q"][1],
        "bayes_p": fit["p"]["q"][1],
        "bayes_EI0_q05": fit["EI0"]["q"][0],
        "bayes_EI0_q95": fit["EI0"]["q"][2],
        "bayes_p_q05": fit["p"]["q"][0],
        "bayes_p_q95": fit["p"]["q"][2],
        "rhat_max": fit["rhat_max"],
    }


def table(rows) -> str:
    out = [
        "| preset | n | EI0: two-stage mean rel. error | EI0: Bayes mean rel. error | p: two-stage mean abs. error "
        "| p: Bayes mean abs. error | Bayes 90% covers EI0 | Bayes 90% covers p |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for preset in sorted({r["preset"] for r in rows}):
        rs = [r for r in rows if r["preset"] == preset]

        def f(k, rs=rs):
            return np.array([float(r[k]) for r in rs])

        e_ts = np.abs(f("ts_EI0") / f("EI0_true") - 1)
        e_b = np.abs(f("bayes_EI0") / f("EI0_true") - 1)
        p_ts = np.abs(f("ts_p") - f("p_true"))
        p_b = np.abs(f("bayes_p") - f("p_true"))
        cE = np.mean((f("bayes_EI0_q05") <= f("EI0_true")) & (f("EI0_true") <= f("bayes_EI0_q95")))
        cp = np.mean((f("bayes_p_q05") <= f("p_true")) & (f("p_true") <= f("bayes_p_q95")))
        out.append(
            f"| {preset} | {len(rs)} | {e_ts.mean():.2%} | {e_b.mean():.2%} | {p_ts.mean():.4f} | {p_b.mean():.4f} "
            f"| {cE:.0%} | {cp:.0%} |"
        )
    return "\n".join(out) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--out", type=Path, default=Path("two-stage-results"))
    ap.add_argument("--two-stage-only", action="store_true", help="re-measure the two-stage errors only (no fits)")
    a = ap.parse_args()
    if a.two_stage_only:
        for preset in ("twig", "grass"):
            e, pe = [], []
            for seed in range(1, a.seeds + 1):
                with tempfile.TemporaryDirectory() as tmp:
                    cfg, ts = _simulated(preset, seed, tmp)
                e.append(abs(ts.EI0 / cfg.EI0 - 1))
                pe.append(abs(ts.p - cfg.p))
            print(f"{preset}: two-stage mean rel. error of EI0 {np.mean(e):.2%}, of p (abs.) {np.mean(pe):.4f}")
        return
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "compare.csv"
    rows = read_rows(path)
    new_file = not rows
    done = {(r["preset"], int(r["seed"])) for r in rows}
    from tqdm import tqdm

    todo = [(p, s) for p in ("twig", "grass") for s in range(1, a.seeds + 1) if (p, s) not in done]
    rows += list(append_rows(path, FIELDS, (one(p, s) for p, s in tqdm(todo, desc="datasets")), new_file))
    md = table(rows)
    (a.out / "compare.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()

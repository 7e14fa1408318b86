"""Simulation-based calibration of the posterior of EI0 and p (docs/validation.md).

    python scripts/sbc.py --replicates 100 --jobs 2 --out sbc-results

Each replicate draws EI0, p and the noise from scripts/sbc_prior.json, simulates
a twig-geometry dataset (heights 0.45/0.55/0.65 m, forces and centerlines),
fits it with the same prior, and records the rank of the truth among 99
posterior draws and whether the 90% interval covers it. Writes sbc.csv,
sbc.md (coverage table) and rank_histograms.png into --out. Resumable: rows
already in sbc.csv are not recomputed.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from bayesrod.api.calibration import sbc_replicate
from bayesrod.dataset.io import append_rows, read_rows

PRIOR = str(Path(__file__).with_name("sbc_prior.json"))


def _run(seed):
    try:
        return sbc_replicate(seed, PRIOR)
    except Exception as e:  # a failed replicate is reported, never dropped silently
        return {"seed": seed, "error": f"{type(e).__name__}: {e}"}


def summarise(rows, out: Path):
    from scipy.stats import binom, chisquare

    ok = [r for r in rows if not r.get("error")]
    lines = [
        f"SBC over {len(ok)} replicates ({len(rows) - len(ok)} failed), prior scripts/sbc_prior.json, "
        "99 posterior draws per replicate.",
        "",
        "| parameter | 90% coverage | binomial 95% range | rank chi2 p-value (10 bins) |",
        "|---|---|---|---|",
    ]
    n = len(ok)
    lo, hi = binom.ppf(0.025, n, 0.9) / n, binom.ppf(0.975, n, 0.9) / n
    for k in ("EI0", "p"):
        cov = np.mean([r[f"{k}_covered"] for r in ok])
        ranks = np.array([r[f"{k}_rank"] for r in ok])
        counts = np.histogram(ranks, bins=10, range=(0, 100))[0]
        pval = chisquare(counts).pvalue
        lines.append(f"| {k} | {cov:.1%} | {lo:.0%}-{hi:.0%} | {pval:.2f} |")
    (out / "sbc.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    for ax, k in zip(axes, ("EI0", "p"), strict=True):
        ranks = np.array([r[f"{k}_rank"] for r in ok])
        ax.hist(ranks, bins=10, range=(0, 100), color="C0", alpha=0.7)
        ax.axhline(n / 10, color="k", ls="--", lw=1)
        ax.set(title=f"SBC ranks of {k}", xlabel="rank of truth among 99 draws", ylabel="replicates")
    fig.tight_layout()
    fig.savefig(out / "rank_histograms.png", dpi=100)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--replicates", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("sbc-results"))
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "sbc.csv"
    rows = read_rows(path)
    new_file = not rows
    for r in rows:
        for k, v in list(r.items()):
            if v in ("True", "False"):
                r[k] = v == "True"
            elif k != "error" and v not in ("", None):
                r[k] = float(v)
    done = {int(r["seed"]) for r in rows}
    todo = [s for s in range(a.replicates) if s not in done]
    from tqdm import tqdm

    fields = ["seed", "rhat_max", "EI0_true", "EI0_median", "EI0_rank", "EI0_covered"]
    fields += ["p_true", "p_median", "p_rank", "p_covered", "error", "steps"]
    with ProcessPoolExecutor(a.jobs) as ex:
        done_rows = append_rows(path, fields, ex.map(_run, todo), new_file)
        rows += list(tqdm(done_rows, total=len(todo), desc="SBC replicates"))
    summarise([r for r in rows if int(r["seed"]) < a.replicates], a.out)


if __name__ == "__main__":
    main()

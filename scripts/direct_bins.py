"""The direct estimator's pooled EI(s) bins against the truth (docs/inference.md).

    python scripts/direct_bins.py [--preset twig] [--seed 2]

Simulates a dataset with default noise, runs ``direct_estimate`` (eq.
direct_estimator, GP curvature) and prints, per bin, the relative error of the
pooled EI and its z-score (error / standard error).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from bayesrod.dataset import read_dataset
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated
from bayesrod.inference.direct import direct_estimate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="twig", choices=["twig", "grass"])
    ap.add_argument("--seed", type=int, default=2)
    args = ap.parse_args()
    cfg = SimConfig.from_preset(args.preset, seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        write_simulated(cfg, simulate(cfg), Path(tmp))
        de = direct_estimate(read_dataset(tmp))
    truth = cfg.EI0 * (1 - de.s_m / cfg.length_m) ** (4 * cfg.p)
    ok = np.isfinite(de.EI)
    print(f"{'s [m]':>7} {'EI':>8} {'truth':>8} {'rel. err':>9} {'z':>6}")
    for s, e, t, se in zip(de.s_m[ok], de.EI[ok], truth[ok], de.se[ok], strict=True):
        print(f"{s:7.3f} {e:8.4f} {t:8.4f} {100 * (e / t - 1):8.1f}% {(e - t) / se:6.1f}")


if __name__ == "__main__":
    main()

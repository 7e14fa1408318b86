"""Raw rig tables of a brace-root series from an independent model (not bayesrod's simulator), for fit-group.

    python scripts/brace_root_tables.py --out tables [--seed 5]
    bayesrod import table tables/stalk7_*.csv --out ds --time "Time (s)" --force-column "Load (N)" \\
        --displacement "Position (mm)" --displacement-unit mm --metadata tables/meta.csv
    bayesrod fit-group ds --out run --force-offsets

A linear (small-deflection) tapered cantilever, EI(s) = EI0 (1 - s/L)^(4p) with L 1.8 m, EI0 30 N m^2, p 0.3,
on a rotational base spring, pushed at one height (0.5 m) to 30 mm under four conditions: intact (a clamp)
and three cuts leaving 0.88, 0.64 and 0.49 of the clamped stiffness (the published brace-root means). The
stem's compliance at the height is a numerical integral (scipy quad), the base's adds c h^2. Each push:
150 samples, AR(1) force noise (sd 0.05 N, lag-1 correlation 0.85) and a load-cell offset (sd 0.02 N), written
as a semicolon-separated table with decimal commas, forces in N, positions in mm, and a metadata CSV naming
each file's height, length, specimen, stem_id and condition. Prints each condition's true base compliance.

With ``--long``, the same series for ``--plants`` stalks (EI0 30 N m^2 times 0.8, 1.0, 1.25, ...) goes into one
long table instead, ``series.csv`` (comma-separated, columns Plant, Treatment, Time (s), Load (N), Position (mm);
docs/data.md, "Long tables"), and ``truth.csv`` lists each plant's EI0 and each condition's base compliance:

    python scripts/brace_root_tables.py --out tables --long --plants 3
    bayesrod import table tables/series.csv --out ds --time "Time (s)" --force "Load (N)" \
        --displacement "Position (mm)" --displacement-unit mm --height-m 0.5 --length-m 1.8 \
        --stem-id-column Plant --condition-column Treatment
    bayesrod fit-group ds --out run --force-offsets
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.integrate import quad

L, EI0, P, H = 1.8, 30.0, 0.3, 0.5
FRACTIONS = {"intact": 1.0, "cut1": 0.88, "cut2": 0.64, "cut3": 0.49}


def _push(rng: np.random.Generator, stiffness_N_per_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Force [N] and position [m] of one push (150 samples to 30 mm) with AR(1) noise and a load-cell offset."""
    d = np.linspace(0.0, 0.03, 150)
    e = np.empty(d.size)
    e[0] = rng.normal(0.0, 0.05)
    for i in range(1, d.size):
        e[i] = 0.85 * e[i - 1] + rng.normal(0.0, 0.05 * np.sqrt(1 - 0.85**2))
    return d * stiffness_N_per_m + e + rng.normal(0.0, 0.02), d


def _compliances(EI0: float) -> tuple[float, dict[str, float]]:
    """The stem's compliance at H [m/N] and each condition's base compliance [rad/(N m)]."""
    stem = quad(lambda s: (H - s) ** 2 / (EI0 * (1 - s / L) ** (4 * P)), 0, H)[0]
    return stem, {cond: (stem / frac - stem) / H**2 for cond, frac in FRACTIONS.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--long", action="store_true", help="one long table of every plant's pushes")
    ap.add_argument("--plants", type=int, default=3, help="with --long: how many stalks")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(a.seed)
    if a.long:
        rows, truth = ["Plant,Treatment,Time (s),Load (N),Position (mm)"], ["plant,condition,EI0,base_compliance"]
        for k in range(a.plants):
            plant, EI = f"stalk{k + 1}", EI0 * 1.25 ** (k - 1)
            stem, comp = _compliances(EI)
            for cond, c in comp.items():
                force, d = _push(rng, 1 / (stem + c * H**2))
                samples = enumerate(zip(force, d, strict=True))
                rows += [f"{plant},{cond},{0.1 * i:.2f},{f:.4f},{1000 * x:.3f}" for i, (f, x) in samples]
                truth.append(f"{plant},{cond},{EI:.6g},{c:.6g}")
        (a.out / "series.csv").write_text("\n".join(rows) + "\n")
        (a.out / "truth.csv").write_text("\n".join(truth) + "\n")
        print("\n".join(truth))
        return
    stem, comp = _compliances(EI0)
    rows = ["file,height_m,length_m,specimen,stem_id,condition"]
    for cond, c in comp.items():
        force, d = _push(rng, 1 / (stem + c * H**2))
        name = f"stalk7_{cond}.csv"
        lines = ["Time (s);Load (N);Position (mm)"]
        samples = enumerate(zip(force, d, strict=True))
        lines += [f"{0.1 * i:.2f};{f:.4f};{1000 * x:.3f}".replace(".", ",") for i, (f, x) in samples]
        (a.out / name).write_text("\n".join(lines) + "\n")
        rows.append(f"{name},{H},{L},stalk7-{cond},stalk7,{cond}")
        print(f"{cond}: base compliance {c:.6g} rad/(N m), stiffness {1 / (stem + c * H**2):.1f} N/m")
    (a.out / "meta.csv").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()

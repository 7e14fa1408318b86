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
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.integrate import quad

L, EI0, P, H = 1.8, 30.0, 0.3, 0.5
FRACTIONS = {"intact": 1.0, "cut1": 0.88, "cut2": 0.64, "cut3": 0.49}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(a.seed)
    stem = quad(lambda s: (H - s) ** 2 / (EI0 * (1 - s / L) ** (4 * P)), 0, H)[0]  # compliance at H [m/N]
    rows = ["file,height_m,length_m,specimen,stem_id,condition"]
    for cond, frac in FRACTIONS.items():
        c = (stem / frac - stem) / H**2  # base compliance [rad/(N m)]: the stiffness falls to frac
        d = np.linspace(0.0, 0.03, 150)
        e = np.empty(d.size)
        e[0] = rng.normal(0.0, 0.05)
        for i in range(1, d.size):
            e[i] = 0.85 * e[i - 1] + rng.normal(0.0, 0.05 * np.sqrt(1 - 0.85**2))
        force = d / (stem + c * H**2) + e + rng.normal(0.0, 0.02)
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

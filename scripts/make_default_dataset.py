"""Regenerate the bundled default dataset (bayesrod/data/default).

    python scripts/make_default_dataset.py

A simulated woody twig with the seed's published parameters (L 0.80 m,
EI0 2.63 N m^2, p 0.43, pushes at 0.45/0.55/0.65 m), default noise, seed 2026,
forces and centerlines (no RGB-D frames, to keep the package small).
"""

import shutil
from pathlib import Path

from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated

out = Path(__file__).resolve().parents[1] / "bayesrod" / "data" / "default"
if out.exists():
    shutil.rmtree(out)
out.mkdir(parents=True)
cfg = SimConfig.from_preset("twig", seed=2026, specimen="demo-twig")
write_simulated(cfg, simulate(cfg), out)
print(f"wrote {out}")

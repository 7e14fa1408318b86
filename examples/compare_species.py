"""Compare two species: simulate 3 + 3 specimens (stand-ins for yours), fit them all with fit-many, compare.

    python examples/compare_species.py [OUTDIR]

Each species is the grass preset with its own EI0 (one 1.5x stiffer) and a
between-specimen spread; the fits run on a local 2-worker Dask cluster (force
only, to keep it to a few minutes), then ``bayesrod compare`` reads the
survey folder. With real data: one dataset folder per specimen, each with
``species`` set in specimen.json.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from bayesrod.simulate import SimConfig, simulate, write_simulated

out = Path(sys.argv[1] if len(sys.argv) > 1 else "example-compare")
rng = np.random.default_rng(1)
for species, EI0 in (("meadow", 0.112), ("verge", 0.168)):
    for j in range(3):
        cfg = SimConfig.from_preset("grass", seed=10 * j + len(species), n_frames_engaged=2)
        cfg = SimConfig(
            **{
                **cfg.__dict__,
                "specimen": f"{species}-{j}",
                "species": species,
                "EI0": EI0 * np.exp(rng.normal(0, 0.2)),
            }
        )
        d = out / "datasets" / cfg.specimen
        d.mkdir(parents=True, exist_ok=True)
        write_simulated(cfg, simulate(cfg), d)
survey = out / "survey"
subprocess.run(["bayesrod", "fit-many", str(out / "datasets"), "--out", str(survey), "--forces-only"], check=True)
cmp_dir = out / "compare"
subprocess.run(["bayesrod", "compare", str(survey), "--out", str(cmp_dir), "--height", "0.1", "--force"], check=True)
res = json.loads((cmp_dir / "compare.json").read_text())
for c in res["contrasts"]:
    print(
        f"{c['parameter']:>8} {c['a']}/{c['b']}: {c['ratio_median']:.3g} [{c['ratio_q05']:.3g}, {c['ratio_q95']:.3g}]"
    )
print("forest plot:", (cmp_dir / "figures" / "forest.png").resolve())

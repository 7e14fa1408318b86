"""Spread of the per-frame contrast scale on the grass (issue 22: why the grass's E is not calibrated).

    python scripts/contrast_scale_check.py [--seeds 1 2 0]

Per seed: the grass preset's middle height, 22 frames drawn with exact widths (as scripts/diameter_study.py
draws them), ``bayesrod.extract``; prints the median and sd over frames of the contrast scale
(``extract_report.json`` ``diameters.contrast_scale``) and the profile's median relative error against the
drawn diameter, overall and over the base and tip thirds of its ok stations. About 2 minutes per seed.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.simulate import SimConfig
from bayesrod.physics import stem_diameter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 0])
    ap.add_argument("--stem", default="grass")
    a = ap.parse_args()
    for seed in a.seeds:
        cfg = SimConfig.from_preset(a.stem, seed=seed)
        h = cfg.heights_m[len(cfg.heights_m) // 2]
        sim = bayesrod.simulate(a.stem, seed=seed, heights_m=[h], config_overrides={"exact_width": True})
        with tempfile.TemporaryDirectory() as tmp:
            sim.save(Path(tmp) / "raw", frames=True)
            ex = bayesrod.extract(Path(tmp) / "raw", progress=False)
        truth, dp, L = ex.source.extra["truth"], ex.diameters, ex.dataset.length_m
        ok = dp.ok
        rel = dp.d_m[ok] / stem_diameter(dp.s_m[ok], truth["base_diameter_m"], truth["diameter_taper"], L) - 1
        third = ok.sum() // 3
        cs = ex.doc["diameters"]["contrast_scale"]
        print(
            f"seed {seed}: contrast scale median {cs['median']:.3f} sd {cs['sd']:.3f} over "
            f"{ex.doc['diameters']['frames']} frames; profile error median {np.median(rel):+.3f}, "
            f"base third {np.median(rel[:third]):+.3f}, tip third {np.median(rel[-third:]):+.3f}",
            flush=True,
        )


if __name__ == "__main__":
    main()

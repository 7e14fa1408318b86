"""Are the diameter profile's station sds calibrated all along the stem? (issue 22)

    python scripts/width_sd_bands.py --stem grass --seeds 20-31 [--graded 120-122]

Per seed: ``bayesrod simulate`` (one contact height, the preset's middle one; rendered frames with
exact widths, clutter, the probe and depth dropouts, as scripts/diameter_study.py draws them), then
``bayesrod.extract``. Prints, pooled over the seeds, the z-scores (measured - drawn) / sd of the ok
stations: their root mean square and 90% coverage overall and in bands of s/L 0.1 wide, and the
median absolute error [px]. A calibrated sd gives z rms 1 in every band. To compare with an earlier
version of the width code, run the same command from a checkout of that commit.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from _study import GRADIENT, extracted_push, seeds


def one(stem: str, seed: int, graded: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z, s/L, error [px]) of the ok stations of one extracted push."""
    with tempfile.TemporaryDirectory() as tmp:
        ex, true, px = extracted_push(stem, seed, graded, Path(tmp))
    dp, ok = ex.diameters, ex.diameters.ok
    err = dp.d_m[ok] - true[ok]
    return err / dp.sd_m[ok], dp.s_m[ok] / ex.dataset.length_m, err / px


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stem", default="grass")
    ap.add_argument("--seeds", default="20-31", help="uniform-modulus seeds: '20-31' or '1,4,7'")
    ap.add_argument("--graded", default="", help=f"seeds drawn with a modulus gradient (diameter taper p - {GRADIENT})")
    a = ap.parse_args(argv)
    jobs = [(s, False) for s in seeds(a.seeds)] + [(s, True) for s in (seeds(a.graded) if a.graded else [])]
    zs, ss, es = [], [], []
    for seed, graded in jobs:
        z, s, e = one(a.stem, seed, graded)
        print(f"{a.stem} seed {seed}{' graded' if graded else ''}: {z.size} stations, z sd {np.std(z):.2f}", flush=True)
        zs.append(z)
        ss.append(s)
        es.append(e)
    z, s, e = (np.concatenate(x) for x in (zs, ss, es))
    rms = float(np.sqrt(np.mean(z**2)))
    cover = float(np.mean(np.abs(z) < 1.645))
    print(f"\n{a.stem}, {len(jobs)} pushes, {z.size} stations: z rms {rms:.2f}, 90% cover {cover:.3f}, ", end="")
    print(f"median |error| {np.median(np.abs(e)):.3f} px")
    print("| s/L | stations | z rms | 90% cover |\n|---|---|---|---|")
    for lo in np.arange(0.0, 1.0, 0.1):
        m = (s >= lo) & (s < lo + 0.1)
        if m.sum() > 5:
            band_rms, band_cover = np.sqrt(np.mean(z[m] ** 2)), np.mean(np.abs(z[m]) < 1.645)
            print(f"| {lo:.1f}-{lo + 0.1:.1f} | {m.sum()} | {band_rms:.2f} | {band_cover:.2f} |")


if __name__ == "__main__":
    main()

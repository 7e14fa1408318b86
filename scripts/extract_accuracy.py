"""Centerline extraction against the simulator's true shapes (issue 4; the table in docs/vision.md).

    python scripts/extract_accuracy.py [--seeds 3,4,5] [--presets twig,grass] [--frames-engaged N] [--arm trailing]

For each preset and seed: simulates a dataset with RGB-D frames, extracts every
frame and prints medians over frames of the point-to-curve error (all points;
points seen in the image), the coverage of the stem (true arc length within
3 px of the extracted curve, its 1-cm points joined, not across gaps; with and
without the bridges across occlusions), the coverage of its visible part (true
points not behind an object in front of the plane by the depth map, seen
points only), the extracted extent s_max / L, the fraction of seen points
farther than 3 px from the truth (mean; worst frame), and the number of
bridged points with the fraction within 1.645 of their sd_m (90% nominal).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.vision.accuracy import frame_metrics


def one(preset: str, seed: int, n_frames: int | None, arm: str = "leading") -> str:
    kw = {} if n_frames is None else {"n_frames_engaged": n_frames}
    with tempfile.TemporaryDirectory() as tmp:
        root = bayesrod.simulate(preset, seed=seed, config_overrides=kw).save(Path(tmp) / preset, frames=True, arm=arm)
        rows = list(frame_metrics(root))
    keys = ("err", "err_seen", "cover", "cover_seen", "cover_visible", "extent", "px")
    med = {k: float(np.median([r[k] for r in rows])) for k in keys}
    false = np.array([r["false"] for r in rows])
    bz = np.concatenate([r["bridge_z"] for r in rows])
    return (
        f"| {preset} | {arm} | {seed} | {len(rows)} | {1000 * med['px']:.2f} mm | {med['err'] / med['px']:.2f} px | "
        f"{med['err_seen'] / med['px']:.2f} px | {med['cover']:.3f} | {med['cover_seen']:.3f} | "
        f"{med['cover_visible']:.3f} | {med['extent']:.3f} | {false.mean():.4f} ({false.max():.3f}) | "
        f"{bz.size} | {np.mean(bz <= 1.6449):.2f} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="3,4,5")
    ap.add_argument("--presets", default="twig,grass")
    ap.add_argument("--frames-engaged", type=int, default=None, help="frames per push (default: the simulator's)")
    ap.add_argument("--arm", default="leading", choices=["trailing", "leading"], help="where the probe's holder is")
    args = ap.parse_args()
    print(
        "| preset | arm | seed | frames | pixel | median error | error, seen | coverage | coverage, seen points"
        " | visible coverage | extent | seen > 3 px off | bridged points | within 1.645 sd |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for preset in args.presets.split(","):
        for seed in map(int, args.seeds.split(",")):
            print(one(preset, seed, args.frames_engaged, args.arm), flush=True)


if __name__ == "__main__":
    main()

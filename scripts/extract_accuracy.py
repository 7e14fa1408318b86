"""Centerline extraction against the simulator's true shapes (issue 4; the table in docs/vision.md).

    python scripts/extract_accuracy.py [--seeds 3,4,5] [--presets twig,grass] [--frames-engaged N]

For each preset and seed: simulates a dataset with RGB-D frames, extracts every
frame and prints medians over frames of the point-to-curve error, the
coverage of the stem (true arc length within 3 px of the extracted curve, its
1-cm points joined, not across gaps), the coverage of its visible part (true
points not behind an object in front of the plane by the depth map), the
extracted extent s_max / L and the fraction of extracted points farther than
3 px from the truth (mean; worst frame).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.conftest import make_dataset  # noqa: E402
from tests.test_extract import frame_metrics  # noqa: E402


def one(preset: str, seed: int, n_frames: int | None) -> str:
    kw = {} if n_frames is None else {"n_frames_engaged": n_frames}
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / preset, preset, seed=seed, frames=True, **kw)
        rows = list(frame_metrics(root))
    med = {k: float(np.median([r[k] for r in rows])) for k in ("err", "cover", "cover_visible", "extent", "px")}
    false = np.array([r["false"] for r in rows])
    return (
        f"| {preset} | {seed} | {len(rows)} | {1000 * med['px']:.2f} mm | {med['err'] / med['px']:.2f} px | "
        f"{med['cover']:.3f} | {med['cover_visible']:.3f} | {med['extent']:.3f} | "
        f"{false.mean():.4f} ({false.max():.3f}) |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="3,4,5")
    ap.add_argument("--presets", default="twig,grass")
    ap.add_argument("--frames-engaged", type=int, default=None, help="frames per push (default: the simulator's)")
    args = ap.parse_args()
    print("| preset | seed | frames | pixel | median error | coverage | visible coverage | extent | off > 3 px |")
    print("|---|---|---|---|---|---|---|---|---|")
    for preset in args.presets.split(","):
        for seed in map(int, args.seeds.split(",")):
            print(one(preset, seed, args.frames_engaged), flush=True)


if __name__ == "__main__":
    main()

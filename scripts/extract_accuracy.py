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
from bayesrod.vision.extract import extract_frame  # noqa: E402
from tests.conftest import make_dataset  # noqa: E402
from tests.test_extract import _densify, _frames_truth, _hidden  # noqa: E402


def one(preset: str, seed: int, n_frames: int | None) -> str:
    kw = {} if n_frames is None else {"n_frames_engaged": n_frames}
    with tempfile.TemporaryDirectory() as tmp:
        root = make_dataset(Path(tmp) / preset, preset, seed=seed, frames=True, **kw)
        spec, frames = _frames_truth(root)
        rows = []
        for rgb, dep, tr in frames:
            line = extract_frame(rgb, dep, spec["camera"], max_length_m=spec["length_m"])
            px = line.plane_depth_m / spec["camera"]["fx"]
            st = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(tr, axis=1)))])
            sd = np.linspace(0, st[-1], 4000)
            tx, tz = np.interp(sd, st, tr[0]), np.interp(sd, st, tr[1])
            d = np.hypot(line.x_m[:, None] - tx[None], line.z_m[:, None] - tz[None]).min(axis=1)
            ex, ez = _densify(line)
            near = np.hypot(tx[:, None] - ex[None], tz[:, None] - ez[None]).min(axis=1) < 3 * px
            u0, v0 = spec["camera"]["base_px"]
            hid = _hidden(dep, line.plane_depth_m, u0 + tx / px, v0 - tz / px)
            ext = min(line.s_m.max() / spec["length_m"], 1.0)
            rows.append((np.median(d) / px, near.mean(), near[~hid].mean(), ext, np.mean(d > 3 * px), px))
    r = np.array(rows)
    med = np.median(r, axis=0)
    return (
        f"| {preset} | {seed} | {len(frames)} | {1000 * med[5]:.2f} mm | {med[0]:.2f} px | {med[1]:.3f} | "
        f"{med[2]:.3f} | {med[3]:.3f} | {r[:, 4].mean():.4f} ({r[:, 4].max():.3f}) |"
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

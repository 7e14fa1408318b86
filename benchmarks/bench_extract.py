"""Extraction throughput (issue 4 target: >= 5 frames per second on 2 cores).

    python benchmarks/bench_extract.py [--preset twig|grass]

Simulates a dataset with RGB-D frames (twig by default), then times
``extract_frame`` on every frame, 3 rounds, and prints the median frames per
second of the full pipeline, of the pipeline without tip tracking (reference,
same process, same frames), their ratio, and the ratio to the 5 fps target.
Frame decoding (PNG) is timed separately and not included.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from bayesrod.dataset import read_dataset
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated
from bayesrod.vision.extract import extract_frame
from bayesrod.vision.render import default_camera


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="twig", choices=["twig", "grass"])
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = SimConfig.from_preset(a.preset, seed=7)
        cam = default_camera(cfg.length_m)
        write_simulated(cfg, simulate(cfg), Path(tmp), frames=True, camera=cam)
        spec = read_dataset(tmp)
        t0 = time.perf_counter()
        frames = []
        for p in spec.pushes:
            for r in p.frames:
                rgb = cv2.cvtColor(cv2.imread(str(r.rgb)), cv2.COLOR_BGR2RGB)
                frames.append((rgb, cv2.imread(str(r.depth), cv2.IMREAD_UNCHANGED)))
        decode = (time.perf_counter() - t0) / len(frames)
    out = {}
    for name, kw in (("full", {}), ("no tip tracking (reference)", {"track": False})):
        per = []
        for _ in range(3):
            for rgb, dep in frames:
                t = time.perf_counter()
                extract_frame(rgb, dep, cam, **kw)
                per.append(time.perf_counter() - t)
        out[name] = 1.0 / np.median(per)
        print(f"{name:>28}: median {1000 * np.median(per):.1f} ms/frame = {out[name]:.1f} fps ({len(per)} timings)")
    full = out["full"]
    print(f"PNG decode: {1000 * decode:.1f} ms/frame (not included)")
    ref = out["no tip tracking (reference)"]
    print(f"ratio full / reference: x{full / ref:.2f}; full / 5 fps target: x{full / 5:.2f}")


if __name__ == "__main__":
    main()

"""fit-many throughput with 1 and 2 Dask workers (docs/performance.md).

    python benchmarks/bench_fit_many.py [--specimens 6]

Simulates N grass datasets (seeds 1..N, 2 frames each), then runs
``fit_many`` (forces only, seed 0) into fresh folders with a LocalCluster of
1 and of 2 workers, and prints specimens per minute (wall clock, including
cluster start-up) and the ratio 2 workers / 1 worker.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bayesrod import fit_many
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--specimens", type=int, default=6)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "data"
        for s in range(1, a.specimens + 1):
            cfg = SimConfig.from_preset("grass", seed=s, n_frames_engaged=2)
            d = root / f"g{s}"
            d.mkdir(parents=True)
            write_simulated(cfg, simulate(cfg), d)
        rate = {}
        for w in (1, 2):
            t0 = time.perf_counter()
            res = fit_many(root, Path(tmp) / f"out{w}", n_workers=w, use_shapes=False, progress=False)
            dt = time.perf_counter() - t0
            rate[w] = len(res.rows) / dt * 60
            print(f"{w} worker(s): {len(res.rows)} specimens in {dt:.1f} s = {rate[w]:.2f} specimens/min")
        print(f"ratio 2 workers / 1 worker: x{rate[2] / rate[1]:.2f}")


if __name__ == "__main__":
    main()

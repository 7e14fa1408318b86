"""Friction force curves built in one process, one batch (as before session 48), and over worker processes.

Run:  python benchmarks/bench_table_workers.py [--repeat 3] [--workers 2] [--nodes 4] [--heights 0.45,0.6,0.8]

The likelihood of a fit with ``contact_friction`` tables one force curve per height and friction node (61 taper
exponents, 160 forces each; 49 nodes). Printed, median seconds of ``--repeat`` builds of ``--nodes`` friction
nodes (mu evenly over -0.3..0.5) at each height, the curve cache emptied before each:

* ``one batch``: every curve in one batched solve (``ForceCurves._solve`` on all rows: the build before
  session 48, whose branch ends depended on the batch);
* ``one per call``: the build as shipped with one process (each friction curve its own solve);
* ``workers``: the same curves over ``--workers`` processes (``table_workers``), and whether they equal the
  one-per-call curves bit for bit.

Ratios are against ``one per call`` in the same process. Run with nothing else on the machine: the workers'
ratio is only as good as the cores they get.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bayesrod.inference import likelihood as LK
from bayesrod.inference.likelihood import ForceCurves, table_workers

P_GRID = np.linspace(0.0, 3.0, 61)
D = np.linspace(0.0, 0.9, 91)


def _build(etas, mus, workers: int | None):
    LK._CURVE_CACHE.clear()
    t = time.perf_counter()
    if workers is None:
        curves = ForceCurves._solve(etas, P_GRID, 160, {"mu": mus})
    else:
        with table_workers(workers):
            curves = ForceCurves.batch(etas, P_GRID, 160, {"mu": mus})
    return time.perf_counter() - t, curves


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--nodes", type=int, default=4)
    ap.add_argument("--heights", default="0.45,0.6,0.8", help="h/L of each height")
    a = ap.parse_args(argv)
    heights = np.array([float(x) for x in a.heights.split(",")])
    nodes = np.linspace(-0.3, 0.5, a.nodes)
    etas, mus = np.tile(heights, nodes.size), np.repeat(nodes, heights.size)
    print(f"{etas.size} friction curves ({heights.size} heights x {nodes.size} nodes), 61 p x 160 forces each")
    times: dict[str, list] = {"one batch": [], "one per call": [], f"{a.workers} workers": []}
    same = True
    for _ in range(a.repeat):
        t, _ = _build(etas, mus, None)
        times["one batch"].append(t)
        t, ref = _build(etas, mus, 1)
        times["one per call"].append(t)
        t, par = _build(etas, mus, a.workers)
        times[f"{a.workers} workers"].append(t)
        same &= all(np.array_equal(x.force(D), y.force(D), equal_nan=True) for x, y in zip(ref, par, strict=True))
    base = float(np.median(times["one per call"]))
    for name, ts in times.items():
        m = float(np.median(ts))
        print(f"{name:>14}: median {m:7.1f} s   ratio to one per call {m / base:.2f}")
    print(f"workers' curves equal one per call's bit for bit: {same}")


if __name__ == "__main__":
    main()

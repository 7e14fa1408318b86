"""Force-curve solves at the batch sizes bayesrod uses, with and without the Newton probe.

Run:  python benchmarks/bench_root_search.py [--repeat 7]

Two batches of displacement -> force solves (twig-like: p about 0.43, h/L 0.55 and 0.75):

* 64 problems: one diagnosis forward evaluation (2 pushes x 32 spline nodes);
* 4000 problems: one height of the report's force band (100 draws x 40 displacements).

Each is timed (median of ``--repeat``) with the root search as shipped (a Newton probe per round
while at most ``elastica.NEWTON_BATCH`` problems remain) and, as the reference in the same process,
with plain Illinois rounds (``NEWTON_BATCH = 0``); the ratio, the number of integrations (marches)
and the largest relative difference of the forces are printed. The other speed-ups of 2026-11-25
(one-buffer RK stages, the contact search stopping once converged, no root search at d <= 0) have no
switch: docs/performance.md gives the same script's numbers on the commit before them.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bayesrod.physics import elastica


def _cases():
    d = np.linspace(0.0, 0.2, 32)
    yield "diagnosis: 2 pushes x 32 nodes", (d[None, :] * np.ones((2, 1)), np.array([0.55, 0.75])[:, None], 0.43)
    rng = np.random.default_rng(0)
    p = 0.43 + 0.02 * rng.standard_normal(100)
    yield "report band: 100 draws x 40", (np.linspace(0.0, 0.15, 40)[None, :], 0.6, p[:, None])


def _time(args, repeat, newton_batch):
    saved = getattr(elastica, "NEWTON_BATCH", None)  # None: a commit before the probe (docs' before row)
    elastica.NEWTON_BATCH = newton_batch
    calls = [0]
    march = elastica._march

    def counted(*a, **k):
        calls[0] += 1
        return march(*a, **k)

    elastica._march = counted
    try:
        times = []
        for _ in range(repeat):
            calls[0] = 0
            t = time.perf_counter()
            f = elastica.force_from_displacement_nd(*args)["f"]
            times.append(time.perf_counter() - t)
    finally:
        elastica._march = march
        if saved is None:
            del elastica.NEWTON_BATCH
        else:
            elastica.NEWTON_BATCH = saved
    return statistics.median(times), calls[0], f


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    head = "| batch | problems | as shipped: median s (marches) | plain Illinois: median s (marches) | ratio |"
    print(head + " max rel diff |")
    print("|---|---|---|---|---|---|")
    for name, args in _cases():
        t1, n1, f1 = _time(args, a.repeat, getattr(elastica, "NEWTON_BATCH", 0))
        t0, n0, f0 = _time(args, a.repeat, 0)
        ok = np.isfinite(f1) & np.isfinite(f0) & (f0 != 0)
        diff = float(np.max(np.abs(f1[ok] / f0[ok] - 1))) if ok.any() else float("nan")
        print(f"| {name} | {f1.size} | {t1:.3f} ({n1}) | {t0:.3f} ({n0}) | x{t0 / t1:.2f} | {diff:.1e} |")


if __name__ == "__main__":
    main()

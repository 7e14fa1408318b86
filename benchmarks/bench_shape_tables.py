"""What reading the shape tables as normal offsets costs: table builds with and without them, same process.

Run:  python benchmarks/bench_shape_tables.py [--repeat 3]

The likelihood's shape tables hold each observed point's signed normal offset from the centerline
(``centerline_normal_offsets``, since 2026-11-27; until 9679df5 beside x(z) and cos(phi)). This builds the likelihood
of two datasets ``--repeat`` times each way, alternating: as it is, and with the normal offsets
replaced by a function that returns zeros (the cost of the build without them; the force curves'
cache is cleared before every build). Prints the medians and their ratio.

- the bundled twig (3 pushes, 66 frames, 4400 points; 61 p nodes, no effect axis);
- scripts/sbc_geometry.py seed 47's stem at one height with a 9-node rest-curvature axis.
"""

from __future__ import annotations

import argparse
import statistics
import time
from importlib import resources

import numpy as np

import bayesrod
import bayesrod.inference.likelihood as LK
from bayesrod.dataset import read_dataset
from bayesrod.dataset.simulate import NoiseModel


def _cases():
    with resources.as_file(resources.files("bayesrod") / "data" / "default") as path:
        twig = read_dataset(path)
    L = 1.131084549316038
    flat = bayesrod.simulate(
        {"EI0": 3.3134, "p": 0.00926, "length_m": L, "heights_m": (0.5094491449609528,), "specimen": "flat"},
        seed=47,
        noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0, shape_sd_reported_m=0.0015),
        effects={"rest_curvature": 1.2025760169036837},
        config_overrides={"robot_step_m": 0.01 * L},
    )
    axis = LK.EffectAxis("rest_curvature", np.linspace(0.0, 1.6, 9))
    return {
        "twig, 61 p nodes": lambda: LK.RodLikelihood(twig),
        "seed 47, 61 p x 9 effect nodes": lambda: LK.RodLikelihood(flat, effects=("rest_curvature",), effect_axis=axis),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    real = LK.centerline_normal_offsets

    def zeros(grid, xi, zeta):
        return np.zeros((np.shape(grid)[-1], np.size(xi)))

    for name, build in _cases().items():
        times = {"with": [], "without": []}
        for _ in range(args.repeat):
            for way, fn in (("with", real), ("without", zeros)):
                LK.centerline_normal_offsets = fn
                LK._CURVE_CACHE.clear()
                t = time.perf_counter()
                build()
                times[way].append(time.perf_counter() - t)
        LK.centerline_normal_offsets = real
        w, wo = statistics.median(times["with"]), statistics.median(times["without"])
        print(f"{name}: build {w:.2f} s with the normal offsets, {wo:.2f} s without", end=" ")
        print(f"(medians of {args.repeat}); ratio {w / wo:.2f}")


if __name__ == "__main__":
    main()

"""Cost of session 72's force curves (24 levels down a plateau, a cubic spline through levels 1e-4 L apart, the
end slope from a quadratic) against session 71's (160 clustered levels, PCHIP), same process.

Run:  python benchmarks/bench_force_levels.py [--repeat 5]

Builds the plain likelihood of the simulated twig (three heights) forces only and with centerlines, and the
curves of one height with contact friction (mu 0.3, 13 p nodes), each with the curve cache cleared, and prints
the median time of each over ``--repeat`` builds with the old curves (the reference: ``PLATEAU_LEVELS = 0``,
``MIN_LEVEL_GAP = 0``, PCHIP and the spline's own end slope patched in by
``scripts/force_curve_accuracy.py``) and with today's, and their ratio.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from bench_forward import _median_time as median_time  # noqa: E402  (benchmarks/ is the script's path)

import bayesrod
from bayesrod.inference import likelihood as LK
from bayesrod.inference.priors import load_prior

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from force_curve_accuracy import old_curves  # noqa: E402  (session 71's curves, patched in)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    ds = bayesrod.simulate("twig", seed=1, heights_m=[0.36, 0.48, 0.60], config_overrides={"n_frames_engaged": 4})
    pr = load_prior("woody")

    def build(shapes: bool):
        def run():
            LK._CURVE_CACHE.clear()
            LK.build_likelihood(ds, pr, (), use_shapes=shapes)

        return run

    def friction():
        LK._CURVE_CACHE.clear()
        LK.ForceCurves.batch(np.array([0.55]), np.linspace(0.0, 1.2, 13), effects_nd={"mu": 0.3})

    cases = {"plain, forces only": build(False), "plain, with centerlines": build(True), "friction curves": friction}
    print(f"{'case':<26} {'session 71 [s]':>15} {'today [s]':>10} {'ratio':>7}")
    for name, fn in cases.items():
        undo = old_curves()
        try:
            old = median_time(fn, args.repeat)
        finally:
            undo()
        new = median_time(fn, args.repeat)
        print(f"{name:<26} {old:>15.2f} {new:>10.2f} {new / old:>7.2f}", flush=True)


if __name__ == "__main__":
    main()

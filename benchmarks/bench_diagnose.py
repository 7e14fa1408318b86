"""Speed of ``bayesrod diagnose`` and of the correlated-noise fit (issue 19), same process.

Run:  python benchmarks/bench_diagnose.py [--repeat 3] [--seeds 1,2,3]

1. Diagnosis of a three-height forces-only dataset: the simulated twig (3 heights,
   AR(1) force noise rho = 0.9, no effect, and one with an undeclared base spring),
   the whole catalog tested, AR(1) noise. Wall time per diagnosis, median over
   ``--repeat`` runs; reference in the same process: the same diagnosis solving the
   forces at every sample (nodes = samples, the obvious path).
2. The AR(1) fit (``bayesrod.fit(DEMO_DATASET, force_noise="ar1")``) against the
   independent-noise fit on the bundled dataset: bulk ESS min(EI0, p) per second of
   wall time, median over ``--repeat`` fits.
The 18 blueberry canes are timed by scripts/diagnose_blueberry.py (column ``s``).
"""

from __future__ import annotations

import argparse
import statistics
import time

import bayesrod
from bayesrod.inference.diagnose import ForwardModel, diagnose
from bayesrod.inference.likelihood import prepare_data


def one_diagnosis(spec, n_nodes: int | None) -> tuple[float, list[str]]:
    """Wall time and effects added; ``n_nodes=None``: solve at every sample (nodes = samples)."""
    data = prepare_data(spec, use_shapes=False)
    n_nodes = n_nodes or max(d.D_m.size for d in data)
    m = ForwardModel(data, spec.length_m, n_nodes=n_nodes)
    t = time.perf_counter()
    r = diagnose(m)
    return time.perf_counter() - t, r["added_effects"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-reference", action="store_true", help="do not time the every-sample reference")
    args = ap.parse_args()
    cases = {
        "clean": bayesrod.simulate("twig", seed=1, noise_rho=0.9),
        "base spring 8 N m/rad": bayesrod.simulate("twig", seed=2, noise_rho=0.9, effects={"base_compliance": 8.0}),
    }
    print("| case | n_force | nodes: median s (runs) | added | every sample: s | ratio |")
    print("|---|---|---|---|---|---|")
    for name, spec in cases.items():
        runs = [one_diagnosis(spec, 32) for _ in range(args.repeat)]
        med = statistics.median(t for t, _ in runs)
        ref = "-"
        ratio = "-"
        if not args.skip_reference:
            tr, _ = one_diagnosis(spec, None)
            ref, ratio = f"{tr:.1f}", f"x{tr / med:.1f}"
        n = sum(p.force.force_N.size for p in spec.pushes)
        times = ", ".join(f"{t:.1f}" for t, _ in runs)
        print(f"| {name} | {n} | {med:.1f} ({times}) | {', '.join(runs[0][1]) or 'none'} | {ref} | {ratio} |")

    print()
    print("| fit | median wall s | bulk ESS min(EI0, p) | ESS/s |")
    print("|---|---|---|---|")
    for noise in ("ar1", "iid"):
        rows = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            post = bayesrod.fit(bayesrod.DEMO_DATASET, force_noise=noise)
            wall = time.perf_counter() - t
            ess = float(post.summary().loc[["EI0", "p"], "ess_bulk"].min())
            rows.append((wall, ess, ess / wall))
        w, e, r = (statistics.median(x[i] for x in rows) for i in range(3))
        print(f"| {noise} | {w:.1f} | {e:.0f} | {r:.0f} |")


if __name__ == "__main__":
    main()

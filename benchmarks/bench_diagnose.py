"""Speed of ``bayesrod diagnose`` and of the correlated-noise fit (issue 19), same process.

Run:  python benchmarks/bench_diagnose.py [--repeat 3] [--every-sample] [--cases clean yield]

1. Diagnosis of a three-height forces-only dataset: the simulated twig (3 heights,
   AR(1) force noise rho = 0.9, no effect, one with an undeclared base spring, and the
   diagnosis study's yielding twig, seed 11: its friction candidate is the slowest fit),
   the whole catalog tested, AR(1) noise. Wall time per diagnosis with 1 and with 2
   worker processes, median over ``--repeat`` runs; references in the same process:
   the same diagnosis (1 worker) with the root search of the forward solves done by
   plain expansion and bisection (one point per round), and (``--every-sample``)
   solving the forces at every sample instead of 32 nodes per push.
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
from bayesrod.physics import elastica


def one_diagnosis(spec, n_nodes: int | None, workers: int = 1, bisection: bool = False) -> tuple[float, list[str]]:
    """Wall time and effects added; ``n_nodes=None``: solve at every sample (nodes = samples);
    ``bisection``: one point per round of the forward solves' root search."""
    data = prepare_data(spec, use_shapes=False)
    n_nodes = n_nodes or max(d.D_m.size for d in data)
    m = ForwardModel(data, spec.length_m, n_nodes=n_nodes)
    points = elastica.EXPAND_POINTS, elastica.BOUNDARY_SECTIONS
    if bisection:
        elastica.EXPAND_POINTS, elastica.BOUNDARY_SECTIONS = 1, 1
    try:
        t = time.perf_counter()
        r = diagnose(m, workers=workers)
        return time.perf_counter() - t, r["added_effects"]
    finally:
        elastica.EXPAND_POINTS, elastica.BOUNDARY_SECTIONS = points


CASES = {
    "clean": lambda: bayesrod.simulate("twig", seed=1, noise_rho=0.9),
    "spring": lambda: bayesrod.simulate("twig", seed=2, noise_rho=0.9, effects={"base_compliance": 8.0}),
    "yield": lambda: bayesrod.simulate(
        "twig", seed=11, noise_rho=0.9, effects={"yield": 3.0}, config_overrides={"n_frames_engaged": 8}
    ),
}
NAMES = {"clean": "clean", "spring": "base spring 8 N m/rad", "yield": "yield 3 N m (study seed 11)"}


def diagnosis_table(repeat: int, every_sample: bool, names=tuple(CASES)) -> None:
    """The first table: diagnoses of the clean, the base-spring and the yielding twig."""
    cases = {NAMES[k]: CASES[k]() for k in names}
    print(
        "| case | n_force | 1 worker: median s (runs) | 2 workers: median s (runs) | added "
        "| bisection, 1 worker: s (ratio) | every sample, 1 worker: s (ratio) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, spec in cases.items():
        one = [one_diagnosis(spec, 32) for _ in range(repeat)]
        two = [one_diagnosis(spec, 32, workers=2) for _ in range(repeat)]
        med1, med2 = (statistics.median(t for t, _ in r) for r in (one, two))
        tb, added_b = one_diagnosis(spec, 32, bisection=True)
        bis = f"{tb:.1f} (x{tb / med1:.2f}){'' if added_b == one[0][1] else ' adds ' + ','.join(added_b)}"
        ref = "-"
        if every_sample:
            tr, _ = one_diagnosis(spec, None)
            ref = f"{tr:.1f} (x{tr / med1:.1f})"
        n = sum(p.force.force_N.size for p in spec.pushes)
        t1, t2 = (", ".join(f"{t:.1f}" for t, _ in r) for r in (one, two))
        added = ", ".join(one[0][1]) or "none"
        print(f"| {name} | {n} | {med1:.1f} ({t1}) | {med2:.1f} ({t2}) | {added} | {bis} | {ref} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fit-only", action="store_true", help="only the second table (the AR(1) fit's ESS/s)")
    ap.add_argument("--every-sample", action="store_true", help="also time the every-sample reference (slow)")
    ap.add_argument("--cases", nargs="+", choices=tuple(CASES), default=list(CASES), help="diagnosis cases")
    args = ap.parse_args()
    if not args.fit_only:
        diagnosis_table(args.repeat, args.every_sample, args.cases)
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

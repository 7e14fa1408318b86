"""Speed of the compiled Runge-Kutta step against the numpy steps, same process.

Run:  python benchmarks/bench_compiled_step.py [--repeat 5]

1. One step (``elastica._step_compiled`` vs the numpy ``elastica._step_plain`` for a plain rod, and vs
   ``elastica._step_general`` for a rod with rest curvature, friction and self-weight) at batch sizes 1 to 4096:
   median microseconds per step over ``--repeat`` rounds of many steps, and the ratio numpy / compiled.
2. Whole forward solves, compiled against numpy (``bayesrod.physics._compiled.step`` set to None for the
   reference): forces at 8 and at 256 displacements of a tapered twig (p = 0.43, h/L = 0.5), plain and with
   rest curvature 0.3, the batch sizes of a diagnosis and of a predictive band; median ms and the ratio.
The first call compiles (or loads numba's cache) before any timing.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bayesrod.physics import _compiled
from bayesrod.physics import elastica as E


def _median_time(fn, repeat: int, inner: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t) / inner)
    return statistics.median(times)


def step_table(repeat: int) -> None:
    rng = np.random.default_rng(0)
    print("one RK step (median us per step)")
    print(f"{'rod':>7} {'rods':>6} {'numpy':>10} {'compiled':>10} {'ratio':>7}")
    for kind, eff, numpy_step in (("plain", None, E._step_plain), ("effects", EFFECTS, E._step_general)):
        for n in (1, 8, 64, 256, 1024, 4096):
            P = E._prepare(E._problem(np.full(n, 0.5), np.full(n, 0.43), eff)[0])
            Y = np.vstack([rng.uniform(0, 0.3, (2, n)), rng.uniform(-0.5, 1.0, (1, n)), rng.uniform(-1, 1, (1, n))])
            f = rng.uniform(0.1, 3.0, n)
            inner = max(20, 20000 // n)
            args = (Y, 0.3, 1 / 48, f, P, 1.0)
            E._step_compiled(*args)
            t_np = _median_time(lambda: numpy_step(*args), repeat, inner)  # noqa: B023
            t_c = _median_time(lambda: E._step_compiled(*args), repeat, inner)  # noqa: B023
            print(f"{kind:>7} {n:6d} {t_np * 1e6:10.1f} {t_c * 1e6:10.1f} {t_np / t_c:7.2f}")


EFFECTS = {"kappa0": 0.3, "mu": 0.2, "w0": 0.5}


def solve_table(repeat: int) -> None:
    print("forces from displacements, tapered twig (median ms per solve)")
    print(f"{'rod':>15} {'displacements':>13} {'numpy':>10} {'compiled':>10} {'ratio':>7}")
    kernel = _compiled.step
    for kind, eff in (("plain", None), ("rest curvature", {"kappa0": 0.3})):
        for n in (8, 256):
            xi = np.linspace(0.01, 0.3, n)

            def solve(xi=xi, eff=eff):
                return E.force_from_displacement_nd(xi, 0.5, 0.43, eff)

            solve()
            times = {}
            for name, k in (("numpy", None), ("compiled", kernel)):
                _compiled.step = k
                try:
                    times[name] = _median_time(solve, repeat, 3)
                finally:
                    _compiled.step = kernel
            print(f"{kind:>15} {n:13d} {times['numpy'] * 1e3:10.1f} {times['compiled'] * 1e3:10.1f} "
                  f"{times['numpy'] / times['compiled']:7.2f}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    if _compiled.step is None:
        raise SystemExit("numba missing or BAYESROD_NO_JIT set: nothing compiled to compare")
    step_table(args.repeat)
    solve_table(args.repeat)


if __name__ == "__main__":
    main()

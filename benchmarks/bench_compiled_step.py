"""Speed of the compiled Runge-Kutta step of a plain rod against the numpy step, same process.

Run:  python benchmarks/bench_compiled_step.py [--repeat 5]

1. One step (``elastica._step_plain_compiled`` vs the numpy ``elastica._step_plain``) at batch sizes 1 to 4096:
   median microseconds per step over ``--repeat`` rounds of many steps, and the ratio numpy / compiled.
2. Whole forward solves, compiled against numpy (``bayesrod.physics._compiled.plain_step`` set to None for the
   reference): forces at 8 and at 256 displacements of a tapered twig (p = 0.43, h/L = 0.5), the batch sizes of a
   diagnosis and of a predictive band; median seconds and the ratio.
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
    print("one RK step of a plain rod (median us per step)")
    print(f"{'rods':>6} {'numpy':>10} {'compiled':>10} {'ratio':>7}")
    for n in (1, 8, 64, 256, 1024, 4096):
        P = E._prepare(E._problem(np.full(n, 0.5), np.full(n, 0.43), None)[0])
        Y = np.vstack([rng.uniform(0, 0.3, (2, n)), rng.uniform(-0.5, 1.0, (1, n)), rng.uniform(-1, 1, (1, n))])
        f = rng.uniform(0.1, 3.0, n)
        inner = max(20, 20000 // n)
        E._step_plain_compiled(Y, 0.3, 1 / 48, f, P, 1.0)
        t_np = _median_time(lambda: E._step_plain(Y, 0.3, 1 / 48, f, P, 1.0), repeat, inner)  # noqa: B023
        t_c = _median_time(lambda: E._step_plain_compiled(Y, 0.3, 1 / 48, f, P, 1.0), repeat, inner)  # noqa: B023
        print(f"{n:6d} {t_np * 1e6:10.1f} {t_c * 1e6:10.1f} {t_np / t_c:7.2f}")


def solve_table(repeat: int) -> None:
    print("forces from displacements, tapered twig (median ms per solve)")
    print(f"{'displacements':>13} {'numpy':>10} {'compiled':>10} {'ratio':>7}")
    kernel = _compiled.plain_step
    for n in (8, 256):
        xi = np.linspace(0.01, 0.3, n)

        def solve(xi=xi):
            return E.force_from_displacement_nd(xi, 0.5, 0.43)

        solve()
        times = {}
        for name, k in (("numpy", None), ("compiled", kernel)):
            _compiled.plain_step = k
            try:
                times[name] = _median_time(solve, repeat, 3)
            finally:
                _compiled.plain_step = kernel
        print(f"{n:13d} {times['numpy'] * 1e3:10.1f} {times['compiled'] * 1e3:10.1f} "
              f"{times['numpy'] / times['compiled']:7.2f}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    if _compiled.plain_step is None:
        raise SystemExit("numba missing or BAYESROD_NO_JIT set: nothing compiled to compare")
    step_table(args.repeat)
    solve_table(args.repeat)


if __name__ == "__main__":
    main()

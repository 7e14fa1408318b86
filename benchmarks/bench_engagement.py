"""The engagement detector's change point, cumulative sums against one line fit per split.

Run:  python benchmarks/bench_engagement.py [--repeat 7]

A push at signal-to-noise 5 whose force falls along its branch before the slip, followed by ``n``
unloaded samples (a rig that keeps logging after the stem left the probe: 30, 300, 3000). Each case
times ``detect_engagement`` as shipped (the change point from cumulative sums) and, as the reference
in the same process, with the slow loop (``_slip_change_point_reference``) in its place; prints the
median of ``--repeat`` runs, their ratio and whether both found the same slip.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bayesrod.dataset import engagement


def _push(n_after: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 1.0, 60)
    true = np.where(x < 0.6, np.sin(x / 0.6 * np.pi / 2), 1.0 - 0.8 * (x - 0.6) / 0.4)
    return np.r_[true, np.zeros(n_after)] + rng.normal(0.0, 0.2, 60 + n_after)


def _time(F: np.ndarray, repeat: int) -> tuple[float, int | None]:
    times, slip = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        slip = engagement.detect_engagement(F).slip_index
        times.append(time.perf_counter() - t)
    return statistics.median(times), slip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    fast = engagement._slip_change_point
    print(f"{'unloaded samples':>17} {'shipped [ms]':>13} {'reference [ms]':>15} {'ratio':>7}  same slip")
    for n in (30, 300, 3000):
        F = _push(n)
        t_fast, s_fast = _time(F, args.repeat)
        engagement._slip_change_point = engagement._slip_change_point_reference
        try:
            t_ref, s_ref = _time(F, args.repeat)
        finally:
            engagement._slip_change_point = fast
        print(f"{n:>17} {1e3 * t_fast:>13.2f} {1e3 * t_ref:>15.2f} {t_ref / t_fast:>7.1f}  {s_fast == s_ref}")


if __name__ == "__main__":
    main()

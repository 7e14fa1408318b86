"""Forward solves per second: batched fast path against the solve_ivp reference.

Run:  python benchmarks/bench_forward.py [--batch 2000] [--repeat 5]

For each published specimen height (twig, grass) and each direction
(force -> contact; displacement -> force), the script

1. measures the fast path's error against a tight reference (rtol 1e-13) on
   a subsample,
2. picks the loosest reference tolerance (1e-6 ... 1e-12) whose own error is
   no larger (equal accuracy), and
3. times both in this process: the fast path on the whole batch (median of
   ``--repeat`` runs, per solve), the reference solve by solve, and prints the
   ratio. Medians over the cases are printed last.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bayesrod.physics import reference as R
from bayesrod.physics.elastica import contact_from_force_nd, force_from_displacement_nd
from bayesrod.physics.presets import PRESETS

RTOLS = [1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12]


def _median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _rel_err(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.max(np.abs(a[ok] / b[ok] - 1))) if ok.any() else np.nan


def bench_case(eta, p, direction, batch, repeat, n_sub=12):
    if direction == "force->contact":
        probe = contact_from_force_nd(np.linspace(0, 60, 3000), eta, p)
        f_end = np.linspace(0, 60, 3000)[probe["found"]].max()
        x = np.linspace(0.001, 0.98, batch) * f_end

        def fast():
            return contact_from_force_nd(x, eta, p)["xi_c"]

        def ref(xi, rtol):
            return R.solve_force(xi, eta, p, rtol=rtol)["xi_c"]
    else:
        d = np.linspace(0, 1.2, 241)
        d_end = d[~force_from_displacement_nd(d, eta, p)["slipped"]].max()
        x = np.linspace(0.001, 0.95, batch) * d_end

        def fast():
            return force_from_displacement_nd(x, eta, p)["f"]

        def ref(xi, rtol):
            return R.solve_displacement(xi, eta, p, rtol=rtol)["f"]

    sub = np.linspace(0, batch - 1, n_sub).astype(int)
    truth = np.array([ref(x[i], 1e-13) for i in sub])
    y_fast = fast()
    err_fast = _rel_err(y_fast[sub], truth)
    chosen = RTOLS[-1]
    for rtol in RTOLS:
        if _rel_err([ref(x[i], rtol) for i in sub], truth) <= max(err_fast, 1e-13):
            chosen = rtol
            break
    err_ref = _rel_err([ref(x[i], chosen) for i in sub], truth)
    t_fast = _median_time(fast, repeat) / batch
    t_ref = _median_time(lambda: [ref(x[i], chosen) for i in sub], max(1, repeat // 2)) / n_sub
    return {
        "err_fast": err_fast,
        "err_ref": err_ref,
        "rtol_ref": chosen,
        "us_fast": t_fast * 1e6,
        "us_ref": t_ref * 1e6,
        "ratio": t_ref / t_fast,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batch", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rows = []
    print(
        f"{'case':<26}{'direction':<22}{'fast err':>10}{'ref rtol':>10}{'ref err':>10}"
        f"{'fast us':>10}{'ref us':>10}{'ratio':>8}"
    )
    for name in ("twig", "grass"):
        pr = PRESETS[name]
        for h in pr["heights_m"]:
            eta = h / pr["length_m"]
            for direction in ("force->contact", "displacement->force"):
                r = bench_case(eta, pr["p"], direction, args.batch, args.repeat)
                rows.append((direction, r))
                print(
                    f"{name + f' h={h:g} m':<26}{direction:<22}{r['err_fast']:>10.1e}{r['rtol_ref']:>10.0e}"
                    f"{r['err_ref']:>10.1e}{r['us_fast']:>10.1f}{r['us_ref']:>10.0f}{r['ratio']:>8.0f}"
                )
    for direction in ("force->contact", "displacement->force"):
        ratios = [r["ratio"] for d, r in rows if d == direction]
        fast = [r["us_fast"] for d, r in rows if d == direction]
        print(
            f"median {direction}: fast {statistics.median(fast):.1f} us/solve, "
            f"speed-up x{statistics.median(ratios):.0f} (min x{min(ratios):.0f})"
        )


if __name__ == "__main__":
    main()

"""ESS per second of the table likelihood against a naive solve_ivp likelihood, same data, same process.

Run:  python benchmarks/bench_likelihood.py [--repeat 3]

1. Fits the bundled dataset (3 pushes, 180 engaged force samples, 66 frames)
   with the table likelihood and emcee exactly as ``bayesrod fit`` does, and
   records the bulk ESS of EI0 and p, the wall time, and the number of
   log-probability evaluations.
2. Times the naive likelihood at the same parameters: per force sample one
   ``reference.solve_displacement`` (solve_ivp + brentq), per frame one
   ``reference.shape_at_force``; residuals and Gaussian log density as in
   ``RodLikelihood`` (median of ``--repeat`` evaluations).
3. The naive sampler would need the same evaluations for the same ESS (same
   target, same sampler), so its ESS/s = ESS / (evaluations x time per
   evaluation). Running it would take days, hence the extrapolation.
4. The naive evaluation is also the yardstick of the machine: the table fit's
   ESS/s scaled by (naive time today / naive time on the reference day,
   ``--reference-naive-s``, 24.5 s on 2026-11-21) is what the fit would give on
   the reference day's machine. The same machine ran the same code 3x slower on
   some days than on others (docs/performance.md), so an absolute ESS/s target
   (issue 19: >= 300 for the AR(1) fit) is read on this scaled number.
"""

from __future__ import annotations

import argparse
import statistics
import time
from importlib import resources

import numpy as np

from bayesrod.dataset import read_dataset
from bayesrod.inference.likelihood import LogPosterior, RodLikelihood
from bayesrod.inference.priors import load_prior
from bayesrod.inference.sampler import find_start, run_ensembles
from bayesrod.physics import reference as R


def naive_log_likelihood(lik: RodLikelihood, EI0: float, p: float, s_force: float, s_scale: float) -> float:
    L = lik.L
    ll = 0.0
    for d in lik.data:
        eta = d.height_m / L
        for D, F in zip(d.D_m, d.F_N, strict=True):
            r = R.solve_displacement(D / L, eta, p)
            pred = 0.0 if r["slipped"] else r["f"] * EI0 / L**2
            ll += -0.5 * ((F - pred) / s_force) ** 2 - np.log(s_force)
        for m, Dm in enumerate(d.frame_D_m):
            sel = d.frame_index == m
            r = R.solve_displacement(Dm / L, eta, p)
            sig = np.linspace(0, 1, 241)
            xz = R.shape_at_force(r["f"], eta, p, sig) if not r["slipped"] else np.vstack([0 * sig, sig])
            x_pred = np.interp(d.z_m[sel] / L, np.maximum.accumulate(xz[1]), xz[0]) * L
            res = d.x_m[sel] - x_pred
            sd = s_scale * d.sd_m[sel]
            ll += float(np.sum(-0.5 * (res / sd) ** 2 - np.log(sd)))
    return ll


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--force-noise", choices=["iid", "ar1"], default="iid", help="the table likelihood's noise model")
    ap.add_argument(
        "--reference-naive-s",
        type=float,
        default=24.5,
        help="seconds of one naive evaluation on the reference day (2026-11-21), the machine's yardstick",
    )
    args = ap.parse_args()
    spec = read_dataset(resources.files("bayesrod") / "data" / "default")
    t0 = time.perf_counter()
    lik = RodLikelihood(spec, force_noise=args.force_noise)
    post = LogPosterior(lik, load_prior("default"))
    t_tables = time.perf_counter() - t0
    calls = {"n": 0}
    inner = post.log_prob

    def counted(theta):
        calls["n"] += np.atleast_2d(theta).shape[0]
        return inner(theta)

    post.log_prob = counted
    theta0 = find_start(post, np.random.default_rng(0))
    res = run_ensembles(post, theta0, progress=False, seed=0)
    t_fit = time.perf_counter() - t0
    ess = min(res.diagnostics["ess_bulk"]["EI0"], res.diagnostics["ess_bulk"]["p"])
    nat = {k: float(np.median(v)) for k, v in post.to_natural(res.chain.reshape(-1, post.ndim)).items()}
    per_eval_fast = t_fit / calls["n"]
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        naive_log_likelihood(lik, nat["EI0"], nat["p"], nat["sigma_force_N"], nat["shape_sd_scale"])
        times.append(time.perf_counter() - t)
    per_eval_naive = statistics.median(times)
    ess_s_fast = ess / t_fit
    ess_s_naive = ess / (calls["n"] * per_eval_naive)
    print(f"force noise: {args.force_noise}")
    print(f"data: {lik.n_force} force samples, {lik.n_points} centerline points, {len(spec.pushes)} pushes")
    print(
        f"table likelihood: tables {t_tables:.1f} s, fit {t_fit:.1f} s in total, {calls['n']} walker evaluations, "
        f"bulk ESS min(EI0, p) = {ess:.0f} -> {ess_s_fast:.1f} ESS/s ({per_eval_fast * 1e6:.1f} us per evaluation, "
        "everything included)"
    )
    print(
        f"naive solve_ivp likelihood: {per_eval_naive:.2f} s per evaluation (median of {args.repeat}) -> "
        f"{ess_s_naive:.2e} ESS/s for the same number of evaluations"
    )
    print(f"ratio: x{ess_s_fast / ess_s_naive:.3g}")
    speed = per_eval_naive / args.reference_naive_s
    print(
        f"machine: the naive evaluation took {speed:.2f}x its {args.reference_naive_s:g} s of the reference day -> "
        f"{ess_s_fast * speed:.0f} ESS/s on the reference day's machine"
    )


if __name__ == "__main__":
    main()

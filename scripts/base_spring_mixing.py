"""One SBC base-compliance case fitted with the spring sampled in u, in log k, or as the fit chooses.

    python scripts/base_spring_mixing.py --seed 121 --coordinates u --max-steps 60000 --target-ess 4000
    python scripts/base_spring_mixing.py --seed 121 --coordinates log_k --max-steps 60000 --target-ess 4000

Since 2026-11-27 a fit samples a base spring by its table coordinate u = c / (1 + c), c = EI0 / (k L),
where its start is a stiff spring (u <= 0.5), else in log k (bayesrod.inference.priors.ParameterSpace,
``settle_base_coordinates``; docs/inference.md "Sampling"): ``--coordinates fit``. ``u`` and ``log_k``
force one or the other: the same posterior, other coordinates. The case is scripts/sbc_geometry.py's
(``draw_case``: stem, heights, effect value, noise; forces only, the fixed robot step of 0.01 L) on the
simulator's data; the script prints the convergence (with the steps the sampler took: the bulk ESS grows with
them, so compare ESS per step) and the 5/50/95% quantiles (docs/validation.md,
"Sampling a base spring").
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sbc_geometry as S

import bayesrod.inference.likelihood as LK
from bayesrod import fit


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=121)
    ap.add_argument("--coordinates", choices=["fit", "u", "log_k"], default="fit")
    ap.add_argument("--max-steps", type=int, default=8000)
    ap.add_argument("--target-ess", type=float, default=400.0)
    ap.add_argument("--fit-seed", type=int, default=None, help="the sampler's seed (default: the case's + 1000)")
    a = ap.parse_args(argv)
    case = S.draw_case(a.seed, S.EFFECTS_BEFORE_FRICTION)
    if case["effect"] != "base_compliance":
        ap.error(f"--seed: expected a base-compliance case (seed = 1 mod 5), got {case['effect']} for seed {a.seed}")
    if a.coordinates == "log_k":
        init = LK.LogPosterior.__init__

        def in_log_k(self, *args, **kw):
            init(self, *args, **kw)
            self.base_length_m = None

        LK.LogPosterior.__init__ = in_log_k
    elif a.coordinates == "u":
        LK.LogPosterior.settle_base_coordinates = lambda self, theta: theta
    ds = S.simulate_case(a.seed, case, frames=2)  # forces only: two frames a push, as the SBC's
    print(
        f"seed {a.seed}: EI0 {case['EI0']:.4g} N m^2, p {case['p']:.4g}, k {case['effect_value']:.4g} N m/rad, "
        f"L {case['length_m']:.3f} m, heights/L {[round(h / case['length_m'], 3) for h in case['heights_m']]}"
    )
    t = time.perf_counter()
    post = fit(
        ds,
        prior=S.PRIOR,
        effects=("base_compliance",),
        seed=a.seed + 1000 if a.fit_seed is None else a.fit_seed,
        progress=False,
        use_shapes=False,
        target_ess=a.target_ess,
        max_steps=a.max_steps,
    )
    c, smp = post.doc["convergence"], post.doc["sampler"]
    print(
        f"{a.coordinates}: {time.perf_counter() - t:.0f} s, R-hat max {c['rhat_max']:.4f}, "
        f"bulk ESS min {c['ess_bulk_min']:.0f}, converged {c['converged']}; {smp['steps']} steps "
        f"(burn-in {smp['burn_in']}), autocorrelation time by ensemble {np.round(smp['autocorr_time'], 1)}"
    )
    for k, v in post.samples.items():
        print(f"  {k}: 5/50/95% {np.round(np.quantile(v, [0.05, 0.5, 0.95]), 5)}")


if __name__ == "__main__":
    main()

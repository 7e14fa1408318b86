"""Why the friction fit's held-out error scatters from seed to seed (issue 21, diagnose).

    python scripts/friction_heldout_probe.py [--seed 13] [--nfev 12 40]

The simulated twig with contact friction mu 0.3 as ``scripts/diagnose_study.py --effects contact_friction``
makes it (8 frames per push, iid force noise 0.03 N), fitted with friction added (the diagnose model: log EI0,
p, mu), then each height held out and predicted from a refit to the other two, once per refit budget
``--nfev`` (diagnose gives slow effects 12 evaluations). Printed: the full fit, per budget the held-out RMSE and
each held-out push's RMSE and refit parameters; then the lowest push's residuals as mu, p and EI0 move about
the full fit (is its prediction steep in a parameter, or broken?). About 10 minutes for the fit and 9 per
budget on one core.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bayesrod
from bayesrod.inference.diagnose import Diagnoser, ForwardModel
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects

EFFECTS = ("contact_friction",)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=13)
    ap.add_argument("--nfev", type=int, nargs="+", default=[12, 40])
    a = ap.parse_args()
    spec = bayesrod.simulate(
        "twig",
        seed=a.seed,
        effects=Effects.from_mapping({"contact_friction": 0.3}),
        noise_rho=0.0,
        config_overrides={"specimen": f"diag-{a.seed}", "n_frames_engaged": 8},
    )
    model = ForwardModel(prepare_data(spec, use_shapes=True), spec.length_m)
    dg = Diagnoser(model)
    t = time.perf_counter()
    plain = dg.fit_plain()
    fit = dg.fit(EFFECTS, x0=np.r_[plain.x, 0.25], max_nfev=40)
    print(f"full fit: EI0 {np.exp(fit.x[0]):.5f} p {fit.x[1]:.5f} mu {fit.x[2]:.5f} ({time.perf_counter() - t:.0f} s)")
    for nfev in a.nfev:
        t = time.perf_counter()
        h, _ = dg.heldout(fit, max_nfev=nfev)
        print(f"refits of {nfev} evaluations: held-out RMSE {h['heldout_force_rmse_N']:.5f} N")
        for u in h["per_push"]:
            r = u["refit"]
            print(
                f"  held out {u['height_m']:.2f} m: RMSE {u['force_rmse_N']:.4f} N; refit EI0 {r['EI0']:.4f} "
                f"p {r['p']:.4f} mu {r['contact_friction']:.4f}"
            )
        print(f"  ({time.perf_counter() - t:.0f} s)")
    first = list(np.flatnonzero(model.first_sample)) + [model.n_force]
    lo = slice(first[0], first[1])  # the lowest push (0.45 m)
    x0 = fit.x.copy()
    for i, name, grid in (
        (2, "mu", x0[2] + np.linspace(-0.00175, 0.00025, 9)),
        (1, "p", x0[1] + np.linspace(-0.001, 0.0005, 7)),
        (0, "log EI0", x0[0] + np.linspace(-0.0017, 0.0021, 6)),
    ):
        print(f"the 0.45-m push's residuals as {name} moves (the others at the full fit):")
        for v in grid:
            x = x0.copy()
            x[i] = v
            rf, _ = dg.raw_residuals(x, EFFECTS)
            r = rf[lo]
            print(f"  {name} {v:.5f}: RMSE {np.sqrt(np.mean(r**2)):.4f} N, last three {np.round(r[-3:], 3)}")


if __name__ == "__main__":
    main()

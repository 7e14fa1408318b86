"""Where between a fit's start and its posterior median the likelihood tables go wrong (issue 21).

    python scripts/table_check_line.py --seed 7 --effects contact_friction \
        --to EI0=2.6792,p=0.7577,sigma_force_N=0.05847,contact_friction=0.50926 [--points 9]

Rebuilds one replicate of scripts/sbc_geometry.py as it fits it (the same simulated data, reference
re-solve, prior, effects and seed), runs ``bayesrod.fit`` up to the point where it would decide whether
to narrow the effect axis, and stops there: the likelihood, the posterior and the sampler's start are the
fit's own. Then prints ``table_check`` (bayesrod.inference.likelihood) at ``--points`` evenly spaced points
on the straight line, in natural units, from the start to ``--to`` (a posterior median from the study's row;
parameters not named keep the start's value): the largest table-vs-exact force error over sigma, the
centerline error over its sd, and the shift of each parameter in Laplace sds.
"""

from __future__ import annotations

import argparse

import numpy as np
import sbc_geometry as S

import bayesrod.api.fitting as fitting
from bayesrod.inference.likelihood import table_check


class _Stop(Exception):
    pass


def fit_start(seed: int, effects: tuple) -> tuple:
    """The fit's likelihood, posterior and start for SBC replicate ``seed`` (the fit stopped before its zoom)."""
    case = S.draw_case(seed, (None, *effects))
    ds, _, _ = S.replicate_dataset(seed, case)
    seen = {}

    def stop(spec, pr, eff, config, post, theta0):
        seen.update(post=post, theta0=theta0)
        raise _Stop

    real = fitting._zoom_tables
    fitting._zoom_tables = stop
    try:
        fitting.fit(
            ds,
            prior=str(S.PRIOR),
            effects=(case["effect"],),
            seed=seed,
            progress=False,
            use_shapes=case["shapes"],
            **S.FIT_BUDGET,
        )
    except _Stop:
        pass
    finally:
        fitting._zoom_tables = real
    return case, seen["post"], seen["theta0"]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--effects", default="contact_friction")
    ap.add_argument("--to", required=True, help="name=value,... in natural units (the posterior median)")
    ap.add_argument("--points", type=int, default=9)
    a = ap.parse_args(argv)
    case, post, theta0 = fit_start(a.seed, tuple(a.effects.split(",")))
    lik = post.likelihood
    start = {k: float(v[0]) for k, v in post.to_natural(np.asarray(theta0)[None]).items()}
    end = start | {k: float(v) for k, v in (kv.split("=") for kv in a.to.split(","))}
    truth = {"EI0": case["EI0"], "p": case["p"], case["effect"]: case["effect_value"]}
    print(f"seed {a.seed}: {case['effect']}, {len(case['heights_m'])} heights, shapes {case['shapes']}")
    print("truth " + ", ".join(f"{k} {v:.5g}" for k, v in truth.items()))
    print("start " + ", ".join(f"{k} {v:.5g}" for k, v in start.items()))
    print("to    " + ", ".join(f"{k} {v:.5g}" for k, v in end.items()))
    g = lik.axis.grid
    print(f"effect axis {lik.axis.name}: {g.size} nodes on u [{g[0]:.4g}, {g[-1]:.4g}]")
    for t in np.linspace(0.0, 1.0, a.points):
        pt = {k: (1 - t) * start[k] + t * end[k] for k in start}
        u = float(lik.effect_coordinate({k: np.atleast_1d(v) for k, v in pt.items()})[0])
        ck = table_check(lik, pt)
        if ck is None:
            print(f"t {t:.3f}: no check")
            continue
        shifts = ", ".join(f"{k} {v:+.3f}" for k, v in ck["shift_in_sd"].items())
        print(
            f"t {t:.3f} u {u:.5f} p {pt['p']:.5f}: force err/sigma {ck['max_error_over_sigma']}, "
            f"shape err/sd {ck.get('max_shape_error_over_sd')}; shifts {shifts}",
            flush=True,
        )


if __name__ == "__main__":
    main()

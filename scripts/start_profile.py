"""The sampler's start with and without the effect's profile (issue 21, docs/validation.md "Session 70").

    python scripts/start_profile.py                 # the soft base
    python scripts/start_profile.py --base-seed 11  # and a base-compliance case of scripts/sbc_geometry.py
    python scripts/start_profile.py --friction      # and the friction case

Measured (session 70): the soft base with ``--base-seed 11`` 64 s on an otherwise idle core; the friction
case's 9-node tables took 21 min on a busy core.

For each case: the likelihood as a fit builds it, then ``find_start`` with and without
``_profile_effect`` (replaced by the identity) and with and without its Nelder-Mead polish (``minimize``
replaced by a failure, as the tests' ``no_polish`` fixture does); prints each start in natural units, its
coordinate u on the effect axis and its log posterior.
"""

from __future__ import annotations

import argparse

import numpy as np
import sbc_geometry as S

import bayesrod
import bayesrod.inference.sampler as sampler
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference.likelihood import LogPosterior, build_likelihood
from bayesrod.inference.priors import load_prior


class _Failed:
    fun, x = float("inf"), None


def starts(post) -> None:
    """Print the four starts of ``post``: profile on/off by polish on/off."""
    lik = post.likelihood
    real_profile, real_minimize = sampler._profile_effect, sampler.minimize
    try:
        for tag, profile in (("with the profile", real_profile), ("without", lambda post, t, lp: (t, lp))):
            for polish in (False, True):
                sampler._profile_effect = profile
                sampler.minimize = real_minimize if polish else (lambda *a, **k: _Failed())
                theta = sampler.find_start(post, np.random.default_rng(0))
                nat = {k: float(v[0]) for k, v in post.to_natural(theta[None]).items()}
                u = float(lik.effect_coordinate(nat)[0])
                shown = ", ".join(f"{k} {v:.4g}" for k, v in nat.items())
                print(f"  {tag}, polish {polish}: {shown}; u {u:.4f}; log posterior {post.log_prob(theta):.1f}")
    finally:
        sampler._profile_effect, sampler.minimize = real_profile, real_minimize


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--friction", action="store_true", help="also the friction case (its 9-node friction tables: 21 min measured)"
    )
    ap.add_argument(
        "--base-seed",
        type=int,
        nargs="*",
        default=[],
        help="base-compliance SBC seeds (1 mod 5), fitted as scripts/base_spring_mixing.py fits them",
    )
    args = ap.parse_args(argv)
    prior = load_prior("woody")
    print("twig on a soft base (c = 1, u 0.5), seed 12, forces only, base spring on 7 nodes:")
    ds = bayesrod.simulate(
        "twig", seed=12, effects={"base_compliance": 2.63 / 0.8}, config_overrides={"n_frames_engaged": 2}
    )
    starts(LogPosterior(build_likelihood(ds, prior, ("base_compliance",), use_shapes=False, n_effect=7), prior))
    for seed in args.base_seed:
        case = S.draw_case(seed, S.EFFECTS_BEFORE_FRICTION)
        if case["effect"] != "base_compliance":
            ap.error(f"--base-seed: expected a base-compliance case (1 mod 5), got {case['effect']} for {seed}")
        print(
            f"SBC seed {seed}: EI0 {case['EI0']:.4g}, p {case['p']:.4g}, k {case['effect_value']:.4g} N m/rad, "
            f"{len(case['heights_m'])} heights, forces only (the SBC's prior):"
        )
        ds = S.simulate_case(seed, case, frames=2)
        sbc_prior = load_prior(S.PRIOR)
        starts(LogPosterior(build_likelihood(ds, sbc_prior, ("base_compliance",), use_shapes=False), sbc_prior))
    if args.friction:
        print("twig with contact friction 0.5, seed 1, forces only (sd 0.05 N), friction on 9 nodes:")
        noise = NoiseModel(force_sd_N=0.05, shape_sd_m=0.0015, shape_sd_reported_m=0.0015)
        ds = bayesrod.simulate(
            "twig",
            seed=1,
            effects={"contact_friction": 0.5},
            noise_model=noise,
            config_overrides={"n_frames_engaged": 2, "robot_step_m": 0.016},
        )
        lik = build_likelihood(ds, prior, ("contact_friction",), use_shapes=False, n_effect=9)
        starts(LogPosterior(lik, prior))


if __name__ == "__main__":
    main()

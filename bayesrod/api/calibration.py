"""Simulation-based calibration (Talts et al. 2018) and recovery studies, through the users' own :func:`fit`.

One SBC replicate draws every sampled parameter from the prior (EI0, p and
the noise terms), simulates a dataset with exactly that noise, fits it with
the same prior (the same :func:`bayesrod.fit` users call), and records the
rank of each true value among L thinned posterior draws and whether the 90%
interval covers it. Over many replicates the ranks are uniform on {0, ..., L}
and coverage is 90% if and only if the posterior is calibrated (for the model
it was simulated from). Nothing is written to disk.
"""

from __future__ import annotations

import numpy as np

from ..inference.priors import load_prior
from ..physics.presets import get_preset
from .data import simulate
from .fitting import fit

NOMINAL_SHAPE_SD_M = 0.0015  # the sd_m the data report; the truth's shape_sd_scale multiplies it


def simulate_from_prior(prior_name: str, seed: int, *, preset: str = "twig", use_shapes: bool = True):
    """Draw a truth from the prior and simulate a dataset with it; returns (dataset, truth in natural units)."""
    from ..dataset.simulate import NoiseModel

    pr = load_prior(prior_name)
    rng = np.random.default_rng(10_000 + seed)
    truth = {"EI0": float(pr.get("EI0").draw(rng, 1)[0]), "p": float(pr.get("p").draw(rng, 1)[0])}
    truth["sigma_force_N"] = float(pr.get("sigma_force_N").draw(rng, 1)[0])
    truth["shape_sd_scale"] = float(pr.get("shape_sd_scale").draw(rng, 1)[0])
    noise = NoiseModel(
        force_sd_N=truth["sigma_force_N"],
        shape_sd_m=NOMINAL_SHAPE_SD_M * truth["shape_sd_scale"],
        shape_sd_reported_m=NOMINAL_SHAPE_SD_M,
    )
    ps = get_preset(preset)
    stem = {
        "EI0": truth["EI0"],
        "p": truth["p"],
        "length_m": ps["length_m"],
        "heights_m": ps["heights_m"],
        "species": ps["species"],
        "specimen": f"sbc-{seed}",
    }
    extra = {} if use_shapes else {"n_frames_engaged": 2}  # frames unused by a force-only fit
    ds = simulate(stem, seed=seed, noise_model=noise, config_overrides=extra)
    return ds, truth


def fit_for_calibration(
    dataset, prior_name: str, *, seed: int, use_shapes: bool = True, target_ess: float = 400.0, n_rank: int = 99
) -> dict:
    """Fit (in memory) and return thinned draws and 5/50/95% quantiles per parameter."""
    post = fit(
        dataset,
        prior=prior_name,
        seed=seed,
        progress=False,
        use_shapes=use_shapes,
        target_ess=target_ess,
        max_steps=6000,
    )
    rng = np.random.default_rng(seed)
    n = post.samples["EI0"].size
    idx = rng.permutation(n)[:n_rank]  # random thinning: ranks need (nearly) independent draws
    out = {"rhat_max": float(post.doc["convergence"]["rhat_max"]), "names": list(post.doc["parameters"])}
    for k, v in post.samples.items():
        out[k] = {"draws": np.asarray(v)[idx], "q": np.quantile(v, [0.05, 0.5, 0.95])}
    return out


def sbc_replicate(seed: int, prior_name: str = "woody", *, use_shapes: bool = True, target_ess: float = 400.0):
    """One SBC replicate: rank of the truth among 99 draws, and 90% coverage, for EI0 and p."""
    ds, truth = simulate_from_prior(prior_name, seed, use_shapes=use_shapes)
    res = fit_for_calibration(ds, prior_name, seed=seed, use_shapes=use_shapes, target_ess=target_ess)
    row = {"seed": seed, "rhat_max": res["rhat_max"]}
    for k in ("EI0", "p"):
        q05, q50, q95 = res[k]["q"]
        row[f"{k}_true"] = truth[k]
        row[f"{k}_median"] = float(q50)
        row[f"{k}_rank"] = int(np.sum(res[k]["draws"] < truth[k]))
        row[f"{k}_covered"] = bool(q05 <= truth[k] <= q95)
    return row

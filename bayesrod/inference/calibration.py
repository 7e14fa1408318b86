"""Simulation-based calibration (Talts et al. 2018) and recovery studies.

One SBC replicate draws every sampled parameter from the prior (EI0, p and
the noise terms), simulates a dataset with exactly that noise, fits it with
the same prior, and records the rank of each true value among L thinned
posterior draws and whether the 90% interval covers it. Over many replicates
the ranks are uniform on {0, ..., L} and coverage is 90% if and only if the
posterior is calibrated (for the model it was simulated from).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ..dataset import read_dataset
from ..presets import get_preset
from .likelihood import LogPosterior, RodLikelihood
from .priors import load_prior
from .sampler import find_start, run_ensembles

NOMINAL_SHAPE_SD_M = 0.0015  # the sd_m written to shapes.csv; the truth's shape_sd_scale multiplies it


def simulate_from_prior(prior_name: str, seed: int, out: Path, *, preset: str = "twig", use_shapes: bool = True):
    """Draw a truth from the prior and write a simulated dataset with it; returns the truth (natural units)."""
    from ..simulate import NoiseModel, SimConfig, simulate, write_simulated

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
    cfg = SimConfig.from_preset(preset, seed=seed, EI0=truth["EI0"], p=truth["p"], specimen=f"sbc-{seed}")
    extra = {} if use_shapes else {"n_frames_engaged": 2}  # frames unused by a force-only fit
    cfg = SimConfig(**{**cfg.__dict__, "noise": noise, "heights_m": tuple(ps["heights_m"]), **extra})
    out.mkdir(parents=True, exist_ok=True)
    write_simulated(cfg, simulate(cfg), out)
    return truth


def fit_for_calibration(
    dataset, prior_name: str, *, seed: int, use_shapes: bool = True, target_ess: float = 400.0, n_rank: int = 99
) -> dict:
    """Fit without writing a run directory; returns thinned draws and 5/50/95% quantiles per parameter."""
    spec = read_dataset(dataset)
    pr = load_prior(prior_name)
    lo, hi = pr.get("p").bounds()
    lik = RodLikelihood(spec, p_range=(lo, min(hi, 3.0)), use_shapes=use_shapes)
    post = LogPosterior(lik, pr)
    theta0 = find_start(post, np.random.default_rng(seed))
    res = run_ensembles(post, theta0, seed=seed, progress=False, target_ess=target_ess, max_steps=6000)
    flat = res.chain.reshape(-1, post.ndim)
    nat = post.to_natural(flat)
    rng = np.random.default_rng(seed)
    idx = rng.permutation(flat.shape[0])[:n_rank]  # random thinning: ranks need (nearly) independent draws
    out = {"rhat_max": float(max(res.diagnostics["rhat"].values())), "names": post.names}
    for k, v in nat.items():
        out[k] = {"draws": np.asarray(v)[idx], "q": np.quantile(v, [0.05, 0.5, 0.95])}
    return out


def sbc_replicate(seed: int, prior_name: str = "woody", *, use_shapes: bool = True, target_ess: float = 400.0):
    """One SBC replicate: rank of the truth among 99 draws, and 90% coverage, for EI0 and p."""
    with tempfile.TemporaryDirectory() as tmp:
        truth = simulate_from_prior(prior_name, seed, Path(tmp) / "ds", use_shapes=use_shapes)
        fit = fit_for_calibration(Path(tmp) / "ds", prior_name, seed=seed, use_shapes=use_shapes, target_ess=target_ess)
    row = {"seed": seed, "rhat_max": fit["rhat_max"]}
    for k in ("EI0", "p"):
        q05, q50, q95 = fit[k]["q"]
        row[f"{k}_true"] = truth[k]
        row[f"{k}_median"] = float(q50)
        row[f"{k}_rank"] = int(np.sum(fit[k]["draws"] < truth[k]))
        row[f"{k}_covered"] = bool(q05 <= truth[k] <= q95)
    return row

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
from ..inference.summary import QUANTILES
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
    dataset,
    prior_name: str,
    *,
    seed: int,
    use_shapes: bool = True,
    target_ess: float = 400.0,
    n_rank: int = 99,
    effects=(),
    max_steps: int = 6000,
    **fit_options,
) -> dict:
    """Fit (in memory, ``effects`` fitted) and return thinned draws and 5/50/95% quantiles per parameter;
    ``fit_options`` go to :func:`bayesrod.fit` (e.g. ``slip=True``)."""
    post = fit(
        dataset,
        prior=prior_name,
        effects=effects,
        seed=seed,
        progress=False,
        use_shapes=use_shapes,
        target_ess=target_ess,
        max_steps=max_steps,
        **fit_options,
    )
    rng = np.random.default_rng(seed)
    n = post.samples["EI0"].size
    idx = rng.permutation(n)[:n_rank]  # random thinning: ranks need (nearly) independent draws
    out = {"rhat_max": float(post.doc["convergence"]["rhat_max"]), "names": list(post.doc["parameters"])}
    out["steps"] = int(post.doc["sampler"]["steps"])
    out |= table_columns(post.doc)
    for k, v in post.samples.items():
        out[k] = {"draws": np.asarray(v)[idx], "q": np.quantile(v, QUANTILES)}
    return out


def table_columns(doc: dict) -> dict:
    """A calibration row's record of the fit's table check (summary.json ``table_check``): ``table_shift_sd``,
    the largest |shift| [Laplace sd] at the posterior median (NaN where not checked); ``table_shift_worst``,
    the parameter it moves most; ``table_shift_start_sd``, the same at the sampler's start, the worst of the
    check there and with the effect, or p, in the middle of its node interval, which decided the zoom (NaN where
    not checked); ``effect_axis_zoom`` and ``p_axis_zoom``: ``"none"`` (axis kept as built), ``"kept"``
    (narrowed around the start) or ``"refused"`` (narrowed, but the check at the start did not improve)."""
    check = doc.get("table_check") or {}
    shifts = {k: abs(float(v)) for k, v in (check.get("shift_in_sd") or {}).items()}
    worst = max(shifts, key=shifts.get) if shifts else ""
    start = check.get("at_start") or {}
    start_shifts = [
        abs(float(v))
        for c in (start, start.get("between_nodes") or {}, start.get("between_p_nodes") or {})
        for v in (c.get("shift_in_sd") or {}).values()
    ]

    def zoomed(key: str) -> str:
        zoom = check.get(key)
        return "none" if zoom is None else ("kept" if zoom.get("kept") else "refused")

    return {
        "table_shift_sd": shifts[worst] if worst else float("nan"),
        "table_shift_worst": worst,
        "table_shift_start_sd": max(start_shifts) if start_shifts else float("nan"),
        "effect_axis_zoom": zoomed("effect_axis_zoom"),
        "p_axis_zoom": zoomed("p_axis_zoom"),
    }


def sbc_replicate(seed: int, prior_name: str = "woody", *, use_shapes: bool = True, target_ess: float = 400.0):
    """One SBC replicate: rank of the truth among 99 draws, and 90% coverage, for EI0 and p."""
    ds, truth = simulate_from_prior(prior_name, seed, use_shapes=use_shapes)
    res = fit_for_calibration(ds, prior_name, seed=seed, use_shapes=use_shapes, target_ess=target_ess)
    row = {"seed": seed, "rhat_max": res["rhat_max"], "steps": res["steps"]}
    for k in ("EI0", "p"):
        row |= rank_columns(res[k], truth[k], k)
    return row


def rank_columns(res_k: dict, truth: float, key: str) -> dict:
    """An SBC row's columns for one parameter (``res_k`` one entry of :func:`fit_for_calibration`):
    ``{key}_true``, ``_median``, ``_rank`` (of the truth among the thinned draws) and ``_covered`` (by 90%)."""
    q05, q50, q95 = res_k["q"]
    return {
        f"{key}_true": truth,
        f"{key}_median": float(q50),
        f"{key}_rank": int(np.sum(res_k["draws"] < truth)),
        f"{key}_covered": bool(q05 <= truth <= q95),
    }


#: the noise levels the table study holds fixed (the twig preset's): force sd [N], centerline sd [m]
TABLE_STUDY_NOISE = (0.03, 0.0015)


def table_shift(
    effect: str | None = None,
    value: float = 0.0,
    *,
    use_shapes: bool = False,
    seed: int = 1,
    n_effect: int | None = None,
) -> dict:
    """How far the likelihood tables move the maximum-likelihood estimate, in Laplace standard deviations.

    A noise-free twig (three heights; every recorded force and centerline an exact solve, with ``effect``
    at ``value`` switched on) has the truth as its exact-model MLE. The table likelihood (the one the fit
    samples) is maximised over (log EI0, p[, the effect]) with the noise held at
    :data:`TABLE_STUDY_NOISE`; its shift from the truth is divided by the Laplace sd (central
    finite-difference Hessian of the same log likelihood at its maximum). ``n_effect``: nodes on the
    effect's table axis (default: the fit's, :func:`~bayesrod.inference.likelihood.build_likelihood`).

    Returns
    -------
    dict
        ``names`` (log EI0, p[, effect]), ``truth``, ``mle``, ``laplace_sd`` and ``shift_in_sd`` (k,) each;
        ``effect_nodes`` the nodes of the effect's table axis (0 without one).
    """
    from ..dataset.simulate import NoiseModel

    effects = {effect: value} if effect else {}
    ds = simulate("twig", seed=seed, noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0), effects=effects)
    truth = ds.extra["truth"]
    return table_shift_on(
        ds,
        load_prior("woody"),
        {"EI0": truth["EI0"], "p": truth["p"], **effects},
        noise=TABLE_STUDY_NOISE,
        use_shapes=use_shapes,
        n_effect=n_effect,
    )


def table_shift_on(
    data,
    prior,
    truth: dict,
    *,
    noise: tuple[float, float] = TABLE_STUDY_NOISE,
    use_shapes: bool = False,
    n_effect: int | None = None,
) -> dict:
    """:func:`table_shift` on any noise-free dataset whose exact-model MLE is ``truth``.

    ``truth``: ``EI0`` [N m^2], ``p`` and at most one tabled effect by name with its value; ``noise``:
    the force sd [N] and centerline sd [m] held fixed (a centerline sd scale at 1). Returns what
    :func:`table_shift` returns, plus ``loglik_truth`` and ``loglik_max``: the table log likelihood at
    the truth and at its maximum.
    """
    from ..inference.likelihood import build_likelihood
    from ._common import as_dataset

    effect = next((k for k in truth if k not in ("EI0", "p")), None)
    lik = build_likelihood(
        as_dataset(data), prior, (effect,) if effect else (), use_shapes=use_shapes, n_effect=n_effect
    )
    return mle_shift(lik, truth, noise=noise)


def mle_shift(lik, truth: dict, *, noise: tuple[float, float] = TABLE_STUDY_NOISE) -> dict:
    """:func:`table_shift_on` on a built likelihood ``lik`` (its tables as they are)."""
    from scipy.optimize import minimize

    effect = next((k for k in truth if k not in ("EI0", "p")), None)
    value = float(truth[effect]) if effect else 0.0
    fixed = {"sigma_force_N": noise[0], "sigma_shape_m": noise[1], "shape_sd_scale": 1.0}

    def loglik(x) -> float:
        params = {"EI0": np.exp(x[:1]), "p": x[1:2], **{k: np.array([v]) for k, v in fixed.items()}}
        if effect:
            params[effect] = x[2:3]
        return float(lik.log_likelihood(params)[0]) if lik.in_table(params)[0] else -np.inf

    x_true = np.array([np.log(truth["EI0"]), truth["p"]] + ([value] if effect else []))
    res = minimize(lambda x: -loglik(x), x_true, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-10})
    step = np.array([1e-4, 1e-4] + ([1e-4 * max(abs(value), 1.0)] if effect else []))
    sd = np.sqrt(np.diag(np.linalg.inv(-_hessian(loglik, res.x, step))))
    return {
        "names": ["log EI0", "p"] + ([effect] if effect else []),
        "truth": x_true,
        "mle": res.x,
        "laplace_sd": sd,
        "shift_in_sd": (res.x - x_true) / sd,
        "effect_nodes": 0 if lik.axis is None else int(lik.axis.grid.size),
        "loglik_truth": loglik(x_true),
        "loglik_max": -float(res.fun),
    }


def _hessian(f, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central finite-difference Hessian of the scalar ``f`` at ``x`` with steps ``h``."""
    n = x.size
    H = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            ei, ej = np.eye(n)[i] * h[i], np.eye(n)[j] * h[j]
            d = f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)
            H[i, j] = H[j, i] = d / (4 * h[i] * h[j])
    return H

"""Posterior summaries: quantiles, credible bands on EI(s) and k_theta(h), the ArviZ file, summary.json."""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from ..physics import flexural_rigidity, k_theta, stem_diameter
from .sampler import rhat_walkers_max


def import_arviz():
    """ArviZ, imported without its refactor FutureWarning banner (noise for users).

    ArviZ 0.23 stamps the banner's day in a file of the user's cache on import, writing a temporary file and
    renaming it: two processes importing it at once on a new day (fit-many's workers, a study's) race for
    that rename and one fails with FileNotFoundError (seen at 00:04 in a two-worker group study). The stamp
    is then written by the other, so the import is tried again once."""
    import importlib

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        try:
            return importlib.import_module("arviz")
        except OSError:  # the daily stamp's rename lost to another process's: written now
            return importlib.import_module("arviz")


#: The credible level of every interval bayesrod writes to a file (summary.json, compare.json,
#: design.json, the group summaries, predict's JSON): equal-tailed, so ``q05`` and ``q95`` are the
#: 5% and 95% posterior quantiles. The API's bands take any level (``level=``).
LEVEL = 0.9
#: The quantiles behind ``q05``, ``median``, ``q95``: (1 - LEVEL)/2, 1/2, (1 + LEVEL)/2.
QUANTILES = (0.05, 0.5, 0.95)


def quantiles(x, axis=0) -> dict:
    """``median``, ``q05``, ``q95`` of draws ``x`` over ``axis`` (the LEVEL interval); NaN draws are ignored."""
    with warnings.catch_warnings():  # all-NaN columns (beyond every draw's slip) give NaN, silently
        warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
        q = np.nanquantile(np.asarray(x, float), QUANTILES, axis=axis)
    return {"median": q[1], "q05": q[0], "q95": q[2]}


def credible_interval(x) -> dict:
    """``{median, q05, q95}`` of 1-D draws ``x`` as floats: the form of every interval in the JSON files."""
    return {k: float(v) for k, v in quantiles(x).items()}


#: power-scaling sensitivity (:func:`prior_sensitivity`) above which fit-group says a quantity leans on the
#: prior component scaled. Kallioinen et al. flag 0.05; a pooled correlation reads 0.02-0.16 where the
#: pushes pin it (two heights) and 0.42-1.02 where one push per condition leaves it on its ridge (every stem of
#: the one-height group study; docs/validation.md, "How much of the noise correlation is the prior's")
SENSITIVITY_WARN = 0.3


def prior_sensitivity(draws: dict, log_prior, log_likelihood, delta: float = 0.01) -> dict:
    """Power-scaling sensitivity of each posterior quantity to one prior component and to the likelihood.

    The posterior is reweighted as if the component's density were raised to the power 1 +- ``delta`` (and,
    separately, the likelihood), by Pareto-smoothed importance sampling over the draws, and the change of
    each quantity's distribution measured (cumulative Jensen-Shannon distance per log power):
    ``arviz.psens`` (Kallioinen, Paananen, Buerkner and Vehtari 2023, "Detecting and diagnosing prior and
    likelihood sensitivity with power-scaling"). No refit.

    Parameters
    ----------
    draws : mapping of str to (n,) arrays
        Posterior draws of the quantities, any units.
    log_prior, log_likelihood : (n,) arrays
        Per draw, the log density of the prior component scaled and the whole log likelihood.

    Returns
    -------
    dict
        Per quantity ``{"prior": float, "likelihood": float}``: 0 where scaling leaves it unchanged; a
        quantity with a high prior sensitivity leans on that prior (with a high likelihood sensitivity too,
        the prior and the data pull it apart); one with a low likelihood sensitivity is barely informed.
    """
    az = import_arviz()
    lp = np.asarray(log_prior, float).reshape(1, -1)
    ll = np.asarray(log_likelihood, float).reshape(1, -1)
    if not (np.all(np.isfinite(lp)) and np.all(np.isfinite(ll))):
        raise ValueError("log_prior, log_likelihood: expected finite values at every draw, got -inf or NaN")
    idata = az.from_dict(
        posterior={k: np.asarray(v, float).reshape(1, -1) for k, v in draws.items()}, log_likelihood={"y": ll}
    )
    idata.add_groups(log_prior={"component": lp})
    with np.errstate(over="ignore"):  # the smoothing's exp of large log weights: inf, a weight of 0
        sens = {c: az.psens(idata, component=c, delta=delta) for c in ("prior", "likelihood")}
    return {k: {c: float(sens[c][k]) for c in sens} for k in draws}


def draw_lengths(samples: dict, length_m: float):
    """The stem length per draw, (n, 1), where it was sampled (``length_m``), else the given one (scalar)."""
    L = samples.get("length_m")
    return float(length_m) if L is None else np.asarray(L, float)[:, None]


def ei_band(EI0, p, length_m, s_m) -> dict:
    """90% band and median of EI(s) (eq. EI_taper) over arc lengths ``s_m``: arrays of shape (len(s_m),).

    ``length_m``: a scalar, or one length per draw, shape (n, 1).
    """
    EI = flexural_rigidity(np.asarray(s_m)[None, :], np.asarray(EI0)[:, None], np.asarray(p)[:, None], length_m)
    return quantiles(EI)


def youngs_modulus(samples: dict) -> NDArray:
    """Young's modulus at the base per draw [Pa]: E0 = 64 EI0 / (pi d0^4) (a solid round section).

    Needs a fit with measured diameters (``d0_m`` in ``samples``).
    """
    if "d0_m" not in samples:
        raise ValueError(
            "youngs_modulus: expected a fit with measured diameters (fit(..., diameter='shared' or 'free') on a "
            "dataset with 'diameters'), got a fit without"
        )
    return 64.0 * np.asarray(samples["EI0"], float) / (np.pi * np.asarray(samples["d0_m"], float) ** 4)


def modulus_draws(samples: dict, length_m: float, s_m) -> NDArray:
    """E(s) [Pa] per draw over ``s_m`` (m,), shape (n, m): E0 (1 - s/L)^(4 (p - p_geom)), flat when p_geom = p;
    NaN at and beyond a draw's tip (s >= L: no stem there, and (1 - s/L)^(negative) would read as infinite
    where the length is sampled), which :func:`quantiles` leaves out."""
    E0 = youngs_modulus(samples)[:, None]
    dq = np.asarray(samples["p"], float) - np.asarray(samples.get("p_geom", samples["p"]), float)
    x = 1.0 - np.asarray(s_m, float)[None, :] / draw_lengths(samples, length_m)
    inside = x > 0.0
    return np.where(inside, E0 * np.where(inside, x, 1.0) ** (4.0 * dq[:, None]), np.nan)


def diameter_draws(samples: dict, length_m: float, s_m) -> NDArray:
    """The fitted diameter d(s) = d0 (1 - s/L)^q [m] per draw over ``s_m`` (m,), shape (n, m); q = p_geom
    under the free width model, else p (the width term of docs/inference.md, "Young's modulus")."""
    if "d0_m" not in samples:
        raise ValueError("diameter: expected a fit with measured diameters, got a fit without")
    q = np.asarray(samples.get("p_geom", samples["p"]), float)[:, None]
    d0 = np.asarray(samples["d0_m"], float)[:, None]
    return stem_diameter(np.asarray(s_m, float)[None, :], d0, q, draw_lengths(samples, length_m))


def youngs_modulus_summary(samples: dict, length_m: float, source: str | None = None) -> dict:
    """summary.json ``youngs_modulus`` (docs/format.md): E at the base, and under the free width model the
    modulus taper p - p_geom, the uniform-modulus verdict (0 inside its 90% interval or not) and E(s)."""
    out = {
        "model": "graded" if "p_geom" in samples else "uniform",
        "source": source,
        "E_Pa": credible_interval(youngs_modulus(samples)),
        "d0_m": credible_interval(samples["d0_m"]),
    }
    if "p_geom" in samples:
        dq = np.asarray(samples["p"], float) - np.asarray(samples["p_geom"], float)
        q = credible_interval(dq)
        out["modulus_taper"] = q
        out["uniform_modulus"] = "consistent" if q["q05"] <= 0.0 <= q["q95"] else "rejected"
        s = np.linspace(0.0, 0.9, 10) * float(length_m)
        band = quantiles(modulus_draws(samples, length_m, s))
        out["band"] = {"s_m": s.tolist(), **{k: np.asarray(v).tolist() for k, v in band.items()}}
    return out


def k_theta_band(EI0, p, length_m: float, heights_m, base_compliance=None) -> dict:
    """90% band and median of k_theta(h) (eq. kdist) over ``heights_m``."""
    kb = np.inf if base_compliance is None else np.asarray(base_compliance)[:, None]
    k = k_theta(np.asarray(heights_m)[None, :], np.asarray(EI0)[:, None], np.asarray(p)[:, None], length_m, kb)
    return quantiles(k)


def predictive_forces(
    samples: dict, idx, D, h: float, L: float, effects=None, preload_m=None, height_error_m=None, force_offset_N=None
) -> dict:
    """Force the sensor reads at contact displacements D (m,) for posterior draws ``idx`` (n,).

    Fitted effects in ``samples`` (any catalog name) override the same effect in ``effects``
    draw by draw. ``preload_m`` (n,), optional: each draw's preload of this push, the displacement
    already made when D = 0 (the model is evaluated at D + preload); ``height_error_m`` (n,): each
    draw's contact-height error (evaluated at h + error); ``force_offset_N`` (n,): each draw's
    load-cell offset of this push (added to the force). A sampled ``length_m`` in ``samples`` is used
    draw by draw. Returns ``force_N`` (n, m) with NaN after the slip (as the solver returns it),
    ``slipped`` and ``contact_s_m`` (n, m).
    """
    from ..physics import Effects, force_from_displacement
    from ..physics.effects import EFFECT_NAMES

    base = (effects or Effects()).to_mapping()
    fitted = [k for k in EFFECT_NAMES if k in samples]
    Ls = samples.get("length_m")  # a sampled stem length: one solve per draw
    D = np.asarray(D, float)
    idx = np.asarray(idx)
    EI0, p = np.asarray(samples["EI0"])[idx], np.asarray(samples["p"])[idx]
    d0 = np.zeros(idx.size) if preload_m is None else np.asarray(preload_m, float)
    dh = None if height_error_m is None else np.asarray(height_error_m, float)
    if not fitted and Ls is None and dh is None:
        DD = D[None, :] + d0[:, None]
        sol = force_from_displacement(DD, h, EI0[:, None], p[:, None], L, Effects.from_mapping(base))
        F, slipped, s_c = sol.force_N, sol.slipped, sol.contact_s_m
    else:
        rows = []
        for j, i in enumerate(idx):
            eff = Effects.from_mapping({**base, **{k: float(samples[k][i]) for k in fitted}})
            Lj = L if Ls is None else float(np.asarray(Ls)[i])
            hj = h if dh is None else h + float(dh[j])
            rows.append(force_from_displacement(D + d0[j], hj, EI0[j], p[j], Lj, eff))
        F = np.stack([r.force_N for r in rows])
        slipped = np.stack([r.slipped for r in rows])
        s_c = np.stack([r.contact_s_m for r in rows])
    if force_offset_N is not None:
        F = F + np.asarray(force_offset_N, float)[:, None]
    return {"force_N": F, "slipped": slipped, "contact_s_m": s_c}


def thin(samples: dict, n: int, rng: np.random.Generator) -> dict:
    m = len(next(iter(samples.values())))
    idx = rng.choice(m, size=min(n, m), replace=False)
    return {k: np.asarray(v)[idx] for k, v in samples.items()}


def to_inference_data(chain: np.ndarray, log_prob: np.ndarray, post, spec, attrs: dict):
    """ArviZ InferenceData: posterior in natural units, chains = walkers of all ensembles."""
    az = import_arviz()
    nat = post.to_natural(chain.reshape(-1, post.ndim))
    shape = chain.shape[:2]
    posterior = {k: np.asarray(v).reshape(shape) for k, v in nat.items()}
    idata = az.from_dict(posterior=posterior, sample_stats={"lp": log_prob})
    clean = {k: (v if isinstance(v, (str, int, float)) else str(v)) for k, v in attrs.items()}
    idata.posterior.attrs.update(clean)
    return idata


def build_summary(spec, post, samples: dict, diag: dict, fit_error: dict, effects, extra: dict) -> dict:
    """summary.json (docs/format.md, section 3), plus extensions under their own keys."""
    L = spec.length_m
    params = {name: credible_interval(samples[name]) for name in post.names}
    heights = [p.height_m for p in spec.pushes]
    kb = samples.get("base_compliance")
    kt = k_theta_band(samples["EI0"], samples["p"], draw_lengths(samples, L), heights, kb)
    summary = {
        "specimen": spec.specimen,
        "species": spec.species,
        "length_m": L,
        "effects": list(effects),
        "parameters": params,
        "k_theta": [
            {"height_m": h, "median": float(kt["median"][i]), "q05": float(kt["q05"][i]), "q95": float(kt["q95"][i])}
            for i, h in enumerate(heights)
        ],
        "convergence": {
            "rhat_max": float(max(diag["rhat"].values())),
            "ess_bulk_min": float(min(diag["ess_bulk"].values())),
            **walker_rhat(diag),
            "rhat": diag["rhat"],
            "ess_bulk": diag["ess_bulk"],
        },
        "fit_error": fit_error,
    }
    if "d0_m" in samples:
        dm = spec.diameters
        summary["youngs_modulus"] = youngs_modulus_summary(samples, L, dm.source if dm is not None else None)
    summary.update(extra)
    return summary


def walker_rhat(diag: dict) -> dict:
    """``{"rhat_walkers_max": ..}``, the largest R-hat with every walker as a chain (a mixing measure: about
    sqrt(1 + 2 tau / kept steps); the criterion is ``rhat_max``, each ensemble as a chain), or ``{}`` where the
    diagnostics do not hold it."""
    return {"rhat_walkers_max": float(rhat_walkers_max(diag))} if diag.get("rhat_walkers") else {}

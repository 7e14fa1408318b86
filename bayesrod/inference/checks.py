"""Does the fit fit? Posterior predictive checks of the force residuals (docs/inference.md, "Model check").

A fitted noise model says what the residuals should look like: independent
(``iid``) or AR(1) (``ar1``) noise of the fitted sd. Standardised innovations
(the residuals, whitened by the fitted AR(1) where there is one) are then iid
standard normal if the model is right. Two discrepancies test that, each as a
posterior predictive p-value over posterior draws (replicates drawn from the
model itself):

- lag-1 structure: T = sum over pushes of n_j r1_j^2 (r1_j the lag-1
  autocorrelation of push j's innovations; Box-Pierce at lag 1);
- runs: the longest run of innovations of one sign in any push, over log2(n_j).

The verdict is ``misfit`` when either p-value falls below alpha/2 (alpha = 0.01
by default): a drift, a preload, a softening or any effect the model lacks
leaves long runs and correlated residuals; correlated noise fitted as iid does
too (then refit with AR(1) noise).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def _lag1(z: NDArray) -> NDArray:
    """Lag-1 autocorrelation along the last axis (mean removed); 0 for fewer than 3 samples."""
    z = z - z.mean(axis=-1, keepdims=True)
    den = np.sum(z**2, axis=-1)
    if z.shape[-1] < 3:
        return np.zeros(z.shape[:-1])
    return np.sum(z[..., 1:] * z[..., :-1], axis=-1) / np.where(den > 0, den, 1.0)


def _longest_run(z: NDArray) -> NDArray:
    """Longest run of one sign along the last axis."""
    s = np.sign(z)
    best = np.ones(z.shape[:-1], int)
    cur = np.ones(z.shape[:-1], int)
    for t in range(1, z.shape[-1]):
        cur = np.where(s[..., t] == s[..., t - 1], cur + 1, 1)
        best = np.maximum(best, cur)
    return best


def standardised_innovations(lik, params: dict) -> NDArray:
    """Force residuals whitened by the fitted noise: (W, N), iid N(0, 1) under the model."""
    from .likelihood import ar1_innovations

    r = lik.residuals(params)["force"]
    s = np.atleast_1d(params["sigma_force_N"])[:, None]
    if getattr(lik, "force_noise", "iid") == "ar1":
        e, v = ar1_innovations(r, np.atleast_1d(params["rho_force"])[:, None], lik.F_first)
        return e / (s * np.sqrt(v))
    return r / s


def model_check(lik, samples: dict, *, n_draws: int = 200, alpha: float = 0.01, seed: int = 0) -> dict:
    """The ``model_check`` block of summary.json: per-push residual structure and a verdict.

    Parameters
    ----------
    lik : RodLikelihood
    samples : dict of arrays (n,)
        Posterior draws in natural units.
    """
    if not lik.n_force:
        return {"verdict": "ok", "checked": "nothing (no force samples)", "pushes": []}
    rng = np.random.default_rng(seed)
    n = len(next(iter(samples.values())))
    idx = rng.choice(n, size=min(n_draws, n), replace=False)
    draws = {k: np.asarray(v)[idx] for k, v in samples.items()}
    z = standardised_innovations(lik, draws)  # (K, N)
    med = {k: np.atleast_1d(np.median(v)) for k, v in samples.items()}
    r_med = lik.residuals(med)["force"][0]
    z_med = standardised_innovations(lik, med)[0]
    pushes = []
    T_obs = np.zeros(len(idx))
    R_obs = np.zeros(len(idx))
    T_rep = np.zeros(len(idx))
    R_rep = np.zeros(len(idx))
    zr = rng.standard_normal(z.shape)
    for j, d in enumerate(lik.data):
        sel = lik.F_push == j
        nj = int(sel.sum())
        if nj < 3:
            continue
        zj, zrj = z[:, sel], zr[:, sel]
        T_obs += nj * _lag1(zj) ** 2
        T_rep += nj * _lag1(zrj) ** 2
        scale = np.log2(nj)
        R_obs = np.maximum(R_obs, _longest_run(zj) / scale)
        R_rep = np.maximum(R_rep, _longest_run(zrj) / scale)
        pushes.append(
            {
                "push": d.id,
                "n": nj,
                "residual_lag1": float(_lag1(r_med[sel])),
                "innovation_lag1": float(_lag1(z_med[sel])),
                "longest_run": int(_longest_run(z_med[sel])),
                "rmse_over_sigma": float(np.sqrt(np.mean(z_med[sel] ** 2))),
            }
        )
    p_lag1 = float(np.mean(T_rep >= T_obs))
    p_runs = float(np.mean(R_rep >= R_obs))
    verdict = "misfit" if min(p_lag1, p_runs) < alpha / 2 else "ok"
    out = {
        "verdict": verdict,
        "noise_model": getattr(lik, "force_noise", "iid"),
        "ppc_p_value_lag1": p_lag1,
        "ppc_p_value_runs": p_runs,
        "alpha": alpha,
        "draws": int(len(idx)),
        "pushes": pushes,
    }
    if verdict == "misfit":
        worst = max(pushes, key=lambda q: abs(q["innovation_lag1"]))
        ar = out["noise_model"] == "ar1"
        whitened = f", {worst['innovation_lag1']:.2f} after AR(1) whitening" if ar else ""
        out["message"] = (
            f"the model does not describe these forces: push {worst['push']} leaves structured residuals "
            f"(lag-1 autocorrelation {worst['residual_lag1']:.2f}{whitened}, "
            f"a run of {worst['longest_run']} residuals of one sign; posterior predictive p = "
            f"{min(p_lag1, p_runs):.3g}). Look for what the model misses with `bayesrod diagnose`"
            + ("" if ar else ", or fit correlated noise (force_noise ar1) if the sensor's noise is correlated")
            + "; until then treat the intervals as too narrow."
        )
    return out

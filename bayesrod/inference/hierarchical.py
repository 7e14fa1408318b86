"""Species comparison: a hierarchical model over per-specimen posteriors.

Each specimen j of species g has intrinsic parameters theta_j = (log EI0, p).
The species level is theta_j ~ N(mu_g, diag(tau^2)), with the between-specimen
spread tau shared by all species (3-4 specimens per species cannot pin a
spread each; a shared one borrows strength, and one specimen per species
still gets an interval).

The per-specimen fits are reused instead of refitting everything jointly:
each specimen's posterior is summarised by its mean m_j and covariance S_j
in (log EI0, p). Because those posteriors are orders of magnitude narrower
than the priors they were fitted with (e.g. EI0 +-0.1% against a log-normal
prior of log-sd 1.5), the prior is flat over them and the specimen's
likelihood is, to that accuracy, N(m_j | theta_j, S_j). Integrating theta_j out:

    m_j ~ N(mu_g(j), diag(tau^2) + S_j)

which is sampled with emcee over (mu_g for every species, log tau). The
validity of this reduction (normal, prior-flat posteriors) is checked per
specimen (``check_reduction``) and its calibration over replications is
tested in tests/test_compare.py.

Priors: mu(log EI0) ~ N(0, 5^2) (EI0 from 7e-3 to 1.5e2 N m^2 within 1 sd),
mu(p) ~ N(1, 1.5^2), tau(log EI0) ~ half-normal(0.5) (between-specimen EI0
ratios up to ~3x), tau(p) ~ half-normal(0.3).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

PRIOR_MU = {"mean": np.array([0.0, 1.0]), "sd": np.array([5.0, 1.5])}
PRIOR_TAU_SCALE = np.array([0.5, 0.3])


@dataclass(frozen=True)
class SpecimenPosterior:
    """Posterior draws of one specimen: ``draws`` (n, 2) of (log EI0 [log N m^2], p)."""

    specimen: str
    species: str
    length_m: float
    draws: NDArray

    @property
    def mean(self) -> NDArray:
        return self.draws.mean(axis=0)

    @property
    def cov(self) -> NDArray:
        return np.cov(self.draws.T) + 1e-12 * np.eye(2)


def check_reduction(sp: SpecimenPosterior, prior_sd=(1.5, 0.4)) -> list[str]:
    """Warnings where the normal, prior-flat reduction may not hold for this specimen."""
    out = []
    sd = np.sqrt(np.diag(sp.cov))
    for k, name in enumerate(("log EI0", "p")):
        if sd[k] > 0.3 * prior_sd[k]:
            out.append(f"{sp.specimen}: posterior sd of {name} ({sd[k]:.3g}) is not small against its prior")
        x = sp.draws[:, k]
        skew = float(np.mean(((x - x.mean()) / (x.std() or 1.0)) ** 3))
        if abs(skew) > 1.0:
            out.append(f"{sp.specimen}: posterior of {name} is skewed ({skew:.2f}); the normal summary is rough")
    return out


class HierarchicalPosterior:
    """log_prob(theta) of the species model; theta = [mu_1 (2), ..., mu_G (2), log tau (2)]."""

    def __init__(self, specimens: list[SpecimenPosterior]):
        self.species = sorted({s.species for s in specimens})
        self.group = np.array([self.species.index(s.species) for s in specimens])
        self.m = np.stack([s.mean for s in specimens])  # (J, 2)
        self.S = np.stack([s.cov for s in specimens])  # (J, 2, 2)
        self.G = len(self.species)
        self.ndim = 2 * self.G + 2

    def split(self, theta: NDArray):
        theta = np.atleast_2d(theta)
        mu = theta[:, : 2 * self.G].reshape(-1, self.G, 2)
        log_tau = theta[:, 2 * self.G :]
        return mu, log_tau

    def log_prob(self, theta: NDArray) -> NDArray:
        mu, log_tau = self.split(theta)
        tau = np.exp(log_tau)  # (W, 2)
        lp = -0.5 * np.sum(((mu - PRIOR_MU["mean"]) / PRIOR_MU["sd"]) ** 2, axis=(1, 2))
        lp += np.sum(-0.5 * (tau / PRIOR_TAU_SCALE) ** 2 + log_tau, axis=1)  # half-normal, Jacobian of log
        C = self.S[None, :, :, :] + np.einsum("wk,kl->wkl", tau**2, np.eye(2))[:, None, :, :]  # (W, J, 2, 2)
        r = self.m[None, :, :] - mu[:, self.group, :]  # (W, J, 2)
        det = C[..., 0, 0] * C[..., 1, 1] - C[..., 0, 1] * C[..., 1, 0]
        inv00, inv11, inv01 = C[..., 1, 1] / det, C[..., 0, 0] / det, -C[..., 0, 1] / det
        quad = r[..., 0] ** 2 * inv00 + r[..., 1] ** 2 * inv11 + 2 * r[..., 0] * r[..., 1] * inv01
        lp += np.sum(-0.5 * quad - 0.5 * np.log(det), axis=1)
        out = np.where(np.isfinite(lp), lp, -np.inf)
        return out if np.ndim(theta) == 2 else float(out[0])


def sample_species(specimens: list[SpecimenPosterior], *, seed: int = 0, n_steps: int = 3000, progress=False):
    """emcee draws of the species model: dict with ``mu`` (n, G, 2), ``tau`` (n, 2), ``species``, diagnostics."""
    import emcee

    from .summary import import_arviz

    post = HierarchicalPosterior(specimens)
    rng = np.random.default_rng(seed)
    start = np.concatenate(
        [np.concatenate([post.m[post.group == g].mean(axis=0) for g in range(post.G)]), np.log(PRIOR_TAU_SCALE / 2)]
    )
    n_walkers = max(32, 4 * post.ndim)
    chains = []
    for _ in range(4):  # independent ensembles for R-hat
        p0 = start + 1e-3 * rng.standard_normal((n_walkers, post.ndim))
        s = emcee.EnsembleSampler(
            n_walkers,
            post.ndim,
            post.log_prob,
            vectorize=True,
            moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)],
        )
        s.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
        s.run_mcmc(p0, n_steps, progress=progress)
        chains.append(s.get_chain(discard=n_steps // 2, thin=5))  # (n, W, ndim)
    chain = np.concatenate([c.reshape(-1, post.ndim) for c in chains])
    az = import_arviz()
    per_ens = np.stack([c.reshape(-1, post.ndim) for c in chains])  # (4, n, ndim)
    idata = az.from_dict(posterior={"theta": per_ens})
    rhat = float(np.max(az.rhat(idata)["theta"].values))
    ess = float(np.min(az.ess(idata, method="bulk")["theta"].values))
    mu, log_tau = post.split(chain)
    return {"mu": mu, "tau": np.exp(log_tau), "species": post.species, "rhat_max": rhat, "ess_bulk_min": ess}


def _q(x) -> dict:
    q05, q50, q95 = np.quantile(x, [0.05, 0.5, 0.95])
    return {"median": float(q50), "q05": float(q05), "q95": float(q95)}


def contrasts(fit: dict, specimens: list[SpecimenPosterior], height_m: float | None = None) -> list[dict]:
    """Every pair of species: EI0 ratio, p (ratio and difference), k_theta ratio at ``height_m``."""
    from ..physics import k_theta

    sp = fit["species"]
    mu = fit["mu"]
    out = []
    lengths = {s: float(np.mean([x.length_m for x in specimens if x.species == s])) for s in sp}
    for ia, ib in combinations(range(len(sp)), 2):
        a, b = sp[ia], sp[ib]
        dlog = mu[:, ia, 0] - mu[:, ib, 0]
        r = _q(np.exp(dlog))
        out.append(
            {
                "a": a,
                "b": b,
                "parameter": "EI0",
                "ratio_median": r["median"],
                "ratio_q05": r["q05"],
                "ratio_q95": r["q95"],
                "prob_a_greater": float(np.mean(dlog > 0)),
            }
        )
        dp = mu[:, ia, 1] - mu[:, ib, 1]
        rp = _q(mu[:, ia, 1] / np.where(mu[:, ib, 1] == 0, np.nan, mu[:, ib, 1]))
        d = _q(dp)
        out.append(
            {
                "a": a,
                "b": b,
                "parameter": "p",
                "ratio_median": rp["median"],
                "ratio_q05": rp["q05"],
                "ratio_q95": rp["q95"],
                "difference_median": d["median"],
                "difference_q05": d["q05"],
                "difference_q95": d["q95"],
                "prob_a_greater": float(np.mean(dp > 0)),
            }
        )
        if height_m is not None and height_m < min(lengths[a], lengths[b]):
            ka = k_theta(height_m, np.exp(mu[:, ia, 0]), np.clip(mu[:, ia, 1], 0, None), lengths[a])
            kb = k_theta(height_m, np.exp(mu[:, ib, 0]), np.clip(mu[:, ib, 1], 0, None), lengths[b])
            rk = _q(ka / kb)
            out.append(
                {
                    "a": a,
                    "b": b,
                    "parameter": "k_theta",
                    "height_m": float(height_m),
                    "ratio_median": rk["median"],
                    "ratio_q05": rk["q05"],
                    "ratio_q95": rk["q95"],
                    "prob_a_greater": float(np.mean(ka > kb)),
                }
            )
    return out

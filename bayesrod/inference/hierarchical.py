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

import warnings
from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from .summary import credible_interval

PRIOR_MU = {"mean": np.array([0.0, 1.0]), "sd": np.array([5.0, 1.5])}
PRIOR_TAU_SCALE = np.array([0.5, 0.3])
#: the species model of log Young's modulus [log Pa] (``compare`` when every fit has diameters):
#: mu ~ N(log 3 GPa, 3^2) (0.15-60 GPa within 1 sd), tau ~ half-normal(0.5)
PRIOR_LOG_E = {"mean": np.array([np.log(3e9)]), "sd": np.array([3.0]), "tau_scale": np.array([0.5])}
#: the species model of a base compliance [rad/(N m)] per condition (``compare`` over stems fitted under
#: several conditions): mu ~ N(0, 1^2) (compliances up to 1 rad/(N m), a base spring of 1 N m/rad, within
#: 1 sd), tau ~ half-normal(0.1 rad/(N m))
PRIOR_COMPLIANCE = {"mean": np.array([0.0]), "sd": np.array([1.0]), "tau_scale": np.array([0.1])}


@dataclass(frozen=True)
class SpecimenPosterior:
    """Posterior draws of one specimen: ``draws`` (n, D), by default D = 2: (log EI0 [log N m^2], p);
    (n, 1) of log E [log Pa] for the modulus model."""

    specimen: str
    species: str
    length_m: float
    draws: NDArray

    @property
    def mean(self) -> NDArray:
        return self.draws.mean(axis=0)

    @property
    def cov(self) -> NDArray:
        D = self.draws.shape[1]
        return np.atleast_2d(np.cov(self.draws.T)) + 1e-12 * np.eye(D)


def check_reduction(sp: SpecimenPosterior, prior_sd=(1.5, 0.4), names=("log EI0", "p")) -> list[str]:
    """Warnings where the normal, prior-flat reduction may not hold for this specimen."""
    out = []
    sd = np.sqrt(np.diag(sp.cov))
    for k, name in enumerate(names):
        if sd[k] > 0.3 * prior_sd[k]:
            out.append(f"{sp.specimen}: posterior sd of {name} ({sd[k]:.3g}) is not small against its prior")
        x = sp.draws[:, k]
        skew = float(np.mean(((x - x.mean()) / (x.std() or 1.0)) ** 3))
        if abs(skew) > 1.0:
            out.append(f"{sp.specimen}: posterior of {name} is skewed ({skew:.2f}); the normal summary is rough")
    return out


class HierarchicalPosterior:
    """log_prob(theta) of the species model; theta = [mu_1 (D), ..., mu_G (D), log tau (D)].

    ``prior`` holds ``mean``, ``sd`` (D,) of mu and ``tau_scale`` (D,); default: (log EI0, p) with
    :data:`PRIOR_MU` and :data:`PRIOR_TAU_SCALE`.
    """

    def __init__(self, specimens: list[SpecimenPosterior], prior: dict | None = None):
        self.species = sorted({s.species for s in specimens})
        self.group = np.array([self.species.index(s.species) for s in specimens])
        self.m = np.stack([s.mean for s in specimens])  # (J, D)
        self.S = np.stack([s.cov for s in specimens])  # (J, D, D)
        self.D = self.m.shape[1]
        prior = prior or {**PRIOR_MU, "tau_scale": PRIOR_TAU_SCALE}
        self.prior_mean, self.prior_sd, self.tau_scale = (
            np.asarray(prior[k], float) for k in ("mean", "sd", "tau_scale")
        )
        if not self.prior_mean.shape == self.prior_sd.shape == self.tau_scale.shape == (self.D,):
            raise ValueError(f"prior: expected mean, sd and tau_scale of length {self.D}, got {prior}")
        self.G = len(self.species)
        self.ndim = self.D * self.G + self.D

    def split(self, theta: NDArray):
        theta = np.atleast_2d(theta)
        mu = theta[:, : self.D * self.G].reshape(-1, self.G, self.D)
        log_tau = theta[:, self.D * self.G :]
        return mu, log_tau

    def log_prob(self, theta: NDArray) -> NDArray:
        mu, log_tau = self.split(theta)
        tau = np.exp(log_tau)  # (W, D)
        lp = -0.5 * np.sum(((mu - self.prior_mean) / self.prior_sd) ** 2, axis=(1, 2))
        lp += np.sum(-0.5 * (tau / self.tau_scale) ** 2 + log_tau, axis=1)  # half-normal, Jacobian of log
        C = self.S[None] + np.einsum("wk,kl->wkl", tau**2, np.eye(self.D))[:, None, :, :]  # (W, J, D, D)
        r = self.m[None, :, :] - mu[:, self.group, :]  # (W, J, D)
        sign, logdet = np.linalg.slogdet(C)
        quad = np.einsum("wjk,wjk->wj", r, np.linalg.solve(C, r[..., None])[..., 0])
        lp += np.sum(-0.5 * quad - 0.5 * logdet, axis=1)
        lp = np.where(np.all(sign > 0, axis=1), lp, -np.inf)
        out = np.where(np.isfinite(lp), lp, -np.inf)
        return out if np.ndim(theta) == 2 else float(out[0])


def sample_species(
    specimens: list[SpecimenPosterior],
    *,
    seed: int = 0,
    n_steps: int = 3000,
    min_steps: int = 1000,
    chunk: int = 500,
    target_ess: float = 1000.0,
    target_rhat: float = 1.01,
    progress=False,
    prior: dict | None = None,
):
    """emcee draws of the species model: dict with ``mu`` (n, G, D), ``tau`` (n, D), ``species``, diagnostics.

    Four independent ensembles run ``min_steps`` steps, then ``chunk`` more at a time until the second
    halves (the draws kept) agree (R-hat <= ``target_rhat``), hold ``target_ess`` effective draws of every
    parameter and span 50 autocorrelation times, or ``n_steps`` is reached (with ``n_steps <= min_steps``:
    exactly ``n_steps``). ``prior``: see :class:`HierarchicalPosterior` (default: the (log EI0, p) model).
    """
    import emcee

    from .moves import default_moves
    from .summary import import_arviz

    post = HierarchicalPosterior(specimens, prior)
    rng = np.random.default_rng(seed)
    start = np.concatenate(
        [np.concatenate([post.m[post.group == g].mean(axis=0) for g in range(post.G)]), np.log(post.tau_scale / 2)]
    )
    n_walkers = max(32, 4 * post.ndim)
    samplers, states = [], []
    for _ in range(4):  # independent ensembles for R-hat
        states.append(start + 1e-3 * rng.standard_normal((n_walkers, post.ndim)))
        s = emcee.EnsembleSampler(
            n_walkers,
            post.ndim,
            post.log_prob,
            vectorize=True,
            moves=default_moves(),  # emcee's own snooker move is biased (inference/moves.py)
        )
        s.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
        samplers.append(s)
    az = import_arviz()
    done = 0
    while True:
        todo = min(max(min_steps - done, chunk), n_steps - done)
        for k, s in enumerate(samplers):
            states[k] = s.run_mcmc(states[k], todo, progress=progress)
        done += todo
        chains = [s.get_chain(discard=done // 2, thin=5) for s in samplers]  # (n, W, ndim)
        per_ens = np.stack([c.reshape(-1, post.ndim) for c in chains])  # (4, n, ndim)
        idata = az.from_dict(posterior={"theta": per_ens})
        rhat = float(np.max(az.rhat(idata)["theta"].values))
        ess = float(np.min(az.ess(idata, method="bulk")["theta"].values))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tau = max(float(np.nanmax(s.get_autocorr_time(discard=done // 2, tol=0))) for s in samplers)
        if done >= n_steps or (rhat <= target_rhat and ess >= target_ess and done >= 50 * tau):
            break
    chain = np.concatenate([c.reshape(-1, post.ndim) for c in chains])
    mu, log_tau = post.split(chain)
    return {
        "mu": mu,
        "tau": np.exp(log_tau),
        "species": post.species,
        "rhat_max": rhat,
        "ess_bulk_min": ess,
        "autocorr_time_max": tau,
        "n_steps": done,
    }


def modulus_contrasts(fit: dict) -> list[dict]:
    """Every pair of species of a log-E species model (:data:`PRIOR_LOG_E`): the ratio of their
    typical Young's moduli E_a / E_b and P(E_a > E_b)."""
    sp, mu = fit["species"], fit["mu"]
    return [
        _log_ratio_contrast(sp[ia], sp[ib], "E", mu[:, ia, 0] - mu[:, ib, 0])
        for ia, ib in combinations(range(len(sp)), 2)
    ]


def _log_ratio_contrast(a: str, b: str, parameter: str, dlog: NDArray) -> dict:
    """A contrast of compare.json from draws of log(a's value) - log(b's): the ratio a / b and P(a > b)."""
    r = credible_interval(np.exp(dlog))
    return {
        "a": a,
        "b": b,
        "parameter": parameter,
        "ratio_median": r["median"],
        "ratio_q05": r["q05"],
        "ratio_q95": r["q95"],
        "prob_a_greater": float(np.mean(dlog > 0)),
    }


def contrasts(fit: dict, specimens: list[SpecimenPosterior], height_m: float | None = None) -> list[dict]:
    """Every pair of species: EI0 ratio, p (ratio and difference), k_theta ratio at ``height_m``."""
    from ..physics import k_theta

    sp = fit["species"]
    mu = fit["mu"]
    out = []
    lengths = {s: float(np.mean([x.length_m for x in specimens if x.species == s])) for s in sp}
    for ia, ib in combinations(range(len(sp)), 2):
        a, b = sp[ia], sp[ib]
        out.append(_log_ratio_contrast(a, b, "EI0", mu[:, ia, 0] - mu[:, ib, 0]))
        dp = mu[:, ia, 1] - mu[:, ib, 1]
        rp = credible_interval(mu[:, ia, 1] / np.where(mu[:, ib, 1] == 0, np.nan, mu[:, ib, 1]))
        d = credible_interval(dp)
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
            rk = credible_interval(ka / kb)
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

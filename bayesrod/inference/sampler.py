"""Sampling: start point, independent emcee ensembles with an HDF5 backend, diagnostics.

emcee only ever sees ``log_prob`` (vectorised over walkers). Several ensembles
are started independently so that R-hat (ArviZ, each ensemble as a chain) is
meaningful; runs extend in chunks until the
targets are met or the step budget is spent, and resume from the HDF5 file
after an interruption.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from .likelihood import force_scale_fit, scale_fit_rows


class CheckpointBackend:
    """emcee's in-memory backend, checkpointed to an HDF5 group every ``flush_every`` steps.

    emcee's own HDFBackend writes every step (about 2 ms each here); this
    keeps the chain in memory and rewrites the group periodically, so an
    interrupted run loses at most ``flush_every`` steps and resumes with
    ``sampler.run_mcmc(None, n)``.
    """

    def __new__(cls, path: Path, name: str, flush_every: int = 200):
        import emcee

        class _Backend(emcee.backends.Backend):
            def save_step(self, state, accepted):
                super().save_step(state, accepted)
                if self.iteration % flush_every == 0:
                    self.flush()

            def flush(self):
                import h5py

                if not self.initialized or self.iteration == 0:
                    return
                with h5py.File(path, "a") as f:
                    if name in f:
                        del f[name]
                    g = f.create_group(name)
                    g.create_dataset("chain", data=self.chain[: self.iteration])
                    g.create_dataset("log_prob", data=self.log_prob[: self.iteration])
                    g.create_dataset("accepted", data=self.accepted)
                    kind, key, pos, has_gauss, cached = self.random_state
                    g.create_dataset("rng_key", data=key)
                    g.attrs.update(rng_kind=kind, rng_pos=pos, rng_has_gauss=has_gauss, rng_cached=cached)

            def load(self, nwalkers, ndim) -> bool:
                import h5py

                if not Path(path).is_file():
                    return False
                with h5py.File(path, "r") as f:
                    if name not in f or f[name]["chain"].shape[1:] != (nwalkers, ndim):
                        return False
                    g = f[name]
                    self.reset(nwalkers, ndim)
                    self.chain = g["chain"][()]
                    self.log_prob = g["log_prob"][()]
                    self.accepted = g["accepted"][()]
                    self.iteration = self.chain.shape[0]
                    a = g.attrs
                    self.random_state = (
                        str(a["rng_kind"]),
                        g["rng_key"][()],
                        int(a["rng_pos"]),
                        int(a["rng_has_gauss"]),
                        float(a["rng_cached"]),
                    )
                return True

        return _Backend()


def find_start(post, rng: np.random.Generator, init: dict | None = None) -> np.ndarray:
    """A high-posterior starting point: grid over p, closed-form EI0 on forces, then Nelder-Mead.

    EI0 is a pure scale of the forces, so for each p of the likelihood's grid
    its least-squares value is closed form (``force_scale_fit``). ``init``
    (e.g. the seed's two-stage estimate, ``{"EI0": .., "p": ..}``) is tried too.
    These candidates hold every effect at its neutral value; a tabled effect is then profiled over its axis
    (:func:`_profile_effect`) and each push's preload over its prior (:func:`_profile_preloads`), before
    the polish.
    """
    lik = post.likelihood
    best, best_lp = None, -np.inf
    names = post.names
    candidates = [(float(p), None) for p in lik.p_grid[1:-1]]
    if init and np.isfinite(init.get("p", np.nan)) and np.isfinite(init.get("EI0", np.nan)):
        candidates.append((float(np.clip(init["p"], lik.p_grid[1], lik.p_grid[-2])), float(init["EI0"])))
    for p, EI0_init in candidates:
        nat = {}
        if lik.n_force:  # with preloads: the scale fit at zero preload, then _profile_preloads
            EI0, rms = force_scale_fit(lik, p, EI0_init)
            EI0 = max(EI0, 1e-6) if np.isfinite(EI0) else 1.0
            nat["sigma_force_N"] = max(rms, 1e-4)
        else:
            EI0 = EI0_init if EI0_init is not None else post.priors[0].quantile(0.5)
        nat.update(EI0=EI0, p=p)
        if lik.n_points:
            nat.update({k: float(v[0]) for k, v in _shape_noise(lik, np.array([p])).items()})
        if lik.diameter != "off":  # the width term: closed-form d0 at this taper
            nat.update(lik.diameter_start(p))
        for n, pr in zip(names, post.priors, strict=True):
            if n not in nat:
                # effects start near their neutral value: a stiff base, a late yield
                q = {"base_compliance": 0.99, "yield": 0.99}.get(n, 0.02 if n.startswith("preload_m_") else 0.5)
                nat[n] = lik.L if n == "length_m" else pr.quantile(q)  # the given length, else the median
        theta = post.to_sample(nat)[0]
        lp = post.log_prob(theta)
        if lp > best_lp:
            best, best_lp = theta, lp
    if best is None:
        raise ValueError("fit: expected a starting point with finite posterior density, found none on the p grid")
    if getattr(lik, "axis", None) is not None:
        best, best_lp = _profile_effect(post, best, best_lp)
    if getattr(lik, "preload", False) and lik.preload_names:
        best, best_lp = _profile_preloads(post, best, best_lp)
    res = minimize(
        lambda t: -post.log_prob(t), best, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-6, "fatol": 1e-6}
    )
    return res.x if np.isfinite(res.fun) and -res.fun >= best_lp else best


def _scale_and_noise(g: NDArray, F: NDArray, fallback: float) -> tuple[NDArray, NDArray]:
    """EI0 [N m^2] and the force noise [N] (G,) that fit forces ``F`` (N,) [N] best for unit-EI0 predictions
    ``g`` (G, N): the least-squares scale (``fallback`` where a row predicts no force), floored at 1e-6, and
    the RMS residual at it, floored at 1e-4 N."""
    EI0, _ = scale_fit_rows(g, F)
    EI0 = np.maximum(np.where(np.isfinite(EI0), EI0, fallback), 1e-6)
    _, rms = scale_fit_rows(g, F, EI0)
    return EI0, np.maximum(rms, 1e-4)


def _shape_noise(lik, p: NDArray, u: NDArray | None = None) -> dict:
    """The centerline noise that fits the shapes at taper exponents ``p`` (G,) (and effect coordinates ``u``):
    the RMS offset of every point, as ``sigma_shape_m`` [m] or, where the points carry their own sd, as
    ``shape_sd_scale`` (RMS offset over RMS sd); each (G,), floored at 1e-5 m and 1e-3."""
    rms = np.sqrt(np.mean(lik.shape_offsets(p, u) ** 2, axis=1))
    if lik.shape_has_sd:
        return {"shape_sd_scale": np.maximum(rms / float(np.sqrt(np.mean(lik.sd_obs**2))), 1e-3)}
    return {"sigma_shape_m": np.maximum(rms, 1e-5)}


def _profile_effect(post, theta: NDArray, lp: float, n_grid: int = 25) -> tuple:
    """The tabled effect on ``n_grid`` coordinates inside its axis, jointly with p on the likelihood's inner
    p nodes, EI0 and the noise refitted in closed form at every node (at fixed p and u the forces are a pure
    scale of EI0); the best point, where it beats ``lp``.

    :func:`find_start`'s p candidates hold every effect at its neutral value (no friction, a stiff base), where
    a strong one leaves the plain rod no fit: on a twig on a soft base (u 0.5, forces only) the polished start
    sat 248 nats below the mode (EI0 0.46 for 2.63, p 0; docs/validation.md, "Session 70"); on friction SBC
    seed 7 (mu 0.51, three heights, centerlines) in the mode where the forces are all noise (force noise 3.6 N
    for 0.054, mu 1e-5), where the table check that decides the effect axis's zoom then read ("Session 69").
    """
    lik = post.likelihood
    nat = {k: float(v[0]) for k, v in post.to_natural(theta[None]).items()}
    us = np.linspace(lik.axis.grid[0], lik.axis.grid[-1], n_grid + 2)[1:-1]  # inside: a clamp's u = 0 is k = inf
    best = None
    for p in lik.p_grid[1:-1]:
        rows = {k: np.full(n_grid, v) for k, v in nat.items()}
        rows["p"] = np.full(n_grid, p)
        if lik.n_force:
            g = lik.predict_nd_force(rows["p"], us) / lik.L**2
            rows["EI0"], rows["sigma_force_N"] = _scale_and_noise(g, lik.F_obs, nat["EI0"])
        if lik.n_points:
            rows.update(_shape_noise(lik, rows["p"], us))
        rows[lik.axis.name] = lik.axis.value(us, rows["EI0"], lik.L)
        thetas = post.to_sample(rows)
        with np.errstate(all="ignore"):
            lps = np.asarray(post.log_prob(thetas), float)
        lps = np.where(np.isfinite(lps), lps, -np.inf)
        k = int(np.argmax(lps))
        if lps[k] > lp:
            lp, best = float(lps[k]), thetas[k]
    return (theta, lp) if best is None else (best, lp)


def _profile_preloads(post, theta: np.ndarray, lp: float, n_grid: int = 81, sweeps: int = 2) -> tuple:
    """Each push's preload on a grid over its prior, EI0 and the force noise refitted in closed form at
    every node (the force scale fit at those preloads), two sweeps over the pushes; the best point.

    Without it the search started every preload near zero and Nelder-Mead, moving the preloads to where
    the centerlines put them, left EI0 in the mode where the forces are all noise (EI0 0.015 for 2.63,
    a force noise of 6 N: six of 112 walkers never left it).
    """
    lik = post.likelihood
    nat = {k: float(v[0]) for k, v in post.to_natural(theta[None]).items()}
    for _ in range(sweeps):
        for n in lik.preload_names:
            lo, hi = post.priors[post.names.index(n)].bounds()
            grid = np.linspace(lo, hi, n_grid)
            rows = {k: np.full(n_grid, v) for k, v in nat.items()}
            rows[n] = grid
            if lik.n_force:
                pre = lik._per_push(rows, lik.preload_names, n_grid)
                g = lik.predict_nd_force_preloaded(np.full(n_grid, nat["p"]), pre) / lik.L**2  # (G, N)
                rows["EI0"], rows["sigma_force_N"] = _scale_and_noise(g, lik.F_obs, nat["EI0"])
            lps = np.asarray(post.log_prob(post.to_sample(rows)))
            k = int(np.argmax(lps))
            if lps[k] > lp:
                lp = float(lps[k])
                nat = {key: float(v[k]) for key, v in rows.items()}
    return post.to_sample(nat)[0], lp


@dataclass
class SamplingResult:
    """Chains of all ensembles after burn-in: ``chain`` (n_chains, n_draws, ndim), ``log_prob`` (n_chains, n_draws)."""

    chain: np.ndarray
    log_prob: np.ndarray
    n_steps: int
    burn: int
    tau: np.ndarray
    acceptance: float
    n_ensembles: int = 1
    diagnostics: dict | None = None
    converged: bool = True  # False: the step budget was spent before the targets were met
    #: per ensemble, how many walkers :func:`replace_stuck_walkers` moved after the first stretch (0: none)
    walkers_restarted: tuple = ()


#: R-hat over walkers (every walker a chain) above which walkers disagree: at emcee's 50 autocorrelation
#: times walkers that mix alike read about 1.03 (:func:`diagnostics`); Gelman and Rubin's original 1.1
WALKER_RHAT_MAX = 1.1


def rhat_walkers_max(diag: dict) -> float:
    """The largest R-hat over walkers in :func:`diagnostics`' output; 1.0 where it holds none."""
    return max(diag.get("rhat_walkers", {"": 1.0}).values())


def missed_targets(
    diag: dict, n_steps: int, tau: NDArray, target_ess: float, target_rhat: float, targeted, n_stuck: int = 0
) -> list[str]:
    """The convergence targets a run has not met, one phrase each; empty when it has met them all.

    The targets: R-hat <= ``target_rhat`` with each ensemble as a chain (independent ensembles agree and the
    run's halves too), R-hat over walkers <= :data:`WALKER_RHAT_MAX` (no walker apart from the rest), bulk
    ESS >= ``target_ess`` for each parameter in ``targeted``, the run at least 50 autocorrelation times
    long (emcee's rule; ``tau`` the largest over ensembles per parameter), and no walker stuck in a far worse
    region at the end (``n_stuck``, :func:`stuck_walkers` over the kept steps).
    """
    out = []
    rhat = max(diag["rhat"].values())
    if not rhat <= target_rhat:
        out.append(f"R-hat max {rhat:.4f} with the ensembles as chains, target {target_rhat:g}")
    rw = rhat_walkers_max(diag)
    if not rw <= WALKER_RHAT_MAX:
        out.append(f"R-hat over walkers {rw:.3f}, above {WALKER_RHAT_MAX:g}: walkers disagree")
    ess = min(diag["ess_bulk"][n] for n in targeted)
    if not ess >= target_ess:
        out.append(f"bulk ESS of {' and '.join(targeted)} {ess:.0f}, target {target_ess:g}")
    t = float(np.nanmax(tau))
    if not n_steps >= 50 * t:
        out.append(f"{n_steps} steps, fewer than 50 autocorrelation times ({50 * t:.0f})")
    if n_stuck:
        out.append(f"{n_stuck} walker(s) stuck in a far worse region")
    return out


def convergence_message(
    res: SamplingResult, max_steps: int, target_ess: float, target_rhat: float = 1.01
) -> str | None:
    """None when the run met its targets (:func:`missed_targets`); else one line for the user: what was missed
    and what to do, with the steps the targets need at this run's rate (:func:`steps_needed`)."""
    if res.converged or res.diagnostics is None:
        return None
    diag = res.diagnostics
    targeted = list(diag["ess_bulk"])[:2]  # run_ensembles' ESS target: the first two parameters
    missed = missed_targets(diag, res.n_steps, res.tau, target_ess, target_rhat, targeted, count_stuck(res))
    ess = min(diag["ess_bulk"][n] for n in targeted)
    rhat, rw = max(diag["rhat"].values()), rhat_walkers_max(diag)
    need = steps_needed(res.n_steps, rhat, ess, float(np.nanmax(res.tau)), target_rhat, target_ess, rw)
    unmet = f"R-hat target {target_rhat:g}, bulk ESS target {target_ess:g}"  # a run stopped short with none missed
    return (
        f"not converged within {max_steps} steps ({'; '.join(missed) or unmet}): treat the intervals "
        f"as provisional and rerun with more steps (at this run's rate, at least about {need} in all)"
    )


def steps_needed(
    n_steps: int,
    rhat: float,
    ess: float,
    tau: float,
    target_rhat: float = 1.01,
    target_ess: float = 1000.0,
    rhat_walkers: float = 1.0,
) -> int:
    """Steps a run needs to meet its targets at the rate it mixed so far, rounded up to 1000: a lower bound.

    R-hat^2 - 1 falls as 1 / steps, both with the ensembles as chains (``rhat``: the variance of their means)
    and with the walkers as chains (``rhat_walkers``: about 2 tau / kept steps for walkers that each mix with
    autocorrelation time tau; 224 simulated AR(1) walkers: 1.036 at tau 150 and 4000 kept steps, predicted
    1.037; docs/validation.md, "What R-hat over walkers measures"); bulk ESS grows as steps; emcee's own rule
    asks for 50 tau. Where tau itself was underestimated (a slow direction the
    run has not yet crossed often) the run needs more than this.
    """
    need = [50.0 * tau if np.isfinite(tau) else 0.0]
    for r, target in ((rhat, target_rhat), (rhat_walkers, WALKER_RHAT_MAX)):
        if np.isfinite(r) and r > target:
            need.append(n_steps * (r**2 - 1.0) / (target**2 - 1.0))
    if np.isfinite(ess) and 0 < ess < target_ess:
        need.append(n_steps * target_ess / ess)
    return int(1000 * np.ceil(max(max(need), n_steps + 1) / 1000))


def stuck_walkers(log_prob: NDArray, ndim: int, p_miss: float = 1e-6) -> NDArray:
    """Which walkers sit in a far worse region: mean log density over the second half of the steps below the
    walkers' median by more than half the ``1 - p_miss`` quantile of chi-square(ndim) (NaN counts as stuck).

    Parameters
    ----------
    log_prob : ndarray, shape (n_steps, n_walkers)
    ndim : int

    Returns
    -------
    ndarray of bool, shape (n_walkers,)
    """
    from scipy.stats import chi2

    mean_lp = np.mean(log_prob[log_prob.shape[0] // 2 :], axis=0)
    return ~(mean_lp >= np.median(mean_lp) - 0.5 * chi2.ppf(1.0 - p_miss, ndim))


def replace_stuck_walkers(
    chain: NDArray, log_prob: NDArray, rng, p_miss: float = 1e-6, log_prob_fn=None
) -> NDArray | None:
    """Walkers left in a far worse region after burn-in, moved onto the others (Hou, Goodman & Hogg 2012).

    An affine-invariant ensemble cannot pull back a walker that sits in a separate, much lower
    optimum: the stretch move proposes along lines through the others' positions and every such
    proposal lands in a valley. On a replicate of the group study 12 of 224 walkers stayed 172 nats
    below the rest for 5000 steps, which put a second mode into the 90% interval of EI0 (q05 2.998
    against a median of 3.71) and R-hat at 1.29.

    Parameters
    ----------
    chain : ndarray, shape (n_steps, n_walkers, ndim)
        The ensemble's positions so far (emcee's ``get_chain()``).
    log_prob : ndarray, shape (n_steps, n_walkers)
    rng : numpy.random.Generator
    p_miss : float
        A walker is stuck when its mean log density over the second half of the steps is below the
        walkers' median by more than half the ``1 - p_miss`` quantile of a chi-square with ndim degrees
        of freedom: the drop of a single draw from a Gaussian posterior's mode would exceed that with
        probability ``p_miss``; a mean over many steps almost never.
    log_prob_fn : callable or None
        The posterior's vectorised log density: a nudge it puts outside the support (a donor on a boundary)
        leaves the walker on its donor instead (emcee would start it at -inf, and warn of inf - inf).

    Returns
    -------
    ndarray, shape (n_walkers, ndim), or None
        The last positions with every stuck walker replaced by another walker's (chosen at random
        among the rest, nudged by 1e-3 of the ensemble's spread); None when no walker is stuck.
    """
    n_steps, n_walkers, ndim = chain.shape
    stuck = stuck_walkers(log_prob, ndim, p_miss)
    if not stuck.any() or stuck.all():
        return None
    last = chain[-1].copy()
    good = np.flatnonzero(~stuck)
    spread = np.std(last[good], axis=0)
    donors = rng.choice(good, size=int(stuck.sum()))
    last[stuck] = last[donors] + 1e-3 * spread * rng.standard_normal((donors.size, ndim))
    if log_prob_fn is not None:
        moved = np.flatnonzero(stuck)
        outside = ~np.isfinite(np.asarray(log_prob_fn(last[moved]), float))
        last[moved[outside]] = chain[-1][donors[outside]]
    return last


def _ball(theta0, n, rng, post):
    """``n`` walkers about ``theta0``, each nudged by N(0, 1e-3) per coordinate and drawn again (up to 100 times)
    while outside the support; a walker still outside starts on ``theta0`` itself. (Where the start sits on a
    boundary in several coordinates, as a group fit's clamps can, most nudges leave the support: one of 56
    walkers of a four-condition fit stayed at -inf, and emcee warned of inf - inf at every step; session 50.)"""
    scale = np.full(theta0.size, 1e-3)
    out = theta0 + scale * rng.standard_normal((n, theta0.size))
    for i in range(n):
        tries = 0
        while not (inside := np.isfinite(post.log_prob(out[i]))) and tries < 100:
            out[i] = theta0 + scale * rng.standard_normal(theta0.size)
            tries += 1
        if not inside:
            out[i] = theta0
    return out


def ensemble_seeds(seed: int, n_ensembles: int) -> list[int]:
    """The seed of each ensemble's random state: distinct for the ensembles of one run, in [0, 2**32)."""
    return [(seed * 7919 + k) % 2**32 for k in range(n_ensembles)]


def run_ensembles(
    post,
    theta0,
    *,
    n_ensembles=4,
    n_walkers=None,
    chunk=500,
    max_steps=8000,
    min_steps=1000,
    target_ess=1000.0,
    target_rhat=1.01,
    seed=0,
    backend_path: Path | None = None,
    progress=True,
) -> SamplingResult:
    """Run independent ensembles until bulk ESS >= target and R-hat <= target (or max_steps)."""
    import emcee

    from .moves import default_moves

    ndim = post.ndim
    n_walkers = n_walkers or max(16, 4 * ndim)
    rng = np.random.default_rng(seed)
    samplers = []
    for k in range(n_ensembles):
        backend = None
        if backend_path is not None:
            backend = CheckpointBackend(Path(backend_path), f"ensemble{k}")
            if not backend.load(n_walkers, ndim):
                backend.reset(n_walkers, ndim)
        s = emcee.EnsembleSampler(
            n_walkers,
            ndim,
            post.log_prob,
            vectorize=True,
            backend=backend,
            moves=default_moves(),  # emcee's own snooker move is biased (inference/moves.py)
        )
        samplers.append(s)
    for s, k_seed in zip(samplers, ensemble_seeds(seed, n_ensembles), strict=True):
        s.random_state = np.random.RandomState(k_seed).get_state()
    replaced = [0] * n_ensembles
    while True:
        done = min(s.iteration for s in samplers)
        todo = min(max(min_steps - done, chunk), max_steps - done)
        for k, s in enumerate(samplers):
            if todo <= 0:
                break
            # None: resume (emcee restores the random state the backend saved with the last sample)
            init = _ball(theta0, n_walkers, rng, post) if s.iteration == 0 else None
            desc = f"ensemble {k + 1}/{n_ensembles}"
            s.run_mcmc(init, todo, progress=progress, progress_kwargs={"desc": desc, "leave": False})
            if init is not None:  # the first stretch from the start ball: a walker left behind starts again
                chain = s.get_chain()
                moved = replace_stuck_walkers(chain, s.get_log_prob(), rng, log_prob_fn=post.log_prob)
                if moved is not None:
                    replaced[k] = int(np.sum(np.any(moved != chain[-1], axis=1)))
                    s.reset()  # the stretch with the stuck walkers is discarded
                    again = {"desc": desc + " (again)", "leave": False}
                    s.run_mcmc(moved, todo, progress=progress, progress_kwargs=again)
            if s.backend is not None and hasattr(s.backend, "flush"):
                s.backend.flush()
        res = _collect(samplers)
        res.walkers_restarted = tuple(replaced)
        # the marginal noise sd's R-hat
        diag = diagnostics(post.prior_coordinates(res.chain), post.names, n_ensembles=res.n_ensembles)
        missed = missed_targets(diag, res.n_steps, res.tau, target_ess, target_rhat, post.names[:2], count_stuck(res))
        enough = not missed
        if enough or todo <= 0 or res.n_steps >= max_steps:
            res.diagnostics = diag
            res.converged = bool(enough)
            return res


def count_stuck(res: SamplingResult) -> int:
    """Walkers of the kept steps that :func:`stuck_walkers` finds in a far worse region, over all ensembles."""
    lp = res.log_prob.reshape(res.n_ensembles, -1, res.log_prob.shape[1])  # (ensembles, walkers, draws)
    return int(sum(np.sum(stuck_walkers(e.T, res.chain.shape[2])) for e in lp))


def _collect(samplers) -> SamplingResult:
    n_steps = min(s.iteration for s in samplers)
    chains = [s.get_chain()[:n_steps] for s in samplers]  # (steps, walkers, ndim)
    lps = [s.get_log_prob()[:n_steps] for s in samplers]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        taus = np.array([s.get_autocorr_time(tol=0) for s in samplers])
    tau = np.nanmax(taus, axis=0)
    burn = int(min(max(n_steps // 3, 5 * np.nanmax(tau)), n_steps // 2))
    chain = np.concatenate([np.swapaxes(c[burn:], 0, 1) for c in chains], axis=0)
    lp = np.concatenate([np.swapaxes(x[burn:], 0, 1) for x in lps], axis=0)
    acc = float(np.mean([np.mean(s.acceptance_fraction) for s in samplers]))
    return SamplingResult(chain, lp, n_steps, burn, tau, acc, n_ensembles=len(samplers))


def diagnostics(chain: np.ndarray, names, n_ensembles: int = 1, max_draws: int = 1000) -> dict:
    """R-hat and bulk ESS per parameter (ArviZ's rank-normalised split R-hat and bulk ESS).

    Parameters
    ----------
    chain : ndarray, shape (n_walkers_total, n_draws, ndim)
        The kept draws, each ensemble's walkers contiguous (:func:`_collect`).
    names : sequence of str, length ndim
    n_ensembles : int
        How many independent ensembles ``chain`` holds.
    max_draws : int
        Draws per walker read: a longer chain is thinned to every k-th step (k = ceil(n_draws / max_draws)).
        For k well below the autocorrelation time, R-hat and bulk ESS are unchanged in expectation, and a
        group fit's check of 224 walkers x 4000 draws x 14 parameters costs a quarter of the time.

    Returns
    -------
    dict
        ``rhat``: each ensemble as one chain, its walkers pooled step by step (split R-hat then compares the
        ensembles and the halves of the run): the convergence criterion, as R-hat over independent chains is
        meant to be read. ``rhat_walkers``: every walker as a chain; R-hat^2 - 1 is about 2 tau / kept steps
        for walkers that mix alike, so it reads 1.03 at emcee's 50 tau and far above only when walkers
        disagree (one left apart from the rest). ``ess_bulk``: walkers as chains.
    """
    from .summary import import_arviz

    az = import_arviz()
    n_walkers, n_draws, ndim = chain.shape
    if n_ensembles < 1 or n_walkers % n_ensembles:
        raise ValueError(f"n_ensembles: expected a divisor of the {n_walkers} walkers, got {n_ensembles!r}")
    chain = chain[:, :: -(-n_draws // max_draws)]
    n_draws = chain.shape[1]
    walkers = az.from_dict(posterior={n: chain[:, :, i] for i, n in enumerate(names)})
    per = n_walkers // n_ensembles  # (ensembles, steps x walkers in step order, ndim)
    pooled = chain.reshape(n_ensembles, per, n_draws, ndim).transpose(0, 2, 1, 3).reshape(n_ensembles, -1, ndim)
    ensembles = az.from_dict(posterior={n: pooled[:, :, i] for i, n in enumerate(names)})
    rhat, rhat_w, ess = az.rhat(ensembles), az.rhat(walkers), az.ess(walkers, method="bulk")
    return {
        "rhat": {n: float(rhat[n]) for n in names},
        "rhat_walkers": {n: float(rhat_w[n]) for n in names},
        "ess_bulk": {n: float(ess[n]) for n in names},
    }

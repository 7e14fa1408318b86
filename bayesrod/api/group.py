"""``bayesrod.fit_group``: one stem under several conditions, the stem separated from its anchorage (issue 23).

Datasets whose ``specimen.json`` share a ``stem_id`` and differ in ``condition`` are one stem
under several conditions (docs/format.md). :func:`fit_group` fits one such stem jointly
(:mod:`bayesrod.inference.group`): EI0 and p shared, a base compliance per condition, noise
per condition. :func:`fit_groups` finds every stem in a folder and fits each.
"""

from __future__ import annotations

import copy
import itertools
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from .._version import __version__
from ..inference.group import (
    POOL_SPREAD,
    STEM_PARAMETERS,
    GroupLikelihood,
    GroupPosterior,
    base_compliance,
    clamp_or_u,
    correlation_spread,
    refit_start,
    sharing_check,
    start_point,
)
from ..inference.priors import load_prior
from ..inference.sampler import convergence_message, run_ensembles
from ..inference.summary import LEVEL, SENSITIVITY_WARN, credible_interval, prior_sensitivity, walker_rhat
from ..physics import k_theta
from ._common import as_dataset, plain_json, progress_enabled, readonly

log = logging.getLogger("bayesrod")


@dataclass(frozen=True, eq=False)
class GroupFit:
    """The joint posterior of one stem under several conditions, immutable.

    Attributes
    ----------
    stem_id : str
    conditions : tuple of str
        Condition names in the order given (e.g. intact, cut1, cut2, cut3).
    samples : Mapping[str, ndarray]
        Draws (n,) in natural units: the shared stem parameters (``EI0``, ``p``), per condition
        ``base_compliance_rad_per_Nm__<condition>`` and the condition's noise terms by their sampled names.
    doc : Mapping
        The content of ``summary.json`` (docs/format.md, "fit-group").
    """

    stem_id: str
    conditions: tuple[str, ...]
    samples: Mapping[str, NDArray] = field(repr=False)
    doc: Mapping = field(repr=False)

    @property
    def species(self) -> str | None:
        """The stem's species (or genotype) from its datasets' specimen.json, or None."""
        return self.doc.get("species")

    @property
    def length_m(self) -> float | None:
        """The stem length the fit used [m] (None in runs written before it was recorded)."""
        return self.doc.get("length_m")

    @classmethod
    def load(cls, path) -> GroupFit:
        """A saved stem (``RUN/<stem_id>/``: summary.json and samples.npz, as :meth:`save` writes them)."""
        import json

        path = Path(path)
        for name in ("summary.json", "samples.npz"):
            if not (path / name).is_file():
                raise ValueError(f"{path}: expected a fit-group stem directory with {name}, got none")
        doc = json.loads((path / "summary.json").read_text())
        if "conditions_order" not in doc or "stem_id" not in doc:
            raise ValueError(f"{path / 'summary.json'}: expected a fit-group summary (stem_id, conditions_order)")
        with np.load(path / "samples.npz") as z:
            samples = {k: readonly(np.array(z[k])) for k in z.files}
        return cls(doc["stem_id"], tuple(doc["conditions_order"]), MappingProxyType(samples), MappingProxyType(doc))

    def to_dict(self) -> dict:
        """summary.json, a fresh copy."""
        return copy.deepcopy(dict(self.doc))

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write ``path/summary.json`` and ``path/samples.npz`` (atomically)."""
        import io

        from ..dataset.io import OutputExistsError, write_bytes_atomic, write_json

        path = Path(path)
        if (path / "summary.json").exists() and not overwrite:
            raise OutputExistsError(path)
        buf = io.BytesIO()
        np.savez(buf, **{k: np.asarray(v) for k, v in self.samples.items()})
        write_bytes_atomic(path / "samples.npz", buf.getvalue())
        write_json(path / "summary.json", self.to_dict())
        return path

    def plot_compliance(self, ax=None):
        """Base compliance per condition: median and 90% interval; returns the error-bar container."""
        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots(figsize=(5, 3.5))
        rows = [self.doc["conditions"][c]["base_compliance_rad_per_Nm"] for c in self.conditions]
        med = np.array([r["median"] for r in rows])
        lo = np.array([r["q05"] for r in rows])
        hi = np.array([r["q95"] for r in rows])
        x = np.arange(len(rows))
        bars = ax.errorbar(x, med, yerr=[med - lo, hi - med], fmt="o", capsize=4)
        ax.set_xticks(x, self.conditions)
        ax.set(ylabel="base compliance [rad/(N m)]", title=f"{self.stem_id}: anchorage per condition (90%)")
        return bars


def load_run(path):
    """A saved run: a fit-group stem (its summary names the conditions) as a :class:`GroupFit`, else a fit
    as a :class:`~bayesrod.Posterior` (whose loader reports what is missing)."""
    from .fitting import Posterior

    try:
        return GroupFit.load(path)
    except ValueError:
        return Posterior.load(path)


@dataclass(frozen=True)
class GroupStudy:
    """Every stem found in a folder, fitted: ``fits`` by stem id, ``problems`` (one line each) for the rest."""

    fits: Mapping[str, GroupFit]
    problems: tuple[str, ...]

    def save(self, path, *, overwrite: bool = False) -> Path:
        """``path/<stem_id>/summary.json`` (+ samples.npz) per stem and ``path/groups.json`` (index, problems)."""
        from ..dataset.io import write_json

        path = Path(path)
        for sid, g in self.fits.items():
            g.save(path / _safe(sid), overwrite=overwrite)
        write_json(
            path / "groups.json",
            {"stems": {sid: _safe(sid) for sid in self.fits}, "problems": list(self.problems)},
        )
        return path


def _safe(s: str) -> str:
    import re

    return re.sub(r"[^0-9A-Za-z_.-]", "_", s)


def _sort_datasets(root) -> tuple[dict, dict[str, dict[str, Path]], list[Path], list[tuple[Path, str]]]:
    """Every dataset under ``root`` read once and sorted by stem: ``({stem_id: {condition: Dataset}},
    {stem_id: {condition: path}}, singles, problems)`` (see :func:`group_paths`)."""
    from .survey import find_datasets

    groups: dict[str, dict] = {}
    where: dict[tuple[str, str], Path] = {}
    singles: list[Path] = []
    problems: list[tuple[Path, str]] = []
    for path in find_datasets(root):
        ds = as_dataset(path)
        sid, cond = ds.extra.get("stem_id"), ds.extra.get("condition")
        if not isinstance(sid, str) or not sid or not isinstance(cond, str) or not cond:
            singles.append(path)
            problems.append(
                (
                    path,
                    f"{path}/specimen.json: stem_id, condition: expected two non-empty strings, got "
                    f"{sid!r} and {cond!r}; not part of a group",
                )
            )
            continue
        if (sid, cond) in where:
            problems.append(
                (
                    path,
                    f"{path}/specimen.json: condition: expected one dataset per condition of stem {sid!r}, got "
                    f"{cond!r} again (also {where[(sid, cond)]}); this one skipped",
                )
            )
            continue
        where[(sid, cond)] = path
        groups.setdefault(sid, {})[cond] = ds
    for sid in list(groups):
        if len(groups[sid]) < 2:
            (cond,) = groups.pop(sid)
            path = where[(sid, cond)]
            singles.append(path)
            problems.append(
                (
                    path,
                    f"stem {sid}: expected two or more conditions, got only {cond!r} ({path}); "
                    "fit it with bayesrod fit",
                )
            )
    paths = {sid: {c: where[(sid, c)] for c in conds} for sid, conds in groups.items()}
    return groups, paths, singles, problems


def group_paths(root) -> tuple[dict[str, dict[str, Path]], list[Path], list[tuple[Path, str]]]:
    """Datasets under ``root`` sorted by stem: ``({stem_id: {condition: path}}, singles, problems)``.

    ``singles``: datasets that are no stem's condition (no ``stem_id`` or ``condition``, or the only
    condition of their stem); ``problems``: ``(path, one line)`` for each of those and for a second dataset
    of one stem with the same condition (skipped).
    """
    _, paths, singles, problems = _sort_datasets(root)
    return paths, singles, problems


def find_groups(root) -> tuple[dict[str, dict], list[str]]:
    """Stems under ``root``: ``{stem_id: {condition: Dataset}}`` and the problems (one line each).

    A dataset without ``stem_id`` or ``condition``, a stem with a single condition, and two datasets of
    one stem with the same condition are reported, not fitted.
    """
    groups, _, _, problems = _sort_datasets(root)
    return groups, [line for _, line in problems]


def fit_group(
    conditions,
    prior=None,
    *,
    shared: Sequence[str] = STEM_PARAMETERS,
    force_noise: str = "ar1",
    force_offsets: bool = False,
    pooled: Sequence[str] | str = "auto",
    pool_spread: float = POOL_SPREAD,
    seed: int = 0,
    progress: bool = True,
    max_steps: int = 6000,
    target_ess: float = 400.0,
    sharing: bool = True,
    stem_id: str | None = None,
) -> GroupFit:
    """Joint posterior of one stem under several conditions (forces only).

    Parameters
    ----------
    conditions : mapping of str to (path or Dataset), or sequence of those
        One dataset per condition. A sequence is keyed by each dataset's ``condition``.
    prior : str, path or None
        Prior of EI0, p and the noise (docs/priors.md). Each condition's base compliance has the
        scale-free prior uniform on u = c/(1+c) in [0, 0.9], c = EI0 C / L (docs/inference.md, "One stem,
        many conditions"); zero (a rigid clamp) is allowed.
    shared : sequence of str
        Parameters common to all conditions: a subset of the stem's ``("EI0", "p")`` and of the force noise's
        ``("sigma_force_N", "rho_force")``; the others get a copy per condition. Share ``rho_force`` where one
        rig and load cell recorded every condition: with two pushes per condition its own correlation is
        loosely known and widens the compliances' intervals (docs/validation.md, "The compliances' width is the
        noise correlation's").
    force_noise : {"ar1", "iid"}
        Force noise per condition (AR(1): sd and lag-1 correlation per condition).
    force_offsets : bool
        A load-cell offset per condition, prior N(0, sd 5% of the condition's peak force), integrated out of the
        likelihood (not sampled); summary.json's ``force_offset_N`` holds its posterior (from up to 4000 draws).
    pooled : sequence of str or "auto"
        Noise parameters the conditions pool (``("rho_force",)`` or none): each condition keeps its own AR(1)
        correlation, and their Fisher z = atanh(rho) are a normal population of sd ``pool_spread`` about an
        unknown centre, so conditions whose correlations agree read them from each other's pushes
        (docs/inference.md, "One stem, many conditions"). ``"auto"`` (default): the correlation is pooled with
        AR(1) noise unless ``shared`` names it. summary.json's ``pooled`` holds the spread and the conditions'
        common correlation tanh(mean z), and how far apart the conditions' own came out (the sd of their
        posterior-median z; above the spread a warning says the pool may not suit them). ``()`` gives each
        condition its own correlation under its own prior (the default before session 47).
    pool_spread : float
        The population's sd on Fisher's z (default 0.25).
    sharing : bool
        Run the sharing check (held-out refits of the joint and the separate models; a minute or more).
    max_steps, target_ess : int, float
        Sampling budget per ensemble, bulk-ESS target of the stem parameters.

    Returns
    -------
    GroupFit
    """
    t0 = time.perf_counter()
    if isinstance(conditions, Mapping):
        specs = {str(c): as_dataset(d) for c, d in conditions.items()}
    else:
        specs = {}
        for d in conditions:
            ds = as_dataset(d)
            c = ds.extra.get("condition")
            if not isinstance(c, str) or not c:
                raise ValueError(f"conditions: expected datasets with a condition in specimen.json, got {c!r}")
            if c in specs:
                raise ValueError(f"conditions: expected one dataset per condition, got {c!r} twice")
            specs[c] = ds
    if len(specs) < 2:
        raise ValueError(f"conditions: expected two or more conditions of one stem, got {len(specs)}")
    if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 100):
        raise ValueError(f"max_steps: expected an integer >= 100, got {max_steps!r}")
    sid = stem_id or next(iter(specs.values())).extra.get("stem_id") or next(iter(specs.values())).specimen
    species = {c: ds.species for c, ds in specs.items()}
    if len(set(species.values())) > 1:
        raise ValueError(
            f"species: expected one species for the conditions of stem {sid}, got "
            + ", ".join(f"{c}: {v!r}" for c, v in species.items())
        )
    pr = load_prior(prior)
    if isinstance(pooled, str):
        if pooled != "auto":
            raise ValueError(f"pooled: expected 'auto' or a sequence of parameter names, got {pooled!r}")
        pooled = ("rho_force",) if force_noise == "ar1" and "rho_force" not in shared else ()
    lik = GroupLikelihood(
        specs,
        pr,
        shared=tuple(shared),
        force_noise=force_noise,
        force_offsets=force_offsets,
        pooled=tuple(pooled),
        pool_spread=pool_spread,
    )
    post = GroupPosterior(lik)
    log.info("%s: %d conditions, parameters %s", sid, len(specs), ", ".join(post.names))
    theta0 = post.settle_base_coordinates(start_point(post))
    res = run_ensembles(
        post, theta0, seed=seed, progress=progress_enabled(progress), max_steps=max_steps, target_ess=target_ess
    )
    nat = post.to_natural(res.chain.reshape(-1, post.ndim))
    per = {c: lik.condition_params(nat, c) for c in lik.conditions}  # EI0, p and k_b of each condition, per draw
    samples = dict(nat)
    for c in lik.conditions:
        u = clamp_or_u(nat[lik.local[c]["z_base"]])
        samples[f"base_compliance_rad_per_Nm__{c}"] = base_compliance(u, per[c]["EI0"], lik.liks[c].L)
    check = sharing_check(lik, refit_start(post, theta0, res.chain, res.log_prob)) if sharing else None
    offsets = offset_draws(lik, nat, np.random.default_rng(seed))
    doc = _summary(sid, lik, nat, per, samples, res, pr, check, time.perf_counter() - t0, offsets)
    _correlation_sensitivity(doc, post, res)
    not_converged = convergence_message(res, max_steps, target_ess)
    doc["convergence"]["converged"] = not_converged is None
    if not_converged:
        doc["warnings"].append(not_converged)
    doc["species"] = next(iter(species.values()))
    doc["length_m"] = float(lik.liks[lik.conditions[0]].L)
    ro = {k: readonly(v) for k, v in samples.items()}
    return GroupFit(sid, tuple(lik.conditions), MappingProxyType(ro), MappingProxyType(plain_json(doc)))


#: draws of each condition's integrated-out offset behind summary.json's force_offset_N (from thinned draws)
OFFSET_DRAWS = 4000


def offset_draws(lik: GroupLikelihood, nat: dict, rng: np.random.Generator) -> dict:
    """Per condition with an integrated-out load-cell offset, draws [N] of it: at up to OFFSET_DRAWS posterior
    draws (evenly thinned), one from its Gaussian conditional given the draw's other parameters."""
    n = next(iter(nat.values())).size
    idx = _evenly(n, OFFSET_DRAWS)
    thin = {k: v[idx] for k, v in nat.items()}
    out = {}
    for c in lik.conditions:
        one = lik.liks[c]
        if one.offset_prior_sd:
            mean, sd = one.offset_posterior(lik.condition_params(thin, c))
            out[c] = mean + sd * rng.standard_normal(mean.size)
    return out


def _evenly(n: int, k: int) -> NDArray:
    """Indices of up to ``k`` of ``n`` draws, evenly spaced (deterministic, the first and the last kept)."""
    return np.unique(np.linspace(0, n - 1, min(n, k)).round().astype(int))


#: evenly thinned draws behind summary.json's identifiability.correlation_prior_sensitivity (0.7 s for 13
#: quantities; with 3000-7500 draws a compliance whose posterior was nearly all clamp read 0.12-0.49 by the
#: thinning's offset, against 0.05 from all 750000)
SENSITIVITY_DRAWS = 20000
#: a base compliance with fewer soft (non-clamp) draws among those is reported null: the sensitivity of a
#: posterior that is nearly all clamp rests on a handful of draws
SENSITIVITY_MIN_SOFT = 200


def sensitivity_draws(post: GroupPosterior, chain: NDArray, log_prob: NDArray) -> tuple[dict, NDArray, NDArray]:
    """Up to SENSITIVITY_DRAWS evenly thinned draws of ``chain`` (..., ndim) in natural units, with their log
    likelihood (``log_prob`` less the log prior) and the correlations' log prior
    (:meth:`GroupLikelihood.correlation_log_prior`), each (n,); draws where either is not finite are left out."""
    lp = np.asarray(log_prob, float).reshape(-1)
    idx = _evenly(lp.size, SENSITIVITY_DRAWS)
    theta, lp = chain.reshape(-1, post.ndim)[idx], lp[idx]
    nat = post.to_natural(theta)
    ll = lp - post.log_prior(theta)
    lp_rho = np.broadcast_to(post.likelihood.correlation_log_prior(nat), lp.shape)
    keep = np.isfinite(ll) & np.isfinite(lp_rho)  # every posterior draw is; a walker stuck outside would not be
    return {k: v[keep] for k, v in nat.items()}, ll[keep], lp_rho[keep]


def correlation_sensitivity(post: GroupPosterior, chain: NDArray, log_prob: NDArray) -> dict | None:
    """How much the noise correlations' prior (:meth:`GroupLikelihood.correlation_log_prior`) shapes the
    answer: the power-scaling sensitivity (:func:`~bayesrod.inference.summary.prior_sensitivity`) of each
    condition's ``rho_force``, ``sigma_force_N`` and base compliance, and of the shared EI0, to that prior
    and to the likelihood, on :func:`sensitivity_draws`. None without AR(1) noise; a compliance with fewer
    than SENSITIVITY_MIN_SOFT soft draws: None."""
    lik = post.likelihood
    conds = lik.conditions
    if not all("rho_force" in lik.local[c] for c in conds):
        return None
    nat, ll, lp_rho = sensitivity_draws(post, chain, log_prob)
    draws, where = {}, {}  # quantity name -> draws; -> (summary key, condition or None)
    for c in conds:
        one = lik.condition_params(nat, c)
        C = base_compliance(clamp_or_u(nat[lik.local[c]["z_base"]]), one["EI0"], lik.liks[c].L)
        for q, x in (("rho_force", one["rho_force"]), ("sigma_force_N", one["sigma_force_N"])):
            draws[f"{q}__{c}"], where[f"{q}__{c}"] = x, (q, c)
        if np.count_nonzero(C > 0) >= SENSITIVITY_MIN_SOFT:
            draws[f"C__{c}"], where[f"C__{c}"] = C, ("base_compliance_rad_per_Nm", c)
    if "EI0" in lik.shared:
        draws["EI0"], where["EI0"] = nat["EI0"], ("EI0", None)
    sens = prior_sensitivity(draws, lp_rho, ll)
    out: dict = {"scaled": "the noise correlations' prior", "warn_above": SENSITIVITY_WARN}
    out |= {"rho_force": {}, "sigma_force_N": {}, "base_compliance_rad_per_Nm": dict.fromkeys(conds)}
    for n, (q, c) in where.items():
        if c is None:
            out[q] = sens[n]
        else:
            out[q][c] = sens[n]
    return out


def _correlation_sensitivity(doc: dict, post: GroupPosterior, res) -> None:
    """summary.json's ``identifiability.correlation_prior_sensitivity`` and, where a condition's correlation
    leans on its prior, a warning saying what that leaves to the prior."""
    sens = correlation_sensitivity(post, res.chain, res.log_prob)
    if sens is None:
        return
    doc["identifiability"]["correlation_prior_sensitivity"] = sens
    lean = {c: v["prior"] for c, v in sens["rho_force"].items() if v["prior"] > SENSITIVITY_WARN}
    if lean:
        soft = [v["prior"] for v in sens["base_compliance_rad_per_Nm"].values() if v is not None]
        comp = f"is at most {max(soft):.2f}" if soft else "is not measured (every base nearly a clamp)"
        stem = f", EI0's {sens['EI0']['prior']:.2f}" if "EI0" in sens else ""
        doc["warnings"].append(
            "the noise correlation of "
            + ", ".join(f"{c} ({v:.2f})" for c, v in lean.items())
            + f" leans on its prior (power-scaling sensitivity above {SENSITIVITY_WARN:g}; "
            "identifiability.correlation_prior_sensitivity): its pushes pin the noise's innovations, "
            "sigma sqrt(1 - rho^2), not rho and sigma apart, so read rho_force and sigma_force_N as partly the "
            f"prior's; the compliances' sensitivity to that prior {comp}{stem}"
        )


def _summary(sid, lik: GroupLikelihood, nat, per, samples, res, pr, check, seconds, offsets) -> dict:
    conds = lik.conditions
    shared = {n: credible_interval(nat[n]) for n in lik.shared}
    out_conds = {}
    warnings = []
    for c in conds:
        loc = lik.local[c]
        EI0, p, kb = per[c]["EI0"], per[c]["p"], per[c]["base_compliance"]  # base_compliance holds k_b
        heights = sorted({float(d.height_m) for d in lik.liks[c].data if d.D_m.size})
        kt = k_theta(np.array(heights)[None, :], EI0[:, None], p[:, None], lik.liks[c].L, kb[:, None])
        row = {
            "base_compliance_rad_per_Nm": credible_interval(samples[f"base_compliance_rad_per_Nm__{c}"]),
            "prob_rigid_clamp": float(np.mean(clamp_or_u(nat[loc["z_base"]]) == 0.0)),
            "k_theta": [{"height_m": h, **credible_interval(kt[:, i])} for i, h in enumerate(heights)],
            "sigma_force_N": credible_interval(nat[loc["sigma_force_N"]]),
        }
        for n in STEM_PARAMETERS:
            if n not in lik.shared:
                row[n] = credible_interval(nat[loc[n]])
        if "rho_force" in per[c]:
            row["rho_force"] = credible_interval(per[c]["rho_force"])
        if c in offsets:
            row["force_offset_N"] = credible_interval(offsets[c])
        out_conds[c] = row
    contrasts = []
    for a, b in itertools.permutations(conds, 2):
        Ca = samples[f"base_compliance_rad_per_Nm__{a}"]
        Cb = samples[f"base_compliance_rad_per_Nm__{b}"]
        contrasts.append(
            {
                "a": a,
                "b": b,
                "compliance_difference_rad_per_Nm": credible_interval(Cb - Ca),
                "prob_b_softer": float(np.mean(Cb > Ca)),
            }
        )
    n_heights = {c: len({d.height_m for d in lik.liks[c].data if d.D_m.size}) for c in conds}
    ident = {"heights_per_condition": n_heights}
    if "EI0" in lik.shared:
        prior = pr.get("EI0")
        post_sd = float(np.std(np.log(nat["EI0"])))
        if prior.dist == "lognormal":
            ident["EI0_posterior_over_prior_sd_log"] = post_sd / prior.args[1]
        ident["EI0_posterior_sd_log"] = post_sd
    if all(v == 1 for v in n_heights.values()):
        warnings.append(
            "every condition was pushed at one height: stem and anchorage are weakly separable (a softer base and "
            "a softer stem bend the stem alike); the shared EI0 leans on the prior (identifiability."
            "EI0_posterior_over_prior_sd_log) and on the stiffest condition being near a clamp; push a second "
            "height (bayesrod design) to separate them"
        )
    if check is not None and check.verdict == "rejected":
        warnings.append(
            "sharing rejected: the joint model predicts held-out pushes worse than separate fits; the stem itself "
            "seems to differ between conditions, so the compliances above are not the whole story"
        )
    pooled = {}
    for n in lik.pooled:
        draws = [nat[lik.local[c][n]] for c in conds]  # each condition's correlation, per draw
        medians = [float(np.median(r)) for r in draws]
        apart = correlation_spread(medians)
        pooled[n] = {
            "spread_fisher_z": lik.pool_spread,
            "centre": credible_interval(np.tanh(np.mean(np.arctanh(draws), axis=0))),
            "conditions_spread_fisher_z": apart,
        }
        if apart > lik.pool_spread:
            each = ", ".join(f"{c} {r:.2f}" for c, r in zip(conds, medians, strict=True))
            warnings.append(
                f"the conditions' {n} ({each}) spread further than the pool allows (sd of their Fisher z "
                f"{apart:.2f}, the pool's {lik.pool_spread:g}): pooling pulls them together, which narrows or "
                "shifts the compliances if the rig's noise really differed between conditions; fit them unpooled "
                "(docs/inference.md, 'One stem, many conditions') and compare"
            )
    diag = res.diagnostics
    return {
        "stem_id": sid,
        "conditions_order": list(conds),
        "shared": shared,
        "pooled": pooled,
        "conditions": out_conds,
        "contrasts": contrasts,
        "sharing": check.to_dict() if check is not None else None,
        "identifiability": ident,
        "warnings": warnings,
        "level": LEVEL,
        "prior": pr.name,
        "force_noise": lik.force_noise,
        "convergence": {
            "rhat_max": float(max(diag["rhat"].values())),
            "ess_bulk_min": float(min(diag["ess_bulk"].values())),
            **walker_rhat(diag),
            "walkers_restarted": int(sum(res.walkers_restarted)),
        },
        "sampler": {"steps": res.n_steps, "burn_in": res.burn, "seconds": round(seconds, 1)},
        "bayesrod": __version__,
    }


def fit_groups(root, prior=None, **kwargs) -> GroupStudy:
    """Every stem under ``root`` (datasets sharing a ``stem_id``) fitted with :func:`fit_group`.

    Problems (ungrouped datasets, a stem with one condition, a repeated condition) and stems whose fit
    fails are listed in ``GroupStudy.problems``, one line each; the others are fitted.
    """
    groups, problems = find_groups(root)
    if not groups:
        raise ValueError(
            f"{root}: expected datasets sharing a stem_id under two or more conditions, got none"
            + (f" ({problems[0]})" if problems else "")
        )
    fits = {}
    for sid, conds in groups.items():
        try:
            fits[sid] = fit_group(conds, prior, stem_id=sid, **kwargs)
        except ValueError as e:
            problems.append(f"stem {sid}: {e}")
    return GroupStudy(MappingProxyType(fits), tuple(problems))

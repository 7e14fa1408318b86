"""``bayesrod.compare``: species contrasts from fitted specimens. Returns a :class:`Comparison`.

The model is :mod:`bayesrod.inference.hierarchical`. ``Comparison.save`` writes
``compare.json`` (docs/format.md, with extensions: species-level estimates, the
between-specimen spread, warnings, convergence) and ``figures/forest.png``.
"""

from __future__ import annotations

import copy
import itertools
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..inference.hierarchical import (
    PRIOR_COMPLIANCE,
    PRIOR_LOG_E,
    SpecimenPosterior,
    check_reduction,
    contrasts,
    modulus_contrasts,
    sample_species,
)
from ..inference.summary import credible_interval
from ._common import DocResult, plain_json

log = logging.getLogger("bayesrod")


def _is_run(path: Path) -> bool:
    return (path / "summary.json").is_file() and (path / "samples.npz").is_file()


def expand_inputs(inputs) -> list[Path]:
    """Paths as given, a ``fit-many`` output standing for all its finished runs (and, when grouped,
    its stems) and a ``fit-group`` output (``groups.json``) for all its stems."""
    import json

    expanded = []
    for raw in inputs:
        path = Path(raw)
        if (path / "survey.csv").is_file() and (path / "runs").is_dir():
            expanded += [d.with_suffix("") for d in sorted((path / "runs").glob("*.done"))]
            expanded += [d.with_suffix("") for d in sorted((path / "groups").glob("*.done"))]  # fit_many(grouped=True)
        elif (path / "groups.json").is_file():
            stems = json.loads((path / "groups.json").read_text()).get("stems", {})
            expanded += [path / d for d in stems.values()]
        else:
            expanded.append(path)
    return expanded


def _specimen_posterior(post, species: str | None = None) -> SpecimenPosterior:
    """(log EI0, p) draws of one fit (its thinned draws: those ``samples.npz`` holds), specimen and species;
    of a stem under several conditions (a :class:`GroupFit`), its shared EI0 and p."""
    from .group import GroupFit

    if isinstance(post, GroupFit):
        species = species or post.species
        missing = [n for n in ("EI0", "p") if n not in post.doc.get("shared", {})]
        if missing:
            raise ValueError(
                f"stem {post.stem_id}: field shared: expected EI0 and p shared by its conditions (the stem's "
                f"own parameters to compare), got {', '.join(missing)} fitted per condition"
            )
        if not species:
            raise ValueError(
                f"stem {post.stem_id}: field species: expected the stem's species or genotype (set it in its "
                "datasets' specimen.json), got none"
            )
        d = post.samples
        return SpecimenPosterior(
            post.stem_id, str(species), float(post.length_m or np.nan), np.column_stack([np.log(d["EI0"]), d["p"]])
        )
    species = species or post.doc.get("species")
    if not species:
        where = post.config.get("run") or post.specimen
        raise ValueError(f"{where}: field species: expected the specimen's species (set it in specimen.json), got none")
    d = post.thinned()
    return SpecimenPosterior(post.specimen, str(species), post.length_m, np.column_stack([np.log(d["EI0"]), d["p"]]))


def _modulus_posterior(post, species: str | None = None) -> SpecimenPosterior | None:
    """log Young's modulus draws (n, 1) of one fit (its thinned draws), or None without diameters."""
    d = post.thinned()
    if "d0_m" not in d:
        return None
    from ..inference.summary import youngs_modulus

    species = species or post.doc.get("species")
    return SpecimenPosterior(post.specimen, str(species), post.length_m, np.log(youngs_modulus(d))[:, None])


def _moduli(fits) -> tuple[list[SpecimenPosterior] | None, list[str]]:
    """log E posteriors of every fit when all have measured diameters (else None), and the warnings."""
    from .group import GroupFit

    if any(isinstance(post, GroupFit) for post, _ in fits):
        return None, []  # stems under several conditions carry no diameters
    moduli = [_modulus_posterior(post, sp) for post, sp in fits]
    if all(m is None for m in moduli):
        return None, []
    if any(m is None for m in moduli):
        missing = [post.specimen for (post, _), m in zip(fits, moduli, strict=True) if m is None]
        return None, [
            f"Young's modulus not compared: {', '.join(missing)} fitted without diameters "
            '(fit with measured diameters: docs/inference.md, "Young\'s modulus")'
        ]
    # "narrow against its prior": log E0 = log EI0 - 4 log d0 + const has a fit prior far wider than log EI0's
    # 1.5 (docs/priors.md); half the species prior's sd (1.5) is the stricter test
    return moduli, [w for m in moduli for w in check_reduction(m, prior_sd=PRIOR_LOG_E["sd"] / 2, names=("log E",))]


def _as_posterior(x):
    from .fitting import Posterior
    from .group import GroupFit, load_run

    if isinstance(x, (Posterior, GroupFit)):
        return x
    if isinstance(x, (str, Path)) and _is_run(Path(x)):
        return load_run(x)
    raise ValueError(
        f"{x}: expected a bayesrod.Posterior, a GroupFit, a fit run directory or a fit-group stem directory "
        "(summary.json + samples.npz)"
    )


def _anchorage(fits, seed: int) -> tuple[dict, list[str]]:
    """Species contrasts of the base compliance per condition, over the stems fitted under several conditions.

    For every condition all those stems share, a one-dimensional normal-normal model (the species model
    of :mod:`~bayesrod.inference.hierarchical`) of each stem's base compliance [rad/(N m)] with
    :data:`PRIOR_COMPLIANCE`. Returns ``{condition: {species, between_stem_sd, contrasts}}`` and warnings.
    """
    from .group import GroupFit

    stems = [(post, sp or post.species) for post, sp in fits if isinstance(post, GroupFit)]
    if not stems:
        return {}, []
    common = [c for c in stems[0][0].conditions if all(c in post.conditions for post, _ in stems)]
    if not common:
        return {}, ["anchorage not compared: the stems share no condition name"]
    if len({str(sp) for _, sp in stems}) < 2:
        return {}, ["anchorage not compared: the stems fitted under several conditions are of one species"]
    out = {}
    for k, cond in enumerate(common):
        per = [
            SpecimenPosterior(
                post.stem_id,
                str(sp),
                float(post.length_m or np.nan),
                np.asarray(post.samples[f"base_compliance_rad_per_Nm__{cond}"], float)[:, None],
            )
            for post, sp in stems
        ]
        # one dimension per species: 600 steps give a bulk ESS of several thousand
        fit = sample_species(per, seed=seed + 2 + k, prior=PRIOR_COMPLIANCE, n_steps=600)
        sp, mu = fit["species"], fit["mu"][:, :, 0]
        out[cond] = {
            "species": {s: {"base_compliance_rad_per_Nm": credible_interval(mu[:, g])} for g, s in enumerate(sp)},
            "between_stem_sd_rad_per_Nm": credible_interval(fit["tau"][:, 0]),
            "contrasts": [
                {
                    "a": sp[a],
                    "b": sp[b],
                    "parameter": "base_compliance_rad_per_Nm",
                    "condition": cond,
                    **{f"difference_{q}": v for q, v in credible_interval(mu[:, a] - mu[:, b]).items()},
                    "prob_a_greater": float(np.mean(mu[:, a] > mu[:, b])),
                }
                for a, b in itertools.combinations(range(len(sp)), 2)
            ],
            "convergence": {"rhat_max": fit["rhat_max"], "ess_bulk_min": fit["ess_bulk_min"]},
        }
    return out, []


@dataclass(frozen=True, eq=False)
class Comparison(DocResult):
    """Species contrasts from a hierarchical model over specimens (the content of ``compare.json``)."""

    doc: Mapping = field(repr=False)
    fit: Mapping = field(repr=False)
    specimens: tuple = field(repr=False)

    @property
    def contrasts(self) -> list[dict]:
        return copy.deepcopy(list(self.doc["contrasts"]))

    def plot(self, ax=None):
        """Forest plot: species-level EI0 with each specimen's median and 90% interval; returns the artists."""
        from ..report.plots import plot_forest

        return plot_forest(dict(self.fit), list(self.specimens), ax=ax)

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write ``compare.json`` and ``figures/forest.png`` into the directory ``path`` (atomically)."""
        from ..dataset.io import atomic_dir, write_bytes_atomic, write_json
        from ..report.figures import render

        path = Path(path)
        n = len(self.specimens) + 2 * len(self.doc["groups"])
        with atomic_dir(path, overwrite) as tmp:
            write_json(tmp / "compare.json", self.to_dict())
            png = render(lambda ax: self.plot(ax=ax), 7, 1.2 + 0.45 * n)
            write_bytes_atomic(tmp / "figures" / "forest.png", png)
        return path


def compare(posteriors, *, height_m: float | None = None, seed: int = 0) -> Comparison:
    """Compare species: a normal-normal hierarchical model over per-specimen posteriors (docs/compare.md).

    Parameters
    ----------
    posteriors : mapping or sequence
        ``{species: [Posterior or run directory, ...]}``, or a flat sequence whose species are read from
        each fit's dataset.
    height_m : float or None
        Also contrast k_theta at this contact height [m].
    seed : int
        Random seed of the hierarchical sampler.
    """
    if isinstance(posteriors, Mapping):
        fits = [(_as_posterior(x), sp) for sp, xs in posteriors.items() for x in xs]
    else:
        fits = [(_as_posterior(x), None) for x in posteriors]
    specimens = [_specimen_posterior(post, sp) for post, sp in fits]
    names = [s.specimen for s in specimens]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"specimen: expected each specimen once, got {', '.join(dup)} more than once")
    if len(specimens) < 2:
        raise ValueError(f"posteriors: expected at least 2 specimens, got {len(specimens)}")
    groups: dict[str, list[str]] = {}
    for s in specimens:
        groups.setdefault(s.species, []).append(s.specimen)
    if len(groups) < 2:
        raise ValueError(f"species: expected at least 2 species to compare, got only {next(iter(groups))!r}")
    warnings = [w for s in specimens for w in check_reduction(s)]
    for sp, members in groups.items():
        if len(members) == 1:
            warnings.append(
                f"{sp}: one specimen only; its species mean rests on the between-specimen spread "
                "estimated from the other species (wide interval)"
            )
    with_E, w_E = _moduli(fits)
    warnings += w_E
    anchorage, w_A = _anchorage(fits, seed)
    warnings += w_A
    for w in warnings:
        log.warning("warning: %s", w)
    fit = sample_species(specimens, seed=seed)
    result = {
        "groups": groups,
        "contrasts": contrasts(fit, specimens, height_m),
        "species": {
            sp: {
                "EI0": credible_interval(np.exp(fit["mu"][:, g, 0])),
                "p": credible_interval(fit["mu"][:, g, 1]),
                "n_specimens": len(groups[sp]),
            }
            for g, sp in enumerate(fit["species"])
        },
        "between_specimen_sd": {
            "log_EI0": credible_interval(fit["tau"][:, 0]),
            "p": credible_interval(fit["tau"][:, 1]),
        },
        "convergence": {"rhat_max": fit["rhat_max"], "ess_bulk_min": fit["ess_bulk_min"]},
        "warnings": warnings,
        "method": "normal-normal hierarchical model on per-specimen posteriors (docs/compare.md)",
        "level": 0.9,
    }
    if with_E:
        # one dimension per species: half the steps of the (log EI0, p) model still give an ESS in the thousands
        fit_E = sample_species(with_E, seed=seed + 1, prior=PRIOR_LOG_E, n_steps=1500)
        result["contrasts"] += modulus_contrasts(fit_E)
        for g, sp in enumerate(fit_E["species"]):
            result["species"][sp]["E_Pa"] = credible_interval(np.exp(fit_E["mu"][:, g, 0]))
        result["between_specimen_sd"]["log_E"] = credible_interval(fit_E["tau"][:, 0])
        result["convergence"] = {
            "rhat_max": max(fit["rhat_max"], fit_E["rhat_max"]),
            "ess_bulk_min": min(fit["ess_bulk_min"], fit_E["ess_bulk_min"]),
        }
    if anchorage:
        result["anchorage"] = anchorage
    result = plain_json(result)
    return Comparison(MappingProxyType(result), MappingProxyType(fit), tuple(specimens))

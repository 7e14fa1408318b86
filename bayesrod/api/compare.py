"""``bayesrod.compare``: species contrasts from fitted specimens. Returns a :class:`Comparison`.

The model is :mod:`bayesrod.inference.hierarchical`. ``Comparison.save`` writes
``compare.json`` (docs/format.md, with extensions: species-level estimates, the
between-specimen spread, warnings, convergence) and ``figures/forest.png``.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..inference.hierarchical import (
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
    """Paths as given, a ``fit-many`` output standing for all its finished runs."""
    expanded = []
    for raw in inputs:
        path = Path(raw)
        if (path / "survey.csv").is_file() and (path / "runs").is_dir():
            expanded += [d.with_suffix("") for d in sorted((path / "runs").glob("*.done"))]
        else:
            expanded.append(path)
    return expanded


def _specimen_posterior(post, species: str | None = None) -> SpecimenPosterior:
    """(log EI0, p) draws of one fit (its thinned draws: those ``samples.npz`` holds), specimen and species."""
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

    if isinstance(x, Posterior):
        return x
    if isinstance(x, (str, Path)) and _is_run(Path(x)):
        return Posterior.load(x)
    raise ValueError(f"{x}: expected a bayesrod.Posterior or a fit run directory (summary.json + samples.npz)")


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
        from ..report.plots import plot_forest

        path = Path(path)
        n = len(self.specimens) + 2 * len(self.doc["groups"])
        with atomic_dir(path, overwrite) as tmp:
            write_json(tmp / "compare.json", self.to_dict())
            png = render(lambda ax: plot_forest(dict(self.fit), list(self.specimens), ax=ax), 7, 1.2 + 0.45 * n)
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
    result = plain_json(result)
    return Comparison(MappingProxyType(result), MappingProxyType(fit), tuple(specimens))

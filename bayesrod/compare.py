"""``bayesrod compare``: species contrasts from fitted runs (or datasets, fitted first).

I/O lives here; the model is :mod:`bayesrod.inference.hierarchical`. Writes
``compare.json`` (CONTRACT.md section 3, with extensions: species-level
estimates, the between-specimen spread, warnings, convergence) and
``figures/forest.png``. Datasets given instead of runs are fitted into
``DIR/fits/<specimen>`` first (default prior, forces and shapes).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .inference.hierarchical import SpecimenPosterior, check_reduction, contrasts, sample_species
from .io import atomic_dir, write_json


def _is_run(path: Path) -> bool:
    return (path / "summary.json").is_file() and (path / "samples.npz").is_file()


def load_run(path: Path) -> SpecimenPosterior:
    """A fitted run's draws of (log EI0, p), its specimen, species and length."""
    summary = json.loads((path / "summary.json").read_text())
    with np.load(path / "samples.npz") as z:
        EI0, p = np.asarray(z["EI0"]), np.asarray(z["p"])
        L = float(z["length_m"])
    species = summary.get("species")
    if not species:
        raise ValueError(
            f"{path / 'summary.json'}: field species: expected the specimen's species (set it in specimen.json), "
            "got none"
        )
    return SpecimenPosterior(summary["specimen"], str(species), L, np.column_stack([np.log(EI0), p]))


def gather(inputs, work: Path, *, seed: int = 0, log=print) -> list[SpecimenPosterior]:
    """Runs as they are; datasets fitted into ``work/fits/<specimen>`` first."""
    from .fit import fit_dataset

    out = []
    expanded = []
    for raw in inputs:  # a fit-many output stands for all its finished runs
        path = Path(raw)
        if (path / "survey.csv").is_file() and (path / "runs").is_dir():
            expanded += [d.with_suffix("") for d in sorted((path / "runs").glob("*.done"))]
        else:
            expanded.append(path)
    for path in expanded:
        if _is_run(path):
            out.append(load_run(path))
        elif (path / "specimen.json").is_file():
            name = json.loads((path / "specimen.json").read_text()).get("specimen", path.name)
            run = work / "fits" / str(name)
            log(f"{path}: a dataset; fitting it into {run}")
            fit_dataset(path, run, seed=seed, progress=False, log=lambda *a: None)
            out.append(load_run(run))
        else:
            raise ValueError(f"{path}: expected a fit run (summary.json + samples.npz) or a dataset (specimen.json)")
    names = [s.specimen for s in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"specimen: expected each specimen once, got {', '.join(dup)} more than once")
    return out


def plot_forest(fit: dict, specimens: list[SpecimenPosterior], ax=None):
    """Species-level EI0 (90% interval) with each specimen's median: a forest plot. Returns the artists."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 0.6 + 0.5 * len(specimens) + 0.6 * len(fit["species"])))
    artists = {"species": [], "specimens": []}
    y = 0
    ticks, labels = [], []
    for g, sp in enumerate(fit["species"]):
        q05, q50, q95 = np.exp(np.quantile(fit["mu"][:, g, 0], [0.05, 0.5, 0.95]))
        artists["species"].append(ax.errorbar(q50, y, xerr=[[q50 - q05], [q95 - q50]], fmt="D", color=f"C{g}", ms=7))
        ticks.append(y)
        labels.append(f"{sp} (species)")
        y -= 1
        for s in [s for s in specimens if s.species == sp]:
            lo, med, hi = np.exp(np.quantile(s.draws[:, 0], [0.05, 0.5, 0.95]))
            artists["specimens"].append(
                ax.errorbar(med, y, xerr=[[med - lo], [hi - med]], fmt="o", color=f"C{g}", ms=4, alpha=0.7)
            )
            ticks.append(y)
            labels.append(f"  {s.specimen}")
            y -= 1
        y -= 0.5
    ax.set_yticks(ticks, labels)
    ax.set(xscale="log", xlabel="EI0 [N m$^2$] (median, 90% interval)", title="Species comparison (forest plot)")
    return artists


def compare(inputs, out, *, height_m: float | None = None, seed: int = 0, force: bool = False, log=print) -> dict:
    """Run the comparison and write ``out`` atomically; returns compare.json's content."""
    out = Path(out)
    with atomic_dir(out, force) as tmp:
        specimens = gather(inputs, tmp, seed=seed, log=log)
        if len(specimens) < 2:
            raise ValueError(f"compare: expected at least 2 specimens, got {len(specimens)}")
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
        for w in warnings:
            log(f"warning: {w}")
        fit = sample_species(specimens, seed=seed)
        result = {
            "groups": groups,
            "contrasts": contrasts(fit, specimens, height_m),
            "species": {
                sp: {
                    "EI0": _qd(np.exp(fit["mu"][:, g, 0])),
                    "p": _qd(fit["mu"][:, g, 1]),
                    "n_specimens": len(groups[sp]),
                }
                for g, sp in enumerate(fit["species"])
            },
            "between_specimen_sd": {"log_EI0": _qd(fit["tau"][:, 0]), "p": _qd(fit["tau"][:, 1])},
            "convergence": {"rhat_max": fit["rhat_max"], "ess_bulk_min": fit["ess_bulk_min"]},
            "warnings": warnings,
            "method": "normal-normal hierarchical model on per-specimen posteriors (docs/compare.md)",
        }
        write_json(tmp / "compare.json", result)
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        (tmp / "figures").mkdir(exist_ok=True)
        fig, ax = plt.subplots(figsize=(7, 1.2 + 0.45 * (len(specimens) + 2 * len(groups))))
        plot_forest(fit, specimens, ax=ax)
        fig.tight_layout()
        fig.savefig(tmp / "figures" / "forest.png", dpi=100)
        plt.close(fig)
    return result


def _qd(x) -> dict:
    q05, q50, q95 = np.quantile(x, [0.05, 0.5, 0.95])
    return {"median": float(q50), "q05": float(q05), "q95": float(q95)}

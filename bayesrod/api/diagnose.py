"""``bayesrod.diagnose``: where does the plain rod fail on these data, and what fixes it?

The statistics are :mod:`bayesrod.inference.diagnose`; :func:`diagnose` returns a
:class:`Diagnosis` whose ``save`` writes ``diagnose.json`` (docs/format.md, with
extensions), ``figures/residuals.png`` (before/after residual structure),
``figures/statistics.png`` (every effect's test) and ``report.html``.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..dataset.plausibility import starts_loaded
from ..inference.diagnose import CATALOG, HELDOUT_ALPHA, ForwardModel
from ..inference.diagnose import diagnose as diagnose_model
from ..inference.likelihood import default_length_prior, length_is_approximate, prepare_data
from ._common import DocResult, plain_json

log = logging.getLogger("bayesrod")


@dataclass(frozen=True, eq=False)
class Diagnosis(DocResult):
    """What the plain rod misses on a dataset and what fixes it (the content of ``diagnose.json``).

    ``added_effects`` names the effects added; ``before``/``after`` hold the in-sample and held-out errors;
    ``unexplained_structure`` says whether residual structure remains.
    """

    doc: Mapping = field(repr=False)
    model: Any = field(repr=False, default=None)
    plain: Any = field(repr=False, default=None)
    after: Any = field(repr=False, default=None)

    @property
    def added_effects(self) -> list[str]:
        return list(self.doc["added_effects"])

    @property
    def unexplained_structure(self) -> bool:
        return bool(self.doc["unexplained_structure"])

    def plot_residuals(self, axes=None):
        """Force and shape residual structure before (plain rod) and after; returns the artists."""
        from ..report.plots import plot_residual_structure

        return plot_residual_structure(self.model, self.plain, self.after, axes=axes)

    def plot_statistics(self, ax=None):
        """Each effect's test statistic per round against its threshold; returns the bars."""
        from ..report.plots import plot_statistics

        return plot_statistics(self.doc, ax=ax)

    def figures(self) -> dict[str, bytes]:
        from ..report.figures import render
        from ..report.plots import plot_residual_structure, plot_statistics

        return {
            "residuals": render(
                lambda axes: plot_residual_structure(self.model, self.plain, self.after, axes=axes), 11, 3.8, ncols=2
            ),
            "statistics": render(lambda ax: plot_statistics(self.doc, ax=ax), 6.4, 3.8),
        }

    def report(self, path) -> Path:
        """Write the HTML report to ``path`` (atomically)."""
        from ..dataset.io import write_text_atomic
        from ..report.html import diagnose_report

        write_text_atomic(path, diagnose_report(self.to_dict(), self.figures()))
        return Path(path)

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write ``diagnose.json``, ``figures/`` and ``report.html`` into the directory ``path`` (atomically)."""
        from ..dataset.io import atomic_dir, write_bytes_atomic, write_json, write_text_atomic
        from ..report.html import diagnose_report

        path = Path(path)
        with atomic_dir(path, overwrite) as tmp:
            write_json(tmp / "diagnose.json", self.to_dict())
            pngs = self.figures()
            for k, v in pngs.items():
                write_bytes_atomic(tmp / "figures" / f"{k}.png", v)
            write_text_atomic(tmp / "report.html", diagnose_report(self.to_dict(), pngs))
        return path


def diagnose(
    dataset,
    *,
    candidates=CATALOG,
    use_shapes: bool = True,
    alpha: float = 0.01,
    min_heldout_gain: float = 0.10,
    heldout_alpha: float = HELDOUT_ALPHA,
    force_noise: str = "ar1",
    preload: bool | str = "auto",
    length: str = "known",
    height_sd_m: float = 0.0,
    n_workers: int = 1,
) -> Diagnosis:
    """Residual analysis: which missing effect explains the misfit, refit, error before and after.

    Parameters
    ----------
    dataset : path or Dataset
    candidates : sequence of str
        Effects to test (default: the whole catalog, docs/diagnose.md).
    use_shapes : bool
        Use centerlines as well as forces.
    alpha : float
        Family-wise test level per round, in (0, 1).
    min_heldout_gain : float
        Relative drop of the held-out force error (true refits without the held-out push, or without
        the last third of a single push) an effect must bring.
    heldout_alpha : float
        Level of the parametric bootstrap test (under the fitted AR(1) noise) that the held-out
        improvement is not chance.
    force_noise : {"ar1", "iid"}
        Force noise of every fit and test: AR(1) per push (default; real pushes are autocorrelated) or
        independent.
    preload : {"auto", True, False}
        Fit each push's preload (the contact displacement already made when recording began; a
        nuisance in [0, 0.1 L], docs/diagnose.md). ``"auto"`` (default): when some push starts
        loaded (its first force above 5 noise sd and 2% of its peak, the dataset check's rule); a
        push's preload shifts its frames' contact displacements as it shifts its forces'.
    length : {"known", "unknown", "auto"}
        The stem length L: ``"known"`` (default) holds it at the dataset's, with a warning when
        specimen.json marks it approximate; ``"unknown"`` fits it in every model as a nuisance within
        the support of the fit's default length prior (uniform on [L/1.5, 1.5 L] of the dataset's
        length, above the highest contact; forces only); ``"auto"``: unknown when specimen.json marks
        the length approximate (``length_m_approximate``, as the blueberry importer does) and the
        diagnosis uses forces only. Why the default holds it (docs/diagnose.md): on the 18 blueberry
        canes fitting it changed no verdict and moved held-out errors by a few percent, and each fit
        is slower (a plain fit 4x: two heights leave L and p on a nearly flat ridge).
    height_sd_m : float
        The sd [m] of each push's contact-height error (default 0: the recorded heights are exact). With
        sd > 0 every model fits one error per push with forces, penalised by its normal prior and cut
        at 4 sd (as ``fit``'s ``height_sd_m``); frames of the push move with it; a held-out push is
        predicted at its recorded height. A height known to a few mm moves the forces of a 0.3 m push by
        about 3 dh / h (3% at 3 mm), as a stiffer or softer stem would.
    n_workers : int
        Processes the candidate fits and the held-out refits are spread over (default 1: none
        started; the result does not depend on it). A 3-height twig with a missing base spring
        takes 152 s with 1 and 86 s with 2 on two cores (docs/performance.md).
    """
    from ._common import as_dataset

    spec = as_dataset(dataset)
    candidates = tuple(candidates)
    bad = [c for c in candidates if c not in CATALOG]
    if bad or not candidates:
        raise ValueError(
            f"candidates: expected effects from {', '.join(CATALOG)}, got {', '.join(candidates) or 'none'}"
        )
    for name, v in (("alpha", alpha), ("heldout_alpha", heldout_alpha)):
        if not (0 < v < 1):
            raise ValueError(f"{name}: expected a level in (0, 1), got {v}")
    if force_noise not in ("ar1", "iid"):
        raise ValueError(f"force_noise: expected 'ar1' or 'iid', got {force_noise!r}")
    if not (isinstance(n_workers, int) and not isinstance(n_workers, bool) and n_workers >= 1):
        raise ValueError(f"n_workers: expected an integer of at least 1, got {n_workers!r}")
    if preload not in ("auto", True, False):
        raise ValueError(f"preload: expected 'auto', True or False, got {preload!r}")
    if length not in ("auto", "known", "unknown"):
        raise ValueError(f"length: expected 'auto', 'known' or 'unknown', got {length!r}")
    data = prepare_data(spec, use_forces=True, use_shapes=use_shapes)
    shapes_used = any(d.x_m.size for d in data)
    if length == "unknown" and shapes_used:
        raise ValueError(
            "length: expected a force-only diagnosis (use_shapes=False) to fit an unknown stem length, got centerlines"
        )
    approximate = length_is_approximate(spec)
    fit_length = length == "unknown" or (length == "auto" and approximate and not shapes_used)
    if approximate and not fit_length:
        log.warning(
            "warning: %s: length_m %g m is marked approximate but stays fixed (%s)",
            spec.specimen,
            spec.length_m,
            "centerlines are used; diagnose with forces only to fit it"
            if shapes_used and length != "known"
            else "diagnose with length 'unknown' to fit it in every model",
        )
    length_bounds = default_length_prior(spec).bounds() if fit_length else None
    loaded = [p.id for p in spec.pushes if starts_loaded(p.force.force_N)]
    use_preload = bool(loaded) if preload == "auto" else bool(preload)
    if loaded and not use_preload:
        log.warning(
            "pushes %s start loaded but their preload is not fitted (preload=False): expect structure at the start",
            ", ".join(loaded),
        )
    model = ForwardModel(
        data, spec.length_m, preload=use_preload, length_bounds_m=length_bounds, height_sd_m=height_sd_m
    )
    res = diagnose_model(
        model,
        candidates=candidates,
        alpha=alpha,
        min_heldout_gain=min_heldout_gain,
        heldout_alpha=heldout_alpha,
        force_noise=force_noise,
        workers=n_workers,
        log=lambda msg: log.info("%s", msg),
    )
    fit_after, plain = res.pop("_fit"), res.pop("_plain")
    doc = {
        "specimen": spec.specimen,
        "dataset": str(Path(spec.root).resolve()) if spec.root is not None else None,
        "length_m": spec.length_m,
        "observations": {"n_force": model.n_force, "n_shape_points": model.n_points},
        **res,
        "settings": {
            "alpha": alpha,
            "min_heldout_gain": min_heldout_gain,
            "heldout_alpha": heldout_alpha,
            "force_noise": force_noise,
            "candidates": list(candidates),
            "preload": use_preload,
            "pushes_starting_loaded": loaded,
            "length": "unknown" if fit_length else "known",
            "length_bounds_m": list(length_bounds) if fit_length else None,
            "height_sd_m": model.height_sd_m,
        },
    }
    truth = spec.extra.get("truth")
    if truth:
        doc["truth"] = truth
    doc = plain_json(doc)
    return Diagnosis(MappingProxyType(doc), model, plain, fit_after)

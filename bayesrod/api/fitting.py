"""``bayesrod.fit``: the posterior of EI0, p and noise for one dataset, as an immutable :class:`Posterior`.

Computing never writes: :func:`fit` returns a :class:`Posterior`; only
:meth:`Posterior.save` and :meth:`Posterior.report` touch the disk (and the
optional ``checkpoint`` file, which the user names so that a long run can be
resumed). A run directory written by :meth:`Posterior.save` holds
``config.json`` (what was asked), ``posterior.nc`` (ArviZ), ``samples.npz``
(thinned natural-unit draws), ``summary.json`` (docs/format.md), ``figures/``
and ``report.html``.
"""

from __future__ import annotations

import copy
import json
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._version import __version__
from ..dataset.model import Specimen
from ..dataset.plausibility import starts_loaded
from ..inference.likelihood import (
    LogPosterior,
    between_nodes,
    build_likelihood,
    check_workers,
    effective_shape_weight,
    geometry_blocker,
    length_is_approximate,
    p_zoom_window,
    table_check,
    table_workers,
    zoom_window,
)
from ..inference.priors import load_prior
from ..inference.sampler import convergence_message, find_start, run_ensembles
from ..inference.summary import (
    build_summary,
    credible_interval,
    draw_lengths,
    predictive_forces,
    to_inference_data,
)
from ..physics import flexural_rigidity, k_theta, k_x
from ._common import as_dataset, interval, plain_json, progress_enabled, readonly
from .bands import Band, ForceBand

log = logging.getLogger("bayesrod")

#: the fit options a checkpoint must share with the run it resumes
_RESUME_KEYS = (
    "dataset",
    "prior",
    "effects",
    "seed",
    "use_forces",
    "use_shapes",
    "shape_weight",
    "force_noise",
    "preload",
    "length",
    "height_sd_m",
    "force_offsets",
    "noise_coordinates",
    "noise_sd_prior",
    "base_coordinates",
    "stiffness_coordinates",
    "slip",
)
#: what a checkpoint written before an option existed meant by it
_RESUME_DEFAULTS = {
    "force_noise": "iid",
    "preload": False,
    "length": "known",
    "height_sd_m": 0.0,
    "force_offsets": False,
    # before 2026-11-26 an AR(1) noise was sampled by its marginal sd; its chains cannot be resumed
    "noise_coordinates": "marginal_sd",
    # before session 53 (2026-11-29) an AR(1) noise's sd prior was the marginal sd's (another target)
    "noise_sd_prior": "marginal_sd",
    # before 2026-11-27 a base spring was sampled in log k; its chains cannot be resumed
    "base_coordinates": "log_k",
    # before 2026-11-27 (session 34) EI0 was sampled as log EI0 also at one height; such chains cannot be resumed
    "stiffness_coordinates": "log_EI0",
    # before 2026-11-26 the likelihood had no slip term
    "slip": False,
}


def _likelihood_options(config: Mapping) -> dict:
    """The likelihood keywords of a fit's config (a loaded run's too)."""
    return {
        "use_forces": config.get("use_forces", True),
        "use_shapes": config.get("use_shapes", True),
        "force_noise": config.get("force_noise", "iid"),
        "preload": config.get("preload", False),
        "length": config.get("length", "known"),
        "height_sd_m": config.get("height_sd_m", 0.0),
        "force_offsets": config.get("force_offsets", False),
        "diameter": config.get("diameter", "off"),
        "slip": config.get("slip", False),
        "effect_window": config.get("effect_window"),
        "p_window": config.get("p_window"),
    }


@dataclass(frozen=True, eq=False)
class Posterior:
    """Posterior draws of one fit, immutable.

    Attributes
    ----------
    samples : Mapping[str, ndarray]
        Every post-burn-in draw in natural units, shape (n_draws,) each, read-only:
        ``EI0`` [N m^2], ``p`` [-], the noise terms and the fitted effects by name.
    idata : arviz.InferenceData
        The same draws as chains (walkers of all ensembles) x draws, with ``sample_stats.lp``.
    length_m : float
        The stem length L the fit assumed [m].
    specimen : str
        The dataset's specimen name.
    effects : tuple of str
        The model effects fitted (docs/model.md).
    config : Mapping
        What was asked (prior, effects, seed, data used, ...).
    dataset : Specimen or None
        The data fitted (None when a saved run's dataset is no longer on disk).
    """

    samples: Mapping[str, NDArray]
    idata: Any = field(repr=False)
    length_m: float
    specimen: str
    effects: tuple[str, ...]
    config: Mapping = field(repr=False)
    doc: Mapping = field(repr=False)
    dataset: Specimen | None = field(default=None, repr=False)
    likelihood: Any = field(default=None, repr=False)
    direct: Any = field(default=None, repr=False)
    draws_are_thinned: bool = field(default=False, repr=False)

    # ------------------------------------------------------------------ numbers
    def to_dict(self) -> dict:
        """The content of ``summary.json`` (docs/format.md), a fresh copy."""
        return copy.deepcopy(dict(self.doc))

    def summary(self, level: float = 0.9):
        """One row per sampled parameter: mean, sd, median, equal-tailed interval at ``level``, R-hat, bulk ESS.

        Returns a :class:`pandas.DataFrame` indexed by parameter name; the interval columns are named
        ``q05``/``q95`` for ``level=0.9`` (``q025``/``q975`` for 0.95, ...) and ``df.attrs["level"]`` holds it.
        """
        import pandas as pd

        level = _check_level(level)
        lo_name, hi_name = _q_names(level)
        conv = self.doc.get("convergence", {})
        rows = {}
        for name in self.doc["parameters"]:
            x = self.samples[name]
            lo, med, hi = interval(x, level)
            rows[name] = {
                "mean": float(np.mean(x)),
                "sd": float(np.std(x, ddof=1)),
                "median": float(med),
                lo_name: float(lo),
                hi_name: float(hi),
                "r_hat": conv.get("rhat", {}).get(name, np.nan),
                "ess_bulk": conv.get("ess_bulk", {}).get(name, np.nan),
            }
        df = pd.DataFrame.from_dict(rows, orient="index")
        df.attrs["level"] = level
        return df

    def thinned(self, n: int = 4000) -> dict[str, NDArray]:
        """A fixed random subset of ``n`` draws (seeded by the fit's seed): the draws ``samples.npz`` holds."""
        m = self.samples["EI0"].size
        if self.draws_are_thinned and m <= n:  # loaded from samples.npz alone: these are the thinned draws
            return dict(self.samples)
        keep = np.random.default_rng(int(self.config.get("seed", 0))).choice(m, size=min(n, m), replace=False)
        return {k: v[keep] for k, v in self.samples.items()}

    def _base_stiffness(self):
        """Fitted base spring [N m/rad] per draw (the ``base_compliance`` effect), or inf for a clamp."""
        kb = self.samples.get("base_compliance")
        return np.inf if kb is None else np.asarray(kb)[:, None]

    def ei_band(self, s_m: ArrayLike, level: float = 0.9) -> Band:
        """EI(s) (eq. EI_taper) over arc lengths ``s_m`` [m], shape (m,): median and equal-tailed band [N m^2]."""
        level = _check_level(level)
        s = _grid(s_m, "s_m", 0.0, self.length_m, closed=True)
        L = draw_lengths(self.samples, self.length_m)
        EI = flexural_rigidity(s[None, :], self.samples["EI0"][:, None], self.samples["p"][:, None], L)
        return Band(s, *interval(EI, level), level=level, x_name="s_m", unit="N m^2")

    def youngs_modulus(self) -> NDArray:
        """Young's modulus at the base per draw [Pa], E0 = 64 EI0 / (pi d0^4), shape (n_draws,).

        Needs a fit with measured diameters (``diameter="shared"`` or ``"free"``); raises ValueError otherwise.
        """
        from ..inference.summary import youngs_modulus

        return youngs_modulus(self.samples)

    def modulus_band(self, s_m: ArrayLike, level: float = 0.9) -> Band:
        """E(s) [Pa] over arc lengths ``s_m`` [m], shape (m,): E0 (1 - s/L)^(4 (p - p_geom)); flat under the
        uniform-modulus model (``diameter="shared"``); NaN where every draw's stem has ended (s >= L), and
        beyond a draw's own tip that draw is left out (a sampled length)."""
        from ..inference.summary import modulus_draws

        level = _check_level(level)
        s = _grid(s_m, "s_m", 0.0, self.length_m, closed=True)
        E = modulus_draws(self.samples, self.length_m, s)
        return Band(s, *interval(E, level), level=level, x_name="s_m", unit="Pa")

    def diameter_band(self, s_m: ArrayLike, level: float = 0.9) -> Band:
        """The fitted diameter d(s) = d0 (1 - s/L)^q [m] over arc lengths ``s_m`` [m], shape (m,) (q = p_geom
        under ``diameter="free"``, else p); needs a fit with measured diameters."""
        from ..inference.summary import diameter_draws

        level = _check_level(level)
        s = _grid(s_m, "s_m", 0.0, self.length_m, closed=True)
        return Band(
            s, *interval(diameter_draws(self.samples, self.length_m, s), level), level=level, x_name="s_m", unit="m"
        )

    def k_theta_band(self, height_m: ArrayLike, level: float = 0.9) -> Band:
        """Lumped rotational stiffness k_theta(h) (eq. kdist) over heights ``height_m`` [m], shape (m,) [N m/rad]."""
        return self._stiffness_band(k_theta, height_m, level, "N m/rad")

    def _stiffness_band(self, fn, height_m, level, unit: str) -> Band:
        """A lumped stiffness ``fn`` (k_theta or k_x, base spring in series) over heights, as a Band."""
        level = _check_level(level)
        h = _grid(height_m, "height_m", 0.0, self.length_m)
        k = fn(
            h[None, :],
            self.samples["EI0"][:, None],
            self.samples["p"][:, None],
            draw_lengths(self.samples, self.length_m),
            self._base_stiffness(),
        )
        return Band(h, *interval(k, level), level=level, x_name="height_m", unit=unit)

    def k_x_band(self, height_m: ArrayLike, level: float = 0.9) -> Band:
        """Small-deflection translational stiffness k_x(h) (eq. kx) over ``height_m`` [m], shape (m,) [N/m]."""
        return self._stiffness_band(k_x, height_m, level, "N/m")

    def predict_force(
        self, height_m: float, displacement_m: ArrayLike, level: float = 0.9, n_draws: int = 400, seed: int = 0
    ) -> ForceBand:
        """Posterior-predictive contact force at a contact height (pushed or not) [N].

        Parameters
        ----------
        height_m : float
            Contact height h [m], 0 < h < L.
        displacement_m : array_like, shape (m,)
            Horizontal contact displacements since first contact [m], >= 0.
        level : float
            Credible level of the band (equal-tailed).
        n_draws : int
            Posterior draws pushed through the elastica (a fixed random subset, ``seed``).

        Returns
        -------
        ForceBand
            ``lower``, ``median``, ``upper`` of the force where the stem still holds the sensor (NaN where
            fewer than two draws do), and ``slip_probability`` per displacement.
        """
        level = _check_level(level)
        h = float(_grid([height_m], "height_m", 0.0, self.length_m)[0])
        D = np.atleast_1d(np.asarray(displacement_m, dtype=float))
        if D.ndim != 1 or not np.all(np.isfinite(D)) or np.any(D < 0):
            raise ValueError(f"displacement_m: expected finite values >= 0 m in one dimension, got {D!r}")
        if not (isinstance(n_draws, (int, np.integer)) and n_draws >= 2):
            raise ValueError(f"n_draws: expected an integer >= 2, got {n_draws!r}")
        n = self.samples["EI0"].size
        idx = np.random.default_rng(seed).choice(n, size=min(n_draws, n), replace=False)
        pred = predictive_forces(self.samples, idx, D, h, self.length_m)
        F = pred["force_N"]
        enough = np.isfinite(F).sum(axis=0) >= 2
        lo, med, hi = (np.where(enough, q, np.nan) for q in interval(F, level))
        return ForceBand(
            D,
            lo,
            med,
            hi,
            level=level,
            x_name="displacement_m",
            unit="N",
            height_m=h,
            slip_probability=pred["slipped"].mean(axis=0),
        )

    # ------------------------------------------------------------------ plots
    def plot_ei(self, ax=None, truth: dict | None = None):
        """EI(s) median and 90% band (with the seed's direct estimate when shapes were fitted); returns the artists."""
        from ..report.plots import plot_ei_band

        return plot_ei_band(
            self.samples, self.length_m, ax=ax, truth=truth or self.doc.get("truth"), direct=self.direct
        )

    def plot_k_theta(self, ax=None):
        """k_theta(h) median and 90% band, pushed heights marked; returns the artists."""
        from ..report.plots import plot_k_theta_band

        heights = self.doc.get("data", {}).get("heights_m", [])
        return plot_k_theta_band(self.samples, self.length_m, heights, ax=ax)

    def plot_forces(self, ax=None, unseen_height: float | None = None):
        """Measured forces with posterior 90% bands per height (and at ``unseen_height``); returns the artists."""
        from ..report.plots import plot_force_fit

        lik = self._require_likelihood("plot_forces")
        return plot_force_fit(self.dataset, lik, self.samples, ax=ax, unseen_height=unseen_height)

    def plot_residuals(self, axes=None):
        """Force and shape residuals at the posterior median (two axes); returns the artists."""
        from ..report.plots import plot_residuals

        lik = self._require_likelihood("plot_residuals")
        return plot_residuals(lik, self._median(), axes=axes)

    def plot_corner(self, fig=None, names: Sequence[str] = ("EI0", "p")):
        """Corner plot of ``names``; returns the figure."""
        from ..report.plots import plot_corner

        return plot_corner(self.samples, names=tuple(names), truth=self.doc.get("truth"), fig=fig)

    def plot_rank(self, axes=None):
        """Rank histograms per independent ensemble for EI0 and p; returns the drawn lines."""
        from ..report.plots import plot_rank

        return plot_rank(self.idata, self.doc.get("sampler", {}).get("ensembles", 4), axes=axes)

    def _median(self) -> dict:
        return {k: float(np.median(v)) for k, v in self.samples.items()}

    def _lik(self):
        """The likelihood of the fitted data: kept from the fit, or rebuilt once for a loaded run (None if the
        run's dataset is no longer readable)."""
        if self.likelihood is None and self.dataset is not None:
            try:
                lik = build_likelihood(
                    self.dataset, load_prior(self.config.get("prior")), self.effects, **_likelihood_options(self.config)
                )
            except ValueError:
                return None
            if "shape_weight" in self.doc.get("data", {}):
                lik.shape_weight = self.doc["data"]["shape_weight"]
            object.__setattr__(self, "likelihood", lik)  # a cache: the fit's numbers do not change
        return self.likelihood

    def _require_likelihood(self, what: str):
        lik = self._lik()
        if lik is None:
            raise ValueError(
                f"{what}: expected the fitted dataset, got a saved run whose dataset "
                f"{self.config.get('dataset')!r} is not on disk"
            )
        return lik

    # ------------------------------------------------------------------ files
    def figures(self) -> dict[str, bytes]:
        """The report's figures as PNG bytes, by name (nothing written)."""
        from ..report.figures import render

        sub = {k: v[:: max(1, len(v) // 2000)] for k, v in self.samples.items()}
        truth = self.doc.get("truth")
        heights = self.doc.get("data", {}).get("heights_m", [])
        lik = self._lik()
        from ..report.plots import plot_ei_band, plot_force_fit, plot_k_theta_band, plot_rank

        out = {
            "ei_band": render(
                lambda ax: plot_ei_band(sub, self.length_m, ax=ax, truth=truth, direct=self.direct), 6.4, 4.2, dpi=110
            ),
            "k_theta_band": render(
                lambda ax: plot_k_theta_band(sub, self.length_m, heights, ax=ax, lumped=_lumped_points(lik)),
                6.4,
                4.2,
                dpi=110,
            ),
        }
        if lik is not None:
            out["force_fit"] = render(
                lambda ax: plot_force_fit(
                    self.dataset, lik, sub, ax=ax, unseen_height=unseen_height(heights, self.length_m)
                ),
                6.4,
                4.2,
                dpi=110,
            )
        from ..report.figures import png_bytes

        out["corner"] = png_bytes(self._corner_figure(sub, truth), dpi=90)
        if lik is not None:
            from ..report.plots import plot_residuals

            med = self._median()
            out["residuals"] = render(lambda axes: plot_residuals(lik, med, axes=axes), 10, 3.6, ncols=2)
        dm = getattr(self.dataset, "diameters", None) if self.dataset is not None else None
        if dm is not None and "d0_m" in sub:
            from ..report.plots import plot_diameter_fit

            if "p_geom" in sub:  # the modulus may vary along s: E(s) beside the widths
                out["diameter_fit"] = render(
                    lambda axes: plot_diameter_fit(sub, self.length_m, dm, ax=axes[0], modulus_ax=axes[1]),
                    10,
                    3.8,
                    ncols=2,
                )
            else:
                out["diameter_fit"] = render(
                    lambda ax: plot_diameter_fit(sub, self.length_m, dm, ax=ax), 6.4, 4.2, dpi=110
                )
        n_ens = self.doc.get("sampler", {}).get("ensembles", 4)
        out["rank"] = render(lambda axes: plot_rank(self.idata, n_ens, axes=axes), 10, 3.4, ncols=2)
        return out

    @staticmethod
    def _corner_figure(sub, truth):
        from matplotlib.figure import Figure

        from ..report.plots import plot_corner

        return plot_corner(sub, truth=truth, fig=Figure(figsize=(5, 5)))

    def report_html(self, pngs: dict[str, bytes] | None = None) -> str:
        """The HTML report as a string, figures embedded (``pngs``: figures already rendered, else rendered here)."""
        from ..report.html import fit_report

        prov = self.dataset.extra.get("provenance") if self.dataset is not None else None
        pngs = self.figures() if pngs is None else pngs
        return fit_report(self.to_dict(), pngs, provenance=prov, source=str(self.config.get("dataset")))

    def report(self, path) -> Path:
        """Write the self-contained HTML report to ``path`` (atomically); returns the path."""
        from ..dataset.io import write_text_atomic

        path = Path(path)
        write_text_atomic(path, self.report_html())
        return path

    def save(self, path, *, overwrite: bool = False, figures: bool = True) -> Path:
        """Write the run directory ``path`` (docs/format.md): every file atomically.

        An existing directory that already holds a saved fit (``summary.json``) is refused unless
        ``overwrite``. Returns the path.
        """
        from ..dataset.io import OutputExistsError, write_bytes_atomic, write_json

        path = Path(path)
        if path.exists() and not path.is_dir():
            raise ValueError(f"path: expected a directory, got {path} which is a file")
        if (path / "summary.json").exists() and not overwrite:
            raise OutputExistsError(path)
        path.mkdir(parents=True, exist_ok=True)
        write_json(path / "config.json", {k: v for k, v in self.config.items() if k != "run"})
        write_bytes_atomic(path / "posterior.nc", _netcdf_bytes(self.idata, path))
        import io

        buf = io.BytesIO()
        # ``length_m`` stays the given stem length (a scalar, docs/format.md); a sampled length's draws
        # are stored as ``length_m_sampled``
        draws = {("length_m_sampled" if k == "length_m" else k): v for k, v in self.thinned().items()}
        np.savez(buf, length_m=self.length_m, **draws)
        write_bytes_atomic(path / "samples.npz", buf.getvalue())
        write_json(path / "summary.json", self.to_dict())
        if figures:
            pngs = self.figures()
            for name, data in pngs.items():
                write_bytes_atomic(path / "figures" / f"{name}.png", data)
            from ..dataset.io import write_text_atomic

            write_text_atomic(path / "report.html", self.report_html(pngs))
        return path

    @classmethod
    def load(cls, path) -> Posterior:
        """A run directory written by :meth:`save` (or by ``bayesrod fit`` of any earlier version)."""
        from ..dataset import read_dataset
        from ..inference.summary import import_arviz

        path = Path(path)
        has_nc, has_npz = (path / "posterior.nc").is_file(), (path / "samples.npz").is_file()
        if not (has_nc or has_npz):
            raise ValueError(f"{path}: expected a fit run directory holding posterior.nc or samples.npz, found none")
        doc = {}
        if (path / "summary.json").is_file():
            try:
                doc = json.loads((path / "summary.json").read_text())
            except json.JSONDecodeError as e:
                raise ValueError(
                    f"{path / 'summary.json'}: expected JSON, got a parse error at line {e.lineno}"
                ) from None
        elif has_nc:
            raise ValueError(f"{path}: expected a fit run directory holding summary.json, found none")
        config = json.loads((path / "config.json").read_text()) if (path / "config.json").is_file() else {}
        config["run"] = str(path.resolve())
        az = import_arviz()
        if has_nc:
            idata = az.from_netcdf(str(path / "posterior.nc"))
            idata.load()
            samples = {k: readonly(idata.posterior[k].values.reshape(-1)) for k in idata.posterior.data_vars}
        else:  # a minimal run: the thinned draws only
            with np.load(path / "samples.npz") as z:
                samples = {
                    ("length_m" if k == "length_m_sampled" else k): readonly(z[k]) for k in z.files if k != "length_m"
                }
                length = float(z["length_m"])
            idata = az.from_dict(posterior={k: v[None, :] for k, v in samples.items()})
            doc = doc or {
                "specimen": path.name,
                "length_m": length,
                "effects": [],
                "parameters": {k: credible_interval(x) for k, x in samples.items()},
            }
        effects = tuple(doc.get("effects", ()))
        spec = None
        ds = config.get("dataset")
        if ds and Path(ds).is_dir():
            try:
                spec = read_dataset(ds)
            except ValueError:
                spec = None
        return cls(
            samples=MappingProxyType(samples),
            idata=idata,
            length_m=float(doc.get("length_m", idata.posterior.attrs.get("length_m"))),
            specimen=str(doc["specimen"]),
            effects=effects,
            config=MappingProxyType(config),
            doc=MappingProxyType(doc),
            dataset=spec,
            draws_are_thinned=not has_nc,
        )


def _netcdf_bytes(idata, near: Path) -> bytes:
    """posterior.nc as bytes (netCDF writers want a file name: a temporary one beside the target)."""
    import os
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=".posterior.", suffix=".nc", dir=near)
    os.close(fd)
    try:
        idata.to_netcdf(tmp)
        return Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)


def _check_level(level) -> float:
    try:
        lv = float(level)
    except (TypeError, ValueError):
        lv = float("nan")
    if not 0 < lv < 1:
        raise ValueError(f"level: expected a credible level in (0, 1), got {level!r}")
    return lv


def _q_names(level: float) -> tuple[str, str]:
    """Column names of the interval's quantiles: the digits of the fraction, at least two (0.05 -> ``q05``,
    0.025 -> ``q025``, 0.1 -> ``q10``), so that no name of one level is another quantile's."""

    def name(q):
        return "q" + f"{q:.10f}".rstrip("0").split(".")[1].ljust(2, "0")

    return name((1 - level) / 2), name((1 + level) / 2)


def _grid(x, name: str, low: float, high: float, closed: bool = False) -> NDArray:
    arr = np.atleast_1d(np.asarray(x, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a number or a 1-d array, got shape {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < low) | (arr > high) | (((arr == low) | (arr == high)) & (not closed))
    if np.any(bad):
        op = "<=" if closed else "<"
        raise ValueError(f"{name}: expected {low:g} {op} value {op} L = {high:g} m, got {arr[bad][0]:g}")
    return arr


def unseen_height(heights_m, length_m: float) -> float:
    """A height never pushed, for the posterior-predictive panel: midway in the widest gap between pushes."""
    hs = np.sort(np.unique(heights_m))
    if hs.size < 2:
        return round(float(min(1.15 * hs[0], 0.5 * (hs[0] + length_m))), 3)
    k = int(np.argmax(np.diff(hs)))
    return round(float(0.5 * (hs[k] + hs[k + 1])), 3)


def _lumped_points(lik) -> list:
    """Per-height k_theta from the torque balance on the linear region (the seed's lumped branch)."""
    from ..physics.lumped import fit_torque_balance, link_angle

    pts = []
    for d in getattr(lik, "data", ()):
        if d.D_m.size >= 3:
            try:
                pts.append(
                    (d.height_m, fit_torque_balance(link_angle(d.D_m, d.height_m), d.F_N, d.height_m)["k_theta"])
                )
            except ValueError:
                continue
    return pts


def _assumptions(spec, lik=None) -> list[str]:
    a = [
        "A1 planar bending in one vertical plane",
        "A2 quasi-static loading",
        "A3 inextensible, unshearable rod",
        "A4 linear elastic, EI(s) = EI0 (1 - s/L)^(4p)",
        "A5 single horizontal point force at the sensor height",
        "A6 base clamped and vertical, tip free",
        f"stem length L = {spec.length_m:g} m",
    ]
    if lik is not None and lik.length_prior is not None:
        lo, hi = lik.length_prior.bounds()
        prior = f"{lik.length_prior.dist} on [{lo:.3g}, {hi:.3g}] m"
        a[-1] = f"stem length L sampled: prior {prior} (given {spec.length_m:g} m)"
    elif length_is_approximate(spec):
        a[-1] += " (marked approximate, held fixed in this fit)"
    if lik is not None and lik.height_sd_m > 0:
        a.append(f"contact height of each push uncertain: error N(0, {1000 * lik.height_sd_m:g} mm) sampled")
    if lik is not None and lik.force_offsets:
        a.append("load-cell offset per push sampled: N(0, 5% of the push's peak force)")
    prov = spec.extra.get("provenance", {})
    for k, v in (prov.get("assumptions") or {}).items():
        a.append(f"{k}: {v}")
    return a


def _two_stage(spec, use_shapes: bool) -> tuple[dict | None, object]:
    """The seed's deterministic estimate, when the data allow it (shapes with enough points)."""
    from ..inference.direct import two_stage_fit

    if not use_shapes or not any(p.shapes for p in spec.pushes):
        return None, None
    try:
        ts = two_stage_fit(spec)
    except ValueError as e:
        log.info("two-stage estimate skipped: %s", e)
        return None, None
    log.info("two-stage (seed) estimate: EI0 = %.4g N m^2, p = %.4g (R^2 %.3f)", ts.EI0, ts.p, ts.r2)
    return ts.to_dict(), ts.direct


#: table_check: the largest shift [Laplace sd] the likelihood tables may cause before a fit warns
TABLE_SHIFT_WARN_SD = 0.1


def table_warning(check: dict) -> str | None:
    """The warning a fit gives (summary.json ``table_check.message``) when its table check ``check``
    (:func:`~bayesrod.inference.likelihood.table_check` at the posterior median) moves some parameter's estimate
    by more than :data:`TABLE_SHIFT_WARN_SD` Laplace sd; None where none does."""
    worst = max((abs(v) for v in check["shift_in_sd"].values()), default=0.0)
    if worst <= TABLE_SHIFT_WARN_SD:
        return None
    return (
        f"the likelihood tables, against exact solves at the posterior median, would move the estimate "
        f"by {worst:.2g} sd (at most {TABLE_SHIFT_WARN_SD:g} expected): the intervals are "
        "less exact than they look; report it (docs/validation.md, 'Likelihood tables against exact solves')"
    )


def sampling_coordinates(force_noise: str, effects, one_height: bool = False) -> dict:
    """The coordinates the sampler moves the force noise, a base spring and EI0 in (ParameterSpace): an AR(1)
    noise by its innovation sd (since 2026-11-26), a base spring on forces alone by its table coordinate u
    where the start's spring is stiff (since 2026-11-27; ``ParameterSpace.settle_base_coordinates``), EI0 by the
    log stiffness at the pushes' height when they are all at one (``one_height``: ``ParameterSpace.stiffness_at``,
    since session 34); and where an AR(1) noise's sd prior sits (``noise_sd_prior``: on the innovation sd since
    session 53, a different target from the marginal sd's before). A checkpoint records them; chains in others
    cannot be resumed."""
    noise_sd = "innovation_sd" if force_noise == "ar1" else "marginal_sd"  # sampled by it; its prior on it
    return {
        "noise_coordinates": noise_sd,
        "noise_sd_prior": noise_sd,
        "base_coordinates": "u_forces_only_stiff_start" if "base_compliance" in effects else "log_k",
        "stiffness_coordinates": "log_k_at_height" if one_height else "log_EI0",
    }


#: _zoom_edge: the share of a narrowed effect axis next to each of its inner ends whose draws are counted
ZOOM_EDGE_SHARE = 0.02


def _worst_shift(check: dict | None) -> float:
    """The largest |shift| [Laplace sd] of a table check (inf without one)."""
    return max((abs(v) for v in check["shift_in_sd"].values()), default=0.0) if check else float("inf")


def _worse(*checks: dict | None) -> dict | None:
    """The table check with the largest |shift| of those given (None when none is)."""
    made = [c for c in checks if c is not None]
    return max(made, key=_worst_shift) if made else None


def _check_between_nodes(lik, point: dict) -> tuple[dict | None, dict | None, dict | None]:
    """:func:`table_check` at ``point`` and at ``point`` with its effect moved to the middle of the node interval
    that holds it (:meth:`EffectAxis.between_nodes`): cubic interpolation in u is exact at a node, so a point
    near one checks well however coarse the axis (base tilt on 5 nodes: 0.038 sd at a node, 9.2 sd between two;
    the suspected reason friction SBC seed 7's start passed while its median read 1.8 sd). Returns the two
    checks (None where one cannot be made, the second also without a tabled effect; the second with its ``u``)
    and the worse of them; raises ValueError where the first cannot be made (an exact solve the tables never
    needed)."""
    at = table_check(lik, point)
    if at is None or lik.axis is None:  # forces not read from the plain tables, or no effect axis
        return at, None, at
    u0 = float(lik.effect_coordinate(point)[0])
    um = lik.axis.between_nodes(u0)
    moved = point | {lik.axis.name: float(lik.axis.value(um, point["EI0"], lik.L))}
    try:
        between = table_check(lik, moved) if lik.in_table(moved)[0] else None
    except ValueError:
        between = None
    between = None if between is None else between | {"u": um}
    return at, between, _worse(at, between)


def _check_between_p_nodes(lik, point: dict) -> dict | None:
    """:func:`table_check` at ``point`` with p moved to the middle of the p-node interval that holds it (with its
    ``p``): the 4-point interpolation in p is exact at a node, as the effect's is (:func:`_check_between_nodes`).
    None where it cannot be made."""
    pm = between_nodes(lik.p_grid, float(point["p"]))
    try:
        check = table_check(lik, point | {"p": pm})
    except ValueError:
        return None
    return None if check is None else check | {"p": pm}


def zoom_decision(lik, point: dict) -> tuple[dict, dict | None, dict]:
    """The fit's rule for narrowing its tables at ``point`` (natural units, scalars): :func:`table_check` there,
    with the effect moved between its nodes (:func:`_check_between_nodes`) and with p moved between its nodes
    (:func:`_check_between_p_nodes`); the worst of them decides (:func:`zoom_window`, :func:`p_zoom_window`).
    Returns (the record for summary.json's ``table_check.at_start``, the deciding check or None where none could
    be made, ``{"effect_window": (lo, hi) or None, "p_window": (lo, hi) or None}``). Also read by
    ``scripts/table_shift_sbc_case.py --zoom``."""
    at_start = {} if lik.axis is None else {"u": float(lik.effect_coordinate(point)[0])}
    none = {"effect_window": None, "p_window": None}
    try:
        at, between, worse = _check_between_nodes(lik, point)
    except ValueError:  # an exact solve the tables never needed: the post-sampling check says so
        return at_start, None, none
    if at is None:
        return at_start, None, none
    at_start["shift_in_sd"] = at["shift_in_sd"]
    if between is not None:
        at_start["between_nodes"] = {"u": between["u"], "shift_in_sd": between["shift_in_sd"]}
    between_p = _check_between_p_nodes(lik, point)
    if between_p is not None:
        at_start["between_p_nodes"] = {"p": between_p["p"], "shift_in_sd": between_p["shift_in_sd"]}
    before = _worse(worse, between_p)
    windows = {"effect_window": zoom_window(lik, point, before), "p_window": p_zoom_window(lik, point, before)}
    return at_start, before, windows


def _zoom_tables(spec, pr, effects, config: dict, post, theta0: NDArray) -> tuple[dict, tuple | None]:
    """Narrow the p grid and the effect axis around the start point where the tables are too coarse there
    (:func:`p_zoom_window`, :func:`zoom_window`).

    The tables are checked at the start and, with its effect, then its p, moved to the middle of their node
    intervals, where the interpolation is least exact (:func:`_check_between_nodes`,
    :func:`_check_between_p_nodes`); the worst of the three decides. Each axis whose window rule allows it is
    narrowed, both in one table build. The windows are centred on the start, which stays the start. Returns
    (the start's record for summary.json's ``table_check.at_start``: with an effect axis its table coordinate
    ``u``, where the check could be made its ``shift_in_sd``, ``between_nodes`` (the check in the middle of the
    effect's node interval, ``{u, shift_in_sd}``) and ``between_p_nodes`` (``{p, shift_in_sd}``); then None
    where the tables stay, else (the zoom's records for ``table_check``, ``effect_axis_zoom`` and
    ``p_axis_zoom`` for the axes narrowed, the likelihood, posterior and start point to sample with)). The
    narrowed tables are kept only when the worst of their checks improves on the worst of the first's, and
    ``config["effect_window"]`` and ``config["p_window"]`` then record them (a saved run rebuilds the same
    tables).
    """
    lik = post.likelihood
    point = {k: float(v[0]) for k, v in post.to_natural(theta0[None]).items()}
    at_start, before, windows = zoom_decision(lik, point)
    if not any(windows.values()):
        return at_start, None
    log.info(
        "%s: the tables would move the start by %.2g sd; building them again over %s%s",
        spec.specimen,
        _worst_shift(before),
        ", ".join(f"{k} [{w[0]:.4g}, {w[1]:.4g}]" for k, w in windows.items() if w),
        " (as long as the first build: contact friction)" if "contact_friction" in effects else "",
    )
    options = _likelihood_options(config) | {k: w for k, w in windows.items() if w}
    if windows["effect_window"]:
        options["n_effect"] = lik.axis.grid.size
    zlik = build_likelihood(spec, pr, effects, **options)
    zlik.shape_weight = lik.shape_weight
    zpost = LogPosterior(zlik, pr)
    ztheta = zpost.to_sample(point)[0]
    after = zoom_decision(zlik, point)[1] if np.isfinite(zpost.log_prob(ztheta)) else None
    common = {
        "shift_in_sd_before": before["shift_in_sd"],
        "shift_in_sd_after": after["shift_in_sd"] if after else None,
        "kept": _worst_shift(after) < _worst_shift(before),
    }
    records = {}
    if windows["effect_window"]:
        records["effect_axis_zoom"] = {
            "nodes": int(zlik.axis.grid.size),
            "u_range_before": [float(lik.axis.grid[0]), float(lik.axis.grid[-1])],
            "u_range": [float(v) for v in windows["effect_window"]],
        } | common
    if windows["p_window"]:
        records["p_axis_zoom"] = {
            "nodes": int(zlik.p_grid.size),
            "p_range_before": [float(lik.p_grid[0]), float(lik.p_grid[-1])],
            "p_range": [float(v) for v in windows["p_window"]],
        } | common
    if not common["kept"]:
        return at_start, (records, lik, post, theta0)
    config.update({k: [float(w[0]), float(w[1])] for k, w in windows.items() if w})
    return at_start, (records, zlik, zpost, ztheta)


def _zoom_edge(lik, samples: Mapping, key: str, zoom: dict) -> dict:
    """Draws of a narrowed axis (``key``: ``effect_axis_zoom`` or ``p_axis_zoom``) next to its inner ends (where
    the window, not the prior, cut the axis): ``draws_at_edge`` (share of draws within :data:`ZOOM_EDGE_SHARE`
    of the window of such an end) and a ``message`` when any are (the window may truncate the posterior)."""
    if not zoom["kept"]:
        return {}
    if key == "p_axis_zoom":
        (lo0, hi0), (lo, hi), x, name = zoom["p_range_before"], zoom["p_range"], np.asarray(samples["p"]), "p"
    else:
        (lo0, hi0), (lo, hi) = zoom["u_range_before"], zoom["u_range"]
        x, name = lik.effect_coordinate(samples), f"{lik.axis.name} axis (u)"
    band = ZOOM_EDGE_SHARE * (hi - lo)
    near = np.zeros(x.shape, bool)
    if lo > lo0:
        near |= x < lo + band
    if hi < hi0:
        near |= x > hi - band
    out = {"draws_at_edge": float(np.mean(near))}
    if out["draws_at_edge"] > 0.0:
        out["message"] = (
            f"{out['draws_at_edge']:.2%} of the draws lie at an end of the narrowed {name} "
            f"(in [{lo:.4g}, {hi:.4g}]): the window may cut the posterior; report it"
        )
    return out


def _check_checkpoint(checkpoint: Path, config: dict) -> None:
    """A checkpoint resumes only the run that made it: same data, prior, effects, seed, weighting."""
    import h5py

    key = json.dumps({k: config[k] for k in _RESUME_KEYS}, sort_keys=True)
    if checkpoint.is_file():
        with h5py.File(checkpoint, "r") as f:
            old = f.attrs.get("bayesrod_config")
        if old is not None:
            old = json.loads(old)
            for k in _RESUME_KEYS:
                if old.get(k, _RESUME_DEFAULTS.get(k)) != config[k]:
                    raise ValueError(
                        f"checkpoint: expected the same {k} as the interrupted run in {checkpoint}, got "
                        f"{config[k]!r} instead of {old.get(k)!r}"
                    )
            return
    checkpoint.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(checkpoint, "a") as f:
        f.attrs["bayesrod_config"] = key


def _slip_report(lik, samples: Mapping) -> list[dict]:
    """Per push with forces: where the data put its slip and where the posterior's model puts it
    (summary.json ``data.slip``, docs/format.md)."""
    thin = {k: np.asarray(v)[:: max(1, np.asarray(v).size // 2000)] for k, v in samples.items()}
    model = lik.slip_displacement_m(thin)  # (draws, J)
    early = lik.slip_displacement_m(thin, early=True)
    return [
        {
            "push": d.id,
            "engaged_to_m": float(d.engaged_to_m),
            "slipped_by_m": float(d.slipped_by_m) if np.isfinite(d.slipped_by_m) else None,
            "model_slip_m": credible_interval(model[:, j]),
            "model_slip_from_m": credible_interval(early[:, j]),
        }
        for j, d in enumerate(lik.force_data)
    ]


def fit(
    dataset,
    prior=None,
    effects: Sequence[str] = (),
    seed: int = 0,
    progress: bool = True,
    *,
    use_forces: bool = True,
    use_shapes: bool = True,
    shape_weight: str | float = "auto",
    max_steps: int = 8000,
    target_ess: float = 1000.0,
    checkpoint=None,
    force_noise: str = "iid",
    preload: bool = False,
    length: str = "auto",
    height_sd_m: float = 0.0,
    force_offsets: bool = False,
    diameter: str = "auto",
    slip: bool = False,
    n_workers: int = 1,
) -> Posterior:
    """Posterior of EI0, p, the noise and the fitted effects for one dataset (emcee).

    Parameters
    ----------
    dataset : path or Dataset
        A dataset directory (docs/format.md) or a :class:`bayesrod.Dataset` in memory.
    prior : str, path or None
        Prior name (``default``, ``grass``, ``woody``) or a prior JSON file (docs/priors.md).
    effects : sequence of str
        Model effects to fit (docs/model.md): ``force_offset`` and at most one of ``base_compliance``,
        ``rest_curvature``, ``base_tilt``, ``contact_friction``; ``yield`` with forces only.
    seed : int
        Random seed: the same seed gives the same draws.
    progress : bool
        Progress bars, shown only on a terminal or in a notebook.
    use_forces, use_shapes : bool
        Which observations enter the likelihood.
    shape_weight : "auto" or float in (0, 1]
        Power on the centerline likelihood: ``"auto"`` = n_eff/n measured from the residual correlation.
    max_steps, target_ess : int, float
        Sampling budget per ensemble and the bulk-ESS target for EI0 and p.
    force_noise : {"iid", "ar1"}
        Force noise model: independent, or stationary AR(1) within each push with its lag-1 correlation
        ``rho_force`` sampled beside ``sigma_force_N`` (docs/inference.md).
    preload : bool
        Fit each push's preload: the contact displacement already made when recording began (m, prior
        uniform on [0, 0.1 L]); with centerlines the preload moves the push's frames along the branch as it
        moves its forces (docs/inference.md).
    length : {"auto", "known", "unknown"}
        The stem length L: ``"unknown"`` samples it (``length_m``) under the prior file's ``length_m`` entry,
        else uniform on [L/1.5, 1.5 L] of the dataset's length (above the highest contact); ``"auto"``
        (default) does so when the dataset marks its length approximate (``length_m_approximate``);
        ``"known"`` fixes it. Forces only; not with a tabled effect or preload (docs/priors.md).
    height_sd_m : float
        Standard deviation of each push's contact-height error [m] (0, default: heights exact); each
        push's ``height_error_m_<id>`` is sampled under N(0, sd) cut at 4 sd. Forces only.
    force_offsets : bool
        Fit a load-cell offset per push (``force_offset_N_<id>`` [N], prior N(0, 5% of the push's peak
        force)); not together with the dataset-wide ``force_offset`` effect.
    diameter : {"auto", "shared", "free", "off"}
        The width term (docs/inference.md, "Young's modulus"), when the dataset has measured diameters
        (``diameters`` in specimen.json; ``bayesrod extract`` writes them from the frames): ``"shared"`` a
        stem of uniform modulus, d(s) = d0 (1 - s/L)^p with bending's p; ``"free"`` its own taper p_geom, so
        that E(s) = E0 (1 - s/L)^(4 (p - p_geom)) may vary (summary ``youngs_modulus.uniform_modulus`` tests
        it); ``"off"`` ignores the diameters; ``"auto"`` (default) is ``"shared"`` with diameters, else off.
        With diameters the summary reports Young's modulus E0 = 64 EI0 / (pi d0^4).
    slip : bool
        Use where each push slipped off the probe (default False): the stem held the probe to its largest
        engaged displacement, and where the force fell while the robot went on it slipped within that
        step; the model's slip displacement (the branch end) must lie there (docs/inference.md, "The slip").
        Off with an unknown length, height errors or yield.
    checkpoint : path or None
        An HDF5 file the chains are checkpointed to; an interrupted fit called again with the same
        arguments and checkpoint resumes from it. None (default): nothing is written.
    n_workers : int
        Processes that build the likelihood's tables (default 1: this one). Worth it with
        ``contact_friction``, whose tables take minutes per height on one core (49 friction nodes, each a
        force curve that searches the base moment); the tables, and so the draws, are the same whatever
        ``n_workers`` (docs/performance.md). Where processes are spawned (macOS, Windows), a script calls
        it under ``if __name__ == "__main__":``.

    Returns
    -------
    Posterior

    Notes
    -----
    The tables are checked against exact solves at the sampler's start (and with p, and a tabled effect, moved
    to the middle of their node intervals); where they would move the estimate by more than 0.05 sd, the p grid
    and the effect's axis are rebuilt over windows around the start before sampling (one more table build;
    ``summary.json`` ``table_check.p_axis_zoom`` and ``effect_axis_zoom``, docs/inference.md).
    """
    t0 = time.perf_counter()
    check_workers(n_workers)  # before any work
    spec = as_dataset(dataset)
    effects = tuple(effects)
    if isinstance(shape_weight, str):
        if shape_weight != "auto":
            raise ValueError(f"shape_weight: expected 'auto' or a number in (0, 1], got {shape_weight!r}")
    elif not (isinstance(shape_weight, (int, float)) and 0 < shape_weight <= 1):
        raise ValueError(f"shape_weight: expected 'auto' or a number in (0, 1], got {shape_weight!r}")
    if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 100):
        raise ValueError(f"max_steps: expected an integer >= 100, got {max_steps!r}")
    if not (isinstance(target_ess, (int, float)) and target_ess > 0):
        raise ValueError(f"target_ess: expected a number > 0, got {target_ess!r}")
    pr = load_prior(prior)
    if length not in ("auto", "known", "unknown"):
        raise ValueError(f"length: expected 'auto', 'known' or 'unknown', got {length!r}")
    if length == "auto":  # resolved here, so that the run records what was fitted
        length = "known"
        if length_is_approximate(spec):
            why = geometry_blocker(spec, effects, use_forces=use_forces, use_shapes=use_shapes, preload=preload)
            if why is None:
                length = "unknown"
            else:
                log.warning(
                    "warning: %s: length_m %g m is marked approximate but stays fixed (%s); intervals assume it",
                    spec.specimen,
                    spec.length_m,
                    why,
                )
    if diameter not in ("auto", "shared", "free", "off"):
        raise ValueError(f"diameter: expected 'auto', 'shared', 'free' or 'off', got {diameter!r}")
    if diameter == "auto":
        diameter = "shared" if spec.diameters is not None else "off"
    config = {
        "dataset": str(Path(spec.root).resolve()) if spec.root is not None else None,
        "prior": pr.source,
        "effects": list(effects),
        "seed": seed,
        "use_forces": use_forces,
        "use_shapes": use_shapes,
        "shape_weight": shape_weight,
        "force_noise": force_noise,
        "preload": bool(preload),
        "length": length,
        "height_sd_m": height_sd_m,
        "force_offsets": bool(force_offsets),
        "diameter": diameter,
        "slip": bool(slip),
        "bayesrod": __version__,
    }
    # the likelihood first: bad effects or data without engaged samples fail before anything is written
    t_tables = time.perf_counter()
    if preload and use_shapes and any(p.shapes for p in spec.pushes):  # the one build that takes long
        log.info("%s: tabling the centerlines over each push's preload (several seconds per push)", spec.specimen)
    if "contact_friction" in effects:
        log.info(
            "%s: tabling contact friction (minutes per height; on %d process%s)",
            spec.specimen,
            n_workers,
            "" if n_workers == 1 else "es",
        )
    with table_workers(n_workers, progress=progress_enabled(progress)):
        lik = build_likelihood(spec, pr, effects, **_likelihood_options(config))
    log.info("%s: likelihood tables built in %.1f s", spec.specimen, time.perf_counter() - t_tables)
    if lik.length_prior is not None:
        lo, hi = lik.length_prior.bounds()
        log.info("%s: stem length sampled (prior %s on [%.3g, %.3g] m)", spec.specimen, lik.length_prior.dist, lo, hi)
    post = LogPosterior(lik, pr)
    # the coordinates the chains move in (a checkpoint stores chains in them): set by the posterior
    config.update(sampling_coordinates(force_noise, effects, one_height=post.stiffness_pair() is not None))
    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        _check_checkpoint(checkpoint, config)
    log.info(
        "%s: %d engaged force samples, %d centerline points, %d pushes; parameters %s",
        spec.specimen,
        lik.n_force,
        lik.n_points,
        len(spec.pushes),
        ", ".join(post.names),
    )
    two_stage, direct = _two_stage(spec, use_shapes)
    rng = np.random.default_rng(seed)
    try:
        theta0 = find_start(post, rng, init=two_stage)
    except ValueError:
        raise ValueError(
            f"{spec.specimen}: expected data the tapered rod can describe, got none of the taper exponents "
            f"{lik.p_grid[0]:g}-{lik.p_grid[-1]:g} giving the data a finite probability under prior "
            f"{pr.name!r}; check units and signs (bayesrod validate), the prior, or what the model misses "
            "(bayesrod diagnose)"
        ) from None
    weight_info = None
    if lik.n_points:
        if shape_weight == "auto":
            mode = {k: float(v[0]) for k, v in post.to_natural(theta0[None]).items()}
            weight_info = effective_shape_weight(lik, mode)
            lik.shape_weight = weight_info["weight"]
            log.info(
                "centerline errors correlated: %.3g points along the stem x %.3g frames per independent residual; "
                "shape likelihood weighted %.3g (n_eff %.0f of %d)",
                weight_info["tau_along"],
                weight_info["tau_frames"],
                lik.shape_weight,
                weight_info["n_eff"],
                lik.n_points,
            )
            if lik.shape_weight < 1:
                theta0 = find_start(post, rng, init=two_stage)
        else:
            lik.shape_weight = float(shape_weight)
    zooms = {}
    with table_workers(n_workers, progress=progress_enabled(progress)):
        at_start, zoomed = _zoom_tables(spec, pr, effects, config, post, theta0)
    if zoomed is not None:
        zooms, lik, post, theta0 = zoomed
    theta0 = post.settle_base_coordinates(theta0)
    if "base_compliance" in post.names:
        log.info("%s: base spring sampled in %s", spec.specimen, "u" if post.base_pair() else "log k")
    res = run_ensembles(
        post,
        theta0,
        seed=seed,
        backend_path=checkpoint,
        progress=progress_enabled(progress),
        max_steps=max_steps,
        target_ess=target_ess,
    )
    flat = res.chain.reshape(-1, post.ndim)
    samples = {k: readonly(v) for k, v in post.to_natural(flat).items()}
    median = {k: float(np.median(v)) for k, v in samples.items()}
    truth = spec.extra.get("truth")
    extra = {
        "prior": pr.name,
        "level": 0.9,
        "data": {
            "n_force": lik.n_force,
            "n_shape_points": lik.n_points,
            "heights_m": list(spec.heights_m),
            **({"shape_weight": lik.shape_weight} if lik.n_points else {}),
            **({"shape_correlation": weight_info} if weight_info else {}),
        },
        "sampler": {
            "ensembles": res.n_ensembles,
            "walkers_per_ensemble": res.chain.shape[0] // res.n_ensembles,
            "steps": res.n_steps,
            "burn_in": res.burn,
            "autocorr_time": [float(t) for t in res.tau],
            "acceptance": res.acceptance,
            "seconds": round(time.perf_counter() - t0, 1),
        },
        "assumptions": _assumptions(spec, lik),
    }
    if lik.slip:
        extra["data"]["slip"] = _slip_report(lik, samples)
    if truth:
        extra["truth"] = truth
    if two_stage:
        extra["two_stage"] = two_stage
    from ..inference.checks import model_check

    extra["model_check"] = model_check(lik, samples, seed=seed)
    misfit = extra["model_check"]["verdict"] == "misfit"
    loaded = []
    if misfit and use_forces and not preload:
        loaded = [p.id for p in spec.pushes if starts_loaded(p.force.force_N)]
    if loaded:
        # the likeliest thing missing is in the data's own first sample: say so beside the generic advice
        extra["model_check"]["message"] += (
            f" Push{'es' if len(loaded) > 1 else ''} {', '.join(loaded)} start{'' if len(loaded) > 1 else 's'} "
            "loaded: fit each push's preload (preload=True), or let diagnose fit it."
        )
        extra["model_check"]["pushes_starting_loaded"] = loaded
    if misfit:
        log.warning("warning: %s: %s", spec.specimen, extra["model_check"]["message"])
    try:
        tables = table_check(lik, median)
    except ValueError as err:  # an exact solve the tables never needed (e.g. a rest shape that misses a height)
        tables = None
        extra["table_check"] = {"message": f"not checked: {err}"}
    if tables is not None:
        extra["table_check"] = tables
        message = table_warning(tables)
        if message:
            tables["message"] = message
            log.warning("warning: %s: %s", spec.specimen, message)
    if at_start:  # the check the zoom decision read, beside the check at the median
        extra.setdefault("table_check", {})["at_start"] = at_start
    for key, zoom in zooms.items():  # beside the check's result, or its "not checked" message
        zoom.update(_zoom_edge(lik, samples, key, zoom))
        extra.setdefault("table_check", {})[key] = zoom
        if zoom.get("message"):
            log.warning("warning: %s: %s", spec.specimen, zoom["message"])
    doc = build_summary(spec, post, samples, res.diagnostics, lik.fit_error(median), effects, extra)
    not_converged = convergence_message(res, max_steps, target_ess)
    doc["convergence"]["converged"] = not_converged is None
    doc["convergence"]["walkers_restarted"] = int(sum(res.walkers_restarted))
    if not_converged:
        doc["convergence"]["message"] = not_converged
        log.warning("warning: %s: %s", spec.specimen, not_converged)
    idata = to_inference_data(
        res.chain,
        res.log_prob,
        post,
        spec,
        {
            "specimen": spec.specimen,
            "length_m": spec.length_m,
            "prior": pr.name,
            "effects": ",".join(effects),
            "bayesrod": __version__,
        },
    )
    return Posterior(
        samples=MappingProxyType(samples),
        idata=idata,
        length_m=float(spec.length_m),
        specimen=spec.specimen,
        effects=effects,
        config=MappingProxyType(config),
        doc=MappingProxyType(plain_json(doc)),
        dataset=spec,
        likelihood=lik,
        direct=direct,
    )

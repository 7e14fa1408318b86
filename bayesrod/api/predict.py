"""``bayesrod.predict``: the forward elastica at a contact height, for one rod or over a posterior."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ..physics import Effects, force_from_displacement, k_theta, k_x
from ..physics.presets import get_preset
from ._common import DocResult


@dataclass(frozen=True, eq=False)
class Prediction(DocResult):
    """Forces, contact points and slip at the asked displacements, with k_theta and k_x (eqs. kdist, kx).

    ``to_dict()`` is the ``predict --json`` document (docs/format.md): plain numbers for one rod,
    ``{median, q05, q95}`` over a posterior.
    """

    doc: Mapping = field(repr=False)

    @property
    def from_posterior(self) -> bool:
        return "posterior" in self.doc


def _check_rod(EI0, p, length_m) -> tuple[float, float, float]:
    vals = {"EI0": EI0, "p": p, "length_m": length_m}
    missing = [k for k, v in vals.items() if v is None]
    if missing:
        raise ValueError(f"{', '.join(missing)}: expected a value (or a preset, or a posterior), got none")
    for k, v in vals.items():
        try:
            vals[k] = float(v)
        except (TypeError, ValueError):
            raise TypeError(f"{k}: expected a number, got {type(v).__name__}") from None
        if not np.isfinite(vals[k]):
            raise ValueError(f"{k}: expected a finite number, got {v}")
    if vals["EI0"] <= 0:
        raise ValueError(f"EI0: expected a flexural rigidity > 0 N m^2, got {vals['EI0']}")
    if vals["p"] < 0:
        raise ValueError(f"p: expected a taper exponent >= 0, got {vals['p']}")
    if vals["length_m"] <= 0:
        raise ValueError(f"length_m: expected a stem length > 0 m, got {vals['length_m']}")
    return vals["EI0"], vals["p"], vals["length_m"]


def _check_inputs(h, D, L):
    D = np.atleast_1d(np.asarray(D, dtype=float))
    if D.ndim != 1 or not np.all(np.isfinite(D)):
        raise ValueError(f"displacement_m: expected finite numbers, got {D!r}")
    if np.any(D < 0):
        raise ValueError(f"displacement_m: expected values >= 0 m, got {D[D < 0][0]:g}")
    if not (np.isfinite(h) and 0 < h < L):
        raise ValueError(f"height_m: expected 0 < height < length ({L:g} m), got {h:g}")
    return float(h), D


def predict(
    height_m: float,
    displacement_m: ArrayLike,
    *,
    EI0: float | None = None,
    p: float | None = None,
    length_m: float | None = None,
    preset: str | None = None,
    posterior=None,
    effects: Effects | Mapping | None = None,
    n_draws: int = 400,
) -> Prediction:
    """Force at contact displacements ``displacement_m`` [m] for a contact at ``height_m`` [m].

    Give the rod as ``EI0`` [N m^2], ``p`` and ``length_m`` [m] (a ``preset`` fills those not given), or a
    ``posterior`` (:class:`~bayesrod.Posterior` or a run directory) for 90% bands over ``n_draws`` draws.
    ``effects`` switches model effects on (docs/model.md); fitted effects of a posterior override them.
    """
    eff = effects if isinstance(effects, Effects) else Effects.from_mapping(dict(effects or {}))
    if posterior is not None:
        return _predict_posterior(posterior, height_m, displacement_m, eff, n_draws)
    if preset is not None:
        pr = get_preset(preset)
        EI0 = pr["EI0"] if EI0 is None else EI0
        p = pr["p"] if p is None else p
        length_m = pr["length_m"] if length_m is None else length_m
    EI0, p, L = _check_rod(EI0, p, length_m)
    h, D = _check_inputs(float(height_m), displacement_m, L)
    sol = force_from_displacement(D, h, EI0, p, L, eff)
    points = []
    for i, d in enumerate(D):
        slipped = bool(sol.slipped[i])
        points.append(
            {
                "displacement_m": float(d),
                "force_N": None if slipped else float(sol.force_N[i]),
                "contact_s_m": None if slipped else float(sol.contact_s_m[i]),
                "slipped": slipped,
                "yielded": bool(sol.yielded[i]),
            }
        )
    doc = {
        "height_m": h,
        "k_theta_Nm_per_rad": float(k_theta(h, EI0, p, L, eff.base_compliance)),
        "k_x_N_per_m": float(k_x(h, EI0, p, L, eff.base_compliance)),
        "model": {"EI0": EI0, "p": p, "length_m": L, "effects": eff.to_mapping()},
        "points": points,
    }
    return Prediction(MappingProxyType(doc))


def _predict_posterior(posterior, height_m, displacement_m, effects: Effects, n_draws: int) -> Prediction:
    from ..inference.summary import draw_lengths, predictive_forces, quantiles
    from .fitting import Posterior

    if isinstance(posterior, (str, Path)):
        run = str(posterior)
        posterior = Posterior.load(posterior)
    elif isinstance(posterior, Posterior):
        run = posterior.config.get("run") or posterior.specimen
    else:
        raise TypeError(f"posterior: expected a bayesrod.Posterior or a run directory, got {type(posterior).__name__}")
    samples, L = posterior.thinned(), posterior.length_m
    h, D = _check_inputs(float(height_m), displacement_m, L)
    rng = np.random.default_rng(0)
    n = samples["EI0"].size
    idx = rng.choice(n, size=min(n_draws, n), replace=False)
    EI0, p = samples["EI0"][idx], samples["p"][idx]
    L_draw = np.broadcast_to(draw_lengths(samples, L), (n, 1))[idx, 0]  # each draw's, where the length was sampled
    pred = predictive_forces(samples, idx, D, h, L, effects)
    F = pred["force_N"]
    slip_prob = pred["slipped"].mean(axis=0)
    kb = samples["base_compliance"][idx] if "base_compliance" in samples else effects.base_compliance
    kt = k_theta(h, EI0, p, L_draw, kb)
    kx = k_x(h, EI0, p, L_draw, kb)

    def q(x):
        return {k: (None if not np.isfinite(v) else float(v)) for k, v in quantiles(x).items()}

    points = []
    for i, d in enumerate(D):
        col = F[:, i]
        ok = np.isfinite(col)
        points.append(
            {
                "displacement_m": float(d),
                "force_N": q(col[ok]) if ok.sum() >= 2 else None,
                "contact_s_m": q(pred["contact_s_m"][ok, i]) if ok.sum() >= 2 else None,
                "slipped": bool(slip_prob[i] > 0.5),
                "slip_probability": float(slip_prob[i]),
            }
        )
    doc = {
        "height_m": h,
        "k_theta_Nm_per_rad": q(kt),
        "k_x_N_per_m": q(kx),
        "posterior": {"run": str(run), "draws": int(idx.size), "length_m": L},
        "points": points,
        "level": 0.9,
    }
    return Prediction(MappingProxyType(doc))

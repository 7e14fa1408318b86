"""``bayesrod.design``: where should the next push go? Returns a :class:`Design`.

The computation is :mod:`bayesrod.inference.design`; the input is a
:class:`~bayesrod.Posterior` (or a saved run), or one condition of a
:class:`~bayesrod.GroupFit` (a stem under several anchorage conditions: the stem's
draws with that condition's base compliance and noise). The planned push defaults
to what the dataset's pushes did: the largest engaged contact displacement and
the median number of engaged force samples per push; the sensor range is
``sensor.force_range_N``.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..inference.design import PushPlan, design_heights
from ._common import DocResult, plain_json

log = logging.getLogger("bayesrod")


def default_plan(spec) -> dict:
    """Planned displacement and sample count from a dataset's pushes (engaged part only)."""
    from ..dataset.engagement import detect_engagement

    reach, counts = [], []
    for push in spec.pushes:
        eng = detect_engagement(push.force.force_N)
        if eng.mask.any():
            reach.append(float(np.nanmax(push.force.contact_x_m[eng.mask])))
            counts.append(int(eng.mask.sum()))
    out = {}
    if reach:
        out["displacement_m"] = max(reach)
        out["n_samples"] = int(np.median(counts))
    if spec.sensor is not None and spec.sensor.force_range_N is not None:
        out["force_range_N"] = tuple(spec.sensor.force_range_N)
    return out


@dataclass(frozen=True, eq=False)
class Design(DocResult):
    """Candidate contact heights ranked for the next push (the content of ``design.json``).

    ``recommended_height_m`` is None when no candidate is feasible; ``candidates`` lists, per height,
    ``expected_information_gain_nats``, ``feasible``, ``predicted_peak_force_N`` and its interval.
    """

    doc: Mapping = field(repr=False)
    recommended_height_m: float | None = None

    @property
    def candidates(self) -> list[dict]:
        return copy.deepcopy(list(self.doc["candidates"]))

    def plot(self, ax=None):
        """Expected information gain against height, infeasible heights marked; returns the artists."""
        from ..report.plots import plot_design

        return plot_design(self.doc, ax=ax, pushed_m=self.doc.get("pushed_heights_m", ()))

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write ``design.json`` and ``figures/design.png`` into the directory ``path``."""
        from ..dataset.io import atomic_dir, write_bytes_atomic, write_json
        from ..report.figures import render

        path = Path(path)
        with atomic_dir(path, overwrite) as tmp:
            write_json(tmp / "design.json", self.to_dict())
            png = render(lambda ax: self.plot(ax=ax), 6.4, 3.6, dpi=120)
            write_bytes_atomic(tmp / "figures" / "design.png", png)
        return path


def design(
    posterior,
    heights=None,
    *,
    sensor=None,
    displacement_m: float | None = None,
    n_samples: int | None = None,
    confidence: float = 0.9,
    target: str = "params",
    target_height_m: float | None = None,
    method: str | None = None,
    condition: str | None = None,
    seed: int = 0,
    progress: bool = True,
) -> Design:
    """Rank candidate contact heights for the next push by expected information gain.

    Parameters
    ----------
    posterior : Posterior, GroupFit or path
        A fit (:func:`bayesrod.fit`), a stem's joint fit (:func:`bayesrod.fit_group`), or a saved
        run or fit-group stem directory.
    heights : array_like or None
        Candidate heights [m]; default 19 heights from 0.05 L to 0.95 L.
    sensor : (low, high) or None
        The force sensor's range [N]; default the dataset's ``sensor.force_range_N``.
    displacement_m, n_samples : planned push; default what the dataset's pushes did.
    confidence : float
        Required probability that the peak force lies in the sensor's range.
    target : {"params", "ei", "k_theta"}
        Information about (log EI0, p), the EI(s) band, or k_theta at ``target_height_m``.
    method : {"nmc", "gaussian"} or None
        Nested Monte Carlo (default for params) or linearised (the only choice for ei, k_theta).
    condition : str or None
        With a GroupFit, the condition whose next push is planned (required there; unused otherwise).
        Its base compliance varies with the draws, so the gain counts what a push teaches about the
        stem and its anchorage together (with one height they are confounded).
    """
    from ._common import progress_enabled
    from .fitting import Posterior
    from .group import GroupFit, load_run

    if isinstance(posterior, (str, Path)):
        posterior = load_run(posterior)
    if isinstance(posterior, GroupFit):
        samples, L, pushed, plan_kw, source = _group_draws(posterior, condition)
    elif isinstance(posterior, Posterior):
        if condition is not None:
            raise ValueError(f"condition: expected None for a single-condition fit, got {condition!r}")
        samples, L, spec = posterior.thinned(), posterior.length_m, posterior.dataset
        pushed = (
            [float(h) for h in spec.heights_m]
            if spec is not None
            else list(posterior.doc.get("data", {}).get("heights_m", []))
        )
        plan_kw = default_plan(spec) if spec is not None else {}
        source = posterior.config.get("run") or posterior.config.get("dataset")
    else:
        raise TypeError(
            "posterior: expected a bayesrod.Posterior, a bayesrod.GroupFit or a run directory, got "
            f"{type(posterior).__name__}"
        )
    if target not in ("params", "ei", "k_theta"):
        raise ValueError(f"target: expected params, ei or k_theta, got {target!r}")
    method = method or ("nmc" if target == "params" else "gaussian")
    if method not in ("nmc", "gaussian"):
        raise ValueError(f"method: expected nmc or gaussian, got {method!r}")
    if displacement_m is not None:
        plan_kw["displacement_m"] = displacement_m
    if n_samples is not None:
        plan_kw["n_samples"] = n_samples
    if sensor is not None:
        try:
            lo, hi = (float(v) for v in sensor)
        except (TypeError, ValueError):
            raise ValueError(f"sensor: expected (low, high) force range in N, got {sensor!r}") from None
        plan_kw["force_range_N"] = (lo, hi)
    if "displacement_m" not in plan_kw:
        raise ValueError(
            "displacement_m: expected the planned contact displacement [m] (the run's dataset is not readable "
            "to take it from its pushes), got none"
        )
    plan = PushPlan(confidence=confidence, **plan_kw)
    cand = np.linspace(0.05, 0.95, 19) * L if heights is None else np.atleast_1d(np.asarray(heights, dtype=float))
    log.info(
        "design: %d candidate heights, planned push %.0f mm with %d force samples, sensor range %s",
        cand.size,
        1000 * plan.displacement_m,
        plan.n_samples,
        f"{plan.force_range_N[0]:g}-{plan.force_range_N[1]:g} N" if plan.force_range_N else "not given",
    )
    res = design_heights(
        samples,
        L,
        cand,
        plan,
        target=target,
        target_height_m=target_height_m,
        method=method,
        seed=seed,
        progress=progress_enabled(progress),
    )
    res["source"] = source
    res["length_m"] = L
    res["pushed_heights_m"] = pushed
    res = plain_json(res)
    return Design(doc=MappingProxyType(res), recommended_height_m=res["recommended_height_m"])


def _group_draws(group, condition: str | None) -> tuple[dict, float | None, list[float], dict, str]:
    """Draws, length, pushed heights, planned-push defaults (none: a fit-group run keeps no dataset) and
    source of one condition of a stem's joint fit: the stem's EI0 and p with that condition's base
    compliance (as the base-spring effect, k_b = 1/compliance, inf at the clamp) and force noise."""
    from ..inference.group import condition_name

    if condition not in group.conditions:
        whose = " (a fit-group stem: whose next push?)" if condition is None else ""
        got = "none" if condition is None else repr(condition)
        raise ValueError(f"condition: expected one of {', '.join(group.conditions)}{whose}, got {got}")
    if group.length_m is None:
        raise ValueError(f"{group.stem_id}: expected the stem length in summary.json (length_m), got none")
    S = group.samples

    def draws(name):
        for key in (condition_name(name, condition), name):
            if key in S:
                return np.asarray(S[key], float)
        raise ValueError(f"{group.stem_id}: expected draws of {name} in the fit-group samples, got none")

    C = np.asarray(S[f"base_compliance_rad_per_Nm__{condition}"], float)
    with np.errstate(divide="ignore"):
        k_b = np.where(C > 0, 1.0 / np.where(C > 0, C, 1.0), np.inf)
    samples = {"EI0": draws("EI0"), "p": draws("p"), "sigma_force_N": draws("sigma_force_N"), "base_compliance": k_b}
    pushed = [float(r["height_m"]) for r in group.doc["conditions"][condition]["k_theta"]]
    return samples, group.length_m, pushed, {}, f"{group.stem_id}/{condition}"

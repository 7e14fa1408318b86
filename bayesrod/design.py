"""``bayesrod design``: where should the next push go? Writes ``design.json`` and a figure.

I/O lives here; the computation is :mod:`bayesrod.inference.design`. The input
is a fit run (its ``samples.npz`` and, through ``config.json``, its dataset) or
a dataset, which is fitted first into ``DIR/fit``. The planned push defaults
to what the dataset's pushes did: the largest engaged contact displacement and
the median number of engaged force samples per push; the sensor range is
``sensor.force_range_N``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .inference.design import PushPlan, design_heights
from .io import write_json


def plot_design(result: dict, ax=None, pushed_m=()):
    """Expected information gain against height; infeasible heights greyed, the pick marked. Returns artists."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 3.6))
    rows = [r for r in result["candidates"] if r["expected_information_gain_nats"] is not None]
    h = np.array([r["height_m"] for r in rows])
    g = np.array([r["expected_information_gain_nats"] for r in rows])
    ok = np.array([r["feasible"] for r in rows])
    art = {"line": ax.plot(h, g, "-", color="0.6", lw=1)[0]}
    art["feasible"] = ax.plot(h[ok], g[ok], "o", color="C0", label="feasible")[0]
    art["infeasible"] = ax.plot(h[~ok], g[~ok], "x", color="C3", label="infeasible (see design.json)")[0]
    rec = result["recommended_height_m"]
    if rec is not None:
        art["recommended"] = ax.axvline(rec, color="C2", lw=2, label=f"recommended {rec:.3g} m")
    for k, hp in enumerate(pushed_m):
        ax.axvline(hp, color="k", ls=":", lw=1, label="already pushed" if k == 0 else None)
    ax.set_xlabel("contact height h [m]")
    ax.set_ylabel(f"expected information gain [nats]\n(target: {result['target']})")
    ax.legend(fontsize=8)
    return art


def _parse_candidates(text: str | None, L: float) -> np.ndarray:
    if not text:
        return np.linspace(0.05, 0.95, 19) * L
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f"--candidates: expected start:stop:num (metres, metres, count), got {text!r}") from None
    if n < 1 or not (np.isfinite(a) and np.isfinite(b)):
        raise ValueError(f"--candidates: expected num >= 1 and finite heights, got {text!r}")
    return np.linspace(a, b, n)


def _load_posterior(source: Path, out: Path, *, seed: int, forces_only: bool, log) -> tuple[dict, float, Path | None]:
    """Posterior draws, stem length and the dataset path behind them."""
    if (source / "samples.npz").is_file():
        with np.load(source / "samples.npz") as z:
            samples = {k: np.asarray(z[k]) for k in z.files}
        cfg = source / "config.json"
        dataset = Path(json.loads(cfg.read_text())["dataset"]) if cfg.is_file() else None
        return samples, float(samples.pop("length_m")), dataset
    if (source / "specimen.json").is_file():
        from .fit import fit_dataset

        log(f"{source}: a dataset; fitting it into {out / 'fit'} first")
        fit_dataset(source, out / "fit", seed=seed, use_shapes=not forces_only, progress=True, log=log)
        return _load_posterior(out / "fit", out, seed=seed, forces_only=forces_only, log=log)
    raise ValueError(f"{source}: expected a fit run (samples.npz) or a dataset (specimen.json)")


def default_plan(spec) -> dict:
    """Planned displacement and sample count from a dataset's pushes (engaged part only)."""
    from .dataset.engagement import detect_engagement

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


def run_design(
    source,
    out,
    *,
    candidates: str | None = None,
    displacement_m: float | None = None,
    n_samples: int | None = None,
    force_range_N=None,
    confidence: float = 0.9,
    target: str = "params",
    target_height_m: float | None = None,
    method: str = "nmc",
    seed: int = 0,
    forces_only: bool = False,
    progress: bool = True,
    log=print,
) -> dict:
    """Rank candidate heights for the next push; writes ``out/design.json`` and ``out/figures/design.png``."""
    from .dataset import read_dataset

    source, out = Path(source), Path(out)
    samples, L, dataset = _load_posterior(source, out, seed=seed, forces_only=forces_only, log=log)
    pushed: list[float] = []
    plan_kw: dict = {}
    if dataset is not None and (dataset / "specimen.json").is_file():
        spec = read_dataset(dataset)
        pushed = [float(h) for h in spec.heights_m]
        plan_kw = default_plan(spec)
    if displacement_m is not None:
        plan_kw["displacement_m"] = displacement_m
    if n_samples is not None:
        plan_kw["n_samples"] = n_samples
    if force_range_N is not None:
        plan_kw["force_range_N"] = tuple(force_range_N)
    if "displacement_m" not in plan_kw:
        raise ValueError(
            "--displacement: expected the planned contact displacement [m] (the run's dataset is not readable "
            "to take it from its pushes), got none"
        )
    plan = PushPlan(confidence=confidence, **plan_kw)
    cand = _parse_candidates(candidates, L)
    log(
        f"design: {cand.size} candidate heights, planned push {1000 * plan.displacement_m:.0f} mm with "
        f"{plan.n_samples} force samples, sensor range "
        + (f"{plan.force_range_N[0]:g}-{plan.force_range_N[1]:g} N" if plan.force_range_N else "not given")
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
        progress=progress,
    )
    res["source"] = str(source.resolve())
    res["length_m"] = L
    res["pushed_heights_m"] = pushed
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "design.json", res)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (out / "figures").mkdir(exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    plot_design(res, ax=ax, pushed_m=pushed)
    tmp = out / "figures" / ".design.png.tmp.png"
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(out / "figures" / "design.png")
    return res

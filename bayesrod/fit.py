"""``bayesrod fit``: posterior of EI0, p and noise for one dataset, written to a run directory.

RUN/ holds ``config.json`` (what was asked), ``chains.h5`` (emcee HDF5
backend: an interrupted run resumes with ``--resume``), ``posterior.nc``
(ArviZ), ``samples.npz`` (thinned natural-unit draws for fast reuse),
``summary.json`` (CONTRACT.md section 3), ``figures/`` and ``report.html``.
"""

from __future__ import annotations

import base64
import html
import io
import json
import time
from pathlib import Path

import numpy as np

from . import __version__
from .dataset import read_dataset
from .inference.likelihood import LogPosterior, build_likelihood, effective_shape_weight
from .inference.priors import load_prior
from .inference.sampler import find_start, run_ensembles
from .inference.summary import build_summary, to_inference_data
from .io import write_json, write_text_atomic


def fit_dataset(
    dataset,
    out,
    *,
    prior=None,
    effects=(),
    seed=0,
    use_forces=True,
    use_shapes=True,
    resume=False,
    progress=True,
    max_steps=8000,
    target_ess=1000.0,
    shape_weight="auto",
    log=print,
) -> dict:
    """Fit one dataset and write the run directory ``out``; returns the summary.

    ``shape_weight``: power on the centerline likelihood, ``"auto"`` (n_eff / n measured at the
    posterior mode, :func:`~bayesrod.inference.likelihood.effective_shape_weight`) or a number in (0, 1].
    """
    t0 = time.perf_counter()
    out = Path(out)
    spec = read_dataset(dataset)
    pr = load_prior(prior)
    config = {
        "dataset": str(Path(dataset).resolve()),
        "prior": pr.source,
        "effects": list(effects),
        "seed": seed,
        "use_forces": use_forces,
        "use_shapes": use_shapes,
        "shape_weight": shape_weight,
        "bayesrod": __version__,
    }
    cfg_path = out / "config.json"
    if resume and cfg_path.is_file():
        old = json.loads(cfg_path.read_text())
        diff = [
            k
            for k in ("dataset", "prior", "effects", "seed", "use_forces", "use_shapes", "shape_weight")
            if old.get(k, "auto" if k == "shape_weight" else None) != config[k]
        ]
        if diff:
            raise ValueError(
                f"--resume: expected the same {diff[0]} as the interrupted run, got "
                f"{config[diff[0]]!r} instead of {old.get(diff[0])!r}"
            )
    # the likelihood first: bad --effects or data without engaged samples leave no half-made run behind
    lik = build_likelihood(spec, pr, effects, use_forces=use_forces, use_shapes=use_shapes)
    out.mkdir(parents=True, exist_ok=True)
    write_json(cfg_path, config)
    post = LogPosterior(lik, pr)
    log(
        f"{spec.specimen}: {lik.n_force} engaged force samples, {lik.n_points} centerline points, "
        f"{len(spec.pushes)} pushes; parameters {', '.join(post.names)}"
    )
    two_stage, direct = _two_stage(spec, use_shapes, log)
    rng = np.random.default_rng(seed)
    theta0 = find_start(post, rng, init=two_stage)
    weight_info = None
    if lik.n_points:
        if shape_weight == "auto":
            mode = {k: float(v[0]) for k, v in post.to_natural(theta0[None]).items()}
            weight_info = effective_shape_weight(lik, mode)
            lik.shape_weight = weight_info["weight"]
            log(
                f"centerline errors correlated: {weight_info['tau_along']:.3g} points along the stem x "
                f"{weight_info['tau_frames']:.3g} frames per independent residual; shape likelihood weighted "
                f"{lik.shape_weight:.3g} (n_eff {weight_info['n_eff']:.0f} of {lik.n_points})"
            )
            if lik.shape_weight < 1:
                theta0 = find_start(post, rng, init=two_stage)
        else:
            lik.shape_weight = float(shape_weight)
    res = run_ensembles(
        post,
        theta0,
        seed=seed,
        backend_path=out / "chains.h5",
        progress=progress,
        max_steps=max_steps,
        target_ess=target_ess,
    )
    diag = res.diagnostics
    flat = res.chain.reshape(-1, post.ndim)
    samples = {k: np.asarray(v) for k, v in post.to_natural(flat).items()}
    median = {k: float(np.median(v)) for k, v in samples.items()}
    fit_error = lik.fit_error(median)
    truth = spec.extra.get("truth")
    extra = {
        "prior": pr.name,
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
        "assumptions": _assumptions(spec),
    }
    if truth:
        extra["truth"] = truth
    if two_stage:
        extra["two_stage"] = two_stage
    summary = build_summary(spec, post, samples, diag, fit_error, effects, extra)
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
    tmp = out / ".posterior.nc.tmp"
    idata.to_netcdf(str(tmp))
    tmp.replace(out / "posterior.nc")
    keep = np.random.default_rng(seed).choice(flat.shape[0], size=min(4000, flat.shape[0]), replace=False)
    buf = io.BytesIO()
    np.savez(buf, length_m=spec.length_m, **{k: v[keep] for k, v in samples.items()})
    (out / ".samples.npz.tmp").write_bytes(buf.getvalue())
    (out / ".samples.npz.tmp").replace(out / "samples.npz")
    summary["sampler"]["seconds"] = round(time.perf_counter() - t0, 1)
    write_json(out / "summary.json", summary)
    figs = write_figures(
        spec, lik, samples, out / "figures", truth, direct=direct, idata=idata, median=median, n_ens=res.n_ensembles
    )
    write_report(out / "report.html", summary, figs, spec)
    return summary


def _two_stage(spec, use_shapes: bool, log) -> tuple[dict | None, object]:
    """The seed's deterministic estimate, when the data allow it (shapes with enough points)."""
    from .inference.direct import two_stage_fit

    if not use_shapes or not any(p.shapes for p in spec.pushes):
        return None, None
    try:
        ts = two_stage_fit(spec)
    except ValueError as e:
        log(f"two-stage estimate skipped: {e}")
        return None, None
    log(f"two-stage (seed) estimate: EI0 = {ts.EI0:.4g} N m^2, p = {ts.p:.4g} (R^2 {ts.r2:.3f})")
    return ts.to_dict(), ts.direct


def _weight_html(data: dict) -> str:
    """One sentence on the centerline likelihood's weight (docs/inference.md), or nothing."""
    corr = data.get("shape_correlation")
    if corr:
        return html.escape(
            f" Centerline errors are correlated ({corr['tau_along']:.3g} points along the stem x "
            f"{corr['tau_frames']:.3g} frames per independent residual), so the centerline likelihood is "
            f"weighted {corr['weight']:.3g} (effectively {corr['n_eff']:.0f} independent points)."
        )
    if "shape_weight" in data and data["shape_weight"] != 1:
        return html.escape(f" Centerline likelihood weighted {data['shape_weight']:.3g} (--shape-weight).")
    return ""


def _assumptions(spec) -> list[str]:
    a = [
        "A1 planar bending in one vertical plane",
        "A2 quasi-static loading",
        "A3 inextensible, unshearable rod",
        "A4 linear elastic, EI(s) = EI0 (1 - s/L)^(4p)",
        "A5 single horizontal point force at the sensor height",
        "A6 base clamped and vertical, tip free",
        f"stem length L = {spec.length_m:g} m",
    ]
    prov = spec.extra.get("provenance", {})
    for k, v in (prov.get("assumptions") or {}).items():
        a.append(f"{k}: {v}")
    return a


def _lumped_points(lik) -> list:
    """Per-height k_theta from the torque balance on the linear region (the seed's lumped branch)."""
    from .physics.lumped import fit_torque_balance, link_angle

    pts = []
    for d in lik.data:
        if d.D_m.size >= 3:
            try:
                pts.append(
                    (d.height_m, fit_torque_balance(link_angle(d.D_m, d.height_m), d.F_N, d.height_m)["k_theta"])
                )
            except ValueError:
                continue
    return pts


def write_figures(
    spec, lik, samples, folder: Path, truth=None, direct=None, idata=None, median=None, n_ens: int = 4
) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .plots import plot_corner, plot_ei_band, plot_force_fit, plot_k_theta_band, plot_rank, plot_residuals

    folder.mkdir(parents=True, exist_ok=True)
    files = {}
    sub = {k: v[:: max(1, len(v) // 2000)] for k, v in samples.items()}
    for name, fn in (
        ("ei_band", lambda ax: plot_ei_band(sub, spec.length_m, ax=ax, truth=truth, direct=direct)),
        (
            "k_theta_band",
            lambda ax: plot_k_theta_band(sub, spec.length_m, spec.heights_m, ax=ax, lumped=_lumped_points(lik)),
        ),
        ("force_fit", lambda ax: plot_force_fit(spec, lik, sub, ax=ax, unseen_height=_unseen(spec))),
    ):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        fn(ax)
        fig.tight_layout()
        fig.savefig(folder / f"{name}.png", dpi=110)
        plt.close(fig)
        files[name] = folder / f"{name}.png"
    fig = plot_corner(sub, truth=truth)
    fig.savefig(folder / "corner.png", dpi=90)
    plt.close(fig)
    files["corner"] = folder / "corner.png"

    def pair(name, draw, height):
        fig, axes = plt.subplots(1, 2, figsize=(10, height))
        draw(axes)
        fig.tight_layout()
        fig.savefig(folder / f"{name}.png", dpi=100)
        plt.close(fig)
        files[name] = folder / f"{name}.png"

    if median is not None:
        pair("residuals", lambda axes: plot_residuals(lik, median, axes=axes), 3.6)
    if idata is not None:
        pair("rank", lambda axes: plot_rank(idata, n_ens, axes=axes), 3.4)
    return files


def _unseen(spec) -> float:
    """A height never pushed, for the posterior-predictive panel: midway in the widest gap between pushes."""
    hs = np.sort(np.unique(spec.heights_m))
    if hs.size < 2:
        return round(float(min(1.15 * hs[0], 0.5 * (hs[0] + spec.length_m))), 3)
    k = int(np.argmax(np.diff(hs)))
    return round(float(0.5 * (hs[k] + hs[k + 1])), 3)


def write_report(path: Path, summary: dict, figs: dict, spec) -> None:
    """One self-contained HTML file (figures embedded)."""
    rows = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{v['median']:.4g}</td><td>{v['q05']:.4g}</td><td>{v['q95']:.4g}</td>"
        f"<td>{summary['convergence']['rhat'][k]:.4f}</td><td>{summary['convergence']['ess_bulk'][k]:.0f}</td></tr>"
        for k, v in summary["parameters"].items()
    )
    conv = summary["convergence"]
    ok = conv["rhat_max"] <= 1.01 and conv["ess_bulk_min"] >= 400
    verdict = (
        "Converged: independent ensembles agree (R-hat <= 1.01) and every parameter has at least 400 "
        "effectively independent draws."
        if ok
        else "Not converged: treat these numbers as provisional (R-hat > 1.01 or bulk ESS < 400); "
        "run longer or check the data."
    )
    imgs = "".join(
        f'<figure><img alt="{k}" src="data:image/png;base64,{base64.b64encode(Path(p).read_bytes()).decode()}">'
        f"<figcaption>{k.replace('_', ' ')}</figcaption></figure>"
        for k, p in figs.items()
    )
    kt = "".join(
        f"<tr><td>{r['height_m']:g}</td><td>{r['median']:.4g}</td><td>{r['q05']:.4g}</td><td>{r['q95']:.4g}</td></tr>"
        for r in summary["k_theta"]
    )
    fe = summary["fit_error"]
    fe_txt = ", ".join(f"{k} = {v:.3g}" for k, v in fe.items() if v is not None)
    assumptions = "".join(f"<li>{html.escape(a)}</li>" for a in summary.get("assumptions", []))
    ts = summary.get("two_stage")
    ts_html = ""
    if ts:
        ts_html = (
            "<h3>The seed's deterministic two-stage estimate (for comparison)</h3>"
            f"<p>Direct estimator (eq. direct_estimator) in {ts['n_bins']} arc-length bins, p by the weighted "
            f"log-linear fit (eq. p_fit, R<sup>2</sup> = {ts['taper_fit_r2']:.3f}), EI0 from the contact-point "
            f"residual (eq. EI0_fit): EI0 = {ts['EI0']:.4g} N m<sup>2</sup>, p = {ts['p']:.4g} "
            f"(&plusmn; {ts['p_se']:.2g}); the seed's error metrics at that taper: median shape RMSE "
            f"{ts['median_shape_rmse_mm']:.3g} mm, median force error {ts['median_force_error_N']:.3g} N. "
            "Its p is biased by curvature smoothing (docs/inference.md); the posterior above uses the whole "
            "elastica.</p>"
        )
    smp = summary.get("sampler", {})
    prov = spec.extra.get("provenance")
    prov_html = f"<pre>{html.escape(json.dumps(prov, indent=1))}</pre>" if prov else ""
    truth = summary.get("truth")
    truth_html = f"<p>Simulated dataset; the truth: {html.escape(json.dumps(truth))}</p>" if truth else ""
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>bayesrod: {html.escape(spec.specimen)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}figure{{display:inline-block;margin:6px}}
img{{max-width:520px}}.ok{{color:#176a1f}}.bad{{color:#a11}}</style></head><body>
<h1>bayesrod report: {html.escape(spec.specimen)}</h1>
<p>Species: {html.escape(str(spec.species))}. Length {spec.length_m:g} m. Prior: {html.escape(summary["prior"])}.
Effects: {html.escape(", ".join(summary["effects"]) or "none")}.</p>
<h2>Posterior (median and 90% credible interval)</h2>
<table><tr><th>parameter</th><th>median</th><th>5%</th><th>95%</th><th>R-hat</th><th>bulk ESS</th></tr>{rows}</table>
<p>Units: EI0 in N m<sup>2</sup>, p dimensionless, sigma_force_N in N, sigma_shape_m in m.</p>
<h3>Lumped stiffness k<sub>&theta;</sub>(h) [N m/rad] at the pushed heights</h3>
<table><tr><th>h [m]</th><th>median</th><th>5%</th><th>95%</th></tr>{kt}</table>
{ts_html}
<h2>Convergence</h2><p class="{"ok" if ok else "bad"}">{verdict}</p>
<p>emcee: {smp.get("ensembles")} independent ensembles of {smp.get("walkers_per_ensemble")} walkers
(differential-evolution moves), {smp.get("steps")} steps each after a burn-in of {smp.get("burn_in")};
acceptance {smp.get("acceptance", float("nan")):.2f}; {smp.get("seconds")} s. R-hat and bulk ESS by ArviZ over
the ensembles; the rank plot shows one histogram per ensemble.</p>
<p>Fit error at the posterior median: {html.escape(fe_txt)}.</p>
<h2>Figures</h2>{imgs}
<h2>Assumptions</h2><ul>{assumptions}</ul>
<h2>Data</h2><p>{html.escape(str(spec.root))}: {summary["data"]["n_force"]} engaged force samples,
{summary["data"]["n_shape_points"]} centerline points, heights
{", ".join(f"{h:g}" for h in summary["data"]["heights_m"])} m.{_weight_html(summary["data"])}</p>{truth_html}{prov_html}
<p>Generated by bayesrod {__version__}.</p></body></html>"""
    write_text_atomic(path, doc)

"""``bayesrod diagnose``: where does the plain rod fail on these data, and what fixes it?

I/O lives here; the statistics are :mod:`bayesrod.inference.diagnose`. Writes
into DIR (atomically): ``diagnose.json`` (CONTRACT.md section 3, with
extensions), ``figures/residuals.png`` (before/after residual structure),
``figures/statistics.png`` (every effect's test) and ``report.html``.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import numpy as np

from .dataset import read_dataset
from .inference.diagnose import CATALOG, ForwardModel, diagnose
from .inference.likelihood import prepare_data
from .io import atomic_dir, write_json, write_text_atomic


def plot_residual_structure(model: ForwardModel, before, after, axes=None, bins: int = 12):
    """Force residuals against displacement and shape residuals against height, before and after.

    ``before`` / ``after``: :class:`~bayesrod.inference.diagnose.MapFit`. Binned means (lines)
    over the raw residuals (dots). ``axes``: two axes, or None for a new figure. Returns the artists.
    """
    if axes is None:
        import matplotlib.pyplot as plt

        _, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    art = {"force": [], "shape": []}
    for k, d in enumerate(model.data):
        col = f"C{k}"
        sel = model.force_push == k
        for fit, ls, lab in ((before, ":", "plain"), (after, "-", "after")):
            r = fit.r_force[sel]
            if r.size:
                if fit is before:
                    axes[0].plot(d.D_m * 1000, r, ".", ms=2, color=col, alpha=0.35)
                art["force"].append(
                    axes[0].plot(*_binned(d.D_m * 1000, r, bins), ls, color=col, label=f"h = {d.height_m:g} m, {lab}")[
                        0
                    ]
                )
        selp = model.point_push == k
        if selp.any():
            for fit, ls in ((before, ":"), (after, "-")):
                art["shape"].append(axes[1].plot(*_binned(d.z_m, 1000 * fit.r_shape[selp], bins), ls, color=col)[0])
    for ax in axes:
        ax.axhline(0, color="k", lw=0.8)
    axes[0].set(xlabel="contact displacement [mm]", ylabel="force residual [N]", title="forces (dots: plain model)")
    axes[0].legend(fontsize=7, ncol=2)
    axes[1].set(xlabel="height z of the point [m]", ylabel="shape residual [mm]", title="shapes (binned means)")
    if not art["shape"]:
        axes[1].text(0.5, 0.5, "no centerlines", ha="center", va="center", transform=axes[1].transAxes)
    return art


def _binned(t, r, bins):
    edges = np.linspace(np.min(t), np.max(t), bins + 1)
    k = np.clip(np.digitize(t, edges) - 1, 0, bins - 1)
    c = np.array([t[k == b].mean() if np.any(k == b) else np.nan for b in range(bins)])
    m = np.array([r[k == b].mean() if np.any(k == b) else np.nan for b in range(bins)])
    return c, m


def plot_statistics(result: dict, ax=None):
    """Each effect's test statistic per round (log scale) against its selection threshold. Returns the bars."""
    from scipy import stats

    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 3.6))
    rows = result["candidates"]
    rounds = sorted({r["round"] for r in rows})
    width = 0.8 / max(len(rounds), 1)
    bars = []
    for j, rnd in enumerate(rounds):
        rr = {r["effect"]: r for r in rows if r["round"] == rnd}
        x = np.arange(len(CATALOG)) + j * width
        val = [max(rr[e]["statistic"], 1e-2) if e in rr else np.nan for e in CATALOG]
        col = ["C2" if e in rr and rr[e]["selected"] else f"C{j}" for e in CATALOG]
        bars.append(ax.bar(x, val, width=width, color=col, label=f"round {rnd}"))
        level = next(iter(rr.values()))["level"]
        ax.hlines(stats.chi2.isf(level, 1), x[0] - width / 2, x[-1] + width / 2, colors="k", linestyles=":")
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(CATALOG)) + 0.4 - width / 2, CATALOG, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("test statistic (chi^2 scale)")
    ax.set_title("effect tests (green: added; dotted: threshold)", fontsize=9)
    ax.legend(fontsize=8)
    return bars


def run_diagnose(
    dataset,
    out,
    *,
    candidates=CATALOG,
    use_shapes: bool = True,
    alpha: float = 0.01,
    min_heldout_gain: float = 0.10,
    force: bool = False,
    log=print,
) -> dict:
    """Diagnose one dataset; writes DIR/diagnose.json, figures and report.html. Returns the JSON document."""
    spec = read_dataset(dataset)
    model = ForwardModel(prepare_data(spec, use_forces=True, use_shapes=use_shapes), spec.length_m)
    res = diagnose(model, candidates=tuple(candidates), alpha=alpha, min_heldout_gain=min_heldout_gain, log=log)
    fit_after, plain = res.pop("_fit"), res.pop("_plain")
    doc = {
        "specimen": spec.specimen,
        "dataset": str(Path(dataset).resolve()),
        "length_m": spec.length_m,
        "observations": {"n_force": model.n_force, "n_shape_points": model.n_points},
        **res,
        "settings": {"alpha": alpha, "min_heldout_gain": min_heldout_gain, "candidates": list(candidates)},
    }
    truth = spec.extra.get("truth")
    if truth:
        doc["truth"] = truth
    with atomic_dir(out, force) as tmp:
        write_json(tmp / "diagnose.json", doc)
        figs = _figures(model, plain, fit_after, doc, tmp / "figures")
        write_text_atomic(tmp / "report.html", _report(doc, figs, spec))
    return doc


def _figures(model, before, after, doc, folder: Path) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), layout="constrained")
    plot_residual_structure(model, before, after, axes=axes)
    fig.savefig(folder / "residuals.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6.4, 3.8), layout="constrained")
    plot_statistics(doc, ax=ax)
    fig.savefig(folder / "statistics.png", dpi=100)
    plt.close(fig)
    return {"residuals": folder / "residuals.png", "statistics": folder / "statistics.png"}


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec)


def _report(doc: dict, figs: dict, spec) -> str:
    b, a = doc["before"], doc["after"]
    keys = ("force_rmse_N", "shape_rmse_mm", "heldout_force_rmse_N")
    err = "".join(f"<tr><td>{k}</td><td>{_fmt(b[k])}</td><td>{_fmt(a[k])}</td></tr>" for k in keys)
    cand = "".join(
        f"<tr><td>{r['round']}</td><td>{html.escape(r['effect'])}</td><td>{r['statistic']:.3g}</td>"
        f"<td>{r['p_value']:.2g}</td><td>{_fmt(r.get('lr_statistic'), '.3g')}</td>"
        f"<td>{_fmt(r.get('heldout_force_rmse_N'))}</td><td>{'added' if r['selected'] else ''}"
        f"{html.escape(r.get('rejected_because', ''))}</td></tr>"
        for r in doc["candidates"]
    )
    blocks = "".join(
        f"<tr><td>{html.escape(s['push'])}</td><td>{s['kind']}</td><td>{s['n']}</td><td>{s['p_value']:.2g}</td>"
        f"<td>{s['structured_sd_ratio']:.2f}</td><td>{'yes' if s['structured'] else ''}</td></tr>"
        for s in doc["structure_after"]
    )
    verdict = (
        "Residual structure remains that no catalog effect removes: the model still misses something here. "
        "Read the figures before trusting extrapolations."
        if doc["unexplained_structure"]
        else "No material residual structure remains."
    )
    added = ", ".join(doc["added_effects"]) or "none"
    imgs = "".join(
        f'<figure><img alt="{k}" src="data:image/png;base64,{base64.b64encode(Path(p).read_bytes()).decode()}">'
        f"<figcaption>{k}</figcaption></figure>"
        for k, p in figs.items()
    )
    truth = doc.get("truth")
    truth_html = f"<p>Simulated; the truth: {html.escape(json.dumps(truth))}</p>" if truth else ""
    title = html.escape(spec.specimen)
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>bayesrod diagnose: {title}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}figure{{display:inline-block;margin:6px}}
img{{max-width:1000px}}</style></head><body>
<h1>Diagnosis: {html.escape(spec.specimen)}</h1>
<p>Effects added: <b>{html.escape(added)}</b>. {verdict}</p>
<p>Fitted after: {html.escape(json.dumps({k: round(v, 5) for k, v in doc["fitted"].items()}))}</p>
<h2>Error before and after</h2>
<table><tr><th>error</th><th>plain rod</th><th>after</th></tr>{err}</table>
<p>Held-out: each height is left out in turn, the model refitted on the others, and its forces predicted.</p>
<h2>Effect tests</h2>
<table><tr><th>round</th><th>effect</th><th>statistic</th><th>p</th><th>LR after fit</th><th>held-out RMSE [N]</th>
<th>outcome</th></tr>{cand}</table>
<h2>Residual structure after</h2>
<table><tr><th>push</th><th>kind</th><th>n</th><th>p (F test)</th><th>structured sd / noise sd</th>
<th>flagged</th></tr>{blocks}</table>
<h2>Figures</h2>{imgs}{truth_html}
</body></html>"""

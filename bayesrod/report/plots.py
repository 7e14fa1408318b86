"""Figures. Each function takes ``ax=None`` (a new figure if None) and returns what it drew."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..inference.diagnose import CATALOG
from ..inference.likelihood import force_offset_name, height_error_name, preload_name
from ..inference.summary import (
    QUANTILES,
    diameter_draws,
    draw_lengths,
    ei_band,
    k_theta_band,
    modulus_draws,
    predictive_forces,
    quantiles,
)

if TYPE_CHECKING:
    from ..inference.diagnose import ForwardModel
    from ..inference.hierarchical import SpecimenPosterior


def _ax(ax):
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 4))
    return ax


def plot_ei_band(samples: dict, length_m: float, ax=None, truth: dict | None = None, color="C3", direct=None):
    """EI(s) median and 90% credible band (seed Fig. ei_direct_vs_taper, with uncertainty).

    ``direct`` (a :class:`~bayesrod.inference.direct.DirectEstimate`) adds the pooled direct-estimate
    bins with 90% error bars (1.645 standard errors).
    """
    ax = _ax(ax)
    s = np.linspace(0, length_m * 0.98, 200)
    band = ei_band(samples["EI0"], samples["p"], draw_lengths(samples, length_m), s)
    fill = ax.fill_between(s, band["q05"], band["q95"], color=color, alpha=0.3, label="90% credible band")
    (line,) = ax.plot(s, band["median"], color=color, label="posterior median")
    artists = {"band": fill, "median": line}
    if truth:
        t = truth["EI0"] * np.clip(1 - s / length_m, 0, 1) ** (4 * truth["p"])
        (artists["truth"],) = ax.plot(s, t, "k--", lw=1, label="truth (simulated)")
    if direct is not None:
        ok = np.isfinite(direct.EI)
        lo = np.maximum(direct.EI[ok] - 1.645 * direct.se[ok], direct.EI[ok] * 0.05)
        artists["direct"] = ax.errorbar(
            direct.s_m[ok],
            direct.EI[ok],
            yerr=[direct.EI[ok] - lo, 1.645 * direct.se[ok]],
            fmt="o",
            ms=3,
            color="k",
            ecolor="0.4",
            label="direct estimate per bin (eq. direct_estimator)",
        )
    ax.set(xlabel="arc length s [m]", ylabel="EI(s) [N m$^2$]", yscale="log", title="Flexural rigidity profile")
    ax.legend()
    return artists


def plot_diameter_fit(samples: dict, length_m: float, diameters, ax=None, color="C2", modulus_ax=None):
    """Measured diameters (90% error bars, 1.645 sd) against the fitted d(s) median and 90% band.

    ``diameters``: a :class:`~bayesrod.dataset.model.Diameters`. ``modulus_ax``: where the modulus may
    vary (the free width model), also draws E(s) [GPa] with its 90% band there. Returns the artists.
    """
    ax = _ax(ax)
    s = np.linspace(0, length_m * 0.98, 200)
    band = quantiles(diameter_draws(samples, length_m, s) * 1000)
    artists = {
        "band": ax.fill_between(s, band["q05"], band["q95"], color=color, alpha=0.3, label="fitted d(s), 90% band"),
        "median": ax.plot(s, band["median"], color=color, label="fitted d(s), median")[0],
        "measured": ax.errorbar(
            diameters.s_m,
            diameters.d_m * 1000,
            yerr=1.645 * diameters.sd_m * 1000,
            fmt="o",
            ms=2,
            color="k",
            ecolor="0.6",
            label=f"measured ({diameters.source})",
        ),
    }
    ax.set(xlabel="arc length s [m]", ylabel="diameter [mm]", title="Stem diameter")
    ax.legend()
    if modulus_ax is not None:
        E = quantiles(modulus_draws(samples, length_m, s) / 1e9)
        artists["modulus_band"] = modulus_ax.fill_between(
            s, E["q05"], E["q95"], color="C4", alpha=0.3, label="90% band"
        )
        (artists["modulus_median"],) = modulus_ax.plot(s, E["median"], color="C4", label="median")
        modulus_ax.set(xlabel="arc length s [m]", ylabel="E(s) [GPa]", title="Young's modulus along the stem")
        modulus_ax.legend()
    return artists


def plot_k_theta_band(samples: dict, length_m: float, heights_pushed, ax=None, color="C0", lumped=None):
    """k_theta(h) (eq. kdist) median and 90% band over heights, pushed heights marked.

    ``lumped``: optional list of (height_m, k_theta) from the per-height torque-balance fit
    (eq. torque_balance with the link angle atan(x_c/h) of the camera-free recovery; the seed's
    Fig. height_invariance), drawn as points. The link angle is not the tangent rotation that
    eq. kdist uses (for constant EI they give 3EI/h against 2EI/h), so the points are compared with
    the posterior band of the quantity they estimate, h^2 k_x(h) (eq. kx), drawn dashed.
    """
    ax = _ax(ax)
    h = np.linspace(0.05 * length_m, 0.95 * length_m, 120)
    Ld = draw_lengths(samples, length_m)
    band = k_theta_band(samples["EI0"], samples["p"], Ld, h, samples.get("base_compliance"))
    fill = ax.fill_between(h, band["q05"], band["q95"], color=color, alpha=0.3, label="90% credible band")
    (line,) = ax.plot(h, band["median"], color=color, label="posterior median")
    marks = [ax.axvline(x, color="0.5", ls=":", lw=1) for x in heights_pushed]
    pts = None
    if lumped:
        from ..physics import k_x

        kb = samples.get("base_compliance")
        kb = np.inf if kb is None else np.asarray(kb)[:, None]
        link = quantiles(
            h[None, :] ** 2
            * k_x(h[None, :], np.asarray(samples["EI0"])[:, None], np.asarray(samples["p"])[:, None], Ld, kb)
        )
        ax.fill_between(h, link["q05"], link["q95"], color="0.5", alpha=0.25)
        ax.plot(h, link["median"], "--", color="0.3", lw=1, label=r"link-angle stiffness $h^2 k_x$ (posterior)")
        hh, kk = np.array(lumped, float).T
        pts = ax.plot(hh, kk, "ks", ms=5, label="per-height torque-balance fit (link angle)")[0]
    ax.set(
        xlabel="contact height h [m]",
        ylabel=r"$k_\theta$ [N m/rad]",
        yscale="log",
        title="Lumped rotational stiffness (eq. kdist)",
    )
    ax.legend()
    return {"band": fill, "median": line, "pushed": marks, "lumped": pts}


def plot_force_fit(spec, lik, samples: dict, ax=None, n_draws=100, unseen_height=None, rng=None):
    """Measured force against contact displacement with posterior bands per height (seed Fig. veg_force_fit)."""
    ax = _ax(ax)
    rng = rng or np.random.default_rng(0)
    n = len(samples["EI0"])
    idx = rng.choice(n, size=min(n_draws, n), replace=False)
    artists = {"data": [], "bands": []}
    heights = [(d.height_m, d) for d in lik.data]
    if unseen_height is not None:
        heights.append((unseen_height, None))
    for k, (h, d) in enumerate(heights):
        col = f"C{k}"
        Dmax = float(d.D_m.max()) if d is not None and d.D_m.size else 0.3 * spec.length_m
        D = np.linspace(0, Dmax, 40)
        # the push's fitted nuisances, draw by draw: preload F(D + d0), height error h + dh, load-cell offset
        nuis = {
            k: (None if d is None or fn(d.id) not in samples else np.asarray(samples[fn(d.id)])[idx])
            for k, fn in (
                ("preload_m", preload_name),
                ("height_error_m", height_error_name),
                ("force_offset_N", force_offset_name),
            )
        }
        F = predictive_forces(samples, idx, D, h, spec.length_m, **nuis)["force_N"]
        q = quantiles(F)
        label = f"h = {h:g} m" + (" (not pushed)" if d is None else "")
        artists["bands"].append(ax.fill_between(D, q["q05"], q["q95"], color=col, alpha=0.3, label=label))
        if d is not None and d.D_m.size:
            artists["data"].append(ax.plot(d.D_m, d.F_N, ".", color=col, ms=3)[0])
        else:
            ax.plot(D, q["median"], "--", color=col)
    ax.set(
        xlabel="contact displacement since first contact [m]",
        ylabel="force [N]",
        title="Force: data and posterior 90% bands",
    )
    ax.legend(fontsize=8)
    return artists


def plot_corner(samples: dict, names=("EI0", "p"), truth: dict | None = None, fig=None):
    """Corner plot (``corner``) of the named parameters."""
    import corner

    data = np.column_stack([samples[n] for n in names])
    truths = [truth.get(n) for n in names] if truth else None
    return corner.corner(
        data, labels=list(names), quantiles=list(QUANTILES), show_titles=True, truths=truths, fig=fig, title_fmt=".4g"
    )


def plot_residuals(lik, params: dict, axes=None):
    """Residuals at one parameter set: force against contact displacement, shape against height z.

    ``axes``: two axes (a new figure if None). Returns the drawn artists.
    """
    if axes is None:
        import matplotlib.pyplot as plt

        _, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    res = lik.residuals({k: np.atleast_1d(v) for k, v in params.items()})
    artists = {"force": [], "shape": []}
    off_f = off_s = 0
    for k, d in enumerate(lik.data):
        col = f"C{k}"
        n = d.D_m.size
        if "force" in res and n:
            artists["force"].append(
                axes[0].plot(
                    d.D_m, res["force"][0, off_f : off_f + n], ".", ms=3, color=col, label=f"h = {d.height_m:g} m"
                )[0]
            )
            off_f += n
        m = d.x_m.size
        if "shape" in res and m:
            artists["shape"].append(
                axes[1].plot(d.z_m, 1000 * res["shape"][0, off_s : off_s + m], ".", ms=1, alpha=0.4, color=col)[0]
            )
            off_s += m
    for ax in axes:
        ax.axhline(0, color="k", lw=0.8)
    axes[0].set(
        xlabel="contact displacement [m]", ylabel="force residual [N]", title="Force residuals (observed - model)"
    )
    axes[1].set(
        xlabel="height z of the point [m]", ylabel="shape residual [mm]", title="Shape residuals (normal distance)"
    )
    if artists["force"]:
        axes[0].legend(fontsize=8)
    return artists


def plot_rank(idata, n_ensembles: int, var_names=("EI0", "p"), axes=None, bins: int = 20):
    """Rank histograms per independent ensemble (Vehtari et al. 2021): flat and overlapping = agreement.

    The posterior's chains are the walkers of all ensembles; walkers of one ensemble are not
    independent, so ranks are pooled per ensemble. Returns the drawn step lines per variable.
    """
    from scipy.stats import rankdata

    if axes is None:
        import matplotlib.pyplot as plt

        _, axes = plt.subplots(1, len(var_names), figsize=(5 * len(var_names), 3.4))
    axes = np.atleast_1d(axes)
    out = {}
    for ax, name in zip(axes, var_names, strict=True):
        x = np.asarray(idata.posterior[name])  # (chains, draws)
        r = rankdata(x.ravel()).reshape(x.shape)
        groups = np.array_split(np.arange(x.shape[0]), n_ensembles)
        edges = np.linspace(0, r.size, bins + 1)
        lines = []
        for k, g in enumerate(groups):
            cnt, _ = np.histogram(r[g].ravel(), bins=edges)
            lines.append(
                ax.step(np.arange(bins), cnt / cnt.mean(), where="mid", color=f"C{k}", label=f"ensemble {k + 1}")[0]
            )
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set(title=f"rank plot: {name}", xlabel="rank bin (all draws)", ylabel="count / mean", ylim=(0, 2))
        ax.legend(fontsize=7, ncol=2)
        out[name] = lines
    return out


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


def plot_forest(fit: dict, specimens: list[SpecimenPosterior], ax=None):
    """Species-level EI0 (90% interval) with each specimen's median: a forest plot. Returns the artists."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 0.6 + 0.5 * len(specimens) + 0.6 * len(fit["species"])))
    artists = {"species": [], "specimens": []}
    y = 0
    ticks, labels = [], []
    for g, sp in enumerate(fit["species"]):
        q05, q50, q95 = np.exp(np.quantile(fit["mu"][:, g, 0], QUANTILES))
        artists["species"].append(ax.errorbar(q50, y, xerr=[[q50 - q05], [q95 - q50]], fmt="D", color=f"C{g}", ms=7))
        ticks.append(y)
        labels.append(f"{sp} (species)")
        y -= 1
        for s in [s for s in specimens if s.species == sp]:
            lo, med, hi = np.exp(np.quantile(s.draws[:, 0], QUANTILES))
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


def plot_extraction(rgb, line, ax=None, camera=None, direction=1):
    """RGB frame with the segmentation (orange), skeleton (blue) and tracked pixel path (cyan).

    With ``camera`` (the specimen's pinhole block) the written points are drawn too: seen points
    yellow, points bridged across an occlusion hollow magenta. Returns the artists drawn.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(8, 6))
    img = ax.imshow(rgb)
    mask = ax.imshow(np.ma.masked_where(~line.mask, line.mask), cmap="autumn", alpha=0.45)
    vv, uu = np.nonzero(line.skeleton)
    sk = ax.plot(uu, vv, ",", color="b")[0]
    (path,) = ax.plot(
        line.path_uv[:, 0], line.path_uv[:, 1], "c-", lw=1.2, label="pixel path (Dijkstra + tip tracking)"
    )
    out = {"image": img, "mask": mask, "skeleton": sk, "path": path}
    if camera is not None:
        u0, v0 = camera["base_px"]
        u = u0 + direction * line.x_m * camera["fx"] / line.plane_depth_m
        v = v0 - line.z_m * camera["fy"] / line.plane_depth_m
        seen = line.observed if line.observed is not None else np.ones(u.size, bool)
        out["seen"] = ax.plot(u[seen], v[seen], "o", ms=2.5, color="yellow", label="centerline points")[0]
        if (~seen).any():
            out["bridged"] = ax.plot(
                u[~seen], v[~seen], "o", ms=4, mfc="none", color="magenta", label="bridged across an occlusion"
            )[0]
    ax.set(title=f"extracted length {line.length_m:.3f} m, plane depth {line.plane_depth_m:.3f} m")
    ax.legend(loc="upper right", fontsize=8)
    ax.axis("off")
    return out

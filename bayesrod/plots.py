"""Figures. Each function takes ``ax=None`` (a new figure if None) and returns what it drew."""

from __future__ import annotations

import numpy as np

from .inference.summary import ei_band, k_theta_band, predictive_forces, quantiles


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
    band = ei_band(samples["EI0"], samples["p"], length_m, s)
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


def plot_k_theta_band(samples: dict, length_m: float, heights_pushed, ax=None, color="C0"):
    """k_theta(h) (eq. kdist) median and 90% band over heights, pushed heights marked."""
    ax = _ax(ax)
    h = np.linspace(0.05 * length_m, 0.95 * length_m, 120)
    band = k_theta_band(samples["EI0"], samples["p"], length_m, h, samples.get("base_compliance"))
    fill = ax.fill_between(h, band["q05"], band["q95"], color=color, alpha=0.3, label="90% credible band")
    (line,) = ax.plot(h, band["median"], color=color, label="posterior median")
    marks = [ax.axvline(x, color="0.5", ls=":", lw=1) for x in heights_pushed]
    ax.set(
        xlabel="contact height h [m]",
        ylabel=r"$k_\theta$ [N m/rad]",
        yscale="log",
        title="Lumped rotational stiffness (eq. kdist)",
    )
    ax.legend()
    return {"band": fill, "median": line, "pushed": marks}


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
        F = predictive_forces(samples, idx, D, h, spec.length_m)["force_N"]
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
        data, labels=list(names), quantiles=[0.05, 0.5, 0.95], show_titles=True, truths=truths, fig=fig, title_fmt=".4g"
    )

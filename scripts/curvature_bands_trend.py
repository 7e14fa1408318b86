"""Curvature bands with and without the smoothing bias (docs/vision.md, "Curvature with uncertainty").

    python scripts/curvature_bands_trend.py arcs     # analytic arcs and elastica angles (1 min)
    python scripts/curvature_bands_trend.py points   # elastica from noisy points, 0.5-3 mm (2 min)
    python scripts/curvature_bands_trend.py grid     # 48 cases: taper, load, noise, spacing (20 min)

Coverage of the 90% band (10 replicates per case; 20 on the grid) for: ``se`` the sampling sd
alone (bayesrod's band before session 5), ``sd`` the shipped ``kappa_sd`` (sampling sd plus the
plug-in bias from the quadratic-trend pilot), ``pbc`` the same with the bias estimate's own
sampling variance removed, and the variants measured and not adopted: ``se2`` the pilot
(quadratic trend) as the estimate, ``lep1`` / ``lep2`` either estimate with the squared
difference of the two added, ``lepmax`` the larger sampling variance plus that difference,
``cv`` the trend degree picked by leave-one-out error (``pick2``: how often 2).
"""

import sys

import numpy as np
from scipy.linalg import cho_solve

from bayesrod.physics.elastica import contact_from_force_nd
from bayesrod.vision.curvature import fit_curvature_gp, tangent_angles

PICK = []  # per replicate: whether leave-one-out preferred the quadratic trend


def _w(g, q):
    """Derivative weights (m, n) of a fitted GP: kappa(q) = W (theta - mean)."""
    _, ks = g._k(q, g.s)
    return cho_solve((g.chol, True), ks.T).T


def _loo(g, y):
    kinv = cho_solve((g.chol, True), np.eye(g.s.size))
    return np.mean(((kinv @ (y - g.mean)) / np.diag(kinv)) ** 2)


def bands(s, y, cov, q):
    g1 = fit_curvature_gp(s, y, noise_cov=cov)
    g2 = g1.pilot
    p1, p2 = g1.predict(q), g2.predict(q)
    d2 = (p1["kappa"] - p2["kappa"]) ** 2
    w1, w2 = _w(g1, q), _w(g2, q)
    k2f = g2._k(g2.s, g2.s)[0]
    s2 = k2f @ cho_solve((g2.chol, True), np.eye(s.size))
    bvar = np.einsum("mi,ij,mj->m", w1 @ s2 - w2, g1.noise_cov, w1 @ s2 - w2)
    pick2 = _loo(g2, y) < _loo(g1, y)
    PICK.append(pick2)
    se1, se2 = p1["kappa_se2"], p2["kappa_se2"]
    return {
        "se": (p1["kappa"], np.sqrt(se1)),
        "sd": (p1["kappa"], p1["kappa_sd"]),
        "pbc": (p1["kappa"], np.sqrt(se1 + np.maximum(p1["kappa_bias2"] - bvar, 0))),
        "se2": (p2["kappa"], np.sqrt(se2)),
        "lep1": (p1["kappa"], np.sqrt(se1 + d2)),
        "lep2": (p2["kappa"], np.sqrt(se2 + d2)),
        "lepmax": (p1["kappa"], np.sqrt(np.maximum(se1, se2) + d2)),
        "cv": (p2["kappa"], np.sqrt(se2)) if pick2 else (p1["kappa"], np.sqrt(se1)),
    }


def run(name, gen, reps=10, seed=1, keys=None):
    PICK.clear()
    rng = np.random.default_rng(seed)
    cov = {}
    for _ in range(reps):
        s, y, c, q, truth = gen(rng)
        for k, (m, sd) in bands(s, y, c, q).items():
            cov.setdefault(k, []).append(np.mean(np.abs(m - truth) <= 1.6449 * sd))
    keys = keys or list(cov)
    print(f"{name:44s} pick2 {np.mean(PICK):.1f} ", "  ".join(f"{k} {np.mean(cov[k]):.2f}" for k in keys), flush=True)


def arc(theta, kappa, sd=0.01):
    def g(rng):
        s = np.linspace(0, 0.8, 80)
        q = np.linspace(s[2], s[-3], 120)
        return s, theta(s) + rng.normal(0, sd, s.size), None, q, kappa(q)

    return g


def el_angles(f, sd=0.005):
    eta, p, L = 0.5625, 0.43, 0.8
    res = contact_from_force_nd(f, eta, p, n_steps=256, keep_shape=True)
    sig = np.linspace(0, 1, 257)
    phi = res["grid"][:, 2]
    s = sig[sig < 0.95 * float(res["sig_c"])][::3] * L

    def g(rng):
        q = np.linspace(s[2], s[-3], 120)
        truth = np.interp(q, sig * L, np.gradient(phi, sig * L))
        return s, np.interp(s, sig * L, phi) + rng.normal(0, sd, s.size), None, q, truth

    return g


def el_points(f, noise=0.0015, step=5, eta=0.5625, p=0.43, L=0.8):
    """Elastica points every ``step`` x 2 mm below the contact with isotropic noise [m]."""
    res = contact_from_force_nd(f, eta, p, n_steps=400, keep_shape=True)
    sig = np.linspace(0, 1, 401)
    g_ = res["grid"]
    kt = np.gradient(g_[:, 2], sig * L)
    idx = np.flatnonzero(sig < 0.95 * float(res["sig_c"]))[::step]

    def g(rng):
        sd = np.full(idx.size, noise)
        x = g_[idx, 0] * L + rng.normal(0, noise, idx.size)
        z = g_[idx, 1] * L + rng.normal(0, noise, idx.size)
        ta = tangent_angles(x, z, sd)
        q = np.linspace(0.03, 0.9 * ta["s"][-1], 60)
        return ta["s"], ta["theta"], ta["cov"], q, np.interp(q, sig * L, kt)

    return g


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "arcs"
    if which == "arcs":
        run("circle", arc(lambda s: 0.2 + 2.0 * s, lambda s: np.full_like(s, 2.0)))
        run("clothoid", arc(lambda s: 3.0 * s**2, lambda s: 6.0 * s))
        run("sine", arc(lambda s: 0.3 * np.sin(6 * s), lambda s: 1.8 * np.cos(6 * s)))
        run("sine fast", arc(lambda s: 0.3 * np.sin(12 * s), lambda s: 3.6 * np.cos(12 * s)))
        for f in (0.6, 1.2, 2.0):
            run(f"elastica angles f={f}", el_angles(f), seed=2)
    elif which == "points":
        for f in (0.3, 0.6, 1.2, 2.0):
            run(f"points 1.5mm f={f}", el_points(f), seed=5)
        for f in (0.6, 1.2):
            run(f"points 0.5mm f={f}", el_points(f, 0.0005), seed=5)
            run(f"points 3mm f={f}", el_points(f, 0.003), seed=5)
    else:
        for p, eta in [(0.43, 0.5625), (1.2, 0.25)]:
            for f in (0.3, 0.6, 1.2, 2.0):
                for noise in (0.0003, 0.001, 0.002):
                    for step in (3, 5):
                        name = f"p={p} eta={eta} f={f} noise={noise} step={step}"
                        run(name, el_points(f, noise, step, eta, p), reps=20, seed=11, keys=["se", "sd", "pbc"])

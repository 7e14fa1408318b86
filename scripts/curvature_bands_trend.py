"""Bias-aware curvature bands from a second trend degree (docs/vision.md, "tried and not adopted").

    python scripts/curvature_bands_trend.py arcs     # analytic arcs and elastica angles
    python scripts/curvature_bands_trend.py points   # elastica from noisy points, 0.5-3 mm

Coverage of the 90% band (10 replicates each) for: ``se1`` the GP with a linear trend and its
sampling band (what bayesrod uses), ``se2`` the same with a quadratic trend, ``lep1``/``lep2``
either estimate with the squared difference of the two added to its variance, ``lep*c`` the same
with the difference's own sampling variance removed, ``lepmax`` the larger sampling variance plus
the difference, ``cv`` the degree picked by leave-one-out error, and ``pick2`` how often that is 2.
"""

import sys

import numpy as np
from scipy.linalg import cho_solve

from bayesrod.physics.elastica import contact_from_force_nd
from bayesrod.vision.curvature import fit_curvature_gp, tangent_angles


def bands(s, y, cov, q):
    g1 = fit_curvature_gp(s, y, noise_cov=cov) if cov is not None else fit_curvature_gp(s, y)
    g2 = fit_curvature_gp(s, y, noise_cov=cov, degree=2) if cov is not None else fit_curvature_gp(s, y, degree=2)
    p1, p2 = g1.predict(q), g2.predict(q)
    d2 = (p1["kappa"] - p2["kappa"]) ** 2

    def Wm(g):
        _, ks = g._k(q, g.s)
        return cho_solve((g.chol, True), ks.T).T

    # plug-in bias of the linear-trend estimate, with the quadratic-trend fit as the pilot truth:
    # b = W1 (S2 y) - k2, S2 the pilot's smoother at the data (K2 without noise times K2^-1)
    W1, W2 = Wm(g1), Wm(g2)
    K2f = g2._k(g2.s, g2.s)[0]
    S2 = K2f @ cho_solve((g2.chol, True), np.eye(s.size))
    b = W1 @ (S2 @ (y - g1.mean)) - p2["kappa"]  # the pilot's mean cancels in W1 (trend in the kernel)
    B = W1 @ S2 - W2
    vb = np.einsum("mi,ij,mj->m", B, g1.noise_cov, B)
    D = W1 - W2
    vd = np.einsum("mi,ij,mj->m", D, g1.noise_cov, D)
    b2 = np.maximum(d2 - vd, 0)

    def loo(g, yy):
        Kinv = cho_solve((g.chol, True), np.eye(g.s.size))
        r = (Kinv @ (yy - g.mean)) / np.diag(Kinv)
        return np.mean(r**2)

    pick2 = loo(g2, y) < loo(g1, y)
    PICK.append(pick2)
    return {
        "pb": (p1["kappa"], np.sqrt(p1["kappa_se2"] + b**2)),
        "pbc": (p1["kappa"], np.sqrt(p1["kappa_se2"] + np.maximum(b**2 - vb, 0))),
        "pbs": (p1["kappa"], np.sqrt(p1["kappa_se2"] + b**4 / (b**2 + vb + 1e-300))),
        "pbq": (p1["kappa"], np.sqrt(p1["kappa_se2"] + np.maximum(b**2 - 0.25 * vb, 0))),
        "pbh": (p1["kappa"], np.sqrt(p1["kappa_se2"] + np.maximum(b**2 - 0.5 * vb, 0))),
        "cv": (p2["kappa"], p2["kappa_sd"]) if pick2 else (p1["kappa"], p1["kappa_sd"]),
        "lep1c": (p1["kappa"], np.sqrt(p1["kappa_se2"] + b2)),
        "lep2c": (p2["kappa"], np.sqrt(p2["kappa_se2"] + b2)),
        "lepmaxc": (p1["kappa"], np.sqrt(np.maximum(p1["kappa_se2"], p2["kappa_se2"]) + b2)),
        "se1": (p1["kappa"], p1["kappa_sd"]),
        "se2": (p2["kappa"], p2["kappa_sd"]),
        "lep1": (p1["kappa"], np.sqrt(p1["kappa_se2"] + d2)),
        "lep2": (p2["kappa"], np.sqrt(p2["kappa_se2"] + d2)),
        "lepmax": (p1["kappa"], np.sqrt(np.maximum(p1["kappa_se2"], p2["kappa_se2"]) + d2)),
    }


PICK = []


def run(name, gen, reps=10, seed=1):
    PICK.clear()
    rng = np.random.default_rng(seed)
    cov = {}
    for _ in range(reps):
        s, y, c, q, truth = gen(rng)
        for k, (m, sd) in bands(s, y, c, q).items():
            cov.setdefault(k, []).append(np.mean(np.abs(m - truth) <= 1.6449 * sd))
    print(
        f"{name:28s}",
        f"pick2 {np.mean(PICK):.1f}",
        "  ".join(f"{k} {np.mean(v):.2f}" for k, v in cov.items()),
        flush=True,
    )


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
    keep = sig < 0.95 * float(res["sig_c"])
    s = sig[keep][::3] * L

    def g(rng):
        q = np.linspace(s[2], s[-3], 120)
        return (
            s,
            np.interp(s, sig * L, phi) + rng.normal(0, sd, s.size),
            None,
            q,
            np.interp(q, sig * L, np.gradient(phi, sig * L)),
        )

    return g


def el_points(f, noise=0.0015, step=5):
    eta, p, L = 0.5625, 0.43, 0.8
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


which = sys.argv[1] if len(sys.argv) > 1 else "arcs"
if which == "arcs":
    run("circle", arc(lambda s: 0.2 + 2.0 * s, lambda s: np.full_like(s, 2.0)))
    run("clothoid", arc(lambda s: 3.0 * s**2, lambda s: 6.0 * s))
    run("sine", arc(lambda s: 0.3 * np.sin(6 * s), lambda s: 1.8 * np.cos(6 * s)))
    run("sine fast", arc(lambda s: 0.3 * np.sin(12 * s), lambda s: 3.6 * np.cos(12 * s)))
    for f in (0.6, 1.2, 2.0):
        run(f"elastica angles f={f}", el_angles(f), seed=2)
else:
    for f in (0.3, 0.6, 1.2, 2.0):
        run(f"points 1.5mm f={f}", el_points(f), seed=5)
    for f in (0.6, 1.2):
        run(f"points 0.5mm f={f}", el_points(f, 0.0005), seed=5)
        run(f"points 3mm f={f}", el_points(f, 0.003), seed=5)

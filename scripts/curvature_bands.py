"""Candidate curvature bands against the truth (docs/vision.md, "tried and not adopted").

    python scripts/curvature_bands.py

Coverage of the 90% band of four uncertainty estimates for the GP curvature:
``se`` (the sampling sd alone: bayesrod's band before session 5, now kappa_sd adds a bias term), ``post`` (the posterior
sd), ``geo`` (geometric mean of the two variances) and ``bias`` (sampling
variance plus the squared residual-based bias estimate W (S y - y)), on a
circle, a clothoid and a sine (theta noise 0.01 rad) and on elastica shapes
from 1.5-mm-noisy points at f = 0.3, 1.2, 2.0 (10 replicates each).
"""

import numpy as np
from scipy.linalg import cho_solve

from bayesrod.physics.elastica import contact_from_force_nd
from bayesrod.vision.curvature import fit_curvature_gp, tangent_angles


def bands(gp, q, y):
    pr = gp.predict(q)
    # residual-based bias estimate: W (S y - y) at the query
    k, _ = gp._k(gp.s, gp.s)
    _, ksq = gp._k(q, gp.s)
    W = cho_solve((gp.chol, True), ksq.T).T
    th_hat = gp.mean + k @ gp.alpha  # smoothed theta at the data (the kernel without noise)
    b = W @ (th_hat - y)
    out = {
        "se": np.sqrt(pr["kappa_se2"]),
        "post": np.sqrt(pr["kappa_var"]),
        "geo": (pr["kappa_se2"] * pr["kappa_var"]) ** 0.25,
        "bias": np.sqrt(pr["kappa_se2"] + b**2),
    }
    return pr["kappa"], out


def arcs(name, theta, kappa, sd=0.01, reps=10, seed=1):
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 0.8, 80)
    cov = {}
    for _ in range(reps):
        y = theta(s) + rng.normal(0, sd, s.size)
        gp = fit_curvature_gp(s, y)
        q = np.linspace(s[2], s[-3], 120)
        k, bs = bands(gp, q, y)
        for kk, v in bs.items():
            cov.setdefault(kk, []).append(np.mean(np.abs(k - kappa(q)) <= 1.6449 * v))
    print(name, {k: round(float(np.mean(v)), 3) for k, v in cov.items()})


def noisy_points(f, seed=5):
    eta, p, L = 0.5625, 0.43, 0.8
    res = contact_from_force_nd(f, eta, p, n_steps=400, keep_shape=True)
    sig = np.linspace(0, 1, 401)
    g = res["grid"]
    kappa_true = np.gradient(g[:, 2], sig * L)
    below = sig < 0.95 * float(res["sig_c"])
    idx = np.flatnonzero(below)[::5]
    rng = np.random.default_rng(seed)
    cov = {}
    for _ in range(10):
        sd = np.full(idx.size, 0.0015)
        x = g[idx, 0] * L + rng.normal(0, 0.0015, idx.size)
        z = g[idx, 1] * L + rng.normal(0, 0.0015, idx.size)
        ta = tangent_angles(x, z, sd)
        gp = fit_curvature_gp(ta["s"], ta["theta"], noise_cov=ta["cov"])
        q = np.linspace(0.03, 0.9 * ta["s"][-1], 60)
        k, bs = bands(gp, q, ta["theta"])
        truth = np.interp(q, sig * L, kappa_true)
        for kk, v in bs.items():
            cov.setdefault(kk, []).append(np.mean(np.abs(k - truth) <= 1.6449 * v))
    print("points f=", f, {k: round(float(np.mean(v)), 3) for k, v in cov.items()})


if __name__ == "__main__":
    arcs("circle", lambda s: 0.2 + 2.0 * s, lambda s: np.full_like(s, 2.0))
    arcs("clothoid", lambda s: 3.0 * s**2, lambda s: 6.0 * s)
    arcs("sine", lambda s: 0.3 * np.sin(6 * s), lambda s: 1.8 * np.cos(6 * s))
    for f in (0.3, 1.2, 2.0):
        noisy_points(f)

"""Why the rho prior matters: exact Bayesian coverage for a linear stand-in of the rod under AR(1) noise.

    python scripts/ar1_prior_toy.py [--replicates 1500] [--seed 0] [--pushes 2]

Three pushes of 68 samples (the AR(1) coverage study's twig, docs/validation.md), each with two
smooth regressors (a stiffness-like slope and a taper-like curvature term, scaled per height),
AR(1) noise of lag-1 correlation 0.9 per push. The posterior is exact, no sampler: flat prior on the
coefficients and 1/sigma on the noise sd integrate out analytically (a Student-t given rho), and rho
is integrated on a grid over [-0.5, 0.995] under three priors: uniform (bayesrod's rho_force prior
before session 19), arcsine (1 - rho^2)^(-1/2) (the reference / Jeffreys prior of a stationary AR(1)
correlation, bayesrod's default since), and 1/(1 - rho). Two more rows keep the arcsine but put a flat
prior on the noise sd instead of 1/sigma, as bayesrod's half-normal of scale 0.5 N is at a rig's 0.03 N: flat
on the marginal sd sigma (bayesrod before session 53: along the ridge a push pins, rho is weighed by a further
(1 - rho^2)^(-1/2)) and flat on the innovation sd sigma sqrt(1 - rho^2) (since session 53). Prints the 90%
coverage of both coefficients and the median interval width of the first for each prior. ``--pushes 2``: two
pushes (the first and the last of the three), as each condition of fit-group's two-height study has to learn
its own noise from; ``--pushes 1``: one push (a condition pushed at one height).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import stats

from bayesrod.dataset.simulate import ar1_noise

N, RHO, SIGMA = 68, 0.9, 0.05
#: the pushes' regressor scales (per height): all three, or the first and last (``--pushes 2``)
SCALES = {3: (1.0, 0.75, 0.55), 2: (1.0, 0.55), 1: (1.0,)}
BETA = np.array([1.0, 0.5])
GRID = np.linspace(-0.5, 0.995, 400)
PRIORS = {"uniform": np.ones_like(GRID), "arcsine": 1 / np.sqrt(1 - GRID**2), "1/(1-rho)": 1 / (1 - GRID)}
#: the arcsine with a flat prior on the noise sd, as a power of (1 - rho^2): on the marginal sd sigma (the whitened
#: rss is in its units: after integrating sigma out, rss^(1/2) more than 1/sigma gives) or on the innovation sd
#: sigma sqrt(1 - rho^2) (a flat density in it is sqrt(1 - rho^2) in sigma)
FLAT_SD = {"arcsine, flat innovation sd": 0.5, "arcsine, flat marginal sd": 0.0}


def design(pushes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    d = np.linspace(0, 1, N)
    X = np.concatenate([np.column_stack([c * d, 0.7 * c * (d**2 - d / 2)]) for c in SCALES[pushes]])
    first = np.zeros(N * pushes, bool)
    first[::N] = True
    return X, first


def whiten(v: np.ndarray, rho: float, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    prev = np.roll(v, 1, axis=0)
    prev[first] = 0.0
    sd = np.where(first, 1.0, np.sqrt(1 - rho**2))
    return ((v - rho * prev).T / sd).T, sd


def intervals(y, X, first) -> dict[str, np.ndarray]:
    """90% intervals (2, 2) of both coefficients under each rho prior: mixtures over the rho grid of
    the Student-t posteriors given rho, weighted by rho's marginal likelihood times its prior."""
    dof = y.size - X.shape[1]
    logm, bh, se, half_log_rss = [], [], [], []
    for r in GRID:
        yw, sd = whiten(y, r, first)
        Xw, _ = whiten(X, r, first)
        A = Xw.T @ Xw
        b = np.linalg.solve(A, Xw.T @ yw)
        rss = np.sum((yw - Xw @ b) ** 2)
        logm.append(-np.sum(np.log(sd)) - 0.5 * np.linalg.slogdet(A)[1] - 0.5 * dof * np.log(rss))
        half_log_rss.append(0.5 * np.log(rss))
        bh.append(b)
        se.append(np.sqrt(rss / dof * np.diag(np.linalg.inv(A))))
    logm, bh, se, half_log_rss = np.array(logm), np.array(bh), np.array(se), np.array(half_log_rss)
    out = {}
    weights = {name: logm + np.log(prior) for name, prior in PRIORS.items()}
    for name, power in FLAT_SD.items():  # the Student-t's dof is one less there: negligible at these dof
        weights[name] = logm + half_log_rss + np.log(PRIORS["arcsine"]) + power * np.log1p(-(GRID**2))
    for name, lw in weights.items():
        w = np.exp(lw - lw.max())
        w /= w.sum()
        qs = np.empty((2, 2))
        for c in range(2):
            lo, hi = bh[:, c].min() - 10 * se[:, c].max(), bh[:, c].max() + 10 * se[:, c].max()
            for k, q in enumerate((0.05, 0.95)):
                qs[c, k] = _bisect(
                    lambda x, c=c, w=w, q=q: np.sum(w * stats.t.cdf((x - bh[:, c]) / se[:, c], dof)) - q, lo, hi
                )
        out[name] = qs
    return out


def _bisect(f, lo: float, hi: float, steps: int = 60) -> float:
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pushes", type=int, choices=sorted(SCALES), default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    X, first = design(args.pushes)
    names = [*PRIORS, *FLAT_SD]
    covered = {k: np.zeros(2, int) for k in names}
    widths = {k: [] for k in names}
    for _ in range(args.replicates):
        y = X @ BETA + np.concatenate([ar1_noise(rng, SIGMA, RHO, N) for _ in range(args.pushes)])
        for name, qs in intervals(y, X, first).items():
            covered[name] += (qs[:, 0] <= BETA) & (BETA <= qs[:, 1])
            widths[name].append(qs[0, 1] - qs[0, 0])
    n = args.replicates
    half = 1.645 * np.sqrt(0.09 / n)
    print(f"{n} replicates; a calibrated 90% interval covers {0.9 - half:.3f}-{0.9 + half:.3f} (binomial 90%)")
    for name in names:
        c = covered[name] / n
        print(f"{name:>27}: slope {c[0]:.3f}, curvature {c[1]:.3f}, median slope width {np.median(widths[name]):.4f}")


if __name__ == "__main__":
    main()

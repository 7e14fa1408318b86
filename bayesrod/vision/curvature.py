"""Curvature with uncertainty: Gaussian-process regression of the tangent angle theta(s).

The seed smooths theta(s) with a GP whose Matern-3/2 covariance keeps sample
paths once differentiable, so kappa(s) = theta'(s) exists (section III-C). The
GP is fitted by marginal likelihood -- with scikit-learn's
``GaussianProcessRegressor`` for white noise, or with scikit-learn's Matern
kernel and a direct optimisation when the noise covariance of theta is known
(theta from finite differences of noisy points has correlated noise) -- and the
derivative follows from the kernel's derivatives:

    k(r)                = s2 (1 + a r) exp(-a r),          a = sqrt(3)/l, r = s - s'
    d k / d s           = -s2 a^2 r exp(-a |r|)
    d^2 k / d s d s'    =  s2 a^2 (1 - a |r|) exp(-a |r|)

so E[kappa(s*)] = k_s(s*, S) K^-1 (theta - m) = W (theta - m) and the posterior
variance is Var[kappa(s*)] = s2 a^2 - k_s K^-1 k_s^T, K = k(S, S) + Sigma.

Two uncertainties are reported (docs/model.md, "Curvature uncertainty"):

* ``kappa_var``: the Bayesian posterior variance under the Matern-3/2 prior.
  When the stem is smoother than that prior (elastica shapes are), it is
  conservative: its 90% band covered 99.6-99.9% of the true curvature in the
  checks of tests/test_curvature.py.
* ``kappa_se2``: the sampling variance of the curvature estimate itself,
  diag(W Sigma W^T), the noise propagated through the fitted smoother. Its 90%
  band covered 88-92% on arcs and elastica shapes (same checks), so this is the
  band ``kappa_sd`` used downstream by the direct estimator. It leaves out the
  smoothing bias, which matters only where the curvature changes on scales
  shorter than the fitted length scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_solve


@dataclass(frozen=True)
class CurvatureGP:
    """Fitted GP on theta(s); call :meth:`predict` for theta and kappa with variances."""

    s: NDArray  # (n,) training arc lengths [m]
    alpha: NDArray  # (n,) K^-1 (theta - mean)
    chol: NDArray  # (n, n) lower Cholesky factor of K
    mean: float
    signal_var: float  # s2 [rad^2]
    length_scale: float  # l [m]
    noise_cov: NDArray  # (n, n) noise covariance of theta [rad^2]

    @property
    def noise_var(self) -> float:
        """Mean noise variance of theta [rad^2]."""
        return float(np.mean(np.diag(self.noise_cov)))

    def _k(self, a: NDArray, b: NDArray):
        r = a[:, None] - b[None, :]
        c = np.sqrt(3.0) / self.length_scale
        e = np.exp(-c * np.abs(r))
        k = self.signal_var * (1 + c * np.abs(r)) * e
        ks = -self.signal_var * c**2 * r * e  # d k / d a
        return k, ks

    def predict(self, s_query: ArrayLike) -> dict[str, NDArray]:
        """Theta [rad] and kappa [1/m] at ``s_query`` (m,), each with its uncertainty.

        Returns
        -------
        dict of (m,) arrays
            ``theta``, ``theta_var`` (posterior), ``kappa`` (posterior mean of theta'),
            ``kappa_var`` (posterior variance), ``kappa_se2`` (sampling variance of the
            estimate, diag(W Sigma W^T)) and ``kappa_sd`` = sqrt(kappa_se2), the calibrated band.
        """
        q = np.asarray(s_query, float)
        k, ks = self._k(q, self.s)
        theta = self.mean + k @ self.alpha
        kappa = ks @ self.alpha
        v = cho_solve((self.chol, True), k.T)
        W = cho_solve((self.chol, True), ks.T).T  # (m, n): kappa = W (theta - mean)
        c2 = 3.0 / self.length_scale**2
        var_theta = np.maximum(self.signal_var - np.sum(k * v.T, axis=1), 0.0)
        var_kappa = np.maximum(self.signal_var * c2 - np.sum(ks * W, axis=1), 0.0)
        se2 = np.maximum(np.einsum("mi,ij,mj->m", W, self.noise_cov, W), 0.0)
        return {
            "theta": theta,
            "theta_var": var_theta,
            "kappa": kappa,
            "kappa_var": var_kappa,
            "kappa_se2": se2,
            "kappa_sd": np.sqrt(se2),
        }


def _matern32(s: NDArray, s2: float, ell: float) -> NDArray:
    r = np.abs(s[:, None] - s[None, :])
    c = np.sqrt(3.0) / ell
    return s2 * (1 + c * r) * np.exp(-c * r)


def _fit_known_cov(s, y, cov, span, n_restarts, rng):
    """Marginal-likelihood fit of (s2, l) with a known noise covariance (scikit-learn's Matern kernel)."""
    from scipy.optimize import minimize
    from sklearn.gaussian_process.kernels import Matern

    X = s[:, None]

    def nll(logp):
        s2, ell = np.exp(logp)
        K = s2 * Matern(ell, nu=1.5)(X) + cov
        try:
            L = np.linalg.cholesky(K)
        except np.linalg.LinAlgError:
            return 1e25
        a = np.linalg.solve(L, y)
        return 0.5 * a @ a + np.sum(np.log(np.diag(L)))

    bounds = [(np.log(1e-10), np.log(1e3)), (np.log(1e-2 * span), np.log(10 * span))]
    starts = [np.log([max(np.var(y), 1e-6), f * span]) for f in (0.2, 1.0, 0.05)]
    starts += [np.array([rng.uniform(*b) for b in bounds]) for _ in range(max(n_restarts - 2, 0))]
    best = min((minimize(nll, x0, method="L-BFGS-B", bounds=bounds) for x0 in starts), key=lambda r: r.fun)
    return tuple(np.exp(best.x))


def fit_curvature_gp(
    s_m: ArrayLike,
    theta_rad: ArrayLike,
    *,
    noise_sd_rad: float | None = None,
    noise_cov: ArrayLike | None = None,
    n_restarts: int = 2,
    seed: int = 0,
) -> CurvatureGP:
    """Fit a Matern-3/2 GP to theta(s) by marginal likelihood.

    Parameters
    ----------
    s_m, theta_rad : (n,) arrays
        Arc lengths [m] and tangent angles [rad] of one centerline.
    noise_sd_rad : float, optional
        Known white noise of theta [rad].
    noise_cov : (n, n) array, optional
        Known noise covariance of theta [rad^2], e.g. from :func:`tangent_angles`.
        Without either, a white-noise level is fitted too (scikit-learn WhiteKernel).
    """
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    s = np.asarray(s_m, float)
    y = np.asarray(theta_rad, float)
    if s.shape != y.shape or s.ndim != 1 or s.size < 4:
        raise ValueError(f"s_m, theta_rad: expected two 1-D arrays of equal length >= 4, got {s.shape} and {y.shape}")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(y))):
        raise ValueError("s_m, theta_rad: expected finite values, got NaN or inf")
    span = float(np.ptp(s)) or 1.0
    mean = float(np.mean(y))
    if noise_cov is not None:
        cov = np.asarray(noise_cov, float)
        if cov.shape != (s.size, s.size) or not np.all(np.isfinite(cov)):
            raise ValueError(f"noise_cov: expected a finite ({s.size}, {s.size}) matrix, got shape {cov.shape}")
        s2, ell = _fit_known_cov(s, y - mean, cov, span, n_restarts, np.random.default_rng(seed))
    else:
        kernel = ConstantKernel(max(np.var(y), 1e-6), (1e-8, 1e3)) * Matern(
            0.2 * span, (1e-3 * span, 10 * span), nu=1.5
        )
        if noise_sd_rad is None:
            kernel = kernel + WhiteKernel(1e-4, (1e-12, 1.0))
            alpha = 1e-10
        else:
            alpha = float(noise_sd_rad) ** 2
        gp = GaussianProcessRegressor(
            kernel, alpha=alpha, normalize_y=False, n_restarts_optimizer=n_restarts, random_state=seed
        )
        import warnings

        from sklearn.exceptions import ConvergenceWarning

        with warnings.catch_warnings():  # a length scale at its bound is a legitimate (very smooth) answer
            warnings.simplefilter("ignore", ConvergenceWarning)
            gp.fit(s[:, None], y - mean)
        k = gp.kernel_
        if noise_sd_rad is None:
            prod, noise = k.k1, float(k.k2.noise_level) + alpha
        else:
            prod, noise = k, alpha
        s2, ell = float(prod.k1.constant_value), float(prod.k2.length_scale)
        cov = noise * np.eye(s.size)
    K = _matern32(s, s2, ell) + cov
    chol = np.linalg.cholesky(K)
    return CurvatureGP(s, cho_solve((chol, True), y - mean), chol, mean, s2, ell, cov)


def tangent_angles(x_m: ArrayLike, z_m: ArrayLike, sd_m: ArrayLike) -> dict[str, NDArray]:
    """Tangent angles of a polyline and their (correlated) noise covariance.

    theta_i = atan2(x_{i+1} - x_i, z_{i+1} - z_i) is measured from the vertical (the
    seed's convention, eq. tangent) at the segment midpoint s_i. To first order in
    isotropic point noise sd_j, d theta_i = n_i . (dr_{i+1} - dr_i) / ds_i with n_i the
    unit normal, so Var theta_i = (sd_i^2 + sd_{i+1}^2) / ds_i^2 and neighbouring
    angles share a point: Cov(theta_i, theta_{i+1}) = -sd_{i+1}^2 (n_i . n_{i+1}) / (ds_i ds_{i+1}).

    Parameters
    ----------
    x_m, z_m, sd_m : (n,) arrays
        Points from base to tip [m] and their standard deviations [m].

    Returns
    -------
    dict
        ``s`` (n-1,) midpoint arc lengths [m], ``theta`` (n-1,) [rad], ``cov`` (n-1, n-1) [rad^2].
    """
    x, z, sd = (np.asarray(a, float) for a in (x_m, z_m, sd_m))
    dx, dz = np.diff(x), np.diff(z)
    ds = np.hypot(dx, dz)
    if np.any(ds <= 0):
        raise ValueError("x_m, z_m: expected distinct consecutive points, got a repeated point")
    s_nodes = np.concatenate([[0.0], np.cumsum(ds)])
    theta = np.unwrap(np.arctan2(dx, dz))
    n = np.stack([np.cos(theta), -np.sin(theta)])  # unit normal of each segment
    var = (sd[:-1] ** 2 + sd[1:] ** 2) / ds**2
    off = -(sd[1:-1] ** 2) * np.sum(n[:, :-1] * n[:, 1:], axis=0) / (ds[:-1] * ds[1:])
    cov = np.diag(var) + np.diag(off, 1) + np.diag(off, -1)
    return {"s": 0.5 * (s_nodes[:-1] + s_nodes[1:]), "theta": theta, "cov": cov}

"""Curvature with uncertainty: Gaussian-process regression of the tangent angle theta(s).

The seed smooths theta(s) with a GP whose Matern-3/2 covariance keeps sample
paths once differentiable, so kappa(s) = theta'(s) exists. Here the GP is
fitted with scikit-learn (hyperparameters by marginal likelihood) and the
posterior of the derivative is computed from the kernel's derivatives:

    k(r)                = s2 (1 + a r) exp(-a r),          a = sqrt(3)/l, r = s - s'
    d k / d s           = -s2 a^2 r exp(-a |r|)
    d^2 k / d s d s'    =  s2 a^2 (1 - a |r|) exp(-a |r|)

so E[kappa(s*)] = k_s(s*, S) K^-1 (theta - m) and
Var[kappa(s*)] = s2 a^2 - k_s(s*, S) K^-1 k_s(S, s*), K = k(S, S) + noise I.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class CurvatureGP:
    """Fitted GP on theta(s); call :meth:`predict` for theta and kappa with variances."""

    s: NDArray  # (n,) training arc lengths [m]
    alpha: NDArray  # (n,) K^-1 (theta - mean)
    chol: NDArray  # (n, n) lower Cholesky factor of K
    mean: float
    signal_var: float  # s2 [rad^2]
    length_scale: float  # l [m]
    noise_var: float  # [rad^2]

    def _k(self, a: NDArray, b: NDArray):
        r = a[:, None] - b[None, :]
        c = np.sqrt(3.0) / self.length_scale
        e = np.exp(-c * np.abs(r))
        k = self.signal_var * (1 + c * np.abs(r)) * e
        ks = -self.signal_var * c**2 * r * e  # d k / d a
        return k, ks

    def predict(self, s_query: ArrayLike) -> dict[str, NDArray]:
        """Posterior mean and variance of theta [rad] and kappa [1/m] at ``s_query`` (m,)."""
        from scipy.linalg import cho_solve

        q = np.asarray(s_query, float)
        k, ks = self._k(q, self.s)
        theta = self.mean + k @ self.alpha
        kappa = ks @ self.alpha
        v = cho_solve((self.chol, True), k.T)
        vs = cho_solve((self.chol, True), ks.T)
        c2 = 3.0 / self.length_scale**2
        var_theta = np.maximum(self.signal_var - np.sum(k * v.T, axis=1), 0.0)
        var_kappa = np.maximum(self.signal_var * c2 - np.sum(ks * vs.T, axis=1), 0.0)
        return {"theta": theta, "theta_var": var_theta, "kappa": kappa, "kappa_var": var_kappa}


def fit_curvature_gp(
    s_m: ArrayLike, theta_rad: ArrayLike, *, noise_sd_rad: float | None = None, n_restarts: int = 2, seed: int = 0
) -> CurvatureGP:
    """Fit a Matern-3/2 GP to theta(s) by marginal likelihood (scikit-learn).

    Parameters
    ----------
    s_m, theta_rad : (n,) arrays
        Arc lengths [m] and tangent angles [rad] of one centerline.
    noise_sd_rad : float, optional
        Known noise of theta; otherwise a white-noise term is fitted too.
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
    kernel = ConstantKernel(max(np.var(y), 1e-6), (1e-8, 1e3)) * Matern(0.2 * span, (1e-3 * span, 10 * span), nu=1.5)
    if noise_sd_rad is None:
        kernel = kernel + WhiteKernel(1e-4, (1e-12, 1.0))
        alpha = 1e-10
    else:
        alpha = float(noise_sd_rad) ** 2
    gp = GaussianProcessRegressor(
        kernel, alpha=alpha, normalize_y=False, n_restarts_optimizer=n_restarts, random_state=seed
    )
    gp.fit(s[:, None], y - mean)
    k = gp.kernel_
    if noise_sd_rad is None:
        prod, white = k.k1, k.k2
        noise = float(white.noise_level) + alpha
    else:
        prod, noise = k, alpha
    s2 = float(prod.k1.constant_value)
    ell = float(prod.k2.length_scale)
    r = np.abs(s[:, None] - s[None, :])
    c = np.sqrt(3.0) / ell
    K = s2 * (1 + c * r) * np.exp(-c * r) + noise * np.eye(s.size)
    chol = np.linalg.cholesky(K)
    from scipy.linalg import cho_solve

    return CurvatureGP(s, cho_solve((chol, True), y - mean), chol, mean, s2, ell, noise)

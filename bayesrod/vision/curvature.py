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

Three pieces of uncertainty are reported (docs/vision.md, "Curvature with uncertainty"):

* ``kappa_var``: the Bayesian posterior variance under the Matern-3/2 prior.
  When the stem is smoother than that prior (elastica shapes are), it is
  conservative: its 90% band covered 99.6-99.9% of the true curvature on arcs.
* ``kappa_se2``: the sampling variance of the curvature estimate itself,
  diag(W Sigma W^T), the noise propagated through the fitted smoother. It
  leaves out the smoothing bias: where the fitted length scale smooths over
  kappa's changes (or the fit collapses onto the trend, s2 -> 0) its band
  covered as little as 47% of elastica curvature.
* ``kappa_bias2``: a plug-in estimate of that bias, squared. A pilot GP with a
  trend one degree higher (a linear curvature unpenalised) is fitted to the
  same data; the bias is what this smoother makes of the pilot's theta(s)
  minus the pilot's own kappa, b = W (theta_pilot(S) - m) - kappa_pilot.

``kappa_sd`` = sqrt(kappa_se2 + kappa_bias2) is the band used downstream by the
direct estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_solve

TREND_SD = 10.0  # prior sd [rad] of the linear trend's intercept and of its change over the span


@dataclass(frozen=True)
class CurvatureGP:
    """Fitted GP on theta(s); call :meth:`predict` for theta and kappa with variances.

    The prior is a broad linear trend (intercept and slope, sd ``TREND_SD`` over the span,
    marginalised) plus a Matern-3/2 process: a stem bent at constant curvature is then
    not shrunk toward a straight line, which a constant-mean GP does at low signal-to-noise.
    """

    s: NDArray  # (n,) training arc lengths [m]
    alpha: NDArray  # (n,) K^-1 (theta - mean)
    chol: NDArray  # (n, n) lower Cholesky factor of K
    mean: float
    signal_var: float  # s2 [rad^2]
    length_scale: float  # l [m]
    noise_cov: NDArray  # (n, n) noise covariance of theta [rad^2]
    centre: float  # trend coordinate u = (s - centre) / span
    span: float
    degree: int = 1  # polynomial trend degree
    pilot: CurvatureGP | None = None  # quadratic-trend fit of the same data, for the smoothing bias

    @property
    def noise_var(self) -> float:
        """Mean noise variance of theta [rad^2]."""
        return float(np.mean(np.diag(self.noise_cov)))

    def _k(self, a: NDArray, b: NDArray):
        """k(a, b) and d k / d a, Matern-3/2 plus the linear trend."""
        return _kernel(a, b, self.signal_var, self.length_scale, self.centre, self.span, self.degree)

    def _mean(self, q: NDArray) -> tuple[NDArray, NDArray]:
        """Posterior means of theta and kappa at ``q`` (m,)."""
        k, ks = self._k(q, self.s)
        return self.mean + k @ self.alpha, ks @ self.alpha

    def predict(self, s_query: ArrayLike) -> dict[str, NDArray]:
        """Theta [rad] and kappa [1/m] at ``s_query`` (m,), each with its uncertainty.

        Returns
        -------
        dict of (m,) arrays
            ``theta``, ``theta_var`` (posterior), ``kappa`` (posterior mean of theta'),
            ``kappa_var`` (posterior variance), ``kappa_se2`` (sampling variance of the
            estimate, diag(W Sigma W^T)), ``kappa_bias2`` (squared plug-in smoothing bias,
            0 without a pilot) and ``kappa_sd`` = sqrt(kappa_se2 + kappa_bias2), the band.
        """
        q = np.asarray(s_query, float)
        k, ks = self._k(q, self.s)
        theta = self.mean + k @ self.alpha
        kappa = ks @ self.alpha
        v = cho_solve((self.chol, True), k.T)
        W = cho_solve((self.chol, True), ks.T).T  # (m, n): kappa = W (theta - mean)
        pq, dpq = _trend_basis(q, self.centre, self.span, self.degree)
        prior_theta = self.signal_var + TREND_SD**2 * np.sum(pq**2, axis=1)
        prior_kappa = self.signal_var * 3.0 / self.length_scale**2 + TREND_SD**2 * np.sum(dpq**2, axis=1)
        var_theta = np.maximum(prior_theta - np.sum(k * v.T, axis=1), 0.0)
        var_kappa = np.maximum(prior_kappa - np.sum(ks * W, axis=1), 0.0)
        se2 = np.maximum(np.einsum("mi,ij,mj->m", W, self.noise_cov, W), 0.0)
        bias2 = np.zeros(q.size)
        if self.pilot is not None:
            # what this smoother makes of the pilot's theta(s), minus the pilot's own kappa: the smoothing
            # bias if the truth were the pilot (docs/vision.md, "Curvature with uncertainty")
            at_data, _ = self.pilot._mean(self.s)
            bias2 = (W @ (at_data - self.mean) - self.pilot._mean(q)[1]) ** 2
        return {
            "theta": theta,
            "theta_var": var_theta,
            "kappa": kappa,
            "kappa_var": var_kappa,
            "kappa_se2": se2,
            "kappa_bias2": bias2,
            "kappa_sd": np.sqrt(se2 + bias2),
        }


def _kernel(a: NDArray, b: NDArray, s2: float, ell: float, centre: float, span: float, degree: int):
    """cov(theta(a), theta(b)) and cov(theta'(a), theta(b)): Matern-3/2 (variance ``s2``, length ``ell``)
    plus the polynomial trend of prior sd TREND_SD; (len(a), len(b)) each."""
    r = a[:, None] - b[None, :]
    c = np.sqrt(3.0) / ell
    e = np.exp(-c * np.abs(r))
    pa, dpa = _trend_basis(a, centre, span, degree)
    pb, _ = _trend_basis(b, centre, span, degree)
    k = s2 * (1 + c * np.abs(r)) * e + TREND_SD**2 * pa @ pb.T
    ks = -s2 * c**2 * r * e + TREND_SD**2 * dpa @ pb.T
    return k, ks


def _trend_basis(s: NDArray, centre: float, span: float, degree: int):
    """Polynomial trend basis u^j, j = 0..degree, u = (s - centre) / span, and its s-derivative: (m, degree+1) each."""
    u = (np.asarray(s, float) - centre) / span
    j = np.arange(degree + 1)
    P = u[:, None] ** j[None, :]
    dP = np.where(j[None, :] > 0, j[None, :] * u[:, None] ** np.maximum(j[None, :] - 1, 0), 0.0) / span
    return P, dP


def _marginal_nll_reference(logp, s, y, cov, trend) -> float:
    """Negative log marginal likelihood of theta(s) (up to a constant), plainly: the value the fast
    :func:`_marginal_nll` must reproduce. ``logp`` = log(s2, l[, white variance when ``cov`` is None])."""
    from sklearn.gaussian_process.kernels import Matern

    s2, ell = np.exp(logp[:2])
    noise = cov if cov is not None else np.exp(logp[2]) * np.eye(s.size)
    K = s2 * Matern(ell, nu=1.5)(s[:, None]) + trend + noise
    _, logdet = np.linalg.slogdet(K)
    return 0.5 * y @ np.linalg.solve(K, y) + 0.5 * logdet


def _marginal_nll(logp, s, y, cov, trend) -> tuple[float, NDArray]:
    """:func:`_marginal_nll_reference` and its gradient in ``logp``, from one Cholesky factor:
    d nll = 0.5 tr((K^-1 - a a^T) dK), a = K^-1 y. (1e25, 0) where K is not positive definite."""
    from sklearn.gaussian_process.kernels import Matern

    s2, ell = np.exp(logp[:2])
    eye = np.eye(s.size)
    Km, dKm = Matern(ell, nu=1.5)(s[:, None], eval_gradient=True)  # dKm: d/dlog(l)
    white = np.exp(logp[2]) if cov is None else 0.0
    K = s2 * Km + trend + (cov if cov is not None else white * eye)
    try:
        L = np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        return 1e25, np.zeros(len(logp))
    a = cho_solve((L, True), y)
    A = cho_solve((L, True), eye) - np.outer(a, a)
    grad = [0.5 * s2 * np.sum(A * Km), 0.5 * s2 * np.sum(A * dKm[:, :, 0])]
    if cov is None:
        grad.append(0.5 * white * np.trace(A))
    return 0.5 * y @ a + np.sum(np.log(np.diag(L))), np.array(grad)


def _fit_hyper(s, y, cov, span, centre, n_restarts, rng, degree=1):
    """Type-II maximum likelihood of (s2, l[, white noise]) with scikit-learn's Matern-3/2 kernel
    (L-BFGS-B on the analytic gradient of :func:`_marginal_nll`).

    ``cov`` is the known noise covariance, or None to fit a white-noise variance too.
    """
    from scipy.optimize import minimize

    P, _ = _trend_basis(s, centre, span, degree)
    trend = TREND_SD**2 * P @ P.T

    def nll(logp):
        return _marginal_nll(logp, s, y, cov, trend)

    bounds = [(np.log(1e-12), np.log(1e3)), (np.log(1e-2 * span), np.log(10 * span))]
    v0 = max(float(np.var(y)), 1e-8)
    starts = [[np.log(v0), np.log(f * span)] for f in (0.2, 1.0, 0.05)]
    if cov is None:
        bounds.append((np.log(1e-12), np.log(1.0)))
        starts = [x + [np.log(0.1 * v0)] for x in starts]
    starts += [[rng.uniform(*b) for b in bounds] for _ in range(max(n_restarts - 2, 0))]
    best = min(
        (minimize(nll, np.array(x0), jac=True, method="L-BFGS-B", bounds=bounds) for x0 in starts),
        key=lambda r: r.fun,
    )
    return np.exp(best.x)


def fit_curvature_gp(
    s_m: ArrayLike,
    theta_rad: ArrayLike,
    *,
    noise_sd_rad: float | None = None,
    noise_cov: ArrayLike | None = None,
    n_restarts: int = 2,
    seed: int = 0,
    degree: int = 1,
    bias: bool = True,
) -> CurvatureGP:
    """Fit the GP (linear trend + Matern-3/2) to theta(s) by marginal likelihood.

    Parameters
    ----------
    s_m, theta_rad : (n,) arrays
        Arc lengths [m] and tangent angles [rad] of one centerline.
    noise_sd_rad : float, optional
        Known white noise of theta [rad].
    noise_cov : (n, n) array, optional
        Known noise covariance of theta [rad^2], e.g. from :func:`tangent_angles`.
        Without either, a white-noise level is fitted too.
    degree : int
        Degree of the broad polynomial trend (default 1: a constant curvature is not shrunk).
        2 puts a linear curvature in the trend: measured as the estimate and not adopted
        (docs/vision.md, ``scripts/curvature_bands_trend.py``); it serves as the pilot.
    bias : bool
        Also fit the pilot (the same GP with a trend of degree + 1) so that :meth:`CurvatureGP.predict`
        adds the plug-in smoothing bias to ``kappa_sd`` (default). Without it the band is the
        sampling sd alone, which under-covers wherever the fitted length scale smooths kappa's
        changes (measured 47-91% on elastica shapes, docs/vision.md).
    """
    s = np.asarray(s_m, float)
    y = np.asarray(theta_rad, float)
    if s.shape != y.shape or s.ndim != 1 or s.size < 4:
        raise ValueError(f"s_m, theta_rad: expected two 1-D arrays of equal length >= 4, got {s.shape} and {y.shape}")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(y))):
        raise ValueError("s_m, theta_rad: expected finite values, got NaN or inf")
    span = float(np.ptp(s)) or 1.0
    centre = float(np.mean(s))
    mean = float(np.mean(y))
    rng = np.random.default_rng(seed)
    if noise_cov is not None:
        cov = np.asarray(noise_cov, float)
        if cov.shape != (s.size, s.size) or not np.all(np.isfinite(cov)):
            raise ValueError(f"noise_cov: expected a finite ({s.size}, {s.size}) matrix, got shape {cov.shape}")
    elif noise_sd_rad is not None:
        cov = float(noise_sd_rad) ** 2 * np.eye(s.size)
    else:
        cov = None
    hyper = _fit_hyper(s, y - mean, cov, span, centre, n_restarts, rng, degree)
    s2, ell = float(hyper[0]), float(hyper[1])
    if cov is None:
        cov = float(hyper[2]) * np.eye(s.size)
    K = _kernel(s, s, s2, ell, centre, span, degree)[0] + cov
    chol = np.linalg.cholesky(K)
    pilot = None
    if bias:
        pilot = fit_curvature_gp(s, y, noise_cov=cov, n_restarts=n_restarts, seed=seed, degree=degree + 1, bias=False)
    alpha = cho_solve((chol, True), y - mean)
    return CurvatureGP(s, alpha, chol, mean, s2, ell, cov, centre, span, degree, pilot)


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
        ``s`` (n-1,) midpoint arc lengths [m] (corrected for the lengthening by the noise),
        ``theta`` (n-1,) [rad], ``cov`` (n-1, n-1) [rad^2], ``s_nodes`` (n,) arc length of each point [m].
    """
    x, z, sd = (np.asarray(a, float) for a in (x_m, z_m, sd_m))
    dx, dz = np.diff(x), np.diff(z)
    ds = np.hypot(dx, dz)
    if np.any(ds <= 0):
        raise ValueError("x_m, z_m: expected distinct consecutive points, got a repeated point")
    # noisy points lengthen the polyline: to second order E|dr_obs| = ds + (sd_i^2 + sd_{i+1}^2) / (2 ds)
    # (the normal part of the noise), about 2% for 1.5-mm noise on 1-cm segments; remove it from s
    ds_true = np.maximum(ds - (sd[:-1] ** 2 + sd[1:] ** 2) / (2 * ds), 0.5 * ds)
    s_nodes = np.concatenate([[0.0], np.cumsum(ds_true)])
    theta = np.unwrap(np.arctan2(dx, dz))
    n = np.stack([np.cos(theta), -np.sin(theta)])  # unit normal of each segment
    var = (sd[:-1] ** 2 + sd[1:] ** 2) / ds**2
    off = -(sd[1:-1] ** 2) * np.sum(n[:, :-1] * n[:, 1:], axis=0) / (ds[:-1] * ds[1:])
    cov = np.diag(var) + np.diag(off, 1) + np.diag(off, -1)
    return {"s": 0.5 * (s_nodes[:-1] + s_nodes[1:]), "theta": theta, "cov": cov, "s_nodes": s_nodes}

"""Lumped-parameter reductions of the tapered rod (seed section III-D).

Closed forms. With sigma = s/L, eta = h/L and q = 4p, the integrals of eqs.
kdist and kx are::

    int_0^h (h - s)^k / EI(s) ds = L^(k+1)/EI0 * eta^(k+1)/(k+1) * 2F1(q, 1; k+2; eta)

(substitute s = h t), so the taper's tip singularity (1 - s/L)^(-4p) is handled
exactly by the Gauss hypergeometric function instead of by quadrature.
``bayesrod.physics.reference`` keeps the plain quadrature beside it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import hyp2f1

__all__ = [
    "ktheta_nd",
    "kx_nd",
    "k_theta",
    "k_x",
    "flexural_rigidity",
    "stem_diameter",
    "wire_dx_from_elongation",
    "wire_elongation_from_dx",
    "seed_angle_solution",
    "link_angle",
    "fit_torque_balance",
]


def flexural_rigidity(s_m: ArrayLike, EI0: ArrayLike, p: ArrayLike, length_m: ArrayLike) -> NDArray:
    """EI(s) = EI0 (1 - s/L)^(4p) [N m^2] (eq. EI_taper); broadcasts over all arguments (L too)."""
    s = np.asarray(s_m, float)
    one_minus = np.clip(1.0 - s / np.asarray(length_m, float), 0.0, None)
    return np.asarray(EI0, float) * one_minus ** (4.0 * np.asarray(p, float))


def stem_diameter(s_m: ArrayLike, d0: ArrayLike, q: ArrayLike, length_m: ArrayLike) -> NDArray:
    """d(s) = d0 (1 - s/L)^q [m]: the solid round stem whose EI(s) = E pi d^4 / 64 follows the taper law
    (q = p under a uniform modulus E); broadcasts over all arguments (L too)."""
    one_minus = np.clip(1.0 - np.asarray(s_m, float) / np.asarray(length_m, float), 0.0, None)
    return np.asarray(d0, float) * one_minus ** np.asarray(q, float)


def ktheta_nd(eta: ArrayLike, p: ArrayLike) -> NDArray:
    """k_theta L / EI0 of eq. kdist for the taper law; shape = broadcast(eta, p)."""
    eta = np.asarray(eta, float)
    return 2.0 / (eta * hyp2f1(4.0 * np.asarray(p, float), 1.0, 3.0, eta))


def kx_nd(eta: ArrayLike, p: ArrayLike) -> NDArray:
    """k_x L^3 / EI0 of eq. kx for the taper law; shape = broadcast(eta, p)."""
    eta = np.asarray(eta, float)
    return 3.0 / (eta**3 * hyp2f1(4.0 * np.asarray(p, float), 1.0, 4.0, eta))


def k_theta(
    height_m: ArrayLike,
    EI0: ArrayLike,
    p: ArrayLike,
    length_m: ArrayLike,
    base_stiffness_Nm_per_rad: ArrayLike = np.inf,
) -> NDArray:
    """Small-deflection rotational stiffness k_theta(h) [N m/rad] (eq. kdist).

    A base spring of stiffness ``base_stiffness_Nm_per_rad`` k_b (the ``base_compliance`` effect's value,
    docs/model.md; inf = a rigid clamp) acts in series: 1/k = 1/k_rod + 1/k_b. For constant EI (p = 0)
    and a clamp, k_theta = 2 EI/h. Broadcasts over all arguments (the stem length L too).
    """
    L = np.asarray(length_m, float)
    k_rod = ktheta_nd(np.asarray(height_m, float) / L, p) * np.asarray(EI0, float) / L
    return 1.0 / (1.0 / k_rod + 1.0 / np.asarray(base_stiffness_Nm_per_rad, float))


def k_x(
    height_m: ArrayLike,
    EI0: ArrayLike,
    p: ArrayLike,
    length_m: ArrayLike,
    base_stiffness_Nm_per_rad: ArrayLike = np.inf,
) -> NDArray:
    """Small-deflection translational stiffness k_x(h) [N/m] (eq. kx).

    A base spring k_b adds F h^2 / k_b to the contact displacement. For constant
    EI and a clamp, k_x = 3 EI / h^3. Broadcasts over all arguments (L too).
    """
    L = np.asarray(length_m, float)
    h = np.asarray(height_m, float)
    k_rod = kx_nd(h / L, p) * np.asarray(EI0, float) / L**3
    return 1.0 / (1.0 / k_rod + h**2 / np.asarray(base_stiffness_Nm_per_rad, float))


def wire_dx_from_elongation(elongation_m: ArrayLike, wire_length_m: float) -> NDArray:
    """Lateral contact displacement from wire elongation (eq. wire_half_ext) [m].

    dx = 1/2 sqrt((dl + L_w)^2 - L_w^2), contact at the wire's midpoint.
    """
    dl = np.asarray(elongation_m, float)
    Lw = float(wire_length_m)
    return 0.5 * np.sqrt(np.clip((dl + Lw) ** 2 - Lw**2, 0.0, None))


def wire_elongation_from_dx(dx_m: ArrayLike, wire_length_m: float) -> NDArray:
    """Inverse of :func:`wire_dx_from_elongation`: dl = 2 sqrt((L_w/2)^2 + dx^2) - L_w."""
    dx = np.asarray(dx_m, float)
    Lw = float(wire_length_m)
    return 2.0 * np.sqrt((0.5 * Lw) ** 2 + dx**2) - Lw


def seed_angle_solution(x_c: ArrayLike, z_c: ArrayLike, h: ArrayLike) -> NDArray:
    """Deflection angle of eq. angle_solution, the root of eq. angle_geom.

    theta = 2 arctan((sqrt(h^2 + x_c^2 - z_c^2) - h) / (x_c + z_c)), which solves
    x_c cos(theta) - h sin(theta) = z_c. Reproduced as published.
    """
    x_c, z_c, h = (np.asarray(a, float) for a in (x_c, z_c, h))
    return 2.0 * np.arctan((np.sqrt(h**2 + x_c**2 - z_c**2) - h) / (x_c + z_c))


def link_angle(x_c: ArrayLike, h: ArrayLike) -> NDArray:
    """Rotation of the rigid link from the base pivot to the contact at height h [rad]."""
    return np.arctan2(np.asarray(x_c, float), np.asarray(h, float))


def fit_torque_balance(
    theta_rad: ArrayLike, force_N: ArrayLike, height_m: float, linear_fraction: float = 0.5
) -> dict[str, float]:
    """Fit tau = F h = k_theta theta (eq. torque_balance) on the linear region.

    The linear region is the samples from first contact until the force first
    exceeds ``linear_fraction`` of its peak (the seed fits "only the linear
    region"). Least squares through the origin.

    Returns
    -------
    dict
        ``k_theta`` [N m/rad], ``n`` samples used, ``r2`` of the fit.
    """
    theta = np.asarray(theta_rad, float)
    F = np.asarray(force_N, float)
    if theta.shape != F.shape or theta.ndim != 1:
        raise ValueError(f"theta_rad, force_N: expected 1-D arrays of equal length, got {theta.shape} and {F.shape}")
    if not 0 < linear_fraction <= 1:
        raise ValueError(f"linear_fraction: expected a value in (0, 1], got {linear_fraction}")
    ok = np.isfinite(theta) & np.isfinite(F)
    theta, F = theta[ok], F[ok]
    if theta.size < 2:
        raise ValueError(f"force_N: expected at least 2 finite samples, got {theta.size}")
    over = np.flatnonzero(F > linear_fraction * F.max())
    end = over[0] + 1 if over.size else F.size
    t, tau = theta[:end], F[:end] * float(height_m)
    denom = float(t @ t)
    if denom <= 0:
        raise ValueError("theta_rad: expected non-zero deflection angles in the linear region, got all zeros")
    k = float(t @ tau) / denom
    resid = tau - k * t
    ss = float(((tau - tau.mean()) ** 2).sum())
    return {"k_theta": k, "n": int(end), "r2": 1.0 - float(resid @ resid) / ss if ss > 0 else 1.0}

"""Lumped reductions (seed III-D): closed forms, quadrature reference, wire geometry, torque balance."""

import numpy as np
import pytest

from bayesrod.physics import k_theta, k_x, ktheta_nd, kx_nd
from bayesrod.physics import reference as R
from bayesrod.physics.elastica import secant_k_theta
from bayesrod.physics.lumped import (
    fit_torque_balance,
    flexural_rigidity,
    seed_angle_solution,
    wire_dx_from_elongation,
    wire_elongation_from_dx,
)


@pytest.mark.parametrize("h", [0.05, 0.3, 0.79])
def test_constant_EI_cantilever_stiffnesses(h):
    EI, L = 1.7, 0.8
    assert k_theta(h, EI, 0.0, L) == pytest.approx(2 * EI / h, rel=1e-12)
    assert k_x(h, EI, 0.0, L) == pytest.approx(3 * EI / h**3, rel=1e-12)


@pytest.mark.parametrize("p", [0.0, 0.1, 0.25, 0.43, 0.5, 1.0, 1.6, 2.5])
@pytest.mark.parametrize("eta", [0.01, 0.2, 0.5, 0.9, 0.99])
def test_closed_form_matches_quadrature_near_the_tip(p, eta):
    assert ktheta_nd(eta, p) == pytest.approx(R.ktheta_quad(eta, p), rel=1e-9)
    assert kx_nd(eta, p) == pytest.approx(R.kx_quad(eta, p), rel=1e-9)


def test_taper_softens_with_height_and_compliance_in_series():
    h = np.linspace(0.1, 0.7, 7)
    kt = k_theta(h, 2.63, 0.43, 0.8)
    assert np.all(np.diff(kt) < 0)
    kb = 5.0
    np.testing.assert_allclose(k_theta(h, 2.63, 0.43, 0.8, kb), 1 / (1 / kt + 1 / kb), rtol=1e-12)
    np.testing.assert_allclose(k_x(h, 2.63, 0.43, 0.8, kb), 1 / (1 / k_x(h, 2.63, 0.43, 0.8) + h**2 / kb))


def test_flexural_rigidity_profile():
    s = np.array([0.0, 0.4, 0.8])
    np.testing.assert_allclose(flexural_rigidity(s, 2.63, 0.43, 0.8), [2.63, 2.63 * 0.5**1.72, 0.0])


def test_secant_stiffness_tends_to_k_theta_and_softens():
    for p in (0.0, 0.43):
        k0 = k_theta(0.45, 2.63, p, 0.8)
        ks = secant_k_theta([1e-4, 5.0], 0.45, 2.63, p, 0.8)
        assert ks[0] == pytest.approx(k0, rel=1e-4)
        assert ks[1] < k0


def test_wire_geometry_roundtrip_and_eq_wire_half_ext():
    Lw = 0.44
    dx = np.linspace(0, 0.2, 11)
    dl = wire_elongation_from_dx(dx, Lw)
    # each half stretched from Lw/2 to sqrt((Lw/2)^2 + dx^2)
    np.testing.assert_allclose(dl, 2 * np.hypot(Lw / 2, dx) - Lw)
    np.testing.assert_allclose(wire_dx_from_elongation(dl, Lw), dx, atol=1e-12)


def test_seed_angle_solution_solves_eq_angle_geom():
    rng = np.random.default_rng(0)
    h = rng.uniform(0.2, 0.8, 50)
    x = rng.uniform(0.0, 0.5, 50)
    z = rng.uniform(-0.5, 0.5, 50) * np.minimum(h, x)
    th = seed_angle_solution(x, z, h)
    np.testing.assert_allclose(x * np.cos(th) - h * np.sin(th), z, atol=1e-12)


def test_torque_balance_recovers_k_on_linear_region():
    k_true, h = 1.6, 0.5
    theta = np.linspace(0, 0.6, 61)
    F = np.minimum(k_true * theta / h, 1.2)  # linear, then a plateau the fit must ignore
    fit = fit_torque_balance(theta, F, h, linear_fraction=0.9)
    assert fit["k_theta"] == pytest.approx(k_true, rel=1e-10)
    assert fit["r2"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="theta_rad"):
        fit_torque_balance(theta[:3], F, h)

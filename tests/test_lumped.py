"""Lumped reductions (seed III-D): closed forms, quadrature reference, wire geometry, torque balance."""

import numpy as np
import pytest

from bayesrod.physics import k_theta, k_x, ktheta_nd, kx_nd
from bayesrod.physics import reference as R
from bayesrod.physics.elastica import secant_k_theta
from bayesrod.physics.lumped import (
    fit_torque_balance,
    flexural_rigidity,
    link_angle,
    seed_angle_solution,
    stem_diameter,
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
    # beyond the tip (s > L, e.g. a tilted centerline's last point) the rod has no stiffness, not NaN
    np.testing.assert_array_equal(flexural_rigidity([0.9, 1.2], 2.63, 0.43, 0.8), [0.0, 0.0])


def test_stem_diameter_is_the_round_section_of_the_taper_law():
    """d = d0 (1 - s/L)^q; with q = p, E pi d^4 / 64 is EI(s) of eq. EI_taper for a uniform E."""
    s = np.array([0.0, 0.2, 0.5, 0.79])
    d = stem_diameter(s, 0.012, 0.43, 0.8)
    np.testing.assert_allclose(d, 0.012 * (1 - s / 0.8) ** 0.43, rtol=1e-14)
    E = 2.63 * 64 / (np.pi * 0.012**4)
    np.testing.assert_allclose(E * np.pi * d**4 / 64, flexural_rigidity(s, 2.63, 0.43, 0.8), rtol=1e-12)
    np.testing.assert_array_equal(stem_diameter([0.8, 1.0], 0.012, 0.43, 0.8), [0.0, 0.0])
    # broadcasts over draws: d0 and q per row, L per row
    got = stem_diameter(s[None], np.array([[0.01], [0.02]]), np.array([[0.3], [0.5]]), np.array([[0.8], [1.0]]))
    np.testing.assert_allclose(got[1], 0.02 * (1 - s / 1.0) ** 0.5, rtol=1e-14)


def test_link_angle_is_the_rigid_links_rotation():
    np.testing.assert_allclose(link_angle([0.0, 0.5, 1.0], [0.5, 0.5, 0.5]), [0.0, np.pi / 4, np.arctan(2.0)])


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
    # a slack wire (negative elongation reading) means no lateral displacement, not NaN
    np.testing.assert_array_equal(wire_dx_from_elongation([-0.01, 0.0], Lw), [0.0, 0.0])


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


def test_torque_balance_by_hand_on_a_softening_push():
    """Default region (first sample over half the peak force, inclusive), its n and r2, written out."""
    h = 0.4
    theta = np.linspace(0.0, 0.5, 26)
    F = 3.0 * theta / h - 4.0 * theta**2  # softens: a fit beyond the linear region would come out lower
    fit = fit_torque_balance(theta, F, h)
    end = np.flatnonzero(F > 0.5 * F.max())[0] + 1
    t, tau = theta[:end], F[:end] * h
    k = (t @ tau) / (t @ t)
    resid = tau - k * t
    r2 = 1 - (resid @ resid) / ((tau - tau.mean()) ** 2).sum()
    assert fit["n"] == end and set(fit) == {"k_theta", "n", "r2"}
    assert fit["k_theta"] == pytest.approx(k, rel=1e-12) and fit["r2"] == pytest.approx(r2, rel=1e-12)
    assert 0.9 < fit["r2"] < 1.0
    whole = fit_torque_balance(theta, F, h, linear_fraction=1.0)  # 1 is allowed: every sample
    assert whole["n"] == theta.size and whole["k_theta"] < fit["k_theta"]
    # a sample exactly at the fraction of the peak is still in the region (strictly over ends it)
    F2 = np.array([0.0, 1.0, 2.0, 4.0, 3.0])
    assert fit_torque_balance(np.arange(5.0), F2, 1.0)["n"] == 4
    # non-finite samples (either array) are dropped, not propagated
    Fn, thn = F.copy(), theta.copy()
    Fn[3], thn[5] = np.nan, np.inf
    keep = np.ones(theta.size, bool)
    keep[[3, 5]] = False
    ref = fit_torque_balance(theta[keep], F[keep], h)
    assert fit_torque_balance(thn, Fn, h) == pytest.approx(ref)
    # a flat torque (no variance) has r2 = 1 by convention
    assert fit_torque_balance(np.array([1.0, 1.0]), np.array([2.0, 2.0]), h)["r2"] == 1.0


def test_torque_balance_rejects_what_it_cannot_fit():
    theta, F = np.array([0.0, 0.1, 0.2]), np.array([0.0, 1.0, 2.0])
    assert fit_torque_balance(theta[1:], F[1:], 0.5)["n"] == 2  # two samples are enough
    for bad in (0.0, -0.1, 1.01, 1.5):
        with pytest.raises(ValueError, match=r"linear_fraction: expected a value in \(0, 1\]"):
            fit_torque_balance(theta, F, 0.5, linear_fraction=bad)
    with pytest.raises(ValueError, match="force_N: expected at least 2 finite samples, got 1"):
        fit_torque_balance(np.array([0.1, np.nan]), np.array([1.0, 2.0]), 0.5)
    with pytest.raises(ValueError, match="^theta_rad: expected non-zero deflection angles"):
        fit_torque_balance(np.zeros(3), F, 0.5)
    with pytest.raises(ValueError, match="theta_rad, force_N: expected 1-D arrays of equal length"):
        fit_torque_balance(theta, F[:2], 0.5)

"""Each model effect against a limit derived by hand, and against the reference."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from bayesrod.physics import Effects, contact_from_force, force_from_displacement, k_x
from bayesrod.physics import reference as R
from bayesrod.physics.effects import parse_effect_assignments

EI0, P, L, H = 2.63, 0.43, 0.8, 0.45


def _ei(s, p=P):
    return EI0 * (1 - s / L) ** (4 * p)


def _linear_compliance(phi0, dphi0, z0, s_c0, p=P):
    """dD/dF at F -> 0 for a rest shape phi0(s): first-order beam theory.

    A unit force rotates the section at s by g(s) = int_0^s (h - z0)/EI; the
    contact, kept at height h, moves by dx - tan(phi0(s_c0)) dz.
    """

    def g(s):
        return quad(lambda t: (H - z0(t)) / _ei(t, p), 0, s, epsabs=0, epsrel=1e-12)[0]

    dx = quad(lambda s: g(s) * math.cos(phi0(s)), 0, s_c0, epsabs=0, epsrel=1e-10)[0]
    dz = -quad(lambda s: g(s) * math.sin(phi0(s)), 0, s_c0, epsabs=0, epsrel=1e-10)[0]
    return dx - math.tan(phi0(s_c0)) * dz


def _small_force(effects, F=1e-4):
    """dD/dF from the solver at a tiny force, and the displacement reference x_c(0)."""
    zero = contact_from_force(0.0, H, EI0, P, L, effects)
    one = contact_from_force(F, H, EI0, P, L, effects)
    return float((one.contact_x_m - zero.contact_x_m) / F), float(zero.contact_x_m)


def test_base_compliance_adds_Fh2_over_k():
    kb = 4.0
    D = np.array([1e-6, 2e-6])
    sol = force_from_displacement(D, H, EI0, P, L, Effects(base_compliance=kb))
    expected = D / (1 / k_x(H, EI0, P, L) + H**2 / kb)
    np.testing.assert_allclose(sol.force_N, expected, rtol=1e-5)
    # and the compliance really softens large deflections too
    stiff = force_from_displacement(0.1, H, EI0, P, L)
    soft = force_from_displacement(0.1, H, EI0, P, L, Effects(base_compliance=kb))
    assert soft.force_N < 0.5 * stiff.force_N


def test_base_tilt_rigid_rotation_and_linear_response():
    t = 0.1
    eff = Effects(base_tilt=t)
    comp, x0 = _small_force(eff)
    assert x0 == pytest.approx(H * math.tan(t), rel=1e-10)
    expected = _linear_compliance(lambda s: t, None, lambda s: s * math.cos(t), H / math.cos(t))
    assert comp == pytest.approx(expected, rel=1e-3)


def test_rest_curvature_is_an_arc_and_linear_response():
    k0 = 0.5
    eff = Effects(rest_curvature=k0)
    sol = contact_from_force(0.0, H, EI0, P, L, eff, keep_shape=True, n_steps=64)
    s = np.linspace(0, L, 65)
    np.testing.assert_allclose(sol.shape_xz_m[:, 0], (1 - np.cos(k0 * s)) / k0, atol=1e-10)
    np.testing.assert_allclose(sol.shape_xz_m[:, 1], np.sin(k0 * s) / k0, atol=1e-10)
    s_c0 = math.asin(k0 * H) / k0
    comp, x0 = _small_force(eff)
    assert x0 == pytest.approx((1 - math.cos(k0 * s_c0)) / k0, rel=1e-10)
    expected = _linear_compliance(lambda s: k0 * s, None, lambda s: math.sin(k0 * s) / k0, s_c0)
    assert comp == pytest.approx(expected, rel=1e-3)


def test_contact_friction_second_order_term():
    """Uniform rod: D = F h^3/(3EI) - (2/15) mu F^2 h^5/EI^2 + O(F^3) (derived in docs/model.md)."""
    mu, EI, h, Lr = 0.3, 1.0, 0.5, 1.0
    F = np.array([1e-3, 2e-3, 4e-3])
    with_mu = contact_from_force(F, h, EI, 0.0, Lr, Effects(contact_friction=mu)).contact_x_m
    without = contact_from_force(F, h, EI, 0.0, Lr).contact_x_m
    coef = (with_mu - without) / F**2
    np.testing.assert_allclose(coef, -2 / 15 * mu * h**5 / EI**2, rtol=2e-2)


def test_force_offset_is_additive_on_measured_force():
    D = np.array([0.0, 0.02, 0.1])
    plain = force_from_displacement(D, H, EI0, P, L)
    off = force_from_displacement(D, H, EI0, P, L, Effects(force_offset=0.25))
    np.testing.assert_allclose(off.force_N, plain.force_N + 0.25, rtol=1e-12)
    np.testing.assert_allclose(off.true_force_N, plain.force_N, rtol=1e-12)


@pytest.mark.parametrize("EI, h, Lr", [(1.0, 0.5, 1.0), (2.5, 0.35, 0.8)])
def test_self_weight_first_order_p_delta(EI, h, Lr):
    """Uniform rod, uniform weight w: x_c = F/k_x + w F C, C from linear beam theory (the second case
    is not in unit length and stiffness, so the weight's scaling w L^3 / EI0 is checked too)."""

    def x1(s):  # linear shape per unit force; straight above the contact
        return s**2 * (3 * h - s) / (6 * EI) if s <= h else h**3 / (3 * EI) + h**2 / (2 * EI) * (s - h)

    def dM(s):  # moment per unit (w F) from the weight above s on the deflected shape
        return quad(lambda t: x1(t) - x1(s), s, Lr, epsabs=0, epsrel=1e-12, points=[h])[0]

    C = quad(lambda s: dM(s) * (h - s) / EI, 0, h, epsabs=0, epsrel=1e-10)[0]
    F, w = 1e-3, np.array([1e-3, 2e-3])
    xw = contact_from_force(F, h, EI, 0.0, Lr, Effects(self_weight=1.0)).contact_x_m  # warm-up, finite
    assert np.isfinite(xw)
    x = np.array([float(contact_from_force(F, h, EI, 0.0, Lr, Effects(self_weight=wi)).contact_x_m) for wi in w])
    x0 = float(contact_from_force(F, h, EI, 0.0, Lr).contact_x_m)
    np.testing.assert_allclose((x - x0) / (w * F), C, rtol=2e-2)


def test_yield_plateau_at_My_over_h():
    My = 0.5
    D = np.array([0.005, 0.02, 0.1, 0.2])
    sol = force_from_displacement(D, H, EI0, P, L, Effects(yield_moment=My))
    elastic = force_from_displacement(D, H, EI0, P, L)
    below = elastic.force_N * H < My
    np.testing.assert_allclose(sol.force_N[below], elastic.force_N[below], rtol=1e-12)
    np.testing.assert_allclose(sol.force_N[~below], My / H, rtol=1e-9)
    assert list(sol.yielded) == list(~below)


#: The reference solver's forces [N] (L 0.8 m, EI0 2.63 N m^2, p 0.43) for the cases with self weight, whose
#: shooting under solve_ivp takes 8-10 s each, keyed by (effects, height [m], displacements [m]): stored to full
#: precision, and recomputed against these by the slow test_stored_reference_forces_are_the_reference_solvers
#: (docs/validation.md, "The slow tier").
STORED_REFERENCE_N = {
    ((("self_weight", 1.5),), 0.45, (0.02, 0.1, 0.25)): (1.2532789350764622, 5.989552170751329, 12.076507906729619),
    ((("base_compliance", 6.0), ("self_weight", 1.5)), 0.55, (0.02, 0.1, 0.2)): (
        0.2334651185236375, 1.1455223491486555, 2.1645734952937317,
    ),
    ((("base_tilt", -0.05), ("self_weight", 1.5)), 0.55, (0.02, 0.1, 0.2)): (
        0.6218793920085921, 3.0561074288139656, 5.631955552610355,
    ),
}  # fmt: skip


def _solve_reference(mapping: dict, h: float, d) -> np.ndarray:
    """The reference solver's sensor forces [N] at contact displacements ``d`` [m], height ``h`` [m]."""
    nd = {k: float(v) for k, v in Effects.from_mapping(mapping).nondim(L, EI0).items()}
    return np.array([R.solve_displacement(x / L, h / L, P, nd)["f"] for x in d]) * EI0 / L**2


def _reference_forces(mapping: dict, h: float, d: np.ndarray) -> np.ndarray:
    """:func:`_solve_reference`, read from :data:`STORED_REFERENCE_N` where that case is stored."""
    key = (tuple(sorted(mapping.items())), h, tuple(d.tolist()))
    return np.array(STORED_REFERENCE_N[key]) if key in STORED_REFERENCE_N else _solve_reference(mapping, h, d)


@pytest.mark.slow  # 26-31 s: three reference solves under self weight
def test_stored_reference_forces_are_the_reference_solvers():
    """The stored values are what the reference solver gives now."""
    for (effects, h, d), want in STORED_REFERENCE_N.items():
        np.testing.assert_allclose(_solve_reference(dict(effects), h, d), want, rtol=1e-12, atol=0)


@pytest.mark.parametrize(
    "name,value",
    [
        ("base_compliance", 6.0),
        ("rest_curvature", 0.4),
        ("base_tilt", -0.08),
        ("contact_friction", 0.25),
        ("self_weight", 1.5),
    ],
)
def test_effects_agree_with_reference(name, value):
    eff = Effects.from_mapping({name: value})
    d = np.array([0.02, 0.1, 0.25])
    fast = force_from_displacement(d, H, EI0, P, L, eff)
    ref = _reference_forces({name: value}, H, d)
    # they agree to 2e-10 (self weight; 3e-12 or better for the others): 1e-8 catches a base-moment secant
    # stopped at 1e-6 instead of 1e-12 (self weight: 1.4e-7), which 1e-6 let through; NaN where both slipped
    np.testing.assert_allclose(fast.true_force_N, ref, rtol=1e-8)


@pytest.mark.parametrize(
    "items,msg",
    [
        (["foo=1"], "effect name"),
        (["base_tilt"], "NAME=VALUE"),
        (["base_tilt=abc"], "base_tilt"),
        (["base_compliance=-1"], "base_compliance"),
        (["base_tilt=0.1", "base_tilt=0.2"], "twice"),
        # the message names what was given
        (["yield=1=2"], "effect yield: expected a number, got '1=2'"),
        (["base_tilt="], "effect: expected NAME=VALUE, got 'base_tilt='"),
        (["=0.1"], "effect: expected NAME=VALUE, got '=0.1'"),
        (["foo=1", "bar=2"], "effect name: expected one of base_compliance, .*, got bar, foo"),
    ],
)
def test_effect_parsing_errors(items, msg):
    with pytest.raises(ValueError, match=msg):
        parse_effect_assignments(items)


def test_effect_mapping_roundtrip():
    eff = parse_effect_assignments(["yield=0.3", "base_tilt=0.02"])
    assert eff.to_mapping() == {"base_tilt": 0.02, "yield": 0.3}
    assert Effects.from_mapping(eff.to_mapping()) == eff


@pytest.mark.parametrize(
    "kwargs, error, msg",
    [
        ({"base_compliance": "5"}, TypeError, "effect base_compliance: expected a number, got '5'"),
        ({"yield_moment": True}, TypeError, "effect yield_moment: expected a number, got True"),
        ({"rest_curvature": float("nan")}, ValueError, "effect rest_curvature: expected a number, got NaN"),
        ({"base_compliance": 0.0}, ValueError, "effect base_compliance: expected a stiffness > 0"),
        ({"yield_moment": 0.0}, ValueError, "effect yield: expected a moment > 0 N m"),
        ({"self_weight": -0.1}, ValueError, r"effect self_weight: expected >= 0 N/m"),
        ({"contact_friction": -1.0}, ValueError, r"effect contact_friction: expected a coefficient in \(-1, 1\)"),
        ({"contact_friction": 1.0}, ValueError, "effect contact_friction"),
        ({"contact_friction": 1.5}, ValueError, "effect contact_friction"),
        ({"base_tilt": np.pi / 4}, ValueError, r"effect base_tilt: expected \|tilt\| < pi/4 rad"),
        ({"base_tilt": -0.8}, ValueError, "effect base_tilt"),
    ],
)
def test_effect_values_are_checked_at_their_bounds(kwargs, error, msg):
    with pytest.raises(error, match=msg):
        Effects(**kwargs)


def test_effect_values_just_inside_their_bounds_are_accepted():
    eff = Effects(base_compliance=0.5, yield_moment=0.5, self_weight=0.0, contact_friction=-0.99, base_tilt=0.7)
    assert eff.base_tilt == 0.7 and Effects(contact_friction=0.99).contact_friction == 0.99
    # the nondimensional groups have the shape of EI0 (one per draw), each with its scaling in L and EI0
    EI = np.array([1.5, 3.0])
    nd = Effects(rest_curvature=0.4, base_tilt=0.1, contact_friction=0.2, self_weight=2.0).nondim(0.8, EI)
    assert all(np.shape(v) == (2,) for v in nd.values())
    np.testing.assert_allclose(nd["kappa0"], [0.32, 0.32])
    np.testing.assert_allclose(nd["w0"], 2.0 * 0.8**3 / EI)


@pytest.mark.parametrize(("name", "value"), [("contact_friction", 0.25), ("self_weight", 1.5)])
def test_base_moment_where_it_is_not_f_h_matches_the_reference(name, value):
    """With friction or self weight the base moment is solved for (a secant on its residual), not F h: the
    reported base moment against the reference solver's moment balance (f eta - mu f xi_c for friction)."""
    eff = Effects.from_mapping({name: value})
    nd = {k: float(v) for k, v in eff.nondim(L, EI0).items()}
    F = np.array([0.5, 2.0])
    fast = contact_from_force(F, H, EI0, P, L, eff)
    ref = np.array([R.solve_force(f * L**2 / EI0, H / L, P, nd)["m0"] for f in F]) * EI0 / L
    assert np.all(np.abs(ref / (F * H) - 1) > 1e-3)  # the moment is not F h here
    np.testing.assert_allclose(fast.base_moment_Nm, ref, rtol=1e-8)


@pytest.mark.parametrize(
    "mapping",
    [
        {"base_compliance": 6.0, "self_weight": 1.5},
        {"base_compliance": 6.0, "contact_friction": 0.25},
        {"base_tilt": -0.05, "self_weight": 1.5},
        {"rest_curvature": 0.3, "contact_friction": 0.25},
    ],
)
def test_two_effects_at_once_agree_with_reference(mapping):
    """Pairs of effects, as diagnose fits them: a base spring or tilt with the solved base moment of self
    weight or friction (the base rotation inside its secant), a rest curvature with friction; against the
    reference solver at 1e-8 (they agree to 3e-10)."""
    eff = Effects.from_mapping(mapping)
    d = np.array([0.02, 0.1, 0.2])
    fast = force_from_displacement(d, 0.55, EI0, P, L, eff)
    ref = _reference_forces(mapping, 0.55, d)
    assert np.isfinite(ref[:2]).all()
    np.testing.assert_allclose(fast.true_force_N, ref, rtol=1e-8)

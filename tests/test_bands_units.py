"""The bands and predictions a user reads from a Posterior, on draws made by hand (no fit: fast).

Every band is checked against the equal-tailed quantiles of the quantity computed here from its definition
(EI(s) of eq. EI_taper, k_theta and k_x of eqs. kdist and kx by quadrature of the beam's compliance, E and
d(s) of the width model), draw by draw with the draw's own stem length and base spring, at more than one
level. Written for the mutation target ``bands`` (scripts/mutation.py, docs/validation.md).
"""

from __future__ import annotations

import dataclasses
import warnings
from types import MappingProxyType

import numpy as np
import pytest

import bayesrod
from bayesrod.api.fitting import Posterior, _check_level, _grid, _q_names, unseen_height
from bayesrod.physics import Effects, force_from_displacement, k_theta, k_x

L_NOMINAL = 0.8


def _posterior(n=3000, *, spring=True, length=True, widths=True, seed=3, parameters=None, doc=None):
    rng = np.random.default_rng(seed)
    s = {
        "EI0": rng.lognormal(np.log(2.6), 0.08, n),
        "p": rng.normal(0.42, 0.03, n),
        "sigma_force_N": rng.lognormal(np.log(0.02), 0.1, n),
    }
    if spring:
        s["base_compliance"] = rng.lognormal(np.log(40.0), 0.2, n)  # a base spring [N m/rad]
    if length:
        s["length_m"] = rng.normal(L_NOMINAL, 0.03, n)
    if widths:
        s["d0_m"] = rng.normal(0.008, 2e-4, n)
        s["p_geom"] = rng.normal(0.36, 0.03, n)
    for v in s.values():
        v.setflags(write=False)
    names = parameters or list(s)
    return Posterior(
        samples=MappingProxyType(s),
        idata=None,
        length_m=L_NOMINAL,
        specimen="by-hand",
        effects=("base_compliance",) if spring else (),
        config=MappingProxyType({"seed": 7}),
        doc=MappingProxyType(doc or {"parameters": names, "convergence": {}}),
    )


def _with(post, samples=None, **changes):
    """``post`` with some fields changed (dataclasses.replace; ``samples`` a dict of arrays)."""
    if samples is not None:
        changes["samples"] = MappingProxyType(samples)
    return dataclasses.replace(post, **changes)


def _three_slips():
    """Three draws that slip at different displacements: p 0.2, 0.5, 0.9 at 0.55 m of 0.8 m slip at about 0.51,
    0.47 and 0.38 m."""
    post = _posterior(n=3, spring=False, length=False, widths=False)
    return _with(post, {**post.samples, "EI0": np.full(3, 2.6), "p": np.array([0.2, 0.5, 0.9])})


def _q(x, level):
    return np.quantile(x, [(1 - level) / 2, 0.5, (1 + level) / 2], axis=0)


def _lengths(post):
    return np.asarray(post.samples.get("length_m", np.full(post.samples["EI0"].size, post.length_m)))


def _compliances(post, h):
    """Per draw and height: int_0^h (h - s)^k / EI(s) ds for k = 1, 2 (Gauss-Legendre, 64 nodes)."""
    x, w = np.polynomial.legendre.leggauss(64)
    h = np.asarray(h, float)
    s = 0.5 * h[:, None] * (x[None, :] + 1.0)  # (m, 64)
    L = _lengths(post)[:, None, None]
    EI = post.samples["EI0"][:, None, None] * (1.0 - s[None] / L) ** (4.0 * post.samples["p"][:, None, None])
    arm = h[None, :, None] - s[None]
    half = 0.5 * h[None, :]
    return tuple((w * arm**k / EI).sum(axis=-1) * half for k in (1, 2))


@pytest.mark.parametrize("level", [0.9, 0.6])
def test_ei_band_is_each_draws_taper_law_at_its_own_length(level):
    post = _posterior()
    s = np.array([0.0, 0.2, 0.5, 0.75])
    b = post.ei_band(s, level=level)
    L = _lengths(post)[:, None]
    EI = post.samples["EI0"][:, None] * np.clip(1 - s / L, 0, None) ** (4 * post.samples["p"][:, None])
    lo, med, hi = _q(EI, level)
    np.testing.assert_allclose(b.lower, lo, rtol=1e-12)
    np.testing.assert_allclose(b.median, med, rtol=1e-12)
    np.testing.assert_allclose(b.upper, hi, rtol=1e-12)
    assert (b.level, b.x_name, b.unit) == (level, "s_m", "N m^2")
    np.testing.assert_array_equal(b.x, s)
    # the tip itself is on the grid (closed); beyond it is refused
    assert post.ei_band([L_NOMINAL]).median[0] >= 0
    with pytest.raises(ValueError, match="s_m"):
        post.ei_band([L_NOMINAL + 1e-6])


@pytest.mark.parametrize("level", [0.9, 0.5])
def test_stiffness_bands_are_the_quadrature_of_each_draws_compliance_with_its_spring_in_series(level):
    post = _posterior()
    h = np.array([0.2, 0.4, 0.55])
    c1, c2 = _compliances(post, h)
    kb = post.samples["base_compliance"][:, None]
    kt = 1.0 / (c1 / h + 1.0 / kb)  # rotation at h per moment F h: the rod's plus the spring's
    kx = 1.0 / (c2 + h**2 / kb)  # displacement at h per force F
    bt, bx = post.k_theta_band(h, level=level), post.k_x_band(h, level=level)
    for band, ref, unit in ((bt, kt, "N m/rad"), (bx, kx, "N/m")):
        lo, med, hi = _q(ref, level)
        np.testing.assert_allclose(band.lower, lo, rtol=1e-9)
        np.testing.assert_allclose(band.median, med, rtol=1e-9)
        np.testing.assert_allclose(band.upper, hi, rtol=1e-9)
        assert (band.level, band.x_name, band.unit) == (level, "height_m", unit)
        np.testing.assert_array_equal(band.x, h)
    # a clamp (no fitted spring): 2 EI / h and 3 EI / h^3 for a stem without taper
    clamp = _posterior(spring=False, length=False, widths=False)
    flat = _with(clamp, {**clamp.samples, "p": np.zeros_like(clamp.samples["p"])})
    EI0 = flat.samples["EI0"]
    np.testing.assert_allclose(flat.ei_band([0.4]).median, np.median(EI0), rtol=1e-12)
    tapered = clamp.samples["EI0"] * (1 - 0.4 / L_NOMINAL) ** (4 * clamp.samples["p"])  # the given length
    np.testing.assert_allclose(clamp.ei_band([0.4]).median, np.median(tapered), rtol=1e-12)
    np.testing.assert_allclose(flat.k_theta_band([0.4]).median, np.median(2 * EI0 / 0.4), rtol=1e-9)
    np.testing.assert_allclose(flat.k_x_band([0.4]).median, np.median(3 * EI0 / 0.4**3), rtol=1e-9)
    # the base and the tip are not heights a stiffness is read at
    for bad in (0.0, L_NOMINAL):
        with pytest.raises(ValueError, match="height_m"):
            post.k_theta_band([bad])


@pytest.mark.parametrize("level", [0.9, 0.7])
def test_modulus_and_diameter_bands_follow_the_width_model_draw_by_draw(level):
    post = _posterior()
    sm = post.samples
    E0 = 64.0 * sm["EI0"] / (np.pi * sm["d0_m"] ** 4)
    np.testing.assert_allclose(post.youngs_modulus(), E0, rtol=1e-12)
    s = np.array([0.0, 0.3, 0.6, 0.79])
    x = 1.0 - s[None, :] / _lengths(post)[:, None]
    E = np.where(x > 0, E0[:, None] * np.where(x > 0, x, 1.0) ** (4 * (sm["p"] - sm["p_geom"])[:, None]), np.nan)
    assert np.isnan(E).any()  # some draws' stems end before 0.79 m: they are left out there
    lo, med, hi = np.nanquantile(E, [(1 - level) / 2, 0.5, (1 + level) / 2], axis=0)
    b = post.modulus_band(s, level=level)
    np.testing.assert_allclose(np.c_[b.lower, b.median, b.upper], np.c_[lo, med, hi], rtol=1e-9)
    assert (b.level, b.unit, b.x_name) == (level, "Pa", "s_m")
    np.testing.assert_array_equal(b.x, s)
    d = sm["d0_m"][:, None] * np.clip(x, 0, None) ** sm["p_geom"][:, None]
    db = post.diameter_band(s, level=level)
    np.testing.assert_allclose(np.c_[db.lower, db.median, db.upper], _q(d, level).T, rtol=1e-9)
    assert (db.level, db.unit, db.x_name) == (level, "m", "s_m")
    np.testing.assert_array_equal(db.x, s)
    # the uniform-modulus model (no p_geom): E flat along s, d(s) tapers with the bending's p
    uni = _posterior(length=False)
    s2 = {k: v for k, v in uni.samples.items() if k != "p_geom"}
    uni = _with(uni, s2)
    np.testing.assert_allclose(uni.modulus_band([0.0, 0.5]).median, np.median(uni.youngs_modulus()), rtol=1e-9)
    d_uni = uni.samples["d0_m"] * (1 - 0.5 / L_NOMINAL) ** uni.samples["p"]
    np.testing.assert_allclose(uni.diameter_band([0.5]).median, np.median(d_uni), rtol=1e-12)
    # without widths there is no modulus to read
    bare = _posterior(widths=False)
    for call in (bare.youngs_modulus, lambda: bare.modulus_band([0.1]), lambda: bare.diameter_band([0.1])):
        with pytest.raises(ValueError, match="diameters"):
            call()


@pytest.mark.parametrize("level, lo_name, hi_name", [(0.9, "q05", "q95"), (0.95, "q025", "q975"), (0.5, "q25", "q75")])
def test_summary_frame_states_its_level_in_its_columns_and_holds_those_quantiles(level, lo_name, hi_name):
    conv = {"rhat": {"EI0": 1.003, "p": 1.004}, "ess_bulk": {"EI0": 812.0, "p": 790.0}}
    post = _posterior(parameters=["EI0", "p"], doc={"parameters": ["EI0", "p"], "convergence": conv})
    df = post.summary(level=level)
    assert list(df.index) == ["EI0", "p"] and df.attrs["level"] == level
    assert {lo_name, hi_name} <= set(df.columns)
    for name in ("EI0", "p"):
        x = post.samples[name]
        lo, med, hi = _q(x, level)
        row = df.loc[name]
        assert (row[lo_name], row["median"], row[hi_name]) == pytest.approx((lo, med, hi), rel=1e-12)
        assert row["mean"] == pytest.approx(x.mean(), rel=1e-12)
        assert row["sd"] == pytest.approx(x.std(ddof=1), rel=1e-12)
        assert (row["r_hat"], row["ess_bulk"]) == (conv["rhat"][name], conv["ess_bulk"][name])
    # the default level is 0.9; a run without convergence numbers reads NaN there
    assert {"q05", "q95"} <= set(post.summary().columns) and post.summary().attrs["level"] == 0.9
    bare = _posterior(parameters=["EI0"], doc={"parameters": ["EI0"]}).summary()
    assert np.isnan(bare.loc["EI0", "r_hat"]) and np.isnan(bare.loc["EI0", "ess_bulk"])
    partial = _posterior(doc={"parameters": ["EI0"], "convergence": {"rhat": {}, "ess_bulk": {}}}).summary()
    assert np.isnan(partial.loc["EI0", "r_hat"]) and np.isnan(partial.loc["EI0", "ess_bulk"])


def test_quantile_names_and_level_checks():
    assert _q_names(0.9) == ("q05", "q95")
    assert _q_names(0.95) == ("q025", "q975")
    assert _q_names(0.5) == ("q25", "q75")
    assert _q_names(0.99) == ("q005", "q995")
    assert _q_names(0.8) == ("q10", "q90")
    assert _check_level("0.8") == 0.8
    for bad in (0, 1, 90, -0.1, "ninety", None, float("nan")):
        with pytest.raises(ValueError, match="level"):
            _check_level(bad)
    np.testing.assert_array_equal(_grid(0.3, "h", 0.0, 1.0), [0.3])
    np.testing.assert_array_equal(_grid([0.0, 1.0], "s", 0.0, 1.0, closed=True), [0.0, 1.0])
    for bad in ([0.0], [1.0], [1.2], [-0.1], [np.nan], [[0.1, 0.2]]):
        with pytest.raises(ValueError, match="^h: expected"):
            _grid(bad, "h", 0.0, 1.0)
    with pytest.raises(ValueError, match="expected 0 < value < L = 1 m, got 1$"):
        _grid([0.5, 1.0], "h", 0.0, 1.0)
    with pytest.raises(ValueError, match="expected 0 <= value <= L = 1 m, got 1.5$"):
        _grid([1.5], "s", 0.0, 1.0, closed=True)
    # every band names its grid in its errors
    post = _posterior(n=50)
    for call, name in (
        (post.ei_band, "s_m"),
        (post.modulus_band, "s_m"),
        (post.diameter_band, "s_m"),
        (post.k_theta_band, "height_m"),
        (post.k_x_band, "height_m"),
        (lambda x: post.predict_force(x, [0.01]), "height_m"),
    ):
        with pytest.raises(ValueError, match=f"^{name}: expected"):
            call(2 * L_NOMINAL)


def test_unseen_height_is_midway_in_the_widest_gap_or_above_a_single_height():
    assert unseen_height([0.3, 0.4, 0.7], 1.0) == 0.55
    assert unseen_height([0.7, 0.3, 0.4, 0.3], 1.0) == 0.55  # order and repeats do not matter
    assert unseen_height([0.2, 0.6, 0.7], 1.0) == 0.4
    assert unseen_height([0.4], 1.0) == 0.46  # 1.15 h below the midpoint to the tip
    assert unseen_height([0.9], 1.0) == 0.95  # the midpoint to the tip below 1.15 h
    assert unseen_height([0.3, 0.5], 1.0) == 0.4  # two heights: between them
    assert unseen_height([0.3333, 0.5], 1.0) == 0.417  # rounded to the millimetre
    assert unseen_height([0.4111], 1.0) == 0.473


def test_thinned_draws_are_a_fixed_subset_without_repeats():
    post = _posterior(n=500)
    a, b = post.thinned(120), post.thinned(120)
    assert all(v.size == 120 for v in a.values())
    np.testing.assert_array_equal(a["EI0"], b["EI0"])
    assert np.unique(a["EI0"]).size == 120 and np.isin(a["EI0"], post.samples["EI0"]).all()
    # a draw keeps its own parameters together
    i = np.searchsorted(np.sort(post.samples["EI0"]), a["EI0"][0])
    j = int(np.flatnonzero(post.samples["EI0"] == np.sort(post.samples["EI0"])[i])[0])
    assert a["p"][0] == post.samples["p"][j]
    assert post.thinned(5000)["EI0"].size == 500
    # the seed is the fit's (config "seed", 0 when absent); samples.npz holds 4000 draws
    other = _with(post, config=MappingProxyType({"seed": 8}))
    assert not np.array_equal(other.thinned(120)["EI0"], a["EI0"])
    unseeded = _with(post, config=MappingProxyType({}))
    zero = _with(post, config=MappingProxyType({"seed": 0}))
    np.testing.assert_array_equal(unseeded.thinned(120)["EI0"], zero.thinned(120)["EI0"])
    assert _posterior(n=4500, spring=False, length=False, widths=False).thinned()["EI0"].size == 4000
    loaded = _with(post, draws_are_thinned=True)
    np.testing.assert_array_equal(loaded.thinned(500)["EI0"], post.samples["EI0"])


def _solve_each(post, idx, h, D):
    """Force per draw by the elastica, each draw with its own spring and length (as the band must)."""
    rows = []
    for i in idx:
        sm = {k: v[i] for k, v in post.samples.items()}
        spring = {"base_compliance": float(sm["base_compliance"])} if "base_compliance" in sm else {}
        eff = Effects.from_mapping(spring)
        sol = force_from_displacement(D, h, sm["EI0"], sm["p"], float(sm.get("length_m", post.length_m)), eff)
        rows.append(np.where(sol.slipped, np.nan, sol.force_N))
    return np.array(rows)


def test_force_band_is_the_quantiles_of_each_draws_elastica_with_its_spring_and_length():
    post = _posterior(n=40, widths=False)
    D = np.array([0.0, 0.01, 0.05, 0.12])
    fb = post.predict_force(0.5, D, level=0.8, n_draws=40)  # every draw: the subset is a permutation
    F = _solve_each(post, range(40), 0.5, D)
    lo, med, hi = np.nanquantile(F, [0.1, 0.5, 0.9], axis=0)
    np.testing.assert_allclose(np.c_[fb.lower, fb.median, fb.upper], np.c_[lo, med, hi], rtol=1e-6, atol=1e-12)
    assert fb.median[0] == 0.0 and np.all(np.diff(fb.median) > 0)
    np.testing.assert_allclose(fb.slip_probability, np.isnan(F).mean(axis=0))
    assert (fb.level, fb.height_m, fb.unit, fb.x_name) == (0.8, 0.5, "N", "displacement_m")
    np.testing.assert_array_equal(fb.x, D)
    assert np.isfinite(post.predict_force(0.5, D, n_draws=2).median).all()  # two draws are enough
    # the documented defaults: 400 draws, seed 0, level 0.9
    many = _posterior(n=1000, spring=False, length=False, widths=False)
    d = many.predict_force(0.5, D)
    e = many.predict_force(0.5, D, level=0.9, n_draws=400, seed=0)
    np.testing.assert_array_equal(np.c_[d.lower, d.median, d.upper], np.c_[e.lower, e.median, e.upper])
    assert d.level == 0.9
    # fewer draws: a random subset of them, fixed by the seed
    a, b = post.predict_force(0.5, D, n_draws=10, seed=1), post.predict_force(0.5, D, n_draws=10, seed=1)
    np.testing.assert_array_equal(a.median, b.median)
    assert not np.array_equal(a.median, post.predict_force(0.5, D, n_draws=10, seed=2).median)
    for kw in ({"n_draws": 1}, {"n_draws": 2.5}):
        with pytest.raises(ValueError, match="n_draws"):
            post.predict_force(0.5, D, **kw)
    for bad in ([-0.01], [np.nan], [[0.01]]):
        with pytest.raises(ValueError, match="displacement_m"):
            post.predict_force(0.5, bad)


def test_force_band_is_nan_where_fewer_than_two_draws_still_hold_the_sensor():
    post = _posterior(n=30, spring=False, length=False, widths=False)
    D = np.array([0.02, 0.3, 0.5, 0.65, 0.79])  # from a small push to past every draw's slip
    with warnings.catch_warnings():  # past every draw's slip the band is NaN, silently
        warnings.simplefilter("error")
        fb = post.predict_force(0.55, D, n_draws=30)
    F = _solve_each(post, range(30), 0.55, D)
    held = np.isfinite(F).sum(axis=0)
    assert held[0] == 30 and held[-1] == 0
    np.testing.assert_array_equal(np.isnan(fb.median), held < 2)
    ok = held >= 2
    np.testing.assert_allclose(fb.median[ok], np.nanmedian(F[:, ok], axis=0), rtol=1e-6)
    np.testing.assert_allclose(fb.slip_probability, 1 - held / 30)


def test_force_band_needs_two_draws_that_hold_and_reads_them():
    """Three draws that slip at different displacements (:func:`_three_slips`): the band is the draws' quantiles
    while two or three hold, NaN once one or none does."""
    post = _three_slips()
    D = np.array([0.2, 0.42, 0.49, 0.6])
    fb = post.predict_force(0.55, D, n_draws=3)
    F = _solve_each(post, range(3), 0.55, D)
    np.testing.assert_array_equal(np.isfinite(F).sum(axis=0), [3, 2, 1, 0])
    np.testing.assert_array_equal(np.isnan(fb.median), [False, False, True, True])
    np.testing.assert_allclose(fb.median[:2], np.nanmedian(F[:, :2], axis=0), rtol=1e-6)
    np.testing.assert_allclose(fb.lower[:2], np.nanquantile(F[:, :2], 0.05, axis=0), rtol=1e-6)
    np.testing.assert_allclose(fb.slip_probability, [0, 1 / 3, 2 / 3, 1])


def test_predict_for_one_rod_gives_the_closed_form_stiffnesses_and_the_elastica_forces():
    EI0, L, h = 2.0, 1.0, 0.4
    pr = bayesrod.predict(h, [0.0, 0.001, 1.2], EI0=EI0, p=0.0, length_m=L)
    doc = pr.to_dict()
    assert doc["k_theta_Nm_per_rad"] == pytest.approx(2 * EI0 / h, rel=1e-12)
    assert doc["k_x_N_per_m"] == pytest.approx(3 * EI0 / h**3, rel=1e-12)
    pts = doc["points"]
    assert pts[0]["force_N"] == 0.0 and pts[0]["slipped"] is False
    assert pts[1]["force_N"] == pytest.approx(3 * EI0 / h**3 * 0.001, rel=2e-3)  # small deflection
    assert pts[2]["slipped"] is True and pts[2]["force_N"] is None and pts[2]["contact_s_m"] is None
    assert pts[1]["contact_s_m"] == pytest.approx(h, abs=1e-3)
    # a base spring in series; a preset fills what is not given
    kb = 30.0
    spr = bayesrod.predict(h, [0.001], EI0=EI0, p=0.0, length_m=L, effects={"base_compliance": kb}).to_dict()
    assert spr["k_theta_Nm_per_rad"] == pytest.approx(1 / (h / (2 * EI0) + 1 / kb), rel=1e-12)
    assert spr["k_x_N_per_m"] == pytest.approx(1 / (h**3 / (3 * EI0) + h**2 / kb), rel=1e-12)
    assert spr["model"]["effects"]["base_compliance"] == kb
    tw = bayesrod.predict(0.4, [0.01], preset="twig", EI0=3.0).to_dict()["model"]
    assert tw["EI0"] == 3.0 and tw["length_m"] == 0.8


def test_predict_over_a_posterior_reads_each_draws_length_and_spring():
    post = _posterior(n=60, widths=False)
    doc = bayesrod.predict(0.5, [0.0, 0.03], posterior=post, n_draws=60).to_dict()
    sm = post.samples
    L, kb = _lengths(post), sm["base_compliance"]
    kt = 1.0 / (1.0 / k_theta(0.5, sm["EI0"], sm["p"], L) + 1.0 / kb)
    kx = k_x(0.5, sm["EI0"], sm["p"], L, kb)
    for key, ref in (("k_theta_Nm_per_rad", kt), ("k_x_N_per_m", kx)):
        lo, med, hi = _q(ref, 0.9)
        assert (doc[key]["q05"], doc[key]["median"], doc[key]["q95"]) == pytest.approx((lo, med, hi), rel=1e-9)
    F = _solve_each(post, range(60), 0.5, np.array([0.0, 0.03]))
    lo, med, hi = _q(F[:, 1], 0.9)
    f = doc["points"][1]["force_N"]
    assert (f["q05"], f["median"], f["q95"]) == pytest.approx((lo, med, hi), rel=1e-6)
    assert doc["points"][1]["slip_probability"] == 0.0 and doc["points"][1]["slipped"] is False
    assert doc["level"] == 0.9 and doc["posterior"]["draws"] == 60
    with pytest.raises(TypeError, match="posterior"):
        bayesrod.predict(0.5, [0.01], posterior={"EI0": 1.0})


@pytest.mark.parametrize(
    "kw, err, field",
    [
        ({"EI0": 0.0, "p": 0.0, "length_m": 1.0}, ValueError, "EI0: expected a flexural rigidity > 0"),
        ({"EI0": -1.0, "p": 0.0, "length_m": 1.0}, ValueError, "EI0: expected a flexural rigidity > 0"),
        ({"EI0": 1.0, "p": -0.1, "length_m": 1.0}, ValueError, "p: expected a taper exponent >= 0"),
        ({"EI0": 1.0, "p": 0.0, "length_m": 0.0}, ValueError, "length_m: expected a stem length > 0"),
        ({"EI0": 1.0, "p": 0.0, "length_m": np.inf}, ValueError, "length_m: expected a finite number"),
        ({"EI0": "stiff", "p": 0.0, "length_m": 1.0}, TypeError, "EI0: expected a number, got str"),
        ({"EI0": 1.0, "p": 0.0}, ValueError, "length_m: expected a value"),
        ({"p": 0.0}, ValueError, "EI0, length_m: expected a value"),
    ],
)
def test_predict_names_the_bad_rod_parameter(kw, err, field):
    with pytest.raises(err, match=f"^{field}"):
        bayesrod.predict(0.4, [0.01], **kw)


@pytest.mark.parametrize(
    "h, D, field",
    [
        (0.0, [0.01], "height_m: expected 0 < height < length"),
        (1.0, [0.01], "height_m"),
        (np.nan, [0.01], "height_m"),
        (0.4, [-0.01], "displacement_m: expected values >= 0 m, got -0.01"),
        (0.4, [np.nan], "displacement_m: expected finite numbers"),
        (0.4, [[0.01, 0.02]], "displacement_m: expected finite numbers"),
    ],
)
def test_predict_names_the_bad_push(h, D, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        bayesrod.predict(h, D, EI0=1.0, p=0.0, length_m=1.0)


def test_predict_for_one_rod_reads_its_preset_its_effects_and_reports_a_yield():
    tw = bayesrod.predict(0.4, [0.01], preset="twig").to_dict()["model"]
    assert (tw["EI0"], tw["length_m"]) == pytest.approx((2.63, 0.8), rel=0.01) and 0 < tw["p"] < 1
    mixed = bayesrod.predict(0.4, [0.01], preset="twig", p=0.2, length_m=0.9).to_dict()["model"]
    assert (mixed["EI0"], mixed["p"], mixed["length_m"]) == (tw["EI0"], 0.2, 0.9)
    assert bayesrod.predict(0.4, [0.01], EI0=0.5, p=0.0, length_m=1.0).to_dict()["model"]["EI0"] == 0.5
    # a base spring softens the force itself, and Effects or a mapping say the same
    kb, D = 30.0, 0.001
    f_spring = bayesrod.predict(0.4, [D], EI0=2.0, p=0.0, length_m=1.0, effects={"base_compliance": kb})
    f_same = bayesrod.predict(0.4, [D], EI0=2.0, p=0.0, length_m=1.0, effects=Effects(base_compliance=kb))
    kx = 1 / (0.4**3 / 6.0 + 0.4**2 / kb)
    assert f_spring.to_dict()["points"][0]["force_N"] == pytest.approx(kx * D, rel=3e-3)
    assert f_same.to_dict() == f_spring.to_dict()
    # a base that yields: flagged where it has
    y = bayesrod.predict(0.4, [0.001, 0.3], EI0=2.0, p=0.0, length_m=1.0, effects={"yield": 0.5}).to_dict()
    assert [q["yielded"] for q in y["points"]] == [False, True]
    assert y["points"][1]["force_N"] <= 0.5 / 0.4 + 1e-9  # capped at M_y / h (before the arm shortens)


def test_predict_over_a_posterior_with_a_known_length_and_given_effects():
    post = _posterior(n=40, spring=False, length=False, widths=False)
    post = _with(post, config=MappingProxyType({"seed": 7, "run": "runs/by-hand"}))
    D = np.array([0.0, 0.03])
    plain = bayesrod.predict(0.5, D, posterior=post).to_dict()
    assert plain["posterior"] == {"run": "runs/by-hand", "draws": 40, "length_m": L_NOMINAL}
    assert plain["height_m"] == 0.5 and [q["displacement_m"] for q in plain["points"]] == [0.0, 0.03]
    sm = post.samples
    lo, med, hi = _q(k_theta(0.5, sm["EI0"], sm["p"], L_NOMINAL), 0.9)
    kt = plain["k_theta_Nm_per_rad"]
    assert (kt["q05"], kt["median"], kt["q95"]) == pytest.approx((lo, med, hi), rel=1e-9)
    c = plain["points"][1]["contact_s_m"]
    assert c is not None and 0.5 < c["q05"] <= c["median"] <= c["q95"] < 0.51  # the arc to the contact
    # given effects: an offset shifts every force, a spring softens the stiffnesses
    shifted = bayesrod.predict(0.5, D, posterior=post, effects={"force_offset": 0.3}).to_dict()
    for a, b in zip(plain["points"], shifted["points"], strict=True):
        assert b["force_N"]["median"] == pytest.approx(a["force_N"]["median"] + 0.3, rel=1e-9)
    soft = bayesrod.predict(0.5, D, posterior=post, effects={"base_compliance": 20.0}).to_dict()
    lo, med, hi = _q(k_theta(0.5, sm["EI0"], sm["p"], L_NOMINAL, 20.0), 0.9)
    kt = soft["k_theta_Nm_per_rad"]
    assert (kt["q05"], kt["median"], kt["q95"]) == pytest.approx((lo, med, hi), rel=1e-9)
    # the run's specimen names it when no run directory does; a fixed subset of the draws
    unnamed = _posterior(n=1000, spring=False, length=False, widths=False)
    one = bayesrod.predict(0.5, D, posterior=unnamed).to_dict()
    assert one["posterior"]["run"] == "by-hand" and one["posterior"]["draws"] == 400
    assert bayesrod.predict(0.5, D, posterior=unnamed).to_dict() == one


def test_predict_over_a_posterior_marks_slips_and_drops_forces_held_by_fewer_than_two_draws():
    post = _three_slips()
    pts = bayesrod.predict(0.55, [0.2, 0.42, 0.49, 0.6], posterior=post).to_dict()["points"]
    assert [q["slip_probability"] for q in pts] == pytest.approx([0, 1 / 3, 2 / 3, 1])
    assert [q["slipped"] for q in pts] == [False, False, True, True]
    assert [q["force_N"] is None for q in pts] == [False, False, True, True]
    assert [q["contact_s_m"] is None for q in pts] == [False, False, True, True]
    F = _solve_each(post, range(3), 0.55, np.array([0.42]))[:, 0]
    assert pts[1]["force_N"]["median"] == pytest.approx(np.nanmedian(F), rel=1e-6)
    # half the draws slipped is not yet "slipped"
    two = _with(post, {k: v[[0, 2]] for k, v in post.samples.items()})
    half = bayesrod.predict(0.55, [0.42], posterior=two).to_dict()["points"][0]
    assert half["slip_probability"] == 0.5 and half["slipped"] is False

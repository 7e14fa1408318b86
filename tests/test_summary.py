"""Posterior summaries (bayesrod.inference.summary), each against a hand computation on known draws.

Fast unit tests: the mutation run (scripts/mutation.py) mutates summary.py against this file alone, so
each number a summary writes is pinned here, both interval ends and the level they state."""

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from bayesrod.inference import summary as S
from bayesrod.physics import flexural_rigidity, k_theta, stem_diameter

RNG = np.random.default_rng(7)
N = 4001
# draws with known quantiles: a shuffled uniform grid, so the q-quantile is exactly lo + q (hi - lo)
EI0 = RNG.permutation(np.linspace(1.0, 3.0, N))
P = RNG.permutation(np.linspace(0.2, 0.6, N))
L = 0.9


def _exact(x, q):
    """The q-quantile of the draws ``x`` by sorting (numpy's default linear interpolation, written out)."""
    xs = np.sort(np.asarray(x, float), axis=0)
    pos = q * (xs.shape[0] - 1)
    i = int(np.floor(pos))
    w = pos - i
    return xs[i] * (1 - w) + xs[min(i + 1, xs.shape[0] - 1)] * w


def test_the_stated_level_is_the_interval_written():
    assert S.LEVEL == 0.9
    assert S.QUANTILES == pytest.approx(((1 - S.LEVEL) / 2, 0.5, (1 + S.LEVEL) / 2), abs=1e-15)
    q = S.credible_interval(EI0)
    assert set(q) == {"median", "q05", "q95"} and all(type(v) is float for v in q.values())
    assert q["q05"] == pytest.approx(1.1, rel=1e-12)  # 1 + 0.05 * 2
    assert q["median"] == pytest.approx(2.0, rel=1e-12)
    assert q["q95"] == pytest.approx(2.9, rel=1e-12)
    # NaN draws (beyond a draw's slip) are ignored, all-NaN gives NaN without a warning
    with_nan = np.concatenate([EI0, [np.nan] * 50])
    assert S.credible_interval(with_nan) == q
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        col = S.quantiles(np.full((5, 2), np.nan))
    assert np.all(np.isnan(col["median"]))


def test_quantiles_work_along_the_axis_asked():
    x = np.stack([EI0, 10 * EI0], axis=1)  # (N, 2)
    q = S.quantiles(x)
    np.testing.assert_allclose(q["q05"], [1.1, 11.0], rtol=1e-12)
    qt = S.quantiles(x.T, axis=1)
    np.testing.assert_allclose(qt["q95"], [2.9, 29.0], rtol=1e-12)


def test_ei_band_is_the_quantile_of_EI_at_each_s():
    s = np.array([0.0, 0.3, 0.6, 0.85])
    band = S.ei_band(EI0, P, L, s)
    EI = flexural_rigidity(s[None], EI0[:, None], P[:, None], L)
    for key, q in (("q05", 0.05), ("median", 0.5), ("q95", 0.95)):
        np.testing.assert_allclose(band[key], [_exact(EI[:, j], q) for j in range(s.size)], rtol=1e-12)
    # a length per draw (shape (n, 1)) is used draw by draw
    Ls = np.linspace(0.8, 1.0, N)[:, None]
    band_L = S.ei_band(EI0, P, Ls, s)
    EI_L = flexural_rigidity(s[None], EI0[:, None], P[:, None], Ls)
    np.testing.assert_allclose(band_L["q95"], [_exact(EI_L[:, j], 0.95) for j in range(s.size)], rtol=1e-12)


def test_draw_lengths_uses_the_sampled_length_when_there_is_one():
    assert S.draw_lengths({"EI0": EI0}, 0.9) == 0.9
    Ls = np.array([0.8, 1.1])
    got = S.draw_lengths({"length_m": Ls}, 0.9)
    assert got.shape == (2, 1) and np.all(got[:, 0] == Ls)


def test_k_theta_band_with_and_without_a_base_spring():
    h = np.array([0.3, 0.5, 0.7])
    band = S.k_theta_band(EI0, P, L, h)
    kt = k_theta(h[None], EI0[:, None], P[:, None], L)
    np.testing.assert_allclose(band["q05"], [_exact(kt[:, j], 0.05) for j in range(3)], rtol=1e-12)
    np.testing.assert_allclose(band["q95"], [_exact(kt[:, j], 0.95) for j in range(3)], rtol=1e-12)
    kb = RNG.uniform(2.0, 20.0, N)
    soft = S.k_theta_band(EI0, P, L, h, kb)
    ks = 1.0 / (1.0 / kt + 1.0 / kb[:, None])  # in series
    np.testing.assert_allclose(soft["median"], [_exact(ks[:, j], 0.5) for j in range(3)], rtol=1e-12)
    assert np.all(soft["q95"] < band["q95"])


def test_youngs_modulus_is_64_EI0_over_pi_d0_to_the_4():
    samples = {"EI0": np.array([2.0, 3.0]), "p": np.array([0.4, 0.4]), "d0_m": np.array([0.01, 0.02])}
    np.testing.assert_allclose(S.youngs_modulus(samples), [64 * 2.0 / (np.pi * 1e-8), 64 * 3.0 / (np.pi * 16e-8)])
    with pytest.raises(ValueError, match="measured diameters"):
        S.youngs_modulus({"EI0": EI0, "p": P})
    with pytest.raises(ValueError, match="measured diameters"):
        S.diameter_draws({"EI0": EI0, "p": P}, L, [0.1])


def test_modulus_and_diameter_draws_follow_the_taper_laws():
    s = np.array([0.0, 0.2, 0.5])
    samples = {"EI0": np.array([2.0, 2.5]), "p": np.array([0.5, 0.3]), "d0_m": np.array([0.012, 0.015])}
    E0 = 64 * samples["EI0"] / (np.pi * samples["d0_m"] ** 4)
    # uniform modulus (no p_geom): E flat, d with q = p
    np.testing.assert_allclose(S.modulus_draws(samples, L, s), np.repeat(E0[:, None], 3, axis=1), rtol=1e-12)
    d = stem_diameter(s[None], samples["d0_m"][:, None], samples["p"][:, None], L)
    np.testing.assert_allclose(S.diameter_draws(samples, L, s), d, rtol=1e-12)
    # graded: E(s) = E0 (1 - s/L)^(4 (p - p_geom)), d with q = p_geom
    graded = {**samples, "p_geom": np.array([0.25, 0.35])}
    x = 1 - s[None] / L
    want = E0[:, None] * x ** (4 * (graded["p"] - graded["p_geom"])[:, None])
    np.testing.assert_allclose(S.modulus_draws(graded, L, s), want, rtol=1e-12)
    # at and beyond the tip no stem, no modulus: NaN whichever way the modulus tapers (a negative power of 0
    # read infinite), and the band's quantiles leave those draws out
    for dq in (0.1, -0.1):
        tapering = {**graded, "p_geom": graded["p"] - dq}
        assert np.isnan(S.modulus_draws(tapering, L, [L, 1.2 * L])).all()
    # a sampled length: each draw ends at its own tip; the summary's band stays finite where some draws reach
    sampled = {**graded, "p_geom": graded["p"] + 0.1, "length_m": np.array([0.85 * L, 1.1 * L])}
    E = S.modulus_draws(sampled, L, [0.5 * L, 0.9 * L])
    assert np.isfinite(E[:, 0]).all() and np.isnan(E[0, 1]) and np.isfinite(E[1, 1])
    band = S.youngs_modulus_summary(sampled, L)["band"]
    assert np.isfinite(np.array([band[k] for k in ("median", "q05", "q95")], float)).all()
    d_g = stem_diameter(s[None], samples["d0_m"][:, None], graded["p_geom"][:, None], L)
    np.testing.assert_allclose(S.diameter_draws(graded, L, s), d_g, rtol=1e-12)
    # beyond the tip the stem has no width (clipped, not negative powers of negative numbers)
    assert np.all(S.diameter_draws(samples, L, [L, 1.2 * L]) == 0)


@pytest.mark.parametrize("shift, verdict", [(0.0, "consistent"), (0.2, "rejected"), (-0.2, "rejected")])
def test_youngs_modulus_summary_states_the_uniform_modulus_verdict(shift, verdict):
    n = 2001
    p = RNG.permutation(np.linspace(0.3, 0.5, n))
    p_geom = p - shift + RNG.permutation(np.linspace(-0.05, 0.05, n))
    d0 = RNG.permutation(np.linspace(0.009, 0.011, n))
    samples = {"EI0": RNG.permutation(np.linspace(1.5, 2.5, n)), "p": p, "d0_m": d0, "p_geom": p_geom}
    out = S.youngs_modulus_summary(samples, L, "frames")
    assert out["model"] == "graded" and out["source"] == "frames" and out["uniform_modulus"] == verdict
    dq = p - p_geom
    assert out["modulus_taper"]["q05"] == pytest.approx(_exact(dq, 0.05), rel=1e-12)
    assert out["modulus_taper"]["q95"] == pytest.approx(_exact(dq, 0.95), rel=1e-12)
    assert out["d0_m"] == pytest.approx({"median": _exact(d0, 0.5), "q05": _exact(d0, 0.05), "q95": _exact(d0, 0.95)})
    E = S.youngs_modulus(samples)
    assert out["E_Pa"]["q95"] == pytest.approx(_exact(E, 0.95), rel=1e-12)
    band = out["band"]
    np.testing.assert_allclose(band["s_m"], np.linspace(0, 0.9, 10) * L)
    Es = S.modulus_draws(samples, L, np.asarray(band["s_m"]))
    np.testing.assert_allclose(band["q05"], [_exact(Es[:, j], 0.05) for j in range(10)], rtol=1e-12)
    uniform = S.youngs_modulus_summary({k: v for k, v in samples.items() if k != "p_geom"}, L)
    assert uniform["model"] == "uniform" and "uniform_modulus" not in uniform and "band" not in uniform


def test_the_verdict_is_consistent_exactly_when_zero_is_inside_the_interval():
    """The boundary: 0 at an interval end counts as inside (q05 <= 0 <= q95)."""
    n = 21  # the 5% quantile of 21 sorted draws is the second, the 95% the twentieth
    base = {"EI0": np.full(n, 2.0), "p": np.zeros(n), "d0_m": np.full(n, 0.01)}
    for dq, verdict in (
        (np.arange(-1.0, n - 1.0), "consistent"),  # q05 = 0 exactly
        (np.arange(0.0, n) + 1e-9, "rejected"),  # q05 just above 0
        (-np.arange(-1.0, n - 1.0), "consistent"),  # q95 = 0 exactly
        (-np.arange(0.0, n) - 1e-9, "rejected"),
    ):
        out = S.youngs_modulus_summary({**base, "p_geom": -dq}, L)  # p - p_geom = dq exactly
        assert out["uniform_modulus"] == verdict, (dq[:3], out["modulus_taper"])


def test_thin_draws_without_replacement():
    samples = {"EI0": np.arange(10.0), "p": np.arange(10.0) * 2}
    t = S.thin(samples, 6, np.random.default_rng(0))
    assert t["EI0"].size == 6 and np.unique(t["EI0"]).size == 6
    np.testing.assert_array_equal(t["p"], 2 * t["EI0"])  # the same draws of every parameter
    every = S.thin(samples, 50, np.random.default_rng(0))["EI0"]  # more asked than there are: each draw once
    assert every.size == 10 and np.unique(every).size == 10


def test_predictive_forces_add_each_draws_offset_and_blank_slipped_samples():
    from bayesrod.physics import force_from_displacement

    samples = {"EI0": np.array([1.8, 2.0, 2.2]), "p": np.array([0.5, 0.4, 0.45])}
    D = np.linspace(0.0, 0.06, 5)
    off = np.array([0.1, -0.2, 0.0])
    out = S.predictive_forces(samples, np.arange(3), D, 0.5, 0.9, force_offset_N=off)
    for j in range(3):
        ref = force_from_displacement(D, 0.5, samples["EI0"][j], samples["p"][j], 0.9).force_N
        np.testing.assert_allclose(out["force_N"][j], ref + off[j], rtol=1e-12, atol=1e-12)
    # a contact-height error per draw: the push is evaluated at h + error
    dh = np.array([0.01, -0.02, 0.0])
    out_h = S.predictive_forces(samples, np.arange(3), D, 0.5, 0.9, height_error_m=dh)
    ref = force_from_displacement(D, 0.5 - 0.02, samples["EI0"][1], samples["p"][1], 0.9).force_N
    np.testing.assert_allclose(out_h["force_N"][1], ref, rtol=1e-12)
    # a sampled length is used draw by draw
    out_L = S.predictive_forces({**samples, "length_m": np.array([0.8, 1.0, 0.9])}, np.array([1]), D, 0.5, 0.9)
    ref = force_from_displacement(D, 0.5, samples["EI0"][1], samples["p"][1], 1.0).force_N
    np.testing.assert_allclose(out_L["force_N"][0], ref, rtol=1e-12)
    # beyond the slip the force is NaN, and the slip is reported
    far = S.predictive_forces(samples, np.arange(1), np.array([0.01, 0.8]), 0.5, 0.9)
    assert far["slipped"][0, 1] and np.isnan(far["force_N"][0, 1]) and np.isfinite(far["force_N"][0, 0])


def test_predictive_forces_with_a_preload_effects_and_per_draw_solves():
    from bayesrod.physics import Effects, force_from_displacement

    samples = {"EI0": np.array([1.8, 2.0]), "p": np.array([0.5, 0.4])}
    D = np.linspace(0.0, 0.05, 4)
    d0 = np.array([0.012, 0.004])
    eff = Effects(base_compliance=4.0)
    out = S.predictive_forces(samples, np.arange(2), D, 0.5, 0.9, effects=eff, preload_m=d0)
    assert set(out) == {"force_N", "slipped", "contact_s_m"}
    for j in range(2):
        ref = force_from_displacement(D + d0[j], 0.5, samples["EI0"][j], samples["p"][j], 0.9, eff)
        np.testing.assert_allclose(out["force_N"][j], ref.force_N, rtol=1e-12)
        np.testing.assert_allclose(out["contact_s_m"][j], ref.contact_s_m, rtol=1e-12)
    # a fitted effect (per draw) overrides the given one, and the per-draw path returns the same fields
    fitted = {**samples, "base_compliance": np.array([2.0, 8.0])}
    D2 = np.array([0.02, 0.9])
    per = S.predictive_forces(fitted, np.arange(2), D2, 0.5, 0.9, effects=eff, preload_m=d0)
    for j in range(2):
        e_j = Effects(base_compliance=fitted["base_compliance"][j])
        ref = force_from_displacement(D2 + d0[j], 0.5, samples["EI0"][j], samples["p"][j], 0.9, e_j)
        np.testing.assert_allclose(per["force_N"][j], ref.force_N, rtol=1e-12)
        np.testing.assert_array_equal(per["slipped"][j], ref.slipped)
        np.testing.assert_allclose(per["contact_s_m"][j], ref.contact_s_m, rtol=1e-12)
    assert per["slipped"][:, 1].all() and not per["slipped"][:, 0].any()
    assert np.isnan(per["force_N"][:, 1]).all()


def _fake_fit(n=400):
    rng = np.random.default_rng(3)
    names = ["EI0", "p", "sigma_force_N"]
    samples = {
        "EI0": rng.normal(2.0, 0.1, n),
        "p": rng.normal(0.4, 0.02, n),
        "sigma_force_N": rng.uniform(0.02, 0.04, n),
    }
    pushes = [SimpleNamespace(height_m=0.3), SimpleNamespace(height_m=0.5)]
    spec = SimpleNamespace(specimen="s1", species="oak", length_m=L, pushes=pushes, diameters=None)
    post = SimpleNamespace(names=names, ndim=3, to_natural=lambda th: {k: th[:, i] for i, k in enumerate(names)})
    diag = {
        "rhat": {"EI0": 1.01, "p": 1.03, "sigma_force_N": 1.0},
        "ess_bulk": {"EI0": 900.0, "p": 700.0, "sigma_force_N": 1200.0},
    }
    return samples, spec, post, diag


def test_build_summary_writes_each_number_from_the_draws():
    samples, spec, post, diag = _fake_fit()
    doc = S.build_summary(spec, post, samples, diag, {"force_rmse_N": 0.03}, ["yield"], {"extra_key": 1})
    assert doc["specimen"] == "s1" and doc["species"] == "oak" and doc["length_m"] == L
    assert doc["effects"] == ["yield"] and doc["fit_error"] == {"force_rmse_N": 0.03} and doc["extra_key"] == 1
    for name in post.names:
        x = samples[name]
        want = {"median": _exact(x, 0.5), "q05": _exact(x, 0.05), "q95": _exact(x, 0.95)}
        assert doc["parameters"][name] == pytest.approx(want, rel=1e-12)
    kt = k_theta(np.array([0.3, 0.5])[None], samples["EI0"][:, None], samples["p"][:, None], L)
    for i, row in enumerate(doc["k_theta"]):
        assert row["height_m"] == [0.3, 0.5][i]
        assert row["q05"] == pytest.approx(_exact(kt[:, i], 0.05), rel=1e-12)
        assert row["median"] == pytest.approx(_exact(kt[:, i], 0.5), rel=1e-12)
        assert row["q95"] == pytest.approx(_exact(kt[:, i], 0.95), rel=1e-12)
    conv = doc["convergence"]
    assert conv["rhat_max"] == 1.03 and conv["ess_bulk_min"] == 700.0 and conv["rhat"] == diag["rhat"]
    assert conv["ess_bulk"] == diag["ess_bulk"] and "youngs_modulus" not in doc
    assert "rhat_walkers_max" not in conv  # diagnostics without the walkers' R-hat: none reported
    walkers = {"EI0": 1.02, "p": 1.04, "sigma_force_N": 1.01}
    told = S.build_summary(spec, post, samples, {**diag, "rhat_walkers": walkers}, {}, [], {})["convergence"]
    assert told["rhat_walkers_max"] == 1.04 and told["rhat_max"] == 1.03
    # a base spring per draw softens k_theta; measured diameters add the modulus block
    soft = S.build_summary(spec, post, {**samples, "base_compliance": np.full(400, 3.0)}, diag, {}, [], {})
    assert soft["k_theta"][0]["median"] < doc["k_theta"][0]["median"]
    spec_d = SimpleNamespace(**{**vars(spec), "diameters": SimpleNamespace(source="calipers")})
    withd = S.build_summary(spec_d, post, {**samples, "d0_m": np.full(400, 0.01)}, diag, {}, [], {})
    assert withd["youngs_modulus"]["source"] == "calipers" and withd["youngs_modulus"]["model"] == "uniform"
    # the graded model's E(s) band runs over 0..0.9 L of this stem; a fit's draws without a recorded source
    graded = {**samples, "d0_m": np.full(400, 0.01), "p_geom": samples["p"] - 0.1}
    g = S.build_summary(spec, post, graded, diag, {}, [], {})["youngs_modulus"]
    assert g["source"] is None and g["model"] == "graded" and g["band"]["s_m"][-1] == pytest.approx(0.9 * L)


def test_inference_data_holds_the_chains_in_natural_units():
    samples, spec, post, diag = _fake_fit()
    chain = np.stack([samples[k] for k in post.names], axis=-1).reshape(4, 100, 3)
    lp = -np.arange(400.0).reshape(4, 100)
    idata = S.to_inference_data(chain, lp, post, spec, {"specimen": "s1", "heights": [0.3, 0.5], "n": 3})
    assert dict(idata.posterior.sizes)["chain"] == 4 and dict(idata.posterior.sizes)["draw"] == 100
    np.testing.assert_array_equal(idata.posterior["p"].values, chain[..., 1])
    np.testing.assert_array_equal(idata.sample_stats["lp"].values, lp)
    attrs = idata.posterior.attrs
    assert attrs["specimen"] == "s1" and attrs["n"] == 3 and attrs["heights"] == "[0.3, 0.5]"


def test_prior_sensitivity_tells_a_prior_that_decides_from_one_the_data_override():
    """Power-scaling sensitivity (arviz.psens) on a normal mean with a N(0, 1) prior: data ten times sharper
    than the prior leave the prior's sensitivity under 0.05 (Kallioinen et al.'s flag) and the likelihood's
    over it; data ten times vaguer, the reverse; a component constant over the draws changes nothing (0).
    The other direction of each: the prior and the likelihood swapped give the swapped numbers."""
    from bayesrod.inference.summary import prior_sensitivity

    rng = np.random.default_rng(1)
    n = 4000
    z = rng.standard_normal(n)
    got = {}
    for s_lik in (0.1, 10.0):
        prec = 1.0 + 1.0 / s_lik**2  # posterior precision with y = 0.5
        mu = 0.5 / s_lik**2 / prec + z / np.sqrt(prec)
        lp, ll = -0.5 * mu**2, -0.5 * ((0.5 - mu) / s_lik) ** 2
        got[s_lik] = prior_sensitivity({"mu": mu}, lp, ll)["mu"]
        swapped = prior_sensitivity({"mu": mu}, ll, lp)["mu"]
        assert swapped == pytest.approx({"prior": got[s_lik]["likelihood"], "likelihood": got[s_lik]["prior"]})
        flat = prior_sensitivity({"mu": mu}, np.zeros(n), ll)["mu"]
        assert flat["prior"] < 1e-4 and flat["likelihood"] == pytest.approx(got[s_lik]["likelihood"])
    assert got[0.1]["prior"] < 0.05 < got[0.1]["likelihood"], got
    assert got[10.0]["likelihood"] < 0.05 < got[10.0]["prior"], got
    with pytest.raises(ValueError, match="expected finite values at every draw"):
        prior_sensitivity({"mu": z}, np.where(z > 2, -np.inf, 0.0), -0.5 * z**2)


def test_import_arviz_tries_again_once_when_its_daily_stamp_races_another_process(monkeypatch):
    """ArviZ's import renames a daily stamp file; a second process doing the same at once can lose the rename
    (FileNotFoundError, an OSError): the import is tried once more, and any other failure is the user's."""
    import importlib

    from bayesrod.inference.summary import import_arviz

    calls = []

    def flaky(name):
        calls.append(name)
        if len(calls) == 1:
            raise FileNotFoundError("daily_warning.tmp -> daily_warning")
        return "the module"

    monkeypatch.setattr(importlib, "import_module", flaky)
    assert import_arviz() == "the module" and calls == ["arviz", "arviz"]

    def always(name):
        calls.append(name)
        raise FileNotFoundError("still racing")

    monkeypatch.setattr(importlib, "import_module", always)
    calls.clear()
    with pytest.raises(FileNotFoundError):
        import_arviz()
    assert calls == ["arviz", "arviz"]

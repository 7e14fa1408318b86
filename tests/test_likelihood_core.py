"""The force likelihood's own arithmetic against independent references: the noise models (with and without the
closed-form offset, and its conditional) against dense Gaussians, held-out restrictions, the fit error a summary
reports, the residuals' branches (a tabled effect, a yield, offsets, preloads, shapes without sds), the force
curves' bracket and ends, and what emcee sees (log_prob, its -inf cases and coordinates). Issue 21: no mutation
target held these lines before session 38 (docs/validation.md, "The force likelihood under mutmut")."""

import copy
import dataclasses

import numpy as np
import pytest
from scipy.stats import multivariate_normal, norm

import bayesrod
from bayesrod.dataset import read_dataset
from bayesrod.dataset.model import Diameters
from bayesrod.inference import likelihood
from bayesrod.inference.likelihood import (
    EffectAxis,
    ForceCurves,
    LogPosterior,
    RodLikelihood,
    ar1_loglik,
    default_length_prior,
    force_scale_fit,
    scale_estimate,
    scale_fit_rows,
)
from bayesrod.inference.priors import load_prior
from bayesrod.physics.elastica import contact_from_force_nd
from tests.test_noise import _ar1_cov
from tests.test_nuisances import HEIGHTS, _dataset, _geometry


@pytest.fixture(scope="module")
def demo():
    return read_dataset(bayesrod.DEMO_DATASET)


@pytest.fixture(scope="module")
def spring(demo):
    """The demo's forces with a base spring on a 5-node axis (EI0 1-5 N m^2)."""

    axis = EffectAxis.from_prior("base_compliance", load_prior("default").get("base_compliance"), (1.0, 5.0), 0.8, n=5)
    return RodLikelihood(demo, effects=("base_compliance",), use_shapes=False, effect_axis=axis)


def _params(lik, W=2):
    out = {"EI0": np.array([2.5, 2.8, 2.6])[:W], "p": np.array([0.41, 0.46, 0.44])[:W]}
    if lik.n_force:
        out["sigma_force_N"] = np.array([0.03, 0.07, 0.05])[:W]
    if lik.force_noise == "ar1":
        out["rho_force"] = np.array([0.6, -0.3, 0.9])[:W]
    if lik.n_points:
        out["shape_sd_scale" if lik.shape_has_sd else "sigma_shape_m"] = np.array([0.8, 1.3, 1.0])[:W]
    return out


def _force_residuals(lik, params):
    """F_obs - EI0 / L^2 f(d; p), from the force table alone."""
    return lik.F_obs[None, :] - params["EI0"][:, None] / lik.L**2 * lik.predict_nd_force(params["p"])


def _force_cov(lik, sigma, rho, offset_sd):
    """Dense covariance of the force noise: AR(1) (stationary, sd sigma) within each push's chain, independent
    between chains, plus offset_sd^2 shared by every sample."""
    chain = np.cumsum(lik.F_first)
    k = np.arange(lik.n_force)
    same = chain[:, None] == chain[None, :]
    lag = np.abs(k[:, None] - k[None, :])
    return np.where(same, sigma**2 * float(rho) ** lag, 0.0) + offset_sd**2


@pytest.mark.parametrize("noise", ["iid", "ar1"])
@pytest.mark.parametrize("offset_sd", [None, 0.05])
def test_force_term_is_the_dense_gaussian_of_its_noise_model(demo, noise, offset_sd):
    """iid or AR(1) noise, with or without a force offset integrated out under N(0, offset_sd^2): the likelihood
    equals scipy's multivariate normal of the residuals with that covariance. An iid likelihood given a
    correlation ignores it; the offset's conditional is the dense Gaussian conditional."""
    lik = RodLikelihood(demo, use_shapes=False, force_noise=noise)
    lik.offset_prior_sd = offset_sd
    params = _params(lik, W=3)  # three walkers: a term that broadcasts over two by accident fails
    r = _force_residuals(lik, params)
    np.testing.assert_allclose(lik.residuals(params)["force"], r, rtol=0, atol=1e-12)
    got = lik.log_likelihood(params)
    rhos = params.get("rho_force", np.zeros(3))
    for w in range(3):
        cov = _force_cov(lik, params["sigma_force_N"][w], rhos[w], offset_sd or 0.0)
        want = multivariate_normal(np.zeros(lik.n_force), cov).logpdf(r[w])
        assert got[w] == pytest.approx(want, rel=1e-9, abs=1e-7)
    if noise == "iid":  # a correlation handed to an iid likelihood is not read
        again = lik.log_likelihood({**params, "rho_force": np.full(3, 0.9)})
        np.testing.assert_allclose(again, got, rtol=1e-12)
    if offset_sd is None:
        with pytest.raises(ValueError, match="offset_prior_sd"):
            lik.offset_posterior(params)
        return
    mean, sd = lik.offset_posterior(params)
    for w in range(3):
        S = _force_cov(lik, params["sigma_force_N"][w], rhos[w], 0.0)
        one = np.ones(lik.n_force)
        K = S + offset_sd**2  # the marginal covariance of the residuals
        gain = offset_sd**2 * np.linalg.solve(K, one)  # Cov(c, r) K^-1
        assert mean[w] == pytest.approx(gain @ r[w], rel=1e-8)
        assert sd[w] == pytest.approx(np.sqrt(offset_sd**2 - offset_sd**2 * gain @ one), rel=1e-8)


def test_a_restricted_likelihood_is_the_density_of_the_samples_it_keeps(demo):
    """Held-out refits use ``restricted(mask)``: the AR(1) chains restart at each push's first kept sample, the
    slip term (data at the end of a push) is left out, and a mask of 0/1 integers is read as one of booleans."""
    lik = RodLikelihood(demo, use_shapes=False, force_noise="ar1", slip=True)
    assert lik.slip
    keep = np.ones(lik.n_force, bool)
    keep[np.flatnonzero(lik.F_first) + 2] = False  # a gap inside each push
    keep[np.flatnonzero(lik.F_first)] = False  # and each push's first sample: its chain starts at the second
    keep[: np.flatnonzero(lik.F_first)[1]] = False  # all of the first push
    sub = lik.restricted(keep)
    assert sub.n_force == keep.sum() and not sub.slip
    params = _params(lik)
    r = _force_residuals(lik, params)[:, keep]
    push = lik.F_push[keep]
    for w in range(2):
        s, rho = params["sigma_force_N"][w], params["rho_force"][w]
        want = 0.0
        for j in np.unique(push):  # a chain per push: consecutive kept samples are neighbours in it
            x = r[w, push == j]
            want += multivariate_normal(np.zeros(x.size), _ar1_cov(x.size, s, rho)).logpdf(x)
        assert sub.log_likelihood(params)[w] == pytest.approx(want, rel=1e-9)
    as_ints = lik.restricted(list(keep.astype(int)))
    np.testing.assert_allclose(as_ints.log_likelihood(params), sub.log_likelihood(params))
    with pytest.raises(ValueError, match=rf"mask: expected shape \({lik.n_force},\), got \(3,\)"):
        lik.restricted(np.ones(3, bool))


def test_fit_error_is_the_rms_of_each_residual_in_the_unit_it_names(demo):
    """summary.json's fit_error: force RMS [N] over the engaged samples, centerline RMS [mm], width RMS [mm]; the
    terms a likelihood does not hold are None."""
    lik = RodLikelihood(demo)
    params = _params(lik, W=1)
    point = {k: float(v[0]) for k, v in params.items()}
    got = lik.fit_error(point)
    r = _force_residuals(lik, params)[0]
    assert got["force_rmse_N"] == pytest.approx(np.sqrt(np.mean(r**2)), rel=1e-12)
    shape = lik.shape_offsets(params["p"])[0]
    assert got["shape_rmse_mm"] == pytest.approx(1000 * np.sqrt(np.mean(shape**2)), rel=1e-12)
    assert "diameter_rmse_mm" not in got
    forces = RodLikelihood(demo, use_shapes=False).fit_error(point)
    assert forces["shape_rmse_mm"] is None and forces["force_rmse_N"] == pytest.approx(got["force_rmse_N"])
    shapes = RodLikelihood(demo, use_forces=False).fit_error(point)
    assert shapes["force_rmse_N"] is None and shapes["shape_rmse_mm"] == pytest.approx(got["shape_rmse_mm"])
    # widths: d(s) = d0 (1 - s/L)^p_geom against the measured profile

    s = np.linspace(0.0, 0.6, 7)
    d = 0.01 * (1 - s / demo.length_m) ** 0.4 * (1 + 0.03 * np.sin(7 * s))
    wide = RodLikelihood(
        dataclasses.replace(demo, diameters=Diameters(s, d, np.full(7, 2e-4), "caliper")),
        use_shapes=False,
        diameter="free",
    )
    point = {**point, "d0_m": 0.0102, "p_geom": 0.37}
    want = d - 0.0102 * (1 - s / demo.length_m) ** 0.37
    assert wide.fit_error(point)["diameter_rmse_mm"] == pytest.approx(1000 * np.sqrt(np.mean(want**2)), rel=1e-9)


def test_log_prob_is_prior_plus_likelihood_and_minus_inf_wherever_either_fails(demo):
    """What emcee sees: log prior + log likelihood, a float for one walker and the same numbers for a batch;
    -inf (never +inf or nan) for a taper outside the tables, a non-finite coordinate, a noise sd of zero."""

    lik = RodLikelihood(demo, use_shapes=False)
    post = LogPosterior(lik, load_prior("default"))
    assert post._p_bounds == (0.0, 3.0)
    theta = post.to_sample(
        {"EI0": np.array([2.6, 2.6]), "p": np.array([0.43, 0.5]), "sigma_force_N": np.array([0.05, 0.1])}
    )
    nat = post.to_natural(theta)
    want = post.log_prior(theta) + lik.log_likelihood(nat)
    batch = post.log_prob(theta)
    np.testing.assert_allclose(batch, want, rtol=1e-12)
    one = post.log_prob(theta[1])
    assert isinstance(one, float) and one == pytest.approx(want[1], rel=1e-12)
    bad = np.repeat(theta[:1], 6, axis=0)
    bad[0, 1] = 3.0  # the tables' last node: inside
    bad[1, 1] = 3.0 + 1e-9  # past it
    bad[2, 1] = -1e-9  # below the first
    bad[3, 2] = np.nan  # a walker the sampler broke
    bad[4, 2] = -800.0  # sigma = exp(-800) = 0: the Gaussian is not a density there
    with np.errstate(divide="ignore", invalid="ignore"):
        got = post.log_prob(bad)
    assert np.isfinite(got[0]) and np.isfinite(got[5])
    assert got[5] == pytest.approx(batch[0], rel=1e-12)  # the others' failures do not reach it
    assert np.all(got[1:5] == -np.inf), got


def test_the_posterior_takes_each_nuisance_prior_from_its_likelihood_and_refuses_a_p_prior_past_the_tables(demo):

    prior = load_prior("default")
    lik = RodLikelihood(demo, use_shapes=False, force_offsets=True)
    post = LogPosterior(lik, prior)
    for n in lik.offset_names:  # N(0, 5% of the push's peak force), not a prior file's entry
        assert post.priors[post.names.index(n)] is lik.nuisance_priors[n]
    assert post.priors[0] is prior.get("EI0")
    for p_range in [(0.5, 3.0), (0.0, 2.5)]:  # the prior's p covers [0, 3]
        narrow = RodLikelihood(demo, p_range=p_range, use_shapes=False)
        with pytest.raises(
            ValueError, match=r"prior p: expected support within the table range \[.*\], got \[0.0, 3.0\]"
        ):
            LogPosterior(narrow, prior)


@pytest.fixture(scope="module")
def clean_twig():
    return bayesrod.simulate("twig", seed=1, noise="none")  # EI0 2.63 N m^2, p 0.43, L 0.8 m, three heights


def test_the_least_squares_scale_of_noise_free_forces_is_the_true_ei0(clean_twig):
    """EI0 is a pure scale of the forces (F = EI0 / L^2 f(d / L; p, h / L)): at the true p the closed-form
    least squares gives the simulated EI0 and a residual at the tables' error; the effect axes and the
    sampler's start use it."""

    lik = RodLikelihood(clean_twig, use_shapes=False)
    peak = np.max(np.abs(lik.F_obs))
    EI0, rms = force_scale_fit(lik, 0.43)
    assert EI0 == pytest.approx(2.63, rel=2e-4) and rms < 1e-4 * peak
    off, rms_off = force_scale_fit(lik, 0.43, EI0=2.0)  # given EI0: only its residual
    assert off == 2.0 and rms_off == pytest.approx(np.sqrt(np.mean((lik.F_obs * (1 - 2.0 / 2.63)) ** 2)), rel=2e-3)
    assert scale_estimate(lik) == pytest.approx(2.63, rel=0.05)  # at the best node of the p grid (0.05 apart)
    assert scale_estimate(RodLikelihood(clean_twig, use_forces=False)) is None


def test_a_preload_moves_each_push_along_its_own_force_curve(clean_twig):
    """The preloaded force table (linear in d between PRELOAD_GRID nodes) at preload P equals the force curve
    read at d + P, push by push; at P = 0 it is the plain table."""

    lik = RodLikelihood(clean_twig, use_shapes=False, preload=True)
    p = np.array([0.38, 0.5])
    pre = np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.012]])  # walker 2: the first and last push preloaded
    got = lik.predict_nd_force_preloaded(p, pre)
    np.testing.assert_allclose(got[0], lik.predict_nd_force(p[:1])[0], atol=2e-4 * np.max(got[0]))
    for j, d in enumerate(lik.force_data):
        (c,) = ForceCurves.batch(np.array([d.height_m / lik.L]), p[1:])
        want = c.force((d.D_m + pre[1, j]) / lik.L)[0]
        np.testing.assert_allclose(got[1, lik.F_push == j], want, atol=2e-4 * np.max(want))


def test_a_likelihood_without_its_effect_axis_is_the_plain_rods(demo, spring):
    """The u = 0 slice of an effect's tables is the plain rod (the neutral value of every tabled effect): the
    group's sharing check compares against it."""
    lik, axis = spring, spring.axis
    plain = RodLikelihood(demo, use_shapes=False)
    cut = lik.without_effect_axis()
    assert cut.axis is None and cut.effects == () and lik.axis is axis  # the original keeps its axis
    params = _params(plain)
    np.testing.assert_allclose(cut.log_likelihood(params), plain.log_likelihood(params), rtol=1e-9)
    np.testing.assert_allclose(cut.predict_nd_force(params["p"]), plain.predict_nd_force(params["p"]), atol=1e-9)
    # without a coordinate the effect sits at its neutral value
    np.testing.assert_allclose(lik.predict_nd_force(params["p"]), plain.predict_nd_force(params["p"]), atol=1e-9)

    shifted = copy.copy(lik)  # the same tables on an axis that does not start at the neutral value
    shifted.axis = dataclasses.replace(axis, grid=axis.grid + 0.01)
    with pytest.raises(
        ValueError, match="effect base_compliance: expected a table axis starting at the neutral value 0"
    ):
        shifted.without_effect_axis()


def test_the_posterior_chooses_its_sampling_coordinates_by_the_data(demo, spring):
    """The same posterior, sampled in coordinates that suit the data (docs/inference.md, "Sampling"): a base spring
    by its table coordinate u on forces alone (log k with centerlines); EI0 as the log stiffness at the height when
    every push is at one height on a known length."""

    prior = load_prior("default")
    post = LogPosterior(spring, prior)
    assert post.base_length_m == spring.L == 0.8 and post.stiffness_at is None  # three heights
    with_shapes = copy.copy(spring)
    with_shapes.n_points = 40
    assert LogPosterior(with_shapes, prior).base_length_m is None
    assert LogPosterior(RodLikelihood(demo, use_shapes=False), prior).base_length_m is None  # no spring
    one = RodLikelihood(bayesrod.simulate("twig", seed=4, heights_m=[0.5]), use_shapes=False)
    assert LogPosterior(one, prior).stiffness_at == (0.5, 0.8)
    unknown = copy.copy(one)  # the same pushes with the length sampled
    unknown.names = [*one.names, "length_m"]
    unknown.nuisance_priors = {"length_m": prior.get("p")}  # any prior: only the name is read here
    assert LogPosterior(unknown, prior).stiffness_at is None


def test_scale_fit_rows_are_least_squares_and_nan_where_a_row_predicts_no_force():

    rng = np.random.default_rng(0)
    g = np.vstack([0.02 * rng.random(30), np.zeros(30), 3.0 * rng.random(30)])  # a row of small predictions
    F = 0.05 * g[0] + rng.normal(0, 1e-4, 30)
    EI0, rms = scale_fit_rows(g, F)
    assert EI0[0] == pytest.approx(np.linalg.lstsq(g[0][:, None], F, rcond=None)[0][0], rel=1e-12)
    assert np.isnan(EI0[1]) and np.isfinite(EI0[2])
    assert rms[0] == pytest.approx(np.sqrt(np.mean((F - EI0[0] * g[0]) ** 2)), rel=1e-12)


def test_in_table_is_true_exactly_on_the_effect_axis(spring):
    """Walkers whose spring lies past the table's last node get zero density (docs/inference.md); the nodes'
    neighbourhoods at both ends are inside."""
    grid, L = spring.axis.grid, spring.L
    EI0 = np.full(5, 2.6)
    u = np.array([0.5 * (grid[0] + grid[1]), 0.5 * (grid[-2] + grid[-1]), grid[-1] - 1e-9, grid[-1] + 1e-6, 0.5])
    c = u / (1 - u)  # u = c / (1 + c), c = EI0 / (k L)
    params = {"EI0": EI0, "p": np.full(5, 0.43), "base_compliance": EI0 / (c * L)}
    np.testing.assert_allclose(spring.effect_coordinate(params), u, rtol=1e-9)
    np.testing.assert_array_equal(spring.in_table(params), [True, True, True, False, grid[-1] >= 0.5])
    # the table's first node, u = 0 (an infinitely stiff spring: the clamp), is inside too
    clamp = {"EI0": np.array([2.6]), "p": np.array([0.43]), "base_compliance": np.array([np.inf])}
    assert grid[0] == 0.0 and spring.effect_coordinate(clamp)[0] == 0.0 and spring.in_table(clamp).all()


def test_shapes_without_point_sds_have_one_noise_sd_in_metres(demo):
    """Centerlines whose points carry no sd: one sigma_shape_m for all, the plain Gaussian density."""

    pushes = [dataclasses.replace(p, shapes=[dataclasses.replace(f, sd_m=None) for f in p.shapes]) for p in demo.pushes]
    lik = RodLikelihood(dataclasses.replace(demo, pushes=pushes), use_forces=False)
    assert not lik.shape_has_sd and lik.names == ["EI0", "p", "sigma_shape_m"]
    params = {"EI0": np.array([2.6, 2.6]), "p": np.array([0.41, 0.47]), "sigma_shape_m": np.array([4e-4, 1e-3])}
    r = lik.shape_offsets(params["p"])
    want = norm.logpdf(r, 0.0, params["sigma_shape_m"][:, None]).sum(axis=1)
    np.testing.assert_allclose(lik.log_likelihood(params), lik.shape_weight * want, rtol=1e-12)


def test_the_force_table_reads_the_effect_at_its_nodes(spring):
    """At a node of p and of the effect axis the interpolation is exact: the residuals are the data minus the rod on
    that spring, solved directly."""

    grid, L = spring.axis.grid, spring.L
    p = spring.p_grid[9]  # 0.45
    u = grid[2]
    c = u / (1 - u)
    params = {"EI0": np.array([2.6]), "p": np.array([p]), "base_compliance": np.array([2.6 / (c * L)])}
    got = spring.residuals(params)["force"][0]
    for j, d in enumerate(spring.force_data):
        (curve,) = ForceCurves.batch(
            np.array([d.height_m / L]), np.array([p]), effects_nd=spring.axis.nondim(np.array([u]))
        )
        want = d.F_N - 2.6 / L**2 * curve.force(d.D_m / L)[0]
        np.testing.assert_allclose(got[spring.F_push == j], want, rtol=0, atol=1e-9 * np.max(np.abs(d.F_N)))


def test_the_spring_posteriors_density_carries_the_jacobian_of_u_and_is_zero_past_the_table(spring):
    """Sampled by u = c / (1 + c) (c = EI0 / (k L)), the prior density gains log |d log k / du| = -log u - log(1 - u);
    a walker with u outside (0, 1), or inside it but past the table's last node, has density zero."""

    post = LogPosterior(spring, load_prior("default"))
    i = post.names.index("base_compliance")
    theta = post.to_sample(
        {
            "EI0": np.array([2.6]),
            "p": np.array([0.43]),
            "sigma_force_N": np.array([0.05]),
            "base_compliance": np.array([3.0]),
        }
    )[0]
    u = theta[i]
    assert 0.0 < u < spring.axis.grid[-1]
    coords = post.prior_coordinates(theta[None])[0]
    want = (
        sum(pr.logpdf_sample(np.array([coords[k]]))[0] for k, pr in enumerate(post.priors)) - np.log(u) - np.log1p(-u)
    )
    assert post.log_prior(theta[None])[0] == pytest.approx(want, rel=1e-12)
    bad = np.repeat(theta[None], 3, axis=0)
    bad[0, i] = 1.2  # not a u
    bad[1, i] = 0.5 * (spring.axis.grid[-1] + 1.0)  # a u, past the table
    assert post.log_prior(bad)[0] == -np.inf
    got = post.log_prob(bad)
    assert got[0] == -np.inf and got[1] == -np.inf and np.isfinite(got[2])


def test_ar1_forces_and_the_slip_term_add(demo):

    lik = RodLikelihood(demo, use_shapes=False, force_noise="ar1", slip=True)
    params = _params(lik)
    s = params["sigma_force_N"][:, None]
    force = ar1_loglik(_force_residuals(lik, params), s, params["rho_force"][:, None], lik.F_first)
    np.testing.assert_allclose(lik.log_likelihood(params), force + lik.slip_loglik(params["p"], None), rtol=1e-12)


def test_a_yield_caps_the_force_at_the_yield_moment_over_the_contact_height_and_an_offset_adds(coarse_length_axis):
    """F = min(EI0 / L^2 f, M_y / h) plus a load-cell offset; with height errors h is the walker's own h + dh."""

    spec = _dataset(0.8)
    grid = {"p_range": (0.0, 1.2), "n_p": 13, "use_shapes": False}
    plain = RodLikelihood(spec, effects=("yield", "force_offset"), **grid)
    params = {"EI0": np.array([2.63, 2.4]), "p": np.array([0.43, 0.5]), "sigma_force_N": np.array([0.01, 0.01])}
    F = params["EI0"][:, None] / 0.8**2 * plain.predict_nd_force(params["p"])
    h = np.asarray(HEIGHTS)[plain.F_push]
    My = np.array([0.9 * np.max(F[0] * h), 1e3])  # the first walker yields, the second does not
    got = plain.residuals({**params, "yield": My, "force_offset": np.array([0.02, -0.03])})["force"]
    want = plain.F_obs - (np.minimum(F, My[:, None] / h) + np.array([[0.02], [-0.03]]))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.any(np.minimum(F, My[:, None] / h)[0] < F[0])
    geo = RodLikelihood(spec, effects=("yield",), length_prior=default_length_prior(spec), height_sd_m=0.003, **grid)
    dh = {n: np.array([e, e]) for n, e in zip(geo.height_names, (0.004, -0.006), strict=True)}
    at = {**params, "length_m": np.array([0.8, 0.85]), **dh}
    F = geo.F_obs - geo.residuals(at)["force"]
    h = (np.asarray(HEIGHTS) + np.array([0.004, -0.006]))[geo.F_push]
    got = geo.residuals({**at, "yield": My})["force"]
    np.testing.assert_allclose(got, geo.F_obs - np.minimum(F, My[:, None] / h), rtol=0, atol=1e-12)


def test_force_curves_find_a_branch_end_above_their_first_guess(monkeypatch):
    """The branch end is bracketed by doubling from 2 / eta^2 until contact is lost, then bisected: on a stand-in rod
    whose contact exists up to f = 37 / eta^2 (above the first guess) with displacement d = f, the curve ends there."""

    def fake(f, etas, p, eff):
        f = np.asarray(f, float)
        end = 37.0 / np.asarray(etas, float) ** 2 * (1.0 + 0.1 * np.asarray(p, float))
        return {"found": f <= end, "yielded": np.zeros(f.shape, bool), "xi_c": np.where(f <= end, f, np.nan)}

    monkeypatch.setattr(likelihood, "contact_from_force_nd", fake)
    monkeypatch.setattr(likelihood, "_CURVE_CACHE", {})
    eta, p = 0.6, np.array([0.0, 2.0])
    (c,) = likelihood.ForceCurves.batch(np.array([eta]), p, n_f=20)
    np.testing.assert_allclose(c.d_end, 37.0 / eta**2 * (1.0 + 0.1 * p), rtol=1e-12)
    np.testing.assert_allclose(c.force(np.array([1.0, 50.0]))[:, 0], 1.0, rtol=1e-9)  # f = d on the branch

    def never(f, etas, p, eff):  # p = 2 never touches the probe (a stem curled away from it)
        out = fake(f, etas, p, eff)
        out["found"] = out["found"] & (np.asarray(p) < 1.0)
        return out

    monkeypatch.setattr(likelihood, "contact_from_force_nd", never)
    monkeypatch.setattr(likelihood, "_CURVE_CACHE", {})
    (c,) = likelihood.ForceCurves.batch(np.array([eta]), p, n_f=20)
    assert c.d_end[1] == 0.0 and c.end_slope[1] == 0.0
    np.testing.assert_array_equal(c.force(np.array([0.0, 1.0, 5.0]))[1], 0.0)  # no contact: no force


def test_friction_force_curves_end_where_the_contact_leaves_the_tip_at_every_taper(monkeypatch):
    """eta 0.5625, mu 0.424 (a node of the friction table), p 0.35-0.5: each branch ends where the contact leaves
    the tip, 0.75-0.77 L, smoothly over p. Before session 46 the moment search read stems held near the tip as
    slipped in isolated holes, the branch-end search stopped at one and p 0.4 ended at 0.328 L; past an end the
    table goes on along the end tangent, and that node moved a friction fit's MLE by -18.5 sd in mu."""
    monkeypatch.setattr(likelihood, "_CURVE_CACHE", {})
    (c,) = ForceCurves.batch(
        np.array([0.5625]), np.array([0.35, 0.40, 0.45, 0.50]), n_f=25, effects_nd={"mu": 0.42409332}
    )
    assert np.all((c.d_end > 0.74) & (c.d_end < 0.78)), c.d_end
    assert np.max(np.abs(np.diff(c.d_end))) < 0.02, c.d_end


def test_force_levels_cluster_at_the_end_and_go_down_a_plateau():
    """n_f levels 1 - (1 - u)^2, then PLATEAU_LEVELS more evenly in log10(1 - f/f_end) down to 1e-13, then the end."""
    n = 160
    levels = likelihood.force_levels(n)
    u = np.linspace(0.0, 1.0, n)
    assert levels.size == n + likelihood.PLATEAU_LEVELS == n + 24 and levels[0] == 0.0 and levels[-1] == 1.0
    np.testing.assert_allclose(levels[: n - 1], 1.0 - (1.0 - u[:-1]) ** 2, rtol=0, atol=1e-15)
    tail = -np.log10(1.0 - levels[n - 2 : -1])  # the last clustered level, then the plateau's
    np.testing.assert_allclose(np.diff(tail), (13.0 - tail[0]) / 24, rtol=1e-3)  # 1 - f rounds near 1e-13
    assert tail[-1] == pytest.approx(13.0, abs=1e-3) and np.all(np.diff(levels) > 0)


@pytest.mark.parametrize(
    ("eta", "p", "rel"),
    [(0.41221, 0.95, 1.5e-6), (0.5, 1.2, 1.5e-6), (0.5, 0.43, 5e-7)],
)
def test_a_force_curve_reads_exact_solves_to_its_end_also_on_a_plateau(monkeypatch, eta, p, rel):
    """A tabled curve against exact solves at 198 displacements up to its branch end. At p 0.95 (SBC seed 108)
    the force nears its end exponentially slowly: it is within 1e-5 of the end's 0.14 L before it. Measured
    (largest error over the peak force; session 72): with the clustered levels alone 1.9e-5 (the last
    interval held 0.16 L; the tables moved seed 108's p by 1.1 sd), with the plateau's levels and PCHIP 3.8e-6,
    with the cubic spline 4.4e-7; at p 0.43 2.8e-6 with PCHIP, 7.9e-8 with the spline."""
    from bayesrod.physics import force_from_displacement_nd

    monkeypatch.setattr(likelihood, "_CURVE_CACHE", {})
    (c,) = ForceCurves.batch(np.array([eta]), np.array([p - 0.05, p, p + 0.05, p + 0.1]))
    d = np.linspace(0.0, c.d_end[1], 200)[1:-1]
    exact = force_from_displacement_nd(d, np.full(d.size, eta), p, None)["f"]
    ok = np.isfinite(exact)
    assert ok.sum() > 180
    err = np.max(np.abs(c.force(d)[1] - exact)[ok]) / np.max(exact[ok])
    assert err < rel, err


def test_force_levels_closer_than_the_gap_are_dropped_but_the_end_is_kept():
    """_spaced keeps levels at least MIN_LEVEL_GAP (1e-4 L) apart, and the last (the branch end) always, dropping
    its predecessor where the two crowd. Measured (session 72, friction mu 0.5, h/L 0.5, p 0.43): through every
    level the table's force lay up to 4.6e-5 of the peak off exact solves near the end, through levels 1e-4 L
    apart 1.6e-6."""
    d = np.array([0.0, 0.1, 0.2, 0.20005, 0.3, 0.30002, 0.30004, 0.5])
    np.testing.assert_array_equal(likelihood._spaced(d, np.arange(7)), [0, 1, 2, 6])
    np.testing.assert_array_equal(likelihood._spaced(d, np.array([0, 3, 4, 7])), [0, 3, 4, 7])
    np.testing.assert_array_equal(likelihood._spaced(d, np.array([4, 5])), [4, 5])  # two levels: both kept
    # three levels, the last crowding the second: the second goes, the first and the end stay
    np.testing.assert_array_equal(likelihood._spaced(d, np.array([1, 2, 3])), [1, 3])


def test_the_end_slope_is_the_quadratic_through_the_levels_near_the_end_or_the_spline_with_fewer_than_five():
    """_end_slope fits a quadratic to the levels within END_FIT_WIDTH (0.01 L) of the branch end where there are
    five or more (a friction curve's levels crowd there), else takes the spline's slope. On a cubic the two differ
    (the spline through points of a cubic is exact), so each rule shows."""
    from scipy.interpolate import CubicSpline

    far = np.array([0.9, 0.95, 0.97])
    for n_near, quadratic in ((5, True), (6, True), (4, False)):
        d = np.concatenate([far, np.linspace(0.9925, 1.0, n_near)])
        f = d**3
        slope = likelihood._end_slope(d, f, 1.0, CubicSpline(d, f))
        if quadratic:
            near = d[-n_near:] - 1.0
            expected = np.polyfit(near, f[-n_near:], 2)[1]
            assert abs(expected - 3.0) > 1e-6  # the two rules differ here
            assert slope == pytest.approx(expected, rel=1e-12), (n_near, slope)
        else:
            assert slope == pytest.approx(3.0, rel=1e-9), (n_near, slope)


def test_friction_end_slopes_are_smooth_in_p(monkeypatch):
    """With friction the branch ends with the force still rising, and past its end the table goes on along that
    slope: it must be smooth in p (interpolated over p nodes). Near the end a friction solve's displacement
    scatters by about 1e-6; measured (eta 0.45, mu 0.3, p 0.5-0.8; session 72): the spline's own slope at the
    end read 58, 0, 30, 0 through every level and 96, 71, 104, 63 through levels 1e-4 L apart; the quadratic
    over the last 0.01 L 98.6, 84.2, 71.3, 61.4 (PCHIP before session 72: 78, 64, 64, 39)."""
    monkeypatch.setattr(likelihood, "_CURVE_CACHE", {})
    (c,) = ForceCurves.batch(np.array([0.45]), np.array([0.5, 0.6, 0.7, 0.8]), effects_nd={"mu": 0.3})
    slope = c.end_slope
    assert np.all((slope > 40) & (slope < 130)) and np.all(np.diff(slope) < 0), slope
    assert np.max(np.abs(np.diff(slope, 2))) < 5.0, slope


def test_force_curves_count_displacement_from_the_unloaded_stem():
    """With a rest curvature the unloaded stem already leans: the curve's displacement is the contact's travel from
    where the unloaded stem meets the probe's height, f(xi(f) - xi(0)) = f, and the same curves serve the shapes."""

    eta, p = 0.6, np.array([0.4])
    c, other = ForceCurves.batch(np.array([eta, 0.5]), p, n_f=60, effects_nd={"kappa0": np.array([0.3, 0.1])})
    # what the shape tables solve with: each height's own value, as a float
    assert c.effects_nd == {"kappa0": 0.3} and other.effects_nd == {"kappa0": 0.1}
    f = np.array([0.0, 0.3, 0.6, 0.9]) * c.force(c.d_end)[0, 0]  # up to 90% of the branch end's force
    r = contact_from_force_nd(f, eta, np.full(4, 0.4), {"kappa0": 0.3})
    assert abs(r["xi_c"][0]) > 0.01  # the offset matters
    np.testing.assert_allclose(c.force(r["xi_c"] - r["xi_c"][0])[0], f, atol=1e-3 * f[-1])


def test_past_its_branch_end_a_curve_goes_on_along_its_end_tangent_by_default():
    """Contact friction ends the branch with the force still rising: by default the tables continue along that
    slope (a flat hold would put a kink into the tables in p); ``continued=False`` holds the end value."""

    (c,) = ForceCurves.batch(np.array([0.6]), np.array([0.4]), n_f=60, effects_nd={"mu": np.array([0.3])})
    assert c.end_slope[0] > 1.0
    d = c.d_end[0] + np.array([0.0, 0.01, 0.03])
    end = c.force(c.d_end)[0, 0]
    np.testing.assert_allclose(c.force(d)[0], end + c.end_slope[0] * (d - c.d_end[0]), rtol=1e-12)
    np.testing.assert_allclose(c.force(d, continued=False)[0], end, rtol=1e-12)


def test_contact_height_errors_on_a_known_length_move_only_the_heights():
    """A fit with contact-height errors and the length given (``height_sd_m`` without a length prior): the
    residuals are those of the plain rod with each push's height moved by its error, the stem length the given
    one."""

    spec = _dataset(0.8)
    grid = {"p_range": (0.0, 1.2), "n_p": 13, "use_shapes": False}
    lik = RodLikelihood(spec, height_sd_m=0.003, **grid)
    assert "length_m" not in lik.names and len(lik.height_names) == 2
    dh = (0.0041, -0.0072)
    params = {"EI0": np.full(2, 2.63), "p": np.array([0.43, 0.6]), "sigma_force_N": np.full(2, 0.01)}
    got = lik.residuals({**params, **{n: np.full(2, e) for n, e in zip(lik.height_names, dh, strict=True)}})["force"]
    ref = RodLikelihood(_geometry(spec, 0.8, dh), **grid).residuals(params)["force"]
    assert np.max(np.abs(got - ref)) < 1e-4 * np.max(np.abs(lik.F_obs))

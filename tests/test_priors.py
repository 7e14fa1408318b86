"""Prior densities, draws and quantiles against scipy.stats, in the sampling space emcee sees.

Fast unit tests: scripts/mutation.py mutates bayesrod/inference/priors.py against this file."""

import math

import numpy as np
import pytest
from scipy import stats

from bayesrod.inference.priors import ParameterSpace, ParamPrior

CASES = [
    ("lognormal", (2.5, 0.7), stats.lognorm(0.7, scale=2.5)),
    ("halfnormal", (0.3,), stats.halfnorm(scale=0.3)),
    ("normal", (0.4, 0.15), stats.norm(0.4, 0.15)),
    ("truncnormal", (0.5, 0.8, 0.0, 3.0), stats.truncnorm((0.0 - 0.5) / 0.8, (3.0 - 0.5) / 0.8, loc=0.5, scale=0.8)),
    ("uniform", (0.2, 1.4), stats.uniform(0.2, 1.2)),
]


@pytest.mark.parametrize("dist, args, ref", CASES, ids=[c[0] for c in CASES])
def test_density_in_the_sampling_space_is_the_natural_density_times_the_jacobian(dist, args, ref):
    pr = ParamPrior("x", dist, args)
    x = np.linspace(*ref.ppf([0.01, 0.99]), 9)
    u = pr.to_sample(x)
    np.testing.assert_allclose(pr.from_sample(u), x, rtol=1e-14)
    want = ref.logpdf(x) + (np.log(x) if pr.log_space else 0.0)  # p(u) = p(x) |dx/du|, x = e^u in log space
    np.testing.assert_allclose(pr.logpdf_sample(u), want, rtol=1e-12, atol=1e-12)
    assert pr.log_space == (dist in ("lognormal", "halfnormal"))


@pytest.mark.parametrize("dist, args, ref", CASES, ids=[c[0] for c in CASES])
def test_draws_and_quantiles_follow_the_distribution(dist, args, ref):
    pr = ParamPrior("x", dist, args)
    for q in (0.05, 0.5, 0.9):
        assert pr.quantile(q) == pytest.approx(ref.ppf(q), rel=1e-12)
    x = pr.draw(np.random.default_rng(4), 20_000)
    assert stats.kstest(x, ref.cdf).pvalue > 0.01
    lo, hi = pr.bounds()
    assert np.all((x >= lo) & (x <= hi))
    assert (lo, hi) == pytest.approx(tuple(ref.support()))


@pytest.mark.parametrize("dist, args", [("truncnormal", (0.5, 0.8, 0.0, 3.0)), ("uniform", (0.2, 1.4))])
def test_outside_a_bounded_support_the_density_is_zero_and_at_the_edge_it_is_not(dist, args):
    pr = ParamPrior("x", dist, args)
    lo, hi = pr.bounds()
    dens = pr.logpdf_sample(np.array([lo - 1e-9, lo, hi, hi + 1e-9]))
    assert np.isneginf(dens[0]) and np.isneginf(dens[3]) and np.all(np.isfinite(dens[1:3]))


def test_parameter_space_maps_every_parameter_with_its_own_transform():
    space = ParameterSpace()
    space.names = ["EI0", "p"]
    space.priors = [ParamPrior("EI0", "lognormal", (2.0, 1.0)), ParamPrior("p", "normal", (0.4, 0.2))]
    assert space.ndim == 2
    nat = {"EI0": np.array([1.0, math.e]), "p": np.array([0.3, 0.5])}
    theta = space.to_sample(nat)
    np.testing.assert_allclose(theta, [[0.0, 0.3], [1.0, 0.5]], atol=1e-15)
    back = space.to_natural(theta)
    np.testing.assert_allclose(back["EI0"], nat["EI0"])
    np.testing.assert_allclose(back["p"], nat["p"])
    one = space.to_natural(np.array([0.0, 0.2]))  # a single point is a batch of one
    assert one["EI0"].shape == (1,) and one["p"][0] == 0.2

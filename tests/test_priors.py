"""Prior densities, draws and quantiles against scipy.stats, in the sampling space emcee sees.

Fast unit tests: scripts/mutation.py mutates bayesrod/inference/priors.py against this file."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from bayesrod.inference.priors import ParameterSpace, ParamPrior


class _TruncArcsine:
    """scipy's arcsine law on [-1, 1] (density 1 / (pi sqrt(1 - x^2))), truncated to [lo, hi]."""

    def __init__(self, lo, hi):
        self.ref, self.lo, self.hi = stats.arcsine(loc=-1.0, scale=2.0), lo, hi
        self.mass = self.ref.cdf(hi) - self.ref.cdf(lo)

    def logpdf(self, x):
        return self.ref.logpdf(x) - np.log(self.mass)

    def cdf(self, x):
        return np.clip((self.ref.cdf(x) - self.ref.cdf(self.lo)) / self.mass, 0.0, 1.0)

    def ppf(self, q):
        return self.ref.ppf(self.ref.cdf(self.lo) + np.asarray(q) * self.mass)

    def support(self):
        return self.lo, self.hi


class _ClampOrUniform:
    """Half the mass uniform on the clamp [-width, 0], half uniform in u = scale z on (0, u_max]: an equal
    mixture of two scipy uniforms in z (fit-group's base coordinate, bayesrod.inference.group)."""

    def __init__(self, width, scale, u_max):
        self.clamp, self.soft = stats.uniform(-width, width), stats.uniform(0.0, u_max / scale)
        self.lo, self.hi = -width, u_max / scale

    def logpdf(self, x):
        x = np.asarray(x, float)
        return np.log(0.5 * np.where(x <= 0, self.clamp.pdf(x), self.soft.pdf(x)))

    def cdf(self, x):
        return 0.5 * self.clamp.cdf(x) + 0.5 * self.soft.cdf(x)

    def ppf(self, q):
        q = np.asarray(q, float)
        return np.where(q <= 0.5, self.clamp.ppf(np.minimum(2 * q, 1.0)), self.soft.ppf(np.maximum(2 * q - 1, 0.0)))

    def support(self):
        return self.lo, self.hi


CASES = [
    ("lognormal", (2.5, 0.7), stats.lognorm(0.7, scale=2.5)),
    ("halfnormal", (0.3,), stats.halfnorm(scale=0.3)),
    ("normal", (0.4, 0.15), stats.norm(0.4, 0.15)),
    ("truncnormal", (0.5, 0.8, 0.0, 3.0), stats.truncnorm((0.0 - 0.5) / 0.8, (3.0 - 0.5) / 0.8, loc=0.5, scale=0.8)),
    ("uniform", (0.2, 1.4), stats.uniform(0.2, 1.2)),
    ("arcsine", (-0.5, 0.995), _TruncArcsine(-0.5, 0.995)),
    ("clamp_or_uniform", (2.0, 0.01, 0.5), _ClampOrUniform(2.0, 0.01, 0.5)),
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
    for q in (0.05, 0.3, 0.5, 0.9):
        assert pr.quantile(q) == pytest.approx(ref.ppf(q), rel=1e-12)
    x = pr.draw(np.random.default_rng(4), 20_000)
    assert x.shape == (20_000,) and stats.kstest(x, ref.cdf).pvalue > 0.01
    # the generator given is the one used: the same seed gives the same draws (studies are reproducible)
    np.testing.assert_array_equal(pr.draw(np.random.default_rng(9), 5), pr.draw(np.random.default_rng(9), 5))
    z = np.random.default_rng(9).standard_normal(5)  # and the draws are the documented transform of it
    if dist == "lognormal":
        np.testing.assert_allclose(pr.draw(np.random.default_rng(9), 5), args[0] * np.exp(args[1] * z))
    if dist == "normal":
        np.testing.assert_allclose(pr.draw(np.random.default_rng(9), 5), args[0] + args[1] * z)
    assert not np.array_equal(pr.draw(np.random.default_rng(9), 5), pr.draw(np.random.default_rng(10), 5))
    lo, hi = pr.bounds()
    assert np.all((x >= lo) & (x <= hi))
    assert (lo, hi) == pytest.approx(tuple(ref.support()))


@pytest.mark.parametrize(
    "dist, args",
    [
        ("truncnormal", (0.5, 0.8, 0.0, 3.0)),
        ("uniform", (0.2, 1.4)),
        ("arcsine", (-0.5, 0.995)),
        ("clamp_or_uniform", (2.0, 0.01, 0.5)),
    ],
)
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


GOOD = {
    "EI0": {"dist": "lognormal", "median": 2.0, "sigma_log": 1.0, "unit": "N m^2"},
    "p": {"dist": "truncnormal", "mean": 0.5, "sd": 0.4, "low": 0.0, "high": 3.0},
    "sigma_force_N": {"dist": "halfnormal", "scale": 0.1},
    "sigma_shape_m": {"dist": "halfnormal", "scale": 0.005},
    "shape_sd_scale": {"dist": "lognormal", "median": 1.0, "sigma_log": 0.3},
}


def _write(tmp_path, doc, name="pr.json"):
    import json

    f = tmp_path / name
    f.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return str(f)


def test_a_prior_file_loads_with_every_value_where_it_belongs(tmp_path):
    from bayesrod.inference.priors import available_priors, load_prior

    doc = {
        "name": "mine",
        "justification": "test",
        "parameters": {**GOOD, "x_norm": {"dist": "normal", "mean": -1.0, "sd": 2.0}},
        "effects": {"base_tilt": {"dist": "uniform", "low": -0.1, "high": 0.2, "unit": "rad"}},
    }
    pr = load_prior(_write(tmp_path, doc))
    assert pr.name == "mine" and pr.source.endswith("pr.json") and pr.doc["justification"] == "test"
    assert pr.get("EI0") == ParamPrior("EI0", "lognormal", (2.0, 1.0), "N m^2")
    assert pr.get("p").args == (0.5, 0.4, 0.0, 3.0) and pr.get("x_norm").args == (-1.0, 2.0)
    assert pr.get("base_tilt") == ParamPrior("base_tilt", "uniform", (-0.1, 0.2), "rad")
    # a nuisance default when the file has none: the AR(1) reference prior (docs/priors.md)
    assert pr.get("rho_force") == ParamPrior("rho_force", "arcsine", (-0.5, 0.995), "1")
    with pytest.raises(ValueError, match=r"^prior mine: expected a prior for nope, got none in .*pr.json$"):
        pr.get("nope")
    unnamed = load_prior(_write(tmp_path, {"parameters": GOOD}, "other.json"))
    assert unnamed.name == "other" and unnamed.effects == {} and unnamed.get("sigma_force_N").unit == ""
    bad_effect = {"parameters": GOOD, "effects": {"base_tilt": {"dist": "normal", "mean": 0.0, "sd": -1.0}}}
    with pytest.raises(ValueError, match=r"^.*bad.json: base_tilt.sd: expected a value > 0, got -1.0$"):
        load_prior(_write(tmp_path, bad_effect, "bad.json"))
    assert available_priors() == sorted(available_priors()) and "woody" in available_priors()
    assert load_prior(None).source == "priors/default.json" and load_prior("woody").source == "priors/woody.json"


@pytest.mark.parametrize(
    "change, msg",
    [
        (
            {"EI0": {"dist": "gamma"}},
            r"pr.json: EI0.dist: expected one of arcsine, halfnormal, lognormal, normal, truncnormal, uniform, "
            r"got 'gamma'",
        ),
        ({"EI0": 3.0}, r"EI0.dist: expected one of .*, got 3.0"),
        (
            {"EI0": {"dist": "lognormal", "median": 2.0}},
            r"EI0.sigma_log: expected a finite number for a lognormal prior, got None",
        ),
        ({"EI0": {"dist": "lognormal", "median": True, "sigma_log": 1}}, r"EI0.median: expected a finite number"),
        ({"EI0": {"dist": "lognormal", "median": "2", "sigma_log": 1}}, r"EI0.median: expected a finite number"),
        ({"EI0": {"dist": "lognormal", "median": 0.0, "sigma_log": 1}}, r"EI0.median: expected a value > 0, got 0.0"),
        ({"EI0": {"dist": "lognormal", "median": 1.0, "sigma_log": 0}}, r"EI0.sigma_log: expected a value > 0"),
        ({"p": {"dist": "normal", "mean": 0.0, "sd": 0.0}}, r"p.sd: expected a value > 0"),
        ({"p": {"dist": "normal", "mean": -1.0, "sd": 1.0}}, None),  # a negative mean is fine
        ({"sigma_force_N": {"dist": "halfnormal", "scale": -1.0}}, r"sigma_force_N.scale: expected a value > 0"),
        ({"p": {"dist": "truncnormal", "mean": 0.5, "sd": 0.0, "low": 0, "high": 1}}, r"p.sd: expected a value > 0"),
        (
            {"p": {"dist": "truncnormal", "mean": 0.5, "sd": 1.0, "low": 1, "high": 1}},
            r"p: expected low < high, got 1.0 and 1.0",
        ),
        ({"p": {"dist": "uniform", "low": 2.0, "high": 1.0}}, r"p: expected low < high, got 2.0 and 1.0"),
        ({"p": {"dist": "truncnormal", "mean": 0.5, "sd": 1.0, "low": 0.5, "high": 0.4}}, r"p: expected low < high"),
        ({"p": {"dist": "uniform", "low": -2.0, "high": 1.0}}, None),
        ({"rho_force": {"dist": "arcsine", "low": -0.9, "high": 0.99}}, None),
        (
            {"rho_force": {"dist": "arcsine", "low": -0.5, "high": 1.0}},
            r"rho_force: expected -1 < low < high < 1 for an arcsine prior, got -0.5 and 1.0",
        ),
        ({"rho_force": {"dist": "arcsine", "low": 0.5, "high": 0.2}}, r"rho_force: expected low < high"),
        (
            {"rho_force": {"dist": "arcsine", "low": -1.0, "high": 0.9}},
            r"rho_force: expected -1 < low < high < 1 for an arcsine prior, got -1.0 and 0.9",
        ),
        ({"p": {"dist": "uniform", "low": 0.0, "high": float("inf")}}, r"p.high: expected a finite number"),
    ],
)
def test_each_bad_prior_value_is_named(tmp_path, change, msg):
    from bayesrod.inference.priors import load_prior

    f = _write(tmp_path, {"parameters": {**GOOD, **change}})  # json.dumps writes inf as Infinity
    if msg is None:
        load_prior(f)
        return
    with pytest.raises(ValueError, match=msg):
        load_prior(f)


@pytest.mark.parametrize(
    "text, msg",
    [
        ("{not json", r"pr.json: expected valid JSON, got Expecting property name enclosed in double quotes at line 1"),
        ('{"parameters": []}', r"pr.json: parameters: expected an object of parameter priors, got none"),
        ("[1, 2]", r"parameters: expected an object"),
        (
            '{"parameters": {"EI0": {"dist": "lognormal", "median": 2.0, "sigma_log": 1.0}}}',
            r"pr.json: parameters.p: expected a prior, got none",
        ),
    ],
)
def test_unreadable_prior_files_say_why(tmp_path, text, msg):
    from bayesrod.inference.priors import load_prior

    with pytest.raises(ValueError, match=msg):
        load_prior(_write(tmp_path, text))


def test_unknown_effects_and_missing_files_are_named(tmp_path):
    import json

    from bayesrod.inference.priors import load_prior

    doc = {
        "parameters": GOOD,
        "effects": {"zz": {"dist": "normal", "mean": 0, "sd": 1}, "yy": {"dist": "normal", "mean": 0, "sd": 1}},
    }
    with pytest.raises(
        ValueError, match=r"pr.json: effects.yy: expected one of base_compliance, rest_curvature, .*, got it"
    ):
        load_prior(_write(tmp_path, json.dumps(doc)))
    with pytest.raises(
        ValueError,
        match=r"^prior: expected a prior name \(default, grass, .*\) or a JSON file, got '.*missing.json' \(no such",
    ):
        load_prior(str(tmp_path / "missing.json"))
    with pytest.raises(
        ValueError, match=r"^prior: expected one of default, grass, .* or a JSON file, got 'nonexistent'"
    ):
        load_prior("nonexistent")


def test_the_clamp_or_uniform_coordinate_owns_zero_and_steps_down_by_its_jacobian_above_it():
    """z = 0 is on the clamp (u = 0); just above it the density in z is p(u) du/dz = (1/2) scale / u_max."""
    width, scale, u_max = 2.0, 0.01, 0.5
    pr = ParamPrior("z", "clamp_or_uniform", (width, scale, u_max))
    below, zero, above = pr.logpdf_sample(np.array([-1e-12, 0.0, 1e-12]))
    assert below == zero == pytest.approx(-math.log(2 * width), rel=1e-15)
    assert above == pytest.approx(math.log(0.5 * scale / u_max), rel=1e-15)
    assert pr.quantile(0.5) == 0.0 and pr.quantile(0.0) == -width and pr.quantile(1.0) == u_max / scale
    assert not pr.log_space and pr.to_sample(0.25) == 0.25 and pr.from_sample(-0.5) == -0.5


def _noise_space(names, priors):
    space = ParameterSpace()
    space.names, space.priors = names, priors
    return space


SD = ParamPrior("sigma_force_N", "halfnormal", (0.1,))
RHO = ParamPrior("rho_force", "arcsine", (-0.5, 0.995))


def test_an_ar1_force_noise_is_sampled_by_its_innovation_sd_and_mapped_back_exactly():
    """(log sigma sqrt(1 - rho^2), rho) in the sampling space, (sigma, rho) in natural units; per-condition
    copies pair by suffix; the shear has unit Jacobian, so prior_coordinates is the prior's own transform."""
    names = ["EI0", "sigma_force_N__a", "rho_force__a", "sigma_force_N__b", "rho_force__b"]
    sd_a, rho_a, sd_b, rho_b = (
        ParamPrior(n, d.dist, d.args) for n, d in zip(names[1:], [SD, RHO, SD, RHO], strict=True)
    )
    space = _noise_space(names, [ParamPrior("EI0", "lognormal", (2.0, 1.0)), sd_a, rho_a, sd_b, rho_b])
    assert space.noise_pairs() == [(1, 2), (3, 4)]
    nat = {
        "EI0": np.array([2.0, 3.0]),
        "sigma_force_N__a": np.array([0.2, 0.05]),
        "rho_force__a": np.array([0.9, -0.4]),
    }
    nat |= {"sigma_force_N__b": np.array([0.1, 0.3]), "rho_force__b": np.array([0.0, 0.6])}
    theta = space.to_sample(nat)
    assert theta.shape == (2, 5)
    want = np.column_stack(
        [
            np.log(nat["EI0"]),
            np.log(nat["sigma_force_N__a"] * np.sqrt(1 - nat["rho_force__a"] ** 2)),
            nat["rho_force__a"],
            np.log(nat["sigma_force_N__b"] * np.sqrt(1 - nat["rho_force__b"] ** 2)),
            nat["rho_force__b"],
        ]
    )
    np.testing.assert_allclose(theta, want, rtol=1e-14)
    before = theta.copy()
    back = space.to_natural(theta)
    np.testing.assert_array_equal(theta, before)  # the caller's array is not sheared in place
    for n, v in nat.items():
        np.testing.assert_allclose(back[n], v, rtol=1e-13)
    prior = space.prior_coordinates(theta)
    np.testing.assert_array_equal(theta, before)
    np.testing.assert_allclose(
        prior[:, [1, 3]], np.log(np.column_stack([nat["sigma_force_N__a"], nat["sigma_force_N__b"]]))
    )
    np.testing.assert_array_equal(prior[:, [0, 2, 4]], theta[:, [0, 2, 4]])
    # a correlation at the edge of [-1, 1] stays finite (clipped a hair inside)
    edge = space.prior_coordinates(np.array([0.0, -1.0, 1.0, -1.0, -1.0]))
    assert np.all(np.isfinite(edge)) and edge[1] == pytest.approx(-1.0 - 0.5 * np.log1p(-((1 - 1e-12) ** 2)), rel=1e-6)


@pytest.mark.parametrize(
    "names, priors",
    [
        (["sigma_force_N", "rho_force"], [ParamPrior("sigma_force_N", "normal", (0.1, 0.1)), RHO]),  # sd not in log
        (["sigma_force_N", "rho_force"], [SD, ParamPrior("rho_force", "lognormal", (0.5, 1.0))]),  # rho in log
        (["sigma_force_N__a", "rho_force__b"], [SD, RHO]),  # different conditions
        (["sigma_force_N", "rho_shape"], [SD, RHO]),  # not the force noise's correlation
    ],
)
def test_only_a_log_sd_with_its_own_linear_force_correlation_is_sheared(names, priors):
    space = _noise_space(names, priors)
    assert space.noise_pairs() == []
    theta = np.array([[-2.0, 0.7]])
    np.testing.assert_array_equal(space.prior_coordinates(theta), theta)


def test_names_and_priors_must_pair_one_to_one():
    space = _noise_space(["EI0", "p"], [ParamPrior("EI0", "lognormal", (2.0, 1.0))])
    with pytest.raises(ValueError):
        space.to_natural(np.zeros((1, 2)))
    with pytest.raises(ValueError):
        space.to_sample({"EI0": 1.0, "p": 0.5})


def test_prior_files_are_found_from_a_source_tree_without_the_installed_package(monkeypatch):
    from importlib import resources

    from bayesrod.inference import priors as P

    def missing(name):
        raise ModuleNotFoundError(name)

    monkeypatch.setattr(resources, "files", missing)
    folder = P._priors_dir()
    assert folder == Path(P.__file__).resolve().parents[2] / "priors"  # the checkout's top-level priors/
    assert (folder / "woody.json").is_file() or not folder.exists()  # (a copy of the package alone has none)


EI0_PRIOR = ParamPrior("EI0", "lognormal", (3.0, 1.5))
K_PRIOR = ParamPrior("base_compliance", "lognormal", (10.0, 2.0))


def _base_space(length_m):
    space = _noise_space(["EI0", "p", "sigma_force_N", "base_compliance"], [EI0_PRIOR, RHO, SD, K_PRIOR])
    space.base_length_m = length_m
    return space


def test_a_base_spring_is_sampled_by_its_table_coordinate_with_the_jacobian_of_that_map():
    """u = c / (1 + c), c = EI0 / (k L), in the sampling space; log k back in the prior's coordinates; the log
    determinant of that map (finite differences of prior_coordinates) is log_jacobian."""
    L = 0.8
    space = _base_space(L)
    assert space.base_pair() == (0, 3)
    nat = {
        "EI0": np.array([2.0, 9.9, 0.3]),
        "p": np.array([0.5, 1.0, 0.1]),
        "sigma_force_N": np.array([0.02, 0.05, 0.1]),
        "base_compliance": np.array([400.0, 3.0, 0.01]),
    }
    theta = space.to_sample(nat)
    c = nat["EI0"] / (nat["base_compliance"] * L)
    np.testing.assert_allclose(theta[:, 3], c / (1 + c), rtol=1e-14)
    np.testing.assert_allclose(theta[:, [0, 2]], np.log(np.column_stack([nat["EI0"], nat["sigma_force_N"]])))
    before = theta.copy()
    back = space.to_natural(theta)
    np.testing.assert_array_equal(theta, before)  # the caller's array is not changed in place
    for n, v in nat.items():
        np.testing.assert_allclose(back[n], v, rtol=1e-12)
    for t in theta:  # the Jacobian: d(log EI0, p, log sd, log k) / d(log EI0, p, log sd, u)
        h = 1e-7
        J = np.column_stack(
            [(space.prior_coordinates(t + h * e) - space.prior_coordinates(t - h * e)) / (2 * h) for e in np.eye(4)]
        )
        assert space.log_jacobian(t) == pytest.approx(np.log(abs(np.linalg.det(J))), abs=1e-6)
        assert space.log_jacobian(t) == pytest.approx(-np.log(t[3] * (1 - t[3])), rel=1e-12)
    # u outside (0, 1) has no spring: zero density, no number
    out = np.array([[0.0, 0.5, -3.0, 0.0], [0.0, 0.5, -3.0, 1.0], [0.0, 0.5, -3.0, -0.2]])
    assert np.all(space.log_jacobian(out) == -np.inf)
    assert np.all(np.isnan(space.prior_coordinates(out)[:, 3]))
    np.testing.assert_array_equal(space.log_jacobian(theta[:2]), -np.log(theta[:2, 3] * (1 - theta[:2, 3])))


@pytest.mark.parametrize(
    "length_m, k_prior",
    [(None, K_PRIOR), (0.8, ParamPrior("base_compliance", "normal", (10.0, 2.0)))],  # unset; k's prior not in log
)
def test_a_base_spring_stays_in_its_prior_coordinate_without_a_length_or_a_log_prior(length_m, k_prior):
    space = _noise_space(["EI0", "p", "sigma_force_N", "base_compliance"], [EI0_PRIOR, RHO, SD, k_prior])
    space.base_length_m = length_m
    assert space.base_pair() is None
    theta = np.array([[0.5, 0.4, -3.0, 2.0]])
    np.testing.assert_array_equal(space.prior_coordinates(theta), theta)
    np.testing.assert_array_equal(space.log_jacobian(theta), [0.0])


@pytest.mark.parametrize("u", [0.02, 0.5, 0.51, 0.93])
def test_a_base_spring_stays_in_u_from_a_stiff_start_and_moves_to_log_k_from_a_soft_one(u):
    """u straightens a stiff clamp's arm of the posterior, log k a soft spring's: the start decides
    (ParameterSpace.settle_base_coordinates, BASE_U_SWITCH 0.5); the start's natural values are kept."""
    from bayesrod.inference.priors import BASE_U_SWITCH

    assert BASE_U_SWITCH == 0.5
    space = _base_space(0.8)
    theta = np.array([np.log(3.0), 0.4, np.log(0.03), u])
    before = space.to_natural(theta[None])
    got = space.settle_base_coordinates(theta)
    if u <= 0.5:
        assert space.base_pair() == (0, 3) and np.array_equal(got, theta)
    else:
        assert space.base_pair() is None
        k = 3.0 * (1 - u) / (u * 0.8)  # c = u / (1 - u) = EI0 / (k L)
        np.testing.assert_allclose(got, [np.log(3.0), 0.4, np.log(0.03), np.log(k)], rtol=1e-12)
    after = space.to_natural(got[None])
    for n in before:
        np.testing.assert_allclose(after[n], before[n], rtol=1e-12)


@pytest.mark.parametrize("eta", [0.1, 0.5, 0.9])
@pytest.mark.parametrize("p", [0.0, 0.43, 1.6, 3.0])
def test_the_compliance_factor_is_the_integral_of_the_taper_law_and_3_ei_over_h3_for_a_uniform_rod(p, eta):
    """log C(p) against scipy's quad; at p = 0, C = eta^3 / 3 (k_x = 3 EI / h^3 for constant EI)."""
    from scipy.integrate import quad

    from bayesrod.inference.priors import log_compliance_factor

    ref = quad(lambda x: (eta - x) ** 2 * (1 - x) ** (-4 * p), 0, eta, epsabs=0, epsrel=1e-12)[0]
    # (the closed form of eq. kx; any smooth function of p would make a valid coordinate)
    assert float(log_compliance_factor(p, eta)) == pytest.approx(math.log(ref), abs=1e-4)
    if p == 0.0:
        assert float(np.exp(log_compliance_factor(p, eta))) == pytest.approx(eta**3 / 3, rel=1e-12)
    np.testing.assert_array_equal(log_compliance_factor(np.full((2, 3), p), eta).shape, (2, 3))


def _stiffness_space(stiffness_at):
    ps = ParameterSpace()
    ps.names = ["EI0", "p", "sigma_force_N", "rho_force"]
    ps.priors = [
        ParamPrior("EI0", "lognormal", (2.0, 1.0)),
        ParamPrior("p", "uniform", (0.0, 3.0)),
        ParamPrior("sigma_force_N", "lognormal", (0.03, 1.0)),
        ParamPrior("rho_force", "arcsine", (-0.5, 0.995)),
    ]
    ps.stiffness_at = stiffness_at
    return ps


def test_at_one_height_ei0_is_sampled_as_the_log_stiffness_there_a_shear_of_unit_jacobian():
    """With ``stiffness_at`` = (h, L) the EI0 coordinate is log EI0 - log C(p, h/L): at fixed stiffness
    EI0 / C, moving p moves nothing else; the map back is exact, the prior coordinates are log EI0 again
    (the log density needs no Jacobian), and the other coordinates are those of the plain space."""
    from bayesrod.inference.priors import log_compliance_factor

    rng = np.random.default_rng(4)
    nat = {
        "EI0": np.exp(rng.normal(1.0, 0.5, 7)),
        "p": rng.uniform(0.0, 3.0, 7),
        "sigma_force_N": np.exp(rng.normal(-3.0, 0.3, 7)),
        "rho_force": rng.uniform(-0.4, 0.99, 7),
    }
    shear, plain = _stiffness_space((0.55, 0.8)), _stiffness_space(None)
    assert shear.stiffness_pair() == (0, 1) and plain.stiffness_pair() is None
    t_shear, t_plain = shear.to_sample(nat), plain.to_sample(nat)
    np.testing.assert_allclose(t_shear[:, 0], np.log(nat["EI0"]) - log_compliance_factor(nat["p"], 0.55 / 0.8))
    np.testing.assert_array_equal(t_shear[:, 1:], t_plain[:, 1:])
    np.testing.assert_allclose(shear.prior_coordinates(t_shear), plain.prior_coordinates(t_plain), rtol=0, atol=1e-12)
    back = shear.to_natural(t_shear)
    for k, v in nat.items():
        np.testing.assert_allclose(back[k], v, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(shear.log_jacobian(t_shear), 0.0)
    # the stiffness fixed, p moved: EI0 follows the ridge log EI0 = log k + log C(p)
    moved = t_shear.copy()
    moved[:, 1] = 2.0
    ei0 = shear.to_natural(moved)["EI0"]
    np.testing.assert_allclose(np.log(ei0) - log_compliance_factor(2.0, 0.55 / 0.8), t_shear[:, 0], rtol=0, atol=1e-12)


def test_the_posterior_samples_ei0_by_the_stiffness_only_when_every_push_is_at_one_height(tmp_path):
    """One height on a known length: the shear, and the log posterior at a natural point is the plain
    coordinates' (unit Jacobian); two heights, or the length sampled: log EI0 as before."""
    import bayesrod
    from bayesrod.inference.likelihood import LogPosterior, build_likelihood
    from bayesrod.inference.priors import load_prior

    prior = load_prior("default")
    one = bayesrod.simulate("twig", seed=3, heights_m=[0.55])
    lik = build_likelihood(one, prior, (), use_shapes=False)
    post = LogPosterior(lik, prior)
    assert post.stiffness_at == (0.55, 0.8) and post.stiffness_pair() == (0, 1)
    plain = LogPosterior(lik, prior)
    plain.stiffness_at = None
    nat = {"EI0": np.array([2.3, 2.63, 3.1]), "p": np.array([0.3, 0.43, 0.9]), "sigma_force_N": np.full(3, 0.03)}
    np.testing.assert_allclose(post.log_prob(post.to_sample(nat)), plain.log_prob(plain.to_sample(nat)), atol=1e-9)
    two = bayesrod.simulate("twig", seed=3, heights_m=[0.45, 0.65])
    assert LogPosterior(build_likelihood(two, prior, (), use_shapes=False), prior).stiffness_at is None
    # a base spring in series is not the rod's stiffness at the height: no shear (the SBC's seed 25: R-hat 1.41
    # with it). The names alone decide; a likelihood with the spring's tables (15 s to build) is checked in
    # tests/test_prior_sampling.py
    spring = LogPosterior(lik, prior)
    spring.names = [*spring.names, "base_compliance"]
    assert spring.stiffness_at == (0.55, 0.8) and spring.stiffness_pair() is None


def test_one_height_stiffness_needs_one_height_one_known_length():
    """(h, L) only for one height on one known length (conditions of a group may differ in either)."""
    from bayesrod.inference.likelihood import one_height_stiffness

    assert one_height_stiffness([0.5, 0.5], [1.8], False) == (0.5, 1.8)
    assert one_height_stiffness([0.5, 0.5], [1.8, 1.8], False) == (0.5, 1.8)
    assert one_height_stiffness([0.5, 0.6], [1.8], False) is None
    assert one_height_stiffness([0.5], [1.8, 1.7], False) is None
    assert one_height_stiffness([0.5], [1.8], True) is None
    assert one_height_stiffness([], [1.8], False) is None


def test_a_one_height_fit_records_its_stiffness_coordinates_for_resuming():
    """A checkpoint must know the coordinates its chains are in: a one-height fit records them."""
    import bayesrod

    one = bayesrod.simulate("twig", seed=3, heights_m=[0.55])
    fit = bayesrod.fit(one, use_shapes=False, progress=False, max_steps=100, target_ess=10)
    assert fit.config["stiffness_coordinates"] == "log_k_at_height"
    assert fit.config["noise_coordinates"] == "marginal_sd" and fit.config["base_coordinates"] == "log_k"


def test_a_walker_far_out_in_log_space_maps_to_inf_without_a_warning():
    """A sampler's walker at log EI0 = 1000 (a stretch move between distant walkers) is EI0 = inf, silently: the
    prior's log density there is below -1e5. numpy's overflow warning reached users' terminals during fit-group
    (session 49)."""
    import warnings

    from bayesrod.inference.priors import ParamPrior

    pr = ParamPrior("EI0", "lognormal", (3.0, 1.5), "N m^2")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x = pr.from_sample(np.array([0.0, 1000.0]))
    assert x[0] == 1.0 and np.isinf(x[1])
    assert pr.logpdf_sample(np.array([1000.0]))[0] < -1e5  # the prior's weight there is nil


def test_a_half_normal_far_out_in_log_space_has_zero_density_without_a_warning():
    """A walker's proposal of log sd 400 (or inf) is beyond any force: density 0 (log -inf, not nan), and no
    overflow warning reaches the user (fit-group's SBC printed one per worker)."""
    import warnings

    pr = ParamPrior("sigma_force_N", "halfnormal", (0.5,), "N")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = pr.logpdf_sample(np.array([400.0, 800.0, np.inf, math.log(0.3)]))
    assert got[0] == got[1] == got[2] == -np.inf
    assert got[3] == pytest.approx(stats.halfnorm.logpdf(0.3, scale=0.5) + math.log(0.3), rel=1e-12)

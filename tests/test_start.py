"""The sampler's start (``bayesrod.inference.sampler.find_start``): the posterior's mode.

Every fit and SBC replicate starts here, so a wrong line of it shows only as a slower or stuck run, not as a
failing fit test (session 69: ``find_start`` sat outside every mutmut target's tests). Checked here directly:
the start is the mode an independent optimiser finds, better than every candidate it began from; the seed's
two-stage estimate is tried as a candidate; the candidates hold an effect at its neutral value (a stiff base)
and the effect's profile over its axis finds a strong one they miss; a posterior with no finite point says so.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

import bayesrod
from bayesrod.inference.likelihood import LogPosterior, build_likelihood, force_scale_fit
from bayesrod.inference.priors import load_prior
from bayesrod.inference.sampler import find_start


@pytest.fixture(scope="module")
def twig():
    """Forces and centerlines of a noisy twig (three heights), a base spring fitted: its posterior."""
    ds = bayesrod.simulate("twig", seed=11, config_overrides={"n_frames_engaged": 2})
    prior = load_prior("woody")
    lik = build_likelihood(ds, prior, ("base_compliance",), use_shapes=True, n_effect=7)
    return LogPosterior(lik, prior)


class _Recorder:
    """The posterior, recording every natural point ``find_start`` maps to the sampler's coordinates: one at a
    time (the candidates) in ``points``, batches (the effect's and the preloads' profiles) in ``rows``."""

    def __init__(self, post):
        self.post, self.points, self.rows = post, [], []

    def __getattr__(self, name):
        return getattr(self.post, name)

    def to_sample(self, nat):
        if all(np.size(v) == 1 for v in nat.values()):
            self.points.append({k: float(np.atleast_1d(v)[0]) for k, v in nat.items()})
        else:
            self.rows.append({k: np.array(v, float) for k, v in nat.items()})
        return self.post.to_sample(nat)


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # Powell's line search past the table
def test_the_start_is_the_posterior_mode_and_beats_every_candidate(twig):
    rec = _Recorder(twig)
    theta = find_start(rec, np.random.default_rng(0))
    lp = float(twig.log_prob(theta))
    candidates = [float(twig.log_prob(twig.to_sample(pt)[0])) for pt in rec.points]
    assert len(candidates) == twig.likelihood.p_grid.size - 2  # one per inner node of the p grid
    assert lp >= max(candidates)
    # an independent optimiser from the start: no better point within reach (measured in session 69: 1.8e-12
    # nats; the start unpolished 216 nats below, polished to xatol = fatol = 1e-2 1.1 below)
    ref = minimize(lambda t: -twig.log_prob(t), theta, method="Powell", options={"xtol": 1e-8, "ftol": 1e-12})
    assert -ref.fun - lp < 0.05


def test_the_two_stage_estimate_is_tried_clipped_to_the_inner_grid(twig):
    g = twig.likelihood.p_grid
    for p_init, p_tried in ((0.5 * (g[3] + g[4]), 0.5 * (g[3] + g[4])), (g[-1] + 1.0, g[-2]), (g[0] - 1.0, g[1])):
        rec = _Recorder(twig)
        find_start(rec, np.random.default_rng(0), init={"EI0": 1.234, "p": p_init})
        tried = [pt for pt in rec.points if pt["EI0"] == 1.234]
        assert len(tried) == 1 and tried[0]["p"] == pytest.approx(p_tried, abs=1e-12)
    rec = _Recorder(twig)
    find_start(rec, np.random.default_rng(0), init={"EI0": float("nan"), "p": 0.5})
    assert len(rec.points) == g.size - 2  # a failed two-stage estimate adds no candidate


def test_candidates_start_at_a_stiff_base_and_the_closed_form_scale_and_noise(twig, no_polish):
    """Before the polish (here switched off: Nelder-Mead returning no finite value), the best candidate: EI0
    the forces' least-squares scale at its p, the force noise their RMS residual, the centerline sd scale
    their RMS offset over the reported sd, the base spring at its prior's 99% quantile (stiff)."""
    lik = twig.likelihood
    nat = {k: float(v[0]) for k, v in twig.to_natural(find_start(twig, np.random.default_rng(0))[None]).items()}
    EI0, rms = force_scale_fit(lik, nat["p"])
    assert nat["EI0"] == pytest.approx(EI0, rel=1e-9) and nat["sigma_force_N"] == pytest.approx(rms, rel=1e-9)
    offsets = lik.shape_offsets(np.array([nat["p"]]))[0]
    scale = np.sqrt(np.mean(offsets**2)) / np.sqrt(np.mean(lik.sd_obs**2))
    assert nat["shape_sd_scale"] == pytest.approx(scale, rel=1e-9)
    q99 = twig.priors[twig.names.index("base_compliance")].quantile(0.99)
    assert nat["base_compliance"] == pytest.approx(q99, rel=1e-9)


@pytest.fixture(scope="module")
def soft_base():
    """Forces only of a twig on a soft base spring (c = EI0 / (k L) = 1: u = c / (1 + c) = 0.5), three heights:
    its posterior with the base spring fitted, and u of the truth."""
    ds = bayesrod.simulate(
        "twig", seed=12, effects={"base_compliance": 2.63 / 0.8}, config_overrides={"n_frames_engaged": 2}
    )
    prior = load_prior("woody")
    lik = build_likelihood(ds, prior, ("base_compliance",), use_shapes=False, n_effect=7)
    return LogPosterior(lik, prior), 0.5


def test_the_effect_profile_finds_a_soft_base_every_neutral_candidate_misses(soft_base, no_polish):
    """The candidates hold the base stiff (its prior's 99% quantile); the effect's profile, p on the inner p
    nodes by u at 25 points inside the axis, EI0 and the force noise in closed form at each, finds the soft base
    (u 0.5) and starts there, far above every candidate (polish off: the profile's own point)."""
    post, u_true = soft_base
    lik = post.likelihood
    rec = _Recorder(post)
    theta = find_start(rec, np.random.default_rng(0))
    q99 = post.priors[post.names.index("base_compliance")].quantile(0.99)
    assert len(rec.points) == lik.p_grid.size - 2
    assert all(pt["base_compliance"] == pytest.approx(q99, rel=1e-12) for pt in rec.points)
    best_candidate = max(float(post.log_prob(post.to_sample(pt)[0])) for pt in rec.points)
    lp = float(post.log_prob(theta))
    assert lp > best_candidate + 50.0  # measured: 376.7 against 106.7 (polished without the profile: 128.7)
    # the profile: one batch per inner p node, each the axis's 25 inner points with EI0 and noise in closed form
    assert len(rec.rows) == lik.p_grid.size - 2
    us = np.linspace(lik.axis.grid[0], lik.axis.grid[-1], 27)[1:-1]
    for rows, p in zip(rec.rows, lik.p_grid[1:-1], strict=True):
        np.testing.assert_allclose(lik.effect_coordinate(rows), us, rtol=1e-9)
        assert np.all(rows["p"] == p)
    nat = {k: float(v[0]) for k, v in post.to_natural(theta[None]).items()}
    u0 = float(lik.effect_coordinate(nat)[0])
    assert np.min(np.abs(us - u0)) < 1e-9 and abs(u0 - u_true) < 0.1
    g = lik.predict_nd_force(np.array([nat["p"]]), np.array([u0])) / lik.L**2
    EI0 = float(g[0] @ lik.F_obs / (g[0] @ g[0]))
    rms = float(np.sqrt(np.mean((lik.F_obs - EI0 * g[0]) ** 2)))
    assert nat["EI0"] == pytest.approx(EI0, rel=1e-9) and nat["sigma_force_N"] == pytest.approx(rms, rel=1e-9)

    # a point of the profile without a density (NaN) costs only that point, not its row of u
    def first_of_each_batch_nan(t):
        lp = post.log_prob(t)
        return np.where(np.arange(len(t)) == 0, np.nan, lp) if np.ndim(t) == 2 else lp

    holed = _Recorder(post)
    holed.log_prob = first_of_each_batch_nan
    np.testing.assert_array_equal(find_start(holed, np.random.default_rng(0)), theta)


def test_a_posterior_without_a_finite_point_on_the_grid_is_an_error(twig, monkeypatch):
    monkeypatch.setattr(twig, "log_prob", lambda theta: -np.inf)
    with pytest.raises(ValueError, match="finite posterior density"):
        find_start(twig, np.random.default_rng(0))

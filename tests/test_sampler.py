"""The sampler's repair of walkers left in a far worse optimum (``replace_stuck_walkers``)."""

import numpy as np

from bayesrod.inference import sampler
from bayesrod.inference.sampler import replace_stuck_walkers, run_ensembles


class _TwoWells:
    """Two Gaussian wells 10 apart in 2-D, the second 200 nats lower, nothing in between.

    A stretch move from the low well proposes along lines through the walkers of the high well, and
    a differential-evolution move by the difference of two of them: every such point lies in neither
    well, so a walker started low never leaves without help.
    """

    ndim = 2
    names = ("x", "y")

    def log_prob(self, theta):
        t = np.atleast_2d(theta)
        a = -0.5 * np.sum(t**2, axis=-1)
        b = -200.0 - 0.5 * np.sum((t - [10.0, 0.0]) ** 2, axis=-1) / 0.01
        out = np.where(np.hypot(*t.T) < 4.0, a, np.where(np.hypot(t[:, 0] - 10.0, t[:, 1]) < 0.4, b, -np.inf))
        return out if np.ndim(theta) > 1 else out[0]

    def prior_coordinates(self, chain):
        return chain


def test_no_walker_stuck_returns_none_and_draws_nothing():
    rng = np.random.default_rng(0)
    chain = rng.standard_normal((200, 16, 3))
    lp = -0.5 * np.sum(chain**2, axis=-1)
    state = rng.bit_generator.state
    assert replace_stuck_walkers(chain, lp, rng) is None
    assert rng.bit_generator.state == state  # an unrepaired run is the same run as before the repair existed


def test_stuck_walkers_move_onto_the_others():
    rng = np.random.default_rng(1)
    chain = rng.standard_normal((200, 16, 2))
    lp = -0.5 * np.sum(chain**2, axis=-1)
    chain[:, [3, 11]] += 10.0
    lp[:, [3, 11]] -= 30.0  # 30 nats: more than half the 1 - 1e-6 quantile of chi2(2) (13.8)
    out = replace_stuck_walkers(chain, lp, rng)
    assert out.shape == (16, 2)
    assert np.all(np.abs(out[[3, 11]]) < 5.0)  # now among the others
    keep = np.setdiff1d(np.arange(16), [3, 11])
    np.testing.assert_array_equal(out[keep], chain[-1, keep])  # the others are untouched
    lp[:, [3, 11]] += 20.0  # 10 nats below: within what a Gaussian posterior's walkers can wander
    assert replace_stuck_walkers(chain, lp, rng) is None


def test_run_ensembles_restarts_a_walker_left_in_a_lower_well(monkeypatch):
    def ball(theta0, n, rng, post):
        out = 0.3 * rng.standard_normal((n, 2))
        out[0] = [10.0, 0.01]  # one walker in the low well (two there could pull each other out by
        # differential-evolution moves along their difference; one cannot)
        return out

    monkeypatch.setattr(sampler, "_ball", ball)
    kw = dict(n_ensembles=2, n_walkers=16, chunk=200, min_steps=200, max_steps=400, progress=False, target_ess=50)
    res = run_ensembles(_TwoWells(), np.zeros(2), seed=0, **kw)
    assert res.walkers_restarted == (1, 1)
    assert np.all(np.abs(res.chain[..., 0]) < 4.0)  # no draw from the low well
    assert abs(np.std(res.chain[..., 0]) - 1.0) < 0.15

"""The sampler's repair of walkers left in a far worse optimum (``replace_stuck_walkers``)."""

import dataclasses

import numpy as np
import pytest

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
    # one stretch only: the check follows the first stretch from the ball, not a later one
    kw = dict(n_ensembles=2, n_walkers=16, chunk=300, min_steps=300, max_steps=300, progress=False, target_ess=50)
    res = run_ensembles(_TwoWells(), np.zeros(2), seed=0, **kw)
    assert res.walkers_restarted == (1, 1)
    assert np.all(np.abs(res.chain[..., 0]) < 4.0)  # no draw from the low well
    assert abs(np.std(res.chain[..., 0]) - 1.0) < 0.15


class _Gauss:
    """A standard normal in ``ndim`` dimensions (cheap: the sampler's logic is under test, not a model)."""

    def __init__(self, ndim=2):
        self.ndim = ndim
        self.names = tuple(f"x{i}" for i in range(ndim))
        self.calls = 0  # walker positions evaluated

    def log_prob(self, theta):
        t = np.atleast_2d(theta)
        self.calls += t.shape[0]
        out = -0.5 * np.sum(t**2, axis=-1)
        return out if np.ndim(theta) > 1 else out[0]

    def prior_coordinates(self, chain):
        return chain


def test_run_ensembles_returns_every_walker_after_burn_in_with_its_log_density():
    post = _Gauss(3)
    kw = dict(n_ensembles=3, chunk=300, min_steps=300, max_steps=300, progress=False, target_ess=1.0)
    res = run_ensembles(post, np.zeros(3), seed=4, **kw)
    assert res.n_ensembles == 3 and res.n_steps == 300
    assert res.chain.shape == (3 * 16, 300 - res.burn, 3)  # 16 walkers each: max(16, 4 ndim)
    assert res.log_prob.shape == res.chain.shape[:2]
    np.testing.assert_allclose(res.log_prob, post.log_prob(res.chain.reshape(-1, 3)).reshape(res.chain.shape[:2]))
    assert res.tau.shape == (3,) and np.all(np.isfinite(res.tau) & (res.tau > 0))
    assert res.burn == int(min(max(300 // 3, 5 * np.max(res.tau)), 150))
    assert 0.2 < res.acceptance < 0.95
    assert res.walkers_restarted == (0, 0, 0)  # a healthy run moves nobody
    assert abs(np.std(res.chain) - 1.0) < 0.1 and abs(np.mean(res.chain)) < 0.1
    assert set(res.diagnostics) == {"rhat", "rhat_walkers", "ess_bulk"}
    assert all(set(v) == set(post.names) for v in res.diagnostics.values())
    assert res.diagnostics == sampler.diagnostics(res.chain, post.names, n_ensembles=3)  # each ensemble a chain
    # the ensembles are independent (their own seeds) and the whole run reproducible from its seed
    first = [res.chain[16 * k : 16 * (k + 1), 0] for k in range(3)]
    assert not np.allclose(first[0], first[1]) and not np.allclose(first[1], first[2])
    again = run_ensembles(_Gauss(3), np.zeros(3), seed=4, **kw)
    np.testing.assert_array_equal(again.chain, res.chain)
    other = run_ensembles(_Gauss(3), np.zeros(3), seed=5, **kw)
    assert not np.allclose(other.chain, res.chain)
    # walkers: at least 16, 4 per dimension above that
    wide = run_ensembles(_Gauss(5), np.zeros(5), seed=4, **{**kw, "n_ensembles": 1})
    assert wide.chain.shape[0] == 20


def test_collect_burns_a_third_or_five_autocorrelation_times_at_most_half():
    """``_collect`` on stand-in samplers whose autocorrelation times are set: burn-in max(n/3, 5 tau) capped
    at n/2, tau the largest over ensembles per parameter, acceptance the mean."""

    class S:
        def __init__(self, tau, acc, n=300, w=4, d=2, off=0.0):
            self.iteration, self._tau, self.acceptance_fraction = n, np.asarray(tau, float), np.full(w, acc)
            self._c = off + np.arange(n * w * d, dtype=float).reshape(n, w, d)

        def get_chain(self):
            return self._c

        def get_log_prob(self):
            return self._c[..., 0] * 10

        def get_autocorr_time(self, tol=0):
            return self._tau

    for taus, burn in (([[4, 9], [3, 2]], 100), ([[4, 24], [3, 2]], 120), ([[4, 80], [3, 2]], 150)):
        res = sampler._collect([S(taus[0], 0.3), S(taus[1], 0.5, off=1e6)])
        np.testing.assert_array_equal(res.tau, np.max(taus, axis=0))
        assert res.burn == burn and res.n_steps == 300 and res.acceptance == 0.4 and res.n_ensembles == 2
        assert res.chain.shape == (8, 300 - burn, 2) and res.log_prob.shape == (8, 300 - burn)
        np.testing.assert_array_equal(res.chain[1, :, 1], S([1], 0).get_chain()[burn:, 1, 1])  # walker 1, step-wise
        np.testing.assert_array_equal(res.chain[4:, 0, 0], 1e6 + S([1], 0).get_chain()[burn, :, 0])  # 2nd ensemble
        np.testing.assert_array_equal(res.log_prob, res.chain[..., 0] * 10)


def test_run_ensembles_stops_when_every_target_is_met_and_says_when_not(monkeypatch):
    """Stops at the first check (min_steps, then every chunk) where the bulk ESS of the first two parameters
    reaches its target, R-hat is at most its target and the run is 50 autocorrelation times long; else runs
    to max_steps and reports converged False with the diagnostics."""
    seen = []

    def fake(ess, rhat):
        def diagnostics(chain, names, **kw):
            seen.append(chain.shape[1])
            return {"rhat": dict.fromkeys(names, rhat), "ess_bulk": {**dict.fromkeys(names, ess), names[-1]: 1.0}}

        return diagnostics

    kw = dict(n_ensembles=1, n_walkers=16, chunk=100, min_steps=300, max_steps=700, progress=False)
    for ess, rhat, target_ess, converged in ((500.0, 1.01, 500.0, True), (499.0, 1.0, 500.0, False)):
        monkeypatch.setattr(sampler, "diagnostics", fake(ess, rhat))
        seen.clear()
        res = run_ensembles(_Gauss(3), np.zeros(3), seed=0, target_ess=target_ess, target_rhat=1.01, **kw)
        assert res.converged is converged and res.diagnostics["rhat"]["x0"] == rhat
        if converged:  # the first check long enough for the autocorrelation time
            assert res.n_steps >= 50 * np.max(res.tau) and (res.n_steps == 300 or res.n_steps - 100 < 50 * max(res.tau))
        else:
            assert res.n_steps == 700 and len(seen) == 5  # 300, then 100 at a time
    monkeypatch.setattr(sampler, "diagnostics", fake(1e4, 1.02))
    res = run_ensembles(_Gauss(3), np.zeros(3), seed=0, target_ess=500.0, target_rhat=1.01, **kw)
    assert res.converged is False and res.n_steps == 700
    # ESS and R-hat met, but 100 steps are fewer than 50 autocorrelation times (about 6 steps here)
    monkeypatch.setattr(sampler, "diagnostics", fake(1e4, 1.0))
    res = run_ensembles(_Gauss(3), np.zeros(3), seed=0, **{**kw, "min_steps": 100, "max_steps": 100})
    assert 100 < 50 * np.max(res.tau) and res.converged is False


def test_a_resumed_run_does_not_redo_the_steps_it_saved(tmp_path):
    kw = dict(n_ensembles=2, n_walkers=16, chunk=100, progress=False, backend_path=tmp_path / "c.h5", seed=1)
    first = _Gauss(2)  # 100 steps: fewer than the checkpoint's flush interval, so the run's end must flush
    run_ensembles(first, np.zeros(2), min_steps=100, max_steps=100, **kw)
    again = _Gauss(2)
    res = run_ensembles(again, np.zeros(2), min_steps=100, max_steps=200, **kw)
    assert res.n_steps == 200
    assert again.calls <= 2 * 100 * 16 + 200  # the 100 new steps of each ensemble (and the start's checks)
    assert first.calls >= 2 * 100 * 16
    done = _Gauss(2)  # a finished run asked again: its saved result, no new step
    res = run_ensembles(done, np.zeros(2), min_steps=100, max_steps=200, **kw)
    assert res.n_steps == 200 and done.calls == 0


def test_a_stuck_walker_lands_beside_another_by_a_thousandth_of_the_spread_per_dimension():
    """Each stuck walker takes a random other walker's place, nudged by N(0, 1e-3 x the ensemble's sd) in
    each dimension independently: distinct walkers, jitter scaled per dimension (here 1 and 100)."""
    rng = np.random.default_rng(2)
    chain = rng.standard_normal((100, 40, 2)) * [1.0, 100.0]
    lp = -0.5 * np.sum((chain / [1.0, 100.0]) ** 2, axis=-1)
    stuck = np.arange(0, 40, 4)  # 10 walkers, far below the rest
    lp[:, stuck] -= 50.0
    out = replace_stuck_walkers(chain, lp, rng)
    good = np.setdiff1d(np.arange(40), stuck)
    spread = np.std(chain[-1, good], axis=0)
    # each moved walker's nearest good walker, in units of 1e-3 of the spread per dimension
    rel = (out[stuck][:, None, :] - chain[-1, good][None, :, :]) / (1e-3 * spread)
    nearest = rel[np.arange(stuck.size), np.argmin(np.sum(rel**2, axis=-1), axis=1)]  # (10, 2)
    assert np.all(np.abs(nearest) < 5.0)  # beside a donor, not a spread away
    assert 0.35 < np.median(np.abs(nearest)) < 1.2  # |N(0, 1)| has median 0.67
    assert not np.allclose(nearest[:, 0], nearest[:, 1])  # each dimension its own draw
    assert len({tuple(np.round(x, 12)) for x in out[stuck]}) == stuck.size  # no two moved walkers alike


def test_the_walkers_restarted_count_every_walker_moved(monkeypatch):
    real = sampler.replace_stuck_walkers

    def three(chain, log_prob, rng, **kw):
        assert kw.get("log_prob_fn") is not None  # the repair checks its nudges against the posterior
        real(chain, log_prob, rng, **kw)
        out = chain[-1].copy()
        out[:3] = out[5] + 1e-6 * np.arange(1, 4)[:, None]
        return out

    monkeypatch.setattr(sampler, "replace_stuck_walkers", three)
    kw = dict(n_ensembles=2, n_walkers=16, chunk=100, min_steps=100, max_steps=100, progress=False)
    assert run_ensembles(_Gauss(2), np.zeros(2), seed=0, **kw).walkers_restarted == (3, 3)


def test_run_ensembles_ignores_numpys_global_random_state():
    """emcee seeds each sampler from numpy's global state; run_ensembles seeds every ensemble itself."""
    kw = dict(n_ensembles=2, n_walkers=16, chunk=100, min_steps=100, max_steps=100, progress=False)
    saved = np.random.get_state()  # noqa: NPY002
    try:
        np.random.seed(0)  # noqa: NPY002 (the global state is what is under test)
        a = run_ensembles(_Gauss(2), np.zeros(2), seed=3, **kw)
        np.random.seed(1)  # noqa: NPY002
        b = run_ensembles(_Gauss(2), np.zeros(2), seed=3, **kw)
    finally:
        np.random.set_state(saved)  # noqa: NPY002
    np.testing.assert_array_equal(a.chain, b.chain)


def test_run_ensembles_never_steps_past_its_budget(monkeypatch):
    def never(chain, names, **kw):
        return {"rhat": dict.fromkeys(names, 2.0), "ess_bulk": dict.fromkeys(names, 1.0)}

    monkeypatch.setattr(sampler, "diagnostics", never)
    kw = dict(n_ensembles=1, n_walkers=16, progress=False)
    assert run_ensembles(_Gauss(2), np.zeros(2), chunk=200, min_steps=300, max_steps=650, **kw).n_steps == 650
    assert run_ensembles(_Gauss(2), np.zeros(2), chunk=100, min_steps=300, max_steps=301, **kw).n_steps == 301


def test_progress_bars_name_each_ensemble(capsys):
    kw = dict(n_ensembles=2, n_walkers=16, chunk=50, min_steps=50, max_steps=50)
    run_ensembles(_Gauss(2), np.zeros(2), seed=0, progress=True, **kw)
    err = capsys.readouterr().err
    assert "ensemble 1/2" in err and "ensemble 2/2" in err


def test_the_defaults_every_fit_samples_with_are_the_documented_ones():
    """``fit`` and ``fit_group`` take the ensemble count, chunk, step budget and targets from these defaults;
    docs/inference.md ("Sampling") states them to the user."""
    import inspect
    from pathlib import Path

    got = {k: v.default for k, v in inspect.signature(run_ensembles).parameters.items() if v.default is not v.empty}
    want = dict(n_ensembles=4, chunk=500, max_steps=8000, min_steps=1000, target_ess=1000.0, target_rhat=1.01)
    assert {k: got[k] for k in want} == want
    doc = " ".join((Path(__file__).parents[1] / "docs" / "inference.md").read_text().split())
    for phrase in (
        "Four independent emcee ensembles",
        "chunks of 500 steps",
        "bulk ESS of EI0 and p is at least 1000",
        "R-hat <= 1.01",
        "or 8000 steps",
        "(the minimum steps, 1000)",
    ):
        assert phrase in doc


def test_every_ensemble_of_a_run_has_its_own_random_state():
    """Two ensembles with one random state would propose alike and understate R-hat."""
    for seed in (0, 1, 4, 7919, 2**31 + 5):
        seeds = sampler.ensemble_seeds(seed, 8)
        assert len(set(seeds)) == 8 and all(0 <= x < 2**32 for x in seeds)
    assert sampler.ensemble_seeds(3, 4) != sampler.ensemble_seeds(4, 4)


def test_a_run_exactly_fifty_autocorrelation_times_long_is_long_enough(monkeypatch):
    """The stopping rule's length test is n_steps >= 50 tau: at tau = n_steps / 50 the run stops."""
    real = sampler._collect

    def collect(samplers):
        res = real(samplers)
        res.tau = np.full_like(res.tau, res.n_steps / 50.0)
        return res

    monkeypatch.setattr(sampler, "_collect", collect)
    monkeypatch.setattr(
        sampler,
        "diagnostics",
        lambda chain, names, **kw: {"rhat": dict.fromkeys(names, 1.0), "ess_bulk": dict.fromkeys(names, 1e4)},
    )
    kw = dict(n_ensembles=1, n_walkers=16, chunk=100, min_steps=200, max_steps=400, progress=False)
    res = run_ensembles(_Gauss(2), np.zeros(2), seed=0, **kw)
    assert res.converged is True and res.n_steps == 200


def test_rhat_over_walkers_is_what_their_autocorrelation_time_gives():
    """Walkers as chains, each an independent AR(1) with autocorrelation time tau: R-hat^2 - 1 is about
    2 tau / (kept steps) (split chains of half the length), so R-hat alone falls to 1.01 only after about 100
    tau kept steps; steps_needed reads it that way."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(0)
    n, tau = 2000, 60.0
    rho = (tau - 1) / (tau + 1)
    x = lfilter([1.0], [1.0, -rho], rng.standard_normal((224, n + 600)), axis=1)[:, 600:] * np.sqrt(1 - rho**2)
    rhat = sampler.diagnostics(x[:, :, None], ["a"])["rhat_walkers"]["a"]
    assert rhat == pytest.approx(np.sqrt(1 + 2 * (tau - 1) / n), abs=0.004), rhat  # 1.0292
    # so many more steps: R-hat 1.07 after 6000 steps asks for (1.07^2 - 1) / (1.01^2 - 1) = 7.2 times as many
    assert sampler.steps_needed(6000, 1.07, 5000.0, 100.0) == 44000
    assert sampler.steps_needed(5000, 1.005, 250.0, 50.0, target_ess=1000) == 20000  # ESS grows as steps
    assert sampler.steps_needed(5000, 1.005, 5000.0, 500.0) == 25000  # emcee's 50 tau
    assert sampler.steps_needed(8000, 1.0, 5000.0, 10.0) == 9000  # never fewer than were run


class _Orthant:
    """A standard normal restricted to the positive orthant of 12 dimensions: a start at the origin sits on the
    boundary in every coordinate, so a nudge about it lands inside with probability 2^-12."""

    ndim = 12

    def log_prob(self, theta):
        t = np.atleast_2d(theta)
        out = np.where(np.all(t >= 0.0, axis=-1), -0.5 * np.sum(t**2, axis=-1), -np.inf)
        return out if np.ndim(theta) > 1 else out[0]


def test_the_start_ball_never_leaves_a_walker_outside_the_support():
    """A walker the ball cannot nudge inside in 100 draws starts on the start itself: emcee would keep one at
    -inf and warn of inf - inf at every step (one of 56 walkers of a four-condition group fit, session 50)."""
    post = _Orthant()
    out = sampler._ball(np.zeros(12), 32, np.random.default_rng(0), post)
    assert np.isfinite(post.log_prob(out)).all()
    assert np.all(out == 0.0, axis=1).sum() >= 30  # (1 - 2^-12)^100: almost every one falls back


def test_a_stuck_walker_nudged_outside_the_support_stays_on_its_donor():
    """Donors on the support's boundary: with the posterior's density at hand, a nudge outside is not taken."""
    rng = np.random.default_rng(3)
    post = _Orthant()
    chain = np.abs(rng.standard_normal((100, 40, 12)))
    stuck = np.arange(0, 40, 4)
    chain[-1, ::2, 0] = 0.0  # half the walkers' last positions on the boundary x0 = 0
    lp = post.log_prob(chain.reshape(-1, 12)).reshape(100, 40)
    lp[:, stuck] -= 100.0
    out = replace_stuck_walkers(chain, lp, np.random.default_rng(4), log_prob_fn=post.log_prob)
    assert np.isfinite(post.log_prob(out)).all()
    good = np.setdiff1d(np.arange(40), stuck)
    for w in stuck:  # on a donor exactly, or nudged inside
        assert out[w, 0] >= 0.0
    assert any(any(np.array_equal(out[w], chain[-1, g]) for g in good) for w in stuck)
    blind = replace_stuck_walkers(chain, lp, np.random.default_rng(4))  # without the density: half land outside
    assert not np.isfinite(post.log_prob(blind)).all()


def test_the_convergence_rhat_reads_each_ensemble_as_a_chain_and_the_walkers_guard_what_it_cannot():
    """Four ensembles of 56 walkers, each walker an AR(1) of autocorrelation time 60 over 2000 kept steps
    (as the two-height group fit of docs/validation.md "Convergence: the ensembles as chains"): over walkers
    R-hat reads 1.03, their autocorrelation, with the ensembles as chains 1.000, and the run meets its targets
    once 50 tau long. One ensemble whose walkers sit 0.5 sd off: the ensembles' R-hat misses its target.
    Six walkers 5 sd apart: the ensembles' R-hat does not see them, the walkers' guard (1.1) does; a walker
    whose log density stays 40 nats down is counted stuck."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(0)
    n, tau = 2000, 60.0
    rho = (tau - 1) / (tau + 1)
    x = lfilter([1.0], [1.0, -rho], rng.standard_normal((224, n + 600)), axis=1)[:, 600:] * np.sqrt(1 - rho**2)
    d = sampler.diagnostics(x[:, :, None], ["a"], n_ensembles=4)
    assert d["rhat"]["a"] < 1.002 and d["rhat_walkers"]["a"] == pytest.approx(1.029, abs=0.004), d
    # read on every second step (max_draws 1000): the same numbers as the whole chain, to within their noise
    whole = sampler.diagnostics(x[:, :, None], ["a"], n_ensembles=4, max_draws=n)
    assert d == sampler.diagnostics(x[:, ::2, None], ["a"], n_ensembles=4, max_draws=n) != whole
    assert abs(whole["rhat_walkers"]["a"] - d["rhat_walkers"]["a"]) < 0.002
    assert abs(whole["ess_bulk"]["a"] / d["ess_bulk"]["a"] - 1) < 0.05, (whole, d)
    assert sampler.missed_targets(d, 3000, np.array([tau]), 400.0, 1.01, ["a"]) == []
    assert sampler.missed_targets(d, 2999, np.array([tau]), 400.0, 1.01, ["a"]) != []  # 50 tau
    assert sampler.missed_targets(d, 3000, np.array([tau]), 400.0, 1.01, ["a"], n_stuck=1) != []
    assert sampler.missed_targets(d, 3000, np.array([tau]), d["ess_bulk"]["a"] + 1, 1.01, ["a"]) != []
    off = x.copy()
    off[:56] += 0.5
    d = sampler.diagnostics(off[:, :, None], ["a"], n_ensembles=4)
    assert d["rhat"]["a"] > 1.02 and d["rhat_walkers"]["a"] < 1.1, d
    assert [m.split(" ")[0] for m in sampler.missed_targets(d, 3000, np.array([tau]), 400.0, 1.01, ["a"])] == ["R-hat"]
    apart = x.copy()
    apart[:6] += 5.0
    d = sampler.diagnostics(apart[:, :, None], ["a"], n_ensembles=4)
    assert d["rhat"]["a"] < 1.01 and d["rhat_walkers"]["a"] > 1.1, d
    (m,) = sampler.missed_targets(d, 3000, np.array([tau]), 400.0, 1.01, ["a"])
    assert "walkers disagree" in m
    lp = -0.5 * x.T**2  # (steps, walkers)
    lp[:, 3] -= 40.0
    assert np.flatnonzero(sampler.stuck_walkers(lp, 1)).tolist() == [3]
    with pytest.raises(ValueError, match="n_ensembles"):
        sampler.diagnostics(x[:, :, None], ["a"], n_ensembles=5)


def test_a_run_with_a_walker_stuck_at_its_end_has_not_converged(monkeypatch):
    """The criterion counts stuck walkers over the kept steps of every ensemble (:func:`count_stuck`)."""
    kw = dict(n_ensembles=2, n_walkers=16, chunk=100, min_steps=300, max_steps=400, progress=False, target_ess=1.0)
    diag = {"rhat": {"x0": 1.0}, "ess_bulk": {"x0": 1e4}}
    monkeypatch.setattr(sampler, "diagnostics", lambda chain, names, **k: diag)
    assert run_ensembles(_Gauss(1), np.zeros(1), seed=0, **kw).converged is True
    real = sampler.stuck_walkers
    monkeypatch.setattr(sampler, "stuck_walkers", lambda lp, ndim, p_miss=1e-6: real(lp, ndim) | (np.arange(16) == 5))
    res = run_ensembles(_Gauss(1), np.zeros(1), seed=0, **kw)
    assert res.converged is False and res.n_steps == 400 and sampler.count_stuck(res) == 2
    assert "2 walker(s) stuck" in sampler.convergence_message(res, 400, 1.0)


def test_steps_needed_at_its_edges():
    """The advice's step count (the not-converged message): one step more than was run, rounded up to 1000; the
    ESS target's default 1000; a NaN or infinite R-hat or tau, and an ESS of 0, leave their term out (ArviZ gives
    them for chains that never moved); an ESS below 1 still counts."""
    assert sampler.steps_needed(999, 1.0, 5000.0, 1.0) == 1000
    assert sampler.steps_needed(1000, 1.0, 500.0, 1.0) == 2000  # 1000 x 1000 / 500
    assert sampler.steps_needed(1000, 1.0, 5000.0, float("nan")) == 2000
    assert sampler.steps_needed(1000, float("inf"), 5000.0, 1.0) == 2000
    assert sampler.steps_needed(1000, 1.0, 0.0, 1.0) == 2000
    assert sampler.steps_needed(1000, 1.0, 0.5, 1.0) == 2_000_000


def test_the_not_converged_message_names_each_missed_target_and_the_steps_they_need():
    """convergence_message on a result made by hand: the targets' numbers as missed_targets words them, the ESS
    of the first two parameters only (the ones run_ensembles targets), R-hat against 1.01 by default, and the
    steps steps_needed gives for this run's own numbers; a converged run, none; a run stopped with nothing
    missed, the targets themselves."""
    n_walkers, n_draws = 8, 50
    diag = {
        "rhat": {"EI0": 1.02, "p": 1.0, "sigma": 1.0},
        "rhat_walkers": {"EI0": 1.5, "p": 1.0, "sigma": 1.0},
        "ess_bulk": {"EI0": 500.0, "p": 800.0, "sigma": 100.0},
    }
    res = sampler.SamplingResult(
        chain=np.zeros((n_walkers, n_draws, 3)),
        log_prob=np.zeros((n_walkers, n_draws)),
        n_steps=2000,
        burn=500,
        tau=np.array([10.0, 20.0, 45.0]),
        acceptance=0.3,
        n_ensembles=2,
        diagnostics=diag,
        converged=False,
    )
    msg = sampler.convergence_message(res, 2000, 1000.0)
    need = sampler.steps_needed(2000, 1.02, 500.0, 45.0, 1.01, 1000.0, 1.5)
    assert need == 12000  # the walkers' R-hat decides: 2000 x (1.5^2 - 1) / (1.1^2 - 1) = 11905 (R-hat: 4020)
    assert msg == (
        "not converged within 2000 steps (R-hat max 1.0200 with the ensembles as chains, target 1.01; R-hat over "
        "walkers 1.500, above 1.1: walkers disagree; bulk ESS of EI0 and p 500, target 1000; 2000 steps, fewer "
        "than 50 autocorrelation times (2250)): treat the intervals as provisional and rerun with more steps (at "
        "this run's rate, at least about 12000 in all)"
    )
    assert sampler.convergence_message(dataclasses.replace(res, converged=True), 2000, 1000.0) is None
    met = {"rhat": dict.fromkeys(diag["rhat"], 1.0), "ess_bulk": dict.fromkeys(diag["rhat"], 1e4)}  # no walkers' R-hat
    short = dataclasses.replace(res, diagnostics=met, tau=np.array([1.0, 1.0, 1.0]))
    assert sampler.convergence_message(short, 2000, 1000.0) == (
        "not converged within 2000 steps (R-hat target 1.01, bulk ESS target 1000): treat the intervals as "
        "provisional and rerun with more steps (at this run's rate, at least about 3000 in all)"
    )


def test_stuck_walkers_are_read_over_the_second_half_and_counted_in_every_ensemble():
    lp = np.zeros((100, 10))  # (steps, walkers)
    lp[:50, 0] = -1000.0  # far below early on, with the others since: not stuck
    lp[:, 7] = -1000.0
    assert np.flatnonzero(sampler.stuck_walkers(lp, 2)).tolist() == [7]
    # count_stuck: the result's (chains, draws), each ensemble's walkers contiguous; one stuck in each of two
    chains = np.zeros((2 * 10, 100))
    chains[3] = chains[15] = -1000.0
    res = sampler.SamplingResult(np.zeros((20, 100, 2)), chains, 300, 200, np.ones(2), 0.3, n_ensembles=2)
    assert sampler.count_stuck(res) == 2


def test_the_start_ball_keeps_walkers_nudged_inside_a_half_space_and_within_a_few_thousandths():
    class HalfSpace:
        def log_prob(self, theta):
            return 0.0 if theta[0] >= 0.0 else -np.inf

    out = sampler._ball(np.zeros(3), 64, np.random.default_rng(1), HalfSpace())
    assert np.all(out[:, 0] >= 0.0)
    assert np.sum(np.all(out == 0.0, axis=1)) == 0  # half the nudges land inside: none falls back to the start
    assert 5e-4 < np.std(out[:, 1:]) < 2e-3 and np.abs(out).max() < 1e-2  # N(0, 1e-3) per coordinate

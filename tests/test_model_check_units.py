"""The model check of summary.json ("does the fit fit?", bayesrod/inference/checks.py) on residuals made by hand.

A stand-in likelihood returns fixed residuals (shifted per draw by an offset parameter), so every number of the
``model_check`` block can be computed here from its definition: the lag-1 autocorrelation, the longest run of one
sign, the standardised (AR(1)-whitened) innovations, the posterior predictive p-values and the verdict at
alpha / 2. Written for the mutation target ``checks`` (scripts/mutation.py).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from bayesrod.inference.checks import _lag1, _longest_run, model_check, standardised_innovations
from bayesrod.inference.likelihood import _chain_starts


class _Lik:
    """Residuals r - offset per draw, pushes by ``F_push``; ``force_noise`` iid or ar1."""

    def __init__(self, r, F_push, force_noise="iid"):
        self.r = np.asarray(r, float)
        self.F_push = np.asarray(F_push)
        self.F_first = _chain_starts(self.F_push)
        self.n_force = self.r.size
        self.force_noise = force_noise
        self.data = [SimpleNamespace(id=f"push-{j}") for j in range(int(self.F_push.max()) + 1)]

    def residuals(self, params):
        off = np.atleast_1d(params["offset"])[:, None]
        return {"force": self.r[None, :] - off}


def _lag1_by_hand(x):
    x = np.asarray(x, float) - np.mean(x)
    return float(np.sum(x[1:] * x[:-1]) / np.sum(x**2))


def _run_by_hand(x):
    best = cur = 1
    for a, b in zip(x[:-1], x[1:], strict=True):
        cur = cur + 1 if np.sign(a) == np.sign(b) else 1
        best = max(best, cur)
    return best


def test_lag1_and_longest_run_by_hand():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(3, 17)) + np.linspace(0, 2, 17)
    np.testing.assert_allclose(_lag1(z), [_lag1_by_hand(row) for row in z], rtol=1e-12)
    assert _lag1(np.array([1.0, -1.0])) == 0.0  # fewer than 3 samples
    assert _lag1(np.ones((4, 2))).shape == (4,) and not _lag1(np.ones((4, 2))).any()  # per row
    x3 = np.array([1.0, 3.0, -2.0])
    assert _lag1(x3) == pytest.approx(_lag1_by_hand(x3), rel=1e-12) != 0.0  # three are enough
    assert _lag1(1e-3 * z[0]) == pytest.approx(_lag1(z[0]), rel=1e-9)  # scale-free, also below 1
    assert _lag1(np.full(5, 2.0)) == 0.0  # no spread: 0, not nan
    x = np.array([1.0, 2.0, -1.0, -3.0, -2.0, 4.0, 5.0, -1.0])
    assert _longest_run(x) == 3 == _run_by_hand(x)
    np.testing.assert_array_equal(_longest_run(np.vstack([x, -x, np.ones(8)])), [3, 3, 8])
    assert _longest_run(np.array([1.0, -1.0, 1.0])) == 1


def test_innovations_are_the_residuals_over_sigma_or_whitened_per_push_under_ar1():
    rng = np.random.default_rng(1)
    r, push = rng.normal(size=12), np.repeat([0, 1, 2], 4)
    params = {"offset": np.array([0.0, 0.3]), "sigma_force_N": np.array([0.5, 2.0]), "rho_force": np.array([0.6, -0.2])}
    z = standardised_innovations(_Lik(r, push), params)
    np.testing.assert_allclose(z, (r[None] - params["offset"][:, None]) / params["sigma_force_N"][:, None])
    z = standardised_innovations(_Lik(r, push, "ar1"), params)
    for w in range(2):
        e = r - params["offset"][w]
        s, rho = params["sigma_force_N"][w], params["rho_force"][w]
        ref = np.empty(12)
        for t in range(12):
            first = t % 4 == 0
            ref[t] = e[t] / s if first else (e[t] - rho * e[t - 1]) / (s * np.sqrt(1 - rho**2))
        np.testing.assert_allclose(z[w], ref, rtol=1e-12)


def _draws(n=300, seed=2, sd=1.0):
    rng = np.random.default_rng(seed)
    return {"offset": rng.normal(0, 0.02, n), "sigma_force_N": sd * np.exp(rng.normal(0, 0.02, n))}


def test_white_residuals_pass_and_each_pushs_numbers_are_those_at_the_median():
    rng = np.random.default_rng(3)
    push = np.repeat([0, 1, 2, 3], [40, 2, 50, 3])  # the 2-sample push is too short to check, 3 are enough
    r = rng.normal(size=push.size)
    draws = _draws()
    out = model_check(_Lik(r, push), draws, n_draws=150, alpha=0.01, seed=4)
    assert out["verdict"] == "ok" and "message" not in out
    assert out["noise_model"] == "iid" and out["alpha"] == 0.01 and out["draws"] == 150
    assert [p["push"] for p in out["pushes"]] == ["push-0", "push-2", "push-3"]
    z_med = (r - np.median(draws["offset"])) / np.median(draws["sigma_force_N"])
    for p, sel in zip(out["pushes"], (push == 0, push == 2, push == 3), strict=True):
        assert p["n"] == sel.sum()
        assert p["residual_lag1"] == pytest.approx(_lag1_by_hand(r[sel] - np.median(draws["offset"])), rel=1e-12)
        assert p["innovation_lag1"] == pytest.approx(_lag1_by_hand(z_med[sel]), rel=1e-12)
        assert p["longest_run"] == _run_by_hand(z_med[sel])
        assert p["rmse_over_sigma"] == pytest.approx(np.sqrt(np.mean(z_med[sel] ** 2)), rel=1e-12)
    assert 0.05 < out["ppc_p_value_lag1"] < 1 and 0.05 < out["ppc_p_value_runs"] <= 1
    assert model_check(_Lik(r, push), _draws(n=80), n_draws=150)["draws"] == 80  # no more draws than there are
    # the defaults: 200 draws, alpha 0.01, seed 0; a likelihood that names no noise model is iid
    default = model_check(_Lik(r, push), _draws(n=1000))
    assert default["draws"] == 200 and default["alpha"] == 0.01
    assert default == model_check(_Lik(r, push), _draws(n=1000), n_draws=200, alpha=0.01, seed=0)
    unnamed = _Lik(r, push)
    del unnamed.force_noise
    assert model_check(unnamed, draws, n_draws=150, seed=4)["noise_model"] == "iid"
    # pushes all too short to check: nothing observed, nothing called a misfit
    short = model_check(_Lik(rng.normal(size=6), np.repeat([0, 1, 2], 2)), draws)
    assert short["verdict"] == "ok" and short["pushes"] == [] and short["ppc_p_value_lag1"] == 1.0


def test_structured_residuals_fail_and_the_message_names_the_worst_push():
    push = np.repeat([0, 1], 60)
    t = np.linspace(0, 1, 60)
    rng = np.random.default_rng(5)
    r = np.r_[rng.normal(size=60), 3 * np.sin(2 * np.pi * t) + 0.3 * rng.normal(size=60)]
    out = model_check(_Lik(r, push), _draws(), seed=1)
    assert out["verdict"] == "misfit" and out["ppc_p_value_lag1"] == 0.0
    assert "push push-1" in out["message"] and "force_noise ar1" in out["message"]
    assert "whitening" not in out["message"]
    worst = out["pushes"][1]
    assert f"lag-1 autocorrelation {worst['residual_lag1']:.2f}," in out["message"]
    assert f"a run of {worst['longest_run']} residuals" in out["message"]
    # fitted as AR(1) the message says so, and does not ask for what was done
    ar = model_check(_Lik(r, push, "ar1"), {**_draws(), "rho_force": np.full(300, 0.1)}, seed=1)
    assert ar["verdict"] == "misfit" and ar["noise_model"] == "ar1"
    assert "after AR(1) whitening" in ar["message"] and "force_noise ar1" not in ar["message"]
    # a model with no forces checks nothing
    none = model_check(SimpleNamespace(n_force=0), {})
    assert none == {"verdict": "ok", "checked": "nothing (no force samples)", "pushes": []}


def test_the_verdict_is_misfit_below_half_alpha_and_the_p_values_are_predictive_tail_areas():
    """p = P(T_rep >= T_obs) over the draws: the share of replicate statistics at least the observed one."""
    push = np.repeat([0, 1], 50)
    rng = np.random.default_rng(11)
    e = rng.normal(size=100)
    r = e.copy()
    r[1:] += 0.35 * e[:-1]  # mildly correlated: a p-value between the extremes
    draws = _draws(n=400)
    out = model_check(_Lik(r, push), draws, n_draws=400, seed=6)
    p = min(out["ppc_p_value_lag1"], out["ppc_p_value_runs"])
    assert 0.005 < p < 0.4
    assert model_check(_Lik(r, push), draws, n_draws=400, seed=6, alpha=1.9 * p)["verdict"] == "ok"
    assert model_check(_Lik(r, push), draws, n_draws=400, seed=6, alpha=2.1 * p)["verdict"] == "misfit"
    assert model_check(_Lik(r, push), draws, n_draws=400, seed=6, alpha=2 * p)["verdict"] == "ok"  # strictly below
    # the p-value of lag 1 by hand, with the replicates the check draws (its seed's generator, after the subset)
    rng = np.random.default_rng(6)
    idx = rng.choice(400, size=400, replace=False)
    zr = rng.standard_normal((400, 100))
    z = (r[None] - draws["offset"][idx, None]) / draws["sigma_force_N"][idx, None]
    T_obs = sum(50 * _lag1(z[:, push == j]) ** 2 for j in (0, 1))
    T_rep = sum(50 * _lag1(zr[:, push == j]) ** 2 for j in (0, 1))
    assert out["ppc_p_value_lag1"] == pytest.approx(np.mean(T_rep >= T_obs), abs=1e-12)
    runs_obs = np.max([_longest_run(z[:, push == j]) / np.log2(50) for j in (0, 1)], axis=0)
    runs_rep = np.max([_longest_run(zr[:, push == j]) / np.log2(50) for j in (0, 1)], axis=0)
    assert out["ppc_p_value_runs"] == pytest.approx(np.mean(runs_rep >= runs_obs), abs=1e-12)


def test_white_noise_is_called_a_misfit_at_about_the_stated_rate():
    """Calibration: over white-noise data the p-values are about uniform (both tails of their histogram)."""
    push = np.repeat([0, 1, 2], 30)
    p_lag, p_run = [], []
    for seed in range(60):
        rng = np.random.default_rng(100 + seed)
        out = model_check(_Lik(rng.normal(size=90), push), _draws(n=200, seed=seed), seed=seed)
        p_lag.append(out["ppc_p_value_lag1"])
        p_run.append(out["ppc_p_value_runs"])
    for ps in (np.array(p_lag), np.array(p_run)):
        assert 0.3 < np.mean(ps) < 0.7
        assert 2 <= np.sum(ps < 0.25) <= 27 and 2 <= np.sum(ps > 0.75) <= 27

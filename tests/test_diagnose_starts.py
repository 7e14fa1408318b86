"""Diagnosis, issue 19: where the fits start. A plain fit must leave its grid start, and a soft base
hidden behind a uniform taper must still be found (docs/diagnose.md, steps 1 and 2)."""

from types import SimpleNamespace

import numpy as np
import pytest

import bayesrod
from bayesrod.inference import diagnose as D
from bayesrod.inference.diagnose import Diagnoser, ForwardModel
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects

TWIG_EI0, TWIG_P = 2.63, 0.43  # the twig preset's stem


def _ar_twig(seed, effects=None, **overrides):
    spec = bayesrod.simulate(
        "twig",
        seed=seed,
        effects=Effects.from_mapping(effects or {}),
        noise_rho=0.9,
        config_overrides={"specimen": "s", "n_frames_engaged": 8, **overrides},
    )
    return ForwardModel(prepare_data(spec, use_shapes=False), spec.length_m)


def test_plain_fit_leaves_its_grid_start_under_correlated_noise():
    # the AR study's clean case 100: profiled at the table start, rho was 0.977 and the fit never moved
    # (10 nats below its optimum); with independent weights first it reaches the fit started at the truth
    # (stuck: p 0.45000, rho 0.977; the fit started at the truth: p 0.4306, rho 0.887)
    dg = Diagnoser(_ar_twig(100), "ar1")
    fit = dg.fit_plain()
    assert fit.natural(1.0)["p"] == pytest.approx(TWIG_P, abs=0.01)
    assert 0.8 < fit.rho_force < 0.95


def test_compliance_grid_start_finds_the_soft_base_behind_a_uniform_taper():
    # a twig on a base spring k_b = 8 N m/rad: the plain optimum is a uniform rod (p = 0) of a third of
    # the true EI0; the grid over (p, c) starts in the compliant stem's basin
    m = _ar_twig(12, {"base_compliance": 8.0}, n_force_engaged=30, heights_m=(0.45, 0.6))
    dg = Diagnoser(m, "ar1")
    x_plain = dg.start()  # the plain fit goes no further (p 1e-16, EI0 0.785)
    assert x_plain[1] == 0.0 and np.exp(x_plain[0]) < 0.4 * TWIG_EI0
    plain = SimpleNamespace(x=x_plain, r_force=dg.raw_residuals(x_plain, ())[0])
    x = dg.grid_start("base_compliance", plain)
    c_true = TWIG_EI0 / (8.0 * m.length_m)
    # a coarse start (c 0.13 for 0.41, p 0.25): the fit from it reaches k_b 8.3 on this stem
    assert 0.25 * c_true <= x[-1] <= 2.0 * c_true and 0.1 <= x[1] <= 0.8

    def profiled(x, effects):
        rf, rs = dg.raw_residuals(x, effects)
        return dg.loglik(rf, rs, dg.profile_noise(rf, rs))

    assert profiled(x, ("base_compliance",)) > profiled(x_plain, ()) + 5.0
    assert dg.grid_start("force_offset", plain) is None


def test_a_grid_started_candidate_is_fitted_from_its_grid_too_and_the_better_fit_kept(monkeypatch):
    # plumbing: a candidate with a grid start is fitted from it (independent weights first) beside the local
    # start, and the better fit is judged; one refitted only for its grid gets the grid's fit alone
    calls = []

    class FakeDiagnoser:
        def fit(self, effects, x0, max_nfev=40, ols_first=False):
            calls.append((effects, float(x0[0]), ols_first))
            ll = 50.0 if x0[0] == 9.0 else 1.0
            return SimpleNamespace(loglik=ll, natural=lambda L, ll=ll: {"loglik": ll})

    monkeypatch.setattr(D, "_no_worse_start", lambda dg, cur, effects, starts: np.array([0.0, 0.0, 0.0]))
    cur = SimpleNamespace(effects=(), loglik=0.0)
    grid = np.array([9.0, 9.0, 9.0])
    gate = (1e-3, 1, 1.0)
    row, ok = D._candidate_lr(FakeDiagnoser(), cur, ("base_compliance",), [0.04], grid, *gate)
    assert calls == [(("base_compliance",), 0.0, False), (("base_compliance",), 9.0, True)]
    assert row["fitted"] == {"loglik": 50.0} and ok.loglik == 50.0
    calls.clear()
    D._candidate_lr(FakeDiagnoser(), cur, ("yield",), None, grid, *gate)
    assert calls == [(("yield",), 9.0, True)]
    calls.clear()
    row, ok = D._candidate_lr(FakeDiagnoser(), cur, ("force_offset",), [0.1], None, *gate)
    assert calls == [(("force_offset",), 0.0, False)] and ok is None


def _fake_fit(effects=()):
    """A stand-in for a MapFit: what the loop reads of a fit."""
    f = SimpleNamespace(
        effects=effects, loglik=0.0, sigma_force=0.1, marginal_sigma_force=0.2, rho_force=0.9, shape_scale=1.0
    )
    f.natural = lambda L: {"EI0": 1.0, "p": 0.5}
    return f


def _fake_diagnoser(score, grid_start=lambda effect, fit: None):
    """A Diagnoser for the loop's plumbing: a plain fit, held-out RMSE 1, no structure, the given screen."""

    class FakeDiagnoser:
        def __init__(self, model, force_noise):
            self.plain = _fake_fit()

        def fit_plain(self):
            return self.plain

        def errors(self, fit, pool=None):
            return {"heldout_force_rmse_N": 1.0}, []

        def structure(self, fit, ratio):
            return {"blocks": [], "unexplained_structure": False}

        def score(self, fit, effect):
            return score(fit, effect)

        def grid_start(self, effect, fit):
            return grid_start(effect, fit)

    return FakeDiagnoser


def test_round_one_refits_a_grid_started_effect_the_screen_passed_over(monkeypatch):
    # plumbing of the loop: while the model is plain, an effect with a grid start is refitted from that
    # start alone even when its screen does not pass; one without a grid start is not refitted
    jobs = []

    def candidate_fit(dg, cur, effects, starts, grid, *rest):
        jobs.append((effects, starts, None if grid is None else grid.tolist()))
        return {"lr_statistic": 0.0, "rejected_because": "likelihood ratio below the threshold"}, None

    def score(fit, effect):
        return {
            "statistic": 40.0 if effect == "force_offset" else 0.0,
            "p_value": 1e-9 if effect == "force_offset" else 1.0,
            "direction": 1.0,
        }

    grid = lambda effect, fit: np.array([1.0, 2.0, 3.0]) if effect == "yield" else None  # noqa: E731
    monkeypatch.setattr(D, "Diagnoser", _fake_diagnoser(score, grid))
    monkeypatch.setattr(D, "_candidate_lr", candidate_fit)
    r = D.diagnose(SimpleNamespace(length_m=1.0), candidates=("force_offset", "yield", "base_compliance"))
    assert sorted(jobs, key=str) == sorted(
        [(("force_offset",), [pytest.approx(0.2)], None), (("yield",), None, [1.0, 2.0, 3.0])], key=str
    )
    rows = {c["effect"]: c for c in r["candidates"]}
    assert rows["yield"].get("refitted_from_grid") and "refitted_from_grid" not in rows["base_compliance"]
    assert r["added_effects"] == []


def test_the_heldout_gate_runs_in_decreasing_likelihood_ratio_and_keeps_the_first_pass():
    # the decision is that of gating every candidate and keeping the passing one with the largest
    # likelihood ratio (ties: the first in screen order); no candidate below the kept one is gated
    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(1, 7))
        lrs = rng.integers(0, 4, n).astype(float)  # ties are common
        passes = rng.random(n) < 0.4
        cands = [((f"e{i}",), {"lr_statistic": lrs[i]}, i) for i in range(n)]
        gated = []

        def gate(row, fit, gated=gated, passes=passes):
            gated.append(fit)
            return ("kept", fit) if passes[fit] else None

        got = D._first_passing(cands, gate)
        ok = [i for i in range(n) if passes[i]]
        if not ok:
            assert got is None and sorted(gated) == list(range(n))
            assert not any("heldout_not_run" in c[1] for c in cands)
            continue
        best = max(ok, key=lambda i: (lrs[i], -i))
        assert got == ((f"e{best}",), ("kept", best), cands[best][1])
        order = sorted(range(n), key=lambda i: -lrs[i])
        assert gated == order[: order.index(best) + 1]
        assert {i for i in range(n) if cands[i][1].get("heldout_not_run")} == set(order[order.index(best) + 1 :])


def test_the_loop_gates_held_out_in_ratio_order_and_adds_the_first_that_passes(monkeypatch):
    # plumbing of the loop: three candidates pass the likelihood ratio (LR 18, 30, 20); the held-out gate
    # fails the largest and passes the next, which is added; the smallest is never held out, and is named as
    # an alternative the data do not tell apart (LR within 2 ln 10), the rejected larger one is not
    lrs = {"force_offset": 18.0, "yield": 30.0, "base_compliance": 20.0}

    def candidate_lr(dg, cur, effects, starts, grid, level, dof, L):
        return {"lr_statistic": lrs[effects[0]], "fitted": {}}, _fake_fit(effects)

    gated = []

    def heldout_gate(dg, cur, new, row, *rest):
        gated.append(new.effects[0])
        if new.effects[0] == "yield":
            row["rejected_because"] = "held-out error not reduced"
            return None
        return new, {"heldout_force_rmse_N": 0.5}, []

    def score(fit, effect):  # every candidate passes the screen in round 1, none after
        return {"statistic": 40.0, "p_value": 1e-9 if not fit.effects else 1.0, "direction": 1.0}

    monkeypatch.setattr(D, "Diagnoser", _fake_diagnoser(score))
    monkeypatch.setattr(D, "_candidate_lr", candidate_lr)
    monkeypatch.setattr(D, "_heldout_gate", heldout_gate)
    r = D.diagnose(SimpleNamespace(length_m=1.0), candidates=tuple(lrs))
    assert gated == ["yield", "base_compliance"] and r["added_effects"] == ["base_compliance"]
    rows = {c["effect"]: c for c in r["candidates"] if c["round"] == 1}
    assert rows["base_compliance"]["selected"] and rows["yield"]["rejected_because"] == "held-out error not reduced"
    assert rows["force_offset"]["heldout_not_run"] and not rows["yield"].get("heldout_not_run")
    assert rows["force_offset"]["rejected_because"] == "a better-fitting effect was added"
    assert r["alternatives"] == {"base_compliance": ["force_offset"]}
    assert rows["force_offset"]["indistinguishable_from_added"] and "indistinguishable_from_added" not in rows["yield"]


def test_the_likelihood_ratio_gate_of_a_candidate(monkeypatch):
    # the ratio is 2 (loglik new - loglik current), compared with chi^2 at the round's level (a ratio exactly
    # at the threshold fails), the budget is 12 evaluations for the slow effects and 40 for the others, the
    # fitted values are read at the given length, and a fit below the current model says so
    from scipy import stats

    calls = []

    class FakeDiagnoser:
        def __init__(self, ll):
            self.ll = ll

        def fit(self, effects, x0, max_nfev=40, ols_first=False):
            calls.append((effects, max_nfev))
            return SimpleNamespace(loglik=self.ll, natural=lambda L: {"L": L})

    monkeypatch.setattr(D, "_no_worse_start", lambda dg, cur, effects, starts: np.zeros(3))
    cur = SimpleNamespace(effects=("yield",), loglik=5.0)
    row, new = D._candidate_lr(FakeDiagnoser(50.0), cur, ("force_offset",), [0.1], None, 1e-3, 1, 0.9)
    assert row == {"lr_statistic": 90.0, "fitted": {"L": 0.9}} and new.loglik == 50.0
    assert calls == [(("yield", "force_offset"), 40)]
    calls.clear()
    D._candidate_lr(FakeDiagnoser(50.0), cur, ("contact_friction",), None, np.zeros(3), 1e-3, 1, 0.9)
    D._candidate_lr(FakeDiagnoser(50.0), cur, ("self_weight",), [0.1], None, 1e-3, 1, 0.9)
    assert calls == [(("yield", "contact_friction"), 12), (("yield", "self_weight"), 12)]
    thr = stats.chi2.isf(2e-3, 2)  # a fit whose ratio is exactly the threshold (x2 is exact in binary)
    plain = SimpleNamespace(effects=(), loglik=0.0)
    row, new = D._candidate_lr(FakeDiagnoser(thr / 2), plain, ("force_offset",), [0.1], None, 2e-3, 2, 0.9)
    assert row["lr_statistic"] == thr and new is None
    assert row["rejected_because"] == "likelihood ratio below the threshold"
    row, new = D._candidate_lr(FakeDiagnoser(thr / 2), plain, ("force_offset",), [0.1], None, 2.01e-3, 2, 0.9)
    assert new is not None and "rejected_because" not in row
    row, _ = D._candidate_lr(FakeDiagnoser(5.0), cur, ("force_offset",), [0.1], None, 1e-3, 1, 0.9)
    assert row["lr_statistic"] == 0.0 and row["rejected_because"] == "likelihood ratio below the threshold"
    row, _ = D._candidate_lr(FakeDiagnoser(4.0), cur, ("force_offset",), [0.1], None, 1e-3, 1, 0.9)
    assert row["rejected_because"] == "the fit stayed below the current model"


def test_candidates_the_data_cannot_tell_from_the_added_one_are_named():
    """Forces alone hardly tell a rest curvature from a base tilt (the AR study's twig, seed 20: likelihood-
    ratio statistics 48.70 and 48.79, tilt added). Every candidate of the round within ALTERNATIVE_LR (2 ln 10)
    of the added one's statistic is named; one further below, or the added row itself, is not."""
    from bayesrod.report.html import alternatives_text

    added = {"effect": "base_tilt", "lr_statistic": 48.79}
    rows = [
        added,
        {"effect": "rest_curvature", "lr_statistic": 48.70},
        {"effect": "force_offset", "lr_statistic": 48.79 - 4.5},
        {"effect": "yield", "lr_statistic": 48.79 - 4.7},
    ]
    passed = [((r["effect"],), r, None) for r in rows]
    near = D._alternatives(passed, added)
    assert [r["effect"] for r in near] == ["rest_curvature", "force_offset"]
    assert D.ALTERNATIVE_LR == pytest.approx(2 * np.log(10))
    text = alternatives_text({"base_tilt": ["rest_curvature", "force_offset"], "yield": []})
    assert text.startswith("base_tilt fits these data no better than rest_curvature or force_offset")
    assert alternatives_text({"yield": []}) == ""

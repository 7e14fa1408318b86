"""Small simulation-based calibration (the full study: scripts/sbc.py, docs/validation.md)."""

from pathlib import Path

import numpy as np
import pytest

from bayesrod.api.calibration import sbc_replicate

PRIOR = str(Path(__file__).resolve().parents[1] / "scripts" / "sbc_prior.json")


@pytest.mark.slow  # 3 minutes: run with `pytest -m slow`; the full study is scripts/sbc.py
def test_small_sbc_forces_only():
    """4 replicates drawn from the prior: 90% intervals of EI0 and p cover the truth.

    8 intervals at nominal 90%: P(at most 5 covered) = 3.8%, so a calibrated posterior fails
    about once in 26 seeds (the test is seeded, so deterministic here); intervals half as wide as
    they should be (nominal ~60%) fail with probability 0.68. The full study: scripts/sbc.py.
    """
    rows = [sbc_replicate(seed, PRIOR, use_shapes=False, target_ess=200) for seed in range(100, 104)]
    covered = sum(r["EI0_covered"] + r["p_covered"] for r in rows)
    assert covered >= 6, rows
    for k in ("EI0", "p"):
        ranks = np.array([r[f"{k}_rank"] for r in rows])
        assert 0 <= ranks.min() and ranks.max() <= 99
        assert not np.all(ranks == 0) and not np.all(ranks == 99)  # truth not always outside the draws
    assert max(r["rhat_max"] for r in rows) < 1.05


def test_the_tables_move_the_plain_rods_estimate_by_under_a_twentieth_of_its_sd():
    """The likelihood tables against exact solves (noise-free twig: the exact MLE is the truth): the
    table MLE of log EI0 and p within 0.05 Laplace sd of the truth (measured 0.010 and 0.011; every
    effect and the shape axes: scripts/table_accuracy.py, docs/validation.md)."""
    from bayesrod.api.calibration import table_shift

    out = table_shift()
    assert out["names"] == ["log EI0", "p"]
    assert np.all(np.abs(out["shift_in_sd"]) <= 0.05), out
    # the sd is the twig's (0.03 N force noise, three heights): a wrong Hessian would not pass
    assert 5e-4 < out["laplace_sd"][0] < 5e-3 and 5e-4 < out["laplace_sd"][1] < 5e-3, out


# slow (34 s: 29 friction curves); the end tangent is also checked by test_likelihood_core (docs/validation.md,
# "The slow tier")
@pytest.mark.slow
def test_force_tables_stay_smooth_past_a_branch_that_ends_rising():
    """With contact friction the stem slides off while the force still rises (the plain rod ends in a
    fold), so a node whose branch ended before d must not hold its end force: the 2-D table (4-point
    Lagrange in p and in mu, the likelihood's spacing) against an exact curve at an off-node (p, mu),
    over the last half of the push. Measured 1.2e-5 of the peak (session 49; 2.4e-4 when written, before the
    base-moment search of sessions 45-46); holding the end value gives 2.2e-3.
    (Before session 43 the solver ended these branches early, at d 0.25 instead of 0.49, where f eta bent
    the stem over: then 1.1e-5 and 9.5e-3. The true branch ends where the contact leaves the tip, whose end
    slopes the 48 fixed steps resolve less well; docs/validation.md "Likelihood tables against exact
    solves".)"""
    from bayesrod.inference.likelihood import ForceCurves, _lagrange4

    eta, p0, mu0 = 0.65 / 0.8, 0.43, 0.3
    p_grid, mu_grid = np.linspace(0.3, 0.6, 7), np.linspace(-0.87, 0.87, 25)  # 0.05 in p as in the fit
    ip, wp = _lagrange4(p_grid, np.array([p0]))
    ie, we = _lagrange4(mu_grid, np.array([mu0]))
    curves = ForceCurves.batch(np.full(4, eta), p_grid, n_f=80, effects_nd={"mu": mu_grid[ie[0]]})
    (exact,) = ForceCurves.batch(np.array([eta]), np.array([p0]), n_f=80, effects_nd={"mu": np.array([mu0])})
    assert exact.end_slope[0] > 1.0  # the case this guards: a branch that ends rising
    d = np.linspace(0.5, 1.0, 40) * exact.d_end[0]
    f_exact = exact.force(d)[0]
    table = np.stack([c.force(d)[ip[0]] for c in curves])  # (4 mu, 4 p, n)
    f = np.einsum("e,p,epn->n", we[0], wp[0], table)
    assert np.abs(f - f_exact).max() < 1e-4 * f_exact.max()


# slow (29 s: 17 friction curves); the reading itself is tested on a synthetic table by test_design.py's
# test_design_reads_an_effect_table_as_the_likelihood_reads_it (docs/validation.md, "The slow tier")
@pytest.mark.slow
def test_the_likelihood_reads_friction_forces_in_log_space_to_the_branch_end():
    """The twig's lowest push (eta 0.5625) with friction 0.3 runs to its branch end (0.745 L), where the force grows
    nearly exponentially along mu (f at 0.738 L: 6.7, 8.7, 11.8, 17.1 on the fit's nodes 0.21-0.42). The
    likelihood's table (4-point Lagrange in p and mu at the fit's spacing) against an exact curve at p 0.43, mu 0.3
    over the last half of the push: read in log space 1.4e-4 of the peak force; linearly 1.5e-3, which moved a
    noise-free friction fit's MLE of mu by +1.7 sd (docs/validation.md, session 46)."""
    from bayesrod.inference.likelihood import EffectAxis, ForceCurves, RodLikelihood

    eta, p0, mu0 = 0.45 / 0.8, 0.43, 0.3
    p_grid = np.arange(0.35, 0.51, 0.05)  # the fit's 0.05 in p: the stencil around 0.43
    mu_nodes = np.linspace(-0.8482, 0.8482, 25)[15:19]  # the fit's friction nodes around 0.3 (0.212-0.424)
    curves = ForceCurves.batch(np.full(4, eta), p_grid, n_f=160, effects_nd={"mu": mu_nodes})
    (exact,) = ForceCurves.batch(np.array([eta]), np.array([p0]), n_f=160, effects_nd={"mu": np.array([mu0])})
    d = np.linspace(0.5, 1.0, 40) * exact.d_end[0]
    f_exact = exact.force(d)[0]
    lik = RodLikelihood.__new__(RodLikelihood)
    lik.p_grid, lik.axis = p_grid, EffectAxis("contact_friction", mu_nodes)
    lik.f_table = np.stack([c.force(d) for c in curves])  # (4 mu, 4 p, n)
    f = lik.interp_force(np.array([p0]), np.array([mu0]))[0]
    assert np.abs(f - f_exact).max() < 4e-4 * f_exact.max()


def test_frames_before_the_second_engaged_sample_are_not_used():
    """A frame's contact displacement is interpolated in time from the force record; before the second
    engaged sample D(t) bends too hard (the simulated twig's first frame was 12% off, which a tilt or a
    rest curvature absorbed). Every frame used lies between the second and the last engaged sample, and
    its interpolated D is within 1% of the simulator's exact one."""
    from bayesrod.api._common import as_dataset
    from bayesrod.api.data import simulate
    from bayesrod.dataset.engagement import detect_engagement
    from bayesrod.dataset.simulate import NoiseModel
    from bayesrod.inference.likelihood import prepare_data

    ds = simulate("twig", seed=1, noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0))
    spec = as_dataset(ds)
    _, sims = ds.simulation  # (config, one SimulatedPush per push)
    for push, data, sim in zip(spec.pushes, prepare_data(spec), sims, strict=True):
        t = push.force.time_s[detect_engagement(push.force.force_N).mask]
        times = np.array([fr.time_s for fr in push.shapes])
        used = (times >= t[1]) & (times <= t[-1])
        assert 0 < used.sum() < times.size  # the first frame is dropped, the rest kept
        assert data.frame_D_m.size == used.sum()
        exact = sim.frame_contact_x_m[used]
        np.testing.assert_allclose(data.frame_D_m, exact, rtol=0.01)


def test_a_calibration_row_records_the_fits_worst_table_shift_and_its_zoom():
    """The SBC rows say how far the fit's own table check moved the median (largest |shift|, which
    parameter) and whether the effect axis was narrowed: a miss beside a table warning is then traceable."""
    from bayesrod.api.calibration import table_columns

    doc = {"table_check": {"shift_in_sd": {"log EI0": 0.02, "p": -1.8, "mu": 0.4}}}
    row = table_columns(doc)
    assert np.isnan(row.pop("table_shift_start_sd"))  # no effect axis: no check at the start
    assert row == {"table_shift_sd": 1.8, "table_shift_worst": "p", "effect_axis_zoom": "none", "p_axis_zoom": "none"}
    doc["table_check"]["at_start"] = {"u": 0.5, "shift_in_sd": {"log EI0": 0.01, "p": 0.02, "mu": -0.04}}
    assert table_columns(doc)["table_shift_start_sd"] == 0.04
    doc["table_check"]["at_start"]["between_nodes"] = {"u": 0.52, "shift_in_sd": {"log EI0": 0.1, "p": 0.7, "mu": 0.6}}
    assert table_columns(doc)["table_shift_start_sd"] == 0.7  # the worse of the two, which decided
    doc["table_check"]["at_start"]["between_p_nodes"] = {"p": 0.425, "shift_in_sd": {"log EI0": -0.9, "p": 0.2}}
    assert table_columns(doc)["table_shift_start_sd"] == 0.9  # the worst of the three
    doc["table_check"]["p_axis_zoom"] = {"kept": True}
    assert table_columns(doc)["p_axis_zoom"] == "kept" and table_columns(doc)["effect_axis_zoom"] == "none"
    doc["table_check"]["effect_axis_zoom"] = {"kept": True}
    assert table_columns(doc)["effect_axis_zoom"] == "kept"
    doc["table_check"]["effect_axis_zoom"] = {"kept": False}
    assert table_columns(doc)["effect_axis_zoom"] == "refused"
    unchecked = table_columns({"table_check": {"message": "not checked: x", "effect_axis_zoom": {"kept": True}}})
    assert np.isnan(unchecked["table_shift_sd"]) and unchecked["table_shift_worst"] == ""
    assert unchecked["effect_axis_zoom"] == "kept"


def test_an_sbc_row_ranks_the_truth_among_random_draws_and_covers_it_by_the_90_interval(monkeypatch):
    """The SBC's statistics (scripts/sbc*.py, docs/validation.md): the rank is the number of thinned draws
    below the truth (so a posterior sitting above the truth ranks low), the 90% interval holds its ends, and
    the draws are a random thinning of the whole chain, not its first draws (which are correlated)."""
    from types import SimpleNamespace

    from bayesrod.api import calibration

    res = {"draws": np.array([0.1, 0.2, 0.3, 0.4]), "q": np.array([0.12, 0.25, 0.38])}
    row = calibration.rank_columns(res, 0.25, "EI0")
    assert row == {"EI0_true": 0.25, "EI0_median": 0.25, "EI0_rank": 2, "EI0_covered": True}
    assert [calibration.rank_columns(res, t, "p")["p_rank"] for t in (0.05, 0.15, 0.35, 0.45)] == [0, 1, 3, 4]
    covered = {t: calibration.rank_columns(res, t, "p")["p_covered"] for t in (0.11, 0.12, 0.38, 0.39)}
    assert covered == {0.11: False, 0.12: True, 0.38: True, 0.39: False}
    # fit_for_calibration on a stand-in fit: a chain of 10000 draws in order
    chain = np.arange(10_000.0)
    doc = {"convergence": {"rhat_max": 1.004}, "parameters": {"EI0": {}}, "sampler": {"steps": 1234}}
    monkeypatch.setattr(calibration, "fit", lambda *a, **kw: SimpleNamespace(samples={"EI0": chain}, doc=doc))
    out = calibration.fit_for_calibration("data", "woody", seed=3, n_rank=99)
    draws = out["EI0"]["draws"]
    assert draws.size == np.unique(draws).size == 99 and np.isin(draws, chain).all()
    assert draws.min() < 1000 and draws.max() > 9000  # spread over the chain
    np.testing.assert_array_equal(out["EI0"]["q"], np.quantile(chain, [0.05, 0.5, 0.95]))
    assert out["rhat_max"] == 1.004 and out["steps"] == 1234 and out["names"] == ["EI0"]


def test_an_sbc_truth_is_a_draw_from_the_prior_and_the_data_carry_its_noise():
    """simulate_from_prior: EI0, p and the noise terms are, in this order, draws of the prior with the replicate's
    seed (an SBC whose truths came from elsewhere would be miscalibrated with a calibrated fit)."""
    from bayesrod.api.calibration import NOMINAL_SHAPE_SD_M, simulate_from_prior
    from bayesrod.inference.priors import load_prior

    ds, truth = simulate_from_prior(PRIOR, 5, use_shapes=False)
    pr, rng = load_prior(PRIOR), np.random.default_rng(10_005)
    names = ("EI0", "p", "sigma_force_N", "shape_sd_scale")
    assert [truth[k] for k in names] == [float(pr.get(k).draw(rng, 1)[0]) for k in names]
    recorded = ds.extra["truth"]  # what the simulator drew the data with
    assert (recorded["EI0"], recorded["p"]) == (truth["EI0"], truth["p"])
    assert recorded["noise"]["force_sd_N"] == truth["sigma_force_N"]
    assert recorded["noise"]["shape_sd_m"] == NOMINAL_SHAPE_SD_M * truth["shape_sd_scale"]

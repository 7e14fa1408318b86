"""Experimental design (issue 7): EIG estimators against exact values, feasibility, the CLI."""

import json

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.inference.design import (
    HeightPredictor,
    PushPlan,
    design_heights,
    eig_gaussian,
    eig_nested_mc,
)

from .conftest import make_dataset


def _linear_case(rng, K=6000, n=5, sigma=0.5):
    """A linear-Gaussian design: F = theta @ A^T, where the EIG is exact: 0.5 log det(I + Sigma A^T A / s^2)."""
    Sigma = np.array([[0.04, 0.015], [0.015, 0.02]])
    theta = rng.multivariate_normal([0.3, 0.5], Sigma, size=K)
    A = rng.normal(size=(n, 2))
    exact = 0.5 * np.linalg.slogdet(np.eye(2) + Sigma @ A.T @ A / sigma**2)[1]
    return theta, A, sigma, exact


def test_both_estimators_match_the_exact_eig_of_a_linear_gaussian_design():
    rng = np.random.default_rng(0)
    theta, A, s, exact = _linear_case(rng)
    F = theta @ A.T
    mask = np.ones_like(F, bool)
    sig = np.full(theta.shape[0], s)
    J = np.broadcast_to(A, (theta.shape[0],) + A.shape)
    g = eig_gaussian(theta, J, mask, sig)
    assert g == pytest.approx(exact, rel=0.03)
    est, se = eig_nested_mc(F[:1000], mask[:1000], sig[:1000], F[1000:], sig[1000:], rng)
    assert abs(est - exact) < 4 * se + 0.02 * exact, (est, se, exact)
    # and the estimate moves with the truth: a 4x noisier sensor teaches less
    est2, _ = eig_nested_mc(F[:1000], mask[:1000], 4 * sig[:1000], F[1000:], 4 * sig[1000:], rng)
    assert est2 < 0.6 * est


def test_derived_target_information_matches_exact_for_a_linear_functional():
    rng = np.random.default_rng(1)
    theta, A, s, _ = _linear_case(rng)
    J = np.broadcast_to(A, (theta.shape[0],) + A.shape)
    Sigma = np.cov(theta, rowvar=False)
    post = np.linalg.inv(np.linalg.inv(Sigma) + A.T @ A / s**2)
    s_nd = np.linspace(0, 0.9, 10)
    g = np.column_stack([np.ones_like(s_nd), 4.0 * np.log1p(-s_nd)])  # gradients of log EI(s), eq. EI_taper
    exact = np.mean(0.5 * np.log(np.einsum("gi,ij,gj->g", g, Sigma, g) / np.einsum("gi,ij,gj->g", g, post, g)))
    got = eig_gaussian(theta, J, np.ones((theta.shape[0], A.shape[0]), bool), np.full(theta.shape[0], s), target="ei")
    assert got == pytest.approx(exact, rel=1e-6)


def _posterior(rng, n=3000, sd_log=0.08, sd_p=0.06, sigma=0.3):
    return {
        "EI0": 2.63 * np.exp(sd_log * rng.standard_normal(n)),
        "p": 0.43 + sd_p * rng.standard_normal(n),
        "sigma_force_N": np.full(n, sigma),
    }


def test_fast_estimator_agrees_with_nested_monte_carlo_on_the_rod():
    """Small case on the real forward model: independent Gaussian posterior, noisy sensor (EIG ~ 1 nat)."""
    samples = _posterior(np.random.default_rng(2))
    plan = PushPlan(0.06, 20, None)
    hs = [0.3, 0.5, 0.7]
    fast = design_heights(samples, 0.8, hs, plan, method="gaussian", n_draws=800)
    ref = design_heights(samples, 0.8, hs, plan, method="nmc", n_draws=600, n_inner=2400)
    for a, b in zip(fast["candidates"], ref["candidates"], strict=True):
        g, n = a["expected_information_gain_nats"], b["expected_information_gain_nats"]
        se = b["eig_standard_error_nats"]
        assert abs(g - n) < 4 * se + 0.12 * n, (a["height_m"], g, n, se)
    assert fast["recommended_height_m"] == ref["recommended_height_m"]


def test_predictor_forces_match_direct_forward_solves():
    from bayesrod.physics import force_from_displacement

    D = np.linspace(0.005, 0.08, 12)
    pred = HeightPredictor(0.5, 0.8, D, (0.3, 0.6))
    p = np.array([0.3, 0.33, 0.47, 0.58, 0.6])  # the span's ends too: the p grid must cover them
    EI0 = [2.0, 2.2, 2.63, 3.1, 2.8]
    F = pred.forces(np.log(EI0), p)
    for k, (e, pp) in enumerate(zip(EI0, p, strict=True)):
        ref = force_from_displacement(D, 0.5, e, pp, 0.8).force_N
        np.testing.assert_allclose(F[k], ref, rtol=2e-4)


def test_feasibility_follows_the_sensor_range_and_says_why():
    samples = _posterior(np.random.default_rng(3), sigma=0.03)
    plan = PushPlan(0.10, 40, (0.05, 8.0))
    hs = np.array([0.1, 0.3, 0.5, 0.6, 0.7, 0.79, 0.8, 0.9])
    res = design_heights(samples, 0.8, hs, plan, method="gaussian", n_draws=400)
    rows = {round(r["height_m"], 3): r for r in res["candidates"]}
    assert not rows[0.1]["feasible"] and "above the sensor maximum 8 N" in rows[0.1]["reason"]
    assert rows[0.1]["predicted_peak_force_N"] > 8
    assert not rows[0.8]["feasible"] and "outside the stem" in rows[0.8]["reason"]
    assert not rows[0.9]["feasible"]
    ok = [r for r in res["candidates"] if r["feasible"]]
    assert ok, "some height must be feasible"
    for r in ok:
        assert 0.05 <= r["peak_force_N"]["median"] <= 8.0 and r["reason"] is None
    rec = rows[round(res["recommended_height_m"], 3)]
    assert rec["feasible"]
    assert rec["expected_information_gain_nats"] == max(r["expected_information_gain_nats"] for r in ok)
    # a sensor that cannot read below 2 N rules the high, soft end out with the other reason
    low = design_heights(samples, 0.8, [0.75], PushPlan(0.10, 40, (2.0, 8.0)), method="gaussian", n_draws=400)
    assert "below the sensor minimum 2 N" in low["candidates"][0]["reason"]
    assert low["recommended_height_m"] is None


def test_a_push_that_slips_at_once_is_infeasible():
    samples = _posterior(np.random.default_rng(4), sigma=0.01)
    res = design_heights(samples, 0.8, [0.795], PushPlan(0.5, 40, None), method="gaussian", n_draws=300)
    assert not res["candidates"][0]["feasible"]
    assert "slips almost at once" in res["candidates"][0]["reason"]


@pytest.fixture(scope="module")
def fake_run(tmp_path_factory):
    """A run directory whose posterior is a synthetic cloud, pointing at a real one-push dataset."""
    root = tmp_path_factory.mktemp("design")
    ds = make_dataset(root / "ds", "twig", seed=3, heights_m=(0.5,), n_frames_engaged=2, max_contact_displacement_m=0.1)
    run = root / "run"
    run.mkdir()
    s = _posterior(np.random.default_rng(5), sigma=0.03)
    np.savez(run / "samples.npz", length_m=0.8, **s)
    (run / "config.json").write_text(json.dumps({"dataset": str(ds)}))
    return run


def test_design_cli_writes_the_contract_json(fake_run, tmp_path, capsys):
    out = tmp_path / "d"
    assert main(["design", str(fake_run), "--out", str(out), "--candidates", "0.3:0.75:6", "--quiet"]) == 0
    doc = json.loads((out / "design.json").read_text())
    assert set(doc) >= {"recommended_height_m", "candidates"}
    for c in doc["candidates"]:
        assert set(c) >= {"height_m", "expected_information_gain_nats", "feasible", "predicted_peak_force_N"}
    assert doc["plan"]["force_range_N"] == [0.05, 8.0]  # from the dataset's sensor
    assert doc["plan"]["displacement_m"] == pytest.approx(0.1, rel=0.02)  # from its push
    assert doc["pushed_heights_m"] == [0.5]
    assert (out / "figures" / "design.png").stat().st_size > 10_000
    rec = [c for c in doc["candidates"] if c["height_m"] == doc["recommended_height_m"]]
    assert rec and rec[0]["feasible"]
    assert "recommended next height" in capsys.readouterr().out


def test_design_cli_rejects_bad_candidates_in_one_line(fake_run, tmp_path, capsys):
    assert main(["design", str(fake_run), "--out", str(tmp_path / "x"), "--candidates", "0.2:0.7"]) == 2
    err = capsys.readouterr().err
    assert "--candidates: expected start:stop:num" in err and "Traceback" not in err
    assert main(["design", str(tmp_path), "--out", str(tmp_path / "y")]) == 2
    assert "expected a fit run (samples.npz) or a dataset" in capsys.readouterr().err


def test_design_cli_exits_1_when_nothing_is_feasible(fake_run, tmp_path, capsys):
    code = main(["design", str(fake_run), "--out", str(tmp_path / "z"), "--candidates", "0.05:0.2:4", "--quiet"])
    assert code == 1
    doc = json.loads((tmp_path / "z" / "design.json").read_text())
    assert doc["recommended_height_m"] is None
    assert all(not c["feasible"] and c["reason"] for c in doc["candidates"])


def test_target_gradients_are_the_derivatives_of_the_quantities_they_name():
    """d log k_theta(h) / d(log EI0, p) and d log EI(s) / d(log EI0, p) at each draw, against central
    differences of bayesrod.physics (eq. kdist, eq. EI_taper); bad targets and heights are named."""
    from bayesrod.inference.design import _functional_gradients
    from bayesrod.physics import flexural_rigidity, k_theta

    theta = np.array([[np.log(2.0), 0.3], [np.log(5.0), 0.8], [np.log(1.0), 0.0]])
    L, h, e = 0.9, 0.5, 1e-6
    g = _functional_gradients("k_theta", theta, L, h)
    assert g.shape == (3, 1, 2)
    for i, (le, p) in enumerate(theta):
        lk = lambda le_, p_: np.log(k_theta(h, np.exp(le_), p_, L))  # noqa: E731
        assert g[i, 0, 0] == pytest.approx((lk(le + e, p) - lk(le - e, p)) / (2 * e), rel=1e-6)
        lo = max(p - e, 0.0)
        assert g[i, 0, 1] == pytest.approx((lk(le, p + e) - lk(le, lo)) / (p + e - lo), rel=1e-3)
    ge = _functional_gradients("ei", theta, L, None)
    s = np.linspace(0.0, 0.9, 10)
    assert ge.shape == (3, 10, 2)
    le, p = theta[1]
    num = (np.log(flexural_rigidity(s * L, 2.0, p + e, L)) - np.log(flexural_rigidity(s * L, 2.0, p - e, L))) / (2 * e)
    np.testing.assert_allclose(ge[1, :, 1], num, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(ge[:, :, 0], 1.0)
    for bad in (None, 0.0, L, 1.2):
        with pytest.raises(
            ValueError, match=r"^target_height_m: expected a height in \(0, L = 0.9\) m for target k_theta"
        ):
            _functional_gradients("k_theta", theta, L, bad)
    with pytest.raises(ValueError, match=r"^target: expected one of params, ei, k_theta, got 'x'"):
        _functional_gradients("x", theta, L, None)


def test_push_plan_checks_each_field_at_its_bound():
    from bayesrod.inference.design import PushPlan

    PushPlan(0.1, n_samples=2, force_range_N=(0.0, 1.0), confidence=0.5)  # every bound just allowed
    for kwargs, msg in (
        ({"displacement_m": 0.0}, r"^displacement_m: expected a positive number \[m\], got 0.0"),
        ({"displacement_m": float("inf")}, r"^displacement_m: expected a positive number"),
        ({"n_samples": 1}, r"^n_samples: expected at least 2, got 1"),
        (
            {"force_range_N": (1.0, 1.0)},
            r"^force_range_N: expected \[low, high\] with 0 <= low < high, got \(1.0, 1.0\)",
        ),
        ({"force_range_N": (-0.1, 1.0)}, r"^force_range_N"),
        ({"confidence": 0.0}, r"^confidence: expected a probability in \(0, 1\), got 0.0"),
        ({"confidence": 1.0}, r"^confidence"),
    ):
        args = {"displacement_m": 0.1, **kwargs}
        with pytest.raises(ValueError, match=msg):
            PushPlan(**args)
    np.testing.assert_allclose(PushPlan(0.1, n_samples=4).D_m, [0.025, 0.05, 0.075, 0.1])


def test_feasibility_by_hand_at_each_threshold():
    """Peak forces of 10 draws 1..10 N: range, slip and noise checks, each at its boundary."""
    from bayesrod.inference.design import PushPlan, feasibility

    K = 10
    peak = np.arange(1.0, K + 1)
    F = np.stack([np.linspace(0, pk, 5) for pk in peak])
    F[:, -1] = -5.0  # a sample the mask drops: the peak is over recorded samples only
    F[:, -2] = peak
    mask = np.ones_like(F, bool)
    mask[:, -1] = False
    slip = np.full(K, 0.05)
    sig = np.full(K, 0.1)
    ok = feasibility(F, mask, slip, sig, PushPlan(0.1, force_range_N=(1.0, 10.0), confidence=0.9))
    assert ok["feasible"] is True and ok["reason"] is None and ok["prob_in_range"] == 1.0  # ends inclusive
    assert ok["slip_displacement_m"] == 0.05 and ok["peak_force_N"]["median"] == pytest.approx(5.5)
    high = feasibility(F, mask, slip, sig, PushPlan(0.1, force_range_N=(0.5, 9.0), confidence=0.95))
    assert high["feasible"] is False and high["prob_in_range"] == pytest.approx(0.9)
    assert "above the sensor maximum 9 N: P(in range) = 0.90 < 0.95" in high["reason"]
    assert feasibility(F, mask, slip, sig, PushPlan(0.1, force_range_N=(0.5, 9.0), confidence=0.9))["feasible"]
    low = feasibility(F, mask, slip, sig, PushPlan(0.1, force_range_N=(2.0, 20.0), confidence=0.95))
    assert low["feasible"] is False and "below the sensor minimum 2 N" in low["reason"]
    tie = feasibility(F, mask, slip, sig, PushPlan(0.1, force_range_N=(1.5, 9.5), confidence=0.95))
    assert "above the sensor maximum" in tie["reason"]  # one draw out on each side: said as above
    # slip: at exactly min_fraction of the plan it is still feasible, just below it is not
    assert feasibility(F, mask, np.full(K, 0.1), sig, PushPlan(0.5))["feasible"] is True  # 0.2 x 0.5 m
    early = feasibility(F, mask, np.full(K, 0.0999), sig, PushPlan(0.5))
    assert early["feasible"] is False and early["reason"].startswith("slips almost at once")
    nan_slip = feasibility(F, mask, np.full(K, np.nan), sig, PushPlan(0.1))
    assert nan_slip["slip_displacement_m"] is None
    # noise: the median peak (5.5 N) against min_snr x sd, at the boundary
    assert feasibility(F, mask, slip, np.full(K, 5.5 / 3), PushPlan(0.1))["feasible"] is True
    small = feasibility(F, mask, slip, np.full(K, 2.0), PushPlan(0.1))
    assert small["feasible"] is False and small["reason"].startswith("too small to measure")
    # a draw that slipped before its first recorded sample peaks at 0 N
    none = mask.copy()
    none[0] = False
    assert feasibility(F, none, slip, sig, PushPlan(0.1))["peak_force_N"]["q05"] < 1.0


def _sampled_compliance(S=5):
    rng = np.random.default_rng(0)
    return (
        np.exp(np.log(2.6) + 0.05 * rng.standard_normal(S)),
        0.43 + 0.03 * rng.standard_normal(S),
        np.exp(np.log(8.0) + 0.2 * rng.standard_normal(S)),
    )


def test_predictor_with_a_sampled_base_compliance_matches_direct_forward_solves():
    """Each draw's own base spring, through the coordinate axis (measured within 6e-6 of the peak force)."""
    from bayesrod.inference.design import _effect_axis
    from bayesrod.physics import Effects, force_from_displacement

    L, h, D = 0.8, 0.5, np.linspace(0.0, 0.06, 25)
    EI0, p, kb = _sampled_compliance()
    kb[-1] = np.inf  # a rigid clamp: u = 0, the grid's end
    axis, u_all = _effect_axis({"EI0": EI0, "p": p, "base_compliance": kb}, L)
    assert axis.name == "base_compliance" and axis.grid[0] == 0.0 and axis.grid[-1] < 0.5  # spans the draws
    pred = HeightPredictor(h, L, D, (p.min(), p.max()), effect_axis=axis)
    u = axis.coordinate(kb, EI0, L)
    np.testing.assert_array_equal(u_all, u)
    F = pred.forces(np.log(EI0), p, u=u)
    for k in range(EI0.size):
        ref = force_from_displacement(D, h, EI0[k], p[k], L, Effects(base_compliance=kb[k])).force_N
        np.testing.assert_allclose(F[k], ref, rtol=0, atol=1e-4 * ref.max())
    # the u column of the Jacobian is the derivative (one-sided at the grid's ends, by the step taken)
    J = pred.jacobian(np.log(EI0), p, u=u)
    assert J.shape == (EI0.size, D.size, 3)
    du = 1e-3
    lo = np.maximum(u - du, 0.0)  # forward at the rigid draw, central elsewhere
    fd = (pred.forces(np.log(EI0), p, u=u + du) - pred.forces(np.log(EI0), p, u=lo)) / (u + du - lo)[:, None]
    np.testing.assert_allclose(J[..., 2], fd, rtol=1e-2, atol=1e-6 * np.abs(fd).max())
    with pytest.raises(ValueError, match="u: expected each draw's base_compliance coordinate"):
        pred.forces(np.log(EI0), p)


def test_predictor_with_a_fixed_tabled_effect_matches_direct_forward_solves():
    """A tabled effect held at its median (the design of a fit with one): the curve cache once failed on it."""
    from bayesrod.physics import Effects, force_from_displacement

    L, h, D, eff = 0.8, 0.5, np.linspace(0.0, 0.05, 12), Effects(base_compliance=8.0)
    pred = HeightPredictor(h, L, D, (0.40, 0.46), eff, EI0_ref=2.6)
    F = pred.forces(np.log([2.6]), [0.43])[0]
    ref = force_from_displacement(D, h, 2.6, 0.43, L, eff).force_N
    np.testing.assert_allclose(F, ref, rtol=0, atol=1e-4 * ref.max())


def test_design_separates_the_stem_from_its_anchorage_after_one_height():
    """One push at 0.5 m cannot tell a softer stem from a softer base: draws on that ridge (EI0 from 2 to 5
    N m^2, each with the base spring that gives the pushed height the same small-deflection stiffness).
    Another push at 0.5 m then teaches almost nothing, one at 0.3 m separates the two (measured: 0.014 vs
    2.50 nats by nested MC, 0.15 vs 2.71 linearised). With the spring held at its median instead, the
    pushed height falsely promised 2.9 nats."""
    from bayesrod.physics import force_from_displacement

    L, h1, P, d = 0.8, 0.5, 0.43, 1e-4
    per_unit_EI0 = force_from_displacement(np.array([d]), h1, 1.0, P, L).force_N[0] / d
    total = 1 / (2.63 * per_unit_EI0) + h1**2 / 8.0  # compliance at h1: rod in series with the base spring
    rng = np.random.default_rng(1)
    EI0 = np.exp(rng.uniform(np.log(2.0), np.log(5.0), 2000))
    samples = {
        "EI0": EI0,
        "p": P + 0.005 * rng.standard_normal(EI0.size),
        "base_compliance": h1**2 / (total - 1 / (EI0 * per_unit_EI0)),
        "sigma_force_N": np.full(EI0.size, 0.03),
    }
    plan = PushPlan(displacement_m=0.04, n_samples=30)
    r = design_heights(samples, L, [0.3, 0.5, 0.7], plan, n_draws=300, n_inner=1500)
    eig = {c["height_m"]: c["expected_information_gain_nats"] for c in r["candidates"]}
    assert r["parameters"] == ["log_EI0", "p", "base_compliance_coordinate"]
    assert eig[0.5] < 0.2 and eig[0.3] > 1.5 and eig[0.7] > 0.3
    assert r["recommended_height_m"] == 0.3


def _pinned(n=400, **effects):
    """A posterior pinned at EI0 2.63 N m^2, p 0.43 (relative spread 1e-4), with effects held at one value each."""
    rng = np.random.default_rng(0)
    s = {
        "EI0": 2.63 * np.exp(1e-4 * rng.standard_normal(n)),
        "p": 0.43 + 1e-4 * rng.standard_normal(n),
        "sigma_force_N": np.full(n, 0.03),
    }
    s.update({k: np.full(n, v) for k, v in effects.items()})
    return s


@pytest.mark.parametrize("method", ["gaussian", "nmc"])
def test_design_peak_forces_carry_the_offset_the_yield_and_a_fixed_tabled_effect(method):
    """Peak forces of a pinned posterior are the forward solve's with every fitted effect: the offset
    added, the base moment capped by the yield (1.867 N = 0.5 N m / 0.3 m + 0.2 N at 0.3 m, while the
    elastic rod would reach 3.41 N), the base spring held at its value (a tabled effect that does not vary)."""
    from bayesrod.physics import Effects, force_from_displacement

    L, plan = 0.8, PushPlan(0.05, 20, None)
    s = _pinned(force_offset=0.2, base_compliance=8.0, **{"yield": 0.5})
    r = design_heights(s, L, [0.3, 0.5, 0.7], plan, method=method, n_draws=200, n_inner=150)
    assert r["fixed_effects"] == {"base_compliance": 8.0} and r["parameters"] == ["log_EI0", "p"]
    eff = Effects(base_compliance=8.0, yield_moment=0.5, force_offset=0.2)
    for c in r["candidates"]:
        ref = float(np.max(force_from_displacement(plan.D_m, c["height_m"], 2.63, 0.43, L, eff).force_N))
        assert c["peak_force_N"]["median"] == pytest.approx(ref, rel=1e-4)
        assert c["predicted_peak_force_N"] == c["peak_force_N"]["median"]
        assert abs(c["expected_information_gain_nats"]) < 2e-3  # a pinned posterior has nothing to learn
    assert r["candidates"][0]["peak_force_N"]["median"] == pytest.approx(0.5 / 0.3 + 0.2, rel=1e-6)


def test_design_information_gain_sees_the_yield_cap():
    """Past the yield the force no longer depends on EI0 or p: the linearised gain (its Jacobian through the
    cap) drops from 2.4 to 0.12 nats at 0.3 m and matches nested Monte Carlo (measured 0.120 vs 0.119)."""
    rng = np.random.default_rng(2)
    n = 3000
    s = {
        "EI0": 2.63 * np.exp(0.08 * rng.standard_normal(n)),
        "p": 0.43 + 0.06 * rng.standard_normal(n),
        "sigma_force_N": np.full(n, 0.3),
    }
    plan = PushPlan(0.06, 20, None)
    free = design_heights(s, 0.8, [0.3], plan, method="gaussian", n_draws=800)["candidates"][0]
    capped = {**s, "yield": np.full(n, 0.6)}
    g = design_heights(capped, 0.8, [0.3], plan, method="gaussian", n_draws=800)["candidates"][0]
    m = design_heights(capped, 0.8, [0.3], plan, method="nmc", n_draws=400, n_inner=1600)["candidates"][0]
    assert free["expected_information_gain_nats"] > 2.0 and g["expected_information_gain_nats"] < 0.3
    se = m["eig_standard_error_nats"]
    assert abs(g["expected_information_gain_nats"] - m["expected_information_gain_nats"]) < 4 * se + 0.02


def test_design_resamples_the_inner_draws_of_a_small_posterior_and_rejects_heights_off_the_stem():
    """400 draws, 350 outer: 50 left for the inner sum, too few: it resamples n_inner of them. Heights at
    the clamp (0) and at the tip (L) are outside the stem."""
    s = _pinned()
    r = design_heights(s, 0.8, [0.0, 0.5, 0.8], PushPlan(0.05, 20, None), n_draws=350, n_inner=300)
    rows = r["candidates"]
    assert r["n_draws"] == 350 and rows[1]["feasible"]
    assert np.isfinite(rows[1]["expected_information_gain_nats"]) and rows[1]["eig_standard_error_nats"] >= 0
    for row in (rows[0], rows[2]):
        assert not row["feasible"] and row["expected_information_gain_nats"] is None
        assert row["reason"] == "outside the stem: expected 0 < h < L = 0.8 m" and row["predicted_peak_force_N"] is None


def test_design_checks_target_method_and_noise_by_name():
    s, plan = _pinned(n=200), PushPlan(0.05, 10, None)
    r = design_heights(s, 0.8, [0.5], plan, method="gaussian", target="ei", n_draws=50)
    assert r["target"] == "ei" and r["method"] == "gaussian"
    with pytest.raises(ValueError, match=r"^target: expected one of params, ei, k_theta, got 'bogus'$"):
        design_heights(s, 0.8, [0.5], plan, target="bogus")
    with pytest.raises(ValueError, match=r"^method: expected gaussian or nmc, got 'mcmc'$"):
        design_heights(s, 0.8, [0.5], plan, method="mcmc")
    with pytest.raises(ValueError, match=r"^method: expected target params for nmc .*got 'ei'$"):
        design_heights(s, 0.8, [0.5], plan, method="nmc", target="ei")
    bare = {k: s[k] for k in ("EI0", "p")}
    with pytest.raises(ValueError, match=r"^samples: expected a posterior with force noise .*got EI0, p$"):
        design_heights(bare, 0.8, [0.5], plan)


def test_nested_mc_estimator_is_the_loop_written_from_its_definition():
    """Uneven noise, masked samples, N not a multiple of the chunk: each outer draw's log-likelihood ratio
    against the mean over the inner draws and itself, written as a plain loop with scipy's densities."""
    from scipy.special import logsumexp
    from scipy.stats import norm

    rng = np.random.default_rng(8)
    N, M, n = 150, 37, 7
    F_o, F_i = rng.normal(2.0, 0.5, (N, n)), rng.normal(2.0, 0.5, (M, n))
    s_o, s_i = rng.uniform(0.2, 0.6, N), rng.uniform(0.2, 0.6, M)
    mask = rng.random((N, n)) > 0.2
    est, se = eig_nested_mc(F_o, mask, s_o, F_i, s_i, np.random.default_rng(3))
    y = F_o + s_o[:, None] * np.random.default_rng(3).standard_normal((N, n))
    terms = []
    for i in range(N):
        m = mask[i]
        own = norm.logpdf(y[i, m], F_o[i, m], s_o[i]).sum()
        others = [norm.logpdf(y[i, m], F_i[j, m], s_i[j]).sum() for j in range(M)]
        terms.append(own - (logsumexp([own, *others]) - np.log(M + 1)))
    assert est == pytest.approx(np.mean(terms), rel=1e-10)
    assert se == pytest.approx(np.std(terms, ddof=1) / np.sqrt(N), rel=1e-10)


@pytest.mark.parametrize("D", [2, 3])
def test_linearised_estimator_is_its_formula_with_masked_samples(D):
    """0.5 log det(I + Sigma J^T J / sigma^2) averaged over draws, the masked samples left out; and for a
    derived quantity with gradient g, 0.5 log(g^T Sigma g / g^T (Sigma^-1 + A)^-1 g) (an effect coordinate,
    the third column, has no gradient)."""
    from bayesrod.inference.design import _functional_gradients

    rng = np.random.default_rng(9)
    K, n = 40, 6
    theta = rng.multivariate_normal(np.zeros(D), 0.02 * np.eye(D) + 0.01, size=K) + [np.log(2.6), 0.43, 0.1][:D]
    J, sig = rng.normal(size=(K, n, D)), rng.uniform(0.3, 0.9, K)
    mask = rng.random((K, n)) > 0.3
    Sigma = np.cov(theta.T)
    A = [J[k][mask[k]].T @ J[k][mask[k]] / sig[k] ** 2 for k in range(K)]
    ref = np.mean([0.5 * np.linalg.slogdet(np.eye(D) + Sigma @ a)[1] for a in A])
    assert eig_gaussian(theta, J, mask, sig) == pytest.approx(ref, rel=1e-9)
    G = _functional_gradients("k_theta", theta, 0.8, 0.5)
    gains = []
    for k in range(K):
        g = np.concatenate([G[k, 0], np.zeros(D - 2)])
        gains.append(0.5 * np.log(g @ Sigma @ g / (g @ np.linalg.inv(np.linalg.inv(Sigma) + A[k]) @ g)))
    got = eig_gaussian(theta, J, mask, sig, target="k_theta", length_m=0.8, target_height_m=0.5)
    assert got == pytest.approx(np.mean(gains), rel=1e-9)


def test_design_row_is_the_predictor_and_the_estimator_applied_to_its_draws(capsys):
    """Every draw outer (n_draws = S: the estimator's mean and covariance ignore the order), target k_theta at
    0.5 m: the row's gain, peak forces, P(in range), slip and recorded fraction are the predictor's, the
    linearised estimator's and the feasibility check's on those draws; no progress is printed unless asked,
    and a second call gives the same numbers."""
    from bayesrod.inference.design import feasibility

    S, L, h = 300, 0.8, 0.6
    s = _posterior(np.random.default_rng(6), n=S, sigma=0.05)
    plan = PushPlan(0.45, 25, (0.05, 6.0))  # past some draws' slip, some peaks above 6 N
    kw = dict(target="k_theta", target_height_m=0.5, method="gaussian", n_draws=S)
    r = design_heights(s, L, [h], plan, **kw)
    row = r["candidates"][0]
    assert r["target"] == "k_theta@0.5" and r["n_draws"] == S and "eig_standard_error_nats" not in row
    pred = HeightPredictor(h, L, plan.D_m, (s["p"].min(), s["p"].max()), None, float(np.median(s["EI0"])))
    th = np.column_stack([np.log(s["EI0"]), s["p"]])
    F, mask = pred.forces(th[:, 0], th[:, 1]), pred.observed(th[:, 1])
    J = pred.jacobian(th[:, 0], th[:, 1])
    eig = eig_gaussian(th, J, mask, s["sigma_force_N"], target="k_theta", length_m=L, target_height_m=0.5)
    feas = feasibility(F, mask, pred.slip_m(th[:, 1]), s["sigma_force_N"], plan)
    assert row["expected_information_gain_nats"] == pytest.approx(eig, rel=1e-9)
    assert row["expected_information_gain_nats"] != pytest.approx(eig_gaussian(th, J, mask, s["sigma_force_N"]))
    assert row["peak_force_N"] == pytest.approx(feas["peak_force_N"], rel=1e-12)
    assert row["prob_in_range"] == feas["prob_in_range"] and 0 < row["prob_in_range"] < 1
    assert row["slip_displacement_m"] == pytest.approx(feas["slip_displacement_m"], rel=1e-12)
    assert row["recorded_fraction"] == pytest.approx(mask.mean()) and 0 < row["recorded_fraction"] < 1
    again = design_heights(s, L, [h], plan, **kw)
    nmc = [design_heights(s, L, [h], plan, n_draws=100, n_inner=200) for _ in range(2)]
    assert again == r and nmc[0] == nmc[1]
    assert capsys.readouterr().err == ""


def test_predictor_jacobian_is_the_central_difference_of_its_forces_through_the_cap_and_the_axis():
    """All three columns (log EI0, p, the base spring's coordinate) with a yield cap and an offset passed
    through: where the cap binds the force depends on none of them."""
    from bayesrod.inference.design import _effect_axis

    L, h, D = 0.8, 0.5, np.linspace(0.0, 0.06, 13)
    EI0, p, kb = _sampled_compliance()
    axis, u = _effect_axis({"EI0": EI0, "p": p, "base_compliance": kb}, L)
    pred = HeightPredictor(h, L, D, (p.min(), p.max()), effect_axis=axis)
    kw = {"yield_moment": np.full(EI0.size, 0.5), "offset": np.full(EI0.size, 0.1)}
    le, d = np.log(EI0), 1e-4
    J = pred.jacobian(le, p, u=u, **kw)
    cols = [
        (pred.forces(le + d, p, u=u, **kw) - pred.forces(le - d, p, u=u, **kw)) / (2 * d),
        (pred.forces(le, p + d, u=u, **kw) - pred.forces(le, p - d, u=u, **kw)) / (2 * d),
        (pred.forces(le, p, u=u + d, **kw) - pred.forces(le, p, u=u - d, **kw)) / (2 * d),
    ]
    capped = pred.forces(le, p, u=u, **kw) >= 0.5 / h + 0.1 - 1e-12
    assert capped.any() and (~capped).any()
    for k in range(3):
        np.testing.assert_allclose(J[..., k], cols[k], rtol=1e-6, atol=1e-9)
        assert np.all(J[..., k][capped] == 0.0) and np.abs(J[..., k][~capped]).max() > 0.05


def test_predictor_slip_is_where_the_forward_solve_slips_with_a_sampled_spring():
    from bayesrod.inference.design import _effect_axis
    from bayesrod.physics import Effects, force_from_displacement

    L, h = 0.8, 0.6
    EI0, p, kb = _sampled_compliance(3)
    axis, u = _effect_axis({"EI0": EI0, "p": p, "base_compliance": kb}, L)
    pred = HeightPredictor(h, L, np.linspace(0, 0.1, 5), (p.min(), p.max()), effect_axis=axis)
    slip, early = pred.slip_m(p, u), pred.slip_m(p, u, early=True)
    D = np.linspace(0.0, 1.2 * L, 2401)
    for k in range(3):
        eff = Effects(base_compliance=kb[k])
        solved = force_from_displacement(D, h, EI0[k], p[k], L, eff)
        first = D[solved.slipped][0]
        assert slip[k] == pytest.approx(first, rel=5e-3), (k, slip[k], first)  # measured: within 0.3%
        # the plateau's start on the spring's axis too: the force within 0.1% of the branch's largest
        F_early = force_from_displacement(np.array([early[k]]), h, EI0[k], p[k], L, eff).force_N[0]
        assert early[k] < slip[k] and 0.997 < F_early / np.nanmax(solved.force_N) < 0.9995, (k, early[k])


def test_the_plateau_before_the_slip_starts_where_the_force_is_within_its_tolerance_of_the_branch_end():
    """The early slip (the plateau's start, where the stem may already leave the probe) lies before the branch
    end, with the force there within SLIP_FORCE_REL (0.1%) of the branch's largest force, by forward solves on
    a fine grid; design.json reports it beside the slip, from the same draws."""
    from bayesrod.inference.likelihood import SLIP_FORCE_REL
    from bayesrod.physics import force_from_displacement

    L, h = 0.8, 0.6
    p = np.array([0.35, 0.43, 0.5])
    pred = HeightPredictor(h, L, np.linspace(0, 0.1, 5), (0.3, 0.55))
    early, end = pred.slip_m(p, early=True), pred.slip_m(p)
    for k in range(3):
        F = force_from_displacement(np.linspace(0.8 * early[k], 1.05 * end[k], 301), h, 1.0, p[k], L).force_N
        top = np.nanmax(F)
        F_early = force_from_displacement(np.array([early[k]]), h, 1.0, p[k], L).force_N[0]
        assert early[k] < end[k] - 0.003  # the plateau is millimetres long: 3.9, 9.4 and 18 mm here
        assert 1 - 2 * SLIP_FORCE_REL < F_early / top < 1 - 0.5 * SLIP_FORCE_REL, (k, F_early / top)
    rng = np.random.default_rng(0)
    draws = {"EI0": 2.6 * np.exp(0.05 * rng.standard_normal(50)), "p": 0.43 + 0.03 * rng.standard_normal(50)}
    res = design_heights(
        {**draws, "sigma_force_N": np.full(50, 0.03)}, L, [h], PushPlan(0.3, 10, None), method="gaussian"
    )
    row = res["candidates"][0]
    assert row["slip_from_displacement_m"] == pytest.approx(np.median(pred.slip_m(draws["p"], early=True)), rel=1e-3)
    assert row["slip_from_displacement_m"] < row["slip_displacement_m"]


def test_a_varying_tabled_effect_is_an_axis_however_small_its_spread_and_only_one_may_vary():
    from bayesrod.inference.design import _effect_axis

    rng = np.random.default_rng(0)
    s = {"EI0": np.full(50, 2.6), "p": np.full(50, 0.43), "base_compliance": 8.0 + 0.3 * rng.random(50)}
    axis, u = _effect_axis(s, 0.8)
    assert axis is not None and axis.name == "base_compliance" and u.shape == (50,)
    assert axis.grid[0] <= u.min() and axis.grid[-1] >= u.max()
    with pytest.raises(
        ValueError, match=r"^samples: expected at most one sampled tabled effect, got base_compliance, "
    ):
        _effect_axis({**s, "base_tilt": 0.01 * rng.random(50)}, 0.8)
    capped = design_heights(_pinned(), 0.8, [0.0], PushPlan(0.05, 10, None), method="gaussian", n_draws=20)
    assert capped["candidates"][0]["feasible"] is False
    # a tilt either way: the axis spans the negative draws too (only a base spring's coordinate stops at 0)
    tilt, _ = _effect_axis({**{k: s[k] for k in ("EI0", "p")}, "base_tilt": np.linspace(-0.03, 0.02, 50)}, 0.8)
    assert tilt.grid[0] < -0.03 and tilt.grid[-1] > 0.02
    # the linearised gain with the spring as a third parameter
    lin = design_heights(
        {**s, "sigma_force_N": np.full(50, 0.03)}, 0.8, [0.5], PushPlan(0.05, 10, None), method="gaussian"
    )
    assert lin["parameters"][-1] == "base_compliance_coordinate"
    assert np.isfinite(lin["candidates"][0]["expected_information_gain_nats"])


def test_design_reads_an_effect_table_as_the_likelihood_reads_it(monkeypatch):
    """The predictor and the likelihood on one table (synthetic force curves in place of the solves: exponential
    along a friction axis, as friction forces grow near the branch end; the same along a rest-curvature axis,
    read linearly there): the same forces at off-node (p, u), so a design plans with the reading the fit will use.
    The exact-solve version with friction is slow (next test)."""
    from types import SimpleNamespace

    from bayesrod.inference import design
    from bayesrod.inference.likelihood import EffectAxis, RodLikelihood

    def curve(d, u, p):  # f = d exp(6 u d + p): convex in u; log f is linear in u and p
        return d * np.exp(6.0 * np.asarray(u)[..., None] * d + np.asarray(p)[..., None])

    def fake_batch(etas, p_grid, effects_nd=None):
        u_nd = next(iter(effects_nd.values()))
        return [SimpleNamespace(force=lambda d, u=u: curve(d, u, p_grid), d_end=np.ones(p_grid.size),
                                d_early=np.ones(p_grid.size)) for u in u_nd]  # fmt: skip

    monkeypatch.setattr(design.ForceCurves, "batch", fake_batch)
    u_nodes = np.linspace(-0.8482, 0.8482, 25)
    L, h, EI0 = 0.8, 0.45, 2.63
    D = np.linspace(0.1, 1.0, 12) * L
    pt, ut = np.array([0.43, 0.412, 0.445]), np.array([0.3, 0.05, -0.61])
    for name in ("contact_friction", "rest_curvature"):
        axis = EffectAxis(name, u_nodes)
        pred = HeightPredictor(h, L, D, (0.40, 0.46), effect_axis=axis)
        got = pred.forces(np.full(3, np.log(EI0)), pt, u=ut)
        lik = RodLikelihood.__new__(RodLikelihood)
        lik.p_grid, lik.axis, lik.f_table = pred.p_grid, axis, pred.f_table
        np.testing.assert_allclose(got, EI0 / L**2 * lik.interp_force(pt, ut), rtol=1e-12, err_msg=name)
        exact = EI0 / L**2 * curve(D / L, ut, pt)
        err = np.abs(got - exact).max() / exact.max()
        # log space reads log f exactly (linear in u and p): 7e-14 measured; linearly along u: 6e-4
        assert (err < 1e-9) if name == "contact_friction" else (err > 1e-4), (name, err)


@pytest.mark.slow  # 34 s: 32 friction curves (docs/validation.md, "The slow tier")
def test_design_reads_friction_forces_in_log_space_as_the_likelihood_does():
    """A planned push at the twig's lowest height with a contact-friction axis (the fit's nodes around mu 0.3),
    to its branch end (0.745 L): the predictor's forces at p 0.43, mu 0.3 against an exact curve over the last half.
    In log space 1.4e-4 of the peak; read linearly 1.5e-3 (the likelihood's own reading: session 46)."""
    from bayesrod.inference.design import HeightPredictor
    from bayesrod.inference.likelihood import EffectAxis, ForceCurves

    L, h, EI0 = 0.8, 0.45, 2.63
    mu_nodes = np.linspace(-0.8482, 0.8482, 25)[15:19]
    (exact,) = ForceCurves.batch(np.array([h / L]), np.array([0.43]), n_f=160, effects_nd={"mu": np.array([0.3])})
    D = np.linspace(0.5, 1.0, 40) * exact.d_end[0] * L
    pred = HeightPredictor(h, L, D, (0.40, 0.46), effect_axis=EffectAxis("contact_friction", mu_nodes))
    F = pred.forces(np.array([np.log(EI0)]), np.array([0.43]), u=np.array([0.3]))[0]
    F_exact = EI0 / L**2 * exact.force(D / L)[0]
    assert np.abs(F - F_exact).max() < 4e-4 * F_exact.max()


def test_the_planned_push_defaults_to_the_farthest_engaged_reach_and_the_median_engaged_count(tmp_path):
    """design's default plan, from pushes of three lengths (a fixed robot step: 3 different engaged counts,
    and samples after each slip): the farthest contact reach while engaged, not the travel after the slip,
    and the median engaged count, not the largest."""
    from bayesrod.api.design import default_plan
    from bayesrod.dataset.engagement import detect_engagement
    from bayesrod.dataset.reader import read_dataset

    path = make_dataset(tmp_path / "ds", "twig", seed=3, heights_m=(0.3, 0.5, 0.7), robot_step_m=0.01)
    spec = read_dataset(path)
    reach, counts = [], []
    for push in spec.pushes:
        x, engaged = push.force.contact_x_m, detect_engagement(push.force.force_N).mask
        assert np.nanmax(x) > np.nanmax(x[engaged]) + 0.01  # travel after the slip
        reach.append(np.nanmax(x[engaged]))
        counts.append(int(engaged.sum()))
    assert len(set(counts)) == 3
    plan = default_plan(spec)
    assert plan["displacement_m"] == pytest.approx(max(reach), rel=1e-12)
    assert plan["n_samples"] == sorted(counts)[1] and plan["force_range_N"] == (0.05, 50.0)


@pytest.fixture
def estimator_call(monkeypatch):
    """``bayesrod.design`` with its estimator replaced by a recorder: the dict filled with what the last call
    passed (``L``, ``cand``, ``plan`` and the keywords), the result one recommended candidate at 0.3 m."""
    import importlib

    api_design = importlib.import_module("bayesrod.api.design")  # the package exports the function of its name
    seen = {}

    def record(samples, L, cand, plan, **kw):
        seen.update(L=L, cand=np.asarray(cand), plan=plan, **kw)
        return {"recommended_height_m": 0.3, "candidates": [{"height_m": 0.3}]}

    monkeypatch.setattr(api_design, "design_heights", record)
    return seen


def test_design_proposes_nineteen_heights_along_the_stem_by_default(fake_run, estimator_call):
    """Without candidate heights: 0.05 L to 0.95 L in 19 steps (L from the run, 0.8 m), in metres."""
    import bayesrod

    bayesrod.design(fake_run, progress=False)
    assert estimator_call["L"] == 0.8
    np.testing.assert_allclose(estimator_call["cand"], np.linspace(0.04, 0.76, 19), rtol=1e-12)


def test_design_of_a_run_whose_dataset_is_gone_takes_the_pushed_heights_from_its_summary(tmp_path, estimator_call):
    """A saved run without its dataset (moved, or fitted elsewhere): the pushed heights come from summary.json's
    ``data.heights_m``, and the plan must be given (else a clear error)."""
    import bayesrod

    run = tmp_path / "run"
    run.mkdir()
    np.savez(run / "samples.npz", length_m=0.8, **_posterior(np.random.default_rng(5), n=400, sigma=0.03))
    (run / "summary.json").write_text(json.dumps({"specimen": "s", "length_m": 0.8, "data": {"heights_m": [0.5, 0.6]}}))
    with pytest.raises(ValueError, match="displacement_m: expected the planned contact displacement"):
        bayesrod.design(run, heights=[0.3], progress=False)
    d = bayesrod.design(run, heights=[0.3], displacement_m=0.05, n_samples=30, progress=False)
    assert d.to_dict()["pushed_heights_m"] == [0.5, 0.6]
    assert (estimator_call["plan"].displacement_m, estimator_call["plan"].n_samples) == (0.05, 30)


def test_the_saved_design_figure_is_drawn(fake_run, tmp_path):
    """design.png shows its coloured marks (an empty frame, or a figure drawn on other axes, would not)."""
    import cv2

    import bayesrod

    bayesrod.design(fake_run, heights=[0.3, 0.5], method="gaussian", progress=False).save(tmp_path / "d")
    png = cv2.imread(str(tmp_path / "d" / "figures" / "design.png")).astype(int)
    assert np.mean(png.max(axis=2) - png.min(axis=2) > 40) > 0.001


def test_design_passes_the_sensor_the_confidence_and_the_target_to_the_estimator(fake_run, estimator_call):
    """What the user asks of `design` reaches the estimator: the sensor range and required confidence in the plan,
    the target and its default method (nested MC for the parameters, linearised for the EI band and k_theta),
    and the run as the design's source."""
    from bayesrod import design

    seen = estimator_call
    d = design(fake_run, heights=[0.3], sensor=(0.2, 5.0), confidence=0.8, progress=False)
    assert (seen["plan"].force_range_N, seen["plan"].confidence) == ((0.2, 5.0), 0.8)
    assert (seen["target"], seen["method"]) == ("params", "nmc")
    assert d.to_dict()["source"] == str(fake_run.resolve())
    for target in ("ei", "k_theta"):
        design(fake_run, heights=[0.3], target=target, target_height_m=0.4, progress=False)
        assert (seen["target"], seen["method"], seen["target_height_m"]) == (target, "gaussian", 0.4)
    with pytest.raises(ValueError, match="sensor: expected \\(low, high\\)"):
        design(fake_run, heights=[0.3], sensor=5.0, progress=False)


def test_a_design_keeps_its_seed_length_and_recommendation_and_an_unsaved_fit_names_its_dataset(
    fake_run, estimator_call
):
    """The seed reaches the estimator (a design is reproducible), the Design holds the estimator's recommended
    height and the run's length, and a fit that was never saved (no ``run`` in its config) names its dataset as
    the design's source."""
    import dataclasses

    import bayesrod
    from bayesrod.api.group import load_run

    d = bayesrod.design(fake_run, heights=[0.3], seed=7, progress=False)
    assert estimator_call["seed"] == 7
    assert d.recommended_height_m == 0.3 and d.to_dict()["recommended_height_m"] == 0.3
    assert d.to_dict()["length_m"] == 0.8
    post = load_run(fake_run)
    unsaved = dataclasses.replace(post, config={k: v for k, v in post.config.items() if k != "run"})
    dataset = json.loads((fake_run / "config.json").read_text())["dataset"]
    assert bayesrod.design(unsaved, heights=[0.3], progress=False).to_dict()["source"] == dataset


def test_the_default_plan_reads_a_sensor_range_only_where_the_dataset_gives_one(tmp_path):
    """A dataset without a sensor, or with a sensor of unknown range, plans without a force range (the
    feasibility check then has nothing to hold the peak force to); with one, the plan carries it."""
    import dataclasses

    from bayesrod.api.design import default_plan
    from bayesrod.dataset.model import Sensor
    from bayesrod.dataset.reader import read_dataset

    spec = read_dataset(make_dataset(tmp_path / "ds", "twig", seed=3, heights_m=(0.5,), n_frames_engaged=2))
    assert default_plan(spec)["force_range_N"] == tuple(spec.sensor.force_range_N)
    assert "force_range_N" not in default_plan(dataclasses.replace(spec, sensor=None))
    unknown = dataclasses.replace(spec, sensor=Sensor("unknown", None, None))
    assert "force_range_N" not in default_plan(unknown)


def test_a_saved_design_is_not_overwritten_unless_asked_and_its_figure_marks_the_pushed_heights(fake_run, tmp_path):
    """``Design.save`` refuses a non-empty directory (nothing lost) unless ``overwrite=True``; ``Design.plot``
    (which the saved figure draws) marks every height already pushed with a dotted line."""
    import matplotlib.pyplot as plt

    import bayesrod
    from bayesrod.dataset.io import OutputExistsError

    d = bayesrod.design(fake_run, heights=[0.3, 0.5], method="gaussian", progress=False)
    out = d.save(tmp_path / "d")
    (out / "mine.txt").write_text("a user's note")
    with pytest.raises(OutputExistsError):
        d.save(out)
    assert (out / "mine.txt").exists()
    d.save(out, overwrite=True)
    assert (out / "design.json").exists() and not (out / "mine.txt").exists()
    fig, ax = plt.subplots()
    try:
        d.plot(ax=ax)
        dotted = [float(line.get_xdata()[0]) for line in ax.lines if line.get_linestyle() == ":"]
    finally:
        plt.close(fig)
    assert dotted == d.to_dict()["pushed_heights_m"] == [0.5]

"""Diagnosis, issue 19: true held-out refits, AR(1) force noise, the bootstrap held-out gate, spline forces.

A file of its own so that the test runner spreads the diagnosis tests over both workers.
"""

import numpy as np
import pytest

from bayesrod.inference.diagnose import Diagnoser, ForwardModel, _cut
from bayesrod.physics import force_from_displacement

from .test_diagnose import _Lazy, _model


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    return _Lazy(tmp_path_factory.mktemp("diag19"))


# ---------------------------------------------------------------- issue 19: true refits, AR(1) noise
def test_heldout_error_is_a_true_refit_without_the_push(datasets):
    """Each held-out push is predicted by a full fit to the other pushes: no steps from the full fit."""
    m = _model(datasets["clean"])
    dg = Diagnoser(m)
    fit = dg.fit_plain()
    summary, errs = dg.heldout(fit)
    assert summary["heldout"] == "leave-one-height-out"
    for k, (row, e) in list(enumerate(zip(summary["per_push"], errs, strict=True)))[:1]:
        rest = ForwardModel([d for j, d in enumerate(m.data) if j != k], m.length_m)
        own = Diagnoser(rest).fit((), fit.x)
        held = ForwardModel([m.data[k]], m.length_m)
        expect = held.F_obs - held.forces(own.x[None], ())[0]
        np.testing.assert_allclose(e.errors_N, expect, rtol=1e-6, atol=1e-9)
        assert row["force_rmse_N"] == pytest.approx(np.sqrt(np.mean(expect**2)), rel=1e-6)
        # the full fit's own prediction of the push (no refit, or the in-sample error) is another number
        assert not np.allclose(e.errors_N, fit.r_force[m.force_push == k], rtol=1e-3, atol=0)


def test_one_push_holds_out_the_last_third(datasets):
    m = _model(datasets["clean"])
    one = ForwardModel([m.data[0]], m.length_m)
    dg = Diagnoser(one)
    fit = dg.fit_plain()
    summary, errs = dg.heldout(fit)
    assert summary["heldout"] == "last third of the push"
    n = m.data[0].D_m.size
    n_train = int(np.ceil(2 * n / 3))
    assert errs[0].errors_N.size == n - n_train
    train = ForwardModel([_cut(m.data[0], np.arange(n_train), np.zeros(0, int))], m.length_m)
    own = Diagnoser(train).fit((), fit.x)
    F = one.forces(own.x[None], ())[0][n_train:]
    np.testing.assert_allclose(errs[0].errors_N, one.F_obs[n_train:] - F, rtol=1e-6, atol=1e-9)


def test_ar1_log_likelihood_is_the_exact_gaussian_density():
    """Diagnoser.loglik with AR(1) forces equals the dense multivariate normal (two pushes)."""
    from scipy.stats import multivariate_normal

    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(0)
    pushes = [
        PushData(
            f"h{k}",
            0.5,
            np.linspace(0.001, 0.02, n),
            rng.normal(size=n),
            np.zeros(0),
            np.zeros(0, int),
            *(np.zeros(0),) * 2,
            None,
        )
        for k, n in enumerate((7, 5))
    ]
    dg = Diagnoser(ForwardModel(pushes, 0.8))
    rf = np.concatenate([d.F_N for d in pushes])
    sf, rho = 0.7, 0.85
    dense = 0.0
    for d in pushes:
        n = d.F_N.size
        lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        cov = sf**2 / (1 - rho**2) * rho**lag
        dense += multivariate_normal(np.zeros(n), cov).logpdf(d.F_N)
    const = -0.5 * rf.size * np.log(2 * np.pi)
    assert dg.loglik(rf, np.zeros(0), (sf, rho, 1.0)) + const == pytest.approx(dense, rel=1e-10)
    # the profile recovers the correlation of long AR(1) residuals
    from bayesrod.dataset.simulate import ar1_noise

    r = ar1_noise(rng, 1.0, 0.9, 4000)
    long = ForwardModel(
        [
            PushData(
                "h", 0.5, np.linspace(0.001, 0.02, 4000), r, np.zeros(0), np.zeros(0, int), *(np.zeros(0),) * 2, None
            )
        ],
        0.8,
    )
    assert Diagnoser(long).profile_noise(r, np.zeros(0))[1] == pytest.approx(0.9, abs=0.02)
    assert Diagnoser(long, "iid").profile_noise(r, np.zeros(0))[1] == 0.0


@pytest.mark.parametrize("coords", [{}, {"yield": np.log(2.0)}, {"base_compliance": 0.3}])
def test_spline_forces_match_the_direct_solve_on_long_pushes(coords):
    """150 samples per push, read off 32 solves: plain, a yield onset mid-push, a soft base."""
    from bayesrod.inference.likelihood import PushData

    D = np.linspace(0.0, 0.25, 150)
    empty = np.zeros(0)
    pushes = [
        PushData(f"h{h}", h, D, np.zeros(D.size), empty, empty.astype(int), empty, empty, None) for h in (0.45, 0.6)
    ]
    m = ForwardModel(pushes, 0.8)
    F = m.predict(np.log(2.63), 0.43, coords, shapes=False)[0]
    from bayesrod.inference.diagnose import effects_from_coords

    eff = effects_from_coords(coords, 2.63, 0.8)
    ref = np.concatenate([force_from_displacement(D, d.height_m, 2.63, 0.43, 0.8, eff).force_N for d in pushes])
    assert np.all(np.isfinite(ref))
    tol = 1e-5 if "yield" not in coords else 1e-4  # each branch its own spline, the kink's interval solved
    assert np.max(np.abs(F - ref)) < tol * np.max(np.abs(ref))


def test_batched_parameter_sets_with_a_yield_onset_match_one_set_at_a_time():
    """The samples a yield onset puts between nodes are solved in one batch over every parameter set
    (a Jacobian's rows): each row must get its own EI0, p, yield moment and height, as when solved alone."""
    from bayesrod.inference.likelihood import PushData

    D = np.linspace(0.0, 0.25, 150)
    empty = np.zeros(0)
    pushes = [
        PushData(f"h{h}", h, D, np.zeros(D.size), empty, empty.astype(int), empty, empty, None) for h in (0.45, 0.6)
    ]
    m = ForwardModel(pushes, 0.8)
    X = np.array([[np.log(2.63), 0.43, np.log(2.0)], [np.log(3.5), 0.3, np.log(1.5)], [np.log(2.0), 0.6, np.log(1.2)]])
    batched = m.forces(X, ("yield",))
    for k in range(X.shape[0]):
        np.testing.assert_allclose(batched[k], m.forces(X[k : k + 1], ("yield",))[0], rtol=1e-10, atol=1e-12)
    assert np.ptp(batched[:, -1]) > 0.1 * np.max(batched[:, -1])  # the rows differ: a mixed-up row would show


def test_structure_test_holds_its_level_under_ar1_noise_and_fails_without_the_correction():
    """Pure AR(1) residuals (rho 0.95): the whitened F test flags no block in 95%+ of pushes; without the
    whitening (the correlated-noise correction dropped) nearly every push is flagged."""
    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit
    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(5)
    n, pushes = 120, []
    for k in range(40):
        r = ar1_noise(rng, 0.05, 0.95, n)
        e = np.zeros(0)
        pushes.append(PushData(f"h{k}", 0.5, np.linspace(0.0, 0.05, n), r, e, e.astype(int), e, e, None))
    m = ForwardModel(pushes, 0.8)
    r = m.F_obs
    sig = 0.05 * np.sqrt(1 - 0.95**2)

    def flagged(rho, sigma):
        fit = MapFit((), np.zeros(2), sigma, 1.0, r, np.zeros(0), np.zeros((r.size, 2)), 0.0, rho)
        return sum(b["structured"] for b in Diagnoser(m).structure(fit)["blocks"])

    assert flagged(0.95, sig) <= 2  # 40 pushes at alpha 1e-3 (and a material size): ~0 expected
    assert flagged(0.0, 0.05) >= 30


def test_heldout_bootstrap_p_values_are_uniform_when_the_effect_is_absent():
    """Linear model, AR(1) noise (rho 0.9), an effect column that is absent: the observed held-out gains come
    from exact GLS refits (dense covariance, written here independently); the bootstrap p-values are uniform."""
    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit, null_heldout_gain

    rng = np.random.default_rng(11)
    n, rho, sig = 60, 0.9, 0.02
    m, D, e = _three_linear_pushes(n)
    push = m.force_push
    scale = 1.0 + 0.3 * push  # the heights differ
    J0 = np.column_stack([D[np.arange(3 * n) % n] * scale, (D[np.arange(3 * n) % n] ** 2) * scale**2])
    G = (D[np.arange(3 * n) % n] ** 3) * scale**3
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    Cinv_block = np.linalg.inv(sig**2 / (1 - rho**2) * rho**lag)

    def gls(X, y, rows):
        A = np.zeros((X.shape[1],) * 2)
        b = np.zeros(X.shape[1])
        for k in np.unique(push[rows]):
            s = rows & (push == k)
            A += X[s].T @ Cinv_block @ X[s]
            b += X[s].T @ Cinv_block @ y[s]
        return np.linalg.solve(A, b)

    dg = Diagnoser(m)
    pv = []
    for _ in range(150):
        y = J0 @ np.array([1.0, -0.3]) + np.concatenate(
            [ar1_noise(rng, sig / np.sqrt(1 - rho**2), rho, n) for _ in range(3)]
        )
        allrows = np.ones(3 * n, bool)
        X1 = np.column_stack([J0, G])
        r0 = y - J0 @ gls(J0, y, allrows)
        r1 = y - X1 @ gls(X1, y, allrows)
        gain = _loho_gain(gls, J0, X1, y, push)
        # p = 1: far inside its bounds (the bounded case is the next test)
        mk = lambda r: MapFit((), np.array([0.0, 1.0]), sig, 1.0, r, np.zeros(0), J0, 0.0, rho, J0)  # noqa: E731
        pv.append(null_heldout_gain(dg, mk(r0), mk(r1), gain, n_draws=400, seed=len(pv)))
    pv = np.array(pv)
    assert 0.01 <= np.mean(pv < 0.05) <= 0.11, np.mean(pv < 0.05)
    assert 0.38 <= np.mean(pv < 0.5) <= 0.62, np.mean(pv < 0.5)


def test_heldout_bootstrap_refits_keep_the_bounds_of_the_true_refits():
    """p at its bound (0) in the truth and the fit, a one-sided effect (base compliance) absent, the true
    refits bounded (p >= 0, amplitude >= 0; exact GLS over every active set, written here): the bounded
    bootstrap's p-values are valid (not below their level). It fails a bootstrap that ignores the noise's
    correlation (P(p < 0.05) 0.14). It does not tell bounded from unbounded refits at this size (the
    unbounded ones are conservative here: P(p < 0.2) 0.10 over 400 replicates); the draw-by-draw test
    against dense bounded GLS below does."""

    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit, null_heldout_gain

    rng = np.random.default_rng(5)
    n, rho, sig = 40, 0.9, 0.02
    m, D, e = _three_linear_pushes(n)
    push = m.force_push
    t = D[np.arange(3 * n) % n] * (1.0 + 0.3 * push)
    J0 = np.column_stack([t, t**2])  # (log EI0, p): p = 0 at its lower bound
    X1 = np.column_stack([J0, t**3])  # + a one-sided effect's signature
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    Ci = np.linalg.inv(sig**2 / (1 - rho**2) * rho**lag)

    Ci_all = np.kron(np.eye(3), Ci)  # the pushes' AR(1) blocks are independent

    def bounded_gls(X, y, rows):  # minimise the GLS objective with every column but the first >= 0
        lower = np.r_[-np.inf, np.zeros(X.shape[1] - 1)]
        return _lower_bounded_gls(X[rows], y[rows][:, None], Ci_all[np.ix_(rows, rows)], lower)[:, 0]

    dg = Diagnoser(m)
    pv = []
    for _ in range(100):
        y = 0.5 * J0[:, 0] + np.concatenate([ar1_noise(rng, sig / np.sqrt(1 - rho**2), rho, n) for _ in range(3)])
        allrows = np.ones(3 * n, bool)
        c0, c1 = bounded_gls(J0, y, allrows), bounded_gls(X1, y, allrows)
        r0, r1 = y - J0 @ c0, y - X1 @ c1
        gain = _loho_gain(bounded_gls, J0, X1, y, push)
        cur = MapFit((), c0, sig, 1.0, r0, e, J0, 0.0, rho, J0)  # the bootstrap's box: p moves to >= 0
        new = MapFit(("base_compliance",), c1, sig, 1.0, r1, e, X1, 0.0, rho, X1)
        pv.append(null_heldout_gain(dg, cur, new, gain, n_draws=200, seed=len(pv)))
    pv = np.array(pv)
    # about half the observed gains are exactly 0 (the effect stays at its bound in every refit): their
    # p-values are large, so the check is one-sided: valid (not below the level), not uniform
    assert np.mean(pv < 0.05) <= 0.12, np.mean(pv < 0.05)
    assert 0.12 <= np.mean(pv < 0.2) <= 0.28, np.mean(pv < 0.2)


def test_structure_pooled_over_pushes_holds_its_level_and_finds_what_each_push_misses():
    """Three pushes of 60 samples, AR(1) noise (rho 0.9, the fitted rho exact). Pure noise: the pooled
    block's p-values are uniform (KS) and it flags 1% +- sampling; a cubic common to the pushes, 0.13 N
    against 0.03 N marginal noise: the pooled block flags most replicates, the per-push blocks well under
    half of them (measured: 0.82 against 0.40 over 300; docs/validation.md)."""
    from scipy import stats

    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit
    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(7)
    n, e, sd, rho = 60, np.zeros(0), 0.03, 0.9
    D = np.linspace(0.0, 0.08, n)
    m = ForwardModel(
        [PushData(f"h{k}", 0.45 + 0.1 * k, D, np.zeros(n), e, e.astype(int), e, e, None) for k in range(3)], 0.8
    )
    u = 2 * D / D[-1] - 1
    dg = Diagnoser(m)

    def run(amp, reps):
        pooled_p, pooled_flag, push_flag, unexplained = [], [], [], []
        for _ in range(reps):
            r = np.concatenate([ar1_noise(rng, sd, rho, n) + amp * (u**3 - 0.6 * u) for _ in range(3)])
            fit = MapFit((), np.zeros(2), sd * np.sqrt(1 - rho**2), 1.0, r, e, np.zeros((r.size, 2)), 0.0, rho)
            st = dg.structure(fit)
            *pushes, pooled = st["blocks"]
            assert pooled["push"] == "all" and pooled["n"] == 3 * n and len(pushes) == 3
            pooled_p.append(pooled["p_value"])
            pooled_flag.append(pooled["structured"])
            push_flag.append(any(b["structured"] for b in pushes))
            unexplained.append(st["unexplained_structure"])
        assert unexplained == [a or b for a, b in zip(pooled_flag, push_flag, strict=True)]
        return np.array(pooled_p), np.mean(pooled_flag), np.mean(push_flag)

    p, pooled_rate, push_rate = run(0.0, 1000)
    assert stats.kstest(p, "uniform").pvalue > 1e-3
    assert 0.002 <= pooled_rate <= 0.025 and push_rate <= 0.01
    _, pooled_rate, push_rate = run(0.13, 300)
    assert pooled_rate >= 0.7 and push_rate <= 0.55


def test_structure_blocks_match_an_independent_gls_and_wls_computation():
    """Every number of the structure blocks against a dense reference written here: forces by GLS under the
    AR(1) correlation matrix (Cholesky), shapes by weighted least squares with each point's sd, the pooled
    block by summing the force blocks; which blocks exist (at least 20 rows; a push without forces still
    gets its shape block) and the strict inequalities of the verdict."""
    from scipy import linalg, stats

    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit, _legendre
    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(11)
    rho, sig_m, scale = 0.8, 0.04, 2.5
    D = np.linspace(0.0, 0.06, 60)
    u = 2 * D / D[-1] - 1
    pushes, rf, rs = [], [], []
    for name, h, n_force, n_pts in (("a", 0.45, 60, 20), ("b", 0.55, 60, 19), ("c", 0.65, 0, 35)):
        Dk = D[:n_force]
        z = np.linspace(0.05, h, n_pts)
        sd = 0.001 * (1.0 + rng.random(n_pts))  # per-point sd: uneven weights
        pushes.append(PushData(name, h, Dk, np.zeros(n_force), np.zeros(0), np.zeros(n_pts, int), z, z, sd))
        rf.append(ar1_noise(rng, sig_m, rho, n_force) + 0.02 * (u[:n_force] ** 3 - 0.6 * u[:n_force]))
        rs.append(scale * sd * rng.standard_normal(n_pts) + 0.002 * np.sin(3 * z / h))
    m = ForwardModel(pushes, 0.8)
    r_force, r_shape = np.concatenate(rf), np.concatenate(rs)
    e = np.zeros(0)
    fit = MapFit((), np.zeros(2), sig_m * np.sqrt(1 - rho**2), scale, r_force, r_shape, e, 0.0, rho)
    st = Diagnoser(m).structure(fit, ratio=0.0, alpha=1.0, pooled_alpha=1.0)
    got = {(b["push"], b["kind"]): b for b in st["blocks"]}
    assert list(got) == [("a", "force"), ("a", "shape"), ("b", "force"), ("c", "shape"), ("all", "force (pooled)")]

    def f_test(yw, Bw):
        coef = np.linalg.lstsq(Bw, yw, rcond=None)[0]
        fitted = Bw @ coef
        q, n = Bw.shape[1], yw.size
        ss_fit, ss_res = fitted @ fitted, np.sum((yw - fitted) ** 2)
        return coef, ss_fit, ss_res, stats.f.sf((ss_fit / q) / (ss_res / (n - q)), q, n - q)

    pooled = np.zeros(4)
    for k, name in ((0, "a"), (1, "b")):
        n = rf[k].size
        chol = linalg.cholesky(linalg.toeplitz(rho ** np.arange(n)), lower=True)
        B = _legendre(D)
        coef, ss_fit, ss_res, p = f_test(
            linalg.solve_triangular(chol, rf[k], lower=True), linalg.solve_triangular(chol, B, lower=True)
        )
        smooth = B @ coef
        b = got[(name, "force")]
        assert b["n"] == n and b["p_value"] == pytest.approx(p, rel=1e-8)
        assert b["structured_sd_ratio"] == pytest.approx(np.std(smooth) / sig_m, rel=1e-8)
        pooled += [ss_fit * (1 - rho**2), ss_res * (1 - rho**2), np.sum((smooth - smooth.mean()) ** 2), n]
    q = 6
    b = got[("all", "force (pooled)")]
    assert b["n"] == 120
    assert b["p_value"] == pytest.approx(
        stats.f.sf((pooled[0] / (2 * q)) / (pooled[1] / (120 - 2 * q)), 2 * q, 120 - 2 * q), rel=1e-8
    )
    assert b["structured_sd_ratio"] == pytest.approx(np.sqrt(pooled[2] / pooled[3]) / sig_m, rel=1e-8)
    for k, name in ((0, "a"), (2, "c")):
        w = 1.0 / (pushes[k].sd_m * scale)
        B = _legendre(pushes[k].z_m)
        _, ss_fit, ss_res, p = f_test(rs[k] * w, B * w[:, None])
        n = rs[k].size
        s2 = ss_res / (n - q)
        b = got[(name, "shape")]
        assert b["n"] == n and b["p_value"] == pytest.approx(p, rel=1e-8)
        assert b["structured_sd_ratio"] == pytest.approx(np.sqrt(max(0.0, (ss_fit - q * s2) / n) / s2), rel=1e-8)
    # the verdict's inequalities are strict: a block exactly at alpha (or at the sd ratio) is not structured
    for key, level in ((("a", "force"), "alpha"), (("all", "force (pooled)"), "pooled_alpha")):
        p_at = got[key]["p_value"]
        at = {(x["push"], x["kind"]): x for x in Diagnoser(m).structure(fit, ratio=0.0, **{level: p_at})["blocks"]}
        above = {
            (x["push"], x["kind"]): x
            for x in Diagnoser(m).structure(fit, ratio=0.0, **{level: np.nextafter(p_at, 1.0)})["blocks"]
        }
        assert not at[key]["structured"] and above[key]["structured"]
        r_at = got[key]["structured_sd_ratio"]
        flags = [
            {(x["push"], x["kind"]): x for x in Diagnoser(m).structure(fit, ratio=r, **{level: 1.0})["blocks"]}[key]
            for r in (r_at, np.nextafter(r_at, 0.0))
        ]
        assert not flags[0]["structured"] and flags[1]["structured"]


def test_heldout_comparison_is_the_pooled_rmse_drop_and_the_dense_ar1_log_density_gain():
    """gain = 1 - RMSE after / RMSE before over all held-out samples pooled; log_score_gain = the sum over
    units of the held-out log density under each refit's AR(1) noise (dense multivariate normal here)."""
    from scipy import linalg, stats

    from bayesrod.inference.diagnose import HeldoutErrors, heldout_comparison

    rng = np.random.default_rng(2)
    sizes = (30, 45)
    before = [HeldoutErrors(rng.normal(0, 0.3, n), 0.1, 0.7) for n in sizes]
    after = [HeldoutErrors(rng.normal(0, 0.2, n), 0.08, 0.5) for n in sizes]

    def dense(u):  # sigma_force is the innovation sd: the marginal variance is sigma^2 / (1 - rho^2)
        n = u.errors_N.size
        cov = u.sigma_force**2 / (1 - u.rho_force**2) * linalg.toeplitz(u.rho_force ** np.arange(n))
        return stats.multivariate_normal(np.zeros(n), cov).logpdf(u.errors_N)

    got = heldout_comparison(before, after)
    rms = [np.sqrt(np.mean(np.concatenate([u.errors_N for u in us]) ** 2)) for us in (before, after)]
    assert got["gain"] == pytest.approx(1 - rms[1] / rms[0], rel=1e-12)
    want = sum(dense(a) - dense(b) for a, b in zip(after, before, strict=True))
    assert got["log_score_gain"] == pytest.approx(want, rel=1e-10)
    for u in before:
        assert u.log_density().sum() == pytest.approx(dense(u), rel=1e-12)
    zero = [HeldoutErrors(np.zeros(5), 0.1, 0.5)]
    assert heldout_comparison(zero, zero)["gain"] == 0.0  # no error before: nothing to gain
    assert heldout_comparison([], []) == {"gain": 0.0, "log_score_gain": 0.0}


def test_the_small_helpers_of_the_verdict_against_their_definitions():
    """_ar1_noise: stationary AR(1) per push (marginal variance sigma^2 / (1 - rho^2) from each push's
    first sample on, lag-1 correlation rho inside a push, none across a restart); lag1 pooled over pushes;
    _hold: past a slip the last finite force is held (0 before any); _legendre over the range of t."""
    from bayesrod.inference.diagnose import _ar1_noise, _hold, _legendre, lag1

    rho, sigma = 0.8, 0.3
    first = np.zeros(50, bool)
    first[[0, 30]] = True
    x = _ar1_noise(first, sigma, rho, 40_000, np.random.default_rng(0))
    var = x.var(axis=1)
    np.testing.assert_allclose(var, sigma**2 / (1 - rho**2), rtol=0.05)
    corr = np.mean(x[1:] * x[:-1], axis=1) / sigma**2 * (1 - rho**2)
    np.testing.assert_allclose(np.delete(corr, 29), rho, atol=0.02)
    assert abs(corr[29]) < 0.02  # sample 30 restarts: independent of sample 29

    r = np.array([1.0, 2.0, -1.0, 0.5, 3.0, -2.0])
    f = np.array([True, False, False, True, False, False])
    num = 1.0 * 2.0 + 2.0 * -1.0 + 0.5 * 3.0 + 3.0 * -2.0  # pairs within a push only
    assert lag1(r, f) == pytest.approx(num / (1.0 + 4.0 + 0.25 + 9.0))
    assert lag1(np.array([1.0, 2.0, 3.0]), np.array([True, False, False])) == pytest.approx(8.0 / 5.0)
    assert lag1(np.array([1.0, 2.0]), np.array([True, False])) == 0.0  # under three samples
    assert lag1(np.zeros(4), np.array([True, False, False, False])) == 0.0  # no variance

    np.testing.assert_array_equal(_hold([np.nan, 1.0, 2.0, np.nan, np.inf, 5.0, np.nan]), [0, 1, 2, 2, 2, 5, 5])
    np.testing.assert_array_equal(_hold([1.0, 2.0]), [1.0, 2.0])
    np.testing.assert_array_equal(_hold([np.nan, np.nan]), [0.0, 0.0])

    t = np.array([3.0, 5.0, 4.0, 7.0])
    B = _legendre(t)
    assert B.shape == (4, 6)
    np.testing.assert_allclose(B, np.polynomial.legendre.legvander(np.array([-1.0, 0.0, -0.5, 1.0]), 5))


def test_the_bootstrap_p_value_is_one_plus_the_draws_at_or_above_over_draws_plus_one():
    """The bootstrap's p-value (1 + #{draws with gain >= observed}) / (n_draws + 1): 1 / (n + 1) for a gain no
    draw reaches, 1 for one every draw reaches, reproducible for a seed (0 by default, 500 draws), and 1
    when nothing can be held out."""
    from bayesrod.inference.diagnose import MapFit, null_heldout_gain
    from bayesrod.inference.likelihood import PushData

    n, e = 40, np.zeros(0)
    D = np.linspace(0.001, 0.05, n)
    pushes = [PushData(f"h{k}", 0.4 + 0.1 * k, D, np.zeros(n), e, e.astype(int), e, e, None) for k in range(3)]
    m = ForwardModel(pushes, 0.8)
    u = D[np.arange(3 * n) % n] / D[-1]
    J = np.column_stack([u, u**2])
    rng = np.random.default_rng(3)
    x = np.array([0.0, 1.0])  # p inside its bounds
    cur = MapFit((), x, 0.02, 1.0, rng.normal(0, 0.02, 3 * n), e, J, 0.0, 0.5, J)
    new = MapFit((), x, 0.02, 1.0, cur.r_force - 0.01 * u**3, e, J, 0.0, 0.5, J)
    dg = Diagnoser(m)
    assert null_heldout_gain(dg, cur, new, np.inf) == pytest.approx(1 / 501)
    assert null_heldout_gain(dg, cur, new, np.inf, n_draws=99) == pytest.approx(1 / 100)
    assert null_heldout_gain(dg, cur, new, -np.inf) == 1.0
    mid = null_heldout_gain(dg, cur, new, 0.0)
    assert 0.05 < mid < 0.95  # a gain some draws reach: the count matters
    assert mid == null_heldout_gain(dg, cur, new, 0.0, n_draws=500, seed=0)
    assert mid != null_heldout_gain(dg, cur, new, 0.0, seed=1)
    one = ForwardModel([PushData("h", 0.5, D[:4], np.zeros(4), e, e.astype(int), e, e, None)], 0.8)  # too short
    J1 = J[:4]
    short = MapFit((), np.zeros(2), 0.02, 1.0, np.zeros(4), e, J1, 0.0, 0.5, J1)
    assert null_heldout_gain(Diagnoser(one), short, short, 0.1) == 1.0


@pytest.mark.parametrize("bounded", [False, True])
def test_the_bootstrap_refits_match_dense_generalised_least_squares_draw_by_draw(bounded):
    """The bootstrap's linearised refits written out densely here (AR(1) covariance of the training forces,
    each shape point's variance, leave one height out) from the same random stream: the same p-value at
    observed gains between consecutive draws' gains. Shapes weigh against forces, so the relative
    weighting of the two is checked as well. ``bounded``: the second parameter sits 0.002 above its lower
    bound and the added effect is one-sided (amplitude >= 0); the reference minimises the GLS objective
    over every active set of the two bounds, draw by draw."""

    from scipy import linalg

    from bayesrod.inference.diagnose import MapFit, null_heldout_gain
    from bayesrod.inference.likelihood import PushData

    n, npt, rho, sig, scale = 30, 12, 0.7, 0.02, 1.5
    D = np.linspace(0.001, 0.05, n)
    rng = np.random.default_rng(4)
    pushes = []
    for k in range(3):
        z = np.linspace(0.05, 0.4 + 0.1 * k, npt)
        sd = 0.002 * (1 + rng.random(npt))
        pushes.append(PushData(f"h{k}", 0.4 + 0.1 * k, D, np.zeros(n), np.zeros(0), np.zeros(npt, int), z, z, sd))
    m = ForwardModel(pushes, 0.8)
    u = np.r_[D[np.arange(3 * n) % n] / D[-1], np.concatenate([p.z_m for p in pushes])]
    J = np.column_stack([u, u**2, np.r_[np.zeros(3 * n), np.ones(3 * npt) * 0.01]])
    rf, rs = rng.normal(0, 0.02, 3 * n), rng.normal(0, 0.003, 3 * npt)
    x = np.array([0.0, 0.002 if bounded else 0.0, 0.0])
    cur = MapFit((), x, sig, scale, rf, rs, J, 0.0, rho, J)
    delta = 0.01 * u**3
    added = ("base_compliance",) if bounded else ()
    new = MapFit(added, np.r_[x, 0.0], sig, scale, rf - delta[: 3 * n], rs - delta[3 * n :], J, 0.0, rho, J)
    box = (np.array([-np.inf, 0.0 if bounded else -np.inf, -np.inf]), np.full(3, np.inf))
    n_draws, seed = 200, 5

    # the reference: the same draws, dense GLS refits
    g = np.random.default_rng(seed)
    eta = g.standard_normal((3 * n, n_draws)) * sig
    eps_f = np.empty_like(eta)
    for t in range(3 * n):
        eps_f[t] = eta[t] / np.sqrt(1 - rho**2) if t % n == 0 else rho * eps_f[t - 1] + eta[t]
    sd_p = scale * np.concatenate([p.sd_m for p in pushes])
    eps = np.r_[eps_f, g.standard_normal((3 * npt, n_draws)) * sd_p[:, None]]
    block = sig**2 / (1 - rho**2) * linalg.toeplitz(rho ** np.arange(n))
    push_of = np.r_[np.repeat(np.arange(3), n), np.repeat(np.arange(3), npt)]
    is_force = np.r_[np.ones(3 * n, bool), np.zeros(3 * npt, bool)]
    X1 = np.column_stack([J, delta])
    sq = np.zeros((2, n_draws))
    for k in range(3):
        train = push_of != k  # two pushes' forces (one AR(1) block each), then their shape points
        Ci = np.linalg.inv(linalg.block_diag(block, block, np.diag(sd_p[push_of[3 * n :] != k] ** 2)))
        held = is_force & (push_of == k)
        order = np.r_[np.flatnonzero(is_force & train), np.flatnonzero(~is_force & train)]
        for i, X in enumerate((J, X1)):
            A, y = X[order], eps[order]
            lower = np.r_[-np.inf, -x[1] if bounded else -np.inf, -np.inf, 0.0 if bounded else -np.inf][: X.shape[1]]
            best = _lower_bounded_gls(A, y, Ci, lower)
            if bounded:  # the bounds bind in some draws, or this checks nothing new
                assert np.mean(np.any(np.isclose(best, lower[:, None]), axis=0)) > 0.1
            sq[i] += np.sum((eps[held] - X[held] @ best) ** 2, axis=0)
    gains = 1 - np.sqrt(sq[1] / sq[0])
    for obs in _between_draws(gains):
        want = (1 + np.sum(gains >= obs)) / (n_draws + 1)
        got = null_heldout_gain(Diagnoser(m), cur, new, obs, n_draws=n_draws, seed=seed, bounds=box)
        assert got == pytest.approx(want)


def test_the_bootstrap_with_preloads_matches_dense_bounded_refits_and_a_whitened_held_out_preload():
    """Forces only, a preload per push (the held-out push's own preload cannot be learnt from the others):
    the dense reference refits the training pushes by GLS within the bounds (p and the training preloads
    near 0, a one-sided effect), then fits the held-out push's preload to what is left by least squares on
    its AR(1)-whitened residuals within its box, as ``_held_x`` does; the bootstrap's p-values match
    at observed gains between consecutive draws' gains."""

    from scipy import linalg

    from bayesrod.inference.diagnose import MapFit, null_heldout_gain

    n, rho, sig, n_draws, seed = 30, 0.8, 0.02, 200, 9
    m, D, e0 = _three_linear_pushes(n, preload=True)
    push = m.force_push
    u = D[np.arange(3 * n) % n]
    pre_cols = [(push == k) * (1.0 + u) * 3.0 for k in range(3)]  # dF/d(preload), on its own push only
    J = np.column_stack([u, u**2, *pre_cols])
    x = np.array([0.0, 0.002, 0.0005, 0.0, 0.01])  # p and two preloads at or near their lower bound 0
    rng = np.random.default_rng(2)
    rf = rng.normal(0, 0.02, 3 * n)
    cur = MapFit((), x, sig, 1.0, rf, e0, J, 0.0, rho, J)
    delta = 0.01 * u**3
    new = MapFit(("base_compliance",), np.r_[x, 0.0], sig, 1.0, rf - delta, e0, J, 0.0, rho, J)

    eps, C = _bootstrap_ar1_draws(seed, n, sig, rho, n_draws)
    Ci2 = np.linalg.inv(linalg.block_diag(C, C))
    Ci1 = np.linalg.inv(C)
    X1 = np.column_stack([J, delta])
    lower_all = np.r_[-np.inf, -x[1:], 0.0]  # steps: p and preloads down to 0, the amplitude >= 0
    upper_all = np.r_[np.inf, np.inf, 0.08 - x[2:], np.inf]  # preloads up to 0.1 L
    sq = np.zeros((2, n_draws))
    for k in range(3):
        train, held = push != k, push == k
        for i, X in enumerate((J, X1)):
            cols = [c for c in range(X.shape[1]) if c != 2 + k]
            A, y = X[train][:, cols], eps[train]
            lower = lower_all[cols]
            best = _lower_bounded_gls(A, y, Ci2, lower)
            err = eps[held] - X[held][:, cols] @ best
            col = X[held][:, 2 + k]
            c = np.clip((col @ Ci1 @ err) / (col @ Ci1 @ col), lower_all[2 + k], upper_all[2 + k])
            sq[i] += np.sum((err - np.outer(col, c)) ** 2, axis=0)
    gains = 1 - np.sqrt(sq[1] / sq[0])
    for obs in _between_draws(gains):
        want = (1 + np.sum(gains >= obs)) / (n_draws + 1)
        assert null_heldout_gain(Diagnoser(m), cur, new, obs, n_draws=n_draws, seed=seed) == pytest.approx(want)


def test_the_bootstrap_with_height_errors_keeps_their_prior_and_holds_the_held_out_push_at_its_height():
    """Forces only, a contact-height error per push under a N(0, sd^2) prior: the dense reference refits the
    training pushes by GLS plus the training errors' prior rows ((dh_cur + step) / sd), the held-out push's
    error column left out (its error is not fitted: it is predicted at its current value in both models);
    the bootstrap's p-values match at observed gains between consecutive draws' gains. Without the prior
    rows the p-values differ (the refits then fit the errors freely)."""

    from scipy import linalg

    from bayesrod.inference.diagnose import MapFit, null_heldout_gain

    n, rho, sig, sd, n_draws, seed = 30, 0.8, 0.02, 0.003, 200, 11
    m, D, e0 = _three_linear_pushes(n, height_sd_m=sd)
    push = m.force_push
    u = D[np.arange(3 * n) % n]
    h_cols = [(push == k) * (1.0 + u) * 10.0 for k in range(3)]  # dF/d(height error), on its own push only
    J = np.column_stack([u, u**2, *h_cols])
    x = np.array([0.0, 0.5, 0.002, -0.001, 0.003])
    rng = np.random.default_rng(3)
    rf = rng.normal(0, 0.02, 3 * n)
    cur = MapFit((), x, sig, 1.0, rf, e0, J, 0.0, rho, J, n_heights=3)
    delta = 0.01 * np.cos(3 * np.pi * u)  # not nearly collinear with u and u^2: the p box does not bind
    new = MapFit(("force_offset",), np.r_[x, 0.0], sig, 1.0, rf - delta, e0, J, 0.0, rho, J, n_heights=3)

    eps, C = _bootstrap_ar1_draws(seed, n, sig, rho, n_draws)
    Ci = np.linalg.inv(linalg.block_diag(C, C))
    X1 = np.column_stack([J, delta])
    sq = {True: np.zeros((2, n_draws)), False: np.zeros((2, n_draws))}
    for k in range(3):
        train, held = push != k, push == k
        for i, X in enumerate((J, X1)):
            cols = [c for c in range(X.shape[1]) if c != 2 + k]
            A, y = X[train][:, cols], eps[train]
            dh = [j for j, c in enumerate(cols) if 2 <= c <= 4]  # the training pushes' errors
            for prior in (True, False):
                H = A.T @ Ci @ A
                b = A.T @ Ci @ y
                if prior:
                    H[dh, dh] += 1.0 / sd**2
                    b[dh] -= (x[[cols[j] for j in dh]] / sd**2)[:, None]
                best = np.linalg.solve(H, b)
                sq[prior][i] += np.sum((eps[held] - X[held][:, cols] @ best) ** 2, axis=0)
    gains = {k: 1 - np.sqrt(v[1] / v[0]) for k, v in sq.items()}
    differs = False
    for obs in _between_draws(gains[True]):
        want = (1 + np.sum(gains[True] >= obs)) / (n_draws + 1)
        got = null_heldout_gain(Diagnoser(m), cur, new, obs, n_draws=n_draws, seed=seed)
        assert got == pytest.approx(want)
        differs |= abs((1 + np.sum(gains[False] >= obs)) / (n_draws + 1) - want) > 0.02
    assert differs  # the prior rows change the answer: this checks them


def _bootstrap_ar1_draws(seed: int, n: int, sig: float, rho: float, n_draws: int):
    """The bootstrap's force draws for three pushes of ``n`` samples, from its seed, written out: (3 n, n_draws)
    AR(1) noise per push (innovation sd ``sig``), and one push's dense covariance (n, n)."""
    from scipy import linalg

    g = np.random.default_rng(seed)
    eta = g.standard_normal((3 * n, n_draws)) * sig
    eps = np.empty_like(eta)
    for t in range(3 * n):
        eps[t] = eta[t] / np.sqrt(1 - rho**2) if t % n == 0 else rho * eps[t - 1] + eta[t]
    return eps, sig**2 / (1 - rho**2) * linalg.toeplitz(rho ** np.arange(n))


def _between_draws(gains: np.ndarray, at=(0.1, 0.5, 0.9)) -> list[float]:
    """Observed gains halfway between two consecutive distinct draws' gains near the quantiles ``at``.

    Bounded refits tie many draws at a gain of 0 up to round-off (the amplitude held at its bound): a
    threshold between two of those would test round-off, not the refits."""
    g = np.sort(gains)
    out = []
    for q in at:
        i = int(q * (g.size - 1))
        while i + 1 < g.size and g[i + 1] - g[i] < 1e-9:
            i += 1
        assert i + 1 < g.size
        out.append(0.5 * (g[i] + g[i + 1]))
    return out


def _lower_bounded_gls(A: np.ndarray, Y: np.ndarray, Ci: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """Coefficients (k, d) minimising (y - A c)' Ci (y - A c) for each column y of Y subject to c >= lower,
    by brute force: every set of columns held at their (finite) lower bound is solved, and of the feasible
    solutions the one with the least objective is kept (exact for this convex problem)."""
    from itertools import product

    k, d = A.shape[1], Y.shape[1]
    best, obj = np.zeros((k, d)), np.full(d, np.inf)
    for fixed in product((False, True), repeat=k):
        fixed = np.array(fixed)
        if not np.all(np.isfinite(lower[fixed])):
            continue
        coef = np.zeros((k, d))
        coef[fixed] = lower[fixed][:, None]
        free = ~fixed
        rest = Y - A[:, fixed] @ coef[fixed]
        coef[free] = np.linalg.solve(A[:, free].T @ Ci @ A[:, free], A[:, free].T @ Ci @ rest)
        r = Y - A @ coef
        o = np.einsum("nd,nm,md->d", r, Ci, r)
        take = np.all(coef >= lower[:, None] - 1e-12, axis=0) & (o < obj - 1e-12)
        best[:, take], obj[take] = coef[:, take], o[take]
    return best


def _three_linear_pushes(n: int, **model):
    """A model of three pushes of ``n`` force samples each (heights 0.4-0.6 m, L 0.8 m) for linear stand-ins:
    (model, the samples' displacement scaled to [0.02, 1], an empty array); ``model``: ForwardModel's
    settings (preload, height_sd_m)."""
    from bayesrod.inference.likelihood import PushData

    D = np.linspace(0.001, 0.05, n) / 0.05
    e = np.zeros(0)
    pushes = [PushData(f"h{k}", 0.4 + 0.1 * k, D, np.zeros(n), e, e.astype(int), e, e, None) for k in range(3)]
    return ForwardModel(pushes, 0.8, **model), D, e


def _loho_gain(fit, J0: np.ndarray, X1: np.ndarray, y: np.ndarray, push: np.ndarray) -> float:
    """Held-out RMSE gain of the linear model X1 over J0, each refitted without one push at a time
    (``fit(X, y, rows)``: the coefficients from the rows ``rows``)."""
    sq0 = sq1 = 0.0
    for k in np.unique(push):
        train, held = push != k, push == k
        sq0 += np.sum((y[held] - J0[held] @ fit(J0, y, train)) ** 2)
        sq1 += np.sum((y[held] - X1[held] @ fit(X1, y, train)) ** 2)
    return float(1 - np.sqrt(sq1 / sq0))

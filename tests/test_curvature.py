"""GP curvature: 90% bands cover the truth on analytic arcs and elastica shapes; derivative variance checks."""

import numpy as np
import pytest

from bayesrod.physics.elastica import contact_from_force_nd
from bayesrod.vision.curvature import fit_curvature_gp, tangent_angles


def _coverage(s, theta_true, kappa_true, sd, rng, reps=10, key="kappa_sd"):
    cov = []
    for _ in range(reps):
        gp = fit_curvature_gp(s, theta_true(s) + rng.normal(0, sd, s.size))
        q = np.linspace(s[2], s[-3], 120)  # interior points
        pred = gp.predict(q)
        half = 1.6449 * (pred["kappa_sd"] if key == "kappa_sd" else np.sqrt(pred["kappa_var"]))
        cov.append(np.mean(np.abs(pred["kappa"] - kappa_true(q)) <= half))
    return float(np.mean(cov))


@pytest.mark.parametrize(
    "name,theta,kappa",
    [
        ("circle", lambda s: 0.2 + 2.0 * s, lambda s: np.full_like(s, 2.0)),
        ("clothoid", lambda s: 3.0 * s**2, lambda s: 6.0 * s),
        ("sine", lambda s: 0.3 * np.sin(6 * s), lambda s: 1.8 * np.cos(6 * s)),
    ],
)
def test_band_covers_analytic_arcs(name, theta, kappa):
    s = np.linspace(0, 0.8, 80)
    cover = _coverage(s, theta, kappa, 0.01, np.random.default_rng(1))
    assert 0.80 <= cover <= 0.98, cover


def test_band_covers_elastica_curvature():
    f, eta, p = 1.2, 0.5625, 0.43
    res = contact_from_force_nd(f, eta, p, n_steps=256, keep_shape=True)
    sig = np.linspace(0, 1, 257)
    phi = res["grid"][:, 2]
    keep = sig < 0.95 * float(res["sig_c"])  # below the contact, where the rod is loaded
    L = 0.8
    s = sig[keep][::3] * L
    th = np.interp(s, sig * L, phi)

    def theta(x):
        return np.interp(x, sig * L, phi)

    def kappa(x):
        return np.interp(x, sig * L, np.gradient(phi, sig * L))

    cover = _coverage(s, theta, kappa, 0.005, np.random.default_rng(2))
    assert th.size > 20 and 0.80 <= cover <= 0.98, cover


def test_posterior_band_is_conservative_on_smooth_truth():
    """The documented reason the calibrated band is the sampling one: the Matern-3/2 posterior over-covers."""
    s = np.linspace(0, 0.8, 80)
    cover = _coverage(s, lambda x: 3.0 * x**2, lambda x: 6.0 * x, 0.01, np.random.default_rng(4), key="var")
    assert cover > 0.98, cover


def _points_coverage(f, noise_m, reps=20, bias=True):
    """Coverage of the 90% kappa band, end to end as the direct estimator uses it: noisy centerline
    points every 1 cm below the contact -> tangent angles -> GP (elastica, eta = 0.5625, p = 0.43)."""
    eta, p, L = 0.5625, 0.43, 0.8
    res = contact_from_force_nd(f, eta, p, n_steps=400, keep_shape=True)
    sig = np.linspace(0, 1, 401)
    g = res["grid"]
    kappa_true = np.gradient(g[:, 2], sig * L)
    idx = np.flatnonzero(sig < 0.95 * float(res["sig_c"]))[::5]
    rng = np.random.default_rng(5)
    cover = []
    for _ in range(reps):
        sd = np.full(idx.size, noise_m)
        x = g[idx, 0] * L + rng.normal(0, noise_m, idx.size)
        z = g[idx, 1] * L + rng.normal(0, noise_m, idx.size)
        ta = tangent_angles(x, z, sd)
        gp = fit_curvature_gp(ta["s"], ta["theta"], noise_cov=ta["cov"], bias=bias)
        q = np.linspace(0.03, 0.9 * ta["s"][-1], 60)
        pr = gp.predict(q)
        truth = np.interp(q, sig * L, kappa_true)
        cover.append(np.mean(np.abs(pr["kappa"] - truth) <= 1.6449 * pr["kappa_sd"]))
    return float(np.mean(cover))


@pytest.mark.parametrize(
    "f,noise_m",
    [
        # measured (20 replicates): 0.93, 0.85, 0.97, 0.91, 0.93; the sampling sd alone 0.74, 0.71, 0.87, 0.75, 0.90
        (1.2, 0.0015),
        (2.0, 0.0015),
        (1.2, 0.003),
        (0.6, 0.001),
        (1.2, 0.0003),
        # measured 0.99 (the sampling sd alone 0.94): at small curvature and noisy points the plug-in bias
        # is inflated by the pilot's own noise -- conservative, above the 98% bound. Open in issue 4.
        pytest.param(0.3, 0.0015, marks=pytest.mark.xfail(strict=True, reason="over-covers, docs/vision.md")),
    ],
)
def test_band_covers_elastica_from_noisy_points(f, noise_m):
    assert 0.80 <= _points_coverage(f, noise_m) <= 0.98


@pytest.mark.parametrize("f,noise_m", [(0.6, 0.0005), (0.3, 0.0003)])
def test_bias_term_rescues_the_collapsed_fit(f, noise_m):
    """Precise points, slowly varying curvature: the fit collapses toward the trend (s2 -> 0) and the
    sampling sd alone covers 58-66%; with the plug-in bias 79-81% (measured). Near, not at, nominal."""
    assert _points_coverage(f, noise_m, bias=False) < 0.70
    assert _points_coverage(f, noise_m) > 0.75


def test_quadratic_trend_recovers_linear_curvature():
    """``degree=2`` (used by scripts/curvature_bands_trend.py): a clothoid's kappa = 6 s is in the trend."""
    s = np.linspace(0, 0.8, 80)
    rng = np.random.default_rng(7)
    gp = fit_curvature_gp(s, 3.0 * s**2 + rng.normal(0, 1e-3, s.size), degree=2)
    q = np.linspace(0.05, 0.75, 15)
    np.testing.assert_allclose(gp.predict(q)["kappa"], 6.0 * q, atol=0.05)


def test_tangent_angle_covariance_matches_monte_carlo():
    rng = np.random.default_rng(6)
    s = np.linspace(0, 0.5, 30)
    x, z = 0.1 * s**2, s
    sd = np.full(s.size, 0.001)
    ta = tangent_angles(x, z, sd)
    draws = np.stack(
        [
            tangent_angles(x + rng.normal(0, 1e-3, s.size), z + rng.normal(0, 1e-3, s.size), sd)["theta"]
            for _ in range(4000)
        ]
    )
    emp = np.cov(draws.T)
    np.testing.assert_allclose(np.diag(emp), np.diag(ta["cov"]), rtol=0.1)
    np.testing.assert_allclose(np.diag(emp, 1), np.diag(ta["cov"], 1), rtol=0.15)


def test_derivative_mean_and_variance_match_finite_differences():
    rng = np.random.default_rng(3)
    s = np.linspace(0, 1, 40)
    gp = fit_curvature_gp(s, np.sin(3 * s) + rng.normal(0, 0.02, s.size))
    q = np.array([0.3, 0.55, 0.8])
    h = 1e-5
    pred = gp.predict(q)
    fd_mean = (gp.predict(q + h)["theta"] - gp.predict(q - h)["theta"]) / (2 * h)
    np.testing.assert_allclose(pred["kappa"], fd_mean, rtol=1e-4, atol=1e-6)
    # Var[(f(q+h) - f(q-h)) / 2h] from the posterior covariance -> Var[f'(q)] as h -> 0
    from scipy.linalg import cho_solve

    hh = 1e-4
    for x in q:
        pts = np.array([x - hh, x + hh])
        k, _ = gp._k(pts, gp.s)
        kpp, _ = gp._k(pts, pts)
        cov = kpp - k @ cho_solve((gp.chol, True), k.T)
        fd_var = (cov[0, 0] + cov[1, 1] - 2 * cov[0, 1]) / (2 * hh) ** 2
        assert gp.predict([x])["kappa_var"][0] == pytest.approx(fd_var, rel=2e-2)


@pytest.mark.parametrize("known_cov", [False, True])
def test_marginal_likelihood_gradient_matches_the_reference(known_cov):
    """The hyperparameter fit's fast path (value and analytic gradient from one Cholesky factor) against
    the plain log-determinant formula and its central differences."""
    from bayesrod.vision.curvature import _marginal_nll, _marginal_nll_reference, _trend_basis

    rng = np.random.default_rng(5)
    s = np.linspace(0, 0.8, 30)
    y = np.sin(4 * s) + rng.normal(0, 0.02, s.size)
    P, _ = _trend_basis(s, 0.4, 0.8, 1)
    trend = 0.5**2 * P @ P.T
    cov = 0.02**2 * np.exp(-np.abs(s[:, None] - s[None, :]) / 0.05) if known_cov else None
    for logp in ([np.log(0.3), np.log(0.2)], [np.log(2.0), np.log(0.05)]):
        logp = np.array(logp + ([] if known_cov else [np.log(1e-3)]))
        value, grad = _marginal_nll(logp, s, y, cov, trend)
        assert value == pytest.approx(_marginal_nll_reference(logp, s, y, cov, trend), abs=1e-8)
        h = 1e-6
        fd = [
            (
                _marginal_nll_reference(logp + h * e, s, y, cov, trend)
                - _marginal_nll_reference(logp - h * e, s, y, cov, trend)
            )
            / (2 * h)
            for e in np.eye(logp.size)
        ]
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)


def test_bad_input():
    with pytest.raises(ValueError, match="s_m, theta_rad"):
        fit_curvature_gp([0, 1, 2], [0, 1])
    with pytest.raises(ValueError, match="finite"):
        fit_curvature_gp([0, 1, 2, 3], [0, np.nan, 1, 2])
    with pytest.raises(ValueError, match="^s_m, theta_rad: expected two 1-D arrays of equal length >= 4"):
        fit_curvature_gp([0, 1, 2], [0, 1, 2])  # too few
    with pytest.raises(ValueError, match="^s_m, theta_rad: expected two 1-D arrays"):
        fit_curvature_gp([0, 1, 2, 3, 4], [0, 1, 2, 3])  # enough, but unequal
    with pytest.raises(ValueError, match="^s_m, theta_rad: expected finite values, got NaN or inf"):
        fit_curvature_gp([0, 1, 2, 3], [0, np.inf, 1, 2])
    with pytest.raises(ValueError, match=r"^noise_cov: expected a finite \(5, 5\) matrix, got shape \(3, 3\)"):
        fit_curvature_gp(np.arange(5.0), np.arange(5.0), noise_cov=np.eye(3))
    with pytest.raises(ValueError, match="^noise_cov"):
        fit_curvature_gp(np.arange(5.0), np.arange(5.0), noise_cov=np.full((5, 5), np.nan))


def _dense_posterior(gp, q, y, cov):
    """The posterior of theta(q) and kappa(q) = theta'(q) given data y at gp.s with noise covariance cov,
    written out densely (np.linalg.solve, no Cholesky): Matern-3/2 with the gp's variance and length scale
    plus the polynomial trend with prior sd TREND_SD, around the data's mean."""
    from bayesrod.vision.curvature import TREND_SD

    c = np.sqrt(3.0) / gp.length_scale

    def basis(x):
        u = (x - gp.centre) / gp.span
        j = np.arange(gp.degree + 1)
        return u[:, None] ** j, np.where(j > 0, j * u[:, None] ** np.maximum(j - 1, 0), 0.0) / gp.span

    def k(a, b):  # cov(theta(a), theta(b)) and cov(theta'(a), theta(b))
        r = a[:, None] - b[None, :]
        e = np.exp(-c * np.abs(r))
        (pa, dpa), (pb, _) = basis(a), basis(b)
        return gp.signal_var * (1 + c * np.abs(r)) * e + TREND_SD**2 * pa @ pb.T, (
            -gp.signal_var * c**2 * r * e + TREND_SD**2 * dpa @ pb.T
        )

    K = k(gp.s, gp.s)[0] + cov
    kq, ksq = k(q, gp.s)
    mean = np.mean(y)
    y = y - mean
    pq, dpq = basis(q)
    prior_theta = gp.signal_var + TREND_SD**2 * np.sum(pq**2, axis=1)
    prior_kappa = gp.signal_var * c**2 + TREND_SD**2 * np.sum(dpq**2, axis=1)
    W = np.linalg.solve(K, ksq.T).T
    return {
        "theta": mean + kq @ np.linalg.solve(K, y),
        "theta_var": prior_theta - np.sum(kq * np.linalg.solve(K, kq.T).T, axis=1),
        "kappa": ksq @ np.linalg.solve(K, y),
        "kappa_var": prior_kappa - np.sum(ksq * W, axis=1),
        "kappa_se2": np.einsum("mi,ij,mj->m", W, cov, W),
        "W": W,
    }


def test_posterior_means_and_variances_match_the_dense_gaussian_process():
    """predict's theta, theta_var, kappa, kappa_var, kappa_se2 and kappa_bias2 against the dense formulas."""
    rng = np.random.default_rng(11)
    s = np.linspace(0.0, 0.6, 25)
    y = 0.4 + 0.5 * s + 0.3 * np.sin(5 * s) + rng.normal(0, 0.01, s.size)
    gp = fit_curvature_gp(s, y, noise_sd_rad=0.01)
    np.testing.assert_allclose(gp.noise_cov, 1e-4 * np.eye(s.size), rtol=1e-12)
    assert gp.mean == pytest.approx(np.mean(y)) and gp.centre == pytest.approx(0.3) and gp.span == pytest.approx(0.6)
    assert gp.degree == 1 and gp.pilot.degree == 2 and gp.pilot.pilot is None  # the pilot: one degree more
    q = np.array([0.0, 0.07, 0.31, 0.55, 0.6])
    got = gp.predict(q)
    want = _dense_posterior(gp, q, y, 1e-4 * np.eye(s.size))
    for key in ("theta", "theta_var", "kappa", "kappa_var", "kappa_se2"):
        np.testing.assert_allclose(got[key], want[key], rtol=1e-7, atol=1e-12, err_msg=key)
    assert np.all(got["theta_var"] > 0) and np.all(got["theta_var"] < gp.signal_var)
    # the smoothing bias: what this smoother makes of the pilot's theta, minus the pilot's own kappa
    pilot_theta = gp.pilot.predict(gp.s)["theta"]
    bias = want["W"] @ (pilot_theta - gp.mean) - gp.pilot.predict(q)["kappa"]
    np.testing.assert_allclose(got["kappa_bias2"], bias**2, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(got["kappa_sd"], np.sqrt(want["kappa_se2"] + bias**2), rtol=1e-6)


def test_tangent_angles_of_a_curved_line_with_uneven_noise_match_monte_carlo():
    """Curved polyline (its normals turn), point sd varying along it: the angles' variances and
    neighbour covariances, and the noise-lengthening correction of the arc length."""
    rng = np.random.default_rng(8)
    t = np.linspace(0, 0.5, 26)
    x, z = 0.25 * np.sin(4 * t), 0.25 * (1 - np.cos(4 * t)) + t  # turns through ~80 degrees
    sd = np.linspace(0.0005, 0.002, t.size)
    ta = tangent_angles(x, z, sd)
    reps = 6000
    draws, lengths = [], []
    for _ in range(reps):
        noisy = tangent_angles(x + rng.normal(0, sd), z + rng.normal(0, sd), sd)
        draws.append(noisy["theta"])
        lengths.append(noisy["s_nodes"][-1])
    emp = np.cov(np.stack(draws).T)
    np.testing.assert_allclose(np.diag(emp), np.diag(ta["cov"]), rtol=0.08)
    np.testing.assert_allclose(np.diag(emp, 1), np.diag(ta["cov"], 1), rtol=0.15)
    # corrected for the lengthening, the noisy polylines are as long as the clean one: measured 0.919995 m
    # against 0.920004 m (Monte Carlo se 2.7e-5 m); uncorrected they come out 0.921134 m
    clean = np.sum(np.hypot(np.diff(x), np.diff(z)))
    assert np.mean(lengths) == pytest.approx(clean, abs=1.2e-4)
    np.testing.assert_allclose(ta["s"], 0.5 * (ta["s_nodes"][:-1] + ta["s_nodes"][1:]))
    with pytest.raises(ValueError, match="x_m, z_m: expected distinct consecutive points, got a repeated point"):
        tangent_angles([0.0, 0.0, 0.1], [0.0, 0.0, 0.2], [1e-3] * 3)


def test_fitted_hyperparameters_maximise_the_marginal_likelihood():
    """With a known noise covariance the fit's (signal variance, length scale) is the maximum of the plain
    marginal likelihood (_marginal_nll_reference): no point of a grid around it is better."""
    from bayesrod.vision.curvature import TREND_SD, _marginal_nll_reference, _trend_basis

    rng = np.random.default_rng(12)
    s = np.linspace(0.0, 0.6, 30)
    y = 0.2 + 0.3 * np.sin(6 * s) + rng.normal(0, 0.02, s.size)
    cov = 4e-4 * np.eye(s.size)
    gp = fit_curvature_gp(s, y, noise_cov=cov, bias=False)
    P, _ = _trend_basis(s, gp.centre, gp.span, gp.degree)
    trend = TREND_SD**2 * P @ P.T
    best = np.log([gp.signal_var, gp.length_scale])
    f0 = _marginal_nll_reference(best, s, y - np.mean(y), cov, trend)
    for da in (-0.2, 0.0, 0.2):
        for db in (-0.2, 0.0, 0.2):
            f = _marginal_nll_reference(best + [da, db], s, y - np.mean(y), cov, trend)
            assert f >= f0 - 1e-9, (da, db, f, f0)
    # and the optimum itself: the reference's gradient vanishes there (central differences)
    for i in range(2):
        e = np.eye(2)[i] * 1e-4
        g = (
            _marginal_nll_reference(best + e, s, y - np.mean(y), cov, trend)
            - _marginal_nll_reference(best - e, s, y - np.mean(y), cov, trend)
        ) / 2e-4
        assert abs(g) < 1e-2, (i, g)
    assert 0.012 * 0.6 < gp.length_scale < 0.9 * 10 * 0.6  # an interior optimum (measured 3.7 m), not a bound

"""The direct estimator's pieces against hand computations (fast: no dataset, no fit).

The end-to-end checks on simulated twigs are in test_direct.py (slow: a fixture dataset each). These
tests check each function of ``inference/direct.py`` on inputs whose answer is known in closed form
(a small-deflection cantilever: kappa = F (h - z) / EI) or is written out here from the module
docstring's definitions, so that a single-line change to the estimator fails in seconds
(scripts/mutation.py, target ``direct``).
"""

import dataclasses

import numpy as np
import pytest

from bayesrod.dataset.model import ForceSeries, Push, ShapeFrame
from bayesrod.inference import direct as dmod
from bayesrod.inference.direct import (
    DirectEstimate,
    FrameSample,
    _frame_curvature,
    _observed_x_at,
    _push_frames,
    direct_estimate,
    fit_EI0,
    fit_p,
    seed_error_metrics,
)
from bayesrod.physics.elastica import contact_from_force, force_from_displacement

EI = 2.0  # N m^2 (constant: the small-deflection beam)
H = 0.4  # m


def _beam_x(z, F, h=H, EI=EI):
    """Small-deflection cantilever with a point load F at h: x(z) below and the straight part above."""
    z = np.asarray(z, float)
    below = F * z**2 * (3 * h - z) / (6 * EI)
    xh, slope = F * h**3 / (3 * EI), F * h**2 / (2 * EI)
    return np.where(z <= h, below, xh + slope * (z - h))


def _beam_frame(F, *, sd=2e-5, n=70, top=1.2, force_sd=0.01, rng=None, pid="p1", h=H):
    z = np.linspace(0.0, top * h, n)
    x = _beam_x(z, F, h)
    if rng is not None:
        x = x + rng.normal(0.0, sd, n)
    return FrameSample(pid, h, 0.0, F, force_sd, F * h**3 / (3 * EI), x, z, np.full(n, sd))


# --------------------------------------------------------------------------------- curvature
def test_frame_curvature_of_a_small_deflection_beam_is_its_moment_over_EI():
    fs = _beam_frame(0.3)
    s = np.array([0.05, 0.15, 0.25, 0.35, 0.9])  # the last is above the data's arc length
    kap, ksd, kse, z = _frame_curvature(fs, s)
    inside = s < 0.39  # below the contact, minus the 1% margin
    truth = 0.3 * (H - s[inside]) / EI
    # within its band (measured: 0.04-0.66 band sd off; the GP smooths the kink at the contact)
    assert np.all(np.abs(kap[inside] - truth) < ksd[inside])
    np.testing.assert_allclose(kap[1:3], truth[1:3], rtol=0.05)  # measured 1.7% and 3.3%
    assert np.all(np.isnan([kap[~inside], ksd[~inside], kse[~inside], z[~inside]]))
    # deflections of 1e-3 of the length: z is the arc length to 1e-5
    np.testing.assert_allclose(z[inside], s[inside], atol=1e-4)
    # the band's sd holds the sampling sd and the smoothing bias: never below the sampling sd alone
    assert np.all(ksd[inside] >= kse[inside]) and np.all(kse[inside] > 0)
    assert np.all(ksd[:3] < 0.12 * truth[:3])  # measured 0.05-0.10: a band that is not vacuous


def test_frame_curvature_uses_only_points_below_the_contact_and_needs_eight():
    fs = _beam_frame(0.3)
    # above the contact the stem is straight: a frame with its points above moved far away gives the
    # same curvature (they are not used), and one with 7 points below gives none
    far = fs.x_m + np.where(fs.z_m >= 0.99 * H, 0.05, 0.0)
    a = _frame_curvature(fs, np.array([0.1, 0.2]))
    b = _frame_curvature(dataclasses.replace(fs, x_m=far), np.array([0.1, 0.2]))
    np.testing.assert_allclose(a, b)
    z7 = np.linspace(0.0, 0.3, 7)
    few = FrameSample("p", H, 0.0, 0.3, 0.01, 0.0, _beam_x(z7, 0.3), z7, np.full(7, 2e-5))
    assert np.all(np.isnan(_frame_curvature(few, np.array([0.1, 0.2]))))


def test_frame_curvature_without_point_sd_fits_a_white_noise_level():
    fs = _beam_frame(0.3)
    kap, *_ = _frame_curvature(dataclasses.replace(fs, sd_m=None), np.array([0.1, 0.2]))
    np.testing.assert_allclose(kap, 0.3 * (H - np.array([0.1, 0.2])) / EI, rtol=0.05)


# ----------------------------------------------------------------------------------- pooling
def _pooled_by_hand(frames, n_bins, s_min):
    """Eq. direct_estimator pooled per bin, written from the module docstring: per frame and bin
    c = kappa / M with sd from the GP band and the force noise; per bin the weighted mean of c with
    weights 1 / se_c^2, its se inflated by the Birge ratio, EI = 1 / c."""
    top = max(f.height_m for f in frames)
    centres = s_min + (np.arange(n_bins) + 0.5) * (top - s_min) / n_bins
    per_bin = {b: [] for b in range(n_bins)}
    samples = []
    for f in frames:
        kap, ksd, kse, z = _frame_curvature(f, centres)
        if not f.force_N > 3 * f.force_sd_N:
            continue
        for b in range(n_bins):
            M = f.force_N * (f.height_m - z[b])
            if not (np.isfinite(kap[b]) and M > 0.05 * f.force_N * f.height_m):
                continue
            c = kap[b] / M
            rel_f = f.force_sd_N / f.force_N
            se = np.hypot(kse[b] / M, c * rel_f)
            sd = np.hypot(ksd[b] / M, c * rel_f)
            per_bin[b].append((c, se))
            samples.append((centres[b], c, sd, f.height_m))
    EIb, seb, relb, nb = (np.full(n_bins, np.nan) for _ in range(4))
    for b, rows in per_bin.items():
        nb[b] = len(rows)
        if len(rows) < 2:
            continue
        c = np.array([r[0] for r in rows])
        w = np.array([r[1] for r in rows]) ** -2.0
        mean = (w @ c) / w.sum()
        chi2 = w @ (c - mean) ** 2 / (len(rows) - 1)
        se = np.sqrt(1.0 / w.sum()) * max(1.0, np.sqrt(chi2))
        if mean > 0:
            EIb[b], relb[b], seb[b] = 1.0 / mean, se / mean, se / mean**2
    return centres, EIb, seb, relb, nb, samples


def test_direct_estimate_pools_frames_as_its_definition_says():
    rng = np.random.default_rng(3)
    frames = [
        _beam_frame(F, rng=rng, sd=4e-5, h=h, pid=f"p{k}")
        for k, (F, h) in enumerate([(0.2, 0.4), (0.35, 0.4), (0.5, 0.3), (0.6, 0.3)])
    ]
    # a frame whose force is within 3 sd of zero contributes nothing
    frames.append(_beam_frame(0.02, rng=rng, sd=4e-5, force_sd=0.01, pid="weak"))
    n_bins, s_min = 9, 0.03
    de = direct_estimate(None, n_bins=n_bins, s_min_m=s_min, frames=frames)
    centres, EIb, seb, relb, nb, samples = _pooled_by_hand(frames, n_bins, s_min)
    np.testing.assert_allclose(de.s_m, centres, rtol=1e-12)
    np.testing.assert_array_equal(de.n, nb.astype(int))
    np.testing.assert_allclose(de.EI, EIb, rtol=1e-10)
    np.testing.assert_allclose(de.se, seb, rtol=1e-10)
    np.testing.assert_allclose(de.rel_se, relb, rtol=1e-10)
    assert np.isfinite(de.EI).sum() >= 6  # the check is not vacuous
    # (both branches of the Birge ratio: test_birge_ratio_inflates_only_when_the_scatter_exceeds_the_errors)
    s, c, sd, h = (np.array(v) for v in zip(*samples, strict=True))
    np.testing.assert_allclose(de.samples["s_m"], s)
    np.testing.assert_allclose(de.samples["EI"], 1.0 / c, rtol=1e-10)
    np.testing.assert_allclose(de.samples["EI_sd"], sd / c**2, rtol=1e-8)
    np.testing.assert_allclose(de.samples["height_m"], h)
    # and the estimate is the beam's EI where the bins are well inside the data
    good = np.isfinite(de.EI) & (de.s_m < 0.25)
    assert np.all(np.abs(de.EI[good] - EI) < 3 * de.se[good] + 0.05 * EI)


def test_birge_ratio_inflates_only_when_the_scatter_exceeds_the_errors(monkeypatch):
    """Two frames per bin with known curvature: se is 1/sqrt(sum w) times max(1, Birge)."""
    centres_seen = {}

    def fake(fs, s_query):
        centres_seen["s"] = s_query
        kap = np.full(s_query.size, fs.force_N * 0.1)  # c = kap / M = 0.1 / (h - z)
        return kap, np.full(s_query.size, fs.x_m[0]), np.full(s_query.size, fs.x_m[0]), np.zeros(s_query.size)

    monkeypatch.setattr(dmod, "_frame_curvature", fake)

    def frame(F, kse):
        return FrameSample("p", 1.0, 0.0, F, 0.0, 0.0, np.full(3, kse), np.zeros(3), None)

    # identical c in both frames: no scatter, se = 1 / sqrt(sum w) exactly
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(1.0, 0.01), frame(2.0, 0.02)])
    s = centres_seen["s"][0]
    M1, M2 = 1.0 * (1 - 0.0), 2.0 * (1 - 0.0)
    c = 0.1
    w = np.array([(M1 / 0.01) ** 2, (M2 / 0.02) ** 2])
    assert s == pytest.approx(0.5)
    assert de.EI[0] == pytest.approx(1 / c) and de.n[0] == 2
    assert de.rel_se[0] == pytest.approx(1 / np.sqrt(w.sum()) / c)
    assert de.se[0] == pytest.approx(de.EI[0] * de.rel_se[0])

    # different c (the second frame's curvature doubled): the scatter inflates se by the Birge ratio
    def fake2(fs, s_query):
        k = fs.force_N * 0.1 * (2.0 if fs.force_N > 1.5 else 1.0)
        return np.full(1, k), np.full(1, fs.x_m[0]), np.full(1, fs.x_m[0]), np.zeros(1)

    monkeypatch.setattr(dmod, "_frame_curvature", fake2)
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(1.0, 0.001), frame(2.0, 0.001)])
    cs = np.array([0.1, 0.2])
    w = np.array([(1.0 / 0.001) ** 2, (2.0 / 0.001) ** 2])
    cbar = w @ cs / w.sum()
    birge = np.sqrt(w @ (cs - cbar) ** 2 / 1)
    assert birge > 1
    assert de.EI[0] == pytest.approx(1 / cbar)
    assert de.rel_se[0] == pytest.approx(birge / np.sqrt(w.sum()) / cbar)
    # one frame in a bin: no estimate (n < 2), but it is counted
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(1.0, 0.01)])
    assert np.isnan(de.EI[0]) and np.isnan(de.se[0]) and de.n[0] == 1
    # a negative pooled compliance: no EI, but the bin's count stays
    monkeypatch.setattr(
        dmod, "_frame_curvature", lambda fs, s: (np.full(1, -0.1), np.full(1, 0.01), np.full(1, 0.01), np.zeros(1))
    )
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(1.0, 0.01), frame(2.0, 0.01)])
    assert np.isnan(de.EI[0]) and de.n[0] == 2
    assert np.isnan(de.samples["EI"]).all()  # a sample with c <= 0 has no EI


def test_direct_estimate_refuses_frames_without_usable_points():
    z = np.linspace(0, 0.3, 5)
    few = FrameSample("p", H, 0.0, 0.3, 0.01, 0.0, _beam_x(z, 0.3), z, np.full(5, 2e-5))
    with pytest.raises(ValueError, match="need 8"):
        direct_estimate(dataclasses.make_dataclass("S", [("specimen", str)])("s"), frames=[few])


# --------------------------------------------------------------------------------------- p fit
def test_fit_p_is_the_weighted_log_linear_least_squares_fit():
    rng = np.random.default_rng(1)
    L = 0.8
    s = np.linspace(0.03, 0.7, 15)
    rel = np.linspace(0.02, 0.2, s.size)
    EIs = 2.0 * (1 - s / L) ** (4 * 0.6) * np.exp(rng.normal(0, 2 * rel))  # scatter beyond the errors
    # rows the fit must skip: NaN EI, zero rel_se, beyond the length
    s_all = np.concatenate([s, [0.2, 0.3, 0.85]])
    EI_all = np.concatenate([EIs, [np.nan, 1.0, 1.0]])
    rel_all = np.concatenate([rel, [0.1, 0.0, 0.1]])
    de = DirectEstimate(s_all, EI_all, EI_all * rel_all, rel_all, np.full(s_all.size, 5), {})
    p, p_se, r2, nb = fit_p(de, L)
    # by hand: y = a + b log(1 - s/L), weights 1/rel^2; se inflated by sqrt(chi2/dof) when above 1
    x, y, w = np.log1p(-s / L), np.log(EIs), rel**-2.0
    coef, cov = np.polyfit(x, y, 1, w=np.sqrt(w), cov="unscaled")
    res = y - np.polyval(coef, x)
    chi2 = w @ res**2
    ybar = w @ y / w.sum()
    assert nb == s.size
    assert p == pytest.approx(coef[0] / 4, rel=1e-10)
    assert chi2 / (s.size - 2) > 1
    assert p_se == pytest.approx(np.sqrt(cov[0, 0] * chi2 / (s.size - 2)) / 4, rel=1e-10)
    assert r2 == pytest.approx(1 - chi2 / (w @ (y - ybar) ** 2), rel=1e-10)
    # exact data: p exact, R^2 = 1, and se not inflated (chi2 = 0 < dof): 1 / sqrt(sum of w x'^2) / 4
    exact = DirectEstimate(s, 2.0 * (1 - s / L) ** 2.4, rel, rel, np.full(s.size, 5), {})
    p, p_se, r2, _ = fit_p(exact, L)
    _, cov = np.polyfit(x, np.log(2.0 * (1 - s / L) ** 2.4), 1, w=np.sqrt(w), cov="unscaled")
    assert p == pytest.approx(0.6, abs=1e-10) and r2 == pytest.approx(1.0, abs=1e-10)
    assert p_se == pytest.approx(np.sqrt(cov[0, 0]) / 4, rel=1e-10)
    # three bins fit; two do not
    three = DirectEstimate(s[:3], EIs[:3], EIs[:3] * rel[:3], rel[:3], np.full(3, 5), {})
    assert fit_p(three, L)[3] == 3
    with pytest.raises(ValueError, match="at least 3 bins.*got 2"):
        fit_p(DirectEstimate(s[:3], np.array([1.0, 1.0, np.nan]), rel[:3], rel[:3], np.full(3, 5), {}), L)


# --------------------------------------------------------------------------- EI0 and the metrics
def test_observed_x_at_interpolates_across_a_gap_and_extrapolates_from_below():
    z = np.array([0.0, 0.1, 0.2, 0.3, 0.5, 0.6])
    x = 2.0 * z + 0.1 * z**2
    fs = FrameSample("p", 0.4, 0.0, 1.0, 0.1, 0.0, x, z, None)
    # across the gap (0.3, 0.5): the straight line between its two ends
    assert _observed_x_at(fs, 0.4) == pytest.approx(x[3] + (x[4] - x[3]) * 0.5)
    assert _observed_x_at(fs, 0.3) == pytest.approx(x[3] + (x[4] - x[3]) * 0.0)
    # nothing above: the line through the last four below
    lo = FrameSample("p", 0.4, 0.0, 1.0, 0.1, 0.0, x[:4], z[:4], None)
    assert _observed_x_at(lo, 0.4) == pytest.approx(np.polyval(np.polyfit(z[:4], x[:4], 1), 0.4))
    # one point below and one above: too little to interpolate; three below and none above: too few
    assert np.isnan(_observed_x_at(FrameSample("p", 0.4, 0, 1, 0.1, 0, x[3:5], z[3:5], None), 0.4))
    assert np.isnan(_observed_x_at(FrameSample("p", 0.4, 0, 1, 0.1, 0, x[:3], z[:3], None), 0.35))
    # two below and one above: interpolated
    two = FrameSample("p", 0.4, 0, 1, 0.1, 0, x[2:5], z[2:5], None)
    assert _observed_x_at(two, 0.4) == pytest.approx(x[3] + (x[4] - x[3]) * 0.5)


def _elastica_frames(EI0, p, L, forces, heights, n=60):
    out = []
    for k, (F, h) in enumerate(zip(forces, heights, strict=True)):
        r = contact_from_force(np.array([F]), np.array([h]), EI0, p, L)
        D = float(r.contact_x_m[0])
        sol = force_from_displacement(D, h, EI0, p, L, keep_shape=True)
        xz = sol.shape_xz_m
        z = np.linspace(0.0, 1.1 * h, n)
        zeta = np.maximum.accumulate(xz[:, 1])
        x = np.interp(z, zeta, xz[:, 0])
        # above the contact the stem is straight along the contact's tangent
        top = z > zeta[-1]
        x[top] = xz[-1, 0]
        out.append(FrameSample(f"p{k}", h, 0.0, float(sol.force_N), 0.01, D, x, z, None))
    return out


def test_fit_EI0_recovers_the_elastica_it_is_given_and_ignores_weak_frames():
    L, EI0, p = 0.8, 2.5, 0.4
    frames = _elastica_frames(EI0, p, L, [2.0, 4.0, 3.0], [0.3, 0.3, 0.4])
    assert fit_EI0(frames, p, L) == pytest.approx(EI0, rel=2e-3)
    # a frame with a force within 3 sd of zero and a wild position does not move it
    wild = dataclasses.replace(frames[0], force_N=0.02, force_sd_N=0.01, x_m=frames[0].x_m + 0.2)
    assert fit_EI0([*frames, wild], p, L) == pytest.approx(fit_EI0(frames, p, L), rel=1e-6)
    # at another taper another EI0 (p is used, not ignored)
    assert abs(fit_EI0(frames, 1.2, L) / EI0 - 1) > 0.05
    with pytest.raises(ValueError, match="EI0_fit"):
        fit_EI0([wild], p, L)


def test_seed_error_metrics_are_the_median_errors_of_the_frames():
    L, EI0, p = 0.8, 2.5, 0.4
    frames = _elastica_frames(EI0, p, L, [2.0, 4.0, 3.0], [0.3, 0.3, 0.4], n=400)
    shape_mm, force_N = seed_error_metrics(frames, EI0, p, L)
    assert shape_mm < 0.05 and force_N < 1e-3  # the model's own frames (interpolated)
    # forces off by 0.1, 0.3, 0.2 N: the median error is 0.2 N; a shift of 1 mm at every point below the
    # contact reads 1 mm times cos(tangent): within 2% of 1 mm at these deflections
    off = [
        dataclasses.replace(f, force_N=f.force_N + dF, x_m=f.x_m + 1e-3)
        for f, dF in zip(frames, [0.1, -0.3, 0.2], strict=True)
    ]
    shape_mm, force_N = seed_error_metrics(off, EI0, p, L)
    assert force_N == pytest.approx(0.2, abs=1e-3)
    assert 0.97 < shape_mm < 1.0
    # a frame whose displacement the model cannot reach (it slips) is skipped; none: NaN
    slipped = dataclasses.replace(frames[0], displacement_m=5 * L)
    assert np.isnan(seed_error_metrics([slipped], EI0, p, L)).all()


def test_push_frames_take_the_engaged_force_at_each_frame_time_in_the_push_direction():
    t = np.linspace(0.0, 10.0, 101)
    F = np.where(t < 8.0, 0.5 * t, 0.0) + 0.3  # rises to 4.3 N, then the slip back to the 0.3 N baseline
    rng = np.random.default_rng(0)
    F = F + rng.normal(0, 0.002, t.size)
    D = 0.01 * t
    z = np.linspace(-0.02, 0.5, 30)
    frames = tuple(ShapeFrame(ts, -0.01 * ts * z, z, np.full(z.size, 1e-4)) for ts in (2.0, 5.0, 9.5))
    push = Push("a", 0.45, ForceSeries(t, F, D), direction=-1, shapes=frames)
    out = _push_frames(push)
    assert [f.time_s for f in out] == [2.0, 5.0]  # 9.5 s is after the slip
    f = out[1]
    assert f.force_N == pytest.approx(0.5 * 5.0, abs=0.02)  # baseline removed
    assert f.displacement_m == pytest.approx(0.05)
    assert f.z_m.min() >= 0 and f.z_m.size == (z >= 0).sum() == 28  # points below the base dropped
    np.testing.assert_allclose(f.x_m, 0.01 * 5.0 * f.z_m)  # direction -1 turns x into the push direction
    assert f.sd_m.size == 28 and f.height_m == 0.45 and f.push_id == "a"
    assert 0 < f.force_sd_N < 0.01
    assert _push_frames(dataclasses.replace(push, shapes=None)) == []
    # frames at the first and last engaged sample are kept; a point at exactly z = 0 is kept; no sd: None
    t_eng = t[F > 0.3 + 0.01]
    z0 = np.linspace(0.0, 0.5, 11)
    ends = tuple(ShapeFrame(ts, 0.001 * z0, z0) for ts in (0.0, 7.9))
    out = _push_frames(dataclasses.replace(push, shapes=ends))
    assert [f.time_s for f in out] == [0.0, 7.9] and t_eng[-1] == pytest.approx(7.9)
    assert out[0].z_m.size == 11 and out[0].sd_m is None


def _elastica_push(pid, h, EI0, p, L, D_max, n_frames=5, n_points=80, sd=2e-5):
    """A noise-free push: forces from the elastica at 40 displacements, then a slip back to zero; frames
    of the centerline (below the contact and a little above) at ``n_frames`` of those times."""
    D = np.linspace(0.0, D_max, 41)[1:]
    F = np.array([float(force_from_displacement(d, h, EI0, p, L).force_N) for d in D])
    t = np.arange(D.size + 5, dtype=float)
    force = ForceSeries(t, np.concatenate([F, np.zeros(5)]), np.concatenate([D, np.full(5, D_max)]))
    shapes = []
    for k in np.linspace(8, D.size - 2, n_frames).astype(int):
        xz = force_from_displacement(D[k], h, EI0, p, L, keep_shape=True).shape_xz_m
        z = np.linspace(0.0, 1.1 * h, n_points)
        zeta = np.maximum.accumulate(xz[:, 1])
        x = np.interp(z, zeta, xz[:, 0])
        shapes.append(ShapeFrame(t[k], x, z, np.full(n_points, sd)))
    return Push(pid, h, force, shapes=tuple(shapes))


def test_two_stage_fit_on_an_elastica_specimen_recovers_its_taper():
    from types import SimpleNamespace

    from bayesrod.inference.direct import engaged_frames, two_stage_fit

    L, EI0, p = 0.8, 2.5, 0.5
    pushes = (_elastica_push("low", 0.3, EI0, p, L, 0.03), _elastica_push("high", 0.45, EI0, p, L, 0.06))
    spec = SimpleNamespace(specimen="s", length_m=L, pushes=pushes)
    frames = engaged_frames(spec)
    assert [f.push_id for f in frames] == ["low"] * 5 + ["high"] * 5
    r = two_stage_fit(spec, n_bins=12)
    # the estimator finds the engaged frames itself when not given them
    np.testing.assert_allclose(direct_estimate(spec, n_bins=12).EI, r.direct.EI, rtol=1e-12)
    # measured: p 0.4962 (se 0.0044), EI0 2.4928, R^2 0.9998, 11 bins, 0.005 mm and 0.0013 N
    assert r.p == pytest.approx(p, abs=0.01) and r.EI0 == pytest.approx(EI0, rel=0.005)
    assert 0.001 < r.p_se < 0.01
    assert r.r2 > 0.999 and r.n_bins == 11 and r.direct.s_m.size == 12
    assert r.shape_rmse_mm < 0.02 and r.force_error_N < 0.005
    d = r.to_dict()
    assert d == {
        "p": r.p,
        "p_se": r.p_se,
        "EI0": r.EI0,
        "taper_fit_r2": r.r2,
        "n_bins": r.n_bins,
        "median_shape_rmse_mm": r.shape_rmse_mm,
        "median_force_error_N": r.force_error_N,
    }


# ------------------------------------------------------- edges the mutation run found untested (direct)
def test_frame_curvature_edges_points_near_the_contact_duplicates_and_the_known_noise():
    from bayesrod.vision.curvature import fit_curvature_gp, tangent_angles

    fs = _beam_frame(0.3, n=200)
    s = np.array([0.1, 0.3, 0.38])
    base = _frame_curvature(fs, s)
    # points between 1% and 6% below the contact are used (moving them changes the curvature near the top)
    near = (fs.z_m > 0.94 * H) & (fs.z_m < 0.99 * H)
    assert near.sum() >= 5
    moved = _frame_curvature(dataclasses.replace(fs, x_m=fs.x_m + np.where(near, 2e-4, 0.0)), s)
    assert abs(moved[0][1] - base[0][1]) > 1e-4
    # a repeated point (a zero-length segment) is dropped, not turned into a NaN tangent
    k = 40
    dup = dataclasses.replace(
        fs,
        x_m=np.insert(fs.x_m, k, fs.x_m[k]),
        z_m=np.insert(fs.z_m, k, fs.z_m[k]),
        sd_m=np.insert(fs.sd_m, k, fs.sd_m[k]),
    )
    np.testing.assert_allclose(_frame_curvature(dup, s), base, rtol=1e-9)
    # the GP is the one with the points' known noise covariance, evaluated at the query points
    below = fs.z_m < 0.99 * H
    ta = tangent_angles(fs.x_m[below], fs.z_m[below], fs.sd_m[below])
    pr = fit_curvature_gp(ta["s"], ta["theta"], noise_cov=ta["cov"]).predict(s)
    np.testing.assert_allclose(base[0], pr["kappa"], rtol=1e-9)
    np.testing.assert_allclose(base[1], pr["kappa_sd"], rtol=1e-9)
    np.testing.assert_allclose(base[2], np.sqrt(pr["kappa_se2"]), rtol=1e-9)
    # queries exactly at the first and last tangent's arc length are inside
    ends = _frame_curvature(fs, np.array([ta["s"][0], ta["s"][-1]]))
    assert np.isfinite(ends).all()
    # eight points below the contact are enough
    z8 = np.linspace(0.0, 0.3, 8)
    eight = FrameSample("p", H, 0.0, 0.3, 0.01, 0.0, _beam_x(z8, 0.3), z8, np.full(8, 2e-5))
    assert np.isfinite(_frame_curvature(eight, np.array([0.15]))[0]).all()


def test_direct_estimate_edges(monkeypatch):
    from types import SimpleNamespace

    # defaults: 24 bins from 2 cm; bin counts are integers
    frames = [_beam_frame(F, pid=f"p{k}") for k, F in enumerate((0.2, 0.3))]
    de = direct_estimate(None, frames=frames)
    assert de.s_m.size == 24 and de.s_m[0] == pytest.approx(0.02 + 0.5 * (H - 0.02) / 24)
    assert de.n.dtype.kind == "i"
    with pytest.raises(ValueError, match="^s: the direct estimator needs engaged centerline frames"):
        direct_estimate(SimpleNamespace(specimen="s", pushes=()))

    def frame(F, sd=0.0):
        return FrameSample("p", 1.0, 0.0, F, sd, 0.0, np.full(3, 0.01), np.zeros(3), None)

    # a frame at exactly 3 force sd is left out, one at 3.5 sd is pooled; a frame left out first does
    # not stop the frames after it
    kap = {}
    monkeypatch.setattr(
        dmod,
        "_frame_curvature",
        lambda fs, s: (
            np.full(s.size, kap.get(fs.force_N, 0.1 * fs.force_N)),
            *(np.full(s.size, 0.01),) * 2,
            np.zeros(s.size),
        ),
    )
    assert 3 * 0.25 == 0.75  # exactly 3 sd in floating point
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(0.75, 0.25), frame(1.0), frame(2.0)])
    assert de.n[0] == 2
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(0.35, 0.1), frame(1.0), frame(2.0)])
    assert de.n[0] == 3
    # a pooled compliance of exactly 0: no EI (not an infinite one), and no sample EI either
    kap.update({1.0: 0.0, 2.0: 0.0})
    de = direct_estimate(None, n_bins=1, s_min_m=0.0, frames=[frame(1.0), frame(2.0)])
    assert np.isnan(de.EI[0]) and np.isnan(de.samples["EI"]).all()
    # a bin with one frame before bins with two: the later bins are still pooled
    monkeypatch.setattr(
        dmod,
        "_frame_curvature",
        lambda fs, s: (
            np.where(np.arange(s.size) == 0, np.nan if fs.force_N > 1.5 else 0.1, 0.1 * fs.force_N),
            *(np.full(s.size, 0.01),) * 2,
            np.zeros(s.size),
        ),
    )
    de = direct_estimate(None, n_bins=3, s_min_m=0.0, frames=[frame(1.0), frame(2.0)])
    np.testing.assert_array_equal(de.n, [1, 2, 2])
    assert np.isnan(de.EI[0]) and np.isfinite(de.EI[1:]).all()


def test_fit_p_edges_a_bin_at_the_length_and_three_bins_with_scatter():
    L = 0.8
    s = np.array([0.1, 0.3, 0.5, 0.8])  # the last bin at the stem's length: log(1 - s/L) is -inf; skipped
    EIs = 2.0 * (1 - s / L) ** 2.4 * np.array([1.1, 0.9, 1.05, 1.0])
    rel = np.full(4, 0.01)
    p, p_se, _, nb = fit_p(DirectEstimate(s, EIs, EIs * rel, rel, np.full(4, 5), {}), L)
    assert nb == 3 and np.isfinite(p)
    x, y, w = np.log1p(-s[:3] / L), np.log(EIs[:3]), rel[:3] ** -2.0
    coef, cov = np.polyfit(x, y, 1, w=np.sqrt(w), cov="unscaled")
    chi2 = w @ (y - np.polyval(coef, x)) ** 2
    # three bins: one degree of freedom
    assert p_se == pytest.approx(np.sqrt(cov[0, 0] * chi2 / 1) / 4, rel=1e-10)


def test_observed_x_at_extrapolates_with_the_last_four_points_only():
    z = np.array([0.0, 0.1, 0.2, 0.3, 0.35])
    x = np.array([0.5, 0.0, 0.01, 0.02, 0.03])  # the first point far off the line of the last four
    fs = FrameSample("p", 0.4, 0.0, 1.0, 0.1, 0.0, x, z, None)
    assert _observed_x_at(fs, 0.4) == pytest.approx(np.polyval(np.polyfit(z[1:], x[1:], 1), 0.4))


def test_fit_EI0_from_one_frame_at_exactly_three_sd_excluded():
    L, EI0, p = 0.8, 2.5, 0.4
    (one,) = _elastica_frames(EI0, p, L, [3.0], [0.35])
    assert fit_EI0([one], p, L) == pytest.approx(EI0, rel=2e-3)
    at3 = dataclasses.replace(one, force_N=0.03, force_sd_N=0.01, x_m=one.x_m + 0.3)
    assert fit_EI0([one, at3], p, L) == pytest.approx(fit_EI0([one], p, L), rel=1e-9)
    above = dataclasses.replace(one, force_N=0.035, force_sd_N=0.01, x_m=one.x_m + 0.3)  # 3.5 sd: used
    assert abs(fit_EI0([one, above], p, L) / fit_EI0([one], p, L) - 1) > 1e-3


def test_seed_error_metrics_subsample_200_points_and_skip_what_they_cannot_use():
    L, EI0, p = 0.8, 2.5, 0.4
    frames = _elastica_frames(EI0, p, L, [2.0, 4.0], [0.3, 0.4], n=500)
    # a shape error growing as z^3: the RMSE depends on which points are taken, 200 spread evenly
    bent = [dataclasses.replace(f, x_m=f.x_m + 0.05 * f.z_m**3) for f in frames]
    shape_mm, _ = seed_error_metrics(bent, EI0, p, L)
    want = []
    for f in bent:
        sol = force_from_displacement(f.displacement_m, f.height_m, EI0, p, L, keep_shape=True)
        xz = sol.shape_xz_m
        idx = np.flatnonzero(f.z_m < f.height_m)
        idx = idx[np.linspace(0, idx.size - 1, 200).astype(int)]
        zeta = np.maximum.accumulate(xz[:, 1])
        slope = np.interp(f.z_m[idx], zeta, np.gradient(xz[:, 0], zeta))
        r = (f.x_m[idx] - np.interp(f.z_m[idx], zeta, xz[:, 0])) / np.sqrt(1 + slope**2)
        want.append(1000 * np.sqrt(np.mean(r**2)))
    assert shape_mm == pytest.approx(np.median(want), rel=1e-9)
    # a slipped frame or one with fewer than two points below the contact first: the others still count
    slipped = dataclasses.replace(frames[0], displacement_m=5 * L)
    two = dataclasses.replace(frames[0], z_m=np.r_[0.1, 0.2, 0.5], x_m=np.r_[0.0, 0.0, 0.0])
    one = dataclasses.replace(frames[0], z_m=np.r_[0.1, 0.5], x_m=np.r_[0.0, 0.0])
    assert np.isfinite(seed_error_metrics([slipped, *bent], EI0, p, L)).all()
    assert seed_error_metrics([one, *bent], EI0, p, L)[0] == pytest.approx(shape_mm, rel=1e-9)
    rmse_two = seed_error_metrics([two], EI0, p, L)[0]
    assert np.isfinite(rmse_two) and rmse_two > 0


def test_two_stage_fit_passes_its_settings_and_clips_p_to_the_tables(monkeypatch):
    from types import SimpleNamespace

    seen = {}
    frames = [_beam_frame(0.3)]
    monkeypatch.setattr(dmod, "engaged_frames", lambda spec: frames)

    def fake_direct(spec, *, n_bins, s_min_m, frames):
        seen["direct"] = (spec, n_bins, s_min_m, frames)
        return "estimate"

    monkeypatch.setattr(dmod, "direct_estimate", fake_direct)
    monkeypatch.setattr(dmod, "fit_EI0", lambda fr, p, L: seen.setdefault("EI0", []).append((fr, p, L)) or 2.0)

    def fake_metrics(fr, EI0, p, L):
        seen["metrics"] = (fr, EI0, p, L)
        return 0.1, 0.2

    monkeypatch.setattr(dmod, "seed_error_metrics", fake_metrics)
    spec = SimpleNamespace(specimen="s", length_m=0.8)
    for p_raw, p_used in ((-0.4, 0.0), (3.6, 3.0), (0.7, 0.7)):
        seen.pop("metrics", None)
        monkeypatch.setattr(dmod, "fit_p", lambda de, L, p_raw=p_raw: (p_raw, 0.1, 0.9, 5))
        r = dmod.two_stage_fit(spec)
        assert seen["direct"] == (spec, 24, 0.02, frames)
        assert seen["EI0"][-1] == (frames, p_used, 0.8)
        assert seen["metrics"] == (frames, 2.0, p_used, 0.8)
        assert r.p == p_raw and r.EI0 == 2.0 and r.direct == "estimate"
        assert (r.shape_rmse_mm, r.force_error_N, r.p_se, r.r2, r.n_bins) == (0.1, 0.2, 0.1, 0.9, 5)

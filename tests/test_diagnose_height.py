"""Contact-height errors in the diagnosis (issue 19): each push's height is known to a few mm; every model
fits one error per push under its normal prior, and a held-out push is predicted at its recorded height.

Data are made from the physics (``force_from_displacement``) at the true heights while the diagnosis is
told the recorded ones, so the truth is set independently of the diagnosis' spline.
"""

import dataclasses

import numpy as np
import pytest

import bayesrod
from bayesrod.inference.diagnose import Diagnoser, ForwardModel
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects, force_from_displacement

EI0, P, L = 2.63, 0.43, 0.80
HEIGHTS = (0.30, 0.45, 0.60)
DH = (0.006, -0.005, 0.004)  # true minus recorded height [m]
DELTAS = (0.010, 0.0, 0.020)  # preloads [m]
SD = 0.003


def _pushes(sigma=0.004, seed=0, n=40, dh=DH, deltas=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(seed)
    D, F = [], []
    for h, e, delta in zip(HEIGHTS, dh, deltas, strict=True):
        d = np.linspace(0.0, 0.15 * h / 0.4, n)
        F.append(force_from_displacement(d + delta, h + e, EI0, P, L).force_N + rng.normal(0, sigma, n))
        D.append(d)
    return bayesrod.Dataset.from_arrays(length_m=L, height_m=list(HEIGHTS), displacement_m=D, force_N=F)


def _model(ds, **kw):
    return ForwardModel(prepare_data(ds, use_shapes=False), L, **kw)


def test_each_parameter_set_is_solved_at_its_own_contact_heights():
    """Rows (log EI0, p, preloads, L, height errors, c): each row's forces are the physics at h + dh."""
    m = _model(_pushes(sigma=0.0), preload=True, length_bounds_m=(0.7, 1.2), height_sd_m=SD)
    assert (m.n_preloads, m.length_index, m.height_index, m.n_heights, m.n_base) == (3, 5, 6, 3, 9)
    assert m.push_columns(1) == [3, 7]
    c = 0.05
    rows = [(0.8, DH), (0.9, (-0.004, 0.002, 0.0))]
    X = np.array([[np.log(EI0), P, *DELTAS, Lr, *dh, c] for Lr, dh in rows])
    F = m.forces(X, ("base_compliance",))
    np.testing.assert_allclose(m.heights(X), np.array(HEIGHTS)[None] + np.array([r[1] for r in rows]))
    for row, (Lr, dh) in enumerate(rows):
        eff = Effects(base_compliance=EI0 / (c * Lr))
        for k, d in enumerate(m.data):
            ref = force_from_displacement(d.D_m + DELTAS[k], d.height_m + dh[k], EI0, P, Lr, eff).force_N
            np.testing.assert_allclose(F[row, m.force_push == k], ref, rtol=0, atol=1e-5 * ref.max())
    # without the nuisance the heights are the recorded ones and the vector has no such coordinates
    m0 = _model(_pushes(sigma=0.0))
    assert m0.n_heights == 0 and m0.n_base == 2 and m0.push_columns(0) == []
    np.testing.assert_array_equal(m0.heights(np.zeros((2, 2))), [HEIGHTS, HEIGHTS])


def test_a_height_error_moves_the_frames_of_its_push_as_it_moves_its_forces():
    ds = bayesrod.simulate("twig", seed=2, config_overrides={"n_frames_engaged": 2, "heights_m": [0.3, 0.5]})
    data = prepare_data(ds, use_shapes=True)
    Ls = ds.length_m
    m = ForwardModel(data, Ls, height_sd_m=SD)
    dh = np.array([0.004, -0.003])
    x = np.concatenate([[np.log(EI0), P], dh])
    moved = ForwardModel([dataclasses.replace(d, height_m=d.height_m + e) for d, e in zip(data, dh, strict=True)], Ls)
    xs, cs = m.shapes(x, ())
    xs0, cs0 = moved.shapes(x[:2], ())
    np.testing.assert_allclose(xs, xs0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cs, cs0, rtol=0, atol=1e-12)
    assert not np.allclose(xs, m.shapes(np.concatenate([x[:2], [0.0, 0.0]]), ())[0], atol=1e-5)


def test_height_sd_is_checked():
    data = prepare_data(_pushes(sigma=0.0), use_shapes=False)
    for bad in (-0.001, float("nan"), True, "3 mm"):
        with pytest.raises(ValueError, match="height_sd_m: expected a contact-height sd >= 0 in metres"):
            ForwardModel(data, L, height_sd_m=bad)
    with pytest.raises(ValueError, match="height_sd_m: expected 4 sd below the lowest contact"):
        ForwardModel(data, L, height_sd_m=0.3 / 4)
    with pytest.raises(ValueError, match="height_sd_m"):
        bayesrod.diagnose(_pushes(sigma=0.0), height_sd_m=-1.0)


def test_the_fit_penalises_the_errors_by_their_prior_and_bounds_them_at_4_sd():
    ds = _pushes()
    dg = Diagnoser(_model(ds, preload=True, height_sd_m=SD), force_noise="iid")
    lo, hi = dg.bounds(("force_offset",))
    np.testing.assert_array_equal(lo[5:8], [-4 * SD] * 3)
    np.testing.assert_array_equal(hi[5:8], [4 * SD] * 3)
    fit = dg.fit_plain()
    assert fit.n_heights == 3 and fit.height_errors_m.shape == (3,) and fit.preloads_m.shape == (3,)
    # the reported log likelihood is the data's plus the errors' log prior (up to its constant)
    data_ll = dg.loglik(fit.r_force, fit.r_shape, (fit.sigma_force, fit.rho_force, fit.shape_scale))
    assert fit.loglik == pytest.approx(data_ll - 0.5 * np.sum((fit.height_errors_m / SD) ** 2), rel=1e-12)
    assert fit.natural(L)["height_error_m"] == pytest.approx(list(fit.height_errors_m))
    # the penalised optimum: where the data's pull on each error balances its prior's, jw' r_w = dh / sd^2
    # (measured within 8%: the last round's noise is re-profiled after its fit; unpenalised, or weighed
    # by the start's noise, the pull is 28 times the prior's)
    rw = dg.weighted(fit.r_force, fit.r_shape, (fit.sigma_force, fit.rho_force, fit.shape_scale))
    pull = (fit.jac.T @ rw)[dg.m.height_index : dg.m.height_index + 3]
    np.testing.assert_allclose(pull, fit.height_errors_m / SD**2, rtol=0.15)
    # with the errors free, the misrecorded heights fit at the noise level (without, they cannot)
    assert np.sqrt(np.mean(fit.r_force**2)) < 1.5 * 0.004
    dg0 = Diagnoser(_model(ds, preload=True), force_noise="iid")
    fit0 = dg0.fit_plain()
    assert np.sqrt(np.mean(fit0.r_force**2)) > 3 * np.sqrt(np.mean(fit.r_force**2))
    # and the fitted errors move the heights the way the truth does (EI0 and p take up a common part)
    assert np.corrcoef(fit.height_errors_m, DH)[0, 1] > 0.9


def test_a_held_out_push_is_predicted_at_its_recorded_height_with_its_own_preload():
    ds = _pushes(dh=(0.0, 0.0, 0.0), deltas=DELTAS)
    dg = Diagnoser(_model(ds, preload=True, height_sd_m=SD), force_noise="iid")
    fit = dg.fit_plain()
    out, errs = dg.heldout(fit)
    assert [u["push"] for u in out["per_push"]] == [d.id for d in dg.m.data]
    assert len(errs) == 3
    for u in out["per_push"]:
        assert len(u["refit"]["height_error_m"]) == 2  # the training pushes' own
    # heights recorded exactly: each held-out push predicted at the noise level (its preload fitted)
    assert out["heldout_force_rmse_N"] < 3 * 0.004
    # the training vector of a unit drops the held-out push's preload and height error, nothing else
    x = np.arange(dg.m.n_base, dtype=float)
    np.testing.assert_array_equal(dg._without_push(x, 1), [0, 1, 2, 4, 5, 7])

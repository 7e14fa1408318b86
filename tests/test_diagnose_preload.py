"""Preloads in the diagnosis (issue 19): each push's unknown start is a fitted nuisance, held-out pushes
fit their own, and a preloaded field push is explained without structure left over.

Data are made from the physics (``force_from_displacement``) at displacements that start ``delta`` into
the push, so the truth is set independently of the diagnosis' spline and tables.
"""

import numpy as np
import pytest

import bayesrod
from bayesrod.inference.diagnose import Diagnoser, ForwardModel
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import force_from_displacement

EI0, P, L = 2.63, 0.43, 0.80
HEIGHTS = (0.40, 0.50, 0.60)
DELTAS = (0.012, 0.0, 0.025)  # preload [m] of each push: recording began this far into it


def _preloaded(sigma=0.004, seed=0, n=60):
    rng = np.random.default_rng(seed)
    D, F = [], []
    for h, delta in zip(HEIGHTS, DELTAS, strict=True):
        d = np.linspace(0.0, 0.15 * h / 0.4, n)  # displacement since recording began
        F.append(force_from_displacement(d + delta, h, EI0, P, L).force_N + rng.normal(0, sigma, n))
        D.append(d)
    return bayesrod.Dataset.from_arrays(length_m=L, height_m=list(HEIGHTS), displacement_m=D, force_N=F)


def _model(ds, preload=True):
    return ForwardModel(prepare_data(ds, use_shapes=False), L, preload=preload)


def test_preloaded_forces_are_the_physics_at_the_shifted_displacement():
    m = _model(_preloaded(sigma=0.0))
    x = np.concatenate([[np.log(EI0), P], DELTAS])
    F = m.forces(x[None], ())[0]
    for k, d in enumerate(m.data):
        ref = force_from_displacement(d.D_m + DELTAS[k], d.height_m, EI0, P, L).force_N
        np.testing.assert_allclose(F[m.force_push == k], ref, rtol=0, atol=1e-5 * ref.max())


def test_preloads_are_recovered_and_the_held_out_push_fits_its_own():
    ds = _preloaded()
    dg = Diagnoser(_model(ds), force_noise="iid")
    fit = dg.fit_plain()
    np.testing.assert_allclose(fit.preloads_m, DELTAS, atol=1.5e-3)
    assert np.exp(fit.x[0]) == pytest.approx(EI0, rel=0.05)
    assert fit.natural(L)["preload_m"] == pytest.approx(list(fit.preloads_m))
    out, errs = dg.heldout(fit)
    # each held-out push is predicted at the noise level once its own preload is fitted ...
    assert out["heldout_force_rmse_N"] < 3 * 0.004
    # ... which a model without preloads cannot do (the pushes start at different forces)
    dg0 = Diagnoser(_model(ds, preload=False), force_noise="iid")
    out0, _ = dg0.heldout(dg0.fit_plain())
    assert out0["heldout_force_rmse_N"] > 5 * out["heldout_force_rmse_N"]


def test_a_preloaded_push_whose_contact_starts_behind_the_origin_is_fitted_at_every_sample():
    """Behind a wire sensor a push recorded from a preload starts at a negative contact displacement (robot
    advance minus the wire's take-up): those samples are in contact, so the spline's nodes must reach them
    (they were read at d = 0, 6x the noise in force rmse on a simulated wire push)."""
    from bayesrod.inference.diagnose import _spline_matrix

    D = np.linspace(-0.01, 0.05, 60)
    nodes, S = _spline_matrix(D, 32, preloaded=True)
    assert nodes[0] == pytest.approx(-0.01) and nodes[-1] == pytest.approx(0.05)
    np.testing.assert_allclose(S @ np.sin(40 * nodes), np.sin(40 * D), atol=2e-4)  # reads every sample
    assert _spline_matrix(D, 32)[0][0] == 0.0  # not preloaded: nothing before first contact but zeros
    rng = np.random.default_rng(3)
    Ds, Fs = [], []
    for h, delta in zip(HEIGHTS, (0.02, 0.015, 0.025), strict=True):
        d = np.linspace(-0.012, 0.15 * h / 0.4, 60)
        Fs.append(force_from_displacement(d + delta, h, EI0, P, L).force_N + rng.normal(0, 0.004, d.size))
        Ds.append(d)
    data = prepare_data(
        bayesrod.Dataset.from_arrays(length_m=L, height_m=list(HEIGHTS), displacement_m=Ds, force_N=Fs),
        use_shapes=False,
    )
    assert all(d.D_m[0] < 0 for d in data)
    dg = Diagnoser(ForwardModel(data, L, preload=True), force_noise="iid")
    # the preloads start where the table forces reach each push's first sample, counted from its first
    # displacement (not from zero: 12 mm off here)
    np.testing.assert_allclose(dg.start()[2:5], (0.02, 0.015, 0.025), atol=4e-3)
    fit = dg.fit_plain()
    np.testing.assert_allclose(fit.preloads_m, (0.02, 0.015, 0.025), atol=1.5e-3)
    assert np.sqrt(np.mean(fit.r_force**2)) < 1.5 * 0.004


def test_a_preload_shifts_the_frames_of_its_push_as_it_shifts_its_forces():
    """With centerlines, each push's preload moves its frames' contact displacements: the preloaded model's
    shapes are the plain model's on frames taken that much further into each push, push by push."""
    from dataclasses import replace

    ds = bayesrod.simulate("twig", seed=1, config_overrides={"n_frames_engaged": 2})
    data = prepare_data(ds, use_shapes=True)
    m = ForwardModel(data, ds.length_m, preload=True)
    deltas = np.array([0.004, 0.0, 0.009])
    x = np.concatenate([[np.log(EI0), P], deltas])
    shifted = [replace(d, frame_D_m=d.frame_D_m + deltas[k]) for k, d in enumerate(data)]
    ref = ForwardModel(shifted, ds.length_m).shapes(x[[0, 1]], ())
    got = m.shapes(x, ())
    np.testing.assert_allclose(got[0], ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[1], ref[1], rtol=0, atol=1e-12)
    unshifted = ForwardModel(data, ds.length_m).shapes(x[[0, 1]], ())
    for k in (0, 2):  # the preloaded pushes' centerlines moved; the one without a preload did not
        sel = m.point_push == k
        assert np.nanmax(np.abs(got[0][sel] - unshifted[0][sel])) > 1e-3
    np.testing.assert_array_equal(got[0][m.point_push == 1], unshifted[0][m.point_push == 1])
    with pytest.raises(ValueError, match="preload"):
        bayesrod.diagnose(ds, preload="yes")


def test_field_push_with_a_preload_and_a_yielding_base_is_explained(tmp_path):
    """examples/rigs/field_push.csv: recording starts 8 mm into the push, the base yields at 1.1 N m."""
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "examples" / "rigs" / "field_push.csv"
    bayesrod.import_table(
        [src],
        time="t_s",
        force="force_N",
        displacement="travel_mm",
        displacement_unit="mm",
        height_m=0.45,
        length_m=0.9,
        specimen="field",
    ).save(tmp_path / "fp")
    r = bayesrod.diagnose(
        tmp_path / "fp" / "field", use_shapes=False, candidates=("yield", "force_offset"), n_workers=2
    ).to_dict()
    assert r["settings"]["preload"] and r["settings"]["pushes_starting_loaded"] == ["h450"]
    assert r["added_effects"] == ["yield"]
    assert r["fitted"]["yield"] == pytest.approx(1.1, rel=0.05)
    assert r["fitted"]["preload_m"][0] == pytest.approx(0.008, abs=0.0015)
    assert not r["unexplained_structure"]
    assert r["after"]["heldout_force_rmse_N"] < 0.5 * r["before"]["heldout_force_rmse_N"]

"""Correlated centerline errors: the measured n_eff / n that weights the shape likelihood."""

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.dataset import read_dataset
from bayesrod.inference.likelihood import RodLikelihood, effective_shape_weight


@pytest.fixture(scope="module")
def clean_lik(twig_clean):
    return RodLikelihood(read_dataset(twig_clean))


def _truth(lik):
    t = lik.spec.extra["truth"]
    return {"EI0": t["EI0"], "p": t["p"], "sigma_force_N": 0.03, "shape_sd_scale": 1.0, "sigma_shape_m": 1e-3}


def _with_noise(lik, noise):
    """The likelihood with ``noise`` [m] added to its observed points along the normal (the data are
    noise-free): the table of normal offsets it reads moves by the noise."""
    n0 = lik.normal_table
    lik.normal_table = n0 + noise[None, None, :]
    try:
        params = {k: v for k, v in _truth(lik).items() if k in lik.names}
        return effective_shape_weight(lik, params)
    finally:
        lik.normal_table = n0


def _ar1(lik, rho, rng, shared=None):
    """AR(1) noise along each frame's points (coefficient rho per point), plus an optional per-push pattern."""
    e = np.empty(lik.n_points)
    key = lik.point_push * 100000 + lik.point_frame
    for k in np.unique(key):
        idx = np.flatnonzero(key == k)
        w = rng.normal(size=idx.size)
        for i in range(1, idx.size):
            w[i] = rho * w[i - 1] + np.sqrt(1 - rho**2) * w[i]
        e[idx] = w
    if shared is not None:
        e = e + shared(lik.z_obs, lik.point_push)
    return 1e-3 * e


def test_independent_points_keep_full_weight(clean_lik):
    rng = np.random.default_rng(0)
    info = _with_noise(clean_lik, 1e-3 * rng.normal(size=clean_lik.n_points))
    assert info["weight"] > 0.8, info


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_along_stem_correlation_measured(clean_lik, rho):
    info = _with_noise(clean_lik, _ar1(clean_lik, rho, np.random.default_rng(1)))
    expected = (1 + rho) / (1 - rho)  # integrated autocorrelation time of an AR(1)
    assert info["tau_along"] == pytest.approx(expected, rel=0.3), info
    assert info["tau_frames"] < 1.5, info  # frames independent
    assert info["weight"] == pytest.approx(1 / (info["tau_along"] * info["tau_frames"]))


def test_error_shared_by_frames_lowers_the_weight(clean_lik):
    # the same smooth error pattern in every frame of a push (a plane-depth or spline artefact)
    def shared(z, push):
        return 1.5 * np.sin(2 * np.pi * z / 0.3 + push)

    info = _with_noise(clean_lik, _ar1(clean_lik, 0.5, np.random.default_rng(2), shared))
    assert info["tau_frames"] > 3, info
    assert info["weight"] < 0.1, info


def test_shape_weight_flag_rejects_bad_values(twig_noisy, tmp_path, capsys):
    assert main(["fit", str(twig_noisy), "--out", str(tmp_path / "r"), "--shape-weight", "2"]) == 2
    err = capsys.readouterr().err
    assert "--shape-weight" in err and "(0, 1]" in err and "'2'" in err
    assert not (tmp_path / "r").exists()

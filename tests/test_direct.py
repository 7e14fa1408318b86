"""Direct estimator (eq. direct_estimator) and the seed's two-stage fit (eqs. p_fit, EI0_fit)."""

import numpy as np
import pytest

from bayesrod.dataset import read_dataset
from bayesrod.inference.direct import DirectEstimate, direct_estimate, fit_p, two_stage_fit


def test_direct_bins_exact_on_noise_free_twig(twig_clean):
    spec = read_dataset(twig_clean)
    de = direct_estimate(spec)
    truth = 2.63 * (1 - de.s_m / 0.8) ** (4 * 0.43)
    ok = np.isfinite(de.EI)
    assert ok.sum() >= 20 and de.s_m.min() >= 0.02
    np.testing.assert_allclose(de.EI[ok], truth[ok], rtol=5e-3)


def test_two_stage_noise_free_recovers_taper(twig_clean):
    r = two_stage_fit(read_dataset(twig_clean))
    assert r.p == pytest.approx(0.43, abs=2e-3)
    assert r.EI0 == pytest.approx(2.63, rel=5e-3)
    assert r.r2 > 0.999
    assert r.shape_rmse_mm < 0.2 and r.force_error_N < 5e-3


def test_two_stage_noisy_twig(twig_noisy):
    r = two_stage_fit(read_dataset(twig_noisy))
    assert r.p == pytest.approx(0.43, abs=0.05)
    assert r.EI0 == pytest.approx(2.63, rel=0.08)
    # the seed's metrics at its own fit: of the order of the noise (1.5 mm, 0.03 N)
    assert 0.5 < r.shape_rmse_mm < 4 and r.force_error_N < 0.2


def test_fit_p_recovers_slope_with_noisy_base_bins_and_needs_three_bins():
    rng = np.random.default_rng(0)
    s = np.linspace(0.03, 0.6, 20)
    rel = np.where(s < 0.2, 0.5, 0.02)  # noisy bins near the base
    EI = 2.0 * (1 - s / 0.8) ** (4 * 0.7) * np.exp(rng.normal(0, rel))
    de = DirectEstimate(s, EI, EI * rel, rel, np.full(s.size, 10), {})
    p, p_se, r2, nb = fit_p(de, 0.8)
    assert nb == 20 and abs(p - 0.7) < 3 * p_se and p_se < 0.03
    with pytest.raises(ValueError, match="at least 3 bins"):
        fit_p(DirectEstimate(s[:2], EI[:2], EI[:2], rel[:2], np.full(2, 10), {}), 0.8)


def test_direct_estimator_needs_shapes(twig_clean):
    import dataclasses

    spec = read_dataset(twig_clean)

    bare = dataclasses.replace(spec, pushes=tuple(dataclasses.replace(p, shapes=None) for p in spec.pushes))
    with pytest.raises(ValueError, match="shapes"):
        direct_estimate(bare)

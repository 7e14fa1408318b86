"""Where a push's engagement ends (bayesrod.dataset.engagement), on force series made by hand."""

import numpy as np
import pytest

from bayesrod.dataset.engagement import detect_engagement


def _push(rng, end_N, n_eng=58, n_after=8, peak_N=0.47, sd_N=0.1):
    """Rises to ``peak_N``, falls to ``end_N`` at the slip (sample ``n_eng``), then the unloaded sensor."""
    x = np.linspace(0.0, 1.0, n_eng)
    true = np.where(x < 0.6, peak_N * np.sin(x / 0.6 * np.pi / 2), peak_N - (peak_N - end_N) * (x - 0.6) / 0.4)
    return np.r_[true, np.zeros(n_after)] + rng.normal(0.0, sd_N, n_eng + n_after)


def test_a_clear_push_ends_at_its_slip():
    for seed in range(20):
        eng = detect_engagement(_push(np.random.default_rng(seed), end_N=0.47, peak_N=0.47, sd_N=0.02))
        assert eng.slip_index == 58 and eng.mask.sum() == 58


@pytest.mark.parametrize(("end_N", "rate"), [(0.1, 0.7), (0.2, 0.9), (0.3, 0.98)])
def test_a_noisy_push_whose_force_falls_before_the_slip_ends_near_its_slip(end_N, rate):
    """Signal-to-noise 5, the force falling to 1-3 sigma before the slip (SBC seeds 272 and 334): the threshold
    rule alone put the slip within 3 samples in 0.5-2.5% of 200 pushes; the change point from there (a
    falling line, then at least four samples of the unloaded sensor) in 77%, 94.5% and 99.5% (measured; the
    bounds leave a margin). Two unloaded samples were allowed before: chance lows among them drew the slip
    6 samples late."""
    ends = np.array([detect_engagement(_push(np.random.default_rng(s), end_N=end_N)).slip_index for s in range(200)])
    assert np.mean(np.abs(ends - 58) <= 3) >= rate
    assert np.all(ends <= 62)  # never far past the slip: the unloaded samples are not taken for loaded ones


def test_noise_after_a_slip_is_not_taken_for_a_loaded_stretch():
    """The unloaded sensor's noise (white, or slowly wandering) after a clear slip does not move the slip later."""
    rng = np.random.default_rng(7)
    for seed in range(200):
        rng = np.random.default_rng(seed)
        F = _push(rng, end_N=0.3, peak_N=0.47, sd_N=0.02, n_after=40)
        F[58:] += 0.02 * np.sin(np.arange(40) / 6.0)  # a slow ring of the sensor after the slip
        assert detect_engagement(F).slip_index == 58


#: scripts/sbc_geometry.py --effects yield, seed 61, the push at 0.70 m: 27 engaged samples (the last, 0.155 N,
#: on the falling branch), then the unloaded sensor (the simulator's own mask)
SEED61_TOP_PUSH_N = [
    0.0624, 0.0233, 0.0237, 0.0566, 0.0882, 0.0802, 0.1038, 0.1573, 0.124, 0.1224, 0.2465, 0.2118,
    0.1542, 0.1755, 0.3085, 0.205, 0.1945, 0.259, 0.1945, 0.2144, 0.2352, 0.2031, 0.2307, 0.2189,
    0.2637, 0.2703, 0.1546, 0.0241, -0.0141, -0.0021, -0.0287, 0.0185, -0.0533, -0.0496, 0.0253,
]  # fmt: skip


def test_a_line_that_falls_through_the_unloaded_level_is_not_a_loaded_stretch():
    """After a fall to 0.155 N the next two samples read 0.024 and -0.014 N: the unloaded sensor. A line through
    0.155, 0.024, -0.014 passed the change point's gaps, join and BIC and took both as loaded (slip 29, two
    unloaded samples fitted at ~5 sigma each: the noise sd read 36% high in the SBC). A stem in contact pushes
    the sensor one way, so the loaded line must end above the unloaded level: the slip stays at sample 26 (one
    engaged sample lost, none unloaded kept)."""
    from bayesrod.dataset.engagement import _slip_change_point, _slip_change_point_reference

    eng = detect_engagement(SEED61_TOP_PUSH_N)
    assert eng.slip_index == 26
    F, sigma = np.asarray(SEED61_TOP_PUSH_N), eng.noise_N
    assert _slip_change_point(F, 26, sigma) == _slip_change_point_reference(F, 26, sigma) == 26
    # noise-free: a stretch falling from 5 sigma to -0.4 sigma (its line ends at -0.3) passes the gaps, the join
    # and the BIC but ends below the unloaded level; the same stretch ending at 2.2 sigma is loaded
    sigma, base = 0.5, 1.0
    F = base + sigma * np.r_[np.full(3, 5.5), [5.0, 2.6, -0.4], np.zeros(6)]
    assert _slip_change_point(F, 3, sigma) == _slip_change_point_reference(F, 3, sigma) == 3
    F = base + sigma * np.r_[np.full(3, 3.2), [3.0, 2.6, 2.2], np.zeros(6)]
    assert _slip_change_point(F, 3, sigma) == _slip_change_point_reference(F, 3, sigma) == 6


def test_robust_noise_reads_the_sd_of_white_noise_through_a_trend_and_needs_two_second_differences():
    from bayesrod.dataset.engagement import robust_noise

    rng = np.random.default_rng(3)
    x = np.arange(20000.0)
    F = 0.07 * rng.standard_normal(x.size) + 1e-4 * x + 0.05 * x**2  # a trend whose second difference is 0.1
    assert robust_noise(F) == pytest.approx(0.07, rel=0.02)
    # by hand: second differences (-2, 2), their median 0, MAD 2: 1.4826 * 2 / sqrt(6)
    assert robust_noise([0.0, 1.0, 0.0, 1.0]) == pytest.approx(1.4826 * 2 / np.sqrt(6.0), rel=1e-12)
    assert robust_noise([1.0, 2.0, 4.0]) == 0.0  # one second difference: no spread to read


def test_an_empty_or_one_sample_push():
    eng = detect_engagement([])
    assert eng.mask.dtype == bool and eng.mask.size == 0
    assert (eng.baseline_N, eng.noise_N, eng.slip_index) == (0.0, 0.0, None)
    one = detect_engagement([0.3])
    assert one.mask.tolist() == [True] and one.slip_index is None and one.baseline_N == 0.3


def test_a_push_that_never_slips_keeps_every_sample_and_the_first_three_set_its_baseline():
    eng = detect_engagement([0.0, 0.2, 0.1, 1.0, 2.0, 3.0, 4.0])
    assert eng.slip_index is None and eng.mask.all() and eng.baseline_N == 0.1


@pytest.mark.parametrize("case", ["noisy", "ring"])
def test_an_unzeroed_sensor_moves_the_baseline_and_nothing_else(case):
    """An offset of 3 N on every sample (a load cell not tared): the same slip, mask and noise; the baseline
    (the post-slip median) moves by the offset."""
    for seed in range(10):
        rng = np.random.default_rng(seed)
        if case == "noisy":
            F = _push(rng, end_N=0.2)
        else:
            F = _push(rng, end_N=0.3, sd_N=0.03, n_after=40)
            F[58:] += 0.02 * np.sin(np.arange(40) / 6.0)
        a, b = detect_engagement(F), detect_engagement(F + 3.0)
        assert a.slip_index == b.slip_index and (a.mask == b.mask).all()
        assert b.noise_N == pytest.approx(a.noise_N, rel=1e-9) and a.noise_N > 0
        assert b.baseline_N == pytest.approx(a.baseline_N + 3.0, abs=1e-9)
        assert a.baseline_N == pytest.approx(np.median(F[a.slip_index :]), abs=1e-12)


def test_an_untared_sensor_and_a_short_fall_after_the_peak_where_the_change_point_cannot_help():
    """Noise-free (sigma 0: no change point), a 10 N offset, the peak 5 N above it, two loaded samples after
    the peak, then the slip: the threshold is a quarter of the rise above the first samples, wherever the
    sensor's zero sits; the same push tared gives the same slip."""
    rise = np.array([0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 4.9, 4.8, 0.0, 0.0, 0.0, 0.0, 0.0])
    for offset in (0.0, 10.0):
        eng = detect_engagement(offset + rise)
        assert eng.noise_N == 0.0 and eng.slip_index == 10 and eng.baseline_N == offset


def test_a_dip_mid_push_is_not_a_slip():
    """Three samples near zero mid-push (the probe lost the stem for an instant), then the force comes back:
    the slip is the real one at the end, where the force stays at the baseline."""
    rng = np.random.default_rng(0)
    F = _push(rng, end_N=0.47, peak_N=0.47, sd_N=0.02, n_after=20)
    F[40:43] = 0.0
    assert detect_engagement(F).slip_index == 58


@pytest.mark.parametrize(("level", "moved"), [(1.9, False), (2.2, True)])
def test_the_change_point_needs_its_bic_where_the_gaps_alone_would_pass(level, moved):
    """Three loaded samples at ``level`` sigma, then 57 at the sensor's zero, noise-free, sigma 0.5 given.
    The split removes level^2 sigma^2 * 3 * 57 / 60 of the squared error; its BIC asks 3 sigma^2 log 60.
    At 1.9 sigma the gaps (1.5 sigma; 3 se = 1.78 sigma) and the join pass and the BIC does not: the slip
    stays where the threshold rule put it. At 2.2 sigma all pass and the slip moves past the three."""
    from bayesrod.dataset.engagement import _slip_change_point

    sigma = 0.5
    a = level * sigma
    F = np.r_[np.full(3, a), np.full(3, a), np.zeros(57)]  # three before the first low, then the window
    reduction, bic = a**2 * 3 * 57 / 60, 3 * sigma**2 * np.log(60)
    assert (reduction > bic) == moved  # the case sits on the side of the BIC it is meant to
    assert a > 3 * sigma * np.sqrt(1 / 3 + 1 / 57) and a > 1.5 * sigma  # the gaps pass in both cases
    assert _slip_change_point(F, 3, sigma) == (6 if moved else 3)


@pytest.mark.parametrize(
    ("n_loaded", "n_unloaded", "level", "pre", "moved"),
    [
        # 30 and 30: 3 se is 0.77 sigma and the BIC passes; the 1.5-sigma gap decides
        (30, 30, 1.4, 1.4, False),
        (30, 30, 1.6, 1.6, True),
        # 3 and 4: 1.5 sigma and the BIC (5.8 sigma^2 against 1.71 level^2 sigma^2) pass; 3 se, 2.29 sigma, decides
        (3, 4, 2.1, 2.1, False),
        (3, 4, 2.4, 2.4, True),
        # the join: the line starts at 2.4 sigma; the force just before the first low was 3 or 8 sigma
        (3, 4, 2.4, 3.0, True),
        (3, 4, 2.4, 8.0, False),
    ],
)
def test_the_change_point_gaps_and_join_each_decide_somewhere(n_loaded, n_unloaded, level, pre, moved):
    """Noise-free stretches on an untared sensor (baseline 1 N), sigma 0.5 N given: each condition of the
    change point is the one that decides in one pair of cases."""
    from bayesrod.dataset.engagement import _slip_change_point

    sigma, base = 0.5, 1.0
    F = base + np.r_[np.full(3, pre * sigma), np.full(n_loaded, level * sigma), np.zeros(n_unloaded)]
    assert _slip_change_point(F, 3, sigma) == (3 + n_loaded if moved else 3)


def test_without_a_noise_estimate_the_change_point_is_not_tried():
    """sigma 0 (a sensor quantised so coarsely that the second differences' MAD is 0): no scale for the gaps
    or the BIC, so the slip stays where the threshold rule put it, even where a split would fit better."""
    from bayesrod.dataset.engagement import _slip_change_point

    F = np.r_[np.full(3, 1.2), np.full(10, 1.0), np.zeros(10)]
    assert _slip_change_point(F, 3, 0.0) == 3
    assert _slip_change_point(F, 3, 0.1) == 13  # with a noise scale the stretch at 1.0 is loaded


def test_the_fast_change_point_is_the_reference_loop_on_random_pushes():
    """The cumulative-sum change point against one least-squares line per split, on 800 random windows:
    a falling loaded stretch (0-30 samples, 0-5 sigma) then the unloaded sensor (0-40 samples), three samples
    before the first low, white noise, offsets up to 1e3 N (an untared sensor). The splits' sums of squares
    differ by rounding only, so the two pick the same sample; both outcomes occur (about three quarters move
    the slip)."""
    from bayesrod.dataset.engagement import _slip_change_point, _slip_change_point_reference

    rng = np.random.default_rng(7)
    moved = 0
    for _ in range(800):
        sigma = rng.uniform(0.01, 1.0)
        n_loaded, n_unloaded = rng.integers(0, 31), rng.integers(0, 41)
        start, end = rng.uniform(0.0, 5.0, 2) * sigma
        loaded = np.linspace(max(start, end), min(start, end), n_loaded)
        pre = rng.uniform(0.0, 8.0, 3) * sigma
        F = rng.choice([0.0, 1.0, 1e3]) + np.r_[pre, loaded, np.zeros(n_unloaded)]
        F = F + rng.normal(0.0, sigma, F.size) * rng.choice([0.0, 1.0], p=[0.1, 0.9])
        sigma *= rng.choice([0.0, 1.0], p=[0.05, 0.95])  # now and then no noise estimate: no change point
        got = _slip_change_point(F, 3, sigma)
        assert got == _slip_change_point_reference(F, 3, sigma), (n_loaded, n_unloaded, sigma)
        moved += got > 3
    assert 300 < moved < 750


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 60])
def test_the_running_median_is_the_median_of_each_sample_and_its_neighbours(n):
    """Against its definition, window by window, cut at the ends (where two samples' median is their mean)."""
    from bayesrod.dataset.engagement import _running_median3

    F = np.random.default_rng(n).normal(size=n)
    want = [np.median(F[max(0, i - 1) : i + 2]) for i in range(n)]
    np.testing.assert_allclose(_running_median3(F), want, rtol=1e-15, atol=0)

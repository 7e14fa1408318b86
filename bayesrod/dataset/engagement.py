"""Which force samples are engaged: from first contact until the stem slips past the sensor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass(frozen=True)
class Engagement:
    """Result of :func:`detect_engagement`.

    Attributes
    ----------
    mask : (n,) bool, True for samples in contact
    baseline_N : force the sensor reads with nothing touching it
    noise_N : robust estimate of the sample-to-sample noise (standard deviation)
    slip_index : first sample after the slip, or None if the push ends engaged
    """

    mask: NDArray[np.bool_]
    baseline_N: float
    noise_N: float
    slip_index: int | None


def robust_noise(force_N: ArrayLike) -> float:
    """Noise standard deviation from second differences (MAD; insensitive to smooth trends and steps).

    For white noise of standard deviation s, F[i+1] - 2 F[i] + F[i-1] has variance 6 s^2.
    """
    d2 = np.diff(np.asarray(force_N, float), 2)
    if d2.size < 2:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def detect_engagement(force_N: ArrayLike, *, drop_fraction: float = 0.25, min_sigmas: float = 5.0) -> Engagement:
    """Engaged samples of one push (docs/format.md: first contact until the slip).

    The series starts at first contact, so the force rises from the sensor's
    baseline. After the peak, the slip is the first sample whose force has
    fallen back to within ``max(min_sigmas * noise, drop_fraction * rise)`` of
    the baseline and stays there for the remaining samples' median; an
    unzeroed sensor only shifts the baseline. If post-slip samples exist, the
    baseline is their median (the unloaded sensor); otherwise the first
    samples' median.

    Parameters
    ----------
    force_N : (n,) array
        Measured force, any constant offset.
    """
    F = np.asarray(force_N, float)
    n = F.size
    if n == 0:
        return Engagement(np.zeros(0, bool), 0.0, 0.0, None)
    sigma = robust_noise(F)
    start = float(np.median(F[: min(3, n)]))
    k = np.arange(n)
    smooth = _running_median3(F)
    peak = int(np.argmax(smooth))
    rise = smooth[peak] - start
    slip = None
    if rise > 0:
        thresh = max(min_sigmas * sigma, drop_fraction * rise)
        low = np.flatnonzero((k > peak) & (F - start < thresh))
        for j in low:
            tail = F[j:]
            if np.median(tail) - start < thresh and (tail.size < 2 or np.median(tail[:3]) - start < thresh):
                slip = int(j)
                break
    if slip is not None:
        slip = _slip_change_point(F, slip, sigma)
    baseline = float(np.median(F[slip:])) if slip is not None else start
    mask = np.ones(n, bool)
    if slip is not None:
        mask[slip:] = False
    return Engagement(mask, baseline, sigma, slip)


def _running_median3(F: NDArray) -> NDArray:
    """Median of each sample and its two neighbours (n,); at each end, the mean of the two samples there
    (the median of the window cut by the end). One sample is its own median."""
    smooth = F.copy()
    if F.size > 1:
        smooth[[0, -1]] = 0.5 * np.array([F[:2].sum(), F[-2:].sum()])
    if F.size > 2:
        smooth[1:-1] = np.median(np.lib.stride_tricks.sliding_window_view(F, 3), axis=1)
    return smooth


def _slip_change_point(F: NDArray, first_low: int, sigma: float) -> int:
    """The slip at or after ``first_low`` (the first sample the threshold rule calls unloaded): where the
    samples from there on best split into a straight line (the stem still loaded, its force falling
    along the branch) and a constant (the unloaded sensor).

    At a low signal-to-noise ratio a force that falls along the branch before the slip dips below the
    threshold while still in contact (SBC seeds 272 and 334 lost 8 and 16 engaged samples; docs/validation.md).
    The split is taken only where it beats "all unloaded" by the BIC of its three extra parameters (line and
    change point) with the noise sd ``sigma``; where the loaded part (at least three samples, with at least
    four unloaded after it: with two, chance lows among them drew the slip 6 samples late) lies above the
    constant by 1.5 sigma and by three standard errors of the difference of their means (the noise taken as
    independent); and where the line starts at least 0.4 of the way from the constant up to the force just
    before ``first_low`` (the stem does not jump), and ends above the constant (a stem in contact pushes the
    sensor one way: a line that falls through the unloaded level is a slip followed by noise; SBC yield seed
    61 read two unloaded samples as loaded so, docs/validation.md, session 60). Otherwise the slip stays at
    ``first_low``. Never moves the slip earlier.

    Every split's line and constant come from cumulative sums, so the cost grows linearly with the samples
    after ``first_low`` (:func:`_slip_change_point_reference` fits each split's line anew; the two agree,
    tests/test_engagement_units.py).

    Parameters
    ----------
    F : (n,) array
        Force [N], any constant offset.
    first_low : int
        Index of the threshold rule's first unloaded sample (after the peak, so at least 1).
    sigma : float
        Noise standard deviation [N] (:func:`robust_noise`).

    Returns
    -------
    int
        Index of the first unloaded sample, at least ``first_low``.
    """
    W = F[first_low:]
    m = W.size
    if m < 7 or sigma <= 0:  # three loaded and four unloaded samples at least
        return first_low
    level = float(W.mean())
    W = W - level  # centred: the sums of squares below then cancel no large offset
    sse_flat = float(np.sum(W**2))
    pre = float(np.median(F[max(0, first_low - 3) : first_low])) - level
    s = np.arange(3, m - 3)  # splits: at least three loaded and four unloaded samples
    x = np.arange(m, dtype=float)
    # prefix sums over the loaded part W[:s] (x = 0 .. s-1) and suffix sums over the unloaded part W[s:]
    cy, cxy, cyy = (np.concatenate(([0.0], np.cumsum(v))) for v in (W, x * W, W**2))
    sy, sxy, syy = cy[s], cxy[s], cyy[s]
    sx, sxx = s * (s - 1) / 2.0, (s - 1) * s * (2 * s - 1) / 6.0
    slope = (s * sxy - sx * sy) / (s * sxx - sx**2)
    intercept = (sy - slope * sx) / s
    sse_line = syy - sy**2 / s - slope * (sxy - sx * sy / s)
    n_after = m - s
    after_sum = cy[m] - sy
    after_mean = after_sum / n_after
    sse_after = (cyy[m] - syy) - after_sum**2 / n_after
    sse = sse_line + sse_after
    # the stem does not jump: the loaded line starts at least 0.4 of the way from the constant to the force
    # just before first_low (a ring of the unloaded sensor after a clear slip starts near the constant)
    joined = intercept - after_mean > 0.4 * (pre - after_mean)
    # still loaded at its last sample: the line ends above the constant
    above = intercept + slope * (s - 1) > after_mean
    # the loaded part's mean above the constant by 1.5 sigma and by 3 standard errors of the difference
    # (iid noise assumed): a sensor's ring or drift after the slip moves a stretch's mean by less
    diff = sy / s - after_mean
    gap = (diff > 1.5 * sigma) & (diff > 3.0 * sigma * np.sqrt(1.0 / s + 1.0 / n_after))
    ok = gap & joined & above & (sse < sse_flat - 3.0 * sigma**2 * np.log(m))
    if not ok.any():
        return first_low
    return first_low + int(s[ok][np.argmin(sse[ok])])


def _slip_change_point_reference(F: NDArray, first_low: int, sigma: float) -> int:
    """The slow, obvious version of :func:`_slip_change_point` (one least-squares line per split, the same rules:
    the BIC, the two gaps, the join), kept to test the fast one against."""
    W = F[first_low:]
    m = W.size
    if m < 7 or sigma <= 0:  # three loaded and four unloaded samples at least
        return first_low
    sse_flat = float(np.sum((W - W.mean()) ** 2))
    best, best_s = sse_flat - 3.0 * sigma**2 * np.log(m), 0
    pre = float(np.median(F[max(0, first_low - 3) : first_low]))  # first_low >= 1: it comes after the peak
    for s in range(3, m - 3):  # at least three loaded and four unloaded samples
        before, after = W[:s], W[s:]
        line = np.polyval(np.polyfit(np.arange(s), before, 1), np.arange(s))
        sse = float(np.sum((before - line) ** 2) + np.sum((after - after.mean()) ** 2))
        # the stem does not jump: the loaded line starts at least 0.4 of the way from the constant to the force
        # just before first_low (a ring of the unloaded sensor after a clear slip starts near the constant)
        joined = line[0] - after.mean() > 0.4 * (pre - after.mean())
        above = line[-1] > after.mean()  # still loaded at its last sample
        # the loaded part's mean above the constant by 1.5 sigma and by 3 standard errors of the difference
        # (iid noise assumed): a sensor's ring or drift after the slip moves a stretch's mean by less
        diff = before.mean() - after.mean()
        gap = diff > 1.5 * sigma and diff > 3.0 * sigma * np.sqrt(1.0 / s + 1.0 / (m - s))
        if sse < best and gap and joined and above:
            best, best_s = sse, s
    return first_low + best_s

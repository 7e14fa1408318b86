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
    smooth = np.array([np.median(F[max(0, i - 1) : i + 2]) for i in k])
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
    baseline = float(np.median(F[slip:])) if slip is not None else start
    mask = np.ones(n, bool)
    if slip is not None:
        mask[slip:] = False
    return Engagement(mask, baseline, sigma, slip)

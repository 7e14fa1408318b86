"""Is a push physically plausible before anything is fitted to it? (docs/data.md, "Plausibility")

Each check names the push and, where one row is at fault, the row (1-based data
row of ``force.csv``), says why, and what to do. Errors stop a fit; warnings
(a start already loaded, forces beyond the declared sensor range) are reported
and the data are used.

Noise levels are estimated from the data themselves, robustly: the median
absolute second difference of a series, scaled to a standard deviation
(MAD / 0.6745 / sqrt(6)); a smooth ramp has second differences near zero, so
this measures the sample-to-sample noise, not the signal.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: no plant-stem push exceeds this force [N] (a 10 kN load would break any stem); larger is a unit error
MAX_PHYSICAL_FORCE_N = 1.0e4
#: the contact point cannot move further than this many stem lengths before the stem slips past the sensor
MAX_CONTACT_TRAVEL_L = 3.0
#: a change counts as real when it exceeds this many noise standard deviations
NOISE_SDS = 5.0


def noise_sd(x: NDArray) -> float:
    """Robust sample-to-sample noise sd of a series from its second differences (0 for < 4 samples)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size < 4:
        return 0.0
    d2 = np.diff(x, 2)
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / np.sqrt(6.0))


def reversal_tolerance(x: NDArray) -> float:
    """How far a displacement series may step back before it counts as a reversal [same units as x]."""
    x = np.asarray(x, float)
    span = float(np.nanmax(x) - np.nanmin(x)) if x.size else 0.0
    return max(NOISE_SDS * noise_sd(x), 0.005 * span, 1e-12)


def first_reversal(x: NDArray, tol: float | None = None) -> int | None:
    """Index of the first sample that lies more than ``tol`` below the running maximum (None: monotone)."""
    x = np.asarray(x, float)
    if x.size < 2:
        return None
    tol = reversal_tolerance(x) if tol is None else tol
    drop = np.maximum.accumulate(x) - x
    bad = np.flatnonzero(drop > tol)
    return int(bad[0]) if bad.size else None


def starts_loaded(force_N: NDArray, floor_N: float = 0.0) -> bool:
    """A push whose first force sample is already loaded (a preload or a load-cell offset): above
    NOISE_SDS noise sd, 2% of the peak and the sensor's floor."""
    F = np.asarray(force_N, float)
    return bool(F.size >= 3 and F[0] > max(NOISE_SDS * noise_sd(F), 0.02 * F.max(), floor_N))


def check_push(where: str, force_N: NDArray, contact_x_m: NDArray, *, length_m: float | None, sensor=None):
    """Problems of one push's samples: list of (field, expected, got, row or None, severity).

    ``where`` names the push in messages; rows are 1-based sample numbers.
    """
    F = np.asarray(force_N, float)
    x = np.asarray(contact_x_m, float)
    out = []
    if F.size == 0 or not np.all(np.isfinite(F)) or not np.all(np.isfinite(x)):
        return out  # the reader reports non-finite cells cell by cell
    big = np.flatnonzero(np.abs(F) > MAX_PHYSICAL_FORCE_N)
    if big.size:
        out.append(
            (
                "column force_N",
                f"|force| <= {MAX_PHYSICAL_FORCE_N:g} N (no stem push is larger; check the force unit)",
                f"{F[big[0]]:g} N" + (f" and {big.size - 1} more" if big.size > 1 else ""),
                int(big[0]) + 1,
                "error",
            )
        )
        return out
    if length_m:
        far = np.flatnonzero(np.abs(x) > MAX_CONTACT_TRAVEL_L * length_m)
        if far.size:
            out.append(
                (
                    "column robot_x_m",
                    f"|displacement| <= {MAX_CONTACT_TRAVEL_L:g} L = "
                    f"{MAX_CONTACT_TRAVEL_L * length_m:g} m (the stem slips long before; check the unit)",
                    f"{x[far[0]]:g} m",
                    int(far[0]) + 1,
                    "error",
                )
            )
            return out
    sd = noise_sd(F)
    sig = np.abs(F) > max(3 * sd, 1e-12)
    if sig.sum() >= 3 and np.mean(F[sig] < 0) > 0.5:
        out.append(
            (
                "column force_N",
                "forces positive in the push direction",
                f"negative forces on "
                f"{np.mean(F[sig] < 0):.0%} of the loaded samples: flip the sign of force_N (the load cell "
                "reads compression as negative?)",
                None,
                "error",
            )
        )
        return out
    floor = sensor.force_range_N[0] if sensor is not None and sensor.force_range_N else 0.0
    base = float(np.median(F[: min(3, F.size)]))
    rise = float(F.max() - min(base, 0.0))
    if F.max() <= floor or rise <= max(NOISE_SDS * sd, 1e-9):
        why = (
            f"a peak of {F.max():.3g} N, below the sensor floor {floor:g} N"
            if F.max() <= floor
            else f"a rise of {rise:.3g} N, within {NOISE_SDS:g} noise sd ({sd:.2g} N) of the start"
        )
        out.append(
            (
                "column force_N",
                "a push that engages the stem (a force rising above the noise)",
                f"{why}: the probe never loaded the stem; drop this push",
                None,
                "error",
            )
        )
        return out
    k = first_reversal(x)
    if k is not None:
        out.append(
            (
                "column robot_x_m",
                "a displacement that only advances (one loading ramp)",
                f"{x[k]:.4g} m, {np.maximum.accumulate(x)[k] - x[k]:.3g} m back from its maximum (more than "
                f"the noise): the push reverses (load/unload cycles?); split it into its loading ramps (the "
                "table importer does: docs/data.md, Raw rig tables)",
                k + 1,
                "error",
            )
        )
    if starts_loaded(F, floor):
        out.append(
            (
                "column force_N",
                "a push that starts unloaded",
                f"{F[0]:.3g} N at the first sample: a preload "
                "(the stem already pressed when recording began: its displacement since first contact is "
                "unknown) or a load-cell offset",
                1,
                "warning",
            )
        )
    if sensor is not None and sensor.force_range_N and F.max() > sensor.force_range_N[1]:
        n = int(np.sum(F > sensor.force_range_N[1]))
        out.append(
            (
                "column force_N",
                f"forces within the declared sensor range (<= {sensor.force_range_N[1]:g} N)",
                f"{n} samples above it, up to {F.max():.3g} N (saturated, or a wrong sensor.force_range_N?)",
                int(np.argmax(F > sensor.force_range_N[1])) + 1,
                "warning",
            )
        )
    return out

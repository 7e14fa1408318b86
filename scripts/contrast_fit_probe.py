"""The contrast fit looked into on one rendered push: its contrast-blur trade-off, and the fit with the thin
profiles always added (issue 22; session 51's "The twig drawn 2.9 px wide, one more look").

    python scripts/contrast_fit_probe.py STEM SEED [BASE_DIAMETER_M] [--always-thin]

Simulates and extracts one push as ``scripts/width_calibration.py`` does, with ``bayesrod.vision.width``'s
``_box_fit`` wrapped so every contrast fit of every frame is also read at its solution: the finite-difference
Jacobian of the profiles' residuals in (log k, log sigma, the centres), and from it ``infl``, the sd of log k with
the blur free over its sd with the blur held (how much the trade-off widens the contrast), and ``rho`` their
correlation; ``w_lo``, ``w_hi`` the 10th and 90th percentiles of the fitted profiles' widths [px]. With
``--always-thin`` the contrast fit always adds up to ``THIN_N`` thin profiles (the shipped one adds them only
when the blur is above ``BLUR_RATIO_OK`` of the width). Prints one JSON row: the stations' median relative
error below s/L = 0.3 (``rel``, %), the declared shared scale sd (``decl``, %) and the medians over the fits.
About 6 s on one core.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from _study import extracted_push

import bayesrod.vision.width as W

FITS: list[dict] = []
_box_fit = W._box_fit


def probed_box_fit(profiles, trend, use, loss, f_scale, n_wide=None):
    """``_box_fit``, then the trade-off read at its solution (appended to FITS)."""
    from scipy.optimize import least_squares

    fit = _box_fit(profiles, trend, use, loss, f_scale, n_wide)
    n = len(use)
    t_all = np.concatenate([profiles[i][0] for i in use])
    y_all = np.concatenate([profiles[i][1] for i in use])
    owner = np.repeat(np.arange(n), [profiles[i][0].size for i in use])
    tie = np.asarray(trend, float)[use]
    log_k = np.log(fit.scale)
    log_s = np.log(fit.blur_px) if np.isfinite(fit.blur_px) else np.log(0.8)

    def resid(x):
        k, sig = np.exp(x[0]), np.exp(x[1])
        return y_all - k * W._blurred_box(t_all - x[2:][owner], (tie / k)[owner], sig)

    centres = least_squares(lambda c: resid(np.concatenate([[log_k, log_s], c])), np.zeros(n), bounds=(-2, 2)).x
    x = np.concatenate([[log_k, log_s], centres])
    J = np.empty((y_all.size, x.size))
    for j in range(x.size):
        d = np.zeros_like(x)
        d[j] = 1e-6
        J[:, j] = (resid(x + d) - resid(x - d)) / 2e-6
    H = J.T @ J
    C = np.linalg.pinv(H)
    held = np.linalg.pinv(np.delete(np.delete(H, 1, 0), 1, 1))[0, 0]  # the blur held, the centres free
    w = tie / fit.scale
    FITS.append(
        {
            "rho": C[0, 1] / np.sqrt(C[0, 0] * C[1, 1]),
            "infl": np.sqrt(C[0, 0] / held),
            "w_lo": np.percentile(w, 10),
            "w_hi": np.percentile(w, 90),
            "blur": fit.blur_px,
            "k": fit.scale,
        }
    )
    return fit


def always_thin_contrast_fit(profiles, s, n_max=W.AREA_N_MAX, *, loss="soft_l1", f_scale=0.1):
    """``contrast_fit`` with the thin profiles added whatever the blur. A copy without its gate, not the shipped
    function under a lowered ``BLUR_RATIO_OK``: that would run the wide-only fit first, and the probe would count
    it among the fits it reads."""
    trend, wide, thin = W.contrast_profiles(profiles, s, n_max)
    if len(wide) < 5:
        return W.ContrastFit()
    return W._box_fit(profiles, trend, wide + thin, loss, f_scale, len(wide))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stem")
    ap.add_argument("seed", type=int)
    ap.add_argument("base_diameter_m", type=float, nargs="?")
    ap.add_argument("--always-thin", action="store_true")
    a = ap.parse_args(argv)
    W._box_fit = probed_box_fit
    if a.always_thin:
        W.contrast_fit = always_thin_contrast_fit
    over = {"base_diameter_m": a.base_diameter_m} if a.base_diameter_m else None
    with tempfile.TemporaryDirectory() as tmp:
        ex, drawn, _ = extracted_push(a.stem, a.seed, False, Path(tmp), overrides=over)
    dp = ex.diameters
    ok = dp.ok
    low = dp.s_m[ok] / ex.dataset.length_m < 0.3
    rel = float(np.median(dp.d_m[ok][low] / drawn[ok][low] - 1))
    row = {"stem": a.stem, "seed": a.seed, "d0": a.base_diameter_m, "always_thin": a.always_thin}
    row |= {"rel": round(100 * rel, 2), "decl": round(100 * dp.shared_scale_sd, 2), "nfits": len(FITS)}
    row |= {k: round(float(np.median([f[k] for f in FITS])), 3) for k in ("rho", "infl", "w_lo", "w_hi", "blur", "k")}
    print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()

"""What structure do the extracted widths' errors have along the stem? (issue 22)

    python scripts/width_error_structure.py --cache DIR grass_20_0 grass_21_0 ...

Reads pushes cached by scripts/width_taper_check.py (``DIR/<stem>_<seed>_<graded>.pkl``), combines their
frames as ``bayesrod.extract`` does and takes the errors against the drawn diameter, e = measured - drawn
[px]. Their covariance is fitted by maximum likelihood, pooled over the pushes, under the width term's
model (each push its own sd scale k and AR(1) correlation r of neighbouring stations, on the stations'
sds; the shared offset and scale errors at their set sizes) with and without one more term: a smooth
error along s, Matern-3/2 of length ell (a fraction of the profile's span), amplitude either in pixels
(``px``) or in station sds (``sd``). Printed: the negative log likelihood of each model, the fitted
amplitude and length, and the profile over ell. Because e is taken against the drawn diameter, the
smooth term is not confounded with the taper here as it is in a fit.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from width_taper_check import combined, load_cached

from bayesrod.physics import stem_diameter


def load(cache: Path, key: str) -> tuple:
    """(e [px], sd [px], s / L, span of s / L, offset sd [px], scale error [px] per station) of one push."""
    fr = load_cached(cache, key)
    dp = combined(fr)
    ok, px = dp.ok, fr["px"]
    s = dp.s_m[ok]
    true = stem_diameter(s, fr["d0"], fr["q"], fr["L"])
    x = s / fr["L"]
    return (
        (dp.d_m[ok] - true) / px,
        dp.sd_m[ok] / px,
        x,
        float(np.ptp(x)),
        dp.shared_offset_sd_m / px,
        dp.shared_scale_sd * true / px,
    )


def matern32(r: np.ndarray) -> np.ndarray:
    a = np.sqrt(3.0) * r
    return (1.0 + a) * np.exp(-a)


def nll(theta: np.ndarray, data: list, mode: str) -> float:
    """Pooled negative log likelihood; theta = (log amplitude, log ell, then log k and atanh r per push)."""
    amp, ell = np.exp(theta[0]), np.exp(theta[1])
    total = 0.0
    for j, (e, sd, x, span, off, sc) in enumerate(data):
        k, r = np.exp(theta[2 + 2 * j]), np.tanh(theta[3 + 2 * j])
        lag = np.abs(np.arange(e.size)[:, None] - np.arange(e.size)[None])
        C = k**2 * np.outer(sd, sd) * r**lag + off**2 + np.outer(sc, sc)
        if mode != "none":
            R = matern32(np.abs(x[:, None] - x[None]) / (ell * span))
            C = C + amp**2 * (R if mode == "px" else np.outer(sd, sd) * R)
        total += 0.5 * np.linalg.slogdet(C)[1] + 0.5 * e @ np.linalg.solve(C, e)
    return float(total)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("pushes", nargs="+", help="cached pushes: <stem>_<seed>_<graded>")
    a = ap.parse_args(argv)
    data = [load(a.cache, k) for k in a.pushes]
    per_push = np.tile([0.0, 0.1], len(data))
    base = minimize(lambda t: nll(np.concatenate([[-50.0, 0.0], t]), data, "none"), per_push, method="L-BFGS-B")
    print(f"{len(data)} pushes; without a smooth error: nll {base.fun:.2f}")
    for mode, amp0 in (("px", 0.03), ("sd", 0.4)):
        start = np.concatenate([[np.log(amp0), np.log(0.2)], per_push])
        fit = minimize(nll, start, args=(data, mode), method="L-BFGS-B")
        print(
            f"smooth error in {mode}: nll {fit.fun:.2f} (gain {base.fun - fit.fun:.2f}), amplitude "
            f"{np.exp(fit.x[0]):.4f}, ell {np.exp(fit.x[1]):.3f} of the span, sd scale k median "
            f"{np.median(np.exp(fit.x[2::2])):.2f}"
        )
        for ell in (0.05, 0.1, 0.2, 0.4, 0.8):
            prof = minimize(
                lambda t, ell=ell, mode=mode: nll(np.concatenate([[t[0], np.log(ell)], t[1:]]), data, mode),
                np.concatenate([[fit.x[0]], fit.x[2:]]),
                method="L-BFGS-B",
            )
            gain = base.fun - prof.fun
            print(f"   ell {ell}: nll {prof.fun:.2f} (gain {gain:.2f}), amplitude {np.exp(prof.x[0]):.4f}")


if __name__ == "__main__":
    main()

"""How far a tabled force curve lies from exact solves, along its whole branch (issue 21, session 72).

    python scripts/force_curve_accuracy.py [--reference | --pchip]

For each (h/L, p) case and effect below, ``ForceCurves.batch`` at four p nodes (p - 0.05 ... p + 0.1) and
``force_from_displacement_nd`` at the second node's p, at evenly spaced displacements up to its branch end;
prints the largest |table - exact| force over the peak force. ``--reference``: with session 71's curves patched
in (:func:`old_curves`: the clustered levels alone, PCHIP, every level kept, the spline's own end slope);
``--pchip``: today's levels but PCHIP (the middle column of docs/validation.md, session 72).
Writes nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.interpolate import PchipInterpolator

from bayesrod.inference import likelihood as LK
from bayesrod.physics import force_from_displacement_nd

PLAIN = [(0.41221, 0.95), (0.6, 0.95), (0.5, 1.2), (0.5, 0.43), (0.7, 0.2)]
EFFECTS = [{"c_base": 0.5}, {"c_base": 3.0}, {"kappa0": 0.8}, {"kappa0": -1.2}, {"tilt": 0.2}, {"tilt": -0.25}]
EFFECTS += [{"mu": 0.3}]


def old_curves(levels: bool = False):
    """Patch session 71's force curves into ``bayesrod.inference.likelihood`` (``levels``: PCHIP and the spline's
    own end slope only, today's levels and spacing kept); returns the undo."""
    saved = (LK.PLATEAU_LEVELS, LK.MIN_LEVEL_GAP, LK.CubicSpline, LK._end_slope)
    if not levels:
        LK.PLATEAU_LEVELS, LK.MIN_LEVEL_GAP = 0, 0.0
    LK.CubicSpline = lambda x, y, extrapolate=True: PchipInterpolator(x, y, extrapolate=extrapolate)
    LK._end_slope = lambda d, f, d_end, spline: float(spline.derivative()(d_end))

    def undo():
        LK.PLATEAU_LEVELS, LK.MIN_LEVEL_GAP, LK.CubicSpline, LK._end_slope = saved

    return undo


def curve_error(eta: float, p: float, effects: dict | None, n: int = 200) -> float:
    """Largest |table - exact| force over the peak force along the curve at (eta, p)."""
    LK._CURVE_CACHE.clear()
    (c,) = LK.ForceCurves.batch(np.array([eta]), np.array([p - 0.05, p, p + 0.05, p + 0.1]), effects_nd=effects)
    d = np.linspace(0.0, c.d_end[1], n)[1:-1]
    exact = force_from_displacement_nd(d, np.full(d.size, eta), p, effects)["f"]
    ok = np.isfinite(exact)
    return float(np.max(np.abs(c.force(d)[1] - exact)[ok]) / np.max(exact[ok]))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    how = ap.add_mutually_exclusive_group()
    how.add_argument("--reference", action="store_true", help="session 71's curves")
    how.add_argument("--pchip", action="store_true", help="today's levels, PCHIP")
    a = ap.parse_args(argv)
    undo = old_curves() if a.reference else old_curves(levels=True) if a.pchip else (lambda: None)
    try:
        for eta, p in PLAIN:
            print(f"plain h/L {eta:g} p {p:g}: {curve_error(eta, p, None, 400):.2e}", flush=True)
        for eff in EFFECTS:
            for eta, p in ((0.5, 0.43), (0.45, 0.95)):
                print(f"{eff} h/L {eta:g} p {p:g}: {curve_error(eta, p, eff):.2e}", flush=True)
    finally:
        undo()


if __name__ == "__main__":
    main()

"""Slow, obvious reference for the elastica: one ``scipy.integrate.solve_ivp`` per solve.

Same equations as :mod:`bayesrod.physics.elastica` (see its docstring), written
as plainly as possible: an adaptive DOP853 integration with a terminal event at
the sensor height, ``brentq`` for the base moment (friction, weight) and for the
force at a given displacement. Used by the tests and the benchmarks only.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

from .elastica import STEEP_ROOT_JUMP, STEEP_ROOT_MOVE, TIP_TOLERANCE

RTOL = 1e-12
ATOL = 1e-14


#: brentq's relative tolerance on the base moment: its least (4 eps), so its root is a few ulps from the sign change
_RTOL_M0 = 4.0 * np.finfo(float).eps
#: points of the scan for the first root of the base-moment residual where the bracket held several (solve_force)
SCAN_POINTS = 129
#: |contact displacement - target| [L] above which solve_displacement's root is not one (a force with no contact
#: inside the bracket, where the scan's "past the target" stood in for it)
DISPLACEMENT_MATCH = 1e-6


def _ei(sig: float, p: float) -> float:
    return max(1.0 - sig, 0.0) ** (4.0 * p) if p > 0 else 1.0


def _weight_above(sig: float, p: float, w0: float) -> float:
    q = 2.0 * p + 1.0
    return w0 * max(1.0 - sig, 0.0) ** q / q


def solve_force(
    f: float, eta: float, p: float, eff: dict | None = None, phi_p: float = 0.0, rtol: float = RTOL
) -> dict:
    """Contact for nondimensional force ``f`` (scalar); ``found`` False if none."""
    eff = eff or {}
    mu, w0 = eff.get("mu", 0.0), eff.get("w0", 0.0)
    kappa0, tilt, c_base = eff.get("kappa0", 0.0), eff.get("tilt", 0.0), eff.get("c_base", 0.0)

    def shoot(m0: float) -> dict:
        def rhs(sig, y, on):
            x, z, phi, m = y
            dm = -on * f * (math.cos(phi) - mu * math.sin(phi)) - _weight_above(sig, p, w0) * math.sin(phi)
            return [math.sin(phi), math.cos(phi), m / max(_ei(sig, p), 1e-300) + kappa0, dm]

        def hit(sig, y, on):
            return y[1] - eta

        hit.terminal, hit.direction = True, 1

        def over(sig, y, on):
            return y[2] - math.pi / 2

        over.terminal, over.direction = True, 1

        def back(sig, y, on):  # bent back past horizontal (a base moment far too small): no contact ahead
            return y[2] + math.pi / 2

        back.terminal, back.direction = True, -1
        y0 = [0.0, 0.0, tilt + phi_p + c_base * m0, m0]
        s1 = solve_ivp(
            rhs,
            (0.0, 1.0 + TIP_TOLERANCE),
            y0,
            args=(1.0,),
            events=(hit, over, back),
            method="DOP853",
            rtol=rtol,
            atol=ATOL,
        )
        if s1.status != 1 or s1.t_events[0].size == 0:
            # bent over: the tangent passed horizontal below the sensor, or the stem ends leaning toward the
            # push below it (else it bent back: a base moment too small)
            return {"found": False, "bent_over": bool(s1.t_events[1].size) or bool(s1.y[2, -1] > 0)}
        sig_c = float(s1.t_events[0][0])
        yc = s1.y_events[0][0]
        out = {"found": True, "sig_c": sig_c, "xi_c": float(yc[0]), "phi_c": float(yc[2]), "m0": m0}
        if w0 == 0.0:
            out["resid"] = float(yc[3])
        else:
            # The last 0.1% of the rod carries a moment below 1e-8 of the weight's: stop
            # there, where a trial base moment cannot make phi' = m/e blow up.
            s2 = solve_ivp(rhs, (sig_c, max(sig_c, 0.999)), yc, args=(0.0,), method="DOP853", rtol=rtol, atol=ATOL)
            out["resid"] = float(s2.y[3, -1])
        return out

    m_guess = f * eta
    if mu == 0.0 and w0 == 0.0:
        return shoot(m_guess)

    def resid(m0):
        """The residual; without a contact, too far (+1) where the stem bent over, else too little (-1)."""
        r = shoot(m0)
        if r["found"]:
            return r["resid"]
        return 1.0 if r["bent_over"] else -1.0

    # The residual rises with the base moment. Bracket its root from below (0 for a push and a stem leaning
    # toward it) and above (the frictionless f eta, grown until the residual is positive or the stem bends
    # over), then brentq. Starting from f eta without a bracket found no contact where friction bends the
    # stem far (docs/model.md, "Friction and weight: the base moment").
    lo, hi = 0.0, max(m_guess, 1e-6)
    while resid(lo) >= 0:
        lo = -2.0 * abs(lo) - 1.0
        if lo < -1e6:
            return {"found": False}
    while resid(hi) < 0:
        lo, hi = hi, 2.0 * hi
        if hi > 1e6:
            return {"found": False}
    out = _settle(shoot, brentq(resid, lo, hi, xtol=1e-15, rtol=_RTOL_M0))
    if out is not None:
        return out
    # The bracket held more than one sign change and brentq closed on a jump (the contact leaping to a later
    # crossing, the stem bending over): SBC friction seed 3 (eta 0.496, p 0.473, mu -0.085) had no contact at
    # f 4.173-4.199 although the residual rises smoothly through a root at m0 2.2152, then jumps back below
    # zero at 2.27 where the contact leaps from 0.70 to 0.93 L. The equilibrium of the loading branch is the
    # first root above the bracket's lower end: scanned for on SCAN_POINTS points, then settled as above.
    grid = np.linspace(lo, hi, SCAN_POINTS)
    for a, b in zip(grid[:-1], grid[1:], strict=True):  # resid(lo) < 0: the first b at or above zero closes it
        if resid(b) >= 0.0:
            return _settle(shoot, brentq(resid, a, b, xtol=1e-15, rtol=_RTOL_M0)) or {"found": False}
    return {"found": False}


def _settle(shoot, m0: float) -> dict | None:
    """The contact at the base moment ``m0`` brentq returned, or None where no equilibrium holds there."""
    out = shoot(m0)
    if out["found"] and abs(out["resid"]) <= 1e-9 * (1.0 + abs(m0)):
        return out
    # Next to the branch's end the residual may rise by 3e-8 per ulp of m0 (eta 0.45, p 0.55, mu 0.2, f 13.95): no
    # moment leaves it under 1e-9. A root still holds where the residual changes sign continuously across brentq's
    # tolerance either side (by at most STEEP_ROOT_JUMP (1 + |m0|), the contact moving at most STEEP_ROOT_MOVE L: the
    # fast path's rule, elastica.py): bisected there to a few ulps, the moment of least |residual|. Else the bracket
    # closed on the branch's end (the contact jumps, or the stem bends over): no equilibrium holds.
    d = 2.0 * (1e-15 + _RTOL_M0 * abs(m0))
    a, b = m0 - d, m0 + d
    below, above = shoot(a), shoot(b)
    if not (below["found"] and above["found"] and below["resid"] < 0.0 <= above["resid"]):
        return None
    jump = above["resid"] - below["resid"] > STEEP_ROOT_JUMP * (1.0 + abs(m0))
    if jump or abs(above["sig_c"] - below["sig_c"]) > STEEP_ROOT_MOVE:
        return None
    best = min((below, above), key=lambda o: abs(o["resid"]))
    while b - a > 4.0 * np.spacing(abs(m0)):
        mid = shoot(0.5 * (a + b))
        if not mid["found"]:
            return None
        a, b = (mid["m0"], b) if mid["resid"] < 0.0 else (a, mid["m0"])
        best = min((best, mid), key=lambda o: abs(o["resid"]))
    return best


def solve_displacement(d: float, eta: float, p: float, eff: dict | None = None, rtol: float = RTOL) -> dict:
    """Force for nondimensional contact displacement ``d`` since first contact (scalar).

    Scans the force upward from zero in small geometric steps along the loading
    branch, then ``brentq`` on the bracketing interval. No yield.
    """
    eff = eff or {}
    x0 = solve_force(0.0, eta, p, eff, rtol=rtol)["xi_c"]
    if d <= 0:
        return {"f": 0.0, "slipped": False, "sig_c": solve_force(0.0, eta, p, eff, rtol=rtol)["sig_c"]}

    def g(f):
        r = solve_force(f, eta, p, eff, rtol=rtol)
        return r["xi_c"] - x0 - d if r["found"] else float("nan")

    lo, hi = 0.0, 1e-3
    while True:
        gh = g(hi)
        if math.isnan(gh):  # past the branch end: bisect for the boundary
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                gm = g(mid)
                if math.isnan(gm):
                    hi = mid
                elif gm >= 0:
                    hi = mid
                    break
                else:
                    lo = mid
                if hi - lo <= 4e-16 * hi:
                    return {"f": float("nan"), "slipped": True}
            else:
                return {"f": float("nan"), "slipped": True}
            if math.isnan(g(hi)):
                return {"f": float("nan"), "slipped": True}
            break
        if gh >= 0:
            break
        lo, hi = hi, hi * 1.25
        if hi > 1e6:
            return {"f": float("nan"), "slipped": True}
    # Inside the scanned bracket, "no contact" can only mean "past the target".
    f = brentq(lambda x: 1.0 if math.isnan(g(x)) else g(x), lo, hi, xtol=1e-14, rtol=1e-13)
    r = solve_force(f, eta, p, eff, rtol=rtol)
    if not r["found"] or abs(r["xi_c"] - x0 - d) > DISPLACEMENT_MATCH:
        # brentq closed on the edge of forces without a contact, not on d: no answer rather than a wrong one
        # (SBC friction seed 3 read the force at one such edge for three displacements 0.02 L apart)
        return {"f": float("nan"), "slipped": False, "no_contact_inside": True}
    return {"f": f, "slipped": False, "sig_c": r["sig_c"], "phi_c": r["phi_c"]}


def ktheta_quad(eta: float, p: float) -> float:
    """k_theta L/EI0 by adaptive quadrature of eq. kdist (reference for the closed form)."""
    val, _ = quad(lambda s: (eta - s) / _ei(s, p), 0.0, eta, epsabs=0, epsrel=1e-13, limit=200)
    return eta / val


def kx_quad(eta: float, p: float) -> float:
    """k_x L^3/EI0 by adaptive quadrature of eq. kx."""
    val, _ = quad(lambda s: (eta - s) ** 2 / _ei(s, p), 0.0, eta, epsabs=0, epsrel=1e-13, limit=200)
    return 1.0 / val


def shape_at_force(f: float, eta: float, p: float, sig: np.ndarray, eff: dict | None = None) -> np.ndarray:
    """Centerline (xi, zeta) at arc lengths ``sig`` (sorted) for force f; no friction/weight.

    ``f`` must be finite: :func:`solve_displacement` returns NaN for a displacement past the slip.
    """
    if not math.isfinite(f):
        raise ValueError(f"f: expected a finite nondimensional force (a push before its slip), got {f}")
    eff = eff or {}
    kappa0, tilt, c_base = eff.get("kappa0", 0.0), eff.get("tilt", 0.0), eff.get("c_base", 0.0)
    r = solve_force(f, eta, p, eff)

    def rhs(s, y):
        on = 1.0 if s < r["sig_c"] else 0.0
        return [math.sin(y[2]), math.cos(y[2]), on * f * (eta - y[1]) / max(_ei(s, p), 1e-300) + kappa0]

    out = solve_ivp(
        rhs,
        (0.0, float(sig[-1])),
        [0.0, 0.0, tilt + c_base * f * eta],
        t_eval=sig,
        method="DOP853",
        rtol=1e-12,
        atol=1e-14,
        max_step=1e-3,
    )
    return out.y[:2]

"""The rod's Runge-Kutta step compiled (numba): the fast path beside the numpy reference.

One step of :func:`bayesrod.physics.elastica._step_plain` (DOP853 tableau, no weight, friction or rest curvature)
or of :func:`bayesrod.physics.elastica._step_general` (any of them) for every rod of a batch, its twelve stages in
one compiled loop per rod instead of five to a dozen array calls per stage. The
numpy path spends its time in array-call overhead at the batch sizes a fit uses (one to a few hundred rods); the
loop takes 3.7-12x less time at 1-64 rods (7-24x with effects) and 1.3x less at 4096
(``benchmarks/bench_compiled_step.py``). Tests
check the two paths agree to round-off (tests/test_elastica.py).

The numpy path is taken instead when numba is missing or the environment sets ``BAYESROD_NO_JIT`` (to a non-empty
value): :data:`step` is then ``None``.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numpy.typing import NDArray


def _load_numba():
    """numba, or None (missing, or BAYESROD_NO_JIT set)."""
    if os.environ.get("BAYESROD_NO_JIT"):
        return None
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; the numpy path still works without it
        return None
    return numba


_numba = _load_numba()


def _jit(**options):
    """numba.njit with the compiled code cached on disk (in __pycache__, or numba's user-wide cache where that is
    read-only; compiled in each process where neither can be written), or the function itself when numba is not
    used."""
    if _numba is None:
        return lambda fn: fn

    def compiled(fn):
        try:
            return _numba.njit(cache=True, **options)(fn)
        except RuntimeError:  # numba: "cannot cache function ...: no locator available" (nowhere to write)
            return _numba.njit(**options)(fn)

    return compiled


@_jit(inline="always")
def _inverse_taper(s: float, p4: float, one_taper: bool) -> float:
    """1 / e(s) of eq. taper as the numpy plain step evaluates it (``elastica._inverse_taper``): e floored at
    1e-300 (past the tip 1 / e = 1e300), (1 - s)^(4p) with one exponent for the batch (1 when p = 0),
    exp(4p log(1 - s)) with one per rod."""
    if one_taper:
        return 1.0 if p4 == 0.0 else 1.0 / max(max(1.0 - s, 0.0) ** p4, 1e-300)
    return 1.0 / max(math.exp(p4 * math.log(max(1.0 - s, 1e-300))), 1e-300)


@_jit(inline="always")
def _taper(s: float, p4: float, power: bool) -> float:
    """e(s) of eq. taper as the numpy general step evaluates it (``elastica._rhs``): infinite at and past the tip
    (no bending there), floored at 1e-300, (1 - s)^(4p) with one exponent and one sigma for the batch (``power``;
    1 when p = 0), else exp(4p log(1 - s))."""
    if s >= 1.0:
        return math.inf
    if power:
        return 1.0 if p4 == 0.0 else max((1.0 - s) ** p4, 1e-300)
    return max(math.exp(p4 * math.log(max(1.0 - s, 1e-300))), 1e-300)


@_jit(inline="always")
def _weight(s: float, q: float) -> float:
    """(1 - s)^q / q, the weight above s per unit w0 (q = 2p + 1), as ``elastica._rhs`` evaluates it."""
    return math.exp(q * math.log(max(1.0 - s, 1e-300))) / q


@_jit(inline="always")
def _at(x: NDArray, j: int) -> float:
    """x[j] of a per-rod array, x[0] of a (1,) array shared by the batch."""
    return x[0] if x.shape[0] == 1 else x[j]


@_jit(nogil=True)
def _step_loop(
    Y: NDArray,
    sig: NDArray,
    h: NDArray,
    f: NDArray,
    active: NDArray,
    p4: NDArray,
    kappa0: NDArray,
    mu: NDArray,
    w0: NDArray,
    q: NDArray,
    general: bool,
    c: NDArray,
    a: NDArray,
    b: NDArray,
) -> NDArray:
    """One RK step (DOP853 tableau) of every rod of the batch.

    Parameters
    ----------
    Y : (4, B) float array
        States (xi, zeta, phi, m) at the step's start (nondimensional, eq. ivp).
    sig, h : (1,) or (B,) float arrays
        Where the step starts and its size, in sigma = s/L.
    f, active : (1,) or (B,) float arrays
        The nondimensional push f = F L^2 / EI0 and the contact factor a(sigma) (1 below the contact, 0 above).
    p4 : (1,) or (B,) float array
        4 p, the exponent of e(sigma) = (1 - sigma)^(4p) (eq. taper): one for the batch, or one per rod.
    kappa0, mu, w0, q : (1,) or (B,) float arrays
        Rest curvature, friction coefficient, weight and 2p + 1 (the weight's exponent) of the general step.
    general : bool
        False: the plain rod (``elastica._step_plain``; kappa0, mu and w0 are not read); True: the general step
        (``elastica._step_general`` and ``elastica._rhs``), with any of the effects: rest curvature where kappa0
        is non-zero, friction where mu is, weight where w0 is.
    c, a, b : (12,), (12, 12) and (12,) float arrays
        The tableau's nodes, stage and weight coefficients.

    Returns
    -------
    (4, B) float array
        The states at the step's end.

    Notes
    -----
    The slopes are (sin phi, cos phi, m / e + kappa0, -a f (cos phi - mu sin phi) - W sin phi) (eqs. ivp,
    constitutive): a stage's state needs only phi and m, so only those two are combined per stage; xi and zeta
    are summed once, from the stages' slopes, at the end. Each path's taper is evaluated as its numpy step does
    (:func:`_inverse_taper`, :func:`_taper`), so the two agree to round-off.
    """
    n = Y.shape[1]
    out = np.empty((4, n))
    k = np.empty((12, 4))
    one_taper = p4.shape[0] == 1
    # one taper, one step start and size: the twelve stages' taper is the same for every rod
    shared = one_taper and sig.shape[0] == 1 and h.shape[0] == 1
    taper = np.empty(12)  # 1 / e (plain) or e (general) at the stages, when shared
    weight = np.empty(12)  # the weight's (1 - s)^q / q at the stages, when shared (q = 2p + 1: one p, one q)
    if shared:
        for i in range(12):
            s = sig[0] + c[i] * h[0]
            taper[i] = _taper(s, p4[0], True) if general else _inverse_taper(s, p4[0], True)
            weight[i] = _weight(s, q[0])
    for j in range(n):
        hj = _at(h, j)
        sj = _at(sig, j)
        pj = _at(p4, j)
        af = _at(active, j) * _at(f, j)
        kap, mu_j, w0_j, qj = _at(kappa0, j), _at(mu, j), _at(w0, j), _at(q, j)  # read by the general path only
        phi0 = Y[2, j]
        m0 = Y[3, j]
        for i in range(12):
            s_phi = 0.0
            s_m = 0.0
            for stage in range(i):
                s_phi += a[i, stage] * k[stage, 2]
                s_m += a[i, stage] * k[stage, 3]
            phi = phi0 + hj * s_phi
            m = m0 + hj * s_m
            s = sj + c[i] * hj
            cos_phi = math.cos(phi)
            sin_phi = math.sin(phi)
            k[i, 0] = sin_phi
            k[i, 1] = cos_phi
            if not general:
                k[i, 2] = m * (taper[i] if shared else _inverse_taper(s, pj, one_taper))
                k[i, 3] = cos_phi * -af
                continue
            k[i, 2] = m / (taper[i] if shared else _taper(s, pj, False)) + kap  # + 0.0 is exact: no branch
            k[i, 3] = -((cos_phi - mu_j * sin_phi) * af) if mu_j != 0.0 else cos_phi * -af
            if w0_j != 0.0:
                k[i, 3] -= w0_j * (weight[i] if shared else _weight(s, qj)) * sin_phi
        for comp in range(4):
            total = 0.0
            for i in range(12):
                total += b[i] * k[i, comp]
            out[comp, j] = Y[comp, j] + hj * total
    return out


step = _step_loop if _numba is not None else None
"""The compiled :func:`_step_loop`, or None when the numpy steps are to be used."""

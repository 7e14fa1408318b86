"""The plain rod's Runge-Kutta step compiled (numba): the fast path beside the numpy reference.

One step of :func:`bayesrod.physics.elastica._step_plain` (DOP853 tableau, no weight, friction or rest curvature)
for every rod of a batch, its twelve stages in one compiled loop per rod instead of five array calls per stage. The
numpy path spends its time in array-call overhead at the batch sizes a fit uses (one to a few hundred rods); the
loop takes 4-15x less time at 1-64 rods and 1.3x less at 4096 (``benchmarks/bench_compiled_step.py``). Tests
check the two paths agree to round-off (tests/test_elastica.py).

The numpy path is taken instead when numba is missing or the environment sets ``BAYESROD_NO_JIT`` (to a non-empty
value): :data:`plain_step` is then ``None``.
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
    read-only), or the function itself when numba is not used."""
    if _numba is None:
        return lambda fn: fn
    return _numba.njit(cache=True, **options)


@_jit(inline="always")
def _inverse_taper(s: float, p4: float, one_taper: bool) -> float:
    """1 / e(s) of eq. taper, e floored at 1e-300, as the numpy path evaluates it: (1 - s)^(4p) with one exponent
    for the batch (1 when p = 0), exp(4p log(1 - s)) with one per rod."""
    if one_taper:
        return 1.0 if p4 == 0.0 else 1.0 / max(max(1.0 - s, 0.0) ** p4, 1e-300)
    return 1.0 / max(math.exp(p4 * math.log(max(1.0 - s, 1e-300))), 1e-300)


@_jit(nogil=True)
def _plain_step_loop(
    Y: NDArray, sig: NDArray, h: NDArray, f: NDArray, active: NDArray, p4: NDArray, c: NDArray, a: NDArray, b: NDArray
) -> NDArray:
    """One RK step of a plain rod for each rod of the batch.

    Parameters
    ----------
    Y : (4, B) float array
        States (xi, zeta, phi, m) at the step's start (nondimensional, eq. ivp).
    sig, h : (1,) or (B,) float arrays
        Where the step starts and its size, in sigma = s/L.
    f, active : (1,) or (B,) float arrays
        The nondimensional push f = F L^2 / EI0 and the contact factor a(sigma) (1 below the contact, 0 above).
    p4 : (1,) or (B,) float array
        4 p, the exponent of e(sigma) = (1 - sigma)^(4p) (eq. taper): one for the batch, or one per rod (then
        evaluated as exp(4p log(1 - sigma)), as the numpy path does).
    c, a, b : (12,), (12, 12) and (12,) float arrays
        The tableau's nodes, stage and weight coefficients.

    Returns
    -------
    (4, B) float array
        The states at the step's end.

    Notes
    -----
    The slopes are (sin phi, cos phi, m / e, -a f cos phi) (eq. constitutive): a stage's state needs only phi and
    m, so only those two are combined per stage; xi and zeta are summed once, from the stages' slopes, at the end.
    e is floored at 1e-300 (past the tip: 1 / e = 1e300, as the numpy path's taper), and 1 when p = 0.
    """
    n = Y.shape[1]
    out = np.empty((4, n))
    k = np.empty((12, 4))
    one_taper = p4.shape[0] == 1
    # one taper, one step start and size: the twelve stages' 1 / e are the same for every rod
    shared = one_taper and sig.shape[0] == 1 and h.shape[0] == 1
    shared_inv_e = np.empty(12)
    if shared:
        for i in range(12):
            shared_inv_e[i] = _inverse_taper(sig[0] + c[i] * h[0], p4[0], True)
    for j in range(n):
        hj = h[0] if h.shape[0] == 1 else h[j]
        sj = sig[0] if sig.shape[0] == 1 else sig[j]
        pj = p4[0] if p4.shape[0] == 1 else p4[j]
        neg_af = -(active[0] if active.shape[0] == 1 else active[j]) * (f[0] if f.shape[0] == 1 else f[j])
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
            inv_e = shared_inv_e[i] if shared else _inverse_taper(sj + c[i] * hj, pj, one_taper)
            cos_phi = math.cos(phi)
            k[i, 0] = math.sin(phi)
            k[i, 1] = cos_phi
            k[i, 2] = m * inv_e
            k[i, 3] = cos_phi * neg_af
        for comp in range(4):
            total = 0.0
            for i in range(12):
                total += b[i] * k[i, comp]
            out[comp, j] = Y[comp, j] + hj * total
    return out


plain_step = _plain_step_loop if _numba is not None else None
"""The compiled :func:`_plain_step_loop`, or None when the numpy path is to be used."""

"""Fast batched planar elastica of a tapered stem pushed at a fixed height.

The seed paper's rod (eq. ivp) in nondimensional form. With sigma = s/L,
xi = x/L, zeta = z/L, phi the tangent angle from vertical (positive toward the
push), e(sigma) = EI(s)/EI0 = (1 - sigma)^(4p), f = F L^2/EI0 and
m = M L/EI0 the bending moment (positive bending toward +x), the state
(xi, zeta, phi, m) obeys::

    xi'   = sin(phi)
    zeta' = cos(phi)
    phi'  = m / e(sigma) + kappa0                     (eq. constitutive, A4)
    m'    = -a(sigma) (f cos(phi) - mu f sin(phi)) - W(sigma) sin(phi)

from the base (xi = zeta = 0, phi = tilt + c_base m(0) + phi_plastic), where
a = 1 below the contact (zeta < eta = h/L) and 0 above it, and W is the
nondimensional weight carried above sigma (effect ``self_weight``). Without
friction or weight, m(0) = f eta exactly and m = f (eta - zeta) below the
contact: eq. M_determinate. The problem therefore depends on f, p and eta only
(plus the nondimensional effect groups), so EI0 is a pure scale.

The fast path is a fixed-step 8th-order Runge-Kutta (DOP853 tableau) batched over a leading axis of any number
of problems, with the contact located exactly by Newton on a partial step
(the moment has a kink there, which a step across it would smear). The slow,
obvious reference is :mod:`bayesrod.physics.reference` (``solve_ivp``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _compiled
from .effects import Effects
from .lumped import kx_nd

__all__ = [
    "ContactSolution",
    "ForceSolution",
    "contact_from_force",
    "contact_from_force_nd",
    "force_from_displacement",
    "force_from_displacement_nd",
    "DEFAULT_STEPS",
    "secant_k_theta",
    "centerline_at",
    "centerline_x_at_heights",
    "centerline_normal_offsets",
]

DEFAULT_STEPS = 48
TIP_TOLERANCE = 1e-4
"""Contact up to this fraction of L past the tip is taken as contact at the tip."""
#: the largest turn of the tangent [rad] over a march's last step (into the tip) taken as one step; a larger one is
#: taken again in the substeps of TIP_SUBSTEPS, fractions of h left to the tip: each halves the distance to the
#: tip, where e(sigma) = (1 - sigma)^(4p) vanishes (2^-30 h: under 2e-11 of L)
TIP_CALM = 0.25
TIP_SUBSTEPS = np.concatenate([2.0 ** -np.arange(31), [0.0]])
_TINY = 1e-300
_HALF_PI = 0.5 * np.pi
_EFFECT_KEYS = ("c_base", "kappa0", "tilt", "mu", "f_offset", "w0", "m_yield")


# --------------------------------------------------------------------------- #
# Problem arrays
# --------------------------------------------------------------------------- #
def _problem(eta: ArrayLike, p: ArrayLike, eff: dict | None, *extra: ArrayLike) -> tuple[dict, list]:
    """Broadcast eta, p, effect groups and extra arrays to one flat batch."""
    eff = dict(eff or {})
    neutral = {"c_base": 0.0, "kappa0": 0.0, "tilt": 0.0, "mu": 0.0, "f_offset": 0.0, "w0": 0.0, "m_yield": np.inf}
    arrays = [np.asarray(eta, float), np.asarray(p, float)]
    arrays += [np.asarray(eff.get(k, neutral[k]), float) for k in _EFFECT_KEYS]
    arrays += [np.asarray(a, float) for a in extra]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    flat = [np.ascontiguousarray(np.broadcast_to(a, shape)).ravel() for a in arrays]
    P = {"eta": flat[0], "p": flat[1]}
    P.update(dict(zip(_EFFECT_KEYS, flat[2:9], strict=True)))
    P["shape"] = shape
    return P, flat[9:]


def _subset(P: dict, idx: NDArray) -> dict:
    return {k: (v[idx] if isinstance(v, np.ndarray) else v) for k, v in P.items()}


def _weighted(P: dict) -> bool:
    return bool(np.any(P["w0"] != 0.0))


# --------------------------------------------------------------------------- #
# Fixed-step 8th-order Runge-Kutta march
# --------------------------------------------------------------------------- #
# Dormand-Prince 8(5,3) tableau (Hairer, Norsett & Wanner, Solving ODEs I), 8th-order weights.
# Same coefficients as scipy.integrate.DOP853, used here with fixed steps.
_C = np.array(
    [
        0.0,
        0.05260015195876773,
        0.0789002279381516,
        0.1183503419072274,
        0.2816496580927726,
        0.3333333333333333,
        0.25,
        0.3076923076923077,
        0.6512820512820513,
        0.6,
        0.8571428571428571,
        1.0,
    ]
)
_B = np.array(
    [
        0.054293734116568765,
        0.0,
        0.0,
        0.0,
        0.0,
        4.450312892752409,
        1.8915178993145003,
        -5.801203960010585,
        0.3111643669578199,
        -0.1521609496625161,
        0.20136540080403034,
        0.04471061572777259,
    ]
)
_A = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [
            0.03709200011850479,
            0.0,
            0.0,
            0.17038392571223998,
            0.10726203044637328,
            -0.015319437748624402,
            0.008273789163814023,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
        ],
        [
            0.6241109587160757,
            0.0,
            0.0,
            -3.3608926294469414,
            -0.868219346841726,
            27.59209969944671,
            20.154067550477894,
            -43.48988418106996,
            0.0,
            0.0,
            0.0,
            0.0,
        ],
        [
            0.47766253643826434,
            0.0,
            0.0,
            -2.4881146199716677,
            -0.590290826836843,
            21.230051448181193,
            15.279233632882423,
            -33.28821096898486,
            -0.020331201708508627,
            0.0,
            0.0,
            0.0,
        ],
        [
            -0.9371424300859873,
            0.0,
            0.0,
            5.186372428844064,
            1.0914373489967295,
            -8.149787010746927,
            -18.52006565999696,
            22.739487099350505,
            2.4936055526796523,
            -3.0467644718982196,
            0.0,
            0.0,
        ],
        [
            2.273310147516538,
            0.0,
            0.0,
            -10.53449546673725,
            -2.0008720582248625,
            -17.9589318631188,
            27.94888452941996,
            -2.8589982771350235,
            -8.87285693353063,
            12.360567175794303,
            0.6433927460157636,
            0.0,
        ],
    ]
)


def _prepare(P: dict) -> dict:
    """Flags and derived arrays the right-hand side needs (computed once per march)."""
    P = dict(P)
    P["_p4"] = 4.0 * P["p"]
    P["_q"] = 2.0 * P["p"] + 1.0
    P["_weighted"] = bool(np.any(P["w0"] != 0.0))
    P["_friction"] = bool(np.any(P["mu"] != 0.0))
    P["_curved"] = bool(np.any(P["kappa0"] != 0.0))
    # One taper exponent for the whole batch (a force-displacement curve, a
    # height sweep): e(sigma) is then a scalar per stage.
    P["_p4_scalar"] = float(P["_p4"][0]) if P["_p4"].size and np.all(P["_p4"] == P["_p4"][0]) else None
    P["_plain"] = not (P["_weighted"] or P["_friction"] or P["_curved"])
    return P


def _rhs(sig, Y, af, P, out=None):
    """d/dsigma of the stacked state Y = (xi, zeta, phi, m), shape (4, B).

    ``af`` is the contact load factor a(sigma) * f (zero above the contact).
    """
    if out is None:
        out = np.empty_like(Y)
    p4 = P["_p4_scalar"]
    # At and past the tip (sigma >= 1: the last step's final stage, the short step of TIP_TOLERANCE) the stem
    # ends: no moment, no bending (e = inf). A tapered stiffness of _TINY there divided the stage's round-off
    # moment into a tip angle of 1e287 under self-weight.
    if p4 is not None and isinstance(sig, float):  # one taper exponent, one sigma (numpy floats are floats)
        e = (max((1.0 - sig) ** p4, _TINY) if p4 else 1.0) if sig < 1.0 else np.inf
        log1m = None
    else:
        log1m = np.log(np.maximum(1.0 - sig, _TINY))
        e = np.where(sig < 1.0, np.maximum(np.exp(P["_p4"] * log1m), _TINY), np.inf)
    np.sin(Y[2], out=out[0])
    np.cos(Y[2], out=out[1])
    np.divide(Y[3], e, out=out[2])
    if P["_curved"]:
        out[2] += P["kappa0"]
    if P["_friction"]:
        np.multiply(out[1] - P["mu"] * out[0], af, out=out[3])
        np.negative(out[3], out=out[3])
    else:
        np.multiply(out[1], -af, out=out[3])
    if P["_weighted"]:
        if log1m is None:
            log1m = np.log(max(1.0 - sig, _TINY))
        out[3] -= P["w0"] * np.exp(P["_q"] * log1m) / P["_q"] * out[0]
    return out


# Rows of the tableau without their zero tail: stage i combines the first i slopes.
_A_ROWS = [np.ascontiguousarray(_A[i, :i]) for i in range(12)]


@functools.lru_cache(maxsize=64)
def _stage_coefficients(h: float) -> tuple:
    """Per stage, the weights of (Y, k_0, ..., k_{i-1}) giving its state: (1, h a_i0, ..., h a_i,i-1);
    last, the weights (1, h b) of the step's result. One dot product per stage, for a fixed step size."""
    rows = [np.concatenate([[1.0], h * _A_ROWS[i]]) for i in range(12)]
    return tuple(rows) + (np.concatenate([[1.0], h * _B]),)


def _inverse_taper(sig: NDArray, P: dict) -> NDArray:
    """1 / e(sigma) at the stage positions ``sig``, (12,) or (12, B): the values :func:`_rhs` divides by
    (e floored at ``_TINY``, e = 1 when p = 0). (12,) with one taper exponent and one sigma, else (12, B)."""
    p4 = P["_p4_scalar"]
    if p4 is not None:
        if not p4:
            return np.ones(np.shape(sig))
        return 1.0 / np.maximum(np.maximum(1.0 - sig, 0.0) ** p4, _TINY)
    log1m = np.log(np.maximum(1.0 - sig, _TINY)).reshape(len(sig), -1)  # (12, 1) or (12, B)
    return 1.0 / np.maximum(np.exp(P["_p4"] * log1m), _TINY)


def _plain_slopes(Yi: NDArray, inv_e: NDArray | float, neg_af: NDArray, k: NDArray) -> None:
    """Slopes of a plain rod (no weight, friction or rest curvature) into ``k`` (4, B): four array calls."""
    np.sin(Yi[2], out=k[0])
    np.cos(Yi[2], out=k[1])
    np.multiply(Yi[3], inv_e, out=k[2])
    np.multiply(k[1], neg_af, out=k[3])


def _step_plain(Y, sig, h, f, P, active):
    """:func:`_step` for one step size and one sigma without weight, friction or rest curvature.

    The stage states are one dot product each against (Y, k_0, ...) and the taper is evaluated at all
    twelve stages at once: about half the array operations of the general path, which a small batch
    (a diagnosis, a force curve) spends its time on. Tests check the two agree.
    """
    B = Y.shape[1]
    neg_af = -(active * f)
    coef = _stage_coefficients(h)
    inv_e = _inverse_taper(sig + _C * h, P)
    K = np.zeros((13, 4, B))  # zeros: a skipped stage reads 0, not a previous call's stage (see _step_general)
    K[0] = Y
    K2 = K.reshape(13, 4 * B)
    buf = np.empty(4 * B)
    Yi = K[0]
    for i in range(12):
        if i:
            np.dot(coef[i], K2[: i + 1], out=buf)
            Yi = buf.reshape(4, B)
        _plain_slopes(Yi, inv_e[i], neg_af, K[i + 1])
    return np.dot(coef[12], K2).reshape(4, B)


def _step_plain_each(Y, sig, h, f, P, active):
    """:func:`_step` without weight, friction or rest curvature, with a step size and sigma per element
    (the partial steps that locate a contact): the taper at every stage and element in one evaluation."""
    B = Y.shape[1]
    neg_af = -(active * f)
    h = np.asarray(h, float)
    inv_e = _inverse_taper(np.asarray(sig, float) + _C[:, None] * h, P)  # (12, B) or (12, 1)
    K = np.zeros((12, 4, B))  # zeros: a skipped stage reads 0 (see _step_general)
    K2 = K.reshape(12, 4 * B)
    Yi = Y
    for i in range(12):
        if i:
            Yi = Y + h * (_A_ROWS[i] @ K2[:i]).reshape(4, B)
        _plain_slopes(Yi, inv_e[i], neg_af, K[i])
    return Y + h * (_B @ K2).reshape(4, B)


def _step_compiled(Y, sig, h, f, P, active):
    """:func:`_step_plain` (a plain rod) or :func:`_step_general` (any effect) in one compiled loop over the rods
    (:data:`bayesrod.physics._compiled.step`), the taper at the stages evaluated inside it as each does."""
    general = not P["_plain"]
    return _compiled.step(
        np.ascontiguousarray(Y, dtype=float),
        _flat(sig),
        _flat(h),
        _flat(f),
        _flat(active),
        _flat(P["_p4_scalar"] if P["_p4_scalar"] is not None else P["_p4"]),
        _flat(P["kappa0"]) if general and P["_curved"] else _ZERO,
        _flat(P["mu"]) if general and P["_friction"] else _ZERO,
        _flat(P["w0"]) if general and P["_weighted"] else _ZERO,
        _flat(P["_q"]) if general and P["_weighted"] else _ONE,
        general,
        _C,
        _A,
        _B,
    )


_ZERO, _ONE = np.zeros(1), np.ones(1)


def _flat(a) -> NDArray:
    """A scalar or array as a 1-d float array (one element, or one per rod), for the compiled step."""
    return np.asarray(a, dtype=float).reshape(-1)


def _step(Y, sig, h, f, P, active):
    """One explicit RK step (DOP853 tableau, 8th order) of size h (scalar or (B,)).

    The compiled loop when numba is there (:mod:`bayesrod.physics._compiled`), else the numpy paths it is tested
    against: a plain rod's, or the general one for any effect."""
    if _compiled.step is not None:
        return _step_compiled(Y, sig, h, f, P, active)
    if P.get("_plain"):
        if isinstance(h, float) and isinstance(sig, float):
            return _step_plain(Y, sig, h, f, P, active)
        return _step_plain_each(Y, sig, h, f, P, active)
    return _step_general(Y, sig, h, f, P, active)


def _step_general(Y, sig, h, f, P, active):
    """The reference path of :func:`_step`: any effects, per-element step sizes."""
    B = Y.shape[1]
    af = active * f
    # zeros, not empty: a stage skipped by mistake must read 0, not the last call's stage left in reused memory
    # (a mutant that skipped stage 1 passed every test with np.empty)
    K = np.zeros((12, 4, B))
    K2 = K.reshape(12, 4 * B)
    _rhs(sig, Y, af, P, K[0])
    if isinstance(h, float):  # one step size: the stages are dot products into one buffer
        Yf = np.ascontiguousarray(Y).reshape(4 * B)
        Yi = np.empty(4 * B)
        Y2 = Yi.reshape(4, B)
        for i in range(1, 12):
            np.dot(h * _A_ROWS[i], K2[:i], out=Yi)
            Yi += Yf
            _rhs(sig + _C[i] * h, Y2, af, P, K[i])
        out = np.dot(h * _B, K2)
        out += Yf
        return out.reshape(4, B)
    for i in range(1, 12):
        Yi = Y + h * (_A_ROWS[i] @ K2[:i]).reshape(4, B)
        _rhs(sig + _C[i] * h, Yi, af, P, K[i])
    return Y + h * (_B @ K2).reshape(4, B)


def _march(f, m0, phi0, P, n_steps, keep=False):
    """Integrate from the base; locate the contact; return contact and residual.

    Returns a dict of flat arrays: ``found`` (contact reached on the rod, below
    a horizontal tangent), ``sig_c``, ``xi_c``, ``phi_c``, ``resid`` (moment
    at the contact without weight, at the tip with weight: zero at
    equilibrium) and, with ``keep``, the grid states ``grid`` of shape
    (n_steps + 1, 3, B) holding xi, zeta, phi at sigma_k = k / n_steps.
    """
    P = _prepare(P)
    B = f.shape[0]
    h = 1.0 / n_steps
    Y = np.zeros((4, B))
    Y[2], Y[3] = phi0, m0
    active = np.ones(B)
    open_ = np.ones(B, bool)  # still below the contact and not lost
    out = {k: np.full(B, np.nan) for k in ("sig_c", "xi_c", "phi_c", "m_c")}
    grid = np.empty((n_steps + 1, 3, B)) if keep else None
    if keep:
        grid[0] = Y[:3]
    run_to_tip = keep or P["_weighted"]

    # Steps that close an element (contact crossed, or tangent past horizontal)
    # are recorded and resolved afterwards in one vectorised call, unless the
    # march must continue past the contact (shapes, self-weight).
    pend_Y = np.zeros((4, B))
    pend_sig = np.zeros(B)
    pend_h = np.zeros(B)
    pend = np.zeros(B, bool)
    bent_back = np.zeros(B, bool)

    def resolve(idx, Y0, sig0, h0):
        """Exact contact (or none) for elements whose step [sig0, sig0 + h0] closed them."""
        Pi = _subset(P, idx)
        fi = f[idx]
        y1 = _step(Y0, sig0, h0, fi, Pi, 1.0)
        dmax = np.array(h0, dtype=float, copy=True) * np.ones(idx.size)
        crossed = y1[1] >= Pi["eta"]
        over = ~crossed & ~bent_back[idx]
        if over.any():
            # zeta may peak above eta inside the step (phi passes pi/2): check the peak.
            io = np.flatnonzero(over)
            Po = _subset(Pi, io)
            hs = dmax[io]
            ypk, dpk = _locate(Y0[:, io], _at(sig0, io), fi[io], Po, 2, _HALF_PI, hs)
            peak = ypk[1] >= Po["eta"]
            crossed[io[peak]] = True
            dmax[io[peak]] = dpk[peak]
        ic = np.flatnonzero(crossed)
        if ic.size == 0:
            return ic, None, None
        Pc = _subset(Pi, ic)
        yc, dc = _locate(Y0[:, ic], _at(sig0, ic), fi[ic], Pc, 1, Pc["eta"], dmax[ic])
        j = idx[ic]
        out["sig_c"][j] = _at(sig0, ic) + dc
        out["xi_c"][j] = yc[0]
        out["phi_c"][j] = yc[2]
        out["m_c"][j] = yc[3]
        return ic, yc, dc

    def advance(Y, sig, step, sel=None, new=None):
        """One step of the elements ``sel`` (all: None) from their states ``Y`` (or its result ``new``, if taken
        already); close those it takes past the sensor height or past horizontal."""
        # every element (the march's steps: no copies) or those of ``sel`` (the last step's substeps)
        Pg, fg, ag, op = (P, f, active, open_) if sel is None else (_subset(P, sel), f[sel], active[sel], open_[sel])
        if new is None:
            new = _step(Y, sig, step, fg, Pg, ag)
        # bent back past horizontal (away from the push) below the sensor: no contact ahead (the tip of a tapered
        # stem then spins, and a contact it finds is not an equilibrium the reference holds)
        back = op & (new[2] <= -_HALF_PI) & (new[1] < Pg["eta"])
        bent_back[back if sel is None else sel[back]] = True
        closing = op & ((new[1] >= Pg["eta"]) | (new[2] >= _HALF_PI) | back)
        if closing.any():
            loc = np.flatnonzero(closing)
            idx = loc if sel is None else sel[loc]
            if run_to_tip:
                ic, yc, dc = resolve(idx, Y[:, loc], sig, step)
                if ic.size:
                    j = idx[ic]
                    if not P["_weighted"]:
                        yc = yc.copy()
                        yc[3] = 0.0  # no load above the contact: M = 0 exactly (round-off / e -> inf at the tip)
                    new[:, loc[ic]] = _step(yc, sig + dc, step - dc, f[j], _subset(P, j), 0.0)
            else:
                pend[idx] = True
                pend_Y[:, idx] = Y[:, loc]
                pend_sig[idx] = sig
                pend_h[idx] = step
            open_[idx] = False
            active[idx] = 0.0
        return new

    def last_step(Y):
        """The step into the tip, where e(sigma) -> 0. An element still open whose tangent this one step turns by
        more than :data:`TIP_CALM` takes it again in the substeps of :data:`TIP_SUBSTEPS`: one step across the tip
        can spin the tangent through hundreds of radians and jump over a contact early in the step (holes in a
        friction branch below its end, session 50)."""
        sig = 1.0 - h
        trial = _step(Y, sig, h, f, P, active)
        wild = open_ & ~(np.abs(trial[2] - Y[2]) <= TIP_CALM)  # NaN too
        if not wild.any():
            return advance(Y, sig, h, new=trial)
        new = Y.copy()
        rest = np.flatnonzero(~wild)
        if rest.size:
            new[:, rest] = advance(Y[:, rest], sig, h, rest, new=trial[:, rest])
        w = np.flatnonzero(wild)
        Yw = Y[:, w]
        edges = 1.0 - h * TIP_SUBSTEPS
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            Yw = advance(Yw, float(a), float(b - a), w)
            done = ~open_[w]
            if done.any():  # closed: the rest of the way to the tip unloaded, in one step
                j = w[done]
                new[:, j] = _step(Yw[:, done], float(b), 1.0 - float(b), f[j], _subset(P, j), 0.0)
                w, Yw = w[~done], Yw[:, ~done]
                if w.size == 0:
                    return new
        new[:, w] = Yw
        return new

    with np.errstate(all="ignore"):
        for k in range(n_steps):
            Y = last_step(Y) if k == n_steps - 1 else advance(Y, k * h, h)
            if keep:
                grid[k + 1] = Y[:3]
            if not run_to_tip and not open_.any():
                break
        if open_.any():
            # Contact within TIP_TOLERANCE * L of the tip still counts (the probe
            # and the tip have a finite size): one short step past sigma = 1.
            Y = advance(Y, 1.0, TIP_TOLERANCE)
        if pend.any():
            idx = np.flatnonzero(pend)
            resolve(idx, pend_Y[:, idx], pend_sig[idx], pend_h[idx])
    found = np.isfinite(out["sig_c"])
    resid = Y[3] if P["_weighted"] else out["m_c"]
    # without a contact: bent over (the tangent passed horizontal toward the push below the sensor, or the stem
    # ends leaning toward it; the base moment is too large) or back (too small), as the reference classifies
    bent_over = ~found & ~bent_back & (~open_ | (Y[2] > 0))
    out.update(found=found, resid=np.where(found, resid, np.nan), grid=grid, bent_over=bent_over)
    return out


def _at(a, idx):
    """``a[idx]`` for arrays, ``a`` for scalars."""
    return a[idx] if np.ndim(a) else a


def _locate(Y, sig, f, P, comp, target, dmax, iters=8):
    """Newton on the partial step length d in [0, dmax] so that Y[comp](sig + d) = target.

    The state component must be increasing over the step (zeta toward the
    sensor height, or phi toward horizontal).
    """
    y0 = Y[comp]
    y1 = _step(Y, sig, dmax, f, P, 1.0)[comp]
    d = np.clip(dmax * (target - y0) / np.where(y1 > y0, y1 - y0, 1.0), 0.0, dmax)
    for _ in range(iters):
        yd = _step(Y, sig, d, f, P, 1.0)
        miss = yd[comp] - target
        if np.all(np.abs(miss) <= 1e-15 * np.maximum(np.abs(target), 1.0)):  # converged: yd is the answer
            return yd, d
        slope = _rhs(sig + d, yd, f, P)[comp]
        d = np.clip(d - miss / np.maximum(slope, 1e-6), 0.0, dmax)
    return _step(Y, sig, d, f, P, 1.0), d


# --------------------------------------------------------------------------- #
# Vectorised scalar root finding (Illinois regula falsi) and bracketing
# --------------------------------------------------------------------------- #
def _too_far(g: NDArray) -> NDArray:
    """Residuals with NaN (beyond the branch's end) counted as "too far" (+inf)."""
    return np.where(np.isnan(g), np.inf, g)


def _illinois(fun, lo, hi, glo, ghi, xtol=1e-13, maxiter=80):
    """Roots of increasing ``fun`` on brackets with glo < 0 <= ghi (elementwise).

    While at most ``NEWTON_BATCH`` elements remain, each round evaluates two points per element in one
    call: the candidate and a point 1e-7 (relative) beyond it. Both narrow the bracket; their
    difference quotient gives a Newton step, the next candidate when it falls inside the bracket
    (otherwise the Illinois regula falsi point of the bracket). Newton needs fewer rounds than regula
    falsi, and for small batches a round costs about the same for twice the problems; large batches
    (where the march's cost grows with the batch) take the plain Illinois rounds.
    """
    lo, hi, glo, ghi = (np.array(a, float) for a in (lo, hi, glo, ghi))
    x = hi.copy()
    # a root at the bracket's end is the answer (the regula falsi point would sit on the end, and bisection
    # would walk towards it for some 40 rounds)
    todo = ghi != 0.0
    side = np.zeros(lo.shape, int)
    newton = np.full(lo.shape, np.nan)  # the Newton candidate of the last round (NaN: none)
    for _ in range(maxiter):
        if not todo.any():
            break
        i = np.flatnonzero(todo)
        denom = ghi[i] - glo[i]
        xs = np.where(
            denom > 0, hi[i] - ghi[i] * (hi[i] - lo[i]) / np.where(denom > 0, denom, 1), 0.5 * (lo[i] + hi[i])
        )
        xn = newton[i]
        use_n = (xn > lo[i]) & (xn < hi[i])
        xs = np.where(use_n, xn, xs)
        bad = ~((xs > lo[i]) & (xs < hi[i]))
        xs[bad] = 0.5 * (lo[i] + hi[i])[bad]
        if i.size <= NEWTON_BATCH:  # probe 1e-7 beyond the candidate: a Newton step for the next round
            x2 = np.minimum(xs + 1e-7 * np.maximum(np.abs(xs), 1e-300), hi[i])
            both = _too_far(fun(np.concatenate([xs, x2]), np.concatenate([i, i])))
            g, g2 = both[: i.size], both[i.size :]
            with np.errstate(invalid="ignore"):  # inf - inf past a branch end: no Newton step there
                slope = (g2 - g) / np.where(x2 > xs, x2 - xs, 1.0)
            ok = np.isfinite(g2) & np.isfinite(g) & (slope > 0) & (x2 > xs)
            newton[i] = np.where(ok, xs - g / np.where(ok, slope, 1.0), np.nan)
            points = ((xs, g), (x2, g2))
        else:
            g = _too_far(fun(xs, i))
            points = ((xs, g),)
        x[i] = xs
        for xv, gv in points:  # each point inside the bracket narrows it
            up = gv >= 0
            ju, jd = i[up], i[~up]
            keep_u = xv[up] < hi[ju]
            ju, xu, gu = ju[keep_u], xv[up][keep_u], gv[up][keep_u]
            # Illinois: halve the retained end's value when the same side repeats.
            glo[ju] = np.where(side[ju] == 1, 0.5 * glo[ju], glo[ju])
            hi[ju], ghi[ju] = xu, np.minimum(gu, 1e300)
            side[ju] = 1
            keep_d = xv[~up] > lo[jd]
            jd, xd, gd = jd[keep_d], xv[~up][keep_d], gv[~up][keep_d]
            ghi[jd] = np.where(side[jd] == -1, 0.5 * ghi[jd], ghi[jd])
            lo[jd], glo[jd] = xd, gd
            side[jd] = -1
        done = (np.abs(g) <= 1e-14) | (hi[i] - lo[i] <= xtol * np.maximum(1.0, np.abs(hi[i])))
        todo[i[done]] = False
    return x


# Points per round of :func:`_bracket_and_solve`: growth steps of the bracket expansion, and
# interior points of the boundary search (1 and 1: the plain expansion and bisection).
EXPAND_POINTS = 4
BOUNDARY_SECTIONS = 7
# Root-search rounds take a Newton probe while at most this many problems remain (see _illinois).
NEWTON_BATCH = 512


def _bracket_and_solve(fun, x_guess, x_max=np.inf, grow=1.6, max_expand=80, boundary_rtol=4e-16):
    """Solve fun(x) = 0 for x >= 0 where fun(0) < 0, fun increasing, NaN past a branch end.

    Returns ``(x, ok)``; ``ok`` is False where the branch ends (fun becomes NaN)
    before fun reaches 0, i.e. the stem slips first.
    """
    B = x_guess.shape[0]
    lo = np.zeros(B)
    glo = fun(lo, np.arange(B))
    hi = np.maximum(x_guess, 1e-12)
    ghi = np.full(B, np.nan)
    state = np.zeros(B, int)  # 0 expanding, 1 bracketed, 2 boundary search, 3 no root

    def advance(i, pts):
        """Evaluate the rows of increasing points ``pts`` (n, m) of elements ``i``; move ``lo`` up to
        the last point below the first that stops (reaches 0: bracketed; NaN: branch end); return
        the first stopping index per row (m: none stopped) and whether that point is past the end."""
        n, m = pts.shape
        g = fun(pts.ravel(), np.repeat(i, m)).reshape(n, m)
        stop = np.isnan(g) | (g >= 0)  # fun rises until it reaches 0 or the branch ends
        first = np.where(stop.any(axis=1), np.argmax(stop, axis=1), m)
        rows = np.arange(n)
        below = first > 0
        lo[i[below]], glo[i[below]] = pts[rows, first - 1][below], g[rows, first - 1][below]
        at = np.minimum(first, m - 1)
        x_stop, g_stop = pts[rows, at], g[rows, at]
        hit = (first < m) & ~np.isnan(g_stop)
        state[i[hit]] = 1
        hi[i[hit]], ghi[i[hit]] = x_stop[hit], g_stop[hit]
        end = (first < m) & np.isnan(g_stop)
        hi[i[end]] = x_stop[end]
        return first, end

    # Every round tries several points of each element at once (one march costs about the same for 1
    # or 100 problems, so rounds are what count). Expansion: EXPAND_POINTS successive growths.
    powers = grow ** np.arange(EXPAND_POINTS)
    for _ in range(max_expand):
        i = np.flatnonzero(state == 0)
        if i.size == 0:
            break
        pts = np.minimum(hi[i, None] * powers, x_max)
        first, end = advance(i, pts)
        state[i[end]] = 2
        none = first == EXPAND_POINTS
        hi[i[none]] = np.minimum(pts[none, -1] * grow, x_max)
        state[i[none & (lo[i] >= x_max)]] = 3
    state[state == 0] = 3
    # Boundary search: BOUNDARY_SECTIONS evenly spaced points per bracket and round, so the bracket
    # shrinks (BOUNDARY_SECTIONS + 1)x per round, to the tolerance of plain bisection. Taking the
    # first point that stops also keeps the loading branch where the force-displacement curve folds.
    frac = np.arange(1, BOUNDARY_SECTIONS + 1) / (BOUNDARY_SECTIONS + 1.0)
    for _ in range(56):  # 56 halvings reach 2e-16 relative; each round here is at least 3 of them
        i = np.flatnonzero(state == 2)
        if i.size == 0:
            break
        advance(i, lo[i, None] + (hi[i] - lo[i])[:, None] * frac)
        narrow = (hi[i] - lo[i]) <= boundary_rtol * hi[i]
        state[i[narrow & (state[i] == 2)]] = 3
    x = np.full(B, np.nan)
    b = np.flatnonzero(state == 1)
    if b.size:
        x[b] = _illinois(lambda xs, j: fun(xs, b[j]), lo[b], hi[b], glo[b], ghi[b])
    return x, state == 1


# --------------------------------------------------------------------------- #
# Force -> contact (direction a)
# --------------------------------------------------------------------------- #
def _equilibrium(f, phi_p, P, n_steps, keep=False):
    """Solve the base moment for given force and plastic base rotation."""
    m0 = f * P["eta"]
    phi0 = P["tilt"] + phi_p + P["c_base"] * m0
    sol = _march(f, m0, phi0, P, n_steps, keep)
    need = np.any(P["mu"] != 0.0) or _weighted(P)
    if not need:
        sol["m0"] = m0
        return sol
    return _balance_base_moment(f, P["tilt"] + phi_p, P, n_steps, keep, m0, sol)


#: most rounds of :func:`_balance_base_moment` (secant steps, or sections of the bracket where they fail)
BALANCE_ITERATIONS = 60
#: points per round where :func:`_balance_base_moment` sections its bracket (it shrinks 16x per round) ...
BALANCE_SECTIONS = 15
#: ... while at most this many elements are open (more: one point, bisection: a march's cost grows with its batch)
BALANCE_FEW = 256
#: a root of :func:`_balance_base_moment` too steep for round-off: the largest change of the residual across a bracket
#: closed to round-off (relative to 1 + |m0|) and the largest move of the contact (sigma) between its ends
STEEP_ROOT_JUMP = 1e-4
STEEP_ROOT_MOVE = 1e-3
#: points of :func:`_balance_base_moment`'s first scan for a moment that reaches the sensor (4x in the second)
BALANCE_SCAN = 15


def _balance_base_moment(f, phi_fixed, P, n_steps, keep, m, sol):
    """The base moment m0 at which the residual of :func:`_march` vanishes (friction, self-weight).

    The residual rises with m0 (unit slope to leading order). A march that does not reach the sensor is classed as
    the reference solver classes it: bent over (its tangent passed horizontal toward the push below the sensor, or
    the stem ends leaning toward it: too much moment) or bent back (it passed horizontal away from the push first:
    too little; a contact its spinning tip finds after that is none, session 46). Such a march moves the bracket by
    its class only outside the moments that found a contact (the class can flip in islands next to a root near
    the tip). Where no march has bracketed the root yet, the element first scans its range (``BALANCE_SCAN``
    points from 0 to twice the first guess, then ``4 BALANCE_SCAN`` over a wider range) in one march. With a
    bracket, each round takes a secant step from the last two contacts where it falls inside, else the regula
    falsi point of the bracket where both its ends reach the sensor; otherwise (or where the last step halved
    neither the bracket nor the residual: near the bend the residual turns like a square root; or where the last
    round left the bracket as it was) ``BALANCE_SECTIONS`` evenly spaced points of the bracket in one march (it
    costs about as much as one point while at most ``BALANCE_FEW`` elements are open; with more, one point:
    bisection), and with one end known a point beyond it. A root is a residual under 1e-12, or under 1e-9 in a
    bracket closed to round-off between two contacts (next to the bend the residual rises by up to 1e5 per unit
    moment). A bracket closes without a root at round-off, at 1e-8 where the residual below stays under -0.05, at
    1e-10 between a stem bent back and one bent over, or where two rounds in a row left it as it was (the residual
    jumps there: the contact leaving the tip). Elements whose bracket closes without a root, that find no bracket
    in their scans, or that do not converge, are returned not ``found``. Only the elements still open are marched
    again (docs/model.md, "Friction and weight: the base moment").
    """
    B = f.shape[0]
    m = np.array(m, float)
    r = np.array(sol["resid"], float)
    lo, hi = np.full(B, -np.inf), np.full(B, np.inf)
    r_lo, r_hi = np.full(B, np.nan), np.full(B, np.nan)  # the residuals at the bracket's ends (NaN: no contact)
    s_lo, s_hi = np.full(B, np.nan), np.full(B, np.nan)  # and their contacts' sigma
    least, most = np.full(B, np.inf), np.full(B, -np.inf)  # the least and largest moments that found a contact
    m_prev, r_prev = np.full(B, np.nan), np.full(B, np.nan)
    last_width = np.full(B, np.inf)
    still = np.zeros(B, int)  # rounds in a row that did not move the bracket
    scans = np.zeros(B, int)
    guess = m.copy()
    u_first, u_wide = (np.arange(1, n + 1) / (n + 1.0) for n in (BALANCE_SCAN, 4 * BALANCE_SCAN))

    def balanced(m, r):
        """The residual vanishes to 1e-12; or to 1e-9 where the bracket has closed to round-off between two
        moments that reach the sensor (next to the bend the residual rises by up to 1e5 per unit moment, and 1e-12
        is below its round-off; a jump of the residual, where the contact moves along the rod, leaves |r| large).
        Where the branch nears its end the residual may rise faster still (3e-8 per ulp of the moment at eta 0.45,
        p 0.55, mu 0.2, f 13.95: no moment leaves it under 1e-9): a bracket closed to round-off whose ends' residuals
        change sign continuously (by at most ``STEEP_ROOT_JUMP`` (1 + |m|), their contacts at most ``STEEP_ROOT_MOVE``
        apart) holds the root at its better end (a point no farther from zero than half the change; session 50: such
        roots, which the reference's ODE confirms, were holes in the branch)."""
        tight = (hi - lo <= 1e-14 * (1.0 + np.abs(hi))) & np.isfinite(r_lo) & np.isfinite(r_hi)
        tol = np.where(tight, 1e-9, 1e-12) * (1.0 + np.abs(m))
        with np.errstate(invalid="ignore"):
            steep = (
                tight
                & (r_lo < 0.0)
                & (r_hi >= 0.0)
                & (r_hi - r_lo <= STEEP_ROOT_JUMP * (1.0 + np.abs(m)))
                & (np.abs(s_hi - s_lo) <= STEEP_ROOT_MOVE)
                & (np.abs(r) <= 0.5 * (r_hi - r_lo))
            )
        return np.isfinite(r) & ((np.abs(r) <= tol) | steep)

    def narrow(e, mv, rv, over, sv):
        """Move the brackets of elements ``e`` with the marches at ``mv`` (residuals ``rv``, NaN: no contact;
        ``over``: a march without contact bent over toward the push, else back). A march without contact counts
        by its class only outside the moments that found one (near the tip the class flips in islands: a stem bent
        back 1e-6 above a root at eta 0.5625, p 0.4, mu 0.42, f 18.39); the upper end moves first and the lower
        only below it, so the bracket never inverts."""
        fin = np.isfinite(rv)
        np.minimum.at(least, e[fin], mv[fin])
        np.maximum.at(most, e[fin], mv[fin])
        above = np.where(fin, rv >= 0, over & (mv > most[e])) & (mv > lo[e])
        np.minimum.at(hi, e[above], mv[above])
        below = np.where(fin, rv < 0, ~over & (mv < least[e])) & (mv < hi[e])
        np.maximum.at(lo, e[below], mv[below])
        at_lo = below & (mv == lo[e])
        r_lo[e[at_lo]], s_lo[e[at_lo]] = rv[at_lo], sv[at_lo]
        at_hi = above & (mv == hi[e])
        r_hi[e[at_hi]], s_hi[e[at_hi]] = rv[at_hi], sv[at_hi]

    narrow(np.arange(B), m, r, sol["bent_over"], sol["sig_c"])
    best_m, best_r = m.copy(), r.copy()  # each element's moment of least |residual| so far
    for _ in range(BALANCE_ITERATIONS):
        finite = np.isfinite(r)
        conv = balanced(m, r)
        width = hi - lo
        # closed without a root: to round-off, or to 1e-8 where the residual below stays under -0.05 (near the
        # bend it rises like a sqrt(distance), a ~ 10 at eta 0.5, p 0.5, mu 0.2: by about 1e-3 over the last 1e-8)
        tight = width <= 1e-14 * (1.0 + np.abs(hi))
        far_below = (width <= 1e-8 * (1.0 + np.abs(hi))) & (r_lo <= -0.05 * (1.0 + np.abs(lo)))
        # or to 1e-10 between a stem bent back and one bent over, neither reaching the sensor: no contact between
        far_below |= (width <= 1e-10 * (1.0 + np.abs(hi))) & np.isnan(r_lo) & np.isnan(r_hi)
        # or where two rounds in a row found no contact inside a bracket between two contacts: there the
        # residual jumps over moments that miss the sensor (the contact leaving the tip), with no root in the gap
        still = np.where(width == last_width, still + 1, 0)
        bracketed = np.isfinite(lo) & np.isfinite(hi)
        closed = bracketed & (tight | far_below | (still >= 2))
        lost = ~np.isfinite(most) & (scans >= 2) & ~bracketed  # no moment reaches the sensor
        open_ = ~(conv | closed | lost)
        if not open_.any():
            break
        pair = finite & np.isfinite(r_prev) & (m != m_prev)
        slope = np.where(pair, (r - r_prev) / np.where(pair, m - m_prev, 1.0), 1.0)
        slope = np.where(np.isfinite(slope) & (slope > 0.05), slope, 1.0)
        step = m - r / slope
        inside = np.isfinite(step) & (step > lo) & (step < hi)
        # no secant step inside: the regula falsi point of a bracket whose ends both reach the sensor
        with np.errstate(invalid="ignore", divide="ignore"):
            falsi = lo - r_lo * (hi - lo) / (r_hi - r_lo)
        use_falsi = ~inside & np.isfinite(falsi) & (falsi > lo) & (falsi < hi)
        step, inside = np.where(use_falsi, falsi, step), inside | use_falsi
        with np.errstate(invalid="ignore"):  # inf - inf where an end is still open: not taken
            towards_zero = np.where(hi > 0, 0.5 * hi, hi - 1.0 - np.abs(hi))
            beyond = np.where(np.isfinite(lo), lo + 1.0 + np.abs(lo), towards_zero)
        # a step that halved neither the bracket nor the residual is followed by sections
        slow = ~(width <= 0.5 * last_width) & ~(np.abs(r) <= 0.5 * np.abs(r_prev))
        last_width = width
        m_prev, r_prev = np.where(finite, m, m_prev), np.where(finite, r, r_prev)
        i = np.flatnonzero(open_)
        blind = ~np.isfinite(most[i]) & ~bracketed[i]  # one side only, and no contact: scan
        scan = i[blind]
        seen = i[~blind]
        sections = bracketed[seen] & (~inside[seen] | slow[seen])
        one, many = seen[~sections], seen[sections]
        # a march costs about the same for 1 or 100 elements but grows with more: many open, plain bisection (the
        # midpoint as a step); but sections where the last round left the bracket as it was (its point a march
        # without contact inside the moments that found one, which a bisection would repeat)
        bisect = (i.size > BALANCE_FEW) & (still[many] == 0)
        many, halved = many[~bisect], many[bisect]
        one = np.concatenate([one, halved])
        inside[halved], step[halved] = True, 0.5 * (lo[halved] + hi[halved])
        n_sec = BALANCE_SECTIONS
        frac = np.arange(1, n_sec + 1) / (n_sec + 1.0)
        g = np.abs(guess[scan])[:, None]
        first = scans[scan] == 0
        pts_first = 2.0 * g[first] * u_first  # (0, 2 |guess|): friction and weight move the root from f eta
        pts_wide = -(g[~first] + 1.0) + (4.0 * g[~first] + 2.0) * u_wide  # (-|g| - 1, 3 |g| + 1)
        scan_first, scan_wide = scan[first], scan[~first]
        scans[scan] += 1
        e = np.concatenate(
            [
                one,
                np.repeat(many, n_sec),
                np.repeat(scan_first, BALANCE_SCAN),
                np.repeat(scan_wide, 4 * BALANCE_SCAN),
            ]
        )
        mv = np.concatenate(
            [
                np.where(inside, step, beyond)[one],
                (lo[many, None] + (hi - lo)[many, None] * frac).ravel(),
                pts_first.ravel(),
                pts_wide.ravel(),
            ]
        )
        s = _march(f[e], mv, phi_fixed[e] + P["c_base"][e] * mv, _subset(P, e), n_steps, keep)
        narrow(e, mv, s["resid"], s["bent_over"], s["sig_c"])
        # each element's new point: its march of smallest |residual| (one without contact if none found one)
        score = np.where(np.isfinite(s["resid"]), np.abs(s["resid"]), np.inf)
        order = np.lexsort((score, e))
        pick = order[np.concatenate([[True], e[order][1:] != e[order][:-1]])]
        j = e[pick]
        m[j] = mv[pick]
        for k in ("found", "sig_c", "xi_c", "phi_c", "m_c", "resid"):
            sol[k][j] = s[k][pick]
        if keep:
            sol["grid"][..., j] = s["grid"][..., pick]
        r[j] = s["resid"][pick]
        better = np.isfinite(r[j]) & ~(np.abs(best_r[j]) <= np.abs(r[j]))
        best_m[j[better]], best_r[j[better]] = m[j[better]], r[j[better]]
    # the sections after a root to round-off may end on a worse point of the same bracket: take the best one
    back = ~balanced(m, r) & balanced(best_m, best_r)
    if back.any():
        e = np.flatnonzero(back)
        s = _march(f[e], best_m[e], phi_fixed[e] + P["c_base"][e] * best_m[e], _subset(P, e), n_steps, keep)
        m[e], r[e] = best_m[e], s["resid"]
        for k in ("found", "sig_c", "xi_c", "phi_c", "m_c", "resid"):
            sol[k][e] = s[k]
        if keep:
            sol["grid"][..., e] = s["grid"]
    found = sol["found"] & balanced(m, r)
    for k in ("sig_c", "xi_c", "phi_c", "m_c", "resid"):
        sol[k] = np.where(found, sol[k], np.nan)
    sol["found"] = found
    sol["m0"] = m
    return sol


def contact_from_force_nd(
    f: ArrayLike,
    eta: ArrayLike,
    p: ArrayLike,
    effects_nd: dict | None = None,
    *,
    n_steps: int = DEFAULT_STEPS,
    keep_shape: bool = False,
) -> dict:
    """Nondimensional direction (a): force to contact point (and shape).

    Parameters
    ----------
    f : array_like
        F L^2 / EI0, broadcast with ``eta``, ``p`` and the effect groups.
    eta : array_like
        h / L, in (0, 1).
    p : array_like
        Taper exponent, EI(s) = EI0 (1 - s/L)^(4p) (eq. EI_taper).
    effects_nd : dict, optional
        Nondimensional effect groups from :meth:`Effects.nondim`.

    Returns
    -------
    dict
        ``found``, ``sig_c`` (s_c/L), ``xi_c`` (x_c/L), ``phi_c`` (tangent angle
        from vertical at the contact, rad), ``m0`` (base moment, M L/EI0) and
        with ``keep_shape`` the grid (n_steps + 1, 3, ...) of xi, zeta, phi.
        Each array has the broadcast shape. ``yielded`` marks forces the base
        cannot carry (effect ``yield``).
    """
    P, (f_,) = _problem(eta, p, effects_nd, f)
    sol = _equilibrium(f_, np.zeros_like(f_), P, n_steps, keep_shape)
    yielded = sol["m0"] > P["m_yield"]
    res = _reshape(sol, P["shape"])
    res["yielded"] = yielded.reshape(P["shape"])
    return res


def _reshape(sol: dict, shape) -> dict:
    out = {}
    for k in ("found", "sig_c", "xi_c", "phi_c", "m0"):
        out[k] = sol[k].reshape(shape)
    if sol.get("grid") is not None:
        g = sol["grid"]
        out["grid"] = g.reshape(g.shape[:2] + tuple(shape))
    return out


# --------------------------------------------------------------------------- #
# Displacement -> force (direction b, the shooting problem the data poses)
# --------------------------------------------------------------------------- #
def force_from_displacement_nd(
    d: ArrayLike,
    eta: ArrayLike,
    p: ArrayLike,
    effects_nd: dict | None = None,
    *,
    n_steps: int = DEFAULT_STEPS,
    keep_shape: bool = False,
) -> dict:
    """Nondimensional direction (b): contact displacement since first contact to force.

    Follows the loading branch continuously from first contact (d = 0). Where
    the requested displacement lies beyond the branch's end (the stem slips
    past the sensor: contact passes the tip, the stem bends over below the
    sensor, or the force-displacement curve turns), ``slipped`` is True and
    the force is NaN. With a base yield moment, loading beyond yield follows
    the plastic branch (base moment held at the yield moment).

    Returns
    -------
    dict
        ``f`` (true force, F L^2/EI0), ``f_measured`` (plus sensor offset),
        ``sig_c``, ``xi_c``, ``phi_c``, ``m0``, ``phi_plastic``, ``slipped``,
        ``yielded``; with ``keep_shape`` also ``grid``. Arrays have the
        broadcast shape of the inputs.
    """
    P, (d_,) = _problem(eta, p, effects_nd, d)
    B = d_.shape[0]
    zeros = np.zeros(B)
    ref = _equilibrium(zeros, zeros, P, n_steps)
    if not np.all(ref["found"]):
        bad = np.flatnonzero(~ref["found"])[0]
        raise ValueError(
            "height_m: expected a height the unloaded stem reaches, got h/L = "
            f"{P['eta'][bad]:.4g} which its rest shape never crosses"
        )
    target = ref["xi_c"] + d_

    # Only displacements past first contact are solved: at d <= 0 the force is zero, and a root at the
    # bracket's end (g(0) = 0) would cost the root finder many rounds for nothing.
    moved = np.flatnonzero(d_ > 0)

    def g_elastic(f, i):
        j = moved[i]
        s = _equilibrium(f, zeros[j], _subset(P, j), n_steps)
        return np.where(s["found"], s["xi_c"] - target[j], np.nan)

    f_sol, ok = np.zeros(B), np.ones(B, bool)
    if moved.size:
        f_guess = d_[moved] * _linear_kx_nd(_subset(P, moved))
        # the slip boundary to 1e-10 (relative, in force), not to round-off: only a displacement within
        # about that of the branch's end can be classed differently, and the search costs a round per 8x
        f_sol[moved], ok[moved] = _bracket_and_solve(g_elastic, f_guess, boundary_rtol=1e-10)
    phi_p = np.zeros(B)
    sol = _equilibrium(np.nan_to_num(f_sol), phi_p, P, n_steps, keep_shape)
    yielded = ok & (sol["m0"] > P["m_yield"])
    if yielded.any():
        iy = np.flatnonzero(yielded)
        f_y, phi_y, ok_y = _plastic_branch(P, iy, target, n_steps)
        f_sol[iy], phi_p[iy], ok[iy] = f_y, phi_y, ok_y
        sol = _equilibrium(np.nan_to_num(f_sol), phi_p, P, n_steps, keep_shape)
    slipped = ~ok | ~sol["found"]
    f_sol = np.where(slipped, np.nan, f_sol)
    out = {
        "f": f_sol,
        "f_measured": f_sol + P["f_offset"],
        "sig_c": np.where(slipped, np.nan, sol["sig_c"]),
        "xi_c": np.where(slipped, np.nan, sol["xi_c"]),
        "phi_c": np.where(slipped, np.nan, sol["phi_c"]),
        "m0": np.where(slipped, np.nan, sol["m0"]),
        "phi_plastic": phi_p,
        "slipped": slipped,
        "yielded": yielded & ~slipped,
        "xi_c0": ref["xi_c"],
    }
    res = {k: v.reshape(P["shape"]) for k, v in out.items()}
    if keep_shape:
        res["grid"] = sol["grid"].reshape(sol["grid"].shape[:2] + tuple(P["shape"]))
    return res


def _plastic_branch(P, iy, target, n_steps):
    """Beyond yield: base moment held at m_yield; solve plastic rotation for the target."""
    Py = _subset(P, iy)
    tgt = target[iy]
    my = Py["m_yield"]

    simple = not (np.any(Py["mu"] != 0.0) or np.any(Py["w0"] != 0.0))

    def f_for_phi(phi_p, j):
        # Force at which the base moment equals the yield moment (m0 increasing in f).
        Pj = _subset(Py, j)
        if simple:  # m0 = f eta exactly (eq. M_determinate at s = 0)
            return my[j] / Pj["eta"]

        def g(fv, k):
            s = _equilibrium(fv, phi_p[k], _subset(Pj, k), n_steps)
            return np.where(s["found"], s["m0"] - my[j][k], np.nan)

        fv, okv = _bracket_and_solve(g, my[j] / Pj["eta"])
        return np.where(okv, fv, np.nan)

    def g_phi(phi_p, j):
        fv = f_for_phi(phi_p, j)
        s = _equilibrium(np.nan_to_num(fv), phi_p, _subset(Py, j), n_steps)
        return np.where(np.isfinite(fv) & s["found"], s["xi_c"] - tgt[j], np.nan)

    phi, ok = _bracket_and_solve(g_phi, np.full(iy.size, 0.05), x_max=_HALF_PI)
    return f_for_phi(np.nan_to_num(phi), np.arange(iy.size)), phi, ok


def _linear_kx_nd(P):
    """Small-deflection k_x L^3/EI0 (with base compliance), for initial guesses."""
    c = P["c_base"]
    kx = kx_nd(P["eta"], P["p"])
    return 1.0 / (1.0 / kx + c * P["eta"] ** 2)


# --------------------------------------------------------------------------- #
# Dimensional wrappers
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class ContactSolution:
    """Elastica at given forces (arrays share the broadcast shape).

    Attributes
    ----------
    force_N : true contact force [N]
    contact_s_m : arc length of the contact s_c [m]
    contact_x_m : horizontal position of the contact x_c [m]
    contact_angle_rad : tangent angle from vertical at the contact [rad]
    base_moment_Nm : moment at the base [N m]; NaN where not ``found``
    found : contact exists (stem reaches the sensor height) and the base holds it (below yield)
    shape_xz_m : optional centerline grid, shape (n_steps + 1, 2, ...), in m; NaN where not ``found``
    """

    force_N: NDArray
    contact_s_m: NDArray
    contact_x_m: NDArray
    contact_angle_rad: NDArray
    base_moment_Nm: NDArray
    found: NDArray
    shape_xz_m: NDArray | None = None


@dataclass(frozen=True)
class ForceSolution:
    """Force at given contact displacements (arrays share the broadcast shape).

    Attributes
    ----------
    displacement_m : horizontal contact displacement since first contact [m]
    force_N : force the sensor reads (true force plus ``force_offset``) [N];
        NaN where slipped
    true_force_N : force on the stem [N]
    contact_s_m : arc length of the contact [m]
    contact_angle_rad : tangent angle from vertical at the contact [rad]
    slipped : True where the stem can no longer hold contact
    yielded : True where the base is on its plastic branch
    shape_xz_m : optional centerline grid (n_steps + 1, 2, ...) [m]
    """

    displacement_m: NDArray
    force_N: NDArray
    true_force_N: NDArray
    contact_s_m: NDArray
    contact_angle_rad: NDArray
    slipped: NDArray
    yielded: NDArray
    shape_xz_m: NDArray | None = None


def check_rod(
    EI0: ArrayLike, p: ArrayLike, length: float, height: ArrayLike
) -> tuple[NDArray, NDArray, float, NDArray]:
    """Validate rod parameters; raise ValueError naming the field and value."""
    EI0 = np.asarray(EI0, float)
    p = np.asarray(p, float)
    h = np.asarray(height, float)
    L = float(length)
    if not np.isfinite(L) or L <= 0:
        raise ValueError(f"length_m: expected a length > 0 m, got {length}")
    if not np.all(np.isfinite(EI0) & (EI0 > 0)):
        raise ValueError(f"EI0: expected a flexural rigidity > 0 N m^2, got {EI0.ravel()[~(EI0.ravel() > 0)][:1]}")
    if not np.all(np.isfinite(p) & (p >= 0)):
        raise ValueError(f"p: expected a taper exponent >= 0, got {p.ravel()[~(p.ravel() >= 0)][:1]}")
    bad = ~(np.isfinite(h) & (h > 0) & (h < L))
    if np.any(bad):
        raise ValueError(f"height_m: expected 0 < height < length ({L:g} m), got {h.ravel()[bad.ravel()][0]:g}")
    return EI0, p, L, h


def contact_from_force(
    force_N: ArrayLike,
    height_m: ArrayLike,
    EI0: ArrayLike,
    p: ArrayLike,
    length_m: float,
    effects: Effects | None = None,
    *,
    n_steps: int = DEFAULT_STEPS,
    keep_shape: bool = False,
) -> ContactSolution:
    """Direction (a) in SI units: true contact force to contact point and shape.

    All array arguments broadcast together (batched over a leading axis).
    """
    EI0, p, L, h = check_rod(EI0, p, length_m, height_m)
    F = np.asarray(force_N, float)
    eff = (effects or Effects()).nondim(L, EI0)
    res = contact_from_force_nd(F * L**2 / EI0, h / L, p, eff, n_steps=n_steps, keep_shape=keep_shape)
    scale = np.broadcast_to(EI0 / L, res["m0"].shape)
    found = res["found"] & ~res["yielded"]
    return ContactSolution(
        force_N=np.broadcast_to(F, res["m0"].shape).astype(float),
        contact_s_m=res["sig_c"] * L,
        contact_x_m=res["xi_c"] * L,
        contact_angle_rad=res["phi_c"],
        # NaN without an equilibrium, like the contact: with friction or weight m0 is then the search's last try
        base_moment_Nm=np.where(found, res["m0"] * scale, np.nan),
        found=found,
        # NaN without an equilibrium too: the grid is then the search's last march (with friction or weight a
        # shape that balances nothing; past yield the elastic one the base cannot hold)
        shape_xz_m=np.where(found, res["grid"][:, :2] * L, np.nan) if keep_shape else None,
    )


def force_from_displacement(
    displacement_m: ArrayLike,
    height_m: ArrayLike,
    EI0: ArrayLike,
    p: ArrayLike,
    length_m: float,
    effects: Effects | None = None,
    *,
    n_steps: int = DEFAULT_STEPS,
    keep_shape: bool = False,
) -> ForceSolution:
    """Direction (b) in SI units: contact displacement since first contact to force.

    Parameters
    ----------
    displacement_m : array_like
        Horizontal displacement of the contact point since first contact [m].
    height_m : array_like
        Sensor height h [m], 0 < h < L.
    EI0 : array_like
        Base flexural rigidity [N m^2].
    p : array_like
        Taper exponent (eq. EI_taper).
    length_m : float
        Stem length L [m].
    effects : Effects, optional
        Model effects (SI).

    Returns
    -------
    ForceSolution
        Arrays of the broadcast shape; ``force_N`` is NaN where ``slipped``.
    """
    EI0, p, L, h = check_rod(EI0, p, length_m, height_m)
    D = np.asarray(displacement_m, float)
    if np.any(~np.isfinite(D)) or np.any(D < 0):
        raise ValueError(f"displacement_m: expected finite values >= 0 m, got {D.ravel()[~(D.ravel() >= 0)][:1]}")
    eff = (effects or Effects()).nondim(L, EI0)
    res = force_from_displacement_nd(D / L, h / L, p, eff, n_steps=n_steps, keep_shape=keep_shape)
    scale = np.broadcast_to(EI0 / L**2, res["f"].shape)
    return ForceSolution(
        displacement_m=np.broadcast_to(D, res["f"].shape).astype(float),
        force_N=res["f_measured"] * scale,
        true_force_N=res["f"] * scale,
        contact_s_m=res["sig_c"] * L,
        contact_angle_rad=res["phi_c"],
        slipped=res["slipped"],
        yielded=res["yielded"],
        shape_xz_m=res["grid"][:, :2] * L if keep_shape else None,
    )


def secant_k_theta(
    force_N: ArrayLike,
    height_m: ArrayLike,
    EI0: ArrayLike,
    p: ArrayLike,
    length_m: float,
    effects: Effects | None = None,
    *,
    n_steps: int = DEFAULT_STEPS,
) -> NDArray:
    """Secant rotational stiffness F h / theta(h) from the elastica [N m/rad] (seed III-D).

    theta(h) is the tangent rotation at the contact relative to the unloaded
    stem; it tends to k_theta(h) of eq. kdist as F -> 0 and falls below it
    for large deflections. NaN where no contact exists.
    """
    sol = contact_from_force(force_N, height_m, EI0, p, length_m, effects, n_steps=n_steps)
    rest = contact_from_force(np.zeros_like(sol.force_N), height_m, EI0, p, length_m, effects, n_steps=n_steps)
    theta = sol.contact_angle_rad - rest.contact_angle_rad
    return np.where(sol.found, sol.force_N * np.asarray(height_m, float) / theta, np.nan)


def _hermite(t: NDArray, p0, d0, p1, d1) -> tuple[NDArray, NDArray]:
    """Cubic Hermite between values p0, p1 with end slopes d0, d1 (per unit t) and its derivative in t."""
    t2, t3 = t * t, t * t * t
    val = (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * d0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * d1
    der = (6 * t2 - 6 * t) * p0 + (3 * t2 - 4 * t + 1) * d0 + (-6 * t2 + 6 * t) * p1 + (3 * t2 - 2 * t) * d1
    return val, der


def centerline_x_at_heights(grid: ArrayLike, zeta: ArrayLike) -> tuple[NDArray, NDArray]:
    """Horizontal position and cos(tangent angle) where each centerline first reaches each height.

    The centerline between grid nodes is the cubic Hermite of :func:`centerline_at`; the arc length at
    which it reaches ``zeta`` is found in the bracketing interval by Newton's method on that cubic
    (started from linear interpolation), so no resampling is needed. Heights are taken on the running
    maximum of zeta (a stem that curls over is read where it first gets there); above the highest point
    the tip is returned. Reference: resample with :func:`centerline_at` on a fine grid and interpolate
    linearly in height (tests/test_elastica.py).

    Parameters
    ----------
    grid : array, shape (n + 1, 3, C)
        March grids (xi, zeta, phi at the nodes) of C centerlines, nondimensional (/L).
    zeta : array, shape (k,)
        Query heights z/L.

    Returns
    -------
    x, cos_phi : arrays, shape (C, k)
        xi at each height, and the cosine of the tangent angle from vertical there.
    """
    g = np.asarray(grid, float)
    z = np.asarray(zeta, float)
    n = g.shape[0] - 1
    h = 1.0 / n
    xi, ze, ph = g[:, 0].T, g[:, 1].T, g[:, 2].T  # (C, n + 1)
    top = np.maximum.accumulate(ze, axis=1)
    idx = np.clip(np.sum(top[:, :, None] <= z[None, None, :], axis=1) - 1, 0, n - 1)  # (C, k)

    def at(a, shift=0):
        return np.take_along_axis(a, idx + shift, axis=1)

    z0, z1, x0, x1 = at(ze), at(ze, 1), at(xi), at(xi, 1)
    s0, s1, c0, c1 = np.sin(at(ph)) * h, np.sin(at(ph, 1)) * h, np.cos(at(ph)) * h, np.cos(at(ph, 1)) * h
    span = z1 - z0
    t = np.clip((z[None, :] - z0) / np.where(span > 0, span, 1.0), 0.0, 1.0)

    for _ in range(4):
        val, der = _hermite(t, z0, c0, z1, c1)
        t = np.clip(t - (val - z[None, :]) / np.where(np.abs(der) > 1e-12, der, 1e-12), 0.0, 1.0)
    x, dx = _hermite(t, x0, s0, x1, s1)
    _, dz = _hermite(t, z0, c0, z1, c1)
    cos_phi = dz / np.maximum(np.hypot(dx, dz), 1e-12)
    above = z[None, :] >= top[:, -1:]  # above the highest point: the tip, as the reference reads it
    x = np.where(above, xi[:, -1:], x)
    cos_phi = np.where(above, np.cos(ph[:, -1:]), cos_phi)
    return x, cos_phi


def centerline_normal_offsets(grid: ArrayLike, xi: ArrayLike, zeta: ArrayLike) -> NDArray:
    """Signed distance of each point from each centerline, along the normal at its nearest point.

    The centerline between grid nodes is the cubic Hermite of :func:`centerline_at`. For each point the
    nearest node is found, then the nearest point on the two segments beside it by Newton's method on
    the squared distance; the offset is (point - nearest) . (cos phi, -sin phi), so a point displaced
    by dx horizontally from a straight stem is dx cos phi off it, as (x_obs - x(z_obs)) cos phi reads
    it. Unlike the horizontal gap at the point's height (:func:`centerline_x_at_heights`) it stays
    smooth in the stem's parameters where the stem is nearly horizontal, or its top passes through the
    point's height. Reference: the nearest of a fine resampling (tests/test_elastica.py).

    Parameters
    ----------
    grid : array, shape (n + 1, 3, C)
        March grids (xi, zeta, phi at the nodes) of C centerlines, nondimensional (/L).
    xi, zeta : arrays, shape (k,)
        The points, nondimensional (/L).

    Returns
    -------
    array, shape (C, k)
        Signed normal offsets (/L); positive on the +x side of an upright stem.
    """
    g = np.asarray(grid, float)
    px, pz = (np.asarray(a, float)[None, :] for a in (xi, zeta))
    n = g.shape[0] - 1
    h = 1.0 / n
    gx, gz, gp = g[:, 0].T, g[:, 1].T, g[:, 2].T  # (C, n + 1)
    # the nearest node, in chunks of points that keep the (C, chunk, n + 1) distances under ~32 MB
    C, k = gx.shape[0], px.shape[1]
    j = np.empty((C, k), int)
    chunk = max(1, 4_000_000 // (C * (n + 1)))
    for a in range(0, k, chunk):
        b = slice(a, a + chunk)
        d2 = (gx[:, None, :] - px[0, b, None]) ** 2 + (gz[:, None, :] - pz[0, b, None]) ** 2
        j[:, b] = np.argmin(d2, axis=2)
    best_d2 = np.full(j.shape, np.inf)
    out = np.zeros(j.shape)
    for seg, t_start in ((j - 1, 1.0), (j, 0.0)):  # the segments on either side of the nearest node, from it
        i = np.clip(seg, 0, n - 1)

        def at(a, shift=0, i=i):
            return np.take_along_axis(a, i + shift, axis=1)

        x0, x1, z0, z1 = at(gx), at(gx, 1), at(gz), at(gz, 1)
        s0, s1 = np.sin(at(gp)) * h, np.sin(at(gp, 1)) * h
        c0, c1 = np.cos(at(gp)) * h, np.cos(at(gp, 1)) * h
        t = np.full(i.shape, t_start)
        for _ in range(6):  # Newton on d/dt |C(t) - P|^2 / 2 = (C - P) . C'
            x, dx = _hermite(t, x0, s0, x1, s1)
            z, dz = _hermite(t, z0, c0, z1, c1)
            ddx = (12 * t - 6) * x0 + (6 * t - 4) * s0 + (-12 * t + 6) * x1 + (6 * t - 2) * s1
            ddz = (12 * t - 6) * z0 + (6 * t - 4) * c0 + (-12 * t + 6) * z1 + (6 * t - 2) * c1
            grad = (x - px) * dx + (z - pz) * dz
            curv = dx * dx + dz * dz + (x - px) * ddx + (z - pz) * ddz
            t = np.clip(t - grad / np.where(curv > 1e-12, curv, 1e-12), 0.0, 1.0)
        x, dx = _hermite(t, x0, s0, x1, s1)
        z, dz = _hermite(t, z0, c0, z1, c1)
        d2 = (x - px) ** 2 + (z - pz) ** 2
        norm = np.maximum(np.hypot(dx, dz), 1e-300)
        off = ((px - x) * dz - (pz - z) * dx) / norm
        better = d2 < best_d2
        best_d2 = np.where(better, d2, best_d2)
        out = np.where(better, off, out)
    return out


def centerline_at(grid: ArrayLike, sig: ArrayLike) -> NDArray:
    """Centerline (xi, zeta) at arc lengths ``sig`` from a march grid.

    Cubic Hermite interpolation between the grid nodes sigma_k = k/n using the
    exact tangents (sin phi, cos phi), so the error is O(n^-4).

    Parameters
    ----------
    grid : array, shape (n + 1, 3, ...)
        ``grid`` from ``keep_shape=True`` (xi, zeta, phi at the nodes).
    sig : array, shape (m,)
        Query arc lengths s/L in [0, 1].

    Returns
    -------
    array, shape (2, m, ...)
    """
    g = np.asarray(grid, float)
    s = np.clip(np.asarray(sig, float), 0.0, 1.0)
    n = g.shape[0] - 1
    k = np.minimum((s * n).astype(int), n - 1)
    t = (s * n - k).reshape((-1,) + (1,) * (g.ndim - 2))
    h = 1.0 / n
    p0, p1 = g[k, :2], g[k + 1, :2]
    phi0, phi1 = g[k, 2], g[k + 1, 2]
    d0 = np.stack([np.sin(phi0), np.cos(phi0)], axis=1) * h
    d1 = np.stack([np.sin(phi1), np.cos(phi1)], axis=1) * h
    out, _ = _hermite(t[:, None], p0, d0, p1, d1)  # (m, 2, ...)
    return np.moveaxis(out, 1, 0)

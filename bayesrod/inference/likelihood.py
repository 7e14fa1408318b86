"""Likelihood of EI0, p, noise (and effect parameters) on forces and shapes jointly.

EI0 is a pure scale of the nondimensional elastica (docs/model.md): at a given
contact displacement the force is F = EI0/L^2 f(d; p, h/L) and the centerline
(x, z)/L depends on p and h/L only. So the likelihood precomputes, once per
dataset, exact tables over a grid of p:

* ``f[p_k, i]``: nondimensional force at every engaged force sample i;
* ``normal[p_k, j]``: every observed point j's signed normal offset from the
  predicted centerline's nearest point (the shape residual).

A log-likelihood evaluation is then a 4-point Lagrange interpolation in p and
a scale by EI0, batched over walkers. Where the model's branch ends before an
engaged displacement (it would have slipped), force and shape go on along their
tangent at the branch end (flat where the branch ends in a fold), and the slip is not
used as a hard constraint (see ``RodLikelihood.predict_nd_force``).

Shape residuals are the signed normal distance from each observed point to the
predicted curve's nearest point; for a small horizontal offset of an upright
stem, (x_obs - x_pred(z_obs)) cos(phi_pred(z_obs)), which is what the tables
interpolated before 2026-11-27 (``RodLikelihood._shape_table``).

Extracted centerlines have errors correlated along the stem and between
consecutive frames (a smoothing spline, the same background and plane depth).
Treating their points as independent makes the posterior far too narrow, so
the shape term is raised to a power ``shape_weight`` = n_eff / n
(a coarsened or composite likelihood, Pauli, Racugno & Ventura 2011;
Miller & Dunson 2019), measured from the residuals at the posterior mode by
:func:`effective_shape_weight`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import special
from scipy.interpolate import CubicSpline, PchipInterpolator

from ..dataset.engagement import detect_engagement
from ..dataset.model import Specimen
from ..physics.elastica import centerline_normal_offsets, contact_from_force_nd, force_from_displacement_nd
from ..physics.lumped import stem_diameter
from .priors import ParameterSpace

_LOG_2PI = math.log(2 * math.pi)
# force_offset is exact (additive); the others enter through a second table axis (at most one of them)
TABLE_EFFECTS = ("base_compliance", "rest_curvature", "base_tilt", "contact_friction")
# exact without a table: the offset adds; a yielding base caps the force at M_y / h (eq. torque balance
# about the base: F h = M_0 <= M_y), the elastic curve below it is the plain model's
CLOSED_EFFECTS = ("force_offset", "yield")
FITTABLE_EFFECTS = CLOSED_EFFECTS + TABLE_EFFECTS
# self_weight is not offered: its forward solves (a secant on the base moment per solve) take 80 s per
# table node and height, so a fit would take about an hour.


def base_stiffness(u: NDArray, EI0: NDArray, L: float) -> NDArray:
    """k_b [N m/rad] from the table coordinate u = c/(1+c), c = EI0 / (k_b L); inf at u = 0 (a clamp)."""
    u = np.asarray(u, float)
    with np.errstate(divide="ignore"):
        return np.where(u > 0, np.asarray(EI0, float) * (1.0 - u) / (np.maximum(u, 1e-300) * L), np.inf)


@dataclass(frozen=True)
class EffectAxis:
    """Second table axis for one effect: a bounded coordinate u, uniform grid, and the map to the solver.

    u is chosen so that the neutral value is u = 0 and the range is finite:
    base_compliance u = c/(1+c) with c = EI0/(k L); rest_curvature u = kappa0 L; base_tilt
    and contact_friction u = the value itself.
    """

    name: str
    grid: NDArray  # (E,)

    def nondim(self, u: NDArray) -> dict:
        """Solver groups (Effects.nondim keys) at coordinates u."""
        u = np.asarray(u, float)
        if self.name == "base_compliance":
            return {"c_base": u / (1.0 - u)}
        return {{"rest_curvature": "kappa0", "base_tilt": "tilt", "contact_friction": "mu"}[self.name]: u}

    def coordinate(self, value: NDArray, EI0: NDArray, L: float) -> NDArray:
        """u of SI effect values (W,) at EI0 (W,)."""
        value = np.asarray(value, float)
        if self.name == "base_compliance":
            c = EI0 / (value * L)
            return c / (1.0 + c)
        if self.name == "rest_curvature":
            return value * L
        return value

    def value(self, u: NDArray, EI0: NDArray, L: float) -> NDArray:
        """SI effect values at coordinates ``u`` (W,) and EI0 (W,): the inverse of :meth:`coordinate`
        (a base spring's u = 0 is a clamp: an infinitely stiff spring)."""
        u = np.asarray(u, float)
        if self.name == "base_compliance":
            return base_stiffness(u, EI0, L)
        if self.name == "rest_curvature":
            return u / L
        return u

    def between_nodes(self, u: float) -> float:
        """The middle of the node interval that holds ``u`` (the end intervals for u outside the grid): where
        the tables' interpolation in u is least exact (it is exact at the nodes)."""
        return between_nodes(self.grid, u)

    @classmethod
    def from_prior(cls, name: str, prior, EI0_range: tuple[float, float], L: float, n: int = 13) -> EffectAxis:
        """Grid covering the prior's central 99.8% at any EI0 in ``EI0_range``."""
        lo_q, hi_q = prior.quantile(0.001), prior.quantile(0.999)
        probe = cls(name, np.zeros(1))
        us = [probe.coordinate(v, e, L) for v in (lo_q, hi_q) for e in EI0_range]
        lo, hi = float(np.min(us)), float(np.max(us))
        caps = {
            "base_compliance": (0.0, 0.95),
            "rest_curvature": (-2.0, 2.0),
            "base_tilt": (-0.6, 0.6),
            "contact_friction": (-0.9, 0.9),
        }[name]
        if name == "base_compliance":
            lo = 0.0  # include the neutral value (a clamp)
        lo, hi = max(lo, caps[0]), min(hi, caps[1])
        if hi <= lo:
            hi = lo + 1e-3
        return cls(name, np.linspace(lo, hi, n))


@dataclass(frozen=True)
class PushData:
    """Engaged observations of one push, ready for the likelihood."""

    id: str
    height_m: float
    D_m: NDArray  # (n,) contact displacement of each engaged force sample
    F_N: NDArray  # (n,) measured force
    frame_D_m: NDArray  # (m,) contact displacement of each engaged frame
    frame_index: NDArray  # (k,) frame of each observed point
    x_m: NDArray  # (k,)
    z_m: NDArray  # (k,)
    sd_m: NDArray | None  # (k,) or None
    #: the largest engaged contact displacement [m]: the stem held the probe at least this far
    engaged_to_m: float = float("nan")
    #: where a slip was seen (the force fell while the robot went on), the contact displacement by which
    #: the stem had slipped [m]; nan when the push ended engaged or the robot withdrew
    slipped_by_m: float = float("nan")
    #: the resolution of the slip's position [m]: the robot's last step before it
    slip_step_m: float = float("nan")


def prepare_data(spec: Specimen, use_forces: bool = True, use_shapes: bool = True) -> list[PushData]:
    """Engaged samples and frames of each push (frames by time, on the force record's clock)."""
    out = []
    for push in spec.pushes:
        eng = detect_engagement(push.force.force_N)
        t = push.force.time_s[eng.mask]
        D = push.force.contact_x_m[eng.mask]
        F = push.force.force_N[eng.mask]
        fD, fi, xs, zs, sds = [], [], [], [], []
        if use_shapes and push.shapes:
            # contact displacement at frame times: monotone cubic in time (D(t) is curved: the robot
            # moves uniformly but the wire's deflection grows with the force)
            D_of_t = PchipInterpolator(t, D) if t.size >= 2 else None
            for fr in push.shapes:
                if t.size < 3 or not (t[1] <= fr.time_s <= t[-1]):
                    # before contact or after the slip: not engaged. A frame before the second engaged
                    # sample is not used either: D(t) bends hardest where the load starts (slack, the
                    # wire taking up), and the interpolated D of such a frame was 12% off on the
                    # simulated twig, an error that a tilt or a rest curvature absorbs (0.2-0.5 sd,
                    # docs/validation.md "Likelihood tables against exact solves")
                    continue
                k = len(fD)
                fD.append(float(D_of_t(fr.time_s)))
                keep = fr.z_m >= 0
                fi.append(np.full(int(keep.sum()), k))
                xs.append(fr.x_m[keep] * push.direction)
                zs.append(fr.z_m[keep])
                sds.append(fr.sd_m[keep] if fr.sd_m is not None else None)
        has_sd = bool(sds) and all(s is not None for s in sds)
        slip = _slip_window(push.force, eng) if use_forces and D.size else {}
        out.append(
            PushData(
                push.id,
                push.height_m,
                D if use_forces else D[:0],
                F if use_forces else F[:0],
                np.array(fD),
                np.concatenate(fi) if fi else np.zeros(0, int),
                np.concatenate(xs) if xs else np.zeros(0),
                np.concatenate(zs) if zs else np.zeros(0),
                np.concatenate(sds) if has_sd else None,
                **slip,
            )
        )
    return out


def _slip_window(force, eng) -> dict:
    """Where a push's slip lies, from its engagement (docs/inference.md, "The slip").

    The stem held the probe to the largest engaged contact displacement D_max. If the force then
    fell while the robot kept advancing (its position past the one at D_max), the slip happened
    before the contact had moved one more robot step: by D_max + (robot at the first disengaged
    sample - robot at D_max), the wire's deflection taken as unchanged over that step.
    """
    idx = np.flatnonzero(eng.mask)
    D = force.contact_x_m[idx]
    R = force.robot_x_m
    k = int(idx[np.argmax(D)])
    D_max = float(D.max())
    step = float(R[k] - R[k - 1]) if k >= 1 and R[k] > R[k - 1] else float("nan")
    out = {"engaged_to_m": D_max, "slip_step_m": step}
    j = eng.slip_index
    if j is not None and k == j - 1 and R[j] > R[k]:
        out["slipped_by_m"] = D_max + float(R[j] - R[k])
    return out


#: interior forces per round of the branch end's search (:class:`ForceCurves`): the bracket shrinks 8x per round
BRANCH_SECTIONS = 7
#: force levels a curve adds between its last clustered level and the branch end (:func:`force_levels`), evenly in
#: log10(1 - f/f_end) down to 10^-PLATEAU_DECADES: on a plateau the force comes within 1e-5 of the end's 0.14 L
#: before the end (h/L 0.41, p 0.95: SBC seed 108's push), and the last interval of the clustered levels held
#: 0.16 L, whose interpolation moved the forces by 2.3 noise sds there (docs/validation.md, session 72)
PLATEAU_LEVELS = 24
PLATEAU_DECADES = 13.0


def force_levels(n_f: int) -> NDArray:
    """The forces, as fractions of the branch end's, at which :class:`ForceCurves` solves a curve, ascending,
    (n_f + PLATEAU_LEVELS,): n_f levels 1 - (1 - u)^2 (u uniform in [0, 1]; evenly spaced in displacement near
    a fold, where f_end - f grows as (d_end - d)^2), and between the last of them below 1 and 1 itself
    :data:`PLATEAU_LEVELS` more, evenly in log10(1 - f/f_end) down to 10^-:data:`PLATEAU_DECADES` (where the force
    nears its end exponentially slowly, on a plateau, the clustered levels leave most of the displacement in one
    interval). The last level is 1, the branch end."""
    u = np.linspace(0.0, 1.0, n_f)
    clustered = 1.0 - (1.0 - u) ** 2
    top = -np.log10(1.0 - clustered[-2])
    plateau = 1.0 - 10.0 ** -np.linspace(top, PLATEAU_DECADES, PLATEAU_LEVELS + 1)[1:]
    return np.concatenate([clustered[:-1], plateau, [1.0]])


#: how :meth:`ForceCurves.batch` runs its solves: ``(processes, progress bar)``, set by :func:`table_workers`
_TABLE_BUILD: ContextVar[tuple[int, bool]] = ContextVar("bayesrod_table_build", default=(1, False))
#: effects whose solves search the base moment (:mod:`bayesrod.physics.elastica`): each curve takes seconds to a
#: minute, so they are solved one curve per call and spread over the workers (docs/performance.md)
SLOW_EFFECT_KEYS = ("mu", "w0")


@contextmanager
def table_workers(n: int, progress: bool = False) -> Iterator[int]:
    """Within the block, :meth:`ForceCurves.batch` solves its curves in ``n`` processes (1: in this one).

    A likelihood's tables come from one batch of force curves (heights x effect nodes). With contact friction
    each curve takes 20-25 s on one core (docs/performance.md), and a three-height friction fit
    spends most of its time there; the curves are independent, so ``n`` processes take about 1/n of the
    time, and the tables are the same whatever ``n`` (:func:`_solve_spread`).

    Parameters
    ----------
    n : int
        Processes, at least 1.
    progress : bool
        A progress bar over the curves of slow effects (:data:`SLOW_EFFECT_KEYS`); the caller decides
        whether a terminal shows it.
    """
    token = _TABLE_BUILD.set((check_workers(n), bool(progress)))
    try:
        yield int(n)
    finally:
        _TABLE_BUILD.reset(token)


def check_workers(n) -> int:
    """``n`` as a number of processes (an integer >= 1, not a bool), else ValueError naming ``n_workers``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n_workers: expected an integer >= 1, got {n!r}")
    return int(n)


def _solve_spread(cls, etas: NDArray, p_grid: NDArray, n_f: int, rows: list, todo: list, keys: list) -> list:
    """The curves of rows ``todo`` of :meth:`ForceCurves.batch`, in this process or, under :func:`table_workers`
    with more than one worker, over a process pool.

    Curves with a slow effect (:data:`SLOW_EFFECT_KEYS`) are solved one per call, in either case: near a fold
    of the force curve the base moment's search misses equilibria at some forces (between forces where it holds
    the stem on the curve's smooth continuation; the reference solver found none at the six such forces checked),
    and which it misses depends on the batch (the search takes other paths in batches of other sizes). So the
    branch end found in a batch depended on what else was in it (four curves at 61 p nodes: by more than 1e-3 L
    at 1-9 nodes per curve, up to 0.016 L; docs/performance.md). One per call, a curve depends on its own
    height, effect and p grid only, and the tables are the same whatever the workers. Other curves (milliseconds
    each in a batch, and exact per element) go in one batch, or one chunk per worker.
    """
    from tqdm.auto import tqdm

    def sub(idx):
        return {k: np.array([rows[q][k] for q in idx]) for k in keys} or None

    workers, progress = _TABLE_BUILD.get()
    slow = any(k in SLOW_EFFECT_KEYS and rows[q][k] != 0.0 for q in todo for k in keys)
    n_tasks = len(todo) if slow else min(workers, len(todo))
    chunks = [todo[i::n_tasks] for i in range(n_tasks)]  # interleaved: heights and nodes mixed in each
    label = f"force curves ({', '.join(keys)})"
    bar = tqdm(total=len(todo), desc=label, unit="curve", disable=not (progress and slow), leave=False)
    done: dict = {}
    with bar:
        if workers <= 1 or n_tasks < 2:
            for c in chunks:
                done.update(zip(c, cls._solve(etas[c], p_grid, n_f, sub(c)), strict=True))
                bar.update(len(c))
        else:
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(max_workers=min(workers, n_tasks)) as pool:
                futures = {pool.submit(cls._solve, etas[c], p_grid, n_f, sub(c)): c for c in chunks}
                for fut in as_completed(futures):
                    done.update(zip(futures[fut], fut.result(), strict=True))
                    bar.update(len(futures[fut]))
    return [done[q] for q in todo]


#: the smallest displacement (nondimensional, d/L) between two force levels a curve keeps (:func:`_spaced`): a
#: friction solve's displacement scatters by about 1e-6 near its end, where the levels crowd within 1e-5 of
#: each other; a spline through every level lay up to 4.6e-5 of the peak force off exact solves near the end
#: (mu 0.5, h/L 0.5, p 0.43), through levels 1e-4 apart 1.6e-6 (session 72)
MIN_LEVEL_GAP = 1e-4


def _spaced(d: NDArray, idx: NDArray) -> NDArray:
    """The indices ``idx`` (ascending ``d``) less those within :data:`MIN_LEVEL_GAP` of the last one kept; the last
    index is always kept (the branch end), its predecessor dropped instead where the two lie that close."""
    out = [int(idx[0])]
    for i in idx[1:-1]:
        if d[i] - d[out[-1]] >= MIN_LEVEL_GAP:
            out.append(int(i))
    last = int(idx[-1])
    if len(out) > 1 and d[last] - d[out[-1]] < MIN_LEVEL_GAP:
        out.pop()
    out.append(last)
    return np.asarray(out)


#: the displacement (nondimensional) before a branch's end over which its end slope is fitted (:func:`_end_slope`)
END_FIT_WIDTH = 0.01


def _end_slope(d: NDArray, f: NDArray, d_end: float, spline) -> float:
    """df/dd at the branch end: the slope at ``d_end`` of a least-squares quadratic through the levels within
    :data:`END_FIT_WIDTH` of it (five or more; else ``spline``'s derivative there). A spline's own slope at the end
    reads the last interval alone: with friction, whose displacements scatter by 1e-6 near the end, 96, 71, 104, 63
    at p 0.5-0.8 (mu 0.3, h/L 0.45), where the quadratic reads 98.6, 84.2, 71.3, 61.4 (session 72); a quadratic is
    exact at a fold's end (slope 0)."""
    near = d >= d_end - END_FIT_WIDTH
    if near.sum() < 5:
        return float(spline.derivative()(d_end))
    return float(np.polyfit(d[near] - d_end, f[near], 2)[1])


class ForceCurves:
    """Force-displacement curves f(d) at one height for every p of a grid, from forward solves.

    For each p: the branch end f_end (sections of a bracket on the existence of contact),
    forward solves at the forces of :func:`force_levels` (n_f clustered toward f_end, more down a plateau), and a
    cubic spline (not-a-knot) of f against d. ``force`` continues each node's curve past its slip displacement
    ``d_end`` along its end tangent so that tables stay smooth in p; slip is decided separately.
    :meth:`batch` builds the curves of several heights in one set of solves.
    """

    def __init__(self, eta: float, p_grid: NDArray, n_f: int = 160, effects_nd: dict | None = None):
        (one,) = self.batch(np.array([eta]), p_grid, n_f, effects_nd)
        self.__dict__.update(one.__dict__)

    @classmethod
    def batch(cls, etas: NDArray, p_grid: NDArray, n_f: int = 160, effects_nd: dict | None = None) -> list[ForceCurves]:
        """Curves at every nondimensional height of ``etas`` (Q,): the solves batched over (Q, P).

        ``effects_nd`` values are scalars or one value per row, shape (Q,). Curves already built (same
        eta, effects, p grid and n_f) are taken from a small in-process cache (:data:`CURVE_CACHE_SIZE`):
        the conditions of one stem share their heights.
        """
        etas = np.asarray(etas, float)
        Q = etas.size
        eff = effects_nd or {}
        # plain floats: the cache keys must hash (a 0-d array from Effects.nondim does not)
        rows = [
            {k: float(np.asarray(v, float).reshape(-1)[q]) if np.ndim(v) else float(v) for k, v in eff.items()}
            for q in range(Q)
        ]
        tag = (np.asarray(p_grid, float).tobytes(), int(n_f))
        keys = [(float(e), tuple(sorted(r.items())), tag) for e, r in zip(etas, rows, strict=True)]
        todo = [q for q in range(Q) if keys[q] not in _CURVE_CACHE]
        # taken before anything is added: inserting the new curves may evict cached ones
        out = {q: _CURVE_CACHE[keys[q]] for q in range(Q) if keys[q] in _CURVE_CACHE}
        if todo:
            solved = _solve_spread(cls, etas, p_grid, n_f, rows, todo, list(eff))
            for q, c in zip(todo, solved, strict=True):
                c.effects_nd = rows[q] or effects_nd
                out[q] = c
                _CURVE_CACHE[keys[q]] = c
                while len(_CURVE_CACHE) > CURVE_CACHE_SIZE:
                    _CURVE_CACHE.pop(next(iter(_CURVE_CACHE)))
        return [out[q] for q in range(Q)]

    @classmethod
    def _solve(cls, etas: NDArray, p_grid: NDArray, n_f: int, effects_nd: dict | None) -> list[ForceCurves]:
        """The batched solves behind :meth:`batch`; ``effects_nd`` values scalars or (Q,)."""
        etas = np.asarray(etas, float)[:, None]
        Q, P = etas.shape[0], p_grid.size
        pg = np.broadcast_to(p_grid[None, :], (Q, P))
        eff = effects_nd or {}
        eff2 = {k: np.asarray(v, float)[:, None] if np.ndim(v) else v for k, v in eff.items()} or None
        eff3 = {k: np.asarray(v, float)[:, None, None] if np.ndim(v) else v for k, v in eff.items()} or None

        def ok(f, e, p, effects):
            r = contact_from_force_nd(f, e, p, effects)
            return r["found"] & ~r["yielded"]

        lo = np.zeros((Q, P))
        hi = np.broadcast_to(2.0 / etas**2, (Q, P)).copy()
        for _ in range(60):  # expand until no contact
            found = ok(hi, etas, pg, eff2)
            if not found.any():
                break
            lo = np.where(found, hi, lo)
            hi = np.where(found, 2 * hi, hi)
        # the branch end: BRANCH_SECTIONS evenly spaced forces per bracket and round, to 2^-48 of the first
        # bracket (where 48 bisections went), keeping the first force without contact: a third of the rounds, and
        # with friction or weight (each solve a search of the base moment) about half the time
        frac = np.arange(1, BRANCH_SECTIONS + 1) / (BRANCH_SECTIONS + 1.0)
        width0 = hi - lo
        while np.any(hi - lo > 2.0**-48 * width0):
            pts = lo[..., None] + (hi - lo)[..., None] * frac
            stop = ~ok(pts, etas[..., None], pg[..., None], eff3)
            first = np.where(stop.any(axis=-1), np.argmax(stop, axis=-1), BRANCH_SECTIONS)
            below = np.take_along_axis(pts, np.maximum(first - 1, 0)[..., None], -1)[..., 0]
            above = np.take_along_axis(pts, np.minimum(first, BRANCH_SECTIONS - 1)[..., None], -1)[..., 0]
            lo = np.where(first > 0, below, lo)
            hi = np.where(first < BRANCH_SECTIONS, above, hi)
        f = lo[..., None] * force_levels(n_f)  # (Q, P, n_f + PLATEAU_LEVELS)
        # one more column in the same solve: the force SLIP_FORCE_REL below the branch end's, where the earliest
        # slip the model allows lies (on a plateau the end's displacement is ill-conditioned; docs/inference.md)
        f_early = lo[..., None] * (1.0 - SLIP_FORCE_REL)
        r = contact_from_force_nd(np.concatenate([f, f_early], axis=-1), etas[..., None], pg[..., None], eff3)
        d_both = r["xi_c"] - r["xi_c"][..., :1]
        d_all, d_early_all = d_both[..., :-1], d_both[..., -1]
        out = []
        for q in range(Q):
            c = cls.__new__(cls)
            c.effects_nd = effects_nd
            d = d_all[q]
            c.d_end = d[:, -1].copy()
            # at most d_end; where the solve found no contact (NaN), the end itself
            c.d_early = np.fmin(d_early_all[q], c.d_end)
            c.end_slope = np.zeros(P)
            c._interp = []
            for k in range(P):
                dk, fk = d[k], f[q, k]
                fin = np.where(np.isfinite(dk), dk, -np.inf)
                prev = np.concatenate([[-np.inf], np.maximum.accumulate(fin)[:-1]])
                keep = np.isfinite(dk) & (fin > prev)  # strictly increasing, finite
                if keep.sum() < 2:  # no equilibrium with contact (e.g. a stem curled away): zero force
                    c.d_end[k] = c.d_early[k] = 0.0
                    c._interp.append(PchipInterpolator([0.0, 1.0], [0.0, 0.0], extrapolate=True))
                    continue
                if not np.isfinite(c.d_end[k]):
                    # the solve at the branch end's force itself found no contact: with friction or weight the
                    # edge of the forces that have an equilibrium can flip within round-off between batches (the
                    # base moment's root meets the bend there); the curve ends at its last equilibrium
                    c.d_end[k] = dk[keep][-1]
                    c.d_early[k] = np.fmin(c.d_early[k], c.d_end[k])
                # a cubic spline, not PCHIP: PCHIP's slopes are first order, and on a plateau curve (eta 0.41,
                # p 0.95) its force lay up to 3.8e-6 of the peak off exact solves, the spline's 4.4e-7 (the
                # regular p 0.43: 2.8e-6 and 7.9e-8; docs/validation.md, session 72)
                at = _spaced(dk, np.flatnonzero(keep))
                spline = CubicSpline(dk[at], fk[at], extrapolate=True)
                c.end_slope[k] = max(_end_slope(dk[at], fk[at], c.d_end[k], spline), 0.0)
                c._interp.append(spline)
            out.append(c)
        return out

    def force(self, d: NDArray, *, continued: bool = True) -> NDArray:
        """f at displacements d (M,) for every p: (P, M), continued past each node's d_end.

        Past the branch end the curve goes on along its tangent there (slope clipped at zero). Where
        the branch ends in a fold (the plain rod: the slope there is ~0) that is the flat hold; where it
        ends with the force still rising (contact friction: the stem slides off at a finite slope) a
        flat hold would put a kink into the table that interpolation in p and in the effect smears
        over the samples near the slip (a 2-5 sd bias of mu; docs/validation.md). ``continued=False``
        holds the end value instead (the force at which a shape can still be solved).
        """
        d = np.asarray(d, float)
        return np.stack(
            [
                fn(np.minimum(d, de)) + (s if continued else 0.0) * np.maximum(d - de, 0.0)
                for fn, de, s in zip(self._interp, self.d_end, self.end_slope, strict=True)
            ]
        )


#: effect-axis nodes of a fit with shapes, where 25 are not enough (build_likelihood)
SHAPE_EFFECT_NODES = {"rest_curvature": 49, "base_tilt": 49}
#: effect-axis nodes where 25 are not enough on forces alone (build_likelihood): a friction axis, read in log
#: space, moved the forces-only twig's MLE of mu by +0.115 sd with 25 nodes and by -0.023 sd with 49
#: (docs/validation.md, session 47); a rest-curvature axis moved its log EI0 by -0.049 sd (0.3 1/m) and -0.053 sd
#: (0.6 1/m) with 25, -0.011 sd with 49 (session 58)
FORCE_EFFECT_NODES = {"contact_friction": 49, "rest_curvature": 49}
#: zoom_window: the largest shift [Laplace sd] the tables may cause at the start point before a fit narrows the
#: effect axis around it (the table-accuracy target of docs/validation.md)
TABLE_ZOOM_SD = 0.05
#: zoom_window: half-width of a narrowed effect axis in Laplace sds of its coordinate at the start point. The
#: Laplace sd assumes independent noise: an AR(1) noise's posterior is wider by up to sqrt((1 + rho) / (1 - rho))
#: (4.4 at rho 0.9), so the window still spans +- 14 sd there
ZOOM_HALF_WIDTH_SD = 60.0
#: zoom_window: the largest share of the current axis a narrowed one may span (at 0.8 its nodes are 1.25 times
#: closer, and the four-point interpolation's error, of order spacing^4, falls by 2.4)
ZOOM_MAX_SHARE = 0.8

#: nondimensional step before a curve's end over which a shape's slope in d is taken (RodLikelihood)
SHAPE_END_STEP = 0.01

#: force curves kept per process (each ~0.3 MB at 61 p nodes x 160 solves): enough for one stem's
#: heights x effect nodes, so that the conditions of a stem (issue 23) share their solves
CURVE_CACHE_SIZE = 128
#: the force table is interpolated in log(f + FORCE_LOG_FLOOR) (nondimensional f): near a branch's end the force
#: grows nearly exponentially along the friction axis (f 6.7, 8.7, 11.8, 17.1 at d 0.738 L, mu 0.21-0.42, eta 0.56),
#: and linear 4-point interpolation over mu missed by 0.013 there, log-space by 0.0012 (docs/inference.md, session 46).
#: Only on the axes of LOG_FORCE_EFFECTS: on a 5-node rest-curvature axis log space moved a noise-free fit's MLE by
#: 10-26 sd (linear: 0.15-1.6), where small forces differ by factors between nodes; a table with a negative force
#: is read linearly too.
FORCE_LOG_FLOOR = 1e-9
LOG_FORCE_EFFECTS = ("contact_friction",)
_CURVE_CACHE: dict = {}


def force_log_table(f_table: NDArray, axis: EffectAxis | None) -> NDArray | None:
    """log(f_table + FORCE_LOG_FLOOR) where a force table is read in log space (an axis of ``LOG_FORCE_EFFECTS`` and
    no negative force), else None (read linearly). Shared by the likelihood and the design's predictor."""
    if axis is None or axis.name not in LOG_FORCE_EFFECTS or not f_table.size or not np.min(f_table) >= 0.0:
        return None
    return np.log(f_table + FORCE_LOG_FLOOR)


def _lagrange4(grid: NDArray, p: NDArray):
    """Indices (W, 4) and weights (W, 4) of 4-point Lagrange interpolation on a uniform grid."""
    h = grid[1] - grid[0]
    n = grid.size
    u = (p - grid[0]) / h
    k = np.clip(np.floor(u).astype(int) - 1, 0, n - 4)
    t = u - k  # position relative to node k, in [1, 2] in the interior
    idx = k[:, None] + np.arange(4)
    # the cardinal cubics of the nodes 0, 1, 2, 3 (tests check them against the product formula)
    t1, t2, t3 = t - 1.0, t - 2.0, t - 3.0
    w = np.empty((p.size, 4))
    w[:, 0] = t1 * t2 * t3 * (-1.0 / 6.0)
    w[:, 1] = t * t2 * t3 * 0.5
    w[:, 2] = t * t1 * t3 * -0.5
    w[:, 3] = t * t1 * t2 * (1.0 / 6.0)
    return idx, w


class RodLikelihood:
    """Log-likelihood of a specimen's forces and shapes.

    Parameters
    ----------
    spec : Specimen
    p_range : (low, high)
        Range of the taper exponent covered by the tables (the prior's support).
    effects : sequence of str
        Effects whose parameters are fitted (currently ``force_offset``).
    use_forces, use_shapes : bool
        Which observations enter (a force-only fit of field data, a shape-only fit).
    n_p : int
        Nodes of the p grid (61 over the prior's support; :func:`build_likelihood` narrows it around a start
        where that is too coarse for the posterior, ``p_window``).

    Attributes
    ----------
    names : list of str
        Natural parameter names in order: EI0, p, sigma_force_N (if forces),
        shape noise (``shape_sd_scale`` if every point has an sd, else
        ``sigma_shape_m``), then effects.
    offset_prior_sd : float or None
        Set (by :class:`~bayesrod.inference.group.GroupLikelihood`) to integrate one force offset common to
        all this likelihood's force samples out of the force term in closed form, prior N(0, sd^2) [N]
        (:func:`shared_error_loglik`); :meth:`offset_posterior` gives its conditional. None: no such offset.
    """

    offset_prior_sd: float | None = None
    #: (lo, hi) when the p grid spans a window narrower than the prior's support (``build_likelihood(p_window=)``;
    #: walkers outside it get zero density); None: the grid covers the prior
    p_window: tuple[float, float] | None = None

    def __init__(
        self,
        spec: Specimen,
        p_range=(0.0, 3.0),
        effects=(),
        use_forces=True,
        use_shapes=True,
        n_p: int = 61,
        effect_axis: EffectAxis | None = None,
        force_noise: str = "iid",
        preload: bool = False,
        length_prior=None,
        height_sd_m: float = 0.0,
        force_offsets: bool = False,
        diameter: str = "off",
        diameter_priors: dict | None = None,
        slip: bool = False,
    ):
        if "self_weight" in effects:
            raise ValueError(
                "effects: self_weight cannot be fitted yet (its forward solves take ~80 s per table node and "
                "height, an hour per fit); expected effects from " + ", ".join(FITTABLE_EFFECTS)
            )
        unsupported = [e for e in effects if e not in FITTABLE_EFFECTS]
        if unsupported:
            raise ValueError(
                f"effects: expected effects from {', '.join(FITTABLE_EFFECTS)}, got {', '.join(unsupported)}"
            )
        tabled = [e for e in effects if e in TABLE_EFFECTS]
        if len(tabled) > 1:
            raise ValueError(
                f"effects: expected at most one of {', '.join(TABLE_EFFECTS)} (plus force_offset), "
                f"got {', '.join(tabled)}"
            )
        if tabled and (effect_axis is None or effect_axis.name != tabled[0]):
            raise ValueError(f"effect {tabled[0]}: expected an EffectAxis for it (see EffectAxis.from_prior)")
        self.axis = effect_axis if tabled else None
        if "yield" in effects and use_shapes and any(p.shapes for p in spec.pushes):
            raise ValueError(
                "effects: yield expects a force-only fit (centerlines not used): the forces on the plastic "
                "branch are exact (F = M_y/h) but the shapes there are not modelled"
            )
        if force_noise not in FORCE_NOISE_MODELS:
            raise ValueError(f"force_noise: expected one of {', '.join(FORCE_NOISE_MODELS)}, got {force_noise!r}")
        self.force_noise = force_noise
        self.preload = bool(preload)
        if self.preload and effect_axis is not None:
            raise ValueError(
                f"preload: expected no tabled effect beside it (one extra table axis at a time), got {effect_axis.name}"
            )
        self.spec = spec
        self.L = float(spec.length_m)
        self.effects = tuple(effects)
        self.length_prior = length_prior
        self.height_sd_m = _check_height_sd(height_sd_m, spec)
        self.force_offsets = bool(force_offsets)
        self.geometry = length_prior is not None or self.height_sd_m > 0
        _check_nuisances(self, effect_axis, use_forces, use_shapes)
        self.data = prepare_data(spec, use_forces, use_shapes)
        self.n_force = int(sum(d.F_N.size for d in self.data))
        self.n_points = int(sum(d.x_m.size for d in self.data))
        self._init_slip(bool(slip))
        if self.n_force == 0 and self.n_points == 0:
            raise ValueError(f"{spec.specimen}: expected engaged force samples or centerline points, got none")
        lo, hi = p_range
        self.p_grid = np.linspace(lo, hi, n_p)
        self.shape_has_sd = self.n_points > 0 and all(d.sd_m is not None for d in self.data if d.x_m.size)
        # power on the shape likelihood: 1 treats points as independent; effective_shape_weight()
        # measures n_eff / n from the residuals' correlation along the stem and between frames
        self.shape_weight = 1.0
        names = ["EI0", "p"]
        if self.n_force:
            names.append("sigma_force_N")
            if force_noise == "ar1":
                names.append("rho_force")
        if self.n_points:
            names.append("shape_sd_scale" if self.shape_has_sd else "sigma_shape_m")
        # per push: the contact displacement already made when recording began (docs/inference.md, preload)
        self.preload_names = [preload_name(d.id) for d in self.force_data] if self.preload else []
        names += self.preload_names
        forced = self.force_data
        self.length_names = ["length_m"] if length_prior is not None else []
        self.height_names = [height_error_name(d.id) for d in forced] if self.height_sd_m > 0 else []
        self.offset_names = [force_offset_name(d.id) for d in forced] if self.force_offsets else []
        names += self.length_names + self.height_names + self.offset_names
        self._init_diameters(spec, diameter, diameter_priors or {})
        names += self.diameter_names
        names += list(self.effects)
        self.names = names
        #: priors of per-dataset nuisances (docs/priors.md, "Nuisances of a real push"): preload uniform on
        #: [0, 0.1 L]; the stem length as given; a contact-height error N(0, sd) cut at 4 sd; a load-cell
        #: offset N(0, 5% of the push's peak force)
        self.nuisance_priors = {
            n: _uniform_prior(n, 0.0, PRELOAD_MAX_L * float(spec.length_m)) for n in self.preload_names
        }
        if length_prior is not None:
            self.nuisance_priors["length_m"] = length_prior
        sd = self.height_sd_m
        for n in self.height_names:
            self.nuisance_priors[n] = _prior(n, "truncnormal", (0.0, sd, -HEIGHT_CUT_SD * sd, HEIGHT_CUT_SD * sd), "m")
        for n, d in zip(self.offset_names, forced if self.offset_names else [], strict=True):
            scale = max(FORCE_OFFSET_SD * float(np.max(np.abs(d.F_N))), 1e-9)
            self.nuisance_priors[n] = _prior(n, "normal", (0.0, scale), "N")
        for n in self.diameter_names:
            self.nuisance_priors[n] = (diameter_priors or {}).get(n) or _diameter_priors()[n]
        self._build_tables()
        if self.geometry:
            self._build_geometry_tables()

    @property
    def force_data(self) -> list[PushData]:
        """The pushes with engaged force samples, in the order of the force tables' push index."""
        return [d for d in self.data if d.D_m.size]

    def _init_slip(self, slip: bool) -> None:
        """The slip term's data (docs/inference.md, "The slip"): per push with forces, the window
        (``slip_lo_m``, ``slip_hi_m``] its slip lies in (hi = inf where none was seen) and the softening
        ``slip_scale_m``. Off with an unknown length or height errors (the slip table is not on their
        axes) and with yield (the plastic branch moves the slip; not tabled)."""
        forced = self.force_data
        self.slip = slip and bool(forced) and not self.geometry and "yield" not in self.effects
        if not self.slip:
            return
        lo = np.array([d.engaged_to_m for d in forced])
        hi = np.array([d.slipped_by_m for d in forced])
        step = np.array([d.slip_step_m for d in forced])
        self.slip_lo_m = lo
        self.slip_hi_m = np.where(np.isfinite(hi), hi, np.inf)
        self.slip_scale_m = np.fmax(SLIP_SOFT_STEPS * np.nan_to_num(step, nan=0.0), SLIP_SOFT_REL * lo)

    def _slip_m(self, p: NDArray, u: NDArray | None, early: bool = False) -> NDArray:
        """The model's slip displacement [m] of each push with forces at p (W,) and effect coordinate u:
        (W, J), its loading branch's end; with ``early`` the earliest slip the model allows (where the
        force first comes within :data:`SLIP_FORCE_REL` of the end's)."""
        return self.L * self._interp(self.slip_table_early if early else self.slip_table, np.atleast_1d(p), u)

    def slip_displacement_m(self, params: dict, early: bool = False) -> NDArray:
        """The model's slip displacement of each push with forces [m], (W, J), at parameter arrays (W,):
        the branch end, or with ``early`` where the force first comes within SLIP_FORCE_REL of its end."""
        return self._slip_m(params["p"], self.effect_coordinate(params), early)

    def slip_loglik(self, p: NDArray, u: NDArray | None, preload_m: NDArray | None = None) -> NDArray:
        """log P(the slip lies in each push's window | p, effect), (W,): per push
        log Phi((D_end - lo) / tau) + log Phi((hi - D_early) / tau). The model's slip lies in
        [D_early, D_end]: D_end the branch end, D_early where the force first comes within
        :data:`SLIP_FORCE_REL` of the end's (tabled in p and the effect; a preload (W, J) [m] moves the
        window). Where the branch ends on a plateau the end's displacement is ill-conditioned, so the term
        asks only that the two windows overlap (docs/inference.md, "The slip"). Where no slip was seen hi
        is inf and its factor is 1."""
        D_end = self._slip_m(p, u)  # (W, J)
        D_early = self._slip_m(p, u, early=True)
        shift = 0.0 if preload_m is None else np.asarray(preload_m, float)
        lo, hi, tau = self.slip_lo_m + shift, self.slip_hi_m + shift, self.slip_scale_m
        return np.sum(special.log_ndtr((D_end - lo) / tau) + special.log_ndtr((hi - D_early) / tau), axis=1)

    def _init_diameters(self, spec: Specimen, diameter: str, priors: dict) -> None:
        """The width term's data and parameter names (docs/inference.md, "Young's modulus")."""
        if diameter not in DIAMETER_MODELS:
            raise ValueError(f"diameter: expected one of {', '.join(DIAMETER_MODELS)}, got {diameter!r}")
        self.diameter = diameter
        self.diameter_names = []
        if diameter == "off":
            return
        dm = spec.diameters
        if dm is None:
            raise ValueError(
                f"diameter: expected a dataset with measured diameters ('diameters' in specimen.json, or "
                f"bayesrod extract on frames) for model {diameter!r}, got none"
            )
        self.d_s, self.d_obs, self.d_sd = (np.asarray(a, float) for a in (dm.s_m, dm.d_m, dm.sd_m))
        self.d_offset_sd, self.d_scale_sd = dm.shared_offset_sd_m, dm.shared_scale_sd
        self.d_taper_sd = dm.shared_taper_sd
        self.n_diameters = int(self.d_s.size)
        self.diameter_names = ["d0_m"] + (["p_geom"] if diameter == "free" else [])
        # a profile of many stations calibrates its own sd scale and the correlation of neighbouring stations'
        # errors (AR(1) along s: they share pixels, background and the frame's stem colour); a few caliper
        # readings are taken as given and independent
        order = np.argsort(self.d_s, kind="stable")
        self.d_s, self.d_obs, self.d_sd = self.d_s[order], self.d_obs[order], self.d_sd[order]
        if self.n_diameters >= DIAMETER_SCALE_MIN:
            self.diameter_names += ["diameter_sd_scale", "rho_diameter"]
            gap = np.diff(self.d_s)
            # a chain of neighbouring stations breaks where stations are missing (flagged, occluded)
            self.d_first = np.concatenate([[True], gap > 1.5 * float(np.median(gap))])
        else:
            self.d_first = None

    def predict_diameter(self, params: dict, s_m: NDArray | None = None) -> NDArray:
        """(W, k) diameter d0 (1 - s/L)^p_geom [m] at ``s_m`` (default: the measured stations); p_geom = p
        under the uniform-modulus model; each walker's own L where the length is sampled."""
        s = self.d_s if s_m is None else np.asarray(s_m, float)
        d0 = np.atleast_1d(np.asarray(params["d0_m"], float))[:, None]
        pg = np.atleast_1d(np.asarray(params["p_geom" if self.diameter == "free" else "p"], float))[:, None]
        L = np.atleast_1d(np.asarray(params.get("length_m", self.L), float))[:, None]
        return stem_diameter(s[None, :], d0, pg, L)

    def diameter_start(self, p_geom: float) -> dict:
        """Least-squares d0 [m] at taper ``p_geom`` (the given L) and the sd scale of its residuals."""
        g = stem_diameter(self.d_s, 1.0, p_geom, self.L)
        w = 1.0 / self.d_sd**2
        d0 = float(np.sum(w * g * self.d_obs) / max(np.sum(w * g * g), 1e-300))
        z = (self.d_obs - d0 * g) / self.d_sd
        out = {"d0_m": max(d0, 1e-6)}
        if "diameter_sd_scale" in self.diameter_names:
            out["diameter_sd_scale"] = float(np.clip(np.sqrt(np.mean(z**2)), 0.05, 20.0))
            out["rho_diameter"] = float(np.clip(np.mean(z[1:] * z[:-1]) / max(np.mean(z**2), 1e-12), -0.4, 0.95))
        if "p_geom" in self.diameter_names:
            out["p_geom"] = p_geom
        return out

    def _diameter_loglik(self, params: dict) -> NDArray:
        """Log density of the measured widths: each station's own error (AR(1) along s with a fitted
        sd scale for a profile; independent for a few caliper readings), plus the offset, scale and taper
        errors all stations share, marginalised exactly (rank-k update, :func:`shared_error_loglik`)."""
        pred = self.predict_diameter(params)
        W = pred.shape[0]
        if self.d_first is None:
            scale, rho, first = np.ones((W, 1)), np.zeros((W, 1)), np.ones(self.n_diameters, bool)
        else:
            scale = np.atleast_1d(np.asarray(params["diameter_sd_scale"], float))[:, None]
            rho = np.atleast_1d(np.asarray(params["rho_diameter"], float))[:, None]
            first = self.d_first
        d0 = np.atleast_1d(np.asarray(params["d0_m"], float))[:, None]
        return width_loglik(
            self.d_obs, pred, self.d_sd, scale, rho, first, self.d_offset_sd, self.d_scale_sd, self.d_taper_sd, d0
        )

    # ------------------------------------------------------------------ tables
    def _build_tables(self) -> None:
        """Tables (E, P, N): E = 1 without a tabled effect. The force curves of every push (and effect
        node) come from one batched set of solves."""
        etas = np.array([d.height_m / self.L for d in self.data])
        J = etas.size
        if self.axis is None:
            curves = ForceCurves.batch(etas, self.p_grid)
            self._build_tables_at(None, curves)
            for k in ("f_table", "normal_table", "slip_table", "slip_table_early"):
                setattr(self, k, getattr(self, k)[None])
            return
        nodes = [self.axis.nondim(u) for u in self.axis.grid]
        (key,) = nodes[0]
        vals = np.repeat([float(e[key]) for e in nodes], J)
        curves = ForceCurves.batch(np.tile(etas, len(nodes)), self.p_grid, effects_nd={key: vals})
        stacks = {"f_table": [], "normal_table": [], "slip_table": [], "slip_table_early": []}
        for i, eff in enumerate(nodes):
            self._build_tables_at(eff, curves[i * J : (i + 1) * J])
            for k in stacks:
                stacks[k].append(getattr(self, k))
        for k, v in stacks.items():
            setattr(self, k, np.stack(v))

    def _build_tables_at(self, eff_nd: dict | None, all_curves: list) -> None:
        L, pg = self.L, self.p_grid
        self._preload_tables = []
        self._preload_shapes = []
        fF, fobs, fh, ns, xobs, zobs, sd, pid, fid = [], [], [], [], [], [], [], [], []
        ends, earlies = [], []
        for d, curves in zip(self.data, all_curves, strict=True):
            eta = d.height_m / L
            if d.D_m.size:
                fF.append(curves.force(d.D_m / L))
                ends.append(curves.d_end)
                earlies.append(curves.d_early)
                if self.preload:
                    # a dense table in d for this push: the force at D + preload, linear in d between nodes
                    top = float(d.D_m.max()) / L + PRELOAD_MAX_L
                    dg = np.linspace(0.0, top, PRELOAD_GRID)
                    self._preload_tables.append((dg[1] - dg[0], curves.force(dg), d.D_m / L))
                fobs.append(d.F_N)
                fh.append(np.full(d.F_N.size, d.height_m))
            if d.x_m.size:
                if self.preload and d.D_m.size:
                    first = sum(x.shape[1] for x in ns)  # the push's first point among all observed points
                    table = self._preload_shape_table(d, eta, curves, len(fobs) - 1)
                    self._preload_shapes.append(table | {"points": slice(first, first + d.x_m.size)})
                ns.append(self._shape_table(d, eta, curves))
                xobs.append(d.x_m)
                zobs.append(d.z_m)
                pid.append(np.full(d.x_m.size, len(pid)))
                fid.append(d.frame_index)
                if self.shape_has_sd:
                    sd.append(d.sd_m)
        P = pg.size
        self.f_table = np.concatenate(fF, axis=1) if fF else np.zeros((P, 0))  # (P, N); stacked to (E, P, N)
        self.F_obs = np.concatenate(fobs) if fobs else np.zeros(0)
        # the nondimensional slip displacement (the branch end) of each push with forces, (P, J)
        self.slip_table = np.stack(ends, axis=1) if ends else np.zeros((P, 0))
        # and where its force first comes within SLIP_FORCE_REL of the end's (the earliest slip the model allows)
        self.slip_table_early = np.stack(earlies, axis=1) if earlies else np.zeros((P, 0))
        # the first force sample of each push: an AR(1) noise chain restarts there
        self.F_push = np.concatenate([np.full(f.size, k) for k, f in enumerate(fobs)]) if fobs else np.zeros(0, int)
        self.F_first = _chain_starts(self.F_push)
        self.F_height = np.concatenate(fh) if fh else np.zeros(0)
        self.normal_table = np.concatenate(ns, axis=1) if ns else np.zeros((P, 0))  # obs minus model, normal
        self.x_obs = np.concatenate(xobs) if xobs else np.zeros(0)
        self.z_obs = np.concatenate(zobs) if zobs else np.zeros(0)
        self.sd_obs = np.concatenate(sd) if sd else None
        self.point_push = np.concatenate(pid) if pid else np.zeros(0, int)  # (k,) push of each point
        self.point_frame = np.concatenate(fid) if fid else np.zeros(0, int)  # (k,) frame within its push

    def _build_geometry_tables(self) -> None:
        """Per push, forces on a grid of stem lengths x contact-height errors: (A, B, P, N_j) each.

        L enters both nondimensional groups (d = D/L, eta = h/L); the length axis is uniform in log L
        over the prior's support (:data:`LENGTH_NODES` nodes, 4-point Lagrange), the height axis uniform
        over +-:data:`HEIGHT_CUT_SD` sd (:func:`height_nodes` nodes, 4-point Lagrange). One batched set of
        forward solves.
        """
        if self.length_prior is not None:
            lo, hi = self.length_prior.bounds()
            self.L_grid = np.exp(np.linspace(np.log(lo), np.log(hi), LENGTH_NODES))
        else:
            self.L_grid = np.array([self.L])
        sd = self.height_sd_m
        forced = self.force_data
        if sd > 0:
            n = height_nodes(sd, min(d.height_m for d in forced))
            self.dh_grid = HEIGHT_CUT_SD * sd * np.linspace(-1.0, 1.0, n)
        else:
            self.dh_grid = np.zeros(1)
        etas = np.array([(d.height_m + b) / a for d in forced for a in self.L_grid for b in self.dh_grid])
        curves = ForceCurves.batch(etas, self.p_grid, n_f=GEOMETRY_N_F)
        A, B = self.L_grid.size, self.dh_grid.size
        self._geom_tables = []
        for j, d in enumerate(forced):
            T = np.empty((A, B, self.p_grid.size, d.D_m.size))
            for a, La in enumerate(self.L_grid):
                for b in range(B):
                    T[a, b] = curves[(j * A + a) * B + b].force(d.D_m / La)
            self._geom_tables.append(T)

    def predict_nd_force_geometry(self, p: NDArray, length_m: NDArray, height_error_m: NDArray) -> NDArray:
        """Nondimensional force F L^2/EI0 at every engaged sample for stem lengths and height errors.

        ``p`` and ``length_m`` (W,), ``height_error_m`` (W, J) [m] (one per push with forces; ignored
        without a height axis); returns (W, N).
        """
        p = np.atleast_1d(np.asarray(p, float))
        W = p.size
        ip, wp = _lagrange4(self.p_grid, p)
        if self.L_grid.size > 1:
            iL, wL = _lagrange4(np.log(self.L_grid), np.log(np.broadcast_to(np.asarray(length_m, float), (W,))))
        else:
            iL, wL = np.zeros((W, 1), int), np.ones((W, 1))
        out = []
        for j, T in enumerate(self._geom_tables):
            if self.dh_grid.size > 1:
                iB, wB = _lagrange4(self.dh_grid, np.asarray(height_error_m, float)[:, j])
            else:
                wB, iB = np.ones((W, 1)), np.zeros((W, 1), int)
            g = T[iL[:, :, None, None], iB[:, None, :, None], ip[:, None, None, :]]  # (W, a, b, p, N_j)
            out.append(np.einsum("wa,wb,wp,wabpn->wn", wL, wB, wp, g))
        return np.concatenate(out, axis=1)

    def _shape_table(self, d: PushData, eta: float, curves: ForceCurves):
        """The signed normal offset [m] of every observed point of the push from the centerline at each p
        node, (P, k).

        The likelihood interpolates the offsets (:func:`centerline_normal_offsets`), not x and cos(phi)
        apart: where the stem is nearly horizontal at a point's height, or its top passes through it,
        x(z) jumps by centimetres between neighbouring nodes while the offset moves smoothly. Read as
        (x_obs - x) cos(phi), a noise-free centerline lay 20 sds off its own curve between nodes
        (scripts/sbc_geometry.py seed 47: p 0.009, rest curvature 1.2 1/m, the last frames before the
        slip; docs/validation.md).
        """
        L, pg = self.L, self.p_grid
        d_nd = d.frame_D_m / L
        # shapes past a node's slip go on along their tangent in d (as the force does, ForceCurves.force):
        # two extra columns, the shape at d_end and DELTA before it, give the slope
        d_end = curves.d_end
        step = np.minimum(SHAPE_END_STEP, 0.5 * d_end)
        f_end = [fn(np.array([de, de - st])) for fn, de, st in zip(curves._interp, d_end, step, strict=True)]
        f_t = np.concatenate([curves.force(d_nd, continued=False), np.array(f_end)], axis=1)  # (P, M + 2)
        P, M = f_t.shape[0], d_nd.size
        r = contact_from_force_nd(f_t, eta, pg[:, None], curves.effects_nd, keep_shape=True)
        grid = r["grid"]  # (n + 1, 3, P, M + 2)
        npt = np.empty((P, d.x_m.size))
        for m in range(M):
            sel = d.frame_index == m
            z, xo = d.z_m[sel] / L, d.x_m[sel] / L
            npt[:, sel] = centerline_normal_offsets(grid[:, :, :, m], xo, z) * L  # exact Hermite, no resampling
            past = d_nd[m] - d_end
            go_on = (past > 0.0) & (step > 0.0)
            if go_on.any():
                n1 = centerline_normal_offsets(grid[:, :, go_on, M], xo, z)
                n0 = centerline_normal_offsets(grid[:, :, go_on, M + 1], xo, z)
                r_ = (past[go_on] / step[go_on])[:, None]
                npt[np.ix_(go_on, sel)] += r_ * (n1 - n0) * L
        return npt

    def _preload_shape_table(self, d: PushData, eta: float, curves: ForceCurves, column: int) -> dict:
        """A preloaded push's shape residuals for any preload (:meth:`shape_offsets_preloaded`).

        A preload moves every frame of the push further along the branch by one unknown displacement.
        The table holds the normal offset [m] of every observed point of the push with its frames moved
        by each of :data:`PRELOAD_SHAPE_NODES` preloads spread evenly over the prior's [0, PRELOAD_MAX_L L],
        (G, P, k), from :meth:`_shape_table` (so past the slip as it continues them). Linear in the preload
        between nodes: a point's x at fixed height has kinks in the displacement (where the stem's top
        passes below it, at the slip) that a higher-order rule spreads over neighbouring nodes.
        """
        grid = np.linspace(0.0, PRELOAD_MAX_L * self.L, PRELOAD_SHAPE_NODES)
        P, M, K = self.p_grid.size, d.frame_D_m.size, d.x_m.size
        per = max(1, PRELOAD_SHAPE_COLUMNS // (P * M))  # preload nodes solved together (one batched march)
        ns = []
        for start in range(0, grid.size, per):
            g = grid[start : start + per]
            n = g.size
            tiled = replace(
                d,
                frame_D_m=(d.frame_D_m[None, :] + g[:, None]).ravel(),
                frame_index=(d.frame_index[None, :] + M * np.arange(n)[:, None]).ravel(),
                x_m=np.tile(d.x_m, n),
                z_m=np.tile(d.z_m, n),
                sd_m=None,
            )
            normal = self._shape_table(tiled, eta, curves)  # (P, n K)
            ns.append(normal.reshape(P, n, K).transpose(1, 0, 2))
        return {
            "step_m": grid[1] - grid[0],
            "normal": np.concatenate(ns),
            "column": column,  # the push's index among the pushes with forces (its preload)
        }

    # -------------------------------------------------------------- evaluation
    def _weights(self, p: NDArray, u: NDArray | None):
        """Gather indices and weights: p (W,4); effect axis (W,4) or a single node."""
        ip, wp = _lagrange4(self.p_grid, p)
        if self.axis is None:
            return ip, wp, np.zeros((p.size, 1), int), np.ones((p.size, 1))
        ie, we = _lagrange4(self.axis.grid, np.asarray(u, float))
        return ip, wp, ie, we

    def _interp(self, table: NDArray, p: NDArray, u: NDArray | None, weights=None) -> NDArray:
        """``table`` (E, P, N) at p (W,) and effect coordinate u: (W, N). ``weights``: from
        :meth:`_gather_weights` for the same p and u (the tables of one evaluation share them)."""
        ip, wp, ie, we = weights if weights is not None else self._gather_weights(p, u)
        if self.axis is None:  # one effect node: a (W, 4) @ (W, 4, N) product
            return np.matmul(wp[:, None, :], table[0][ip])[:, 0, :]
        g = table[ie[:, :, None], ip[:, None, :]]  # (W, 4e, 4p, N)
        w = we[:, :, None] * wp[:, None, :]
        W, N = g.shape[0], g.shape[-1]
        return np.matmul(w.reshape(W, 1, -1), g.reshape(W, -1, N))[:, 0, :]

    def _gather_weights(self, p: NDArray, u: NDArray | None):
        p = np.atleast_1d(np.asarray(p, float))
        if self.axis is not None and u is None:
            u = np.zeros(p.shape)  # the neutral value of every tabled effect
        return self._weights(p, u)

    def effect_coordinate(self, params: dict) -> NDArray | None:
        """Table coordinate of the tabled effect (W,), or None."""
        if self.axis is None:
            return None
        return self.axis.coordinate(
            np.atleast_1d(params[self.axis.name]), np.atleast_1d(np.asarray(params["EI0"], float)), self.L
        )

    def in_table(self, params: dict) -> NDArray:
        """True where the tabled effect's coordinate lies inside the table (always True without one)."""
        u = self.effect_coordinate(params)
        if u is None:
            return np.ones(np.atleast_1d(params["p"]).shape, bool)
        return (u >= self.axis.grid[0]) & (u <= self.axis.grid[-1])

    def predict_nd_force_preloaded(self, p: NDArray, preload_m: NDArray) -> NDArray:
        """Nondimensional force at every engaged sample with each push's preload added to its displacement.

        ``p`` (W,), ``preload_m`` (W, J) [m]; returns (W, N). Linear interpolation in d on a
        :data:`PRELOAD_GRID`-node table per push, 4-point Lagrange in p.
        """
        p = np.atleast_1d(np.asarray(p, float))
        ip, wp = _lagrange4(self.p_grid, p)
        out = []
        for j, (step, table, d_nd) in enumerate(self._preload_tables):
            d = d_nd[None, :] + np.asarray(preload_m, float)[:, j : j + 1] / self.L  # (W, N_j)
            u = np.clip(d / step, 0.0, table.shape[1] - 1.000001)
            k = np.floor(u).astype(int)
            t = u - k
            g0 = table[ip[:, :, None], k[:, None, :]]
            g1 = table[ip[:, :, None], k[:, None, :] + 1]
            out.append(np.einsum("wa,wan->wn", wp, g0 + t[:, None, :] * (g1 - g0)))
        return np.concatenate(out, axis=1)

    def shape_offsets_preloaded(self, p: NDArray, preload_m: NDArray) -> NDArray:
        """:meth:`shape_offsets` with each push's frames moved by its preload along the branch, (W, k) [m].

        ``p`` (W,), ``preload_m`` (W, J) [m] (one per push with forces). Linear in the preload between
        the nodes of :meth:`_preload_shape_table`, 4-point Lagrange in p. A push with frames but no
        forces has no preload: its points come from the plain shape table.
        """
        p = np.atleast_1d(np.asarray(p, float))
        W = p.size
        pre = np.asarray(preload_m, float).reshape(W, -1)
        ip, wp = _lagrange4(self.p_grid, p)  # (W, 4)
        out = self.shape_offsets(p).copy()
        for t in self._preload_shapes:
            G = t["normal"].shape[0]
            v = np.clip(pre[:, t["column"]] / t["step_m"], 0.0, G - 1.000001)
            g = np.floor(v).astype(int)
            w = np.stack([1.0 - (v - g), v - g], axis=1)[:, :, None] * wp[:, None, :]  # (W, 2, 4)
            rows = (g[:, None, None] + np.arange(2)[None, :, None], ip[:, None, :])  # (W, 2, 4) each
            out[:, t["points"]] = np.matmul(w.reshape(W, 1, 8), t["normal"][rows].reshape(W, 8, -1))[:, 0, :]
        return out

    def _force_log_table(self) -> NDArray | None:
        """log(f_table + FORCE_LOG_FLOOR), cached for the current ``f_table``; None (read linearly) without an
        axis of ``LOG_FORCE_EFFECTS`` or where a force is negative."""
        if getattr(self, "_f_log_of", None) is not self.f_table:  # built, restricted or without the axis: anew
            self._f_log = force_log_table(self.f_table, self.axis)
            self._f_log_of = self.f_table
        return self._f_log

    def interp_force(self, p: NDArray, u: NDArray | None = None, weights=None) -> NDArray:
        """The force table at p (W,) and effect coordinate u, (W, N) nondimensional: in log space on a friction axis
        (``LOG_FORCE_EFFECTS``), else linearly."""
        table = self._force_log_table()
        if table is None:
            return self._interp(self.f_table, p, u, weights)
        return np.exp(self._interp(table, p, u, weights)) - FORCE_LOG_FLOOR

    def predict_nd_force(self, p: NDArray, u: NDArray | None = None) -> NDArray:
        """Nondimensional force at every engaged sample, (W, N).

        Past a p's branch end the force goes on along the curve's end tangent
        (:meth:`ForceCurves.force`), so the forces stay smooth in p. Where the slip lies is a separate
        term of the likelihood (:meth:`slip_loglik`): a rule "slipped means zero" alone would say only
        "not yet slipped" for engaged samples and bias p toward late slips when a push stops at its slip.
        """
        return self.interp_force(p, u)

    def shape_offsets(self, p: NDArray, u: NDArray | None = None, weights=None) -> NDArray:
        """Signed normal offset [m] of every observed point from the centerline, (W, M): the shape
        residual, observed minus model (:meth:`_shape_table`)."""
        return self._interp(self.normal_table, p, u, weights)

    def residuals(self, params: dict) -> dict:
        """Force and shape residuals (observed - predicted) for parameter arrays of shape (W,)."""
        p = np.atleast_1d(np.asarray(params["p"], float))
        EI0 = np.atleast_1d(np.asarray(params["EI0"], float))
        out = {}
        u = self.effect_coordinate(params)
        weights = None  # the gather weights in p (and u), shared by the force and shape tables
        if self.n_force:
            heights = self.F_height[None, :]
            if self.preload and all(n in params for n in self.preload_names):
                pre = self._per_push(params, self.preload_names, p.size)
                F = EI0[:, None] / self.L**2 * self.predict_nd_force_preloaded(p, pre)
            elif self.geometry:
                Lw = np.broadcast_to(np.atleast_1d(np.asarray(params.get("length_m", self.L), float)), p.shape)
                dh = self._per_push(params, self.height_names, p.size)
                F = EI0[:, None] / Lw[:, None] ** 2 * self.predict_nd_force_geometry(p, Lw, dh)
                heights = heights + dh[:, self.F_push]
            else:
                weights = self._gather_weights(p, u)
                F = EI0[:, None] / self.L**2 * self.interp_force(p, u, weights)
            if "yield" in params:
                F = np.minimum(F, np.atleast_1d(params["yield"])[:, None] / heights)
            if "force_offset" in params:
                F = F + np.atleast_1d(params["force_offset"])[:, None]
            if self.offset_names:
                F = F + self._per_push(params, self.offset_names, p.size)[:, self.F_push]
            out["force"] = self.F_obs[None, :] - F
        if self.n_points:
            if self.preload and all(n in params for n in self.preload_names):
                out["shape"] = self.shape_offsets_preloaded(p, self._per_push(params, self.preload_names, p.size))
            else:
                out["shape"] = self.shape_offsets(p, u, weights)
        return out

    def _per_push(self, params: dict, names: list[str], W: int) -> NDArray:
        """(W, J) per-push nuisance values (zeros where not fitted or not given)."""
        J = int(self.F_push.max(initial=-1)) + 1
        if not names or not all(n in params for n in names):
            return np.zeros((W, J))
        return np.stack([np.broadcast_to(np.atleast_1d(np.asarray(params[n], float)), (W,)) for n in names], axis=1)

    def restricted(self, mask: NDArray) -> RodLikelihood:
        """The same forces-only likelihood on the force samples where ``mask`` (N,) is True: the tables
        are sliced, not rebuilt (a held-out refit of the same pushes)."""
        mask = np.asarray(mask, bool)
        if mask.shape != self.F_obs.shape:
            raise ValueError(f"mask: expected shape {self.F_obs.shape}, got {mask.shape}")
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.f_table = self.f_table[..., mask]
        new.F_obs, new.F_push, new.F_height = self.F_obs[mask], self.F_push[mask], self.F_height[mask]
        new.F_first = _chain_starts(new.F_push)
        new.n_force = int(mask.sum())
        new.slip = False  # where the slip lies is data at the push's end: held out with it (conservative)
        return new

    def without_effect_axis(self) -> RodLikelihood:
        """The same data with the tabled effect at its neutral value (the u = 0 slice of the tables)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        if self.axis is not None:
            if self.axis.grid[0] != 0.0:
                raise ValueError(f"effect {self.axis.name}: expected a table axis starting at the neutral value 0")
            for k in ("f_table", "normal_table", "slip_table", "slip_table_early"):
                setattr(new, k, getattr(self, k)[:1])
            new.axis = None
        new.effects = tuple(e for e in self.effects if e not in TABLE_EFFECTS)
        return new

    def log_likelihood(self, params: dict) -> NDArray:
        """Sum of Gaussian log densities; parameter arrays of shape (W,), result (W,)."""
        res = self.residuals(params)
        ll = np.zeros(np.atleast_1d(params["p"]).shape)
        if self.slip:
            pre = None
            if self.preload and all(n in params for n in self.preload_names):
                pre = self._per_push(params, self.preload_names, ll.size)
            ll += self.slip_loglik(params["p"], self.effect_coordinate(params), pre)
        if "force" in res:
            s = np.atleast_1d(params["sigma_force_N"])[:, None]
            if self.offset_prior_sd:
                ll += shared_error_loglik(res["force"], s, self._rho(params, s), self.F_first, [self._offset_column()])
            elif self.force_noise == "ar1":
                ll += ar1_loglik(res["force"], s, self._rho(params, s), self.F_first)
            else:
                ll += np.sum(-0.5 * (res["force"] / s) ** 2 - np.log(s), axis=1) - 0.5 * self.n_force * _LOG_2PI
        if "shape" in res:
            # sd = scale x sd_obs (or sigma_shape_m): sum log sd = M log scale + sum log sd_obs
            if self.shape_has_sd:
                scale = np.atleast_1d(params["shape_sd_scale"])
                sum_log_sd = float(np.sum(np.log(self.sd_obs)))
                q = np.sum((res["shape"] / self.sd_obs[None, :]) ** 2, axis=1)
            else:
                scale = np.atleast_1d(params["sigma_shape_m"])
                sum_log_sd = 0.0
                q = np.sum(res["shape"] ** 2, axis=1)
            ll_shape = -0.5 * q / scale**2 - self.n_points * np.log(scale) - sum_log_sd - 0.5 * self.n_points * _LOG_2PI
            ll += self.shape_weight * ll_shape
        if self.diameter != "off":
            ll += self._diameter_loglik(params)
        return ll

    def _rho(self, params: dict, s: NDArray) -> NDArray:
        """(W, 1) lag-1 correlation of the force noise (zeros for independent noise)."""
        return np.atleast_1d(params["rho_force"])[:, None] if self.force_noise == "ar1" else np.zeros_like(s)

    def _offset_column(self) -> NDArray:
        return np.full((1, self.n_force), float(self.offset_prior_sd))

    def offset_posterior(self, params: dict) -> tuple[NDArray, NDArray]:
        """Mean and sd [N], each (W,), of the integrated-out force offset (``offset_prior_sd``) given the
        other parameters: Gaussian, a = sd b / M and sd / sqrt(M) with M = 1 + u^T S^-1 u, b = u^T S^-1 r
        (u the constant column of the prior sd, r the force residuals, S the noise covariance; by whitening)."""
        if not self.offset_prior_sd:
            raise ValueError("offset_posterior: expected a likelihood with offset_prior_sd set, got none")
        r = self.residuals(params)["force"]
        s = np.atleast_1d(params["sigma_force_N"])[:, None]
        M, b = shared_error_terms(r, s, self._rho(params, s), self.F_first, [self._offset_column()])
        M, b = M[:, 0, 0], b[:, 0]
        return self.offset_prior_sd * b / M, self.offset_prior_sd / np.sqrt(M)

    def fit_error(self, params: dict) -> dict:
        """RMS force error [N] and shape error [mm] at one parameter set (docs/format.md: summary.fit_error)."""
        res = self.residuals({k: np.atleast_1d(v) for k, v in params.items()})
        out = {}
        f = res.get("force")  # engaged samples only (see prepare_data)
        out["force_rmse_N"] = float(np.sqrt(np.mean(f**2))) if f is not None and f.size else None
        out["shape_rmse_mm"] = float(1000 * np.sqrt(np.mean(res["shape"] ** 2))) if "shape" in res else None
        if self.diameter != "off":
            r = self.d_obs - self.predict_diameter({k: np.atleast_1d(v) for k, v in params.items()})[0]
            out["diameter_rmse_mm"] = float(1000 * np.sqrt(np.mean(r**2)))
        return out


FORCE_NOISE_MODELS = ("iid", "ar1")
#: the model's slip lies between the branch end and where the force first comes within this fraction of the
#: end's force: on a plateau (seed 240 of the SBC: D 0.54 L at 99.9% of the end force, 0.816 L at its end)
#: the end's displacement is ill-conditioned, this is not (docs/inference.md, "The slip")
SLIP_FORCE_REL = 1e-3
#: the slip term's softening (docs/inference.md, "The slip"): the larger of half the robot's last step
#: before the slip and 0.5% of the largest engaged displacement (the tables' and the detection's error)
SLIP_SOFT_STEPS = 0.5
SLIP_SOFT_REL = 0.005
#: the width term (docs/inference.md, "Young's modulus"): off; d(s) = d0 (1 - s/L)^p (a stem of uniform
#: modulus: geometry and bending share p); or d(s) = d0 (1 - s/L)^p_geom with p_geom free (E(s) may vary)
DIAMETER_MODELS = ("off", "shared", "free")
#: a diameter profile of at least this many stations gets its own sd scale (diameter_sd_scale)
DIAMETER_SCALE_MIN = 8
#: a preload is at most this fraction of the stem length (its prior: uniform on [0, PRELOAD_MAX_L L])
PRELOAD_MAX_L = 0.1
#: nodes of the per-push force table in d that a preload needs (linear interpolation between them)
PRELOAD_GRID = 2001
#: preload nodes of a preloaded push's shape table over [0, PRELOAD_MAX_L L], linear between them
#: (docs/performance.md, "A preload with centerlines")
PRELOAD_SHAPE_NODES = 41
#: p nodes x frames solved in one batched march when building those tables
PRELOAD_SHAPE_COLUMNS = 6000


#: nuisances of a real push (docs/priors.md): nodes of the log-uniform stem-length table axis (a push taken to its
#: branch end crosses the end of shorter stems' branches along this axis, where the curves go on along their end
#: tangent: C1, so the error falls as the node step squared; on a noise-free twig pushed to its slips the
#: maximum-likelihood estimate moved by up to 0.48 sd with 13 nodes, 0.058 with 37, 0.037 with 49: docs/validation.md,
#: "Session 56"); the
#: default length prior for a length given as approximate: uniform on [L / LENGTH_FACTOR, L LENGTH_FACTOR]
#: (above the highest contact); the contact-height error's prior is cut at HEIGHT_CUT_SD sd; the per-push
#: load-cell offset has sd FORCE_OFFSET_SD x the push's peak force
LENGTH_NODES = 49
#: forward solves per force curve of the geometry tables (160 for the plain tables): tested within 1e-4 of
#: the peak force against the plain tables (tests/test_nuisances.py)
GEOMETRY_N_F = 80
LENGTH_FACTOR = 1.5
HEIGHT_CUT_SD = 4.0
#: the contact-height error axis (4-point Lagrange over +-HEIGHT_CUT_SD sd): at least HEIGHT_NODES nodes, spaced
#: at most HEIGHT_STEP_FRACTION of the lowest contact height (:func:`height_nodes`)
HEIGHT_NODES = 5
HEIGHT_STEP_FRACTION = 0.025
FORCE_OFFSET_SD = 0.05


def _diameter_priors() -> dict:
    return {
        # base diameter: log-normal, median 1 cm, 95% in [0.5 mm, 19 cm] (grasses to canes)
        "d0_m": _prior("d0_m", "lognormal", (0.01, 1.5), "m"),
        "diameter_sd_scale": _prior("diameter_sd_scale", "lognormal", (1.0, 0.5), "1"),
        "p_geom": _prior("p_geom", "truncnormal", (0.8, 0.8, 0.0, 3.0), "1"),
        "rho_diameter": _uniform_prior("rho_diameter", -0.5, 0.995),
    }


def default_length_prior(spec: Specimen):
    """Uniform on [L/1.5, 1.5 L] of the given (approximate) length, above 1.05 x the highest contact."""
    L = float(spec.length_m)
    lo = max(L / LENGTH_FACTOR, 1.05 * max(p.height_m for p in spec.pushes))
    return _prior("length_m", "uniform", (lo, L * LENGTH_FACTOR), "m")


def height_nodes(sd_m: float, lowest_height_m: float) -> int:
    """Nodes of the contact-height error axis for an error sd ``sd_m`` [m] and the lowest contact [m].

    The force moves with the contact height about as h^-3, so the axis (uniform over +-:data:`HEIGHT_CUT_SD`
    sd, 4-point Lagrange) is spaced by at most :data:`HEIGHT_STEP_FRACTION` of the lowest contact, and has at
    least :data:`HEIGHT_NODES` nodes. Three nodes read quadratically (until session 58) moved the estimate of a
    noise-free three-height push with contacts from 0.30 m by up to 0.27 sd at an sd of 3 mm and by 41 sd at
    15 mm; 5 nodes by at most 0.002 sd at 3 mm (spaced by 2% of the lowest contact) and 0.84 sd at 15 mm (10%),
    17 (2.5%) by at most 0.003 sd (scripts/table_height_shift.py; docs/validation.md, "Session 58").
    """
    span = 2.0 * HEIGHT_CUT_SD * float(sd_m)
    return max(HEIGHT_NODES, 1 + math.ceil(span / (HEIGHT_STEP_FRACTION * float(lowest_height_m)) - 1e-9))


def _check_height_sd(height_sd_m, spec: Specimen) -> float:
    if isinstance(height_sd_m, bool) or not isinstance(height_sd_m, (int, float)) or not np.isfinite(height_sd_m):
        raise ValueError(f"height_sd_m: expected a contact-height sd >= 0 in metres, got {height_sd_m!r}")
    h_min = min(p.height_m for p in spec.pushes)
    if not 0 <= height_sd_m <= 0.05 * h_min:
        raise ValueError(
            f"height_sd_m: expected a contact-height sd in [0, {0.05 * h_min:g}] m (5% of the lowest contact), "
            f"got {height_sd_m:g}"
        )
    return float(height_sd_m)


def _chain_starts(push: NDArray) -> NDArray:
    """True at each push's first force sample (where an AR(1) noise chain restarts), from the push index (N,)."""
    push = np.asarray(push)
    return np.r_[True, push[1:] != push[:-1]] if push.size else np.zeros(0, bool)


def geometry_blocker(spec: Specimen, effects, *, use_forces=True, use_shapes=True, preload=False) -> str | None:
    """Why a sampled length or contact-height error cannot be tabled in this fit (None: it can).

    The geometry tables are forces only and the one extra table axis: no centerlines, no tabled effect,
    no preload beside them.
    """
    if not use_forces:
        return "a shape-only fit"
    if use_shapes and any(p.shapes for p in spec.pushes):
        return "centerlines are used (fit forces only)"
    tabled = [e for e in effects if e in TABLE_EFFECTS]
    if tabled or preload:
        return f"{tabled[0] if tabled else 'preload'} takes the one extra table axis"
    return None


def _check_nuisances(lik, effect_axis, use_forces: bool, use_shapes: bool) -> None:
    """The nuisances' combinations the tables support (one extra table axis, forces only)."""
    if lik.geometry:
        what = "length" if lik.length_prior is not None else "height_sd_m"
        why = geometry_blocker(
            lik.spec,
            [effect_axis.name] if effect_axis is not None else [],
            use_forces=use_forces,
            use_shapes=use_shapes,
            preload=lik.preload,
        )
        if why:
            raise ValueError(
                f"{what}: expected no tabled effect or preload and no centerlines beside an unknown length or "
                f"height error (forces only, one extra table axis), got {why}; fix the length (length 'known') "
                "or drop the other"
            )
        if lik.length_prior is not None:
            lo, hi = lik.length_prior.bounds()
            h_max = max(p.height_m for p in lik.spec.pushes)
            if not (np.isfinite(hi) and lo > h_max):
                raise ValueError(
                    f"prior length_m: expected a bounded prior above the highest contact ({h_max:g} m), "
                    f"got support [{lo:g}, {hi:g}] m"
                )
    if lik.force_offsets and "force_offset" in lik.effects:
        raise ValueError(
            "force_offsets: expected either one offset per push or the dataset-wide force_offset effect, got both"
        )


def height_error_name(push_id: str) -> str:
    """The parameter name of a push's contact-height error (m): ``height_error_m_<id>``."""
    return "height_error_m_" + _ident(push_id)


def force_offset_name(push_id: str) -> str:
    """The parameter name of a push's load-cell offset (N): ``force_offset_N_<id>``."""
    return "force_offset_N_" + _ident(push_id)


def _ident(push_id: str) -> str:
    import re

    return re.sub(r"[^0-9A-Za-z_]", "_", str(push_id))


def preload_name(push_id: str) -> str:
    """The parameter name of a push's preload (a displacement offset, m): ``preload_m_<id>``."""
    return "preload_m_" + _ident(push_id)


def _prior(name: str, dist: str, args: tuple, unit: str):
    from .priors import ParamPrior

    return ParamPrior(name, dist, tuple(float(a) for a in args), unit)


def _uniform_prior(name: str, lo: float, hi: float):
    return _prior(name, "uniform", (lo, hi), "m")


def ar1_innovations(r: NDArray, rho: NDArray, first: NDArray) -> tuple[NDArray, NDArray]:
    """Innovations of stationary AR(1) noise and their variance factors, O(n).

    ``r`` (..., N) residuals (any leading batch axes, e.g. walkers W), ``rho`` (..., 1), ``first`` (N,) True
    where a chain (a push) starts. Returns
    ``e`` = r_t - rho r_{t-1} (r_t at a chain's start) and ``v`` = 1 - rho^2 (1 at a start): given the
    marginal sd sigma, e_t ~ N(0, sigma^2 v_t) independently.
    """
    r = np.asarray(r, float)
    prev = np.concatenate([np.zeros(r.shape[:-1] + (1,)), r[..., :-1]], axis=-1)
    prev = np.where(first, 0.0, prev)
    e = r - rho * prev
    v = np.where(first, 1.0, 1.0 - rho**2)
    return e, v


def ar1_loglik(r: NDArray, sigma: NDArray, rho: NDArray, first: NDArray) -> NDArray:
    """Exact log density of residuals under stationary AR(1) noise per chain (marginal sd ``sigma``), O(n).

    With e_t = r_t - rho r_{t-1}: log p = sum_t [-log(2 pi)/2 - log sigma - log(v_t)/2 - e_t^2 / (2 sigma^2 v_t)],
    v_t = 1 - rho^2 (1 at each chain's first sample). Shapes: r (..., N), sigma and rho (..., 1) (any leading
    batch axes, e.g. walkers W); returns (...,).
    """
    e, v = ar1_innovations(r, rho, first)
    n = r.shape[-1]
    return (
        np.sum(-0.5 * e**2 / (sigma**2 * v) - 0.5 * np.log(v), axis=-1) - n * np.log(sigma[..., 0]) - 0.5 * n * _LOG_2PI
    )


def width_loglik(
    d_obs: NDArray,
    pred: NDArray,
    sd: NDArray,
    scale: NDArray,
    rho: NDArray,
    first: NDArray,
    offset_sd: float,
    scale_sd: float,
    taper_sd: float = 0.0,
    d0: NDArray | None = None,
) -> NDArray:
    """Log density (W,) of measured widths ``d_obs`` (N,) [m] given predicted ones ``pred`` (W, N).

    Each station's error has sd ``scale`` x ``sd`` (``sd`` (N,) or (W, N) [m], ``scale`` (W, 1)), AR(1)
    along s with correlation ``rho`` (W, 1) (chains start where ``first`` (N,)); an offset of sd
    ``offset_sd`` [m], a relative scale error of sd ``scale_sd`` and an error g in the taper of sd
    ``taper_sd`` (each width read as pred (pred / d0)^g, linearised: pred + g pred log(pred / d0), with
    ``d0`` (W, 1) [m] the predicted base diameter, so the base's width is left to the scale error) are
    shared by all stations and marginalised exactly (:func:`shared_error_loglik`). The width term of
    :class:`RodLikelihood` (docs/inference.md, "Young's modulus").
    """
    sd = np.broadcast_to(sd, pred.shape)
    z = (d_obs - pred) / sd
    shared = []
    if offset_sd > 0:
        shared.append(offset_sd / sd)
    if scale_sd > 0:
        shared.append(scale_sd * pred / sd)
    if taper_sd > 0:
        if d0 is None:
            raise TypeError("width_loglik: expected d0, the predicted base diameter (W, 1) [m], with taper_sd > 0")
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(pred > 0, pred * np.log(pred / d0), 0.0)  # -> 0 at a tip of zero width
        shared.append(taper_sd * slope / sd)
    return shared_error_loglik(z, scale, rho, first, shared) - np.sum(np.log(sd), axis=-1)


def shared_error_loglik(z: NDArray, sigma: NDArray, rho: NDArray, first: NDArray, shared: list) -> NDArray:
    """Log density of standardised residuals ``z`` (W, N) under AR(1) noise plus errors all points share.

    z = e + sum_j a_j u_j with e AR(1) (marginal sd ``sigma``, correlation ``rho``, both (W, 1); chains
    start where ``first`` (N,)) and independent a_j ~ N(0, 1) along each column u_j (W, N) of
    ``shared`` (an offset: a constant column; a scale error: the prediction). Exact and O(N k^2): with
    S the AR(1) covariance, U = [u_j], M = I + U^T S^-1 U and b = U^T S^-1 z (S^-1 applied by whitening),
    log p = ar1_loglik(z) + b^T M^-1 b / 2 - log det M / 2 (Woodbury, matrix determinant lemma).
    With no columns it is :func:`ar1_loglik`.
    """
    base = ar1_loglik(z, sigma, rho, first)
    if not shared:
        return base
    M, b = shared_error_terms(z, sigma, rho, first, shared)
    sol = np.linalg.solve(M, b[..., None])[..., 0]
    return base + 0.5 * np.sum(b * sol, axis=1) - 0.5 * np.linalg.slogdet(M)[1]


def shared_error_terms(z: NDArray, sigma: NDArray, rho: NDArray, first: NDArray, shared: list) -> tuple:
    """M = I + U^T S^-1 U (W, k, k) and b = U^T S^-1 z (W, k) of :func:`shared_error_loglik` (S^-1 applied by
    whitening with the AR(1) innovations). The coefficients a given z are Gaussian, mean M^-1 b, covariance M^-1."""

    def whiten(x):
        e, v = ar1_innovations(x, rho, first)
        return e / (sigma * np.sqrt(v))

    wu = np.stack([whiten(np.asarray(u, float)) for u in shared], axis=1)  # (W, k, N)
    M = np.eye(len(shared))[None] + np.einsum("wkn,wln->wkl", wu, wu)
    return M, np.einsum("wkn,wn->wk", wu, whiten(z))


class PosteriorBase(ParameterSpace):
    """Prior times ``self.likelihood`` in the sampling space; ``log_prob(theta)`` is what emcee sees.

    Subclasses set ``likelihood``, ``names``, ``priors``, ``_p_idx`` (the columns holding a taper
    exponent) and ``_p_bounds`` (the range the tables cover); ``_in_support`` may exclude parameter
    sets outside the tables.
    """

    _p_idx: list
    _p_bounds: tuple

    def log_prior(self, theta) -> NDArray:
        """The log prior density in the sampling space at ``theta`` (W, ndim) or (ndim,); shape (W,).

        Each parameter's prior at its prior coordinate, but an AR(1) force noise's sd prior at the log of its
        innovation sd sigma sqrt(1 - rho^2) (the sampled coordinate, :meth:`noise_pairs`) rather than at the
        marginal sd: the innovation sd is what a push pins, and a nearly flat prior on the marginal sd leans
        rho toward 1 along that ridge (docs/priors.md, "The force noise's sd under AR(1)")."""
        theta = np.atleast_2d(theta)
        jac = self.log_jacobian(theta)  # ParameterSpace: 0 but for a base spring sampled by its u
        pc = self.prior_coordinates(theta)
        for s, _ in self.noise_pairs():
            pc[:, s] = theta[:, s]  # log innovation sd: only the shear moves this column
        lp = sum(pr.logpdf_sample(pc[:, i]) for i, pr in enumerate(self.priors)) + jac
        return np.where(np.isfinite(jac), lp, -np.inf)  # nan coordinates outside u's (0, 1)

    def _in_support(self, natural: dict) -> NDArray:
        return np.ones(np.atleast_1d(next(iter(natural.values()))).shape, bool)

    def log_prob(self, theta) -> NDArray | float:
        theta_arr = np.asarray(theta, float)
        single = theta_arr.ndim == 1
        theta2 = np.atleast_2d(theta_arr)
        lp = self.log_prior(theta2)
        p = theta2[:, self._p_idx]
        ok = np.isfinite(lp) & np.all((p >= self._p_bounds[0]) & (p <= self._p_bounds[1]), axis=1)
        ok &= np.all(np.isfinite(theta2), 1)
        out = np.full(theta2.shape[0], -np.inf)
        if ok.any():
            nat = {k: v[ok] for k, v in self.to_natural(theta2).items()}
            inside = self._in_support(nat)
            ll = np.full(inside.shape, -np.inf)
            if inside.any():
                ll[inside] = self.likelihood.log_likelihood({k: v[inside] for k, v in nat.items()})
            out[ok] = np.where(np.isfinite(ll), lp[ok] + ll, -np.inf)
        return float(out[0]) if single else out


def one_height_stiffness(heights, lengths, length_sampled: bool) -> tuple[float, float] | None:
    """(h, L) when the pushes' ``heights`` [m] are all one h and their stems' ``lengths`` [m] one known L, else
    None: :attr:`ParameterSpace.stiffness_at`, the coordinates the sampler moves EI0 in."""
    hs, Ls = ({round(float(x), 9) for x in v} for v in (heights, lengths))
    return (hs.pop(), Ls.pop()) if len(hs) == 1 and len(Ls) == 1 and not length_sampled else None


class LogPosterior(PosteriorBase):
    """Prior times likelihood in the sampling space; ``log_prob(theta)`` is what emcee sees.

    ``theta`` has shape (ndim,) or (W, ndim): log EI0, p, then the noise terms
    in log space, then effect parameters (log for positive ones).
    """

    def __init__(self, likelihood: RodLikelihood, prior):
        self.likelihood = likelihood
        self.names = likelihood.names
        extra = getattr(likelihood, "nuisance_priors", {})
        self.priors = [extra[n] if n in extra else prior.get(n) for n in self.names]
        lo, hi = likelihood.p_grid[0], likelihood.p_grid[-1]
        plo, phi = self.priors[1].bounds()
        if getattr(likelihood, "p_window", None) is None and (plo < lo - 1e-12 or phi > hi + 1e-12):
            raise ValueError(f"prior p: expected support within the table range [{lo}, {hi}], got [{plo}, {phi}]")
        self._p_bounds = (max(lo, plo), min(hi, phi))
        self._p_idx = [1]
        # a base spring is sampled by its table coordinate u (ParameterSpace; any fixed L serves) on forces
        # alone: centerlines pin EI0 and p apart from the spring, and then log k is the better coordinate
        forces_only = not getattr(likelihood, "n_points", 0)
        self.base_length_m = float(likelihood.L) if "base_compliance" in self.names and forces_only else None
        # every push at one height on a known length: EI0 sampled as the log stiffness there (ParameterSpace)
        heights = [d.height_m for d in getattr(likelihood, "data", ())]  # (a stand-in likelihood may hold none)
        self.stiffness_at = one_height_stiffness(heights, [getattr(likelihood, "L", 1.0)], "length_m" in self.names)

    def _in_support(self, natural: dict) -> NDArray:
        return self.likelihood.in_table(natural)  # a tabled effect's coordinate inside its table


def table_check(lik: RodLikelihood, point: dict) -> dict | None:
    """How far the likelihood tables lie from exact solves at one parameter point, and how far that error
    would move the maximum-likelihood estimate, in Laplace sds.

    The forces the tables give at ``point`` (natural units, scalars: ``EI0``, ``p``, ``sigma_force_N``,
    the tabled effect, offsets, and with centerlines ``shape_sd_scale`` or ``sigma_shape_m``) are
    compared with exact solves (:func:`force_from_displacement_nd`) at every engaged sample the point has
    not slipped past; with centerlines, each observed point's normal offset from the tabled centerline
    (:meth:`RodLikelihood.shape_offsets`) with its offset from the exact centerline of its frame (the
    exact force at the frame's displacement, :func:`contact_from_force_nd`, then
    :func:`centerline_normal_offsets`), at every frame the point has not slipped past. With r the
    residuals the likelihood whitens (forces over sigma, offsets over their sd times the square root of
    the shape term's weight) and J their derivatives in (log EI0, p, the effect's table coordinate u, any
    force offsets), delta = r_table - r_exact, data on the exact model would move the table MLE by
    -(J'J)^-1 J' delta (one Gauss-Newton step); each shift is divided by its Laplace sd, sqrt((J'J)^-1)_ii.
    Independent noise: with an AR(1) force noise the posterior sd differs, and the shift is a guide, not
    the posterior's. The reference is :func:`bayesrod.api.calibration.table_shift_on` (the MLE on
    noise-free exact data); tests check that they agree. None where the forces are not read from the
    plain tables (preloads, a sampled length or height errors, yield).

    Returns
    -------
    dict or None
        ``max_error_over_sigma`` (largest |table - exact| force over sigma; None without forces),
        ``shift_in_sd`` (name -> shift), ``n_samples`` (force samples compared), and with centerlines
        ``max_shape_error_over_sd`` (largest |table - exact| offset over its sd) and ``n_points``.
    """
    if lik.preload or lik.geometry or "yield" in lik.effects:
        return None
    one = {k: np.atleast_1d(np.asarray(v, float))[:1] for k, v in point.items()}
    EI0, p = float(one["EI0"][0]), float(one["p"][0])
    u = lik.effect_coordinate(one)
    eff = {} if lik.axis is None else {k: float(v) for k, v in lik.axis.nondim(u[0]).items()}
    names = ["log EI0", "p"] + ([effect_axis_label(lik.axis)] if lik.axis is not None else [])
    names += (["force_offset"] if "force_offset" in lik.effects else []) + list(lik.offset_names)
    blocks, out = [], {"max_error_over_sigma": None, "n_samples": 0}

    def steps(interp) -> list[NDArray]:  # central differences of an interpolated table in p (and u), per unit step
        cols = []
        for dp, du in ((1e-4, 0.0),) + (((0.0, 1e-4),) if lik.axis is not None else ()):
            up = interp(one["p"] + dp, None if u is None else u + du)[0]
            dn = interp(one["p"] - dp, None if u is None else u - du)[0]
            cols.append((up - dn) / (2 * max(dp, du)))
        return cols

    if lik.n_force:
        sigma = float(one["sigma_force_N"][0])
        f_tab = lik.interp_force(one["p"], u)[0]  # (N,) nondimensional, as the likelihood reads it
        d_nd = np.concatenate([d.D_m for d in lik.force_data]) / lik.L
        exact = force_from_displacement_nd(d_nd, lik.F_height / lik.L, p, eff or None)["f"]
        ok = np.isfinite(exact)
        scale = EI0 / lik.L**2
        cols = [scale * f_tab] + [scale * c for c in steps(lik.interp_force)]  # dF / d(log EI0, p, u) [N]
        if "force_offset" in lik.effects:
            cols.append(np.ones_like(f_tab))
        cols += [(lik.F_push == j).astype(float) for j in range(len(lik.offset_names))]
        # residuals are observed - model: r_table - r_exact = -(F_table - F_exact), dr = -dF
        blocks.append((-np.column_stack(cols)[ok] / sigma, -scale * (f_tab - exact)[ok] / sigma))
        if ok.any():
            out["max_error_over_sigma"] = float(np.max(np.abs(scale * (f_tab - exact)[ok])) / sigma)
        out["n_samples"] = int(ok.sum())
    if lik.n_points:
        if lik.shape_has_sd:  # each point's sd, as the likelihood reads it
            sd = lik.sd_obs * float(one["shape_sd_scale"][0])
        else:
            sd = np.full(lik.n_points, float(one["sigma_shape_m"][0]))
        o_tab = lik.shape_offsets(one["p"], u)[0]  # (k,) [m]
        o_exact = np.full(lik.n_points, np.nan)
        first = 0
        for d in lik.data:
            if not d.x_m.size:
                continue
            eta = d.height_m / lik.L
            f = force_from_displacement_nd(d.frame_D_m / lik.L, eta, p, eff or None)["f"]
            seen = np.flatnonzero(np.isfinite(f))
            if seen.size:
                grid = contact_from_force_nd(f[seen], eta, p, eff or None, keep_shape=True)["grid"]
                for c, m in enumerate(seen):
                    sel = np.flatnonzero(d.frame_index == m)
                    o_exact[first + sel] = (
                        lik.L
                        * centerline_normal_offsets(grid[:, :, c : c + 1], d.x_m[sel] / lik.L, d.z_m[sel] / lik.L)[0]
                    )
            first += d.x_m.size
        ok = np.isfinite(o_exact)
        w = np.sqrt(lik.shape_weight) / sd[ok]
        cols = [np.zeros(lik.n_points)] + steps(lik.shape_offsets)  # a centerline does not depend on EI0
        cols += [np.zeros(lik.n_points)] * (len(names) - len(cols))  # nor on force offsets
        blocks.append((np.column_stack(cols)[ok] * w[:, None], (o_tab - o_exact)[ok] * w))
        out["max_shape_error_over_sd"] = float(np.max(np.abs(o_tab - o_exact)[ok] / sd[ok])) if ok.any() else None
        out["n_points"] = int(ok.sum())
    if sum(b[1].size for b in blocks) < len(names) + 1:
        return None
    J = np.concatenate([b[0] for b in blocks])
    delta = np.concatenate([b[1] for b in blocks])
    seen = np.flatnonzero(np.any(J != 0.0, axis=0))  # centerlines alone say nothing of EI0 or an offset
    J = J[:, seen]
    cov = np.linalg.pinv(J.T @ J)
    shift = -cov @ (J.T @ delta)
    sd_theta = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return out | {
        "shift_in_sd": {names[i]: float(v) for i, v in zip(seen, shift / sd_theta, strict=True)},
        "laplace_sd": {names[i]: float(v) for i, v in zip(seen, sd_theta, strict=True)},
    }


def effect_axis_label(axis: EffectAxis) -> str:
    """The name :func:`table_check` gives the tabled effect's coordinate."""
    return f"{axis.name} (table coordinate u)"


def zoom_window(lik: RodLikelihood, point: dict, check: dict | None) -> tuple[float, float] | None:
    """A narrower range of the effect axis, around ``point``, where the tables there are too coarse.

    Where ``check``, :func:`table_check` at ``point`` (natural units, scalars, as it takes them), says the
    tables would move the estimate by more than :data:`TABLE_ZOOM_SD` on any parameter,
    the window is the point's table coordinate u0 +- :data:`ZOOM_HALF_WIDTH_SD` of u's Laplace sd, within
    the current axis. A table over it with the same number of nodes (``build_likelihood(effect_window=...)``)
    is finer by the ratio of the ranges. None without a tabled effect, when the check passes or cannot be
    made, or when the window would span more than :data:`ZOOM_MAX_SHARE` of the current axis.

    Why: an axis spread over the effect's whole prior can be coarse for a precise posterior (SBC seed 5 of
    the friction study, forces only: Laplace sd 0.0016 in mu against a node spacing of 0.0375 on 49 nodes;
    the tables moved mu by +0.50 sd, 97 nodes by 0.00; docs/validation.md, session 65).
    """
    if lik.axis is None:
        return None
    u0 = float(lik.effect_coordinate(point)[0])
    return _window(check, effect_axis_label(lik.axis), u0, lik.axis.grid)


def p_zoom_window(lik: RodLikelihood, point: dict, check: dict | None) -> tuple[float, float] | None:
    """A narrower range of the taper exponent p, around ``point``, where the tables there are too coarse.

    The rule of :func:`zoom_window` on the p grid: where ``check`` (:func:`table_check` at ``point``) says the
    tables would move the estimate by more than :data:`TABLE_ZOOM_SD`, the window is p0 +-
    :data:`ZOOM_HALF_WIDTH_SD` of p's Laplace sd within the current grid (``build_likelihood(p_window=...)``
    tables it with the same number of nodes); None when the check passes or cannot be made, or when the window
    would span more than :data:`ZOOM_MAX_SHARE` of the grid.

    Why: 61 nodes over the prior's p are coarse for a very precise posterior (SBC seed 68, one height with
    centerlines, force sd 6e-6 of the peak force: Laplace sd of p 1e-5 against a node spacing of 0.05; near
    the branch end the tables' force was 7e-5 off the exact solve and moved p by -1.37 sd; 61 nodes over
    [0.2, 0.45] by +0.003 sd; docs/validation.md, session 72).
    """
    return _window(check, "p", float(np.atleast_1d(point["p"])[0]), lik.p_grid)


def _window(check: dict | None, name: str, x0: float, grid: NDArray) -> tuple[float, float] | None:
    """x0 +- ZOOM_HALF_WIDTH_SD Laplace sds of ``name`` (``check["laplace_sd"]``) within ``grid``, when the
    check's worst shift exceeds TABLE_ZOOM_SD and the window spans at most ZOOM_MAX_SHARE of the grid."""
    if check is None or max(abs(v) for v in check["shift_in_sd"].values()) <= TABLE_ZOOM_SD:
        return None
    sd = check["laplace_sd"].get(name)
    if sd is None or not 0.0 < sd < np.inf:
        return None
    lo, hi = max(float(grid[0]), x0 - ZOOM_HALF_WIDTH_SD * sd), min(float(grid[-1]), x0 + ZOOM_HALF_WIDTH_SD * sd)
    if not hi > lo or hi - lo > ZOOM_MAX_SHARE * (grid[-1] - grid[0]):
        return None
    return lo, hi


def between_nodes(grid: NDArray, x: float) -> float:
    """The middle of the interval of the uniform ``grid`` that holds ``x`` (the end intervals for x outside
    it): where the tables' interpolation along that axis is least exact (it is exact at the nodes)."""
    i = int(np.clip(np.searchsorted(grid, x) - 1, 0, grid.size - 2))
    return float(0.5 * (grid[i] + grid[i + 1]))


def force_scale_fit(lik: RodLikelihood, p: float, EI0: float | None = None) -> tuple[float, float]:
    """EI0 and the RMS force residual of the plain model at taper ``p`` (needs forces).

    EI0 is a pure scale of the forces, so its least-squares value is sum(F g) / sum(g g) with
    g = f(p) / L^2; pass ``EI0`` to get only the residual at that value.
    """
    g = lik.predict_nd_force(np.array([p])) / lik.L**2
    EI0s, rms = scale_fit_rows(g, lik.F_obs, None if EI0 is None else np.array([EI0]))
    return float(EI0s[0]), float(rms[0])


def scale_fit_rows(g: NDArray, F: NDArray, EI0: NDArray | None = None) -> tuple[NDArray, NDArray]:
    """Least-squares EI0 (G,) of forces ``F`` (N,) for unit-EI0 predictions ``g`` (G, N) [N / (N m^2)], and
    the RMS residual (G,); ``EI0`` given: only the residuals (nan EI0 where a row predicts no force)."""
    if EI0 is None:
        gg = np.einsum("gn,gn->g", g, g)
        EI0 = np.where(gg > 0, g @ F / np.where(gg > 0, gg, 1.0), np.nan)
    return EI0, np.sqrt(np.mean((F[None, :] - EI0[:, None] * g) ** 2, axis=1))


def scale_estimate(lik: RodLikelihood) -> float | None:
    """Least-squares EI0 of the plain model on the forces, at the best p of the grid (None without forces)."""
    if not lik.n_force:
        return None
    fits = [force_scale_fit(lik, p) for p in lik.p_grid[1:-1]]
    fits = [(e, r) for e, r in fits if np.isfinite(e) and e > 0]
    return min(fits, key=lambda er: er[1])[0] if fits else None


def effect_axis_ei0_range(effect: str, EI0_hat: float | None, prior) -> tuple[float, float]:
    """The EI0 [N m^2] over which a tabled effect's axis must cover its prior (:meth:`EffectAxis.from_prior`).

    Within a factor 2 of the plain model's least-squares EI0 ``EI0_hat`` (the EI0 prior's central 99.8%
    without forces). A base spring only softens the stem, so with base compliance the plain model's EI0
    is the apparent stiffness and the true EI0 may lie far above it: the range then reaches up to the
    EI0 prior's 99.9% quantile. Before 2026-11-27 it stopped at 2 ``EI0_hat``, and an SBC case with a
    soft base (scripts/sbc_geometry.py seed 86: EI0 4.13 N m^2, k 0.37 N m/rad, ``EI0_hat`` 0.069) had
    its truth outside the table (u 0.924 against the axis's 0.879): zero density there, a certain miss.
    """
    top = prior.get("EI0").quantile(0.999)
    if EI0_hat is None:
        return prior.get("EI0").quantile(0.001), top
    if effect == "base_compliance":
        return EI0_hat / 2.0, max(EI0_hat * 2.0, top)
    return EI0_hat / 2.0, EI0_hat * 2.0


def build_likelihood(
    spec: Specimen,
    prior,
    effects=(),
    *,
    use_forces=True,
    use_shapes=True,
    n_effect: int | None = None,
    force_noise: str = "iid",
    preload: bool = False,
    length: str = "known",
    height_sd_m: float = 0.0,
    force_offsets: bool = False,
    diameter: str = "off",
    slip: bool = False,
    effect_window: tuple[float, float] | None = None,
    p_window: tuple[float, float] | None = None,
) -> RodLikelihood:
    """The likelihood for ``effects``; a tabled effect gets its axis from the prior and a plain EI0 estimate.

    The effect axis must cover the effect's prior at every plausible EI0 (the axis of compliance,
    self-weight and yield scales with EI0): EI0 over :func:`effect_axis_ei0_range` (within a factor 2
    of the plain model's least-squares scale on the forces, up to the EI0 prior's 99.9% quantile for
    base compliance; the EI0 prior's central 99.8% without forces).
    Walkers outside the table get zero density (docs/inference.md). ``length`` ``"unknown"`` samples the
    stem length under the prior's ``length_m`` entry or :func:`default_length_prior`; ``"auto"`` does so
    when the dataset marks its length approximate (``length_m_approximate``). ``n_effect`` nodes on the
    effect axis, default 25: with 13, the tables moved the maximum-likelihood estimate of a forces-only
    twig by 0.16 sd (base compliance, rest curvature); with 25 by at most 0.049 sd
    (``scripts/table_accuracy.py``, docs/validation.md). The tables take about twice as long to build.
    With shapes, rest curvature and base tilt get 49 nodes (:data:`SHAPE_EFFECT_NODES`): the centerline
    above the contact, nearly level late in a push, moves steeply with either, and 25 nodes moved the
    estimate by up to 0.50 sd (49: at most 0.015 sd). Contact friction and rest curvature get 49 with or
    without shapes (:data:`FORCE_EFFECT_NODES`; rest curvature on forces alone moved log EI0 by -0.053 sd with
    25; their tables take twice as long to build). ``slip`` adds the term for where
    each push's slip lies (:meth:`RodLikelihood.slip_loglik`; docs/inference.md, "The slip").
    ``effect_window`` (lo, hi): the effect axis spans this range of its table coordinate u instead (with
    ``n_effect`` nodes; :func:`zoom_window` picks it); walkers outside it get zero density.
    ``p_window`` (lo, hi): the p grid spans this range (61 nodes; :func:`p_zoom_window` picks it) instead of the
    prior's support; walkers outside it get zero density.
    """
    tabled = [e for e in effects if e in TABLE_EFFECTS]
    if effect_window is not None:
        lo_w, hi_w = (float(v) for v in effect_window)
        if not tabled or not np.isfinite(lo_w) or not np.isfinite(hi_w) or not hi_w > lo_w:
            raise ValueError(
                "effect_window: expected (lo, hi), finite, lo < hi, with a tabled effect "
                f"({', '.join(TABLE_EFFECTS)}), got {effect_window!r} with effects {list(effects)!r}"
            )
    if n_effect is None:
        n_effect = FORCE_EFFECT_NODES.get(tabled[0], 25) if tabled else 25
        if tabled and use_shapes:
            n_effect = max(n_effect, SHAPE_EFFECT_NODES.get(tabled[0], 25))
    lo, hi = prior.get("p").bounds()
    p_range = (lo, min(hi, 3.0))
    if p_window is not None:
        lo_p, hi_p = (float(v) for v in p_window)
        if not (np.isfinite(lo_p) and np.isfinite(hi_p) and p_range[0] <= lo_p < hi_p <= p_range[1]):
            raise ValueError(
                f"p_window: expected (lo, hi), finite, within the p prior's table range [{p_range[0]:g}, "
                f"{p_range[1]:g}], lo < hi, got {p_window!r}"
            )
        p_range = (lo_p, hi_p)
    axis = None
    if tabled and effect_window is not None:
        axis = EffectAxis(tabled[0], np.linspace(lo_w, hi_w, n_effect))
    elif tabled:
        plain = RodLikelihood(spec, p_range=p_range, use_forces=use_forces, use_shapes=False)
        rng = effect_axis_ei0_range(tabled[0], scale_estimate(plain), prior)
        axis = EffectAxis.from_prior(tabled[0], prior.get(tabled[0]), rng, float(spec.length_m), n=n_effect)
    if length not in ("known", "unknown", "auto"):
        raise ValueError(f"length: expected 'known', 'unknown' or 'auto', got {length!r}")
    length_prior = None
    if length == "unknown" or (length == "auto" and length_is_approximate(spec)):
        length_prior = prior.params.get("length_m") or default_length_prior(spec)
    lik = RodLikelihood(
        spec,
        p_range=p_range,
        effects=effects,
        use_forces=use_forces,
        use_shapes=use_shapes,
        effect_axis=axis,
        force_noise=force_noise,
        preload=preload,
        length_prior=length_prior,
        height_sd_m=height_sd_m,
        force_offsets=force_offsets,
        diameter=diameter,
        diameter_priors=diameter_priors(prior) if diameter != "off" else None,
        slip=slip,
    )
    if p_window is not None:
        lik.p_window = p_range
    return lik


def diameter_priors(prior) -> dict:
    """Priors of the width term: the prior file's ``d0_m``, ``diameter_sd_scale`` (else the defaults of
    docs/priors.md) and ``p_geom`` = the prior of ``p`` under another name."""
    from dataclasses import replace

    out = {n: prior.params.get(n) or d for n, d in _diameter_priors().items()}
    out["p_geom"] = prior.params.get("p_geom") or replace(prior.get("p"), name="p_geom")
    return out


def length_is_approximate(spec: Specimen) -> bool:
    """True when the dataset says its ``length_m`` is a guess (``length_m_approximate`` in specimen.json)."""
    return bool((getattr(spec, "extra", None) or {}).get("length_m_approximate", False))


def _integrated_autocorr(rho: NDArray) -> float:
    """1 + 2 sum of autocorrelations up to the first one below 0.05 (initial positive sequence)."""
    tau = 1.0
    for r in rho:
        if not np.isfinite(r) or r < 0.05:
            break
        tau += 2.0 * r
    return float(tau)


def effective_shape_weight(lik: RodLikelihood, params: dict, max_lag: int = 60) -> dict:
    """n_eff / n of the shape points, from their standardised residuals at ``params``.

    Separable estimate: the integrated autocorrelation time along the stem (lag = consecutive
    points of a frame) times that between frames (lag = frames of a push, at the same height,
    1-cm bins of z), both pooled over pushes; n_eff = n / (tau_s tau_f).

    Parameters
    ----------
    lik : RodLikelihood
        With shape points.
    params : dict
        One parameter set (e.g. the posterior mode), natural units.
    max_lag : int
        Largest lag considered in either direction.

    Returns
    -------
    dict
        ``weight`` (n_eff / n, in [1/n, 1]), ``tau_along``, ``tau_frames``, ``n_points``, ``n_eff``.
    """
    if not lik.n_points:
        raise ValueError("effective_shape_weight: expected shape points, got none")
    r = lik.residuals({k: np.atleast_1d(v) for k, v in params.items()})["shape"][0]
    if lik.sd_obs is not None:
        r = r / lik.sd_obs
    r = r - np.mean(r)
    var = float(np.mean(r**2)) or 1.0
    along = np.zeros(max_lag)
    n_along = np.zeros(max_lag)
    across = np.zeros(max_lag)
    n_across = np.zeros(max_lag)
    zbin = np.round(lik.z_obs / 0.01).astype(int)
    for push in np.unique(lik.point_push):
        sel = lik.point_push == push
        rp, fp, zp = r[sel], lik.point_frame[sel], zbin[sel]
        for k in range(1, max_lag + 1):
            if rp.size <= k:
                break
            ok = fp[k:] == fp[:-k]
            along[k - 1] += np.sum(rp[k:][ok] * rp[:-k][ok])
            n_along[k - 1] += ok.sum()
        frames = np.unique(fp)
        if frames.size < 2:
            continue
        zs = np.unique(zp)
        grid = np.full((frames.max() + 1, zs.size), np.nan)
        grid[fp, np.searchsorted(zs, zp)] = rp
        for k in range(1, min(max_lag, grid.shape[0] - 1) + 1):
            prod = grid[k:] * grid[:-k]
            ok = np.isfinite(prod)
            across[k - 1] += np.sum(prod[ok])
            n_across[k - 1] += ok.sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        rho_along = along / n_along / var
        rho_across = across / n_across / var
    tau_s = _integrated_autocorr(rho_along)
    tau_f = _integrated_autocorr(rho_across)
    n = lik.n_points
    w = float(np.clip(1.0 / (tau_s * tau_f), 1.0 / n, 1.0))
    return {"weight": w, "tau_along": tau_s, "tau_frames": tau_f, "n_points": int(n), "n_eff": w * n}

"""Likelihood of EI0, p, noise (and effect parameters) on forces and shapes jointly.

EI0 is a pure scale of the nondimensional elastica (docs/model.md): at a given
contact displacement the force is F = EI0/L^2 f(d; p, h/L) and the centerline
(x, z)/L depends on p and h/L only. So the likelihood precomputes, once per
dataset, exact tables over a grid of p:

* ``f[p_k, i]``: nondimensional force at every engaged force sample i;
* ``x[p_k, j]`` and ``cos(phi)[p_k, j]``: the predicted centerline's
  horizontal position and tangent at the height of every observed point j.

A log-likelihood evaluation is then a 4-point Lagrange interpolation in p and
a scale by EI0, batched over walkers. Where the model's branch ends before an
engaged displacement (it would have slipped), force and shape are held at the
branch end: the force curve is flat there, and the slip is not used as a hard
constraint (see ``RodLikelihood.predict_nd_force``).

Shape residuals are the normal distance from each observed point to the
predicted curve, (x_obs - x_pred(z_obs)) cos(phi_pred(z_obs)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from ..dataset.engagement import detect_engagement
from ..dataset.model import Specimen
from ..physics.elastica import centerline_at, contact_from_force_nd

_LOG_2PI = math.log(2 * math.pi)
FITTABLE_EFFECTS = ("force_offset",)


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
                if t.size < 2 or not (t[0] <= fr.time_s <= t[-1]):
                    continue  # before contact or after the slip: not engaged
                k = len(fD)
                fD.append(float(D_of_t(fr.time_s)))
                keep = fr.z_m >= 0
                fi.append(np.full(int(keep.sum()), k))
                xs.append(fr.x_m[keep] * push.direction)
                zs.append(fr.z_m[keep])
                sds.append(fr.sd_m[keep] if fr.sd_m is not None else None)
        has_sd = bool(sds) and all(s is not None for s in sds)
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
            )
        )
    return out


class ForceCurves:
    """Force-displacement curves f(d) at one height for every p of a grid, from forward solves.

    For each p: the branch end f_end (bisection on the existence of contact),
    forward solves at n_f forces clustered toward f_end, and a monotone cubic
    (PCHIP) of f against d. ``force`` clamps d at each node's slip displacement
    ``d_end`` so that tables stay continuous in p; slip is decided separately.
    """

    def __init__(self, eta: float, p_grid: NDArray, n_f: int = 160):
        P = p_grid.size
        lo = np.zeros(P)
        hi = np.full(P, 2.0 / eta**2)
        for _ in range(60):  # expand until no contact
            found = contact_from_force_nd(hi, eta, p_grid)["found"]
            if not found.any():
                break
            lo = np.where(found, hi, lo)
            hi = np.where(found, 2 * hi, hi)
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            found = contact_from_force_nd(mid, eta, p_grid)["found"]
            lo, hi = np.where(found, mid, lo), np.where(found, hi, mid)
        u = np.linspace(0.0, 1.0, n_f)
        f = lo[:, None] * (1.0 - (1.0 - u[None, :]) ** 2)
        r = contact_from_force_nd(f, eta, p_grid[:, None])
        d = r["xi_c"] - r["xi_c"][:, :1]
        self.d_end = d[:, -1]
        self._interp = []
        for k in range(P):
            dk, fk = d[k], f[k]
            keep = np.concatenate([[True], np.diff(dk) > 0])
            self._interp.append(PchipInterpolator(dk[keep], fk[keep], extrapolate=True))

    def force(self, d: NDArray) -> NDArray:
        """f at displacements d (M,) for every p: (P, M), clamped at each node's d_end."""
        d = np.asarray(d, float)
        return np.stack([fn(np.minimum(d, de)) for fn, de in zip(self._interp, self.d_end, strict=True)])


def _lagrange4(grid: NDArray, p: NDArray):
    """Indices (W, 4) and weights (W, 4) of 4-point Lagrange interpolation on a uniform grid."""
    h = grid[1] - grid[0]
    n = grid.size
    u = (p - grid[0]) / h
    k = np.clip(np.floor(u).astype(int) - 1, 0, n - 4)
    t = u - k  # position relative to node k, in [1, 2] in the interior
    idx = k[:, None] + np.arange(4)
    w = np.empty((p.size, 4))
    nodes = np.arange(4.0)
    for a in range(4):
        others = [b for b in range(4) if b != a]
        w[:, a] = np.prod([(t - nodes[b]) / (nodes[a] - nodes[b]) for b in others], axis=0)
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
        Nodes of the p grid (61 over [0, 3]: interpolation error < 1e-6 relative).

    Attributes
    ----------
    names : list of str
        Natural parameter names in order: EI0, p, sigma_force_N (if forces),
        shape noise (``shape_sd_scale`` if every point has an sd, else
        ``sigma_shape_m``), then effects.
    """

    def __init__(self, spec: Specimen, p_range=(0.0, 3.0), effects=(), use_forces=True, use_shapes=True, n_p: int = 61):
        unsupported = [e for e in effects if e not in FITTABLE_EFFECTS]
        if unsupported:
            raise ValueError(
                f"--effects: expected effects the fit supports ({', '.join(FITTABLE_EFFECTS)}), "
                f"got {', '.join(unsupported)} (the others enter with bayesrod diagnose)"
            )
        self.spec = spec
        self.L = float(spec.length_m)
        self.effects = tuple(effects)
        self.data = prepare_data(spec, use_forces, use_shapes)
        self.n_force = int(sum(d.F_N.size for d in self.data))
        self.n_points = int(sum(d.x_m.size for d in self.data))
        if self.n_force == 0 and self.n_points == 0:
            raise ValueError(f"{spec.specimen}: expected engaged force samples or centerline points, got none")
        lo, hi = p_range
        self.p_grid = np.linspace(lo, hi, n_p)
        self.shape_has_sd = self.n_points > 0 and all(d.sd_m is not None for d in self.data if d.x_m.size)
        names = ["EI0", "p"]
        if self.n_force:
            names.append("sigma_force_N")
        if self.n_points:
            names.append("shape_sd_scale" if self.shape_has_sd else "sigma_shape_m")
        names += list(self.effects)
        self.names = names
        self._build_tables()

    # ------------------------------------------------------------------ tables
    def _build_tables(self) -> None:
        L, pg = self.L, self.p_grid
        fF, fobs, xs, cs, xobs, zobs, sd = [], [], [], [], [], [], []
        for d in self.data:
            eta = d.height_m / L
            curves = ForceCurves(eta, pg)
            if d.D_m.size:
                fF.append(curves.force(d.D_m / L))
                fobs.append(d.F_N)
            if d.x_m.size:
                xp, cp = self._shape_table(d, eta, curves)
                xs.append(xp)
                cs.append(cp)
                xobs.append(d.x_m)
                zobs.append(d.z_m)
                if self.shape_has_sd:
                    sd.append(d.sd_m)
        P = pg.size
        self.f_table = np.concatenate(fF, axis=1) if fF else np.zeros((P, 0))
        self.F_obs = np.concatenate(fobs) if fobs else np.zeros(0)
        self.x_table = np.concatenate(xs, axis=1) if xs else np.zeros((P, 0))
        self.cos_table = np.concatenate(cs, axis=1) if cs else np.zeros((P, 0))
        self.x_obs = np.concatenate(xobs) if xobs else np.zeros(0)
        self.z_obs = np.concatenate(zobs) if zobs else np.zeros(0)
        self.sd_obs = np.concatenate(sd) if sd else None

    def _shape_table(self, d: PushData, eta: float, curves: ForceCurves):
        L, pg = self.L, self.p_grid
        f_t = curves.force(d.frame_D_m / L)  # (P, M), clamped at each node's slip
        P, M = f_t.shape
        r = contact_from_force_nd(f_t, eta, pg[:, None], keep_shape=True)
        sig = np.linspace(0.0, 1.0, 961)  # 0.5 mm spacing on a 0.47 m stem: x(z) error < 1 um
        xz = centerline_at(r["grid"], sig)  # (2, 961, P, M)
        dx = np.gradient(xz[0], sig, axis=0)
        dz = np.gradient(xz[1], sig, axis=0)
        cos_phi = dz / np.maximum(np.hypot(dx, dz), 1e-12)
        xp = np.empty((P, d.x_m.size))
        cp = np.empty((P, d.x_m.size))
        for m in range(M):
            sel = d.frame_index == m
            z = d.z_m[sel] / L
            for k in range(P):
                zeta = np.maximum.accumulate(xz[1, :, k, m])
                xp[k, sel] = np.interp(z, zeta, xz[0, :, k, m]) * L
                cp[k, sel] = np.interp(z, zeta, cos_phi[:, k, m])
        return xp, cp

    # -------------------------------------------------------------- evaluation
    def predict_nd_force(self, p: NDArray) -> NDArray:
        """Nondimensional force at every engaged sample, (W, N).

        The slip is not used as a hard constraint: past a p's branch end the force is held at its
        end value (the curve is flat there). A hard "slipped means zero" rule would say only "not
        yet slipped" for engaged samples and bias p; the end of the branch is also where the model
        is most sensitive to what it leaves out (friction, the probe's shape).
        """
        idx, w = _lagrange4(self.p_grid, p)
        return np.einsum("wk,wkn->wn", w, self.f_table[idx])

    def predict_shape_x(self, p: NDArray) -> tuple[NDArray, NDArray]:
        idx, w = _lagrange4(self.p_grid, p)
        return np.einsum("wk,wkn->wn", w, self.x_table[idx]), np.einsum("wk,wkn->wn", w, self.cos_table[idx])

    def residuals(self, params: dict) -> dict:
        """Force and shape residuals (observed - predicted) for parameter arrays of shape (W,)."""
        p = np.atleast_1d(np.asarray(params["p"], float))
        EI0 = np.atleast_1d(np.asarray(params["EI0"], float))
        out = {}
        if self.n_force:
            F = EI0[:, None] / self.L**2 * self.predict_nd_force(p)
            if "force_offset" in params:
                F = F + np.atleast_1d(params["force_offset"])[:, None]
            out["force"] = self.F_obs[None, :] - F
        if self.n_points:
            x, c = self.predict_shape_x(p)
            out["shape"] = (self.x_obs[None, :] - x) * c
        return out

    def log_likelihood(self, params: dict) -> NDArray:
        """Sum of Gaussian log densities; parameter arrays of shape (W,), result (W,)."""
        res = self.residuals(params)
        ll = np.zeros(np.atleast_1d(params["p"]).shape)
        if "force" in res:
            s = np.atleast_1d(params["sigma_force_N"])[:, None]
            ll += np.sum(-0.5 * (res["force"] / s) ** 2 - np.log(s), axis=1) - 0.5 * self.n_force * _LOG_2PI
        if "shape" in res:
            if self.shape_has_sd:
                s = np.atleast_1d(params["shape_sd_scale"])[:, None] * self.sd_obs[None, :]
            else:
                s = np.atleast_1d(params["sigma_shape_m"])[:, None]
            ll += np.sum(-0.5 * (res["shape"] / s) ** 2 - np.log(s), axis=1) - 0.5 * self.n_points * _LOG_2PI
        return ll

    def fit_error(self, params: dict) -> dict:
        """RMS force error [N] and shape error [mm] at one parameter set (CONTRACT summary.fit_error)."""
        res = self.residuals({k: np.atleast_1d(v) for k, v in params.items()})
        out = {}
        f = res.get("force")  # engaged samples only (see prepare_data)
        out["force_rmse_N"] = float(np.sqrt(np.mean(f**2))) if f is not None and f.size else None
        out["shape_rmse_mm"] = float(1000 * np.sqrt(np.mean(res["shape"] ** 2))) if "shape" in res else None
        return out


class LogPosterior:
    """Prior times likelihood in the sampling space; ``log_prob(theta)`` is what emcee sees.

    ``theta`` has shape (ndim,) or (W, ndim): log EI0, p, then the noise terms
    in log space, then effect parameters (log for positive ones).
    """

    def __init__(self, likelihood: RodLikelihood, prior):
        self.likelihood = likelihood
        self.names = likelihood.names
        self.priors = [prior.get(n) for n in self.names]
        lo, hi = likelihood.p_grid[0], likelihood.p_grid[-1]
        plo, phi = self.priors[1].bounds()
        if plo < lo - 1e-12 or phi > hi + 1e-12:
            raise ValueError(f"prior p: expected support within the table range [{lo}, {hi}], got [{plo}, {phi}]")
        self._p_bounds = (max(lo, plo), min(hi, phi))

    @property
    def ndim(self) -> int:
        return len(self.names)

    def to_natural(self, theta) -> dict:
        theta = np.atleast_2d(theta)
        return {n: pr.from_sample(theta[:, i]) for i, (n, pr) in enumerate(zip(self.names, self.priors, strict=True))}

    def to_sample(self, natural: dict) -> NDArray:
        return np.stack(
            [pr.to_sample(np.atleast_1d(natural[n])) for n, pr in zip(self.names, self.priors, strict=True)], axis=-1
        )

    def log_prior(self, theta) -> NDArray:
        theta = np.atleast_2d(theta)
        return sum(pr.logpdf_sample(theta[:, i]) for i, pr in enumerate(self.priors))

    def log_prob(self, theta) -> NDArray | float:
        theta_arr = np.asarray(theta, float)
        single = theta_arr.ndim == 1
        theta2 = np.atleast_2d(theta_arr)
        lp = self.log_prior(theta2)
        p = theta2[:, 1]
        ok = np.isfinite(lp) & (p >= self._p_bounds[0]) & (p <= self._p_bounds[1]) & np.all(np.isfinite(theta2), 1)
        out = np.full(theta2.shape[0], -np.inf)
        if ok.any():
            nat = {k: v[ok] for k, v in self.to_natural(theta2).items()}
            ll = self.likelihood.log_likelihood(nat)
            out[ok] = np.where(np.isfinite(ll), lp[ok] + ll, -np.inf)
        return float(out[0]) if single else out

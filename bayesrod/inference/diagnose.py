"""Close the loop: residual structure, effect attribution, refit (issue 9).

The plain rod (eq. ivp, clamped, straight, frictionless) is fitted to a
specimen's forces and shapes; its residuals are tested for every effect of the
catalog, the best-supported effect is added only on clear evidence, and the
loop repeats until nothing further helps.

Fits here are maximum-likelihood fits of the *direct* forward model
(:func:`bayesrod.physics.force_from_displacement`, any combination of effects,
no tables) by scipy's trust-region least squares, with the noise scales
profiled. Posterior sampling is what ``bayesrod.fit(..., effects=...)`` is for; the
diagnosis needs many fits and compares models.

Statistics (all on residuals weighted by the fitted noise sd):

* **Score test** (Rao) for each smooth effect absent from the model: with the
  residual vector r, the effect's sensitivity g = d prediction / d effect at
  its neutral value, and the Jacobian X of the fitted parameters,
  S = (g~^T r)^2 / (g~^T g~), g~ = g projected off X. Under "the effect is
  absent" S ~ chi^2_1; one-sided for effects bounded at their neutral value
  (base compliance, self weight). One forward solve per effect.
* **Profile likelihood ratio** for ``yield`` (its derivative at the neutral
  value is zero): the largest drop of the weighted residual sum of squares
  when the forces are capped at M_y / h, over M_y.
* The (up to two) most significant candidates with p < alpha / (number of
  candidates) are fitted. A fitted candidate passes if its likelihood-ratio
  statistic exceeds the chi^2_1 quantile at the same level *and* the
  leave-one-height-out force error falls by at least ``min_heldout_gain``
  (when there are two or more heights). The passing candidate with the
  largest likelihood ratio is **added**; when none passes the loop stops.
* **Structure test** on the final residuals, per push and observation kind: an
  F test of a degree-5 Legendre smooth against displacement (forces) or height
  (shapes). ``unexplained_structure`` is set when some block has p < 1e-3 and a
  structured component above ``structure_ratio`` times the noise sd.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.optimize import least_squares

from ..physics import Effects, force_from_displacement
from ..physics.effects import EFFECT_NAMES
from ..physics.elastica import centerline_at, force_from_displacement_nd
from .likelihood import PushData

CATALOG = EFFECT_NAMES  # every effect of the contract's catalog is a candidate

# fitted coordinate of each effect: (neutral value, score step, lower bound, upper bound)
# base_compliance is fitted as c = EI0 / (k_b L) (0 = clamped); self_weight as w0 L^3 / EI0;
# yield as log(M_y) [N m]; the others in SI units (1/m, rad, 1, N).
_COORD = {
    "base_compliance": (0.0, 0.02, 0.0, 20.0),
    "rest_curvature": (0.0, 0.02, np.nan, np.nan),  # bounds |kappa0 L| <= 1.2 (Diagnoser._bound)
    "base_tilt": (0.0, 0.005, -0.3, 0.3),
    "contact_friction": (0.0, 0.02, -0.9, 0.9),
    "force_offset": (0.0, 0.01, -np.inf, np.inf),
    "self_weight": (0.0, 0.02, 0.0, 1.5),  # w0 L^3/EI0; a uniform column buckles under its weight at 7.8
    "yield": (np.nan, np.nan, -20.0, 20.0),
}
_ONE_SIDED = ("base_compliance", "self_weight")
# forward solves 10-40x slower than the others (slip boundary, self-weight secant): fewer fit iterations
SLOW = ("contact_friction", "self_weight")


def effects_from_coords(coords: dict[str, float], EI0: float, L: float) -> Effects:
    """SI effects from the fitted coordinates (see _COORD)."""
    m = {}
    for name, v in coords.items():
        if name == "base_compliance":
            m[name] = EI0 / (v * L) if v > 0 else np.inf
        elif name == "self_weight":
            m[name] = v * EI0 / L**3
        elif name == "yield":
            m[name] = float(np.exp(v))
        else:
            m[name] = v
    return Effects.from_mapping({k: v for k, v in m.items() if not (k == "base_compliance" and np.isinf(v))})


def _hold(F: NDArray) -> NDArray:
    """Past a predicted slip, hold the last predicted force (the likelihood tables do the same)."""
    F = np.array(F, float)
    bad = ~np.isfinite(F)
    if bad.all():
        return np.zeros_like(F)
    if bad.any():
        idx = np.where(~bad, np.arange(F.size), 0)
        np.maximum.accumulate(idx, out=idx)
        F = F[idx]
        F[~np.isfinite(F)] = 0.0
    return F


@dataclass
class ForwardModel:
    """Predictions of a specimen's engaged observations for one parameter set (direct solves).

    Parameters
    ----------
    data : list of PushData
        Engaged forces and centerline points of each push (``prepare_data``).
    length_m : float
    """

    data: list[PushData]
    length_m: float
    n_force: int = field(init=False)
    n_points: int = field(init=False)

    def __post_init__(self) -> None:
        self.n_force = int(sum(d.D_m.size for d in self.data))
        self.n_points = int(sum(d.x_m.size for d in self.data))
        self.F_obs = np.concatenate([d.F_N for d in self.data]) if self.n_force else np.zeros(0)
        self.x_obs = np.concatenate([d.x_m for d in self.data]) if self.n_points else np.zeros(0)
        self.force_push = np.concatenate([np.full(d.D_m.size, k) for k, d in enumerate(self.data)]).astype(int)
        self.point_push = np.concatenate([np.full(d.x_m.size, k) for k, d in enumerate(self.data)]).astype(int)
        sds = [d.sd_m for d in self.data if d.x_m.size]
        self.sd_obs = np.concatenate(sds) if sds and all(s is not None for s in sds) else None

    def thinned(self, max_per_push: int) -> ForwardModel:
        """The same pushes with at most ``max_per_push`` force samples and frames each (evenly spread)."""
        from dataclasses import replace

        out = []
        for d in self.data:
            kf = max(1, int(np.ceil(d.D_m.size / max_per_push)))
            keep_frames = np.arange(0, d.frame_D_m.size, max(1, int(np.ceil(d.frame_D_m.size / max_per_push))))
            sel = np.isin(d.frame_index, keep_frames)
            remap = np.full(max(d.frame_D_m.size, 1), -1)
            remap[keep_frames] = np.arange(keep_frames.size)
            out.append(
                replace(
                    d,
                    D_m=d.D_m[::kf],
                    F_N=d.F_N[::kf],
                    frame_D_m=d.frame_D_m[keep_frames],
                    frame_index=remap[d.frame_index[sel]] if sel.any() else d.frame_index[:0],
                    x_m=d.x_m[sel],
                    z_m=d.z_m[sel],
                    sd_m=None if d.sd_m is None else d.sd_m[sel],
                )
            )
        return ForwardModel(out, self.length_m)

    def predict(
        self, log_EI0: float, p: float, coords: dict[str, float], shapes: bool = True
    ) -> tuple[NDArray, NDArray, NDArray]:
        """Sensor forces (n_force,), centerline x (n_points,) and cos(tangent angle) (n_points,).

        ``shapes=False`` skips the centerlines (empty arrays).
        """
        L = self.length_m
        EI0 = float(np.exp(np.clip(log_EI0, -60.0, 60.0)))  # a wild trial step must not overflow
        eff = effects_from_coords(coords, EI0, L)
        Fs, xs, cs = [], [], []
        for d in self.data:
            if d.D_m.size:
                Fs.append(_hold(force_from_displacement(d.D_m, d.height_m, EI0, p, L, eff).force_N))
            if shapes and d.x_m.size:
                x, c = self._shape(d, EI0, p, eff)
                xs.append(x)
                cs.append(c)
        cat = lambda a: np.concatenate(a) if a else np.zeros(0)  # noqa: E731
        return cat(Fs), cat(xs), cat(cs)

    def _shape(self, d: PushData, EI0: float, p: float, eff: Effects):
        L = self.length_m
        r = force_from_displacement_nd(d.frame_D_m / L, d.height_m / L, p, eff.nondim(L, EI0), keep_shape=True)
        sig = np.linspace(0.0, 1.0, 961)
        xz = centerline_at(r["grid"], sig)  # (2, 961, M)
        dx, dz = np.gradient(xz[0], sig, axis=0), np.gradient(xz[1], sig, axis=0)
        cos_phi = dz / np.maximum(np.hypot(dx, dz), 1e-12)
        x = np.full(d.x_m.size, np.nan)
        c = np.ones(d.x_m.size)
        for m in range(d.frame_D_m.size):
            sel = d.frame_index == m
            if not np.all(np.isfinite(xz[:, :, m])):
                continue  # the model slipped before this frame: no prediction (residual 0)
            zeta = np.maximum.accumulate(xz[1, :, m])
            x[sel] = np.interp(d.z_m[sel] / L, zeta, xz[0, :, m]) * L
            c[sel] = np.interp(d.z_m[sel] / L, zeta, cos_phi[:, m])
        return x, c


@dataclass
class MapFit:
    """A maximum-likelihood fit: parameters, noise scales, residuals, Jacobian."""

    effects: tuple[str, ...]
    x: NDArray  # (log_EI0, p, effect coordinates...)
    sigma_force: float
    shape_scale: float  # multiplies sd_m (or is the shape sd [m] without sd_m)
    r_force: NDArray  # observed - predicted [N]
    r_shape: NDArray  # normal distance [m]
    jac: NDArray  # (n_obs, n_par) of the weighted predictions
    loglik: float

    @property
    def coords(self) -> dict[str, float]:
        return {e: float(v) for e, v in zip(self.effects, self.x[2:], strict=True)}

    def natural(self, L: float) -> dict:
        EI0 = float(np.exp(self.x[0]))
        out = {"EI0": EI0, "p": float(self.x[1])}
        out.update(effects_from_coords(self.coords, EI0, L).to_mapping())
        return out


class Diagnoser:
    """Fits, statistics and held-out errors for one specimen (see the module docstring)."""

    def __init__(self, model: ForwardModel):
        if model.n_force == 0:
            raise ValueError("diagnose: expected engaged force samples (the forces fix EI0), got none")
        self.m = model

    # ---------------------------------------------------------------- residuals
    def _weights(self, sigma_force: float, shape_scale: float) -> NDArray:
        wf = np.full(self.m.n_force, 1.0 / sigma_force)
        if self.m.n_points:
            sd = self.m.sd_obs if self.m.sd_obs is not None else np.ones(self.m.n_points)
            ws = 1.0 / (shape_scale * sd)
        else:
            ws = np.zeros(0)
        return np.concatenate([wf, ws])

    def raw_residuals(self, x: NDArray, effects) -> tuple[NDArray, NDArray]:
        try:
            F, xs, c = self.m.predict(x[0], x[1], dict(zip(effects, x[2:], strict=True)))
        except ValueError:
            # parameters the model cannot solve (e.g. a rest shape that never reaches the sensor):
            # a large finite misfit so that the least-squares step backs off
            big = 1e3 * (np.abs(self.m.F_obs).max() + 1.0)
            return np.full(self.m.n_force, big), np.full(self.m.n_points, 1e3 * self.m.length_m)
        rf = self.m.F_obs - F
        rs = np.nan_to_num((self.m.x_obs - xs) * c) if self.m.n_points else np.zeros(0)
        return rf, rs

    def _profile_noise(self, rf, rs) -> tuple[float, float]:
        sf = float(np.sqrt(np.mean(rf**2))) if rf.size else 1.0
        if rs.size:
            sd = self.m.sd_obs if self.m.sd_obs is not None else 1.0
            ss = float(np.sqrt(np.mean((rs / sd) ** 2)))
        else:
            ss = 1.0
        return max(sf, 1e-9), max(ss, 1e-12)

    def _loglik(self, rf, rs, sf, ss) -> float:
        ll = -0.5 * np.sum((rf / sf) ** 2) - rf.size * np.log(sf)
        if rs.size:
            s = ss * (self.m.sd_obs if self.m.sd_obs is not None else 1.0)
            ll += -0.5 * np.sum((rs / s) ** 2) - np.sum(np.log(np.broadcast_to(s, rs.shape)))
        return float(ll)

    # --------------------------------------------------------------------- fits
    def fit(self, effects=(), x0: NDArray | None = None, max_nfev: int = 40) -> MapFit:
        """Maximum-likelihood fit with ``effects`` (noise profiled: two rounds of least squares).

        With a slow effect (friction, self-weight) the iterations run on at most 20 force samples
        and frames per push, and the full data only polish the result (two evaluations and one
        Jacobian): the solves cost in proportion to the samples.
        """
        effects = tuple(effects)
        if any(e in SLOW for e in effects) and max(d.D_m.size for d in self.m.data) > 20:
            x0 = Diagnoser(self.m.thinned(20)).fit(effects, x0, max_nfev=max_nfev).x
            max_nfev = 2
        lo = [-np.inf, 0.0] + [self._bound(e, 2) for e in effects]
        hi = [np.inf, 4.0] + [self._bound(e, 3) for e in effects]
        x = np.array(x0, float)
        x = np.clip(x, np.array(lo) + 1e-9 * np.isfinite(lo), np.array(hi) - 1e-9 * np.isfinite(hi))
        rf, rs = self.raw_residuals(x, effects)
        sf, ss = self._profile_noise(rf, rs)
        res = w = None
        rounds = 2 if (self.m.n_force and self.m.n_points) else 1  # one kind: the weights are uniform
        for _ in range(rounds):
            w = self._weights(sf, ss)

            def fun(v, w=w):
                a, b = self.raw_residuals(v, effects)
                return np.concatenate([a, b]) * w

            res = least_squares(
                fun, x, bounds=(lo, hi), x_scale="jac", diff_step=1e-4, max_nfev=max_nfev, ftol=1e-7, xtol=1e-7
            )
            x = res.x
            rf, rs = self.raw_residuals(x, effects)
            sf, ss = self._profile_noise(rf, rs)
        # res.jac is d(weighted residual)/dx = -(d prediction/dx) * w; re-weight to the final noise scales
        jac = -res.jac / w[:, None] * self._weights(sf, ss)[:, None]
        return MapFit(effects, x, sf, ss, rf, rs, jac, self._loglik(rf, rs, sf, ss))

    def _bound(self, effect: str, k: int) -> float:
        if effect == "rest_curvature":  # the unloaded stem must still rise: |kappa0 L| <= 1.2 rad
            return (-1.2 if k == 2 else 1.2) / self.m.length_m
        return _COORD[effect][k]

    def start(self, p_grid: NDArray | None = None) -> NDArray:
        """(log EI0, p) of the plain model: the force tables of the likelihood over a p grid, closed-form EI0.

        Forces are linear in EI0, so each p of the grid has a least-squares EI0; the best pair starts
        the direct fit.
        """
        from .likelihood import ForceCurves

        p_grid = np.linspace(0.0, 3.0, 61) if p_grid is None else np.asarray(p_grid, float)
        L = self.m.length_m
        g = (
            np.concatenate(
                [ForceCurves(d.height_m / L, p_grid).force(d.D_m / L) for d in self.m.data if d.D_m.size], axis=1
            )
            / L**2
        )  # (P, n_force): force per unit EI0
        gg = np.einsum("pn,pn->p", g, g)
        a = (g @ self.m.F_obs) / np.where(gg > 0, gg, np.inf)
        rss = np.sum((self.m.F_obs[None, :] - a[:, None] * g) ** 2, axis=1)
        rss = np.where(a > 0, rss, np.inf)
        k = int(np.argmin(rss))
        if not np.isfinite(rss[k]):
            raise ValueError("diagnose: expected forces that rise with displacement, got none the model can fit")
        return np.array([np.log(a[k]), float(p_grid[k])])

    # -------------------------------------------------------------- statistics
    def _weighted(self, fit: MapFit) -> tuple[NDArray, NDArray]:
        w = self._weights(fit.sigma_force, fit.shape_scale)
        return np.concatenate([fit.r_force, fit.r_shape]) * w, w

    def score(self, fit: MapFit, effect: str) -> dict:
        """Score statistic (chi^2_1 under absence) of ``effect`` at ``fit``."""
        if effect == "yield":
            return self._yield_lr(fit)
        r, w = self._weighted(fit)
        neutral, step = _COORD[effect][0], _COORD[effect][1]
        if effect == "force_offset":
            step = 0.1 * fit.sigma_force
        x = np.concatenate([fit.x, [neutral + step]])
        rf, rs = self.raw_residuals(x, fit.effects + (effect,))
        # d prediction / d effect = -(d residual / d effect)
        g = (np.concatenate([fit.r_force, fit.r_shape]) - np.concatenate([rf, rs])) / step * w
        X = fit.jac
        coef, *_ = np.linalg.lstsq(X, g, rcond=None)
        gt = g - X @ coef
        den = float(gt @ gt)
        if den <= 1e-30:
            return {"statistic": 0.0, "p_value": 1.0, "direction": 0.0}
        U = float(gt @ r)
        S = U * U / den
        if effect in _ONE_SIDED and U < 0:
            S = 0.0
        return {"statistic": S, "p_value": float(stats.chi2.sf(S, 1)), "direction": float(np.sign(U))}

    def _yield_lr(self, fit: MapFit) -> dict:
        """Profile likelihood ratio over the yield moment, forces only, other parameters held."""
        F = self.m.F_obs - fit.r_force
        h = np.array([self.m.data[k].height_m for k in self.m.force_push])
        M = F * h
        best, best_my = 0.0, None
        for frac in np.linspace(0.3, 0.995, 60):
            my = frac * float(M.max())
            Fc = np.minimum(F, my / h)
            # EI0 re-scaled on the samples below the cap (forces are linear in EI0 there)
            below = F * h < my
            a = float(Fc[below] @ self.m.F_obs[below]) / float(Fc[below] @ Fc[below]) if below.sum() > 2 else 1.0
            Fc = np.minimum(a * F, my / h)
            drop = (np.sum(fit.r_force**2) - np.sum((self.m.F_obs - Fc) ** 2)) / fit.sigma_force**2
            if drop > best:
                best, best_my = drop, my
        out = {"statistic": float(best), "p_value": float(stats.chi2.sf(best, 2)), "direction": 1.0}
        if best_my is not None:
            out["yield_moment_Nm"] = best_my
        return out

    def heldout(self, fit: MapFit, iters: int = 3) -> dict:
        """Leave-one-height-out force error: refit without each push (chord Gauss-Newton from ``fit``)."""
        if len(self.m.data) < 2:
            return {"heldout_force_rmse_N": None, "per_push": []}
        n_f = self.m.n_force
        w = self._weights(fit.sigma_force, fit.shape_scale)
        sq, per = [], []
        for k, d in enumerate(self.m.data):
            held_f = self.m.force_push == k
            held = np.concatenate([held_f, self.m.point_push == k])
            if not held_f.any():
                continue
            Jt = fit.jac[~held]
            x = fit.x.copy()
            rf, rs = fit.r_force, fit.r_shape
            for _ in range(iters):
                r = (np.concatenate([rf, rs]) * w)[~held]
                dx, *_ = np.linalg.lstsq(Jt, r, rcond=None)
                x = x + dx
                x[1] = max(x[1], 0.0)
                rf, rs = self.raw_residuals(x, fit.effects)
            e = rf[held_f[:n_f]]
            sq.append(e**2)
            per.append({"push": d.id, "height_m": d.height_m, "force_rmse_N": float(np.sqrt(np.mean(e**2)))})
        return {"heldout_force_rmse_N": float(np.sqrt(np.mean(np.concatenate(sq)))), "per_push": per}

    def errors(self, fit: MapFit) -> dict:
        out = {
            "force_rmse_N": float(np.sqrt(np.mean(fit.r_force**2))),
            "shape_rmse_mm": float(1000 * np.sqrt(np.mean(fit.r_shape**2))) if fit.r_shape.size else None,
        }
        out.update(self.heldout(fit))
        return out

    def structure(self, fit: MapFit, ratio: float = 0.25, alpha: float = 1e-3) -> dict:
        """Per push and kind: F test of a degree-5 Legendre smooth of the weighted residuals."""
        r, _ = self._weighted(fit)
        n_f = self.m.n_force
        blocks = []
        for k, d in enumerate(self.m.data):
            for kind, sel, t in (
                ("force", self.m.force_push == k, d.D_m),
                ("shape", self.m.point_push == k, d.z_m),
            ):
                rr = r[:n_f][sel] if kind == "force" else r[n_f:][sel]
                if rr.size < 20:
                    continue
                u = 2 * (t - t.min()) / max(np.ptp(t), 1e-12) - 1
                B = np.polynomial.legendre.legvander(u, 5)
                coef, *_ = np.linalg.lstsq(B, rr, rcond=None)
                fitted = B @ coef
                q = B.shape[1]
                ss_fit, ss_res = float(fitted @ fitted), float(np.sum((rr - fitted) ** 2))
                Fst = (ss_fit / q) / max(ss_res / (rr.size - q), 1e-300)
                pval = float(stats.f.sf(Fst, q, rr.size - q))
                excess = max(0.0, (ss_fit - q * ss_res / (rr.size - q)) / rr.size)
                sd_ratio = float(np.sqrt(excess / max(ss_res / (rr.size - q), 1e-300)))
                blocks.append(
                    {
                        "push": d.id,
                        "height_m": d.height_m,
                        "kind": kind,
                        "n": int(rr.size),
                        "p_value": pval,
                        "structured_sd_ratio": sd_ratio,
                        "structured": bool(pval < alpha and sd_ratio > ratio),
                    }
                )
        return {"blocks": blocks, "unexplained_structure": any(b["structured"] for b in blocks)}


def diagnose(
    model: ForwardModel,
    *,
    candidates=CATALOG,
    alpha: float = 0.01,
    min_heldout_gain: float = 0.10,
    max_effects: int = 3,
    top_k: int = 2,
    structure_ratio: float = 0.25,
    log=None,
) -> dict:
    """The loop: fit plain, test every candidate, add the best on clear evidence, repeat.

    Parameters
    ----------
    model : ForwardModel
    candidates : effect names to test (default: the whole catalog)
    alpha : float
        Family-wise level: each round's candidates are tested at alpha / (number of candidates).
    min_heldout_gain : float
        Relative drop of the leave-one-height-out force RMSE an effect must bring (ignored with one push).
    max_effects : int
        At most this many effects are added.
    top_k : int
        Each round fits the ``top_k`` most significant candidates and adds the one with the
        largest likelihood ratio among those that pass (the score test is local; the fitted
        likelihood ratio tells similar signatures apart, e.g. base tilt and rest curvature).

    Returns
    -------
    dict
        ``added_effects``, ``candidates`` (every test of every round), ``before`` / ``after``
        errors, ``unexplained_structure``, the structure blocks, and the fitted values.
    """
    log = log or (lambda msg: None)
    unknown = [c for c in candidates if c not in CATALOG]
    if unknown:
        raise ValueError(f"candidates: expected effects from {', '.join(CATALOG)}, got {', '.join(unknown)}")
    dg = Diagnoser(model)
    L = model.length_m
    log("fitting the plain model")
    cur = plain = dg.fit((), dg.start())
    before = dg.errors(cur)
    before_struct = dg.structure(cur, ratio=structure_ratio)
    added: list[str] = []
    rows: list[dict] = []
    history = [{"effects": [], "errors": before, "loglik": cur.loglik}]
    for rnd in range(1, max_effects + 1):
        remaining = [c for c in candidates if c not in added]
        if not remaining:
            break
        level = alpha / len(remaining)
        tests = []
        for e in remaining:
            log(f"round {rnd}: testing {e}")
            t = dg.score(cur, e)
            tests.append({"effect": e, "round": rnd, **t, "level": level, "selected": False})
        tests.sort(key=lambda t: t["p_value"])
        rows += tests
        accepted = None
        for t in [t for t in tests if t["p_value"] < level][:top_k]:
            e = t["effect"]
            log(f"round {rnd}: fitting with {e}")
            x0 = np.concatenate([cur.x, [_start_coord(e, t, cur, L)]])
            new = dg.fit(cur.effects + (e,), x0, max_nfev=12 if e in SLOW else 40)
            lr = 2.0 * (new.loglik - cur.loglik)
            t["lr_statistic"] = float(lr)
            t["fitted"] = new.natural(L)
            if lr <= stats.chi2.isf(level, 1):
                t["rejected_because"] = "likelihood ratio below the threshold"
                continue  # no held-out refits for a candidate that fails already
            err = dg.errors(new)
            t["heldout_force_rmse_N"] = err["heldout_force_rmse_N"]
            gain_ok = (
                before["heldout_force_rmse_N"] is None
                or err["heldout_force_rmse_N"] <= (1 - min_heldout_gain) * history[-1]["errors"]["heldout_force_rmse_N"]
            )
            if not gain_ok:
                t["rejected_because"] = "held-out error not reduced"
            elif accepted is None or lr > accepted[3]:
                accepted = (e, new, err, lr, t)
        if accepted is not None:
            accepted[4]["selected"] = True
            for t in tests:
                if "lr_statistic" in t and not t["selected"] and "rejected_because" not in t:
                    t["rejected_because"] = "a better-fitting effect was added"
        if accepted is None:
            break
        e, cur, err = accepted[:3]
        added.append(e)
        history.append({"effects": list(added), "errors": err, "loglik": cur.loglik})
        log(f"added {e}")
    after = history[-1]["errors"]
    struct = dg.structure(cur, ratio=structure_ratio)
    return {
        "added_effects": added,
        "candidates": rows,
        "before": before,
        "after": after,
        "unexplained_structure": struct["unexplained_structure"],
        "structure_before": before_struct["blocks"],
        "structure_after": struct["blocks"],
        "fitted": cur.natural(L),
        "noise": {"sigma_force_N": cur.sigma_force, "shape_scale": cur.shape_scale},
        "history": history,
        "_fit": cur,
        "_plain": plain,
    }


def _start_coord(effect: str, test: dict, fit: MapFit, L: float) -> float:
    """A start for the new coordinate: a small step in the direction the score points."""
    if effect == "yield":
        return float(np.log(test.get("yield_moment_Nm", 1.0)))
    neutral, step = _COORD[effect][0], _COORD[effect][1]
    if effect == "force_offset":
        step = fit.sigma_force
    return neutral + 2 * step * (test["direction"] or 1.0)

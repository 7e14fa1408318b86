"""Which height next: expected information gain of one more push (issue 7).

A planned push at height h advances the contact by up to ``displacement_m`` and
records ``n_samples`` forces, equally spaced in contact displacement; samples
past a draw's slip are not recorded (the fit only uses engaged samples). The
utility is the expected information gain (EIG) about (log EI0, p),

    EIG(h) = E_{theta ~ posterior, y ~ p(y | theta, h)} [ log p(y | theta, h) - log p(y | h) ],

the expected KL divergence from the current posterior to the next one.

Two estimators share one force predictor (the force-displacement table of
:class:`~bayesrod.inference.likelihood.ForceCurves` at that height, interpolated in p;
EI0 is a pure scale, eq. ivp nondimensionalised):

* :func:`eig_gaussian` (fast, the default): per posterior draw, the Fisher
  information of the planned forces, J^T J / sigma^2, combined with the
  posterior covariance Sigma of (log EI0, p): ``0.5 log det(I + Sigma A)``,
  averaged over draws (local linearisation, "Bayesian D-optimality").
  It also gives the information about one derived quantity (k_theta at a
  target height, or log EI(s) averaged along the stem).
* :func:`eig_nested_mc` (reference, the CLI default): nested Monte Carlo
  (Ryan 2003) with independent inner draws plus the outer draw itself (the
  contrastive bound of Foster et al. 2020, finite and <= log(M + 1)); it
  converges as the inner sample grows and validates the fast one on small
  cases (tests/test_design.py).

Feasibility (:func:`feasibility`) follows the seed: near the base the force
exceeds the sensor's range, near the tip it is too small to measure, and a
push that slips almost at once teaches nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from ..physics import Effects
from ..physics.lumped import ktheta_nd
from .likelihood import FORCE_LOG_FLOOR, TABLE_EFFECTS, EffectAxis, ForceCurves, _lagrange4, force_log_table
from .summary import credible_interval

TARGETS = ("params", "ei", "k_theta")


@dataclass(frozen=True)
class PushPlan:
    """What the next push will do.

    Attributes
    ----------
    displacement_m : float
        Planned contact displacement [m]; the push stops there (or at the slip).
    n_samples : int
        Force samples over the planned displacement (equally spaced in displacement).
    force_range_N : (float, float) or None
        Sensor range [N] (``sensor.force_range_N``); None: no range check, only the noise check.
    confidence : float
        A height is feasible when the peak force lies in range with at least this probability.
    min_fraction : float
        Infeasible if the median draw slips before this fraction of the planned displacement.
    min_snr : float
        Without a range: infeasible if the median peak force is below this many force-noise sd.
    """

    displacement_m: float
    n_samples: int = 40
    force_range_N: tuple[float, float] | None = None
    confidence: float = 0.9
    min_fraction: float = 0.2
    min_snr: float = 3.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.displacement_m) and self.displacement_m > 0):
            raise ValueError(f"displacement_m: expected a positive number [m], got {self.displacement_m!r}")
        if int(self.n_samples) < 2:
            raise ValueError(f"n_samples: expected at least 2, got {self.n_samples!r}")
        if self.force_range_N is not None:
            lo, hi = self.force_range_N
            if not (0 <= lo < hi):
                raise ValueError(f"force_range_N: expected [low, high] with 0 <= low < high, got {self.force_range_N}")
        if not (0 < self.confidence < 1):
            raise ValueError(f"confidence: expected a probability in (0, 1), got {self.confidence!r}")

    @property
    def D_m(self) -> NDArray:
        """Planned contact displacements (n_samples,) [m]."""
        n = int(self.n_samples)
        return self.displacement_m * np.arange(1, n + 1) / n


class HeightPredictor:
    """Sensor forces of posterior draws for a planned push at one height.

    Parameters
    ----------
    height_m, length_m : float
    D_m : (n,) array
        Contact displacements [m].
    p_span : (low, high)
        Range of p the draws cover; the table's p grid spans it (step <= 0.05, >= 8 nodes).
    effects : Effects, optional
        Fixed effects (e.g. a fitted tabled effect at its posterior median) of the forward model.
    EI0_ref : float
        EI0 at which the nondimensional effect groups are taken (the posterior median).
    effect_axis : EffectAxis, optional
        A tabled effect that varies from draw to draw (the one a fit sampled, e.g. a base compliance):
        the curves are built at every node of its uniform coordinate grid and interpolated in it (4-point
        Lagrange, as in p), and :meth:`forces` takes each draw's coordinate ``u``. ``effects`` must then
        hold no tabled effect.
    """

    def __init__(
        self,
        height_m: float,
        length_m: float,
        D_m,
        p_span,
        effects: Effects | None = None,
        EI0_ref=1.0,
        effect_axis: EffectAxis | None = None,
    ):
        self.h, self.L = float(height_m), float(length_m)
        self.D = np.asarray(D_m, float)
        lo, hi = float(p_span[0]), float(p_span[1])
        pad = max(0.02, 0.05 * (hi - lo))
        lo, hi = max(0.0, lo - pad), hi + pad
        n = max(8, int(np.ceil((hi - lo) / 0.05)) + 1)
        self.p_grid = np.linspace(lo, hi, n)
        eff = effects or Effects()
        tabled = {k: v for k, v in eff.to_mapping().items() if k in TABLE_EFFECTS}
        self.effect_axis = effect_axis
        if effect_axis is not None:
            if tabled:
                raise ValueError(
                    f"effects: expected no fixed tabled effect beside the varying {effect_axis.name}, "
                    f"got {', '.join(tabled)}"
                )
            eta = np.full(effect_axis.grid.size, self.h / self.L)
            rows = ForceCurves.batch(eta, self.p_grid, effects_nd=effect_axis.nondim(effect_axis.grid))
            self.f_table = np.stack([c.force(self.D / self.L) for c in rows])  # (E, P, n)
            self.d_end = np.stack([c.d_end for c in rows])  # (E, P)
            self.d_early = np.stack([c.d_early for c in rows])  # (E, P)
            # read in log space along a friction axis, as the likelihood reads its own (RodLikelihood.interp_force)
            self._f_log = force_log_table(self.f_table, effect_axis)
        else:
            eff_nd = Effects.from_mapping(tabled).nondim(self.L, EI0_ref) if tabled else None
            curves = ForceCurves(self.h / self.L, self.p_grid, effects_nd=eff_nd)
            self.f_table = curves.force(self.D / self.L)  # (P, n)
            self.d_end = curves.d_end  # (P,)
            self.d_early = curves.d_early  # (P,): where the force comes within SLIP_FORCE_REL of the end's
            self._f_log = None
        self.offset = eff.force_offset
        self.yield_moment = eff.yield_moment

    def _weights(self, p: NDArray, u: NDArray | None):
        """Table indices and weights of draws (K,): p only, or (u, p) with an effect axis."""
        p = np.atleast_1d(np.asarray(p, float))
        idx, w = _lagrange4(self.p_grid, np.clip(p, self.p_grid[0], self.p_grid[-1]))
        if self.effect_axis is None:
            return idx, w, None, None
        if u is None:
            raise ValueError(f"u: expected each draw's {self.effect_axis.name} coordinate, got none")
        g = self.effect_axis.grid
        iu, wu = _lagrange4(g, np.clip(np.atleast_1d(np.asarray(u, float)), g[0], g[-1]))
        return idx, w, iu, wu

    def _interp(self, table: NDArray, p: NDArray, u: NDArray | None) -> NDArray:
        """``table`` ((P, ...) or (E, P, ...)) at each draw: (K, ...)."""
        idx, w, iu, wu = self._weights(p, u)
        if iu is None:
            return np.einsum("ka,ka...->k...", w, table[idx])
        return np.einsum("ka,kb,kba...->k...", w, wu, table[iu[:, :, None], idx[:, None, :]])

    def forces(self, log_EI0: NDArray, p: NDArray, offset=None, yield_moment=None, u=None) -> NDArray:
        """Noise-free sensor force (K, n) [N] for draws (K,), held at the slip value past the slip;
        ``u`` (K,): each draw's effect coordinate (with an effect axis)."""
        if self._f_log is None:
            f = self._interp(self.f_table, p, u)
        else:
            f = np.exp(self._interp(self._f_log, p, u)) - FORCE_LOG_FLOOR
        F = np.exp(np.atleast_1d(log_EI0))[:, None] / self.L**2 * f
        my = self.yield_moment if yield_moment is None else np.atleast_1d(yield_moment)[:, None]
        if np.any(np.isfinite(my)):
            F = np.minimum(F, my / self.h)
        off = self.offset if offset is None else np.atleast_1d(offset)[:, None]
        return F + off

    def slip_m(self, p: NDArray, u: NDArray | None = None, *, early: bool = False) -> NDArray:
        """Contact displacement at which each draw slips (K,) [m] (inf: beyond the table): the branch's end,
        or with ``early`` where its force first comes within ``SLIP_FORCE_REL`` of the end's (the start of the
        plateau on which the stem may leave the probe; docs/inference.md, "The slip")."""
        table = self.d_early if early else self.d_end
        if self.effect_axis is None:
            return np.interp(np.atleast_1d(p), self.p_grid, table) * self.L
        return self._interp(table, p, u) * self.L

    def observed(self, p: NDArray, u: NDArray | None = None) -> NDArray:
        """(K, n) True where the planned sample is taken before the draw's slip."""
        return self.D[None, :] <= self.slip_m(p, u)[:, None]

    def jacobian(self, log_EI0: NDArray, p: NDArray, u: NDArray | None = None, **kw) -> NDArray:
        """d force / d (log EI0, p[, u]) at each draw: (K, n, 2), or (K, n, 3) with an effect axis;
        central differences."""
        d = 1e-4
        cols = []
        for a, b in ((d, 0.0), (0.0, d)):
            up = self.forces(log_EI0 + a, p + b, u=u, **kw)
            dn = self.forces(log_EI0 - a, p - b, u=u, **kw)
            cols.append((up - dn) / (2 * d))
        if self.effect_axis is not None:
            # one-sided at the grid's ends (a rigid clamp sits at u = 0): divide by the step taken
            g = self.effect_axis.grid
            u = np.atleast_1d(np.asarray(u, float))
            hi, lo = np.minimum(u + d, g[-1]), np.maximum(u - d, g[0])
            up = self.forces(log_EI0, p, u=hi, **kw)
            dn = self.forces(log_EI0, p, u=lo, **kw)
            cols.append((up - dn) / np.maximum(hi - lo, 1e-12)[:, None])
        return np.stack(cols, axis=-1)


def _functional_gradients(target: str, theta: NDArray, length_m: float, target_height_m: float | None) -> NDArray:
    """Gradients (K, G, 2) of the target quantities in (log EI0, p) at each draw."""
    K = theta.shape[0]
    if target == "k_theta":
        if target_height_m is None or not (0 < target_height_m < length_m):
            raise ValueError(
                f"target_height_m: expected a height in (0, L = {length_m:g}) m for target k_theta, "
                f"got {target_height_m!r}"
            )
        eta = target_height_m / length_m
        d = 1e-4
        p = theta[:, 1]
        dp = (np.log(ktheta_nd(eta, p + d)) - np.log(ktheta_nd(eta, np.maximum(p - d, 0.0)))) / (
            p + d - np.maximum(p - d, 0.0)
        )
        return np.stack([np.ones(K), dp], axis=-1)[:, None, :]
    if target == "ei":
        s = np.linspace(0.0, 0.9, 10)  # log EI(s) = log EI0 + 4 p log(1 - s/L), eq. EI_taper
        g = np.stack([np.ones_like(s), 4.0 * np.log1p(-s)], axis=-1)
        return np.broadcast_to(g, (K, s.size, 2))
    raise ValueError(f"target: expected one of {', '.join(TARGETS)}, got {target!r}")


def eig_gaussian(
    theta: NDArray,
    J: NDArray,
    mask: NDArray,
    sigma: NDArray,
    *,
    target: str = "params",
    length_m: float | None = None,
    target_height_m: float | None = None,
) -> float:
    """Expected information gain [nats] by local linearisation (fast estimator).

    Parameters
    ----------
    theta : (K, D) array
        Posterior draws of (log EI0, p), and of a sampled effect's coordinate when D = 3.
    J : (K, n, D) array
        Force sensitivities d F / d theta of the planned samples at each draw [N].
    mask : (K, n) bool array
        Samples recorded at each draw (before its slip).
    sigma : (K,) array
        Force noise sd of each draw [N].
    target : {"params", "ei", "k_theta"}
        Information about (log EI0, p) jointly, about log EI(s) (mean over s/L in [0, 0.9]), or
        about log k_theta at ``target_height_m`` (eq. kdist).

    Returns
    -------
    float
        mean over draws of 0.5 log det(I + Sigma A_k), A_k = J_k^T J_k / sigma_k^2 ("params"), or
        of 0.5 log(g^T Sigma g / g^T (Sigma^-1 + A_k)^-1 g) for a derived quantity with gradient g.
    """
    theta = np.asarray(theta, float)
    D = theta.shape[1]
    Sigma = np.atleast_2d(np.cov(theta, rowvar=False)) + 1e-12 * np.eye(D)
    Jm = np.where(np.asarray(mask)[..., None], J, 0.0)
    A = np.einsum("kni,knj->kij", Jm, Jm) / np.asarray(sigma, float)[:, None, None] ** 2
    if target == "params":
        M = np.eye(D)[None] + Sigma[None] @ A
        return float(np.mean(0.5 * np.linalg.slogdet(M)[1]))
    G = _functional_gradients(target, theta, length_m, target_height_m)  # (K, G, 2): stem quantities
    G = np.concatenate([G, np.zeros(G.shape[:2] + (D - 2,))], axis=-1)  # an effect coordinate does not enter
    post = np.linalg.inv(np.linalg.inv(Sigma)[None] + A)  # (K, 2, 2)
    v_pre = np.einsum("kgi,ij,kgj->kg", G, Sigma, G)
    v_post = np.einsum("kgi,kij,kgj->kg", G, post, G)
    return float(np.mean(0.5 * np.log(v_pre / v_post)))


def eig_nested_mc(
    F_outer: NDArray,
    mask_outer: NDArray,
    sigma_outer: NDArray,
    F_inner: NDArray,
    sigma_inner: NDArray,
    rng: np.random.Generator,
    chunk: int = 64,
) -> tuple[float, float]:
    """Expected information gain [nats] by nested Monte Carlo (reference estimator).

    Outer draws i simulate data y_i ~ N(F_i, sigma_i^2) on their recorded samples; the
    evidence p(y_i) is the mean likelihood over M independent inner draws j and draw i
    itself (prior contrastive estimation, Foster et al. 2020). Returns the estimate and its
    Monte Carlo standard error. It is a lower bound on the EIG that tightens as M grows and
    never exceeds log(M + 1): keep the EIGs you compare well below that.

    Parameters
    ----------
    F_outer : (N, n), mask_outer : (N, n) bool, sigma_outer : (N,)
    F_inner : (M, n), sigma_inner : (M,)
    """
    N, M = F_outer.shape[0], F_inner.shape[0]
    y = F_outer + sigma_outer[:, None] * rng.standard_normal(F_outer.shape)
    terms = np.empty(N)
    for a in range(0, N, chunk):
        b = min(N, a + chunk)
        m = mask_outer[a:b].astype(float)  # (c, n)
        r_self = (y[a:b] - F_outer[a:b]) / sigma_outer[a:b, None]
        ll_self = np.sum(m * (-0.5 * r_self**2), axis=1) - m.sum(1) * np.log(sigma_outer[a:b])
        r = (y[a:b, None, :] - F_inner[None]) / sigma_inner[None, :, None]  # (c, M, n)
        ll = np.einsum("cn,cmn->cm", m, -0.5 * r**2) - m.sum(1)[:, None] * np.log(sigma_inner)[None, :]
        # the outer draw joins the inner ones (prior contrastive estimation): a lower bound <= log(M + 1)
        # that converges to the EIG as M grows, and stays finite where plain nested MC explodes
        lse = logsumexp(np.concatenate([ll_self[:, None], ll], axis=1), axis=1)
        terms[a:b] = ll_self - (lse - np.log(M + 1))
    return float(terms.mean()), float(terms.std(ddof=1) / np.sqrt(N))


def feasibility(F: NDArray, mask: NDArray, slip_m: NDArray, sigma: NDArray, plan: PushPlan) -> dict:
    """Whether the planned push at one height can be made and measured.

    Parameters
    ----------
    F : (K, n) predicted sensor force [N]; mask : (K, n) recorded samples; slip_m : (K,) slip displacement [m];
    sigma : (K,) force noise sd [N].

    Returns
    -------
    dict
        ``feasible``, ``reason`` (None when feasible), ``peak_force_N`` quantiles, ``prob_in_range``
        and the median slip displacement.
    """
    Fm = np.where(mask, F, -np.inf)
    peak = np.max(Fm, axis=1)
    peak = np.where(np.isfinite(peak), peak, 0.0)  # slipped before the first sample
    q = credible_interval(peak)
    q05, q50, q95 = q["q05"], q["median"], q["q95"]
    slip_med = float(np.median(slip_m))
    out = {
        "peak_force_N": q,
        "slip_displacement_m": slip_med if np.isfinite(slip_med) else None,
        "prob_in_range": None,
        "feasible": True,
        "reason": None,
    }
    if slip_med < plan.min_fraction * plan.displacement_m:
        out["feasible"] = False
        out["reason"] = (
            f"slips almost at once: median slip at {1000 * slip_med:.1f} mm, before "
            f"{100 * plan.min_fraction:.0f}% of the planned {1000 * plan.displacement_m:.0f} mm"
        )
        return out
    if plan.force_range_N is not None:
        lo, hi = plan.force_range_N
        p_in = float(np.mean((peak >= lo) & (peak <= hi)))
        out["prob_in_range"] = p_in
        if p_in < plan.confidence:
            above = np.mean(peak > hi) >= np.mean(peak < lo)
            side, bound = ("above the sensor maximum", hi) if above else ("below the sensor minimum", lo)
            out["feasible"] = False
            out["reason"] = (
                f"peak force {q50:.3g} N [{q05:.3g}, {q95:.3g}] {side} {bound:g} N: "
                f"P(in range) = {p_in:.2f} < {plan.confidence:g}"
            )
            return out
    s = float(np.median(sigma))
    if q50 < plan.min_snr * s:
        out["feasible"] = False
        out["reason"] = (
            f"too small to measure: peak force {q50:.3g} N is below {plan.min_snr:g} x the force noise ({s:.3g} N)"
        )
    return out


#: table-coordinate nodes of a sampled effect in a design (over the draws' range: the posterior is narrow)
DESIGN_EFFECT_NODES = 9


def _effect_axis(samples: dict, length_m: float) -> tuple[EffectAxis | None, NDArray | None]:
    """The table axis of the tabled effect the posterior sampled (its draws vary), over the draws' range
    of its coordinate, and that coordinate of every draw (S,); (None, None) without one. A fit samples
    at most one (the likelihood's one extra table axis)."""
    varying = [k for k in TABLE_EFFECTS if k in samples and np.ptp(np.asarray(samples[k], float)) > 0]
    if not varying:
        return None, None
    if len(varying) > 1:
        raise ValueError(f"samples: expected at most one sampled tabled effect, got {', '.join(varying)}")
    name = varying[0]
    u = EffectAxis(name, np.zeros(1)).coordinate(np.asarray(samples[name], float), np.asarray(samples["EI0"]), length_m)
    lo, hi = float(np.min(u)), float(np.max(u))
    pad = 0.05 * (hi - lo)
    lo = max(lo - pad, 0.0) if name == "base_compliance" else lo - pad  # u >= 0: the clamp is the end
    return EffectAxis(name, np.linspace(lo, hi + pad, DESIGN_EFFECT_NODES)), u


def design_heights(
    samples: dict,
    length_m: float,
    candidates_m,
    plan: PushPlan,
    *,
    target: str = "params",
    target_height_m: float | None = None,
    method: str = "nmc",
    n_draws: int = 400,
    n_inner: int = 4000,
    seed: int = 0,
    progress: bool = False,
) -> dict:
    """Rank candidate heights for the next push by expected information gain.

    Parameters
    ----------
    samples : dict of (S,) arrays
        Posterior draws in natural units: ``EI0``, ``p``, ``sigma_force_N`` (else ``sigma_force_N``
        must be given in ``plan``-free form via ``samples["sigma_force_N"]``), and any fitted effects.
        A sampled tabled effect (e.g. ``base_compliance``) varies with the draws: its table coordinate is
        a third parameter of the information gain (the stem and its anchorage together: with one height
        they are confounded, and the gain is largest where a push separates them); other tabled effects
        are held at their medians.
    length_m : float
    candidates_m : (C,) heights [m]
    plan : PushPlan
    target : {"params", "ei", "k_theta"}
    method : {"nmc", "gaussian"}
        Nested Monte Carlo (``n_draws`` outer, ``n_inner`` inner; the default), or the fast
        linearised estimator (``n_draws`` draws; needed for the derived targets).

    Returns
    -------
    dict
        ``recommended_height_m`` (None if no candidate is feasible) and ``candidates``: for each
        height ``expected_information_gain_nats``, ``feasible``, ``reason``, ``predicted_peak_force_N``
        (median) and the peak force quantiles.
    """
    from tqdm.auto import tqdm

    if target not in TARGETS:
        raise ValueError(f"target: expected one of {', '.join(TARGETS)}, got {target!r}")
    if method not in ("gaussian", "nmc"):
        raise ValueError(f"method: expected gaussian or nmc, got {method!r}")
    if method == "nmc" and target != "params":
        raise ValueError(f"method: expected target params for nmc (nested MC is for (log EI0, p)), got {target!r}")
    if "sigma_force_N" not in samples:
        raise ValueError(
            "samples: expected a posterior with force noise sigma_force_N (a fit that used forces), got "
            + ", ".join(sorted(samples))
        )
    L = float(length_m)
    rng = np.random.default_rng(seed)
    S = np.asarray(samples["EI0"]).size
    take = rng.permutation(S)
    outer = take[: min(n_draws, S)]
    inner = take[min(n_draws, S) :][:n_inner] if method == "nmc" else None
    if method == "nmc" and inner.size < 100:
        inner = rng.choice(S, size=n_inner)  # too few left over: resample (adds a little dependence)

    axis, u_all = _effect_axis(samples, L)

    def draws(ix):
        cols = [np.log(samples["EI0"][ix]), samples["p"][ix]]
        if axis is not None:  # the sampled effect's table coordinate (u = c/(1+c) for a base compliance)
            cols.append(u_all[ix])
        th = np.column_stack(cols)
        kw = {}
        if "force_offset" in samples:
            kw["offset"] = np.asarray(samples["force_offset"])[ix]
        if "yield" in samples:
            kw["yield_moment"] = np.asarray(samples["yield"])[ix]
        return th, np.asarray(samples["sigma_force_N"])[ix], kw

    th_o, sig_o, kw_o = draws(outer)
    u_o = th_o[:, 2] if axis is not None else None
    varying = axis.name if axis is not None else None
    fixed = {k: float(np.median(samples[k])) for k in TABLE_EFFECTS if k in samples and k != varying}
    effects = Effects.from_mapping(fixed)
    p_all = np.asarray(samples["p"])
    p_span = (float(np.min(p_all)), float(np.max(p_all)))
    EI0_ref = float(np.median(samples["EI0"]))
    rows = []
    for h in tqdm(np.atleast_1d(candidates_m), desc="design: candidate heights", unit="height", disable=not progress):
        h = float(h)
        row = {"height_m": h}
        if not (0 < h < L):
            row.update(
                expected_information_gain_nats=None,
                feasible=False,
                reason=f"outside the stem: expected 0 < h < L = {L:g} m",
                predicted_peak_force_N=None,
            )
            rows.append(row)
            continue
        pred = HeightPredictor(h, L, plan.D_m, p_span, effects, EI0_ref, effect_axis=axis)
        F = pred.forces(th_o[:, 0], th_o[:, 1], u=u_o, **kw_o)
        mask = pred.observed(th_o[:, 1], u_o)
        feas = feasibility(F, mask, pred.slip_m(th_o[:, 1], u_o), sig_o, plan)
        slip_from = float(np.median(pred.slip_m(th_o[:, 1], u_o, early=True)))
        if method == "gaussian":
            J = pred.jacobian(th_o[:, 0], th_o[:, 1], u=u_o, **kw_o)
            eig = eig_gaussian(th_o, J, mask, sig_o, target=target, length_m=L, target_height_m=target_height_m)
            se = None
        else:
            th_i, sig_i, kw_i = draws(inner)
            F_i = pred.forces(th_i[:, 0], th_i[:, 1], u=th_i[:, 2] if axis is not None else None, **kw_i)
            eig, se = eig_nested_mc(F, mask, sig_o, F_i, sig_i, rng)
        row.update(
            expected_information_gain_nats=float(eig),
            feasible=bool(feas["feasible"]),
            reason=feas["reason"],
            predicted_peak_force_N=feas["peak_force_N"]["median"],
            peak_force_N=feas["peak_force_N"],
            prob_in_range=feas["prob_in_range"],
            slip_displacement_m=feas["slip_displacement_m"],
            slip_from_displacement_m=slip_from if np.isfinite(slip_from) else None,
            recorded_fraction=float(mask.mean()),
        )
        if se is not None:
            row["eig_standard_error_nats"] = se
        rows.append(row)
    ok = [r for r in rows if r["feasible"]]
    best = max(ok, key=lambda r: r["expected_information_gain_nats"]) if ok else None
    return {
        "recommended_height_m": best["height_m"] if best else None,
        "candidates": rows,
        "target": target if target != "k_theta" else f"k_theta@{target_height_m:g}",
        "method": method,
        "plan": {
            "displacement_m": plan.displacement_m,
            "n_samples": int(plan.n_samples),
            "force_range_N": list(plan.force_range_N) if plan.force_range_N else None,
            "confidence": plan.confidence,
            "min_fraction": plan.min_fraction,
        },
        "fixed_effects": fixed,
        "parameters": ["log_EI0", "p"] + ([f"{varying}_coordinate"] if varying else []),
        "n_draws": int(outer.size),
    }

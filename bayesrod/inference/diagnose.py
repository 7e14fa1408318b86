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

Noise: AR(1) force noise per push by default (residuals whitened to innovations, rho and the
innovation sd profiled per model), independent shape points. Statistics (docs/diagnose.md):

* **Screen**: a score (Rao) test per smooth effect, S = (g~^T r)^2 / (g~^T g~) with g~ the
  effect's whitened sensitivity projected off the fitted Jacobian (chi^2_1; one-sided for base
  compliance and self weight), and a profile likelihood ratio over the yield moment (chi^2_2). The
  screen whitens with the AR(1) of the residuals around a degree-5 smooth (the fit's own rho absorbs
  the trend a missing effect leaves). Level alpha / (number of candidates).
* **Every screened candidate is refitted** and passes when (1) its likelihood ratio, each model with
  its own profiled noise, exceeds the chi^2_1 quantile; (2) the held-out force RMSE from **true
  refits** (leave one height out; one push: its last third) falls by ``min_heldout_gain``; (3) a
  parametric bootstrap under the current model's AR(1) noise (:func:`null_heldout_gain`) gives
  p < ``heldout_alpha`` for that fall. The passing candidate with the largest likelihood ratio is
  **added**; with none, pairs are tried when structure remains; otherwise the loop stops.
* **Structure test** on the final residuals, per push and kind: an F test of a degree-5 Legendre
  smooth, generalised least squares under the fitted AR(1) for forces. ``unexplained_structure``
  when some block has p < 1e-3, or the force blocks pooled over pushes have p < 0.01, with a smooth
  above ``structure_ratio`` marginal noise sd.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.interpolate import CubicSpline, PchipInterpolator
from scipy.optimize import least_squares, lsq_linear

from ..physics import Effects
from ..physics.effects import EFFECT_NAMES
from ..physics.elastica import centerline_normal_offsets, centerline_x_at_heights, force_from_displacement_nd
from .likelihood import HEIGHT_CUT_SD, PRELOAD_MAX_L, ForceCurves, PushData, ar1_innovations

CATALOG = EFFECT_NAMES  # every effect of the contract's catalog is a candidate

#: level of the held-out bootstrap gate (:func:`null_heldout_gain`) per candidate. On clean data the
#: likelihood-ratio gate passes often (its chi^2 reference assumes the fitted AR(1) noise exactly; seed 149
#: of the AR(1) study: LR 15.3 against 10.2), so this gate sets the false-add rate: at 0.05 clean data got an
#: effect in 3 of 50 replicates, each with p 0.040-0.048 (docs/validation.md, "Session 36").
HELDOUT_ALPHA = 0.02

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
# effects with a second start from a grid when added to the plain model (Diagnoser.grid_start)
GRID_STARTED = ("yield", "base_compliance")
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


MAX_NODES = 32  # force solves per push and parameter set; other samples read off a cubic spline through them
P_MAX = 3.0  # the taper exponent's upper bound: the priors' (priors/*.json truncate p to [0, 3]) and the tables'
RHO_MAX = 0.99  # AR(1) correlation of the force noise is estimated in [-0.5, RHO_MAX]
BLOCK_TRAIN = 2.0 / 3.0  # one push: the first two thirds of its samples fit, the last third is held out
#: a candidate of the round an effect was added in whose likelihood ratio falls short of the added one's by
#: less than this (2 ln 10: a likelihood ratio of 10 between the two models, the same number of parameters)
#: is an alternative these data do not tell apart (forces alone: rest curvature 0.3 1/m and a base tilt of
#: 0.076 rad on the twig, seed 20, likelihood-ratio statistics 48.70 and 48.79; docs/diagnose.md)
ALTERNATIVE_LR = 2.0 * np.log(10.0)


def _scale_fit(g: NDArray, F: NDArray) -> tuple[NDArray, NDArray]:
    """Forces linear in EI0: for each row of ``g`` (P, n), forces per unit EI0, the least-squares EI0
    (P,) fitting ``F`` (n,) and its residual sum of squares (P,), infinite where that EI0 is not positive."""
    gg = np.einsum("pn,pn->p", g, g)
    a = (g @ F) / np.where(gg > 0, gg, np.inf)
    return a, np.where(a > 0, np.sum((F[None, :] - a[:, None] * g) ** 2, axis=1), np.inf)


def _spline_matrix(D: NDArray, n_nodes: int, preloaded: bool = False) -> tuple[NDArray, NDArray]:
    """Solver nodes (n_nodes,) of one push and the matrix (n, n_nodes) reading its n samples off them.

    With at most ``n_nodes`` samples the nodes are the samples (padded by repeating the last one) and
    the matrix selects them; otherwise the nodes are evenly spaced over the displacements and the matrix
    is the not-a-knot cubic spline through them (linear in the node values), the nodes spaced as
    Chebyshev-Lobatto points between first contact and the largest displacement. ``preloaded``: the push
    is in contact from its first sample (a preload is added to every displacement), so displacements
    below zero are nodes too (a wire sensor's contact point starts behind the robot's origin).
    """
    if D.size <= n_nodes:
        pad = np.full(n_nodes - D.size, D[-1] if D.size else 0.0)
        return np.concatenate([D, pad]), np.eye(D.size, n_nodes)
    # the force is zero (plus any offset) up to first contact, d = 0: a kink the spline must not straddle
    lo = float(D.min()) if preloaded else max(float(D.min()), 0.0)
    hi = max(float(D.max()), lo + 1e-12)
    nodes = lo + (hi - lo) * 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n_nodes)))  # denser at both ends
    return nodes, CubicSpline(nodes, np.eye(n_nodes))(np.maximum(D, lo))


def _through(nodes: NDArray, f: NDArray, D: NDArray) -> NDArray:
    """Forces at ``D`` from node values: a cubic spline (4+ nodes), a monotone cubic (2-3), a constant (1)."""
    if nodes.size >= 4:
        return CubicSpline(nodes, f)(D)
    if nodes.size >= 2:
        return PchipInterpolator(nodes, f)(D)
    return np.full(D.shape, f[0])


def _block(d: PushData) -> tuple[int, NDArray] | None:
    """One push held out by blocks: the training samples (the first two thirds) and the frames taken
    before the last of them; None when the push is too short (fewer than 4 training or 2 held samples)."""
    n_train = int(np.ceil(BLOCK_TRAIN * d.D_m.size))
    if n_train < 4 or d.D_m.size - n_train < 2:
        return None
    return n_train, np.flatnonzero(d.frame_D_m <= d.D_m[n_train - 1])


def _cut(d: PushData, samples: NDArray, frames: NDArray) -> PushData:
    """``d`` restricted to the force ``samples`` (bool or index) and the ``frames`` (indices) kept."""
    from dataclasses import replace

    frames = np.asarray(frames, int)
    sel = np.isin(d.frame_index, frames)
    remap = np.full(max(d.frame_D_m.size, 1), -1)
    remap[frames] = np.arange(frames.size)
    return replace(
        d,
        D_m=d.D_m[samples],
        F_N=d.F_N[samples],
        frame_D_m=d.frame_D_m[frames],
        frame_index=remap[d.frame_index[sel]] if sel.any() else d.frame_index[:0],
        x_m=d.x_m[sel],
        z_m=d.z_m[sel],
        sd_m=None if d.sd_m is None else d.sd_m[sel],
    )


@dataclass
class ForwardModel:
    """Predictions of a specimen's engaged observations (direct solves, batched over parameter sets).

    Parameters
    ----------
    data : list of PushData
        Engaged forces and centerline points of each push (``prepare_data``).
    length_m : float
    n_nodes : int
        Force solves per push: pushes with more samples are read off a cubic spline through
        ``n_nodes`` displacements (relative error below 1e-5 of the peak force, tested against the
        direct solve; a push whose prediction slips is solved at every sample, one that yields between
        nodes is read off a monotone cubic).
    preload : bool
        Each push with forces has a preload [m]: the contact displacement already made when recording
        began, added to its displacements (a nuisance, in [0, PRELOAD_MAX_L L] as in the fit's prior),
        those of its forces and of its frames alike. Parameter vectors are then (log EI0, p, preload of
        each push with forces, effect coordinates).
    length_bounds_m : (float, float) or None
        Fit the stem length as a nuisance within these bounds [m] (the fit's length prior's support,
        :func:`~bayesrod.inference.likelihood.default_length_prior`) instead of holding it at
        ``length_m``; forces only. The length follows the preloads in a parameter vector:
        (log EI0, p, preloads, L, effect coordinates). Every model of a diagnosis fits it, so a
        likelihood ratio compares like with like.
    height_sd_m : float
        Each push with forces has a contact-height error [m] with this prior sd (0: the heights are
        exact): the force is applied at h + dh, in its force solves and its frames alike. The errors
        follow the length: (log EI0, p, preloads, L, height errors, effect coordinates); the fits
        penalise them by their normal prior (a penalised likelihood) and bound them at 4 sd, as the
        fit's prior is cut (:func:`bayesrod.fit`'s ``height_sd_m``). A held-out push is predicted at
        its recorded height (its error's prior mean): nothing else tells its error.
    """

    data: list[PushData]
    length_m: float
    n_nodes: int = MAX_NODES
    preload: bool = False
    length_bounds_m: tuple[float, float] | None = None
    height_sd_m: float = 0.0
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
        self.force_pushes = [k for k, d in enumerate(self.data) if d.D_m.size]
        nodes, self._spline, self._slices = [], [], []
        start = 0
        for d in self.data:
            if d.D_m.size:
                nd, S = _spline_matrix(d.D_m, self.n_nodes, preloaded=self.preload)
                nodes.append(nd)
                self._spline.append(S)
                self._slices.append(slice(start, start + d.D_m.size))
            start += d.D_m.size
        self._nodes = np.array(nodes).reshape(len(nodes), self.n_nodes)
        self.first_sample = np.zeros(self.n_force, bool)  # first force sample of each push (AR(1) whitening)
        for sl in self._slices:
            self.first_sample[sl.start] = True
        if self.length_bounds_m is not None:
            if self.n_points:
                raise ValueError(
                    "length: expected a force-only diagnosis (centerlines not used) to fit the stem length, "
                    "got centerlines"
                )
            lo, hi = (float(v) for v in self.length_bounds_m)
            h_max = max(d.height_m for d in self.data)
            if not (np.isfinite(hi) and h_max < lo < hi):
                raise ValueError(
                    f"length_bounds_m: expected bounds above the highest contact ({h_max:g} m), got [{lo:g}, {hi:g}] m"
                )
            self.length_bounds_m = (lo, hi)
        sd = self.height_sd_m
        if isinstance(sd, bool) or not isinstance(sd, (int, float)) or not (np.isfinite(sd) and sd >= 0):
            raise ValueError(f"height_sd_m: expected a contact-height sd >= 0 in metres, got {sd!r}")
        h_min = min(self.data[k].height_m for k in self.force_pushes) if self.force_pushes else np.inf
        if HEIGHT_CUT_SD * sd >= h_min:
            raise ValueError(
                f"height_sd_m: expected {HEIGHT_CUT_SD:g} sd below the lowest contact ({h_min:g} m), got sd {sd:g} m"
            )
        self.height_sd_m = float(sd)

    @property
    def n_preloads(self) -> int:
        """Preload coordinates of a parameter vector (one per push with forces, or none)."""
        return len(self.force_pushes) if self.preload else 0

    @property
    def length_index(self) -> int | None:
        """Index of the fitted stem length [m] in a parameter vector (None: the length is held)."""
        return 2 + self.n_preloads if self.length_bounds_m is not None else None

    @property
    def n_heights(self) -> int:
        """Contact-height error coordinates of a parameter vector (one per push with forces, or none)."""
        return len(self.force_pushes) if self.height_sd_m > 0 else 0

    @property
    def height_index(self) -> int:
        """Index of the first contact-height error [m] in a parameter vector (after the length)."""
        return 2 + self.n_preloads + (self.length_bounds_m is not None)

    @property
    def n_base(self) -> int:
        """Parameters before the effect coordinates: log EI0, p, the preloads, the length (if fitted)
        and the contact-height errors (if any)."""
        return self.height_index + self.n_heights

    @property
    def start_length(self) -> float | None:
        """Where a fitted length starts [m]: the given one, inside its bounds (None: the length is held)."""
        return float(np.clip(self.length_m, *self.length_bounds_m)) if self.length_bounds_m is not None else None

    def lengths(self, X: NDArray) -> NDArray:
        """Stem length [m] of each parameter set of ``X`` (K, n_par): fitted, or ``length_m``."""
        X = np.atleast_2d(np.asarray(X, float))
        i = self.length_index
        return X[:, i].copy() if i is not None else np.full(X.shape[0], float(self.length_m))

    def push_columns(self, unit: int) -> list[int]:
        """Columns of a parameter vector that belong to the ``unit``-th push with forces alone: its
        preload and its contact-height error (where the model has them)."""
        out = [2 + unit] if self.preload else []
        if self.n_heights:
            out.append(self.height_index + unit)
        return out

    def heights(self, X: NDArray) -> NDArray:
        """Contact height [m] of each push with forces for each parameter set of ``X`` (K, n_par): (K, J),
        the recorded heights plus the sets' height errors (if any)."""
        X = np.atleast_2d(np.asarray(X, float))
        h = np.array([self.data[k].height_m for k in self.force_pushes], float)
        if not self.n_heights:
            return np.broadcast_to(h, (X.shape[0], h.size)).copy()
        i = self.height_index
        return h[None, :] + X[:, i : i + self.n_heights]

    def _like(self, data: list[PushData]) -> ForwardModel:
        """A model of other data with this one's settings (length, nodes, preload, length bounds)."""
        return ForwardModel(data, self.length_m, self.n_nodes, self.preload, self.length_bounds_m, self.height_sd_m)

    def heldout_splits(self) -> list[tuple[str, ForwardModel, ForwardModel]]:
        """(name, training model, held-out model) of every held-out unit.

        Two or more pushes with forces: leave one push (height) out, all its forces and frames.
        One push: its last third of force samples (by time: extrapolation to larger displacements),
        with the frames taken after the last training sample.
        """
        fp = self.force_pushes
        if len(fp) >= 2:
            return [
                (
                    self.data[k].id,
                    self._like([d for j, d in enumerate(self.data) if j != k]),
                    self._like([self.data[k]]),
                )
                for k in fp
            ]
        k = fp[0]
        d = self.data[k]
        if (block := _block(d)) is None:
            return []
        n_train, frames = block
        train = [_cut(d, np.arange(n_train), frames) if j == k else e for j, e in enumerate(self.data)]
        held = _cut(d, np.arange(n_train, d.D_m.size), np.zeros(0, int))
        return [
            (
                f"{d.id} (last third)",
                self._like(train),
                self._like([held]),
            )
        ]

    def heldout_masks(self) -> list[tuple[NDArray, NDArray, NDArray]]:
        """Row masks (training forces, training points, held-out forces) of each ``heldout_splits`` unit."""
        fp = self.force_pushes
        if len(fp) >= 2:
            return [(self.force_push != k, self.point_push != k, self.force_push == k) for k in fp]
        k = fp[0]
        d = self.data[k]
        if (block := _block(d)) is None:
            return []
        n_train, frames = block
        idx = np.zeros(self.n_force, int)
        idx[self._slices[0]] = np.arange(d.D_m.size)
        train_f = (self.force_push != k) | (idx < n_train)
        train_p = (self.point_push != k) | np.isin(np.where(self.point_push == k, self._frame_of_point(k), -1), frames)
        return [(train_f, train_p, ~train_f)]

    def _frame_of_point(self, k: int) -> NDArray:
        out = np.full(self.n_points, -1)
        out[self.point_push == k] = self.data[k].frame_index
        return out

    def forces(self, X: NDArray, effects: tuple[str, ...]) -> NDArray:
        """Sensor forces (K, n_force) for K parameter sets ``X`` (K, 2 + n_effects): one batched solve."""
        X = np.atleast_2d(np.asarray(X, float))
        K = X.shape[0]
        out = np.zeros((K, self.n_force))
        if not self.n_force:
            return out
        EI0 = np.exp(np.clip(X[:, 0], -60.0, 60.0))  # a wild trial step must not overflow
        Ls = self.lengths(X)  # (K,): the nondimensional groups of each set use its own length
        nb = self.n_base
        effs = [effects_from_coords(dict(zip(effects, X[k, nb:], strict=True)), EI0[k], Ls[k]) for k in range(K)]
        nds = [e.nondim(Ls[k], EI0[k]) for k, e in enumerate(effs)]
        eff = {key: np.array([float(n[key]) for n in nds])[:, None, None] for key in nds[0]}
        heights = self.heights(X)  # (K, J)
        eta = heights[:, :, None] / Ls[:, None, None]
        # each push's preload shifts its nodes and samples alike: the spline weights do not change
        shift = X[:, 2 : 2 + self.n_preloads] if self.preload else np.zeros((K, len(self.force_pushes)))
        r = force_from_displacement_nd(
            (self._nodes[None] + shift[:, :, None]) / Ls[:, None, None], eta, X[:, 1][:, None, None], eff
        )
        scale = EI0 / Ls**2
        # Samples that need their own solve (a yield onset between nodes) are gathered over every
        # parameter set and push and solved in one batch: one march costs about the same for 1 or 100
        # problems, and a Jacobian asks for one set per coordinate.
        direct: list[tuple[int, float, slice, NDArray, NDArray, bool]] = []  # (set, height, slice, where, D, hold)
        for j, k in enumerate(self.force_pushes):
            d, sl, S = self.data[k], self._slices[j], self._spline[j]
            exact = S.shape[0] <= S.shape[1]  # the nodes are the samples
            for kk in range(K):
                f = r["f_measured"][kk, j] * scale[kk]
                y = r["yielded"][kk, j]
                if exact:
                    out[kk, sl] = _hold(f[: d.D_m.size])
                elif np.all(np.isfinite(f)) and (y.all() or not y.any()):
                    out[kk, sl] = S @ f
                elif np.all(np.isfinite(f)):  # the yield onset (a kink) between nodes
                    out[kk, sl], gap, D = self._yield_branches(j, d, f, y)
                    if gap.any():
                        direct.append((kk, heights[kk, j], sl, gap, D[gap] + shift[kk, j], False))
                elif not (y.any() and not y[np.isfinite(f)].all()):  # slips (no yield onset): hold
                    out[kk, sl] = self._slipped(j, d, f)
                else:  # slips and yields: solve at every sample, hold past the slip
                    direct.append((kk, heights[kk, j], sl, np.ones(d.D_m.size, bool), d.D_m + shift[kk, j], True))
        if direct:
            kks = np.concatenate([np.full(job[4].size, job[0]) for job in direct])
            D = np.concatenate([job[4] for job in direct])
            h = np.concatenate([np.full(job[4].size, job[1]) for job in direct])
            sol = force_from_displacement_nd(
                D / Ls[kks], h / Ls[kks], X[kks, 1], {key: v[kks, 0, 0] for key, v in eff.items()}
            )
            F = sol["f_measured"] * scale[kks]
            start = 0
            for kk, _, sl, where, Dj, hold in direct:
                f = F[start : start + Dj.size]
                start += Dj.size
                if hold:
                    out[kk, sl] = _hold(f)
                else:
                    out[kk, sl][where] = f
        return out

    def _slipped(self, j: int, d: PushData, f: NDArray) -> NDArray:
        """Forces of a push whose prediction slips between nodes: a spline through the nodes before the
        slip, and past the last of them the force held (what the measured force does once the stem slips
        past the sensor is not modelled; the likelihood tables hold it too)."""
        nodes = self._nodes[j]
        ok = np.isfinite(f)
        n_ok = int(np.argmin(ok)) if not ok.all() else ok.size  # the finite prefix
        if n_ok == 0:
            return np.zeros(d.D_m.size)
        D = np.maximum(d.D_m, nodes[0])
        last = nodes[n_ok - 1]
        out = np.full(D.size, f[n_ok - 1])
        sel = D <= last
        if sel.any():
            out[sel] = _through(nodes[:n_ok], f[:n_ok], D[sel])
        return out

    def _yield_branches(self, j: int, d: PushData, f: NDArray, yielded: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """Forces of a push whose prediction yields between nodes: a spline per branch (elastic, plastic).

        Returns the forces (n,), the samples between the last elastic and the first plastic node (n,)
        bool, whose forces the caller solves directly (they are left unset here), and the samples'
        displacements clipped to the first node (n,) [m].
        """
        nodes = self._nodes[j]
        D = np.maximum(d.D_m, nodes[0])
        out = np.zeros(D.size)
        last_e, first_p = nodes[~yielded].max(), nodes[yielded].min()
        for sel, keep in ((D <= last_e, ~yielded), (D >= first_p, yielded)):
            if sel.any():
                out[sel] = _through(nodes[keep], f[keep], D[sel])
        return out, (D > last_e) & (D < first_p), D

    def predict(
        self, log_EI0: float, p: float, coords: dict[str, float], shapes: bool = True
    ) -> tuple[NDArray, NDArray, NDArray]:
        """Sensor forces (n_force,), centerline x (n_points,) and cos(tangent angle) (n_points,).

        ``shapes=False`` skips the centerlines (empty arrays).
        """
        effects = tuple(coords)
        x = np.concatenate([[log_EI0, p], [coords[e] for e in effects]])
        F = self.forces(x[None], effects)[0]
        xs, cs = self.shapes(x, effects) if shapes else (np.zeros(0), np.zeros(0))
        return F, xs, cs

    def shapes(self, x: NDArray, effects: tuple[str, ...]) -> tuple[NDArray, NDArray]:
        """Centerline x (n_points,) and cos(tangent angle) at the observed heights, one parameter set."""
        return self._shape_parts(x, effects)[:2]

    def shape_offsets(self, x: NDArray, effects: tuple[str, ...]) -> NDArray:
        """Signed normal offset [m] of every observed point from its frame's centerline (n_points,), one
        parameter set; NaN on a frame the model has slipped before: the fit's shape residual
        (:func:`bayesrod.physics.elastica.centerline_normal_offsets`, docs/inference.md)."""
        return self._shape_parts(x, effects)[2]

    def _shape_parts(self, x: NDArray, effects: tuple[str, ...]) -> tuple[NDArray, NDArray, NDArray]:
        if not self.n_points:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        L = self.length_m
        EI0 = float(np.exp(np.clip(x[0], -60.0, 60.0)))
        eff = effects_from_coords(dict(zip(effects, x[self.n_base :], strict=True)), EI0, L)
        # a push's preload shifts its frames' contact displacements as it shifts its forces'
        pre = dict(zip(self.force_pushes, x[2 : 2 + self.n_preloads], strict=True)) if self.preload else {}
        # and its height error moves its frames' contact as it moves its forces'
        hs = dict(zip(self.force_pushes, self.heights(x)[0], strict=True))
        parts = [
            self._shape(d, EI0, float(x[1]), eff, float(pre.get(k, 0.0)), float(hs.get(k, d.height_m)))
            for k, d in enumerate(self.data)
            if d.x_m.size
        ]
        return tuple(np.concatenate(a) for a in zip(*parts, strict=True))

    def _shape(self, d: PushData, EI0: float, p: float, eff: Effects, preload_m: float = 0.0, height_m=None):
        L = self.length_m
        D = (d.frame_D_m + preload_m) / L
        h = d.height_m if height_m is None else height_m
        r = force_from_displacement_nd(D, h / L, p, eff.nondim(L, EI0), keep_shape=True)
        grid = r["grid"]  # (n + 1, 3, M)
        # every point read on every frame's centerline in one call, then each point on its own frame
        xa, ca = centerline_x_at_heights(np.nan_to_num(grid), d.z_m / L)  # (M, k)
        pts = np.arange(d.x_m.size)
        x, c = xa[d.frame_index, pts] * L, ca[d.frame_index, pts]
        n = centerline_normal_offsets(np.nan_to_num(grid), d.x_m / L, d.z_m / L)[d.frame_index, pts] * L
        # the model slipped before a frame: no prediction there (residual 0)
        slipped = ~np.all(np.isfinite(grid), axis=(0, 1))[d.frame_index]
        return np.where(slipped, np.nan, x), np.where(slipped, 1.0, c), np.where(slipped, np.nan, n)


@dataclass
class MapFit:
    """A maximum-likelihood fit: parameters, noise, residuals, Jacobian.

    ``sigma_force`` is the sd of the force noise's innovations [N] and ``rho_force`` its AR(1)
    correlation per push (0 for independent noise); the marginal force-noise sd is
    ``sigma_force / sqrt(1 - rho_force**2)``.
    """

    effects: tuple[str, ...]
    x: NDArray  # (log_EI0, p, effect coordinates...)
    sigma_force: float
    shape_scale: float  # multiplies sd_m (or is the shape sd [m] without sd_m)
    r_force: NDArray  # observed - predicted [N]
    r_shape: NDArray  # normal distance [m]
    jac: NDArray  # (n_obs, n_par): d prediction / dx, whitened and weighted by the noise
    loglik: float
    rho_force: float = 0.0
    jac_pred: NDArray | None = None  # (n_obs, n_par): d prediction / dx, raw units
    length_fitted: bool = False  # x holds the stem length [m] after the preloads
    n_heights: int = 0  # x holds this many contact-height errors [m] just before the effect coordinates

    @property
    def coords(self) -> dict[str, float]:
        return {e: float(v) for e, v in zip(self.effects, self.x[self.x.size - len(self.effects) :], strict=True)}

    @property
    def preloads_m(self) -> NDArray:
        """The preload of each push with forces [m] (empty without the preload nuisance)."""
        return np.asarray(self.x[2 : self.x.size - len(self.effects) - self.n_heights - self.length_fitted], float)

    @property
    def length_m(self) -> float | None:
        """The fitted stem length [m] (None: the length was held at the model's)."""
        return float(self.x[self.x.size - len(self.effects) - self.n_heights - 1]) if self.length_fitted else None

    @property
    def height_errors_m(self) -> NDArray:
        """The contact-height error of each push with forces [m] (empty without the nuisance)."""
        end = self.x.size - len(self.effects)
        return np.asarray(self.x[end - self.n_heights : end], float)

    @property
    def marginal_sigma_force(self) -> float:
        return float(self.sigma_force / np.sqrt(1.0 - self.rho_force**2))

    def natural(self, L: float) -> dict:
        """EI0, p, the effects in SI units, the preloads and the fitted length; ``L``: the model's length
        (the effects' nondimensional coordinates are converted with the fitted length when there is one)."""
        EI0 = float(np.exp(self.x[0]))
        out = {"EI0": EI0, "p": float(self.x[1])}
        out.update(effects_from_coords(self.coords, EI0, self.length_m or L).to_mapping())
        if self.preloads_m.size:
            out["preload_m"] = [float(v) for v in self.preloads_m]
        if self.length_fitted:
            out["length_m"] = self.length_m
        if self.n_heights:
            out["height_error_m"] = [float(v) for v in self.height_errors_m]
        return out


def _legendre(t: NDArray, degree: int = 5) -> NDArray:
    """Legendre basis (n, degree + 1) over the range of ``t``: the smooth of the screen and the structure test."""
    return np.polynomial.legendre.legvander(2 * (t - t.min()) / max(np.ptp(t), 1e-12) - 1, degree)


def lag1(r: NDArray, first: NDArray) -> float:
    """Lag-1 autocorrelation of residuals ``r`` pooled over pushes (``first`` marks each push's first sample)."""
    if r.size < 3:
        return 0.0
    valid = ~first[1:]
    num = float(np.sum((r[1:] * r[:-1])[valid]))
    den = float(np.sum((r[:-1] ** 2)[valid]))
    return num / den if den > 0 else 0.0


@dataclass(frozen=True)
class HeldoutErrors:
    """Force errors [N] of one held-out unit and the noise (innovation sd, AR(1) rho) of its refit."""

    errors_N: NDArray
    sigma_force: float
    rho_force: float

    def log_density(self) -> NDArray:
        """Held-out log predictive density per sample under the refit's AR(1) noise (one-step conditionals).

        The joint Gaussian AR(1) density of the held-out push factorises into the marginal of its first
        sample and the conditionals of each next sample given the previous one: sum = log p(held | refit).
        """
        w = _whiten_rows(self.errors_N, None, self.rho_force) / self.sigma_force
        out = -0.5 * w**2 - np.log(self.sigma_force) - 0.5 * np.log(2 * np.pi)
        out[0] += 0.5 * np.log(1.0 - self.rho_force**2)
        return out


def heldout_comparison(before: list[HeldoutErrors], after: list[HeldoutErrors]) -> dict:
    """How much better does the model ``after`` predict the held-out data (the same units as ``before``)?

    ``gain``: relative drop of the held-out force RMSE (the gate of :func:`diagnose`); ``log_score_gain``:
    the held-out log predictive density under each refit's AR(1) noise (:meth:`HeldoutErrors.log_density`),
    after minus before (reported; with a few heights its sampling spread is too large for a test of its
    own, which is why the gate's significance comes from :func:`null_heldout_gain`).
    """
    if not before or not sum(u.errors_N.size for u in before):
        return {"gain": 0.0, "log_score_gain": 0.0}
    total = float(sum((a.log_density() - b.log_density()).sum() for a, b in zip(after, before, strict=True)))
    rb = np.sqrt(np.mean(np.concatenate([u.errors_N for u in before]) ** 2))
    ra = np.sqrt(np.mean(np.concatenate([u.errors_N for u in after]) ** 2))
    return {"gain": float(1 - ra / rb) if rb > 0 else 0.0, "log_score_gain": total}


def _ar1_noise(first: NDArray, sigma: float, rho: float, n_draws: int, rng) -> NDArray:
    """Draws (n, n_draws) of AR(1) noise restarting (stationary) at each ``first`` sample."""
    eta = rng.standard_normal((first.size, n_draws)) * sigma
    out = np.empty_like(eta)
    for t in range(first.size):
        out[t] = eta[t] / np.sqrt(1.0 - rho * rho) if first[t] else rho * out[t - 1] + eta[t]
    return out


def _first_of(mask: NDArray, push: NDArray) -> NDArray:
    """First selected sample of each push among the rows ``mask`` selects (AR(1) restarts there)."""
    sel_push = push[mask]
    return np.r_[True, sel_push[1:] != sel_push[:-1]] if sel_push.size else np.zeros(0, bool)


def _box_lstsq(A: NDArray, Y: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """Least-squares coefficients (k, d) of each column of ``Y`` (n, d) on ``A`` (n, k) within the box
    ``lo <= coef <= hi`` (k,): every column solved unconstrained, those that leave the box again by
    bounded-variable least squares (the constrained minimum; the box must contain 0)."""
    coef, *_ = np.linalg.lstsq(A, Y, rcond=None)
    outside = ((coef < lo[:, None]) | (coef > hi[:, None])).any(axis=0)
    for j in np.flatnonzero(outside):
        coef[:, j] = lsq_linear(A, Y[:, j], bounds=(lo, hi), method="bvls").x
    return coef


def null_heldout_gain(
    dg: Diagnoser,
    cur: MapFit,
    new: MapFit,
    observed_gain: float,
    n_draws: int = 500,
    seed=0,
    bounds: tuple[NDArray, NDArray] | None = None,
):
    """Parametric bootstrap p-value of a held-out gain under "the added effect is absent".

    Data are simulated from ``cur`` with its fitted noise (AR(1) forces per push, independent shape
    points); both models are refitted on each unit's training rows and predict its held-out forces,
    exactly as :meth:`Diagnoser.heldout` does, but the refits are linearised: model ``cur`` by its
    Jacobian, model ``new`` by the same plus one column, the fitted change of the predictions
    (``new`` - ``cur``: the effect's signature with a free amplitude). The p-value is the share of draws
    whose held-out RMSE gain reaches ``observed_gain``. Calibration: docs/validation.md.

    The linearised refits keep the true refits' bounds (``bounds``: those of ``cur``'s parameters,
    default :meth:`Diagnoser.bounds`): a parameter at or near a bound (p at 0, a preload at 0) moves
    only inwards, and the amplitude of a one-sided effect (base compliance, self weight) is not
    negative. Unbounded, a plain fit at p ~ 0 let the null refits bend p below zero and fit noise that
    the true refits cannot, which fattened the null's tail (docs/validation.md, seed 13).
    """
    m = dg.m
    masks = m.heldout_masks()
    if not masks or cur.jac_pred is None:
        return 1.0
    lo, hi = dg.bounds(cur.effects) if bounds is None else (np.asarray(b, float) for b in bounds)
    lo = np.minimum(lo - cur.x, 0.0)  # the box of a step from cur's parameters
    hi = np.maximum(hi - cur.x, 0.0)
    hi = np.where(hi > lo, hi, np.inf)  # a degenerate box (lo = hi = x) is left free
    added = new.effects[len(cur.effects) :]
    one_sided = bool(added) and all(e in _ONE_SIDED for e in added)
    lo1, hi1 = np.r_[lo, 0.0 if one_sided else -np.inf], np.r_[hi, np.inf]
    rng = np.random.default_rng(seed)
    nf = m.n_force
    sig = np.concatenate([cur.r_force - new.r_force, cur.r_shape - new.r_shape])  # new - cur predictions
    J0 = cur.jac_pred
    J1 = np.column_stack([J0, sig])
    eps_f = _ar1_noise(m.first_sample, cur.sigma_force, cur.rho_force, n_draws, rng)
    sd_p = cur.shape_scale * (m.sd_obs if m.sd_obs is not None else np.ones(m.n_points))
    eps_p = rng.standard_normal((m.n_points, n_draws)) * sd_p[:, None]
    sq0, sq1 = 0.0, 0.0
    loho = len(m.force_pushes) >= 2
    for u, (train_f, train_p, held_f) in enumerate(masks):
        first = _first_of(train_f, m.force_push)
        # as in Diagnoser.heldout: the held-out push's own preload is fitted to it, after the refit, and
        # its height error is not fitted (held at the current value in both models: the same shift)
        own = 2 + u if (m.preload and loho) else None
        fixed = [m.height_index + u] if (m.n_heights and loho) else []

        def w(v, first=first, train_f=train_f, train_p=train_p):
            f = _whiten_rows(v[:nf][train_f], first, cur.rho_force) / cur.sigma_force
            return np.concatenate([f, (v[nf:][train_p].T / sd_p[train_p]).T])

        y = w(np.concatenate([eps_f, eps_p]))
        for J, acc, blo, bhi in ((J0, 0, lo, hi), (J1, 1, lo1, hi1)):
            keep = ~np.isin(np.arange(J.shape[1]), [own, *fixed] if own is not None else fixed)
            A, Y = w(J[:, keep]), y
            if m.n_heights:  # the training pushes' height errors keep their prior, as in the true refits:
                # rows (dh_cur + step) / sd, pulled towards 0
                cols = [c for c in range(m.height_index, m.height_index + m.n_heights) if keep[c]]
                P = np.zeros((len(cols), int(keep.sum())))
                P[np.arange(len(cols)), [int(np.sum(keep[:c])) for c in cols]] = 1.0 / m.height_sd_m
                prior_y = -cur.x[cols] / m.height_sd_m
                A, Y = np.vstack([A, P]), np.vstack([y, np.repeat(prior_y[:, None], y.shape[1], axis=1)])
            coef = _box_lstsq(A, Y, blo[keep], bhi[keep])
            e = eps_f[held_f] - J[:nf][held_f][:, keep] @ coef
            if own is not None:  # the push's preload column fitted to what is left, as _held_x fits it:
                # least squares on the AR(1)-whitened residuals, within its box
                col = J[:nf][held_f][:, own]
                cw, ew = _whiten_rows(col, None, cur.rho_force), _whiten_rows(e, None, cur.rho_force)
                c = np.clip((cw @ ew) / max(float(cw @ cw), 1e-300), blo[own], bhi[own])
                e = e - np.outer(col, c)
            if acc == 0:
                sq0 = sq0 + np.sum(e**2, axis=0)
            else:
                sq1 = sq1 + np.sum(e**2, axis=0)
    gain = 1.0 - np.sqrt(sq1 / sq0)
    return float((1 + np.sum(gain >= observed_gain)) / (n_draws + 1))


def _whiten_rows(v: NDArray, first: NDArray | None, rho: float) -> NDArray:
    """AR(1) innovations of rows ``v`` (n, ...), restarting at ``first`` (None: one push), each with the
    innovation variance: v_t - rho v_(t-1), and sqrt(1 - rho^2) v_t at a start (the likelihood's
    :func:`~bayesrod.inference.likelihood.ar1_innovations` on the leading axis, rescaled)."""
    v = np.asarray(v, float)
    if rho == 0.0 or not v.shape[0]:
        return v.copy()
    if first is None:
        first = np.arange(v.shape[0]) == 0
    e, var = ar1_innovations(np.moveaxis(v, 0, -1), rho, first)
    return np.moveaxis(e * np.sqrt((1.0 - rho * rho) / var), -1, 0)


class Diagnoser:
    """Fits, statistics and held-out errors for one specimen (see the module docstring).

    Parameters
    ----------
    model : ForwardModel
    force_noise : {"ar1", "iid"}
        Force noise AR(1) per push (profiled correlation; every fit, score, likelihood ratio and
        structure test on the whitened residuals) or independent.
    """

    def __init__(self, model: ForwardModel, force_noise: str = "ar1"):
        if model.n_force == 0:
            raise ValueError("diagnose: expected engaged force samples (the forces fix EI0), got none")
        if force_noise not in ("ar1", "iid"):
            raise ValueError(f"force_noise: expected 'ar1' or 'iid', got {force_noise!r}")
        self.m = model
        self.force_noise = force_noise

    # ---------------------------------------------------------------- residuals
    def whiten(self, v: NDArray, rho: float) -> NDArray:
        """AR(1) innovations of force-indexed ``v`` (n_force, ...) per push: v_t - rho v_(t-1), first scaled."""
        return _whiten_rows(np.asarray(v, float), self.m.first_sample, rho)

    def _shape_sd(self) -> NDArray:
        return self.m.sd_obs if self.m.sd_obs is not None else np.ones(self.m.n_points)

    def weighted(self, rf: NDArray, rs: NDArray, noise: tuple[float, float, float]) -> NDArray:
        """Whitened force and scaled shape residuals, unit variance under the noise model (leading axis obs)."""
        sf, rho, ss = noise
        out = [self.whiten(rf, rho) / sf]
        if self.m.n_points:
            sd = self._shape_sd()
            out.append(rs / (ss * sd.reshape((-1,) + (1,) * (rs.ndim - 1))))
        return np.concatenate(out, axis=0)

    def raw_residuals(self, x: NDArray, effects) -> tuple[NDArray, NDArray]:
        rf, rs = self.raw_residuals_batch(np.asarray(x, float)[None], tuple(effects))
        return rf[0], rs[0]

    def raw_residuals_batch(self, X: NDArray, effects: tuple[str, ...]) -> tuple[NDArray, NDArray]:
        """Force (K, n_force) and shape (K, n_points) residuals of K parameter sets."""
        K = X.shape[0]
        try:
            F = self.m.forces(X, effects)
        except ValueError:
            if K > 1:  # one set the model cannot solve must not spoil the others
                parts = [self.raw_residuals_batch(X[k : k + 1], effects) for k in range(K)]
                return np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts])
            # parameters the model cannot solve (e.g. a rest shape that never reaches the sensor):
            # a large finite misfit so that the least-squares step backs off
            big = 1e3 * (np.abs(self.m.F_obs).max() + 1.0)
            return np.full((1, self.m.n_force), big), np.full((1, self.m.n_points), 1e3 * self.m.length_m)
        rf = self.m.F_obs[None] - F
        rs = np.zeros((K, self.m.n_points))
        for k in range(K if self.m.n_points else 0):
            try:
                rs[k] = np.nan_to_num(self.m.shape_offsets(X[k], effects))
            except ValueError:
                rs[k] = 1e3 * self.m.length_m
        return rf, rs

    def profile_noise(self, rf: NDArray, rs: NDArray) -> tuple[float, float, float]:
        """(innovation sd [N], AR(1) correlation, shape scale) maximising the likelihood given residuals."""
        rho = 0.0
        if self.force_noise == "ar1" and rf.size > 3 * len(self.m.force_pushes):
            rho = float(np.clip(lag1(rf, self.m.first_sample), -0.5, RHO_MAX))
        e = self.whiten(rf, rho)
        sf = float(np.sqrt(np.mean(e**2))) if e.size else 1.0
        ss = float(np.sqrt(np.mean((rs / self._shape_sd()) ** 2))) if rs.size else 1.0
        return max(sf, 1e-9), rho, max(ss, 1e-12)

    def loglik(self, rf: NDArray, rs: NDArray, noise: tuple[float, float, float]) -> float:
        """Gaussian log likelihood (AR(1) forces per push, independent shape points)."""
        sf, rho, ss = noise
        e = self.whiten(rf, rho)
        ll = -0.5 * np.sum((e / sf) ** 2) - rf.size * np.log(sf)
        ll += 0.5 * int(self.m.first_sample.sum()) * np.log(1.0 - rho * rho)
        if rs.size:
            s = ss * self._shape_sd()
            ll += -0.5 * np.sum((rs / s) ** 2) - np.sum(np.log(s))
        return float(ll)

    def pred_jac(self, x: NDArray, effects: tuple[str, ...], lo, hi) -> tuple[NDArray, NDArray, NDArray]:
        """Residuals at ``x`` and d prediction / dx (n_obs, n_par), forward differences in one batched solve."""
        n = x.size
        h = 1e-5 * np.maximum(np.abs(x), 1.0)
        sgn = np.where(x + h > np.asarray(hi), -1.0, 1.0)
        X = np.vstack([x, x + np.diag(sgn * h)])
        rf, rs = self.raw_residuals_batch(X, effects)
        R = np.concatenate([rf, rs], axis=1)
        J = -(R[1:] - R[0]) / (sgn * h)[:, None]  # residual = observed - prediction
        return rf[0], rs[0], J.T.reshape(-1, n)

    # --------------------------------------------------------------------- fits
    def fit_plain(self, max_nfev: int = 40) -> MapFit:
        """The plain model's maximum-likelihood fit, started from the force tables (:meth:`start`)."""
        return self.fit((), self.start(), max_nfev=max_nfev, ols_first=True)

    def fit(self, effects=(), x0: NDArray | None = None, max_nfev: int = 40, ols_first: bool = False) -> MapFit:
        """Maximum-likelihood fit with ``effects`` (noise profiled: two rounds of least squares).

        Forces are solved at ``ForwardModel.n_nodes`` displacements per push whatever the number of
        samples, and each Jacobian is one batched solve. ``ols_first``: the first round weighs the
        forces as independent, for a start from a grid (see the comment below); a fit started at a
        fitted model profiles its AR(1) from the start.
        """
        effects = tuple(effects)
        lo, hi = self.bounds(effects)
        x = np.clip(np.array(x0, float), lo + 1e-9 * np.isfinite(lo), hi - 1e-9 * np.isfinite(hi))
        rf, rs = self.raw_residuals(x, effects)
        noise = self.profile_noise(rf, rs)
        if ols_first and noise[1] != 0.0:
            # the first round weighs the forces as independent: an AR(1) profiled at a grid start absorbs
            # the start's own misfit (a smooth trend reads as rho near 1), and whitened with it the objective
            # is flat along the step that would remove the misfit (a plain fit then never left its grid start:
            # 10 nats below its optimum on a clean simulated twig)
            noise = (float(np.sqrt(np.mean(rf**2))), 0.0, noise[2])
        # iid forces alone: uniform weights, one round; shapes, AR(1) forces or the height errors' prior rows
        # weigh by the noise, which the second round re-profiles
        rounds = 2 if (self.m.n_points or self.force_noise == "ar1" or self.m.n_heights) else 1
        cache: dict = {}

        for rnd in range(rounds):
            budget = max_nfev if rnd == 0 else max(5, max_nfev // 2)  # the re-profiled noise only polishes

            def fun(v, noise=noise):
                a, b = self.raw_residuals(v, effects)
                return np.concatenate([self.weighted(a, b, noise), self._prior_rows(v)])

            def jac(v, noise=noise):
                a, b, J = self.pred_jac(v, effects, lo, hi)
                cache.update(x=v.copy(), J=J)
                nf = self.m.n_force
                return np.vstack([-self.weighted(J[:nf], J[nf:], noise), self._prior_jac(v.size)])

            res = least_squares(fun, x, jac=jac, bounds=(lo, hi), x_scale="jac", max_nfev=budget, ftol=1e-6, xtol=1e-6)
            x = res.x
            rf, rs = self.raw_residuals(x, effects)
            noise = self.profile_noise(rf, rs)
        J = cache["J"] if "x" in cache and np.array_equal(cache["x"], x) else self.pred_jac(x, effects, lo, hi)[2]
        nf = self.m.n_force
        jw = self.weighted(J[:nf], J[nf:], noise)
        sf, rho, ss = noise
        ll = self.loglik(rf, rs, noise) - 0.5 * float(np.sum(self._prior_rows(x) ** 2))
        return MapFit(
            effects,
            x,
            sf,
            ss,
            rf,
            rs,
            jw,
            ll,
            rho,
            J,
            length_fitted=self.m.length_bounds_m is not None,
            n_heights=self.m.n_heights,
        )

    def _prior_rows(self, x: NDArray) -> NDArray:
        """The contact-height errors' normal prior as least-squares rows: dh / sd (none without them)."""
        i, n = self.m.height_index, self.m.n_heights
        return np.asarray(x[i : i + n], float) / self.m.height_sd_m if n else np.zeros(0)

    def _prior_jac(self, n_par: int) -> NDArray:
        """d :meth:`_prior_rows` / dx: (n_heights, n_par)."""
        i, n = self.m.height_index, self.m.n_heights
        J = np.zeros((n, n_par))
        if n:
            J[np.arange(n), i + np.arange(n)] = 1.0 / self.m.height_sd_m
        return J

    def bounds(self, effects: tuple[str, ...]) -> tuple[NDArray, NDArray]:
        """Lower and upper bounds (n_par,) of a parameter vector with ``effects``: log EI0 free, p in
        [0, P_MAX], each preload in [0, PRELOAD_MAX_L L], the length within its bounds, each contact-height
        error within 4 prior sd, each effect's coordinate within its own (``_COORD``)."""
        n_pre, n_h = self.m.n_preloads, self.m.n_heights
        lb = list(self.m.length_bounds_m or ())
        cut = HEIGHT_CUT_SD * self.m.height_sd_m
        lo = np.array([-np.inf, 0.0] + [0.0] * n_pre + lb[:1] + [-cut] * n_h + [self._bound(e, 2) for e in effects])
        hi = np.array(
            [np.inf, P_MAX]
            + [PRELOAD_MAX_L * self.m.length_m] * n_pre
            + lb[1:]
            + [cut] * n_h
            + [self._bound(e, 3) for e in effects]
        )
        return lo, hi

    def _bound(self, effect: str, k: int) -> float:
        if effect == "rest_curvature":  # the unloaded stem must still rise: |kappa0 L| <= 1.2 rad
            return (-1.2 if k == 2 else 1.2) / self.m.length_m
        return _COORD[effect][k]

    def start(self, p_grid: NDArray | None = None) -> NDArray:
        """(log EI0, p[, preloads][, L]) of the plain model: the force tables of the likelihood over a p grid,
        closed-form EI0 (a fitted length starts at the given one).

        Forces are linear in EI0, so each p of the grid has a least-squares EI0; the best pair starts
        the direct fit. With preloads, each push's preload starts where that pair's force reaches the
        push's first force sample, and the pair is chosen again with those preloads.
        """
        shift = np.zeros(len(self.m.force_pushes))
        dh = np.zeros(self.m.n_heights)
        for _ in range(2 if (self.m.preload or self.m.n_heights) else 1):
            g, p_grid = self._unit_forces(p_grid, shift, dh=dh if dh.size else None)
            a, rss = _scale_fit(g, self.m.F_obs)
            k = int(np.argmin(rss))
            if not np.isfinite(rss[k]):
                raise ValueError("diagnose: expected forces that rise with displacement, got none the model can fit")
            if self.m.preload:
                shift = self._preload_start(float(a[k]), p_grid, k)
            if self.m.n_heights:
                dh = self._height_start(float(a[k]), float(p_grid[k]), shift, dh)
        length = [self.m.start_length] if self.m.length_bounds_m is not None else []
        return np.concatenate([[np.log(a[k]), float(p_grid[k])], shift if self.m.preload else [], length, dh])

    def _height_start(self, EI0: float, p: float, shift: NDArray, dh: NDArray) -> NDArray:
        """Per push: the contact-height error [m] of one Gauss-Newton step from ``dh`` at the plain model
        (EI0, p) and preloads ``shift``, within its 4-sd box.

        A misrecorded height scales a push's forces as a stiffer or softer stem does (by about 3 dh / h):
        started at the recorded heights, the fit can settle with the pushes' different scales absorbed in p
        and the preloads instead (a simulated twig with errors of +6, -5, +4 mm and preloads: a fit 190
        nats below the one started near the truth).
        """
        step = self.m.height_sd_m
        cut = HEIGHT_CUT_SD * step
        L, J = self.m.length_m, len(self.m.force_pushes)
        h = np.array([self.m.data[k].height_m for k in self.m.force_pushes]) + dh
        # the three heights of every push in one batch of solves (one march costs about the same for 1 or 3J)
        curves = ForceCurves.batch(np.concatenate([h, h + step, h - step]) / L, np.array([p]), 160)
        g0, gp, gm = (EI0 * self._curve_forces(curves[i * J : (i + 1) * J], shift, L)[0] for i in range(3))
        out = dh.copy()
        for j in range(len(self.m.force_pushes)):
            sel = self.m.force_push == self.m.force_pushes[j]
            d = (gp[sel] - gm[sel]) / (2 * step)
            r = self.m.F_obs[sel] - g0[sel]
            if float(d @ d) > 0:
                out[j] = float(np.clip(dh[j] + (d @ r) / (d @ d), -cut, cut))
        return out

    def _preload_start(self, EI0: float, p_grid: NDArray, k: int) -> NDArray:
        """Per push: the displacement [m] at which the plain model (EI0, p_grid[k]) reaches the push's
        first force sample, read off the p grid's force curves (the ones :meth:`_unit_forces` built)."""
        L = self.m.length_m
        grid = np.linspace(0.0, PRELOAD_MAX_L, 201)
        out = []
        for j in self.m.force_pushes:
            d = self.m.data[j]
            f = ForceCurves(d.height_m / L, p_grid).force(grid)[k] * EI0 / L**2
            at = float(np.interp(max(float(d.F_N[0]), 0.0), np.maximum.accumulate(f), grid)) * L
            # the first sample sits at D[0] (below zero behind a wire sensor): the preload makes up the rest
            out.append(float(np.clip(at - d.D_m[0], 0.0, PRELOAD_MAX_L * L)))
        return np.array(out)

    def _unit_forces(
        self,
        p_grid: NDArray | None,
        shift: NDArray | None = None,
        length_m: float | None = None,
        c_base: float = 0.0,
        n_f: int = 160,
        dh: NDArray | None = None,
    ) -> tuple[NDArray, NDArray]:
        """Forces per unit EI0 (P, n_force) over a p grid, from the likelihood's force tables (``n_f``
        solves per curve); ``shift``: each force push's displacements moved by this much [m] (its
        preload); ``length_m``: the stem length (default: the model's); ``c_base``: a base spring's
        EI0 / (k_b L) (0: the plain, clamped rod); ``dh``: each force push's contact-height error [m] (default:
        none). At fixed ``c_base`` the forces are linear in EI0."""
        p_grid = np.linspace(0.0, P_MAX, 61) if p_grid is None else np.asarray(p_grid, float)
        L = self.m.length_m if length_m is None else float(length_m)
        shift = np.zeros(len(self.m.force_pushes)) if shift is None else np.asarray(shift, float)
        dh = np.zeros(len(self.m.force_pushes)) if dh is None else np.asarray(dh, float)
        etas = np.array([(self.m.data[k].height_m + e) / L for k, e in zip(self.m.force_pushes, dh, strict=True)])
        curves = ForceCurves.batch(etas, p_grid, n_f, {"c_base": float(c_base)} if c_base > 0 else None)
        return self._curve_forces(curves, shift, L), p_grid

    def _curve_forces(self, curves: list, shift: NDArray, L: float) -> NDArray:
        """Forces per unit EI0 (P, n_force) read off one force table per push with forces, each push's
        displacements moved by its ``shift`` [m]."""
        pushes = zip(curves, self.m.force_pushes, shift, strict=True)
        return np.concatenate([c.force((self.m.data[k].D_m + s) / L) for c, k, s in pushes], axis=1) / L**2

    def compliance_start(self, plain: MapFit) -> NDArray:
        """(log EI0, p[, preloads][, L], c) for the base-compliance candidate of the plain model: a grid
        over p and c = EI0 / (k_b L), EI0 in closed form.

        A soft base and a soft uniform rod bend alike, so the plain optimum can sit at p = 0 with a low
        EI0, far from the compliant stem's optimum and out of reach of a local fit started near c = 0
        (a simulated twig with k_b = 8 N m/rad: plain fit p = 0 and EI0 0.79 for the true 2.63). The
        forces depend on p, h/L and c only (the nondimensional elastica), so at each (p, c) of the grid
        they are linear in EI0, fitted in closed form as in :meth:`start`. Preloads and a fitted length
        are held at ``plain``'s.
        """
        pre = plain.preloads_m if self.m.preload else None
        length = plain.length_m if self.m.length_bounds_m is not None else None
        p_grid = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, P_MAX])  # a start: coarse (a curve costs)
        best, out = np.inf, plain.x[: self.m.n_base]
        for c in np.concatenate([[0.0], np.geomspace(0.05, 2.5, 5)]):
            a, rss = _scale_fit(self._unit_forces(p_grid, pre, length, c_base=c, n_f=80)[0], self.m.F_obs)
            k = int(np.argmin(rss))
            if rss[k] < best:
                best = rss[k]
                out = np.concatenate([[np.log(a[k]), p_grid[k]], plain.x[2 : self.m.n_base], [c]])
        return out

    def grid_start(self, effect: str, plain: MapFit) -> NDArray | None:
        """A second start, from a grid, for ``effect`` added to the plain model ``plain``: yield
        (:meth:`yield_start`) and base compliance (:meth:`compliance_start`), the two whose optimum the
        plain one can hide behind another taper. None for other effects, and when the start's forces fit
        no better (sum of squares) than ``plain``'s: the grid then found nothing the local fit would miss."""
        if effect not in GRID_STARTED:
            return None
        x = self.yield_start(plain) if effect == "yield" else self.compliance_start(plain)
        rf, _ = self.raw_residuals(x, (effect,))
        return x if float(rf @ rf) < float(plain.r_force @ plain.r_force) else None

    def yield_start(self, plain: MapFit | None = None) -> NDArray:
        """(log EI0, p[, preloads][, L], log M_y) for the yield candidate of the plain model: a grid over p and M_y.

        The plain model's optimum can sit far from the yielding stem's (an extreme taper mimics the
        softening), out of reach of a local fit; this start caps the table forces at M_y / h and takes
        EI0 in closed form on the samples below the cap, for every p of the grid and 40 moments.
        With preloads or a fitted length, those of ``plain`` (the plain fit) are kept.
        """
        pre = np.zeros(0)  # the preloads, kept at the plain fit's
        if self.m.preload:
            pre = plain.preloads_m if plain is not None else np.zeros(len(self.m.force_pushes))
        length = None  # the length, kept at the plain fit's (or where a fit starts it)
        if self.m.length_bounds_m is not None:
            length = plain.length_m if plain is not None else self.m.start_length
        g, p_grid = self._unit_forces(np.linspace(0.0, P_MAX, 31), pre if pre.size else None, length)
        dh = plain.height_errors_m if plain is not None else np.zeros(self.m.n_heights)
        held = np.concatenate([pre, [length] if length is not None else [], dh])  # between p and log M_y
        F = self.m.F_obs
        h = np.array([self.m.data[k].height_m for k in self.m.force_push])
        m_max = float(np.max(F * h))
        best, out = np.inf, None
        for frac in np.linspace(0.3, 1.0, 40):
            cap = frac * m_max / h
            below = F < 0.98 * cap
            if below.sum() < 3:
                continue
            gb = g[:, below]
            a = (gb @ F[below]) / np.maximum(np.einsum("pn,pn->p", gb, gb), 1e-300)
            rss = np.sum((F[None, :] - np.minimum(a[:, None] * g, cap[None, :])) ** 2, axis=1)
            rss = np.where(a > 0, rss, np.inf)
            k = int(np.argmin(rss))
            if rss[k] < best:
                best, out = rss[k], np.concatenate([[np.log(a[k]), p_grid[k]], held, [np.log(frac * m_max)]])
        return out

    # -------------------------------------------------------------- statistics
    def screen_noise(self, fit: MapFit) -> tuple[float, float, float]:
        """The noise the screening tests whiten with: AR(1) of the residuals around a smooth.

        The plain fit's own AR(1) absorbs the systematic misfit a missing effect leaves (on real pushes
        its correlation reaches the 0.99 bound, and a score test whitened with it sees nothing). The
        screen estimates the correlation from the residuals minus a degree-5 Legendre smooth per push
        (the structure test's smooth): the noise around the structure. Screening is only a filter: every
        candidate it passes is refitted and judged by the likelihood ratio under its own profiled noise
        and by true held-out refits.
        """
        if self.force_noise == "iid":
            return fit.sigma_force, 0.0, fit.shape_scale
        detr = np.zeros_like(fit.r_force)
        for k, d in enumerate(self.m.data):
            sel = self.m.force_push == k
            if sel.sum() < 12:
                continue
            B = _legendre(d.D_m)
            coef, *_ = np.linalg.lstsq(B, fit.r_force[sel], rcond=None)
            detr[sel] = fit.r_force[sel] - B @ coef
        rho = float(np.clip(lag1(detr, self.m.first_sample), -0.5, RHO_MAX))
        sf = float(np.sqrt(np.mean(self.whiten(fit.r_force, rho) ** 2)))
        return max(sf, 1e-9), rho, fit.shape_scale

    def score(self, fit: MapFit, effect: str) -> dict:
        """Score statistic (chi^2_1 under absence, on whitened residuals) of ``effect`` at ``fit``."""
        if effect == "yield":
            return self._yield_lr(fit)
        noise = self.screen_noise(fit)
        r = self.weighted(fit.r_force, fit.r_shape, noise)
        neutral, step = _COORD[effect][0], _COORD[effect][1]
        if effect == "force_offset":
            step = 0.1 * fit.marginal_sigma_force
        x = np.concatenate([fit.x, [neutral + step]])
        rf, rs = self.raw_residuals(x, fit.effects + (effect,))
        # d prediction / d effect = -(d residual / d effect)
        g = self.weighted(fit.r_force - rf, fit.r_shape - rs, noise) / step
        nf = self.m.n_force
        X = fit.jac if fit.jac_pred is None else self.weighted(fit.jac_pred[:nf], fit.jac_pred[nf:], noise)
        coef, *_ = np.linalg.lstsq(X, g, rcond=None)
        gt = g - X @ coef
        den = float(gt @ gt)
        if den <= 1e-30:
            return {"statistic": 0.0, "p_value": 1.0, "direction": 0.0}
        U = float(gt @ r)
        S = U * U / den
        if effect in _ONE_SIDED and U < 0:
            S = 0.0
        return {
            "statistic": S,
            "p_value": float(stats.chi2.sf(S, 1)),
            "direction": float(np.sign(U)),
        }

    def _yield_lr(self, fit: MapFit) -> dict:
        """Profile likelihood ratio over the yield moment (whitened), forces only, other parameters held."""
        F = self.m.F_obs - fit.r_force
        h = np.array([self.m.data[k].height_m for k in self.m.force_push])
        M = F * h
        sf, rho, _ = self.screen_noise(fit)
        base = float(np.sum(self.whiten(fit.r_force, rho) ** 2))
        best, best_my = 0.0, None
        for frac in np.linspace(0.3, 0.995, 60):
            my = frac * float(M.max())
            Fc = np.minimum(F, my / h)
            # EI0 re-scaled on the samples below the cap (forces are linear in EI0 there)
            below = F * h < my
            a = float(Fc[below] @ self.m.F_obs[below]) / float(Fc[below] @ Fc[below]) if below.sum() > 2 else 1.0
            Fc = np.minimum(a * F, my / h)
            drop = (base - float(np.sum(self.whiten(self.m.F_obs - Fc, rho) ** 2))) / sf**2
            if drop > best:
                best, best_my = drop, my
        out = {"statistic": float(best), "p_value": float(stats.chi2.sf(best, 2)), "direction": 1.0}
        if best_my is not None:
            out["yield_moment_Nm"] = best_my
        return out

    def heldout(self, fit: MapFit, max_nfev: int = 40, pool=None) -> tuple[dict, list[HeldoutErrors]]:
        """Held-out force error from true refits: each unit of ``ForwardModel.heldout_splits`` is
        held out, the model with ``fit.effects`` is refitted to the rest (a full maximum-likelihood fit
        started at ``fit``), and the held-out forces are predicted.

        Returns the summary (RMSE over every held-out sample, per unit) and the raw errors per unit.
        ``pool``: an executor the refits are mapped over (None: one after the other).
        """
        splits = self.m.heldout_splits()
        if not splits:
            return {"heldout_force_rmse_N": None, "heldout": None, "per_push": []}, []
        errs, per = [], []
        loho = len(self.m.force_pushes) >= 2
        jobs = [
            (train, self.force_noise, fit.effects, self._without_push(fit.x, u) if loho else fit.x, max_nfev)
            for u, (_, train, _) in enumerate(splits)
        ]
        for (name, _, held), refit in zip(splits, _map(pool, _refit, jobs), strict=True):
            x_held = refit.x  # one push: the training part's own preload and height error hold
            if loho:  # the held-out push's own preload fitted to it, its height at the recorded one
                x_held = _held_x(held, refit, fit.effects)
            e = held.F_obs - _held_forces(held, x_held, fit.effects)
            errs.append(HeldoutErrors(e, refit.sigma_force, refit.rho_force))
            per.append(
                {
                    "push": name,
                    "height_m": held.data[0].height_m,
                    "force_rmse_N": float(np.sqrt(np.mean(e**2))),
                    "refit": refit.natural(self.m.length_m),
                }
            )
        kind = "leave-one-height-out" if len(self.m.force_pushes) >= 2 else "last third of the push"
        rmse = float(np.sqrt(np.mean(np.concatenate([u.errors_N for u in errs]) ** 2)))
        return {"heldout_force_rmse_N": rmse, "heldout": kind, "per_push": per}, errs

    def _without_push(self, x: NDArray, unit: int) -> NDArray:
        """``x`` without the preload and the height error of the ``unit``-th push with forces
        (leave-one-height-out training)."""
        drop = self.m.push_columns(unit)
        return np.delete(x, drop) if drop else x

    def errors(self, fit: MapFit, pool=None) -> tuple[dict, list[HeldoutErrors]]:
        out = {
            "force_rmse_N": float(np.sqrt(np.mean(fit.r_force**2))),
            "shape_rmse_mm": float(1000 * np.sqrt(np.mean(fit.r_shape**2))) if fit.r_shape.size else None,
            "residual_lag1": lag1(fit.r_force, self.m.first_sample),
        }
        h, e = self.heldout(fit, max_nfev=12 if any(x in SLOW for x in fit.effects) else 40, pool=pool)
        out.update(h)
        return out, e

    def structure(self, fit: MapFit, ratio: float = 0.25, alpha: float = 1e-3, pooled_alpha: float = 1e-2) -> dict:
        """Per push and kind: F test of a degree-5 Legendre smooth of the residuals, under the noise model.

        Force blocks are tested on whitened residuals against the whitened basis (generalised least
        squares under the fitted AR(1)); a block is ``structured`` when p < alpha and the smooth's sd
        exceeds ``ratio`` times the marginal noise sd. With two or more pushes of forces, one more
        block (``push`` "all", kind "force (pooled)") pools their sums of squares into one F test at
        ``pooled_alpha``: a missing effect leaves structure in every push, and pooling finds it where
        each push alone (about 60 samples at rho 0.9 hold only a few independent ones) falls short.
        Calibration and power: docs/validation.md, "The structure test pooled over pushes".
        """
        blocks, pooled = [], []
        for k, d in enumerate(self.m.data):
            for kind, sel, t in (
                ("force", self.m.force_push == k, d.D_m),
                ("shape", self.m.point_push == k, d.z_m),
            ):
                if sel.sum() < 20:
                    continue
                B = _legendre(t)
                if kind == "force":
                    rho = fit.rho_force
                    rw, Bw = _whiten_rows(fit.r_force[sel], None, rho), _whiten_rows(B, None, rho)
                    scale = fit.marginal_sigma_force
                else:
                    sd = (self.m.sd_obs[sel] if self.m.sd_obs is not None else 1.0) * fit.shape_scale
                    rw, Bw, scale = fit.r_shape[sel] / sd, B / np.reshape(sd, (-1, 1)), None
                coef, *_ = np.linalg.lstsq(Bw, rw, rcond=None)
                fitted = Bw @ coef
                q = B.shape[1]
                ss_fit, ss_res = float(fitted @ fitted), float(np.sum((rw - fitted) ** 2))
                Fst = (ss_fit / q) / max(ss_res / (rw.size - q), 1e-300)
                pval = float(stats.f.sf(Fst, q, rw.size - q))
                if kind == "force":
                    smooth = B @ coef
                    sd_ratio = float(np.std(smooth) / scale)
                else:
                    excess = max(0.0, (ss_fit - q * ss_res / (rw.size - q)) / rw.size)
                    sd_ratio = float(np.sqrt(excess / max(ss_res / (rw.size - q), 1e-300)))
                blocks.append(
                    {
                        "push": d.id,
                        "height_m": d.height_m,
                        "kind": kind,
                        "n": int(rw.size),
                        "p_value": pval,
                        "structured_sd_ratio": sd_ratio,
                        "structured": bool(pval < alpha and sd_ratio > ratio),
                    }
                )
                if kind == "force":
                    pooled.append(
                        (ss_fit, ss_res, q, rw.size - q, float(np.sum((smooth - smooth.mean()) ** 2)), smooth.size)
                    )
        if len(pooled) >= 2:
            ss_fit, ss_res, q, dof, ss_smooth, n = (sum(v) for v in zip(*pooled, strict=True))
            pval = float(stats.f.sf((ss_fit / q) / max(ss_res / dof, 1e-300), q, dof))
            sd_ratio = float(np.sqrt(ss_smooth / n) / fit.marginal_sigma_force)
            blocks.append(
                {
                    "push": "all",
                    "height_m": None,
                    "kind": "force (pooled)",
                    "n": int(n),
                    "p_value": pval,
                    "structured_sd_ratio": sd_ratio,
                    "structured": bool(pval < pooled_alpha and sd_ratio > ratio),
                }
            )
        return {"blocks": blocks, "unexplained_structure": any(b["structured"] for b in blocks)}


def _held_x(held: ForwardModel, refit: MapFit, effects: tuple[str, ...]) -> NDArray:
    """Parameters predicting a held-out push (leave one height out): the refit's stem, the push's height
    error at 0 (its prior mean: the recorded height) and, with preloads, the push's own preload fitted to
    its forces.

    A preload belongs to one push and cannot be learnt from the others; the held-out error then measures
    how well the model predicts the push's shape of force against displacement, not its unknown start.
    Least squares on the AR(1)-whitened residuals (the refit's correlation), every other parameter held.
    A height error is not fitted: it would scale the push's forces as a stiffer or softer stem does, and
    the held-out error would no longer test the model's prediction at that height.
    """
    L = held.length_m
    n = held.n_preloads
    base, coords = refit.x[:2], refit.x[refit.x.size - len(effects) :]
    length = [refit.length_m] if refit.length_fitted else []  # the stem's length: the refit's
    dh = np.zeros(held.n_heights)

    def build(v):
        return np.concatenate([base, v, length, dh, coords])

    if not n:
        return build(np.zeros(0))

    def fun(v):
        return _whiten_rows(held.F_obs - _held_forces(held, build(v), effects), held.first_sample, refit.rho_force)

    v0 = np.clip([float(np.median(refit.preloads_m)) if refit.preloads_m.size else 0.0], 0.0, PRELOAD_MAX_L * L)
    res = least_squares(fun, v0, bounds=([0.0] * n, [PRELOAD_MAX_L * L] * n), max_nfev=20)
    return build(res.x)


def _held_forces(held: ForwardModel, x: NDArray, effects: tuple[str, ...]) -> NDArray:
    """Forces of a held-out push at a refit's parameters ``x``; zero where the refit's stem cannot be solved
    there (e.g. its rest shape never reaches the held-out height): it predicts no contact, as the force
    tables do, and the held-out error counts the push's whole force."""
    try:
        return held.forces(np.asarray(x, float)[None], effects)[0]
    except ValueError:
        return np.zeros(held.n_force)


def _refit(model: ForwardModel, force_noise: str, effects: tuple[str, ...], x0: NDArray, max_nfev: int) -> MapFit:
    """A held-out refit (module level: it runs in worker processes)."""
    return Diagnoser(model, force_noise).fit(effects, x0, max_nfev=max_nfev)


def _map(pool, fn, jobs: list[tuple]) -> list:
    """``[fn(*job) for job in jobs]``, over the executor ``pool`` when given (results in order)."""
    if pool is None or len(jobs) < 2:
        return [fn(*job) for job in jobs]
    return list(pool.map(fn, *zip(*jobs, strict=True)))


def _quiet(msg: str) -> None:
    """The log of work done in worker processes (their messages are not forwarded)."""


def _candidate_lr(dg, cur, effects, starts, grid, level, dof, L):
    """Fit ``cur`` plus ``effects`` and gate on the likelihood ratio: (row, fit or None).

    ``starts``: the new coordinates' local start (None: no fit from ``cur``); ``grid``: a whole start
    from a grid (:meth:`Diagnoser.grid_start`; None: none), fitted with independent weights first. The
    better of the two fits is judged. The held-out gate (:func:`_heldout_gate`) comes after, in the
    calling process, only for the candidates this one passes.
    """
    model, budget = cur.effects + tuple(effects), 12 if any(e in SLOW for e in effects) else 40
    fitted = []
    if starts is not None:
        fitted.append(dg.fit(model, _no_worse_start(dg, cur, effects, np.asarray(starts, float)), max_nfev=budget))
    if grid is not None:
        fitted.append(dg.fit(model, grid, max_nfev=budget, ols_first=True))
    new = max(fitted, key=lambda f: f.loglik)
    lr = 2.0 * (new.loglik - cur.loglik)
    row = {"lr_statistic": float(lr), "fitted": new.natural(L)}
    if lr <= stats.chi2.isf(level, dof):
        row["rejected_because"] = (
            "likelihood ratio below the threshold" if lr >= 0 else "the fit stayed below the current model"
        )
        return row, None
    return row, new


def _heldout_gate(dg, cur, new, row, before_errs, before_rmse, min_gain, heldout_alpha, pool=None, log=_quiet):
    """The held-out gates of a candidate fit ``new`` that passed the likelihood ratio.

    Fills ``row`` and returns (fit, errors, error arrays) when the true held-out refits lower the
    held-out force RMSE by ``min_gain`` and the parametric bootstrap finds that fall significant;
    None otherwise (``row["rejected_because"]`` says which gate).
    """
    log(f"held-out refits with {'+'.join(new.effects[len(cur.effects) :])}")
    err, errs = dg.errors(new, pool)
    row["heldout_force_rmse_N"] = err["heldout_force_rmse_N"]
    if before_rmse is None:  # nothing to hold out (one short push): the likelihood ratio decides
        return new, err, errs
    t = heldout_comparison(before_errs, errs)
    row["heldout_gain"], row["heldout_log_score_gain"] = t["gain"], t["log_score_gain"]
    if t["gain"] < min_gain:
        row["rejected_because"] = "held-out error not reduced"
        return None
    row["heldout_p_value"] = null_heldout_gain(dg, cur, new, t["gain"])
    if row["heldout_p_value"] >= heldout_alpha:
        row["rejected_because"] = "held-out improvement not significant"
        return None
    return new, err, errs


def _alternatives(passed: list[tuple], added: dict) -> list[dict]:
    """The rows of ``passed`` ((effects, row, fit) past the likelihood ratio in the round the row ``added``
    was accepted in) whose likelihood-ratio statistic falls short of ``added``'s by less than
    :data:`ALTERNATIVE_LR`: models these data do not tell apart from the one added. A row the held-out gates
    rejected is not one (its ratio may be larger: the held-out refits said no)."""
    return [
        t
        for _, t, _ in passed
        if t is not added and "rejected_because" not in t and added["lr_statistic"] - t["lr_statistic"] < ALTERNATIVE_LR
    ]


def _first_passing(candidates: list[tuple], gate) -> tuple | None:
    """The candidate with the largest likelihood ratio among those ``gate`` passes.

    ``candidates``: (effects, row, fit) that passed the likelihood ratio; ``gate(row, fit)`` returns
    None (failed) or what to keep. The gate runs in decreasing likelihood ratio (ties: in the given
    order) and stops at the first pass: the decision is that of gating all and keeping the largest
    ratio, without the held-out refits of the candidates below it (their rows get
    ``heldout_not_run: true``). Returns (effects, gate's result, row) or None.
    """
    order = sorted(range(len(candidates)), key=lambda i: -candidates[i][1]["lr_statistic"])
    for rank, i in enumerate(order):
        effects, row, fit = candidates[i]
        kept = gate(row, fit)
        if kept is not None:
            for j in order[rank + 1 :]:
                candidates[j][1]["heldout_not_run"] = True
            return effects, kept, row
    return None


def diagnose(
    model: ForwardModel,
    *,
    candidates=CATALOG,
    alpha: float = 0.01,
    min_heldout_gain: float = 0.10,
    heldout_alpha: float = HELDOUT_ALPHA,
    max_effects: int = 3,
    structure_ratio: float = 0.25,
    force_noise: str = "ar1",
    pairs: bool = True,
    workers: int = 1,
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
        Relative drop of the held-out force RMSE an effect must bring.
    heldout_alpha : float
        Level of the parametric bootstrap (:func:`null_heldout_gain`) that the held-out gain is not chance.
    max_effects : int
        At most this many effects are added.
    force_noise : {"ar1", "iid"}
        Force noise model of every fit and test (AR(1) per push by default).
    pairs : bool
        When no single candidate passes and the residuals keep significant structure, fit pairs of
        the (up to four) most significant candidates.
    workers : int
        Processes the candidate fits and the held-out refits are spread over (1: none started).
        The result does not depend on it.

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
    if not (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1):
        raise ValueError(f"workers: expected an integer of at least 1, got {workers!r}")
    settings = dict(
        candidates=candidates,
        alpha=alpha,
        min_heldout_gain=min_heldout_gain,
        heldout_alpha=heldout_alpha,
        max_effects=max_effects,
        structure_ratio=structure_ratio,
        force_noise=force_noise,
        pairs=pairs,
        log=log,
    )
    if workers == 1:
        return _loop(model, pool=None, **settings)
    with ProcessPoolExecutor(workers) as pool:
        return _loop(model, pool=pool, **settings)


def _loop(
    model,
    *,
    candidates,
    alpha,
    min_heldout_gain,
    heldout_alpha,
    max_effects,
    structure_ratio,
    force_noise,
    pairs,
    log,
    pool,
) -> dict:
    """The body of :func:`diagnose`; independent fits are mapped over ``pool`` (None: in turn)."""
    dg = Diagnoser(model, force_noise)
    L = model.length_m
    log("fitting the plain model")
    cur = plain = dg.fit_plain()
    log("held-out refits of the plain model")
    before, cur_errs = dg.errors(cur, pool)
    before_struct = dg.structure(cur, ratio=structure_ratio)
    added: list[str] = []
    alternatives: dict[str, list[str]] = {}  # added effect (or pair "a+b") -> candidates the data do not tell apart
    rows: list[dict] = []
    history = [{"effects": [], "errors": before, "loglik": cur.loglik}]

    def fits(groups, rnd, cur, level):
        """(row, fit or None) of the candidate fit of each group of screen rows (one effect, or a pair)."""
        if groups:
            log(f"round {rnd}: fitting with {', '.join(' + '.join(t['effect'] for t in g) for g in groups)}")

        def local(g):  # the new coordinates' local start; none for a single refitted only for its grid
            return (
                None
                if len(g) == 1 and g[0].get("refitted_from_grid")
                else [_start_coord(t["effect"], t, cur, L) for t in g]
            )

        jobs = [
            (
                dg,
                cur,
                tuple(t["effect"] for t in g),
                local(g),
                grids.get(g[0]["effect"]) if len(g) == 1 else None,
                level,
                len(g),
                L,
            )
            for g in groups
        ]
        return _map(pool, _candidate_lr, jobs)

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
        cur_rmse = history[-1]["errors"]["heldout_force_rmse_N"]
        state = (rnd, cur, level)

        def gate(row, new, cur=cur, cur_errs=cur_errs, cur_rmse=cur_rmse):
            """The held-out gates of one candidate fit against this round's model (refits over ``pool``)."""
            return _heldout_gate(dg, cur, new, row, cur_errs, cur_rmse, min_heldout_gain, heldout_alpha, pool, log)

        # While the model is plain, an effect whose grid start fits better than the plain fit is refitted
        # from that start whatever its screen says (and from there only: the screen says the local step
        # shows nothing). The screen is local, at the plain optimum, and that optimum can hide the effect
        # behind another taper (a yielding twig: plain fit p = 2, yield screen 0.8, yield refit LR 228).
        grids = {e: dg.grid_start(e, cur) for e in GRID_STARTED if e in remaining} if not cur.effects else {}
        for t in tests:
            if grids.get(t["effect"]) is not None and t["p_value"] >= level:
                t["refitted_from_grid"] = True
        screened = [t for t in tests if t["p_value"] < level or t.get("refitted_from_grid")]
        passed = []  # (effects, row, fit) past the likelihood ratio
        for t, (row, new) in zip(screened, fits([(t,) for t in screened], *state), strict=True):
            t.update(row)
            if new is not None:
                passed.append(((t["effect"],), t, new))
        accepted = _first_passing(passed, gate)
        if accepted is None and pairs and len(remaining) >= 2 and len(added) + 2 <= max_effects:
            if dg.structure(cur, ratio=structure_ratio)["unexplained_structure"]:
                # pairs of the (up to three) singles that moved the likelihood (LR above chi^2_1 at 0.05)
                moved = [t for t in tests if t.get("lr_statistic", 0.0) > stats.chi2.isf(0.05, 1)]
                top = sorted(moved, key=lambda t: -t["lr_statistic"])[:3]
                duos = list(combinations(top, 2))
                passed = []
                for (a, b), (row, new) in zip(duos, fits(duos, *state), strict=True):
                    effs = (a["effect"], b["effect"])
                    prow = {"effect": "+".join(effs), "round": rnd, "pair": list(effs), "level": level}
                    prow.update(row, selected=False, statistic=float(row["lr_statistic"]))
                    prow["p_value"] = float(stats.chi2.sf(max(row["lr_statistic"], 0.0), 2))
                    rows.append(prow)
                    if new is not None:
                        passed.append((effs, prow, new))
                accepted = _first_passing(passed, gate)
        if accepted is None:
            break
        effs, (cur, err, cur_errs), trow = accepted
        trow["selected"] = True
        near = _alternatives(passed, trow)
        for t in near:
            t["indistinguishable_from_added"] = True
        alternatives["+".join(effs)] = [t["effect"] for t in near]
        for t in rows:
            if t.get("round") == rnd and "lr_statistic" in t and not t["selected"] and "rejected_because" not in t:
                t["rejected_because"] = "a better-fitting effect was added"
        added += list(effs)
        history.append({"effects": list(added), "errors": err, "loglik": cur.loglik})
        log(f"added {', '.join(effs)}")
        if len(added) >= max_effects:
            break
    after = history[-1]["errors"]
    struct = dg.structure(cur, ratio=structure_ratio)
    return {
        "added_effects": added,
        "alternatives": alternatives,
        "candidates": rows,
        "before": before,
        "after": after,
        "unexplained_structure": struct["unexplained_structure"],
        "structure_before": before_struct["blocks"],
        "structure_after": struct["blocks"],
        "fitted": cur.natural(L),
        "noise": {
            "model": force_noise,
            "sigma_force_N": cur.marginal_sigma_force,
            "innovation_sd_N": cur.sigma_force,
            "rho_force": cur.rho_force,
            "shape_scale": cur.shape_scale,
        },
        "history": history,
        "_fit": cur,
        "_plain": plain,
    }


def _no_worse_start(dg: Diagnoser, cur: MapFit, effects: tuple[str, ...], starts: NDArray, tries: int = 3) -> NDArray:
    """``cur.x`` plus the new coordinates at ``starts``, pulled towards their neutral values (a quarter
    of the step at a time, then the neutral value itself) while the start fits worse than ``cur``.

    A fit started worse than the current model may end worse within its iteration budget: a friction
    step of 0.04 moves the slip of a twig by more than the noise (47 nats below the plain fit).
    """
    # yield has no neutral value (its start comes from a grid): it is kept as given
    neutral = np.array([starts[i] if e == "yield" else _COORD[e][0] for i, e in enumerate(effects)])
    noise = (cur.sigma_force, cur.rho_force, cur.shape_scale)
    for factor in 0.25 ** np.arange(tries):  # 1, 1/4, 1/16: the step, then a quarter of it, ...
        x = np.concatenate([cur.x, neutral + factor * (starts - neutral)])
        if dg.loglik(*dg.raw_residuals(x, cur.effects + tuple(effects)), noise) >= cur.loglik:
            return x
    return np.concatenate([cur.x, neutral])  # the current model itself


def _start_coord(effect: str, test: dict, fit: MapFit, L: float) -> float:
    """A start for the new coordinate: a small step in the direction the score points."""
    if effect == "yield":
        return float(np.log(test.get("yield_moment_Nm", 1.0)))
    neutral, step = _COORD[effect][0], _COORD[effect][1]
    if effect == "force_offset":
        step = fit.sigma_force
    return neutral + 2 * step * (test["direction"] or 1.0)

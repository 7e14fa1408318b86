"""The seed's deterministic pipeline, with the curvature uncertainty carried through.

1. Direct estimator (eq. direct_estimator with eq. M_determinate): in every
   engaged frame, M(s) = F_c (h - z(s)) below the contact and kappa(s) from the
   Matern-3/2 GP on the tangent angle (``vision.curvature``), so
   EI_sample(t, s) = M / kappa. The ratio is ill-conditioned as kappa -> 0, so
   samples are pooled per arc-length bin through the compliance c = kappa / M,
   which is linear in the noisy curvature: a weighted mean of c with weights
   1 / sd_c^2 (sd_c from the GP band and the force noise), its standard error
   inflated by the Birge ratio when the scatter exceeds the stated errors, and
   EI_bin = 1 / c_bin with relative standard error se_c / c_bin. Bins with
   s < 0.02 m are excluded as in the seed; samples pool across heights.
2. p from the weighted log-linear fit (eq. p_fit), weights 1 / rel_se^2, with
   its weighted R^2.
3. EI0 with p fixed from the contact-point residual (eq. EI0_fit): the elastica
   at each frame's measured force against the observed centerline at z = h.
4. The seed's error metrics at the fitted taper: per engaged frame, the force
   error at the frame's contact displacement and the shape RMSE over up to 200
   observed points below the contact; medians over frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from ..dataset.engagement import detect_engagement
from ..dataset.model import Push, Specimen
from ..physics.elastica import contact_from_force, force_from_displacement
from ..vision.curvature import fit_curvature_gp, tangent_angles

S_MIN_M = 0.02  # the seed excludes bins below 2 cm (near-zero curvature at the base)


@dataclass(frozen=True)
class FrameSample:
    """One engaged frame, ready for the estimators (x already in the push direction)."""

    push_id: str
    height_m: float
    time_s: float
    force_N: float  # measured force at the frame time, baseline removed
    force_sd_N: float
    displacement_m: float  # contact displacement at the frame time
    x_m: NDArray
    z_m: NDArray
    sd_m: NDArray | None


@dataclass(frozen=True)
class DirectEstimate:
    """Per-bin direct estimate of EI(s), pooled over frames and heights.

    Attributes
    ----------
    s_m : (B,) bin centres [m]
    EI : (B,) pooled EI [N m^2] (NaN where the pooled compliance is not positive)
    se : (B,) standard error of EI [N m^2]
    rel_se : (B,) relative standard error
    n : (B,) frames contributing
    samples : dict of (K,) arrays ``s_m``, ``EI``, ``EI_sd`` (its band sd, smoothing bias included), ``height_m``:
        every frame-bin sample
    """

    s_m: NDArray
    EI: NDArray
    se: NDArray
    rel_se: NDArray
    n: NDArray
    samples: dict


def engaged_frames(spec: Specimen) -> list[FrameSample]:
    """Engaged frames of every push with shapes: force and displacement interpolated to the frame time."""
    out = []
    for push in spec.pushes:
        out.extend(_push_frames(push))
    return out


def _push_frames(push: Push) -> list[FrameSample]:
    if not push.shapes:
        return []
    eng = detect_engagement(push.force.force_N)
    t = push.force.time_s[eng.mask]
    if t.size < 2:
        return []
    F = push.force.force_N[eng.mask] - eng.baseline_N
    D = push.force.contact_x_m[eng.mask]
    out = []
    for fr in push.shapes:
        if not (t[0] <= fr.time_s <= t[-1]):
            continue
        keep = fr.z_m >= 0
        out.append(
            FrameSample(
                push.id,
                push.height_m,
                fr.time_s,
                float(np.interp(fr.time_s, t, F)),
                float(eng.noise_N),
                float(np.interp(fr.time_s, t, D)),
                fr.x_m[keep] * push.direction,
                fr.z_m[keep],
                fr.sd_m[keep] if fr.sd_m is not None else None,
            )
        )
    return out


def _frame_curvature(fs: FrameSample, s_query: NDArray):
    """GP curvature at arc lengths ``s_query`` below the contact: mean, band sd (sampling and smoothing
    bias), sampling sd alone, and z there; NaN outside."""
    below = fs.z_m < fs.height_m - 0.01 * fs.height_m
    x, z = fs.x_m[below], fs.z_m[below]
    nan = np.full(s_query.size, np.nan)
    if x.size < 8:
        return nan, nan, nan, nan
    seg = np.hypot(np.diff(x), np.diff(z))
    ok = np.concatenate([[True], seg > 0])
    x, z = x[ok], z[ok]
    if fs.sd_m is not None:
        ta = tangent_angles(x, z, fs.sd_m[below][ok])
        gp = fit_curvature_gp(ta["s"], ta["theta"], noise_cov=ta["cov"])
    else:  # noise unknown: no arc-length correction, a white-noise level fitted
        ta = tangent_angles(x, z, np.zeros_like(x))
        gp = fit_curvature_gp(ta["s"], ta["theta"])
    s_nodes = ta["s_nodes"]
    inside = (s_query >= ta["s"][0]) & (s_query <= ta["s"][-1])
    kap, sd, se, zq = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    if inside.any():
        pr = gp.predict(s_query[inside])
        kap[inside], sd[inside], se[inside] = pr["kappa"], pr["kappa_sd"], np.sqrt(pr["kappa_se2"])
        zq[inside] = np.interp(s_query[inside], s_nodes, z)
    return kap, sd, se, zq


def direct_estimate(
    spec: Specimen, *, n_bins: int = 24, s_min_m: float = S_MIN_M, frames: list[FrameSample] | None = None
) -> DirectEstimate:
    """Direct estimate of EI(s) (eq. direct_estimator) in arc-length bins, with standard errors.

    Parameters
    ----------
    spec : Specimen
        Needs pushes with ``shapes``.
    n_bins : int
        Bins over [s_min_m, max contact height].
    s_min_m : float
        Bins below this arc length are excluded (the seed: 0.02 m).
    """
    frames = engaged_frames(spec) if frames is None else frames
    if not frames:
        raise ValueError(f"{spec.specimen}: the direct estimator needs engaged centerline frames (shapes), got none")
    s_top = max(fs.height_m for fs in frames)
    edges = np.linspace(s_min_m, s_top, n_bins + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    S, C, SDC, SEC, H = [], [], [], [], []
    for fs in frames:
        kap, ksd, kse, z = _frame_curvature(fs, centres)
        M = fs.force_N * (fs.height_m - z)  # eq. M_determinate
        ok = np.isfinite(kap) & (M > 0.05 * fs.force_N * fs.height_m) & (fs.force_N > 3 * fs.force_sd_N)
        if not ok.any():
            continue
        c = kap[ok] / M[ok]
        force_part = (c * fs.force_sd_N / fs.force_N) ** 2
        S.append(centres[ok])
        C.append(c)
        SDC.append(np.sqrt((ksd[ok] / M[ok]) ** 2 + force_part))  # one frame's band, bias included
        # the bins weigh frames by the sampling error alone (the seed's weights): the smoothing bias is
        # shared by neighbouring frames rather than averaged away, and weighting by it made the two-stage
        # p worse (grass: mean error 0.0252 -> 0.0409, scripts/compare_two_stage.py); Birge covers scatter
        SEC.append(np.sqrt((kse[ok] / M[ok]) ** 2 + force_part))
        H.append(np.full(c.size, fs.height_m))
    if not S:
        raise ValueError(f"{spec.specimen}: no frame had enough centerline points below the contact (need 8)")
    S, C, SDC, SEC, H = (np.concatenate(a) for a in (S, C, SDC, SEC, H))
    EI, se, rel, n = (np.full(n_bins, np.nan) for _ in range(4))
    for b, sc in enumerate(centres):
        sel = S == sc
        n[b] = sel.sum()
        if n[b] < 2:
            continue
        w = 1.0 / SEC[sel] ** 2
        cbar = np.sum(w * C[sel]) / np.sum(w)
        se_c = 1.0 / np.sqrt(np.sum(w))
        birge = np.sqrt(np.sum(w * (C[sel] - cbar) ** 2) / (n[b] - 1))
        se_c *= max(1.0, birge)
        if cbar > 0:
            EI[b] = 1.0 / cbar
            rel[b] = se_c / cbar
            se[b] = EI[b] * rel[b]
    with np.errstate(divide="ignore", invalid="ignore"):
        EIs = np.where(C > 0, 1.0 / C, np.nan)
        samples = {"s_m": S, "EI": EIs, "EI_sd": EIs**2 * SDC, "height_m": H}
    return DirectEstimate(centres, EI, se, rel, n.astype(int), samples)


@dataclass(frozen=True)
class TwoStageFit:
    """The seed's deterministic estimate (eqs. p_fit and EI0_fit) and its error metrics."""

    p: float
    p_se: float
    EI0: float
    r2: float
    n_bins: int
    shape_rmse_mm: float  # median over engaged frames (seed's metric)
    force_error_N: float  # median |F_pred - F_meas| over engaged frames
    direct: DirectEstimate

    def to_dict(self) -> dict:
        return {
            "p": self.p,
            "p_se": self.p_se,
            "EI0": self.EI0,
            "taper_fit_r2": self.r2,
            "n_bins": self.n_bins,
            "median_shape_rmse_mm": self.shape_rmse_mm,
            "median_force_error_N": self.force_error_N,
        }


def fit_p(direct: DirectEstimate, length_m: float) -> tuple[float, float, float, int]:
    """Weighted log-linear fit of eq. p_fit: returns p, its standard error, weighted R^2, bins used."""
    ok = np.isfinite(direct.EI) & (direct.rel_se > 0) & (direct.s_m < length_m)
    if ok.sum() < 3:
        raise ValueError(f"p_fit: expected at least 3 bins with a positive direct estimate, got {int(ok.sum())}")
    y = np.log(direct.EI[ok])
    X = np.stack([np.ones(ok.sum()), np.log1p(-direct.s_m[ok] / length_m)], axis=1)
    w = 1.0 / direct.rel_se[ok] ** 2
    XtW = X.T * w
    cov = np.linalg.inv(XtW @ X)
    a, b = cov @ (XtW @ y)
    res = y - X @ np.array([a, b])
    dof = max(int(ok.sum()) - 2, 1)
    chi2 = float(np.sum(w * res**2))
    ybar = np.sum(w * y) / np.sum(w)
    r2 = 1.0 - chi2 / float(np.sum(w * (y - ybar) ** 2))
    b_se = float(np.sqrt(cov[1, 1] * max(1.0, chi2 / dof)))
    return float(b / 4.0), b_se / 4.0, float(r2), int(ok.sum())


def _observed_x_at(fs: FrameSample, z0: float) -> float:
    """Observed centerline x at height z0: linear across the occlusion gap, or extrapolated from below."""
    z, x = fs.z_m, fs.x_m
    lo = np.flatnonzero(z <= z0)
    hi = np.flatnonzero(z > z0)
    if lo.size >= 2 and hi.size >= 1:
        i, j = lo[-1], hi[0]
        return float(x[i] + (x[j] - x[i]) * (z0 - z[i]) / (z[j] - z[i]))
    if lo.size >= 4:
        k = lo[-4:]
        return float(np.polyval(np.polyfit(z[k], x[k], 1), z0))
    return float("nan")


def fit_EI0(frames: list[FrameSample], p: float, length_m: float) -> float:
    """EI0 with p fixed from the contact-point position residual (eq. EI0_fit)."""
    use = [fs for fs in frames if fs.force_N > 3 * fs.force_sd_N]
    xo = np.array([_observed_x_at(fs, fs.height_m) for fs in use])
    ok = np.isfinite(xo)
    if ok.sum() < 1:
        raise ValueError("EI0_fit: expected frames with centerline points around the contact height, got none")
    F = np.array([fs.force_N for fs in use])[ok]
    h = np.array([fs.height_m for fs in use])[ok]
    xo = xo[ok]

    def cost(logEI0):
        r = contact_from_force(F, h, np.exp(logEI0), p, length_m)
        pred = np.where(r.found, r.contact_x_m, length_m)  # no contact: the stem has slipped; a large penalty
        return float(np.sum((pred - xo) ** 2))

    # bracket from the small-deflection guess x = F h^3 / (3 EI): EI ~ F h^3 / (3 x)
    guess = float(np.median(F * h**3 / (3 * np.maximum(np.abs(xo), 1e-4))))
    lg = np.log(max(guess, 1e-9))
    res = minimize_scalar(cost, bounds=(lg - 5, lg + 5), method="bounded", options={"xatol": 1e-7})
    return float(np.exp(res.x))


def seed_error_metrics(frames: list[FrameSample], EI0: float, p: float, length_m: float) -> tuple[float, float]:
    """Median shape RMSE [mm] below the contact (up to 200 points) and median force error [N] over frames."""
    F_err, rmse = [], []
    for fs in frames:
        sol = force_from_displacement(fs.displacement_m, fs.height_m, EI0, p, length_m, keep_shape=True)
        if bool(sol.slipped):
            continue
        F_err.append(abs(float(sol.force_N) - fs.force_N))
        xz = sol.shape_xz_m  # (n+1, 2)
        below = fs.z_m < fs.height_m
        if below.sum() < 2:
            continue
        idx = np.flatnonzero(below)
        if idx.size > 200:
            idx = idx[np.linspace(0, idx.size - 1, 200).astype(int)]
        zeta = np.maximum.accumulate(xz[:, 1])
        xp = np.interp(fs.z_m[idx], zeta, xz[:, 0])
        dxdz = np.gradient(xz[:, 0], zeta, edge_order=1) if np.all(np.diff(zeta) > 0) else np.zeros_like(zeta)
        cos = 1.0 / np.sqrt(1.0 + np.interp(fs.z_m[idx], zeta, dxdz) ** 2)
        rmse.append(1000 * float(np.sqrt(np.mean(((fs.x_m[idx] - xp) * cos) ** 2))))
    return _median_or_nan(rmse), _median_or_nan(F_err)


def _median_or_nan(a: list) -> float:
    return float(np.median(a)) if a else float("nan")


def two_stage_fit(spec: Specimen, *, n_bins: int = 24, s_min_m: float = S_MIN_M) -> TwoStageFit:
    """The seed's deterministic pipeline: direct estimate -> p (eq. p_fit) -> EI0 (eq. EI0_fit) -> errors."""
    frames = engaged_frames(spec)
    direct = direct_estimate(spec, n_bins=n_bins, s_min_m=s_min_m, frames=frames)
    p, p_se, r2, nb = fit_p(direct, spec.length_m)
    p_fit = float(np.clip(p, 0.0, 3.0))
    EI0 = fit_EI0(frames, p_fit, spec.length_m)
    shape_mm, force_N = seed_error_metrics(frames, EI0, p_fit, spec.length_m)
    return TwoStageFit(p, p_se, EI0, r2, nb, shape_mm, force_N, direct)

"""Is the diameter taper p_geom from the width profile alone calibrated? (issue 22)

    python scripts/width_taper_check.py --stem grass --seeds 20-31 [--graded 120-122] --cache DIR
        [--same-pixels 1,3] [--style shaded]

Per seed: simulate and extract one rendered push as scripts/diameter_study.py does (``_study.extracted_push``),
keeping every frame's width profile (cached in ``DIR``, so variants of how the frames are combined rerun in
seconds). For each value of ``SAME_PIXELS_PX`` given (how far apart [px] two frames' samples of a station must
lie to read independent background pixels; the library's value first), the frames are combined again
(``combine_profiles``) and the width term of ``bayesrod.fit`` alone (d0, p_geom, the station sd scale and
their AR(1) correlation, the shared offset and scale marginalised; flat prior on p_geom) is sampled with
emcee. Printed per variant: the widths' scale error (d0 fitted at the drawn taper, the stations' median
relative error), the taper's z-score (median - drawn) / (90% half-width / 1.645) and whether its
90% interval covers the drawn taper, per seed and pooled (z rms 1 and 90% cover when calibrated).
"""

from __future__ import annotations

import argparse
import pickle
import tempfile
from pathlib import Path

import numpy as np
from _study import extracted_push, seeds

from bayesrod.dataset.io import write_bytes_atomic
from bayesrod.inference.likelihood import width_loglik
from bayesrod.physics import stem_diameter
from bayesrod.vision import width as W


def load_cached(cache: Path, key: str) -> dict:
    """A push cached by :func:`frames_of` under ``key`` = ``<stem>_<seed>_<graded>``."""
    return pickle.loads((cache / f"{key}.pkl").read_bytes())


def combined(fr: dict):
    """The frames of a cached push combined as ``bayesrod.extract`` does (a ``DiameterProfile``)."""
    return W.combine_profiles(fr["profiles"], fr["s_m"], *fr["args"], **fr["kwargs"])


def frames_of(stem: str, seed: int, graded: bool, cache: Path, style: str = "flat") -> dict:
    """The frames' width profiles of one push and its truth (cached; ``style``: the renderer's)."""
    key = f"{stem}_{seed}_{int(graded)}" + ("" if style == "flat" else f"_{style}")
    if (cache / f"{key}.pkl").exists():
        return load_cached(cache, key)
    seen = {}
    real = W.combine_profiles

    def keep(profiles, s_m, *a, **k):
        seen.update(profiles=profiles, s_m=s_m, args=a, kwargs=k)
        return real(profiles, s_m, *a, **k)

    W.combine_profiles = keep
    try:
        with tempfile.TemporaryDirectory() as tmp:
            ex, _, px = extracted_push(stem, seed, graded, Path(tmp), style)
    finally:
        W.combine_profiles = real
    truth = ex.source.extra["truth"]
    out = {
        **seen,
        "d0": truth["base_diameter_m"],
        "q": truth["diameter_taper"],
        "L": ex.dataset.length_m,
        "px": px,
    }
    cache.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(cache / f"{key}.pkl", pickle.dumps(out))
    return out


def taper_posterior(dp, L: float, seed: int, floor: bool = False) -> np.ndarray:
    """Draws of p_geom from the width term alone (as RodLikelihood._diameter_loglik; flat p_geom in [0, 3])."""
    import emcee

    ok = dp.ok
    s, d, sd = dp.s_m[ok], dp.d_m[ok], dp.sd_m[ok]
    first = np.concatenate([[True], np.diff(s) > 1.5 * float(np.median(np.diff(s)))])

    typical = float(np.median(sd))

    def log_prob(th):
        th = np.atleast_2d(th)
        logd0, pg, logk, rho = th.T[:4]
        logf = th[:, 4] if floor else None
        bad = (pg < 0) | (pg > 3) | (rho < -0.5) | (rho > 0.995)
        pred = stem_diameter(s[None], np.exp(logd0)[:, None], pg[:, None], L)
        f = np.exp(logf)[:, None] * typical if floor else 0.0
        # each station's sd: the sd scale k times its own, and (floor) a floor f x the median station sd
        sde = np.sqrt((np.exp(logk)[:, None] * sd[None]) ** 2 + f**2)
        ones = np.ones((pred.shape[0], 1))
        with np.errstate(invalid="ignore", divide="ignore"):
            ll = width_loglik(
                d,
                pred,
                sde,
                ones,
                rho[:, None],
                first,
                dp.shared_offset_sd_m,
                dp.shared_scale_sd,
                dp.shared_taper_sd,
                np.exp(logd0)[:, None],
            )
        lp = -0.5 * (logk / 0.5) ** 2
        if floor:  # half-normal(1) on the floor's ratio to the median sd, sampled in log
            lp = lp - 0.5 * np.exp(2 * logf) + logf
        return np.where(bad | ~np.isfinite(ll), -np.inf, ll + lp)

    rng = np.random.default_rng(seed)
    nw = 32
    start = np.column_stack(
        [
            np.log(d[0]) + 0.01 * rng.standard_normal(nw),
            1.0 + 0.05 * rng.standard_normal(nw),
            0.1 * rng.standard_normal(nw),
            0.1 * rng.uniform(0, 1, nw),
        ]
        + ([np.log(0.3) + 0.1 * rng.standard_normal(nw)] if floor else [])
    )
    sampler = emcee.EnsembleSampler(nw, start.shape[1], log_prob, vectorize=True)
    sampler._random = np.random.mtrand.RandomState(seed)  # emcee's own generator, seeded: reproducible draws
    sampler.run_mcmc(start, 3000, progress=False)
    return sampler.get_chain(discard=1000, flat=True)[:, 1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stem", default="grass")
    ap.add_argument("--seeds", default="20-31")
    ap.add_argument("--graded", default="")
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--same-pixels", default=str(W.SAME_PIXELS_PX), help="SAME_PIXELS_PX values, comma separated")
    ap.add_argument("--style", default="flat", choices=("flat", "shaded"), help="the renderer's style")
    ap.add_argument("--floor", action="store_true", help="stations' sd with a sampled floor (sd^2 k^2 + f^2)")
    a = ap.parse_args(argv)
    jobs = [(s, False) for s in seeds(a.seeds)] + [(s, True) for s in seeds(a.graded)]
    values = [float(v) for v in a.same_pixels.split(",")]
    keep = W.SAME_PIXELS_PX
    pooled = {v: [] for v in values}
    for seed, graded in jobs:
        fr = frames_of(a.stem, seed, graded, a.cache, a.style)
        line = [f"{a.stem} {seed}{' graded' if graded else ''}: drawn p_geom {fr['q']:.3f}"]
        for v in values:
            W.SAME_PIXELS_PX = v
            try:
                dp = combined(fr)
            finally:
                W.SAME_PIXELS_PX = keep
            # the widths' scale error: d0 fitted at the drawn taper (weights 1/sd^2), the stations' median error
            ok = dp.ok
            g = stem_diameter(dp.s_m[ok], 1.0, fr["q"], fr["L"])
            w = 1.0 / dp.sd_m[ok] ** 2
            d0_at_truth = float(np.sum(w * g * dp.d_m[ok]) / np.sum(w * g * g)) / fr["d0"] - 1.0
            station = float(np.median(dp.d_m[ok] / (fr["d0"] * g) - 1.0))
            pg = taper_posterior(dp, fr["L"], seed, a.floor)
            q05, q50, q95 = np.quantile(pg, [0.05, 0.5, 0.95])
            z = (q50 - fr["q"]) / ((q95 - q05) / 2 / 1.645)
            pooled[v].append((z, q05 <= fr["q"] <= q95, (q95 - q05) / 2))
            line.append(
                f"same_px {v:g}: {q50:.3f} [{q05:.3f}, {q95:.3f}] z {z:+.2f}, d0 at the drawn taper "
                f"{100 * d0_at_truth:+.2f}%, stations' median error {100 * station:+.2f}%"
            )
        print("; ".join(line), flush=True)
    for v, rows in pooled.items():
        z, cov, hw = (np.array(c) for c in zip(*rows, strict=True))
        print(
            f"SAME_PIXELS_PX {v:g}: {len(z)} pushes, taper z rms {np.sqrt(np.mean(z**2)):.2f}, "
            f"90% cover {np.mean(cov):.2f}, median half-width {np.median(hw):.3f}"
        )


if __name__ == "__main__":
    main()

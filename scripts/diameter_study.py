"""Diameter from the frames, taper and Young's modulus: replicate study (issue 22).

    python scripts/diameter_study.py --out diameter-study --reps 10 [--workers 1] [--style shaded]

Per replicate and stem (twig, grass; one contact height, the preset's middle one; rendered frames
with clutter, the probe and depth dropouts, ``bayesrod simulate``'s renderer):

1. ``bayesrod.extract``: the diameter profile from the frames (docs/vision.md); its median absolute
   error against the drawn diameter [px], the sd of (measured - true) / sd over the ok stations,
   the fraction within +-1.645 sd;
2. force-only fits with the width term ``shared`` (uniform modulus), ``off`` (width ignored) and
   ``free`` (p_geom free): E0's and d0's 90% intervals against the truth, the p interval's width with
   and without the width, the uniform-modulus verdict;
3. the same stem drawn with a modulus gradient (diameter taper q = p - 0.15, so that
   E(s) ~ (1 - s/L)^0.6): the ``free`` fit's verdict (expected ``rejected``).

``--base-diameter-m D`` draws every stem with that base diameter [m] (e.g. the twig at 0.006: 2.9 px; write
to an ``--out`` of its own: rows are resumed by stem and seed). ``--length unknown`` fits every model with the
stem length sampled (``bayesrod.fit(length="unknown")``):
on forces only p then trades off with L and EI0, and the width term's share of p's interval shows.

Writes diameter_study.csv (resumable: done rows are skipped) and diameter_study.md (the table of
docs/validation.md).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _study import extracted_push, run_pending

import bayesrod
from bayesrod.dataset.io import read_rows

FIELDS = ["stem", "seed", "graded", "stations_ok", "median_abs_err_px", "z_sd", "z_cover90"]
FIELDS += ["d0_true", "d0", "d0_q05", "d0_q95", "E_true", "E", "E_q05", "E_q95"]
FIELDS += ["p_true", "p_q05_shared", "p_q95_shared", "p_q05_off", "p_q95_off", "dq_q05", "dq_q95", "verdict"]
FIELDS += ["seconds", "length", "style"]


def one(job) -> dict:
    stem, seed, graded, length, style, d0 = job
    t0 = time.perf_counter()
    row = {"stem": stem, "seed": seed, "graded": int(graded), "length": length, "style": style}
    with tempfile.TemporaryDirectory() as tmp:
        overrides = {} if d0 is None else {"base_diameter_m": d0}
        ex, true, px = extracted_push(stem, seed, graded, Path(tmp), style, overrides=overrides)
        ds, dp, truth = ex.dataset, ex.diameters, ex.source.extra["truth"]
        ok = dp.ok
        z = (dp.d_m[ok] - true[ok]) / dp.sd_m[ok]
        row.update(
            stations_ok=int(ok.sum()),
            median_abs_err_px=float(np.median(np.abs(dp.d_m[ok] - true[ok])) / px),
            z_sd=float(np.std(z)),
            z_cover90=float(np.mean(np.abs(z) < 1.645)),
            d0_true=truth["base_diameter_m"],
            E_true=truth["youngs_modulus_Pa"],
            p_true=truth["p"],
        )
        modes = ("free",) if graded else ("shared", "off", "free")
        for mode in modes:
            post = bayesrod.fit(ds, use_shapes=False, diameter=mode, length=length, progress=False, max_steps=4000)
            doc = post.to_dict()
            pq = doc["parameters"]["p"]
            if mode in ("shared", "off"):
                row[f"p_q05_{mode}"], row[f"p_q95_{mode}"] = pq["q05"], pq["q95"]
            if mode == "shared" or (graded and mode == "free"):
                y = doc["youngs_modulus"]
                row.update(d0=y["d0_m"]["median"], d0_q05=y["d0_m"]["q05"], d0_q95=y["d0_m"]["q95"])
                row.update(E=y["E_Pa"]["median"], E_q05=y["E_Pa"]["q05"], E_q95=y["E_Pa"]["q95"])
            if mode == "free":
                y = doc["youngs_modulus"]
                row.update(dq_q05=y["modulus_taper"]["q05"], dq_q95=y["modulus_taper"]["q95"])
                row["verdict"] = y["uniform_modulus"]
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def _style(row) -> str:
    """A row's render style (rows written before the column was added: flat)."""
    return row.get("style") or "flat"


def table(rows) -> str:
    out = [
        "| stem | style | modulus | reps | width error, median px | station z sd | station 90% cover | d0 within 5% "
        "| d0 90% cover | E 90% cover | p width with / without width | p 90% cover with / without width "
        "| uniform modulus rejected |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    styles = sorted({_style(r) for r in rows})
    for stem, style, graded in ((st, sy, g) for st in ("twig", "grass") for sy in styles for g in (0, 1)):
        rs = [r for r in rows if r["stem"] == stem and _style(r) == style and int(float(r["graded"])) == graded]
        if rs:

            def f(k, rs=rs):
                return np.array([float(r[k]) for r in rs])

            cover_d0 = np.mean((f("d0_q05") <= f("d0_true")) & (f("d0_true") <= f("d0_q95")))
            cover_E = np.mean((f("E_q05") <= f("E_true")) & (f("E_true") <= f("E_q95")))
            within = np.mean(np.abs(f("d0") / f("d0_true") - 1) < 0.05)
            if graded:
                ratio = cover_p = "-"
            else:
                ratio = f"{np.median((f('p_q95_shared') - f('p_q05_shared')) / (f('p_q95_off') - f('p_q05_off'))):.2f}"
                cover_p = " / ".join(
                    f"{np.mean((f(f'p_q05_{m}') <= f('p_true')) & (f('p_true') <= f(f'p_q95_{m}'))):.2f}"
                    for m in ("shared", "off")
                )
            rej = sum(r["verdict"] == "rejected" for r in rs)
            out.append(
                f"| {stem} | {style} | {'graded' if graded else 'uniform'} | {len(rs)} "
                f"| {np.median(f('median_abs_err_px')):.3f} "
                f"| {np.median(f('z_sd')):.2f} | {np.median(f('z_cover90')):.2f} | {within:.2f} | {cover_d0:.2f} "
                f"| {cover_E:.2f} | {ratio} | {cover_p} | {rej}/{len(rs)} |"
            )
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="diameter-study")
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--graded-reps", type=int, default=5)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--stems", default="twig,grass", help="presets to render, comma separated (default twig,grass)")
    ap.add_argument(
        "--first-seed", type=int, default=0, help="seeds first..first+reps-1 (graded: 100+first...); fresh cases"
    )
    ap.add_argument(
        "--length", choices=("known", "unknown"), default="known", help="the fits' stem length: given, or sampled"
    )
    ap.add_argument("--style", choices=("flat", "shaded"), default="flat", help="the renderer's render_style")
    ap.add_argument("--base-diameter-m", type=float, help="the drawn base diameter [m] (default: the preset's)")
    a = ap.parse_args(argv)
    if a.base_diameter_m is not None and not a.base_diameter_m > 0:
        ap.error(f"--base-diameter-m: expected a positive diameter in metres, got {a.base_diameter_m}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "diameter_study.csv"
    stems = [s for s in a.stems.split(",") if s]
    d0 = a.base_diameter_m
    jobs = [(s, a.first_seed + k, False, a.length, a.style, d0) for k in range(a.reps) for s in stems]
    jobs += [(s, 100 + a.first_seed + k, True, a.length, a.style, d0) for k in range(a.graded_reps) for s in stems]

    def done_key(r):
        return r["stem"], int(float(r["seed"])), bool(int(float(r["graded"]))), r["length"], _style(r)

    for row in run_pending(csv, FIELDS, jobs, one, done_key=done_key, workers=a.workers):
        print(row["stem"], row["seed"], row["graded"], row.get("verdict"), row["seconds"], flush=True)
    (out / "diameter_study.md").write_text(table(read_rows(csv)))
    print(table(read_rows(csv)))


if __name__ == "__main__":
    main()

"""Errors of the extracted diameter profile that the stations share: offset and scale (issue 22).

    python scripts/width_error_study.py --out width-study --reps 20 [--workers 2] [--style shaded]
        [--colour-model unmixing]

Per replicate and stem (twig, grass; one contact height, the preset's middle one; frames drawn with
exact widths, clutter, the probe and depth dropouts), ``bayesrod.extract`` measures the diameter
profile, and against the drawn diameter this records, over the ``ok`` stations (``--style shaded``:
frames of a round, limb-darkened stem through a defocused lens, ``bayesrod.vision.render``):

* ``offset_px``: the median signed error [px], the part of the error all stations share;
* ``z_sd_within``: the sd of the errors about that offset, in units of the stations' sd (the
  station-to-station part the fit's own sd scale absorbs);
* ``depth_rel_err``: the plane depth the extraction used, relative to the rendered plane (a scale
  error every width and every centerline shares).

The spread of ``offset_px`` and ``depth_rel_err`` over replicates sets the defaults of the width
term's shared errors (``bayesrod.vision.width.OFFSET_SD_PX``, ``DEPTH_SCALE_SD``; docs/inference.md).
Writes width_error_study.csv (resumable: done rows are skipped) and width_error_study.md.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _study import run_pending

import bayesrod
from bayesrod.dataset.io import read_rows
from bayesrod.physics import stem_diameter
from bayesrod.vision.render import STYLES
from bayesrod.vision.width import COLOUR_CHOICES, COLOUR_MODELS

FIELDS = ["stem", "style", "colour_model", "seed", "stations_ok", "px_mm", "offset_px", "median_abs_err_px"]
FIELDS += ["z_sd_within", "depth_rel_err", "seconds", "model_used"]


def one(job) -> dict:
    stem, seed, style, colour_model = job
    t0 = time.perf_counter()
    from bayesrod.dataset.simulate import SimConfig
    from bayesrod.vision.render import plane_depth

    cfg = SimConfig.from_preset(stem, seed=seed)
    h = cfg.heights_m[len(cfg.heights_m) // 2]
    over = {"exact_width": True, "render_style": style}
    sim = bayesrod.simulate(stem, seed=seed, heights_m=[h], config_overrides=over)
    with tempfile.TemporaryDirectory() as tmp:
        sim.save(Path(tmp) / "raw", frames=True)
        ex = bayesrod.extract(Path(tmp) / "raw", progress=False, width_colour_model=colour_model)
    truth = ex.source.extra["truth"]
    d0, q, L = truth["base_diameter_m"], truth["diameter_taper"], ex.dataset.length_m
    dp = ex.diameters
    ok = dp.ok
    Z = ex.doc["pushes"][ex.dataset.pushes[0].id]["plane_depth_m"]
    px = Z / ex.dataset.camera.fx  # metres per pixel at the plane the extraction used
    err = dp.d_m[ok] - stem_diameter(dp.s_m[ok], d0, q, L)
    offset = float(np.median(err))
    return {
        "stem": stem,
        "style": style,
        "colour_model": colour_model,
        "seed": seed,
        "stations_ok": int(ok.sum()),
        "px_mm": 1000 * px,
        "offset_px": offset / px,
        "median_abs_err_px": float(np.median(np.abs(err)) / px),
        "z_sd_within": float(np.std((err - offset) / dp.sd_m[ok])),
        "depth_rel_err": Z / plane_depth(L) - 1.0,
        "seconds": round(time.perf_counter() - t0, 1),
        "model_used": ex.doc["diameters"]["colour_model"]["model"],  # what auto chose (or the model asked for)
    }


def table(rows: list[dict]) -> str:
    out = [
        "| stem | style | colour model | reps | offset_px mean | offset_px sd | offset_px rms | depth_rel_err sd "
        "| z_sd_within median |"
    ]
    out.append("|---|---|---|---|---|---|---|---|---|")
    for key in sorted({(r["stem"], r["style"], r["colour_model"]) for r in rows}):
        sub = [r for r in rows if (r["stem"], r["style"], r["colour_model"]) == key]
        stem, style, colour_model = key
        off = np.array([float(r["offset_px"]) for r in sub])
        dep = np.array([float(r["depth_rel_err"]) for r in sub])
        zs = np.array([float(r["z_sd_within"]) for r in sub])
        sd = off.std(ddof=1) if off.size > 1 else float("nan")
        out.append(
            f"| {stem} | {style} | {colour_model} | {len(sub)} | {off.mean():+.3f} | {sd:.3f} "
            f"| {np.sqrt(np.mean(off**2)):.3f} | {dep.std(ddof=1) if dep.size > 1 else float('nan'):.4f} "
            f"| {np.median(zs):.2f} |"
        )
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--stems", nargs="+", default=["twig", "grass"])
    ap.add_argument("--style", default=STYLES[0], choices=STYLES)
    ap.add_argument("--colour-model", default=COLOUR_MODELS[0], choices=COLOUR_CHOICES)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    csv_path = a.out / "width_error_study.csv"
    jobs = [(s, seed, a.style, a.colour_model) for seed in range(a.reps) for s in a.stems]

    def done_key(r):
        return r["stem"], int(r["seed"]), r["style"], r["colour_model"]

    for row in run_pending(csv_path, FIELDS, jobs, one, done_key=done_key, workers=a.workers):
        print(row["stem"], row["seed"], f"offset {row['offset_px']:+.3f} px", f"depth {row['depth_rel_err']:+.4f}")
    (a.out / "width_error_study.md").write_text(table(read_rows(csv_path)))
    print(table(read_rows(csv_path)))


if __name__ == "__main__":
    main()

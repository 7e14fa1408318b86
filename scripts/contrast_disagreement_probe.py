"""How far the contrast fit's two variants disagree on a rendered push, against the push's base error (issue 22;
docs/validation.md, "Session 62", "Session 63").

    python scripts/contrast_disagreement_probe.py STEM BASE_DIAMETER_M|- FIRST-LAST

``bayesrod.vision.width.contrast_fit`` reads the contrast from the widest profiles alone, and adds up to
``THIN_N`` thin ones when the blur is over ``BLUR_RATIO_OK`` of their width. Here every contrast fit of every
frame computes both and records |log| of the ratio of their scales at any ratio (the library's own fit is
returned, so the extraction and the sd it declares are the library's; since session 63 that sd holds the
spread from ``VARIANT_RATIO_FROM`` up: the rows of docs/results/contrast_disagreement_session6{2,3}.jsonl
predate it). One JSON row per seed (``scripts/_study.extracted_push``: the preset's middle height,
exact widths; ``-`` for the preset's diameter): the median relative error of the stations below s/L 0.3 [%], the
scale sd the extraction declared [%], and the median disagreement over all fits and over each frame's second
(final) fit [%], the median of the final fits' signed log ratio (thin over wide) [%], the sd over frames of the
log of each frame's scale (its two fits' scales multiplied) [%], and the median blur over width the wide
profiles alone read (the ratio the switch tests) over all fits and over the final ones; ``fits`` lists each
fit's (ratio, signed log ratio [%], the returned scale; before session 64 only the first two, the ratio
unsigned). About 20-40 s a seed on one core.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from _study import extracted_push

import bayesrod.vision.width as W

SHIFT: list[float] = []  # each fit's log of the thin fit's scale over the wide one's (its size: the disagreement)
SCALE: list[float] = []  # the scale the library's fit returned
RATIO: list[float] = []  # each fit's blur over the wide profiles' width, from the wide profiles alone
_box_fit = W._box_fit
_contrast_fit = W.contrast_fit  # the library's, which the extraction keeps using


def contrast_fit_both(profiles, s, n_max=W.AREA_N_MAX, *, loss="soft_l1", f_scale=0.1):
    """``contrast_fit`` as shipped (the library's own answer is returned), recording the blur ratio of the wide
    profiles alone and how far the fit with the thin profiles lands from the one without, at every ratio (the
    library reads the second fit only from ``VARIANT_RATIO_FROM`` up)."""
    trend, wide, thin = W.contrast_profiles(profiles, s, n_max)
    if len(wide) < 5:
        return W.ContrastFit()
    fit = _box_fit(profiles, trend, wide, loss, f_scale)
    alt = _box_fit(profiles, trend, wide + thin, loss, f_scale, len(wide)) if thin else fit
    SHIFT.append(float(np.log(alt.scale / fit.scale)))
    RATIO.append(fit.blur_px / fit.width_px if fit.width_px > 0 else float("nan"))
    out = _contrast_fit(profiles, s, n_max, loss=loss, f_scale=f_scale)
    SCALE.append(out.scale)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stem", choices=("twig", "grass"))
    ap.add_argument("base_diameter_m", help="the drawn base diameter [m], or - for the preset's")
    ap.add_argument("seeds", help="FIRST-LAST")
    a = ap.parse_args(argv)
    overrides = {} if a.base_diameter_m == "-" else {"base_diameter_m": float(a.base_diameter_m)}
    first, last = (int(x) for x in a.seeds.split("-"))
    W.contrast_fit = contrast_fit_both
    for seed in range(first, last + 1):
        SHIFT.clear()
        SCALE.clear()
        RATIO.clear()
        with tempfile.TemporaryDirectory() as tmp:
            ex, drawn, _ = extracted_push(a.stem, seed, False, Path(tmp), overrides=overrides)
        d = ex.diameters
        ok = np.isfinite(d.d_m) & (d.s_m < 0.3 * ex.dataset.length_m) & (d.flag == "ok")
        row = {"stem": a.stem, "base_diameter_m": overrides.get("base_diameter_m"), "seed": seed}
        row["rel_pct"] = round(100 * float(np.median(d.d_m[ok] / drawn[ok] - 1)), 2)
        row["declared_pct"] = round(100 * d.shared_scale_sd, 2)
        gap = np.abs(SHIFT)
        row["disagree_median_pct"] = round(100 * float(np.median(gap)), 2)
        row["disagree_final_fits_median_pct"] = round(100 * float(np.median(gap[1::2] if gap.size > 1 else gap)), 2)
        row["shift_final_fits_median_pct"] = round(100 * float(np.median(SHIFT[1::2] or SHIFT)), 2)
        row["wide_ratio_median"] = round(float(np.nanmedian(RATIO)), 3)
        row["wide_ratio_final_fits_median"] = round(float(np.nanmedian(RATIO[1::2] or RATIO)), 3)
        k = np.log(SCALE)
        # each frame's scale: its first fit's times its second's (the second reads the colour the first made pure)
        row["frame_scale_sd_pct"] = round(100 * float(np.std(k[0::2] + k[1::2] if k.size % 2 == 0 else k)), 2)
        row["fits"] = [
            [round(r, 4), round(100 * g, 3), round(k, 5)] for r, g, k in zip(RATIO, SHIFT, SCALE, strict=True)
        ]
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()

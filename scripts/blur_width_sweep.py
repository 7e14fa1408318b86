"""Blur against width: how the lens's blur moves the widths of thin stems (issue 22).

    python scripts/blur_width_sweep.py [--widths 3.27 5] [--blurs 0.6 0.8 1.0 1.2] [--seeds 0 1 2]
        [--styles flat shaded]

The synthetic stem of the width tests (``bayesrod.vision.render.synthetic_stem_frame``: a gently curved
stem of base width w0 px tapering with p 1.6 on a flat background, noise 3 levels; ``shaded``: its colour
falls to 55% at the limbs) blurred by a Gaussian lens of each sd, then by other lenses on every width: a
Gaussian of sd 1.2 cut to a 7 x 7 kernel (the renderer's shaded frames), disks of radius 1.5 and 2 px
(defocus), a 3 x 3 box. The colour model as ``bayesrod extract`` chooses it
(``bayesrod.vision.width.choose_colour_model``), then ``width_profile`` on each seed. Prints per case the
stations' median relative error against the drawn width (mean over seeds), the contrast fit's blur over
the profiles' width (``WidthProfile.blur_over_width``, median over seeds) and the scale error sd the
extraction then declares for blur, lens and the contrast fit's variants (``contrast_fit_scale_sd``; the
resolution term left out); last, the rms of the
errors over the declared sd and the share within 1.645 sd. About three seconds per image.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from bayesrod.vision.render import SYNTHETIC_CAMERA, synthetic_stem_frame
from bayesrod.vision.width import BLUR_RATIO_OK, choose_colour_model, contrast_fit_scale_sd, width_profile


def _disk(r: float) -> np.ndarray:
    """An anti-aliased disk kernel of radius r [px] (8 x 8 supersampling), normalised."""
    n = 2 * int(np.ceil(r)) + 1
    yy, xx = np.mgrid[:n, :n] - n // 2
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    acc = sum((np.hypot(xx + a, yy + b) <= r).astype(float) for a in sub for b in sub)
    return acc / acc.sum()


def case(w0: float, seeds, lens, shaded: bool) -> tuple[float, float, float, float, str]:
    """(mean stations' median relative error, median blur / width, median share of fitted stations, median
    spread of the contrast fit's variants, the models chosen) over ``seeds``."""
    errors, ratios, shares, spreads, models = [], [], [], [], set()
    for seed in seeds:
        if isinstance(lens, float):
            img, line, truth = synthetic_stem_frame(w0, 1.6, 3.0, seed, blur=lens, shaded=shaded)
        else:  # another lens: the synthetic's own 0.6-px blur is replaced by it
            img, line, truth = synthetic_stem_frame(w0, 1.6, 3.0, seed, blur=1e-3, shaded=shaded)
            img = lens(img)
        model = choose_colour_model(img, None, line, SYNTHETIC_CAMERA).model
        wp = width_profile(img, None, line, SYNTHETIC_CAMERA, colour_model=model)
        ok = wp.flag == "ok"
        errors.append(np.median(wp.width_px[ok] / truth(wp.s_m[ok]) - 1.0))
        ratios.append(wp.blur_over_width)
        shares.append(wp.borrowed_share)
        spreads.append(wp.contrast_variant_spread)
        models.add(model)
    med = [float(np.median(x)) for x in (ratios, shares, spreads)]
    return float(np.mean(errors)), *med, "/".join(sorted(models))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--widths", type=float, nargs="+", default=[3.27, 5.0])
    ap.add_argument("--blurs", type=float, nargs="+", default=[0.6, 0.8, 1.0, 1.2])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--styles", nargs="+", default=["flat", "shaded"], choices=["flat", "shaded"])
    a = ap.parse_args(argv)
    print("| base width [px] | stem | lens | colour model | stations' median error | blur / width | declared sd |")
    print("|---|---|---|---|---|---|---|")
    others = {
        "Gaussian sd 1.2, 7 x 7 kernel": lambda im: cv2.GaussianBlur(im, (7, 7), 1.2),
        "disk of radius 1.5 px": lambda im: cv2.filter2D(im, -1, _disk(1.5)),
        "disk of radius 2 px": lambda im: cv2.filter2D(im, -1, _disk(2.0)),
        "box 3 x 3": lambda im: cv2.blur(im, (3, 3)),
    }
    rows = [(w, f"Gaussian sd {b:g}", b) for w in a.widths for b in a.blurs]
    rows += [(w, name, fn) for w in a.widths for name, fn in others.items()]
    cases = []  # (error, declared sd, ratio)
    for style in a.styles:
        for w, name, lens in rows:
            err, ratio, share, spread, model = case(w, a.seeds, lens, style == "shaded")
            sd = contrast_fit_scale_sd(ratio, share, spread)
            print(
                f"| {w:g} | {style} | {name} | {model} | {100 * err:+.2f}% | {ratio:.2f} | {100 * sd:.1f}% |",
                flush=True,
            )
            cases.append((err, sd, ratio))
    e, sd, r = np.array(cases).T
    z = e / np.maximum(sd, 1e-12)
    print(
        f"\n{len(cases)} cases: errors rms {100 * float(np.sqrt(np.mean(e**2))):.2f}%; error / declared sd rms "
        f"{float(np.sqrt(np.mean(z**2))):.2f}, within 1.645 in {float(np.mean(np.abs(z) < 1.645)):.2f} "
        f"({int(np.sum(r > BLUR_RATIO_OK))} above blur / width {BLUR_RATIO_OK})"
    )


if __name__ == "__main__":
    main()

"""Blur against width: how the lens's blur moves the widths of thin stems (issue 22).

    python scripts/blur_width_sweep.py [--widths 3.27 5 8] [--blurs 0.6 0.8 1.0 1.2] [--seeds 0 1 2]

The synthetic stem of the width tests (``bayesrod.vision.render.synthetic_stem_frame``: a gently curved
stem of base width w0 px tapering with p 1.6 on a flat background, noise 3 levels) blurred by a Gaussian
lens of each sd, then a disk of radius 1.5 px and a 3 x 3 box on the first width;
``bayesrod.vision.width.width_profile`` on each seed. Prints per case the stations' median relative error
against the drawn width (mean over seeds), the contrast fit's blur over the profiles' width
(``WidthProfile.blur_over_width``, median over seeds) and the scale error sd the extraction then declares
(``blur_scale_sd``). About a second per image.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from bayesrod.vision.render import SYNTHETIC_CAMERA, synthetic_stem_frame
from bayesrod.vision.width import blur_scale_sd, width_profile


def _disk(r: float) -> np.ndarray:
    """An anti-aliased disk kernel of radius r [px] (8 x 8 supersampling), normalised."""
    n = 2 * int(np.ceil(r)) + 1
    yy, xx = np.mgrid[:n, :n] - n // 2
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    acc = sum((np.hypot(xx + a, yy + b) <= r).astype(float) for a in sub for b in sub)
    return acc / acc.sum()


def case(w0: float, seeds, lens) -> tuple[float, float]:
    """(mean stations' median relative error, median blur / width) over ``seeds``."""
    errors, ratios = [], []
    for seed in seeds:
        if isinstance(lens, float):
            img, line, truth = synthetic_stem_frame(w0, 1.6, 3.0, seed, blur=lens)
        else:  # another lens: the synthetic's own 0.6-px blur is replaced by it
            img, line, truth = synthetic_stem_frame(w0, 1.6, 3.0, seed, blur=1e-3)
            img = lens(img)
        wp = width_profile(img, None, line, SYNTHETIC_CAMERA)
        ok = wp.flag == "ok"
        errors.append(np.median(wp.width_px[ok] / truth(wp.s_m[ok]) - 1.0))
        ratios.append(wp.blur_over_width)
    return float(np.mean(errors)), float(np.median(ratios))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--widths", type=float, nargs="+", default=[3.27, 5.0, 8.0])
    ap.add_argument("--blurs", type=float, nargs="+", default=[0.6, 0.8, 1.0, 1.2])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    a = ap.parse_args(argv)
    print("| base width [px] | lens | stations' median error | blur / width | declared scale sd |")
    print("|---|---|---|---|---|")
    others = {
        "disk of radius 1.5 px": lambda im: cv2.filter2D(im, -1, _disk(1.5)),
        "box 3 x 3": lambda im: cv2.blur(im, (3, 3)),
    }
    rows = [(w, f"Gaussian sd {b:g}", b) for w in a.widths for b in a.blurs]
    rows += [(a.widths[0], name, fn) for name, fn in others.items()]
    for w, name, lens in rows:
        err, ratio = case(w, a.seeds, lens)
        print(f"| {w:g} | {name} | {100 * err:+.2f}% | {ratio:.2f} | {100 * blur_scale_sd(ratio):.1f}% |", flush=True)


if __name__ == "__main__":
    main()

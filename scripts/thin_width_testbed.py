"""The width tests' synthetic stem as a fast testbed for the thin-stem width bias (issue 22; docs/validation.md,
"Session 62").

    python scripts/thin_width_testbed.py [--tapers 0.43,1.6] [--widths 2.0,2.3,2.6,2.9,3.3,4.0,4.8,6.0]
        [--noise 0,3] [--seeds 4] [--true-colour]

Draws ``bayesrod.vision.render.synthetic_stem_frame(w0, p, noise, seed)`` (a gently curved stem, the renderer's
3 x 3 blur at 0.6 px, exact coverage) and reads it with ``bayesrod.vision.width.width_profile``. Prints, per
taper, base width and pixel noise, the median relative error of the ok stations below s = 0.14 m (s/L 0.3) over
the seeds (one seed when the noise is 0: the frame is then the same for every seed), the contrast fit's blur over
width, the scale error's sd the frame declares for the contrast fit and the resolution (``contrast_fit_scale_sd``
and ``thin_scale_sd`` in quadrature; an extraction adds the depth's and the frames' scatter), and the scale each of
the frame's contrast fits returned (the first on the picked colour, the second after the colour was made pure with
the first's scale). ``--true-colour`` hands the width measurement the drawn stem colour instead of the picked
pixel, so the contrast fit starts from the truth (a scale of 1 is then right). ``--psf-uniforms N`` has the
contrast fit model the point spread as its Gaussian convolved with N unit boxes (1: the pixel's area; 3: that and
the triangle of the profiles' bilinear sampling) instead of the Gaussian alone (docs/validation.md, "Session 64").
About 0.2 s a frame (several times that with ``--psf-uniforms``).
"""

from __future__ import annotations

import argparse

import numpy as np

import bayesrod.vision.width as W
from bayesrod.vision.render import STEM_RGB, SYNTHETIC_CAMERA, synthetic_stem_frame


def read(w0: float, p: float, noise: float, seed: int, true_colour: bool) -> tuple[float, float, list, float]:
    """(median relative error below s/L 0.3 [%], blur over width, the contrast fits' scales, the scale sd the
    contrast fit and the resolution declare [%]) of one frame."""
    scales: list[float] = []
    contrast_fit, purest = W.contrast_fit, W._purest_pixel

    def logged(*a, **k):
        fit = contrast_fit(*a, **k)
        scales.append(round(fit.scale, 4))
        return fit

    def drawn_colour(*a):
        pick = purest(*a)
        return None if pick is None else (np.asarray(STEM_RGB, float), pick[1])

    W.contrast_fit = logged
    if true_colour:
        W._purest_pixel = drawn_colour
    try:
        img, line, truth = synthetic_stem_frame(w0, p, noise, seed)
        wp = W.width_profile(img, None, line, SYNTHETIC_CAMERA)
    finally:
        W.contrast_fit, W._purest_pixel = contrast_fit, purest
    ok = wp.flag == "ok"
    low = ok & (wp.s_m < 0.14)
    declared = W.frame_scale_sd(wp)
    err = 100 * float(np.median(wp.width_px[low] / truth(wp.s_m[low]) - 1))
    return err, wp.blur_over_width, scales, 100 * float(declared)


def boxed_psf(n_boxes: int, per_box: int = 8):
    """A stand-in for ``bayesrod.vision.width._blurred_box``: the box seen through the Gaussian convolved with
    ``n_boxes`` unit boxes (midpoint rule, ``per_box`` nodes a box)."""
    from scipy.special import ndtr

    u = (np.arange(per_box) + 0.5) / per_box - 0.5
    pts = np.zeros(1)
    for _ in range(n_boxes):
        pts = (pts[:, None] + u[None, :]).ravel()
    off, count = np.unique(np.round(pts, 9), return_counts=True)
    wt = count / count.sum()

    def blurred_box(t, w, sigma):
        t = np.asarray(t, float)[..., None] - off
        w = np.asarray(w, float)[..., None]
        return np.sum((ndtr((t + w / 2) / sigma) - ndtr((t - w / 2) / sigma)) * wt, axis=-1)

    return blurred_box


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tapers", default="0.43,1.6")
    ap.add_argument("--widths", default="2.0,2.3,2.6,2.9,3.3,4.0,4.8,6.0")
    ap.add_argument("--noise", default="0,3")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--true-colour", action="store_true")
    ap.add_argument("--psf-uniforms", type=int, default=0)
    a = ap.parse_args(argv)
    if a.psf_uniforms > 0:
        W._blurred_box = boxed_psf(a.psf_uniforms)
    print(
        "| taper p | base width [px] | pixel noise | error below s/L 0.3: mean [%] | sd over seeds | blur / width |"
        " declared scale sd [%] | scales of the two fits (first seed) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for p in (float(x) for x in a.tapers.split(",")):
        for w0 in (float(x) for x in a.widths.split(",")):
            for noise in (float(x) for x in a.noise.split(",")):
                rows = [read(w0, p, noise, s, a.true_colour) for s in range(1 if noise == 0 else a.seeds)]
                err = np.array([r[0] for r in rows])
                print(
                    f"| {p:g} | {w0:g} | {noise:g} | {err.mean():+.2f} | {err.std():.2f} | "
                    f"{np.mean([r[1] for r in rows]):.3f} | {np.mean([r[3] for r in rows]):.2f} | {rows[0][2]} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()

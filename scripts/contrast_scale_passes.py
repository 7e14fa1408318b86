"""Does the contrast scale read what the frames need, in both passes of width_profile? (issue 22)

    python scripts/contrast_scale_passes.py --stem grass --seed 40

Simulates and extracts one push as scripts/diameter_study.py does (``_study.extracted_push``), recording
every call of ``bayesrod.vision.width.contrast_scale``: per frame the first pass (coverage against the
picked, blur-mixed stem colour) and the second (against the pure colour extrapolated from it). For each
pass it prints the scale read and the scale the frame needs: the median, over its clean stations 2 px or
wider, of the coverage integral over the drawn width (and the slope of a straight line through them, which
an offset in the integrals does not move). The final widths are divided by the second pass's scale, so
second scale / need below 1 reads every narrow station that much too wide. Then the same ratio with the
fit's robust loss replaced (linear, soft L1 at two scales, Cauchy), to tell the loss from the shape model.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from _study import extracted_push

from bayesrod.physics import stem_diameter
from bayesrod.vision import width as W


def need(s: np.ndarray, profiles: list, truth: dict, L: float, px: float) -> tuple[float, float]:
    """(median coverage integral / drawn width, slope of integral on drawn width) at clean stations >= 2 px."""
    area = W._coverage_integrals(profiles)
    drawn = stem_diameter(s, truth["base_diameter_m"], truth["diameter_taper"], L) / px
    clean, _ = W._clean_profiles(profiles, s)
    use = clean & (drawn >= 2.0)
    if use.sum() < 4:
        return float("nan"), float("nan")
    return float(np.median(area[use] / drawn[use])), float(np.polyfit(drawn[use], area[use], 1)[0])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stem", default="grass")
    ap.add_argument("--seed", type=int, default=40)
    a = ap.parse_args(argv)
    calls: list[list] = []
    real_scale, real_profile = W.contrast_scale, W.width_profile

    def scale(profiles, s, *args, **kwargs):
        r = real_scale(profiles, s, *args, **kwargs)
        calls[-1].append((np.array(s), [(t.copy(), x.copy()) for t, x in profiles], r))
        return r

    def profile(*args, **kwargs):
        calls.append([])
        return real_profile(*args, **kwargs)

    W.contrast_scale, W.width_profile = scale, profile
    try:
        with tempfile.TemporaryDirectory() as tmp:
            ex, _, px = extracted_push(a.stem, a.seed, False, Path(tmp))
    finally:
        W.contrast_scale, W.width_profile = real_scale, real_profile
    truth, L = ex.source.extra["truth"], ex.dataset.length_m
    frames = [c for c in calls if len(c) == 2]  # frames whose narrow stations were measured again (both passes)
    rows = []
    for c in frames:
        (s1, p1, r1), (s2, p2, r2) = c
        rows.append((r1, *need(s1, p1, truth, L, px), r2, *need(s2, p2, truth, L, px)))
    R = np.array(rows)
    print(f"{a.stem} seed {a.seed}: {len(frames)} frames with both passes; medians over frames:")
    med = np.nanmedian(R, axis=0)
    print(f"  first pass: scale {med[0]:.3f}, need {med[1]:.3f} (slope {med[2]:.3f})")
    print(f"  second pass: scale {med[3]:.3f}, need {med[4]:.3f} (slope {med[5]:.3f})")
    print(f"  second scale / need: {np.nanmedian(R[:, 3] / R[:, 4]):.4f}")
    for loss, f_scale in (("soft_l1", 0.1), ("linear", 1.0), ("soft_l1", 0.3), ("cauchy", 0.1)):
        ratio = [
            real_scale(c[1][1], c[1][0], loss=loss, f_scale=f_scale) / r[4] for c, r in zip(frames, rows, strict=True)
        ]
        print(f"  loss {loss} (f_scale {f_scale}): second scale / need {np.nanmedian(ratio):.4f}")


if __name__ == "__main__":
    main()

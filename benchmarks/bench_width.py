"""What reading the contrast fit's two variants near the switch costs a frame's width profile (issue 22).

    python benchmarks/bench_width.py [--rounds 5]

``bayesrod.vision.width.contrast_fit`` reads the wide profiles, and from a blur of ``VARIANT_RATIO_FROM``
(0.2) of their width on also the fit with the thin profiles added, to declare how far the two land apart
(session 63; before, the second fit ran only above ``BLUR_RATIO_OK``, 0.3). Times ``width_profile`` on the
width tests' synthetic stems (``synthetic_stem_frame``, noise 3) of the twig's taper 2.9 and 4.8 px wide and the
steep taper 3.3 px wide, as shipped and with ``VARIANT_RATIO_FROM`` set to ``BLUR_RATIO_OK`` (the reference: the
second fit only where it is the one returned), interleaved in the same process, and prints the medians and their
ratio per stem.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bayesrod.vision.width as W
from bayesrod.vision.render import SYNTHETIC_CAMERA, synthetic_stem_frame

STEMS = ((0.43, 2.9), (0.43, 4.8), (1.6, 3.3))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)
    shipped = W.VARIANT_RATIO_FROM
    for p, w0 in STEMS:
        img, line, _ = synthetic_stem_frame(w0, p, 3.0, seed=0)
        times: dict[str, list[float]] = {"shipped": [], "reference": []}
        for _ in range(a.rounds):
            for name, start in (("shipped", shipped), ("reference", W.BLUR_RATIO_OK)):
                W.VARIANT_RATIO_FROM = start
                try:
                    t0 = time.perf_counter()
                    wp = W.width_profile(img, None, line, SYNTHETIC_CAMERA)
                    times[name].append(time.perf_counter() - t0)
                finally:
                    W.VARIANT_RATIO_FROM = shipped
        med = {k: float(np.median(v)) for k, v in times.items()}
        print(
            f"p {p}, {w0} px (blur / width {wp.blur_over_width:.3f}): shipped {1000 * med['shipped']:.0f} ms, "
            f"reference {1000 * med['reference']:.0f} ms, ratio x{med['shipped'] / med['reference']:.2f} "
            f"(medians of {a.rounds})"
        )


if __name__ == "__main__":
    main()

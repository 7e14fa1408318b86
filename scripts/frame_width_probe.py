"""Each frame's share of one rendered push's diameter profile (issue 22): which frames pull the median.

    python scripts/frame_width_probe.py grass 115 [--style shaded]

Renders and extracts one push as ``scripts/diameter_study.py`` does (``_study.extracted_push``), keeps the
per-frame width profiles ``bayesrod.extract`` combines (``vision.width.combine_profiles``), and prints per frame
its contrast scale, the contrast fit's blur / width, the share of its ok stations that took their width from
the contrast fit, how many stations it read ok and the median of its widths over the drawn diameter at its
first 30 ok stations (the base, where d0 is read); then the combined profile's. Reads only; writes nothing.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from _study import extracted_push

import bayesrod.vision.width as width


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stem", help="preset: twig, grass")
    ap.add_argument("seed", type=int)
    ap.add_argument("--style", default="flat", choices=("flat", "shaded"))
    args = ap.parse_args(argv)
    seen = {}
    combine = width.combine_profiles

    def spy(profiles, stations, **kw):  # bayesrod.extract imports combine_profiles when called: this one
        seen["profiles"], seen["stations"] = profiles, stations
        return combine(profiles, stations, **kw)

    width.combine_profiles = spy
    try:
        with tempfile.TemporaryDirectory() as tmp:
            ex, drawn, _ = extracted_push(args.stem, args.seed, False, Path(tmp), args.style)
    finally:
        width.combine_profiles = combine
    dp = ex.diameters
    print(
        f"d0 drawn {ex.source.extra['truth']['base_diameter_m']:.5f} m; contrast scale over frames "
        f"{ex.doc['diameters']['contrast_scale']}; shared scale sd {dp.shared_scale_sd:.4f}"
    )
    print("frame  scale  blur/width  fitted share  ok stations  width / drawn (first 30 ok)")
    for j, wp in enumerate(seen["profiles"]):
        good = wp.flag == "ok"
        at = np.searchsorted(seen["stations"], wp.s_m[good])
        rel = float(np.median(wp.width_m[good][:30] / drawn[at][:30])) if good.any() else np.nan
        print(
            f"{j:5d}  {wp.contrast_scale:5.3f}  {wp.blur_over_width:10.2f}  {wp.borrowed_share:12.2f}  "
            f"{int(good.sum()):11d}  {rel:.3f}"
        )
    ok = dp.ok
    z = (dp.d_m[ok] - drawn[ok]) / dp.sd_m[ok]
    print(
        f"combined: width / drawn (first 30 ok) {np.median(dp.d_m[ok][:30] / drawn[ok][:30]):.3f}; "
        f"stations' z sd {np.std(z):.2f}"
    )


if __name__ == "__main__":
    main()

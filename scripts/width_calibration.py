"""The diameter profile's stations against the drawn diameter, without any fit (issue 22).

    python scripts/width_calibration.py --stems twig,grass --seeds 200-209 [--frames 4] [--sensor-noise 8]
        [--base-diameter-m 0.0025] [--out rows.jsonl]

Per stem and seed: ``bayesrod simulate`` one push at the preset's middle height with frames drawn at each
pixel's exact coverage (``exact_width``), then ``bayesrod.extract``. Printed per push, one JSON row:

- ``zsd``, ``cover``: the sd of (measured - drawn) / sd over the ok stations, and the share within 1.645 sd
  (1 and 0.90 when the stations' sds are calibrated); ``zsd_base`` and ``zsd_up`` the same below and above
  s/L = 0.3;
- ``median_abs_err_px``: the stations' median absolute error [px];
- ``rel_base``: the median relative error of the stations below s/L = 0.3 (the error d0 inherits), with the
  profile's declared ``shared_scale_sd``, its ``base_width_px`` and whether extract warned;
- ``thin_width_px``: the 5th percentile of the ok stations' widths [px] and ``blur_over_width`` the contrast
  fit's blur over the width of the profiles it read (how well the frames pin the blur).

Options change the case: ``--frames`` the frames before the slip (default 20), ``--sensor-noise`` each
frame's fresh pixel noise (grey levels; default 3), ``--base-diameter-m`` the drawn base diameter (default
1 cm for a twig, 4 mm for a grass: 4.8 and 3.3 px). About 10-20 s per push on one core.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from _study import extracted_push, seeds


def one(stem: str, seed: int, frames: int | None, sensor_noise: float | None, d0: float | None) -> dict:
    t0 = time.perf_counter()
    given = {"n_frames_engaged": frames, "sensor_noise": sensor_noise, "base_diameter_m": d0}
    with tempfile.TemporaryDirectory() as tmp:
        ex, drawn, px = extracted_push(
            stem, seed, False, Path(tmp), overrides={k: v for k, v in given.items() if v is not None}
        )
    ds, dp = ex.dataset, ex.diameters
    ok = dp.ok
    z = (dp.d_m[ok] - drawn[ok]) / dp.sd_m[ok]
    lo = dp.s_m[ok] / ds.length_m < 0.3
    rel = dp.d_m[ok] / drawn[ok] - 1

    def sd(x):
        return float(np.std(x)) if x.size > 3 else float("nan")

    return {
        "stem": stem,
        "seed": seed,
        "d0_px": round(ex.source.extra["truth"]["base_diameter_m"] / px, 3),
        "stations_ok": int(ok.sum()),
        "zsd": sd(z),
        "cover": float(np.mean(np.abs(z) < 1.645)) if z.size else float("nan"),
        "zsd_base": sd(z[lo]),
        "zsd_up": sd(z[~lo]),
        "median_abs_err_px": float(np.median(np.abs(dp.d_m[ok] - drawn[ok])) / px) if ok.any() else float("nan"),
        "rel_base": float(np.median(rel[lo])) if lo.any() else float("nan"),
        "shared_scale_sd": dp.shared_scale_sd,
        "base_width_px": dp.base_width_px,
        # the thin end of the measured stations [px] and the blur's share of the profiles' width: how well the
        # frames pin the blur (issue 22, the twig near 3 px)
        "thin_width_px": float(np.percentile(dp.d_m[ok], 5) / px) if ok.any() else float("nan"),
        "blur_over_width": dp.blur_over_width,
        "warned": "warning" in ex.doc.get("diameters", {}),
        "frames": int(np.median(dp.n_frames[ok])) if ok.any() else 0,
        "seconds": round(time.perf_counter() - t0, 1),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stems", default="twig,grass")
    ap.add_argument("--seeds", default="200-209", help="200-209 or 1,5,7")
    ap.add_argument("--frames", type=int, help="frames before the slip (default: the simulator's 20)")
    ap.add_argument("--sensor-noise", type=float, help="fresh pixel noise per frame [grey levels] (default 3)")
    ap.add_argument("--base-diameter-m", type=float, help="the drawn base diameter [m]")
    ap.add_argument("--out", type=Path, help="append the rows to this JSON-lines file")
    args = ap.parse_args(argv)
    for stem in args.stems.split(","):
        for seed in seeds(args.seeds):
            row = one(stem, seed, args.frames, args.sensor_noise, args.base_diameter_m)
            line = json.dumps(row)
            print(line, flush=True)
            if args.out:
                with open(args.out, "a") as f:
                    f.write(line + "\n")


if __name__ == "__main__":
    main()

"""Each frame's share of one rendered push's diameter profile (issue 22): which frames pull the median.

    python scripts/frame_width_probe.py grass 115 [--style shaded] [--bins 10] [--cache DIR]

Renders and extracts one push as ``scripts/diameter_study.py`` does, keeping the per-frame width profiles that
``bayesrod.extract`` combines (``width_taper_check.frames_of``; cached in ``--cache`` when given), and prints per
frame its contrast scale, the contrast fit's blur / width, the share of its ok stations that took their width from
the contrast fit, how many stations it read ok and the median of its widths over the drawn diameter at its first
30 ok stations (the base, where d0 is read); then the combined profile's (``combine_profiles``). ``--bins N``
also prints, per frame and combined, that median in N equal bins of s/L (``-`` where fewer than 3 ok stations).
Writes nothing but the cache.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from width_taper_check import combined, frames_of

from bayesrod.physics import stem_diameter


def _binned(s_m: np.ndarray, rel: np.ndarray, ok: np.ndarray, L: float, n: int) -> str:
    """The median of ``rel`` over the ``ok`` stations in each of ``n`` equal bins of s/L ('-' under 3)."""
    edges = np.linspace(0.0, 1.0, n + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        m = ok & (s_m / L >= a) & (s_m / L < b)
        out.append(f"{np.median(rel[m]):5.2f}" if m.sum() >= 3 else "  -  ")
    return " ".join(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stem", help="preset: twig, grass")
    ap.add_argument("seed", type=int)
    ap.add_argument("--style", default="flat", choices=("flat", "shaded"))
    ap.add_argument("--bins", type=int, default=0, help="also the widths over the drawn in this many bins of s/L")
    ap.add_argument("--cache", type=Path, help="keep the frames' profiles here (default: not kept)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        fr = frames_of(args.stem, args.seed, False, args.cache or Path(tmp), args.style)
    profiles, s_m, L = fr["profiles"], fr["s_m"], fr["L"]
    drawn = np.asarray(stem_diameter(s_m, fr["d0"], fr["q"], L), float)
    scales = [wp.contrast_scale for wp in profiles]
    print(
        f"d0 drawn {fr['d0']:.5f} m; contrast scale over frames median {np.median(scales):.3f}, sd {np.std(scales):.3f}"
    )
    print(
        "frame  scale  blur/width  fitted share  ok stations  width / drawn (first 30 ok)"
        + ("  by s/L" * bool(args.bins))
    )
    for j, wp in enumerate(profiles):
        at = np.searchsorted(s_m, wp.s_m)
        good = wp.flag == "ok"
        rel = wp.width_m / drawn[at]
        base = float(np.median(rel[good][:30])) if good.any() else np.nan
        line = (
            f"{j:5d}  {wp.contrast_scale:5.3f}  {wp.blur_over_width:10.2f}  {wp.borrowed_share:12.2f}  "
            f"{int(good.sum()):11d}  {base:.3f}"
        )
        print(line + (f"  {_binned(wp.s_m, rel, good, L, args.bins)}" if args.bins else ""))
    dp = combined(fr)
    ok = dp.ok
    z = (dp.d_m[ok] - drawn[ok]) / dp.sd_m[ok]
    print(
        f"combined: width / drawn (first 30 ok) {np.median(dp.d_m[ok][:30] / drawn[ok][:30]):.3f}; "
        f"shared scale sd {dp.shared_scale_sd:.4f}; stations' z sd {np.std(z):.2f}"
    )
    if args.bins:
        print(f"combined by s/L: {_binned(dp.s_m, dp.d_m / drawn, ok, L, args.bins)}")


if __name__ == "__main__":
    main()

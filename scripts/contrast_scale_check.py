"""Spread of the per-frame contrast scale on the grass (issue 22: why the grass's E is not calibrated).

    python scripts/contrast_scale_check.py [--seeds 1 2 0]

Per seed: the grass preset's middle height, 22 frames drawn with exact widths (as scripts/diameter_study.py
draws them), ``bayesrod.extract``; prints the median and sd over frames of the contrast scale
(``extract_report.json`` ``diameters.contrast_scale``) and the profile's median relative error against the
drawn diameter, overall and over the base and tip thirds of its ok stations. About 2 minutes per seed.

    python scripts/contrast_scale_check.py --seeds 5 --fixture tests/data/grass_profiles_seed5.npz

also writes, for the first seed, the coverage profiles ``contrast_scale`` was given in every 7th frame, with
their stations and the drawn widths in pixels: the fixture of tests/test_width.py's check on rendered grass.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.simulate import SimConfig
from bayesrod.physics import stem_diameter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 0])
    ap.add_argument("--stem", default="grass")
    ap.add_argument("--fixture", type=Path, default=None, help="write the first seed's profiles here (.npz)")
    a = ap.parse_args()
    captured = _capture() if a.fixture else None
    for seed in a.seeds:
        cfg = SimConfig.from_preset(a.stem, seed=seed)
        h = cfg.heights_m[len(cfg.heights_m) // 2]
        sim = bayesrod.simulate(a.stem, seed=seed, heights_m=[h], config_overrides={"exact_width": True})
        with tempfile.TemporaryDirectory() as tmp:
            sim.save(Path(tmp) / "raw", frames=True)
            ex = bayesrod.extract(Path(tmp) / "raw", progress=False)
        truth, dp, L = ex.source.extra["truth"], ex.diameters, ex.dataset.length_m
        ok = dp.ok
        rel = dp.d_m[ok] / stem_diameter(dp.s_m[ok], truth["base_diameter_m"], truth["diameter_taper"], L) - 1
        third = ok.sum() // 3
        cs = ex.doc["diameters"]["contrast_scale"]
        print(
            f"seed {seed}: contrast scale median {cs['median']:.3f} sd {cs['sd']:.3f} over "
            f"{ex.doc['diameters']['frames']} frames; profile error median {np.median(rel):+.3f}, "
            f"base third {np.median(rel[:third]):+.3f}, tip third {np.median(rel[-third:]):+.3f}",
            flush=True,
        )
        if captured is not None and seed == a.seeds[0]:
            _write_fixture(a.fixture, captured, ex, truth)


def _capture() -> list:
    """Record the arguments of every ``contrast_scale`` call of ``width_profile`` (one per frame)."""
    from bayesrod.vision import width

    calls, real = [], width.contrast_scale

    def spy(profiles, s, *args, **kwargs):
        calls.append((profiles, np.asarray(s, float)))
        return real(profiles, s, *args, **kwargs)

    width.contrast_scale = spy
    return calls


def _write_fixture(path: Path, calls: list, ex, truth: dict) -> None:
    """Every 7th frame's profiles: t, a, s of each, the frame each belongs to and the drawn width [px]."""
    from bayesrod.api.extract import _camera_dict

    cam = _camera_dict(ex.source)  # pixels per metre at the push's plane (the stem is near-vertical: fx ~ fy)
    plane = next(iter(ex.doc["pushes"].values()))["plane_depth_m"]
    px_per_m = float(np.sqrt(cam["fx"] * cam["fy"])) / float(plane)
    L = ex.dataset.length_m
    rows = {"t": [], "a": [], "s": [], "frame": [], "true_px": []}
    for f, (profiles, s) in enumerate(calls[::7]):
        true_px = stem_diameter(s, truth["base_diameter_m"], truth["diameter_taper"], L) * px_per_m
        for (t, a), si, wi in zip(profiles, s, true_px, strict=True):
            rows["t"].append(t)
            rows["a"].append(a)
            rows["s"].append(si)
            rows["frame"].append(f)
            rows["true_px"].append(wi)
    n = np.array([t.size for t in rows["t"]])
    np.savez_compressed(
        path,
        t=np.concatenate(rows["t"]),
        a=np.concatenate(rows["a"]),
        size=n,
        s=np.array(rows["s"]),
        frame=np.array(rows["frame"]),
        true_px=np.array(rows["true_px"]),
    )
    print(f"wrote {path}: {len(calls[::7])} frames, {n.size} profiles")


if __name__ == "__main__":
    main()

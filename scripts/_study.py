"""What the study scripts share: skip the jobs whose rows are already in the results CSV, run the rest in a
process pool and append each row as it finishes (an interrupted study resumes); simulate and extract one
rendered push of a stem with its drawn diameter profile (the width studies); the calibration statistics of the
SBC scripts' tables (:func:`calibration_stats`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from bayesrod.dataset.io import append_rows, read_rows

#: p - q of the width studies' graded stems: a diameter taper 0.15 below the bending taper
GRADIENT = 0.15


def run_pending(
    csv_path: Path, fields: list[str], jobs: Iterable[tuple], fn: Callable, *, done_key: Callable, workers: int = 1
) -> Iterator[dict]:
    """Rows of ``fn(job)`` for the ``jobs`` not yet in ``csv_path`` (``done_key(row)`` gives a written row's
    job), appended to it as they arrive. A CSV written before columns were added gains them (its rows
    keep empty cells: ``append_rows``); one of other columns is refused, not appended to."""
    old = read_rows(csv_path)
    if old and not set(old[0]) <= set(fields):
        raise SystemExit(f"{csv_path}: columns {', '.join(old[0])}, expected {', '.join(fields)}: use another --out")
    done = {done_key(r) for r in old}
    todo = [j for j in jobs if j not in done]
    new_file = not Path(csv_path).exists()
    with ProcessPoolExecutor(workers) as pool:
        yield from append_rows(csv_path, fields, pool.map(fn, todo), new_file=new_file)


def seeds(text: str) -> list[int]:
    """'20-31' or '1,4,7' -> list of ints (the width scripts' seed arguments)."""
    if "-" in text:
        a, b = (int(x) for x in text.split("-"))
        return list(range(a, b + 1))
    return [int(x) for x in text.split(",") if x]


def extracted_push(stem: str, seed: int, graded: bool, folder: Path, style: str = "flat", overrides=None):
    """``bayesrod simulate`` one push of preset ``stem`` (its middle contact height; rendered frames with
    exact widths; ``graded``: a diameter taper ``GRADIENT`` below the bending taper; ``style``: the
    renderer's ``render_style``, ``"shaded"`` a limb-darkened stem through a 1.2-px blur; ``overrides``: more
    ``SimConfig`` fields, e.g. ``n_frames_engaged``, ``sensor_noise``, ``base_diameter_m``) into
    ``folder``/raw, then ``bayesrod.extract``. Returns (extraction, the drawn diameter at its stations [m]
    (k,), metres per pixel at the push's plane)."""
    import bayesrod
    from bayesrod.dataset.simulate import SimConfig
    from bayesrod.physics import stem_diameter

    cfg = SimConfig.from_preset(stem, seed=seed)
    h = cfg.heights_m[len(cfg.heights_m) // 2]
    over = {"exact_width": True, "render_style": style, **({"diameter_taper": cfg.p - GRADIENT} if graded else {})}
    over.update(overrides or {})
    bayesrod.simulate(stem, seed=seed, heights_m=[h], config_overrides=over).save(Path(folder) / "raw", frames=True)
    ex = bayesrod.extract(Path(folder) / "raw", progress=False)
    ds, truth = ex.dataset, ex.source.extra["truth"]
    drawn = stem_diameter(ex.diameters.s_m, truth["base_diameter_m"], truth["diameter_taper"], ds.length_m)
    metres_per_px = ex.doc["pushes"][ds.pushes[0].id]["plane_depth_m"] / ds.camera.fx
    return ex, np.asarray(drawn, float), float(metres_per_px)


def calibration_stats(covered, ranks, n_rank: int) -> dict:
    """One row of an SBC table: ``covered`` (n,) whether each 90% interval held the truth, ``ranks`` (n,) the
    truth's rank among ``n_rank`` draws. Returns n, the coverage, the binomial 95% range of a calibrated 90%
    (``lo``, ``hi``), the misses with the truth above / below the draws' middle, the mean rank with the se of a
    uniform one, and the rank histogram's chi-square p (10 bins; NaN under 20 replicates)."""
    from scipy.stats import binom, chisquare

    covered, ranks = np.asarray(covered, bool), np.asarray(ranks, float)
    n = covered.size
    missed = ranks[~covered]
    counts = np.histogram(ranks, bins=10, range=(0, n_rank + 1))[0]
    return {
        "n": n,
        "coverage": float(covered.mean()),
        "lo": binom.ppf(0.025, n, 0.9) / n,
        "hi": binom.ppf(0.975, n, 0.9) / n,
        "above": int(np.sum(missed > n_rank / 2)),
        "below": int(np.sum(missed <= n_rank / 2)),
        "mean_rank": float(ranks.mean()),
        "se": float(np.sqrt(((n_rank + 1) ** 2 - 1) / 12 / n)),  # sd of a uniform rank on 0..n_rank over sqrt(n)
        "chi2_p": float(chisquare(counts).pvalue) if n >= 20 else float("nan"),
    }

"""What the study scripts share: skip the jobs whose rows are already in the results CSV, run the rest in a
process pool and append each row as it finishes (an interrupted study resumes); simulate and extract one
rendered push of a stem with its drawn diameter profile (the width studies)."""

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

"""``bayesrod.fit_many``: fit every dataset of a folder on a Dask cluster; one run each and a survey table.

Layout of the output folder::

    OUT/runs/<specimen>/         a normal fit run (summary.json, posterior.nc, report.html, ...)
    OUT/runs/<specimen>.done     written after the run finished (the restart marker)
    OUT/survey.csv, survey.parquet   one row per finished specimen
    OUT/failures.json            datasets that failed, with the one-line reason

Restartable: a rerun skips specimens with a ``.done`` marker and resumes
interrupted ones from their ``chains.h5`` checkpoint.
One failing dataset is reported and does not stop the others. Each dataset is
fitted with the same seed, so a run equals ``bayesrod.fit(dataset, seed=N)``.
"""

from __future__ import annotations

import copy
import json
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from ..dataset.io import write_json

log = logging.getLogger("bayesrod")

SURVEY_COLUMNS = [
    "specimen",
    "species",
    "length_m",
    "EI0_median",
    "EI0_q05",
    "EI0_q95",
    "p_median",
    "p_q05",
    "p_q95",
    "rhat_max",
    "ess_bulk_min",
    "force_rmse_N",
    "shape_rmse_mm",
    "seconds",
    "run",
]


def find_datasets(root) -> list[Path]:
    """Sub-directories of ``root`` holding a specimen.json (sorted); ``root`` itself if it is one."""
    root = Path(root)
    if (root / "specimen.json").is_file():
        return [root]
    if not root.is_dir():
        raise ValueError(f"{root}: expected a directory of datasets, got no such directory")
    found = sorted(p.parent for p in root.glob("*/specimen.json"))
    if not found:
        raise ValueError(f"{root}: expected sub-directories holding specimen.json, got none")
    return found


def fit_one(dataset: str, run: str, options: dict) -> dict:
    """Worker task: fit one dataset and save it into ``run`` (resuming its checkpoint); never raises."""
    from .fitting import fit

    t0 = time.perf_counter()
    try:
        post = fit(dataset, progress=False, checkpoint=Path(run) / "chains.h5", **options)
        post.save(run, overwrite=True)
    except Exception as e:  # reported per dataset; the others go on
        return {"dataset": dataset, "ok": False, "error": f"{type(e).__name__}: {e}"}
    return {"dataset": dataset, "ok": True, "summary": post.to_dict(), "seconds": time.perf_counter() - t0}


def _row(summary: dict, run: Path) -> dict:
    P = summary["parameters"]
    fe = summary.get("fit_error", {})
    return {
        "specimen": summary["specimen"],
        "species": summary.get("species"),
        "length_m": summary.get("length_m"),
        "EI0_median": P["EI0"]["median"],
        "EI0_q05": P["EI0"]["q05"],
        "EI0_q95": P["EI0"]["q95"],
        "p_median": P["p"]["median"],
        "p_q05": P["p"]["q05"],
        "p_q95": P["p"]["q95"],
        "rhat_max": summary["convergence"]["rhat_max"],
        "ess_bulk_min": summary["convergence"]["ess_bulk_min"],
        "force_rmse_N": fe.get("force_rmse_N"),
        "shape_rmse_mm": fe.get("shape_rmse_mm"),
        "seconds": summary.get("sampler", {}).get("seconds"),
        "run": str(run),
    }


def finished_rows(out: Path) -> list[dict]:
    """One survey row per finished run under ``out/runs`` (a ``.done`` marker and its summary.json)."""
    rows = []
    for done in sorted((Path(out) / "runs").glob("*.done")):
        run = done.with_suffix("")
        s = run / "summary.json"
        if s.is_file():
            rows.append(_row(json.loads(s.read_text()), run))
    return rows


@dataclass(frozen=True, eq=False)
class Survey:
    """Every specimen of a folder fitted: one row per finished run, and the failures with their reason."""

    rows: tuple[Mapping, ...]
    failures: Mapping[str, Mapping]
    n_datasets: int

    def to_frame(self):
        """The survey as a pandas DataFrame (columns as survey.csv)."""
        import pandas as pd

        return pd.DataFrame([dict(r) for r in self.rows], columns=SURVEY_COLUMNS)

    def to_dict(self) -> dict:
        return {
            "datasets": self.n_datasets,
            "fitted": len(self.rows),
            "failed": copy.deepcopy(dict(self.failures)),
            "rows": [dict(r) for r in self.rows],
        }

    def save(self, path) -> Path:
        """Write ``survey.csv``, ``survey.parquet`` and ``failures.json`` into ``path`` (each atomically)."""
        import io

        import pyarrow as pa
        import pyarrow.parquet as pq

        from ..dataset.io import write_bytes_atomic, write_json, write_text_atomic

        path = Path(path)
        lines = [",".join(SURVEY_COLUMNS)]
        for r in self.rows:
            lines.append(",".join("" if r[c] is None else str(r[c]).replace(",", ";") for c in SURVEY_COLUMNS))
        write_text_atomic(path / "survey.csv", "\n".join(lines) + "\n")
        buf = io.BytesIO()
        pq.write_table(pa.table({c: [r[c] for r in self.rows] for c in SURVEY_COLUMNS}), buf)
        write_bytes_atomic(path / "survey.parquet", buf.getvalue())
        write_json(path / "failures.json", dict(self.failures))
        return path


def fit_many(
    root,
    out,
    *,
    scheduler: str | None = None,
    n_workers: int = 2,
    prior=None,
    seed: int = 0,
    use_shapes: bool = True,
    progress: bool = True,
) -> Survey:
    """Fit every dataset under ``root`` on Dask, each saved as a run in ``out/runs/<specimen>``.

    Restartable: specimens with a ``.done`` marker are skipped and interrupted ones resume from their
    checkpoint. One failing dataset is reported in ``Survey.failures`` and does not stop the others.

    Parameters
    ----------
    root : path
        A folder whose sub-directories are datasets (or one dataset).
    out : path
        Where the runs go (``out/runs``); :meth:`Survey.save` writes the table.
    scheduler : str or None
        Address of a running Dask scheduler; None starts a local cluster of ``n_workers`` processes.
    prior, seed, use_shapes
        As :func:`bayesrod.fit`, the same for every dataset.
    """
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm.auto import tqdm

    from ._common import progress_enabled

    if not (isinstance(n_workers, int) and n_workers >= 1):
        raise ValueError(f"n_workers: expected at least 1, got {n_workers!r}")
    options = {"prior": prior, "seed": seed, "use_shapes": use_shapes}
    out = Path(out)
    datasets = find_datasets(root)
    names = {}
    for d in datasets:
        name = json.loads((d / "specimen.json").read_text()).get("specimen") or d.name
        if name in names:
            raise ValueError(f"{d / 'specimen.json'}: field specimen: expected a unique name, got {name!r} twice")
        names[name] = d
    (out / "runs").mkdir(parents=True, exist_ok=True)
    todo = {n: d for n, d in names.items() if not (out / "runs" / f"{n}.done").is_file()}
    log.info("%d datasets, %d already fitted, %d to fit", len(names), len(names) - len(todo), len(todo))
    failures = {}
    if todo:
        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        try:
            futures = {
                client.submit(fit_one, str(d), str(out / "runs" / n), options, key=f"fit-{n}", pure=False): n
                for n, d in todo.items()
            }
            bar = tqdm(
                total=len(futures), desc="fitting specimens", unit="specimen", disable=not progress_enabled(progress)
            )
            for fut in as_completed(futures):
                n = futures[fut]
                try:
                    res = fut.result()
                except Exception as e:  # a worker lost, say
                    res = {"ok": False, "error": f"{type(e).__name__}: {e}"}
                if res["ok"]:
                    write_json(out / "runs" / f"{n}.done", {"seconds": res["seconds"], "dataset": str(todo[n])})
                else:
                    failures[n] = {"dataset": str(todo[n]), "error": res["error"]}
                    log.warning("%s: failed: %s", n, res["error"])
                bar.update()
            bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows = tuple(MappingProxyType(r) for r in finished_rows(out))
    return Survey(rows, MappingProxyType(failures), len(names))

"""``bayesrod fit-many``: fit every dataset of a folder on a Dask cluster; one RUN each and a survey table.

Layout of ``--out``::

    OUT/runs/<specimen>/         a normal fit run (summary.json, posterior.nc, report.html, ...)
    OUT/runs/<specimen>.done     written after the run finished (the restart marker)
    OUT/survey.csv, survey.parquet   one row per finished specimen
    OUT/failures.json            datasets that failed, with the one-line reason

Restartable: a rerun skips specimens with a ``.done`` marker and resumes
interrupted ones from their ``chains.h5`` checkpoint (``bayesrod fit --resume``).
One failing dataset is reported and does not stop the others. Each dataset is
fitted with the same seed, so a run equals ``bayesrod fit DATASET --seed N``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from .io import write_json, write_text_atomic

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
    """Worker task: fit one dataset into ``run`` (resuming a checkpoint); never raises."""
    from .fit import fit_dataset

    t0 = time.perf_counter()
    try:
        s = fit_dataset(dataset, run, progress=False, resume=True, log=lambda *a: None, **options)
    except Exception as e:  # reported per dataset; the others go on
        return {"dataset": dataset, "ok": False, "error": f"{type(e).__name__}: {e}"}
    return {"dataset": dataset, "ok": True, "summary": s, "seconds": time.perf_counter() - t0}


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


def write_survey(out: Path) -> list[dict]:
    """survey.csv and survey.parquet from every finished run (atomic writes)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = []
    for done in sorted((out / "runs").glob("*.done")):
        run = done.with_suffix("")
        s = run / "summary.json"
        if s.is_file():
            rows.append(_row(json.loads(s.read_text()), run))
    lines = [",".join(SURVEY_COLUMNS)]
    for r in rows:
        lines.append(",".join("" if r[c] is None else str(r[c]).replace(",", ";") for c in SURVEY_COLUMNS))
    write_text_atomic(out / "survey.csv", "\n".join(lines) + "\n")
    table = pa.table({c: [r[c] for r in rows] for c in SURVEY_COLUMNS})
    tmp = out / ".survey.parquet.tmp"
    pq.write_table(table, tmp)
    tmp.replace(out / "survey.parquet")
    return rows


def fit_many(
    root,
    out,
    *,
    scheduler: str | None = None,
    n_workers: int = 2,
    options: dict | None = None,
    progress: bool = True,
    log=print,
) -> dict:
    """Fit every dataset under ``root`` into ``out`` on Dask; returns counts and failures."""
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm.auto import tqdm

    options = dict(options or {})
    out = Path(out)
    datasets = find_datasets(root)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    names = {}
    for d in datasets:
        name = json.loads((d / "specimen.json").read_text()).get("specimen") or d.name
        if name in names:
            raise ValueError(f"{d / 'specimen.json'}: field specimen: expected a unique name, got {name!r} twice")
        names[name] = d
    todo = {n: d for n, d in names.items() if not (out / "runs" / f"{n}.done").is_file()}
    log(f"{len(names)} datasets, {len(names) - len(todo)} already fitted, {len(todo)} to fit")
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
            bar = tqdm(total=len(futures), desc="fitting specimens", unit="specimen", disable=not progress)
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
                    log(f"{n}: failed: {res['error']}")
                bar.update()
            bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    write_json(out / "failures.json", failures)
    rows = write_survey(out)
    return {"datasets": len(names), "fitted": len(rows), "failed": failures}

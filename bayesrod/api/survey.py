"""``bayesrod.fit_many``: fit every dataset of a folder on a Dask cluster; one run each and a survey table.

Layout of the output folder::

    OUT/runs/<specimen>/         a normal fit run (summary.json, posterior.nc, report.html, ...)
    OUT/runs/<specimen>.done     written after the run finished (the restart marker)
    OUT/survey.csv, survey.parquet   one row per finished specimen
    OUT/failures.json            datasets that failed, with the one-line reason
    OUT/groups/<stem_id>/        with ``grouped``: a fit-group run per stem (summary.json, samples.npz)
    OUT/groups/<stem_id>.done    its restart marker
    OUT/groups.csv, groups.parquet   one row per condition of each finished stem

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

_QUANTILES = ("median", "q05", "q95")


def _interval_columns(*names: str) -> list[str]:
    """``<name>_median, <name>_q05, <name>_q95`` for each name, in order."""
    return [f"{n}_{q}" for n in names for q in _QUANTILES]


def _interval_cells(**intervals: Mapping) -> dict:
    """The cells of :func:`_interval_columns` from ``{median, q05, q95}`` mappings."""
    return {f"{n}_{q}": iv[q] for n, iv in intervals.items() for q in _QUANTILES}


SURVEY_COLUMNS = [
    "specimen",
    "species",
    "length_m",
    *_interval_columns("EI0", "p"),
    "rhat_max",
    "ess_bulk_min",
    "force_rmse_N",
    "shape_rmse_mm",
    "seconds",
    "run",
]

#: one row per condition of a stem fitted jointly (``fit_many(..., grouped=True)``); EI0 and p are the
#: stem's shared ones (the condition's own where they were not shared)
GROUP_COLUMNS = [
    "stem_id",
    "condition",
    "species",
    "length_m",
    *_interval_columns("EI0", "p", "base_compliance"),
    "prob_rigid_clamp",
    "sharing",
    "rhat_max",
    "ess_bulk_min",
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


def fit_group_one(stem_id: str, conditions: dict, run: str, options: dict) -> dict:
    """Worker task: fit one stem under its conditions ({condition: dataset path}) and save it into ``run``."""
    from .group import fit_group

    t0 = time.perf_counter()
    try:
        g = fit_group(conditions, options.get("prior"), stem_id=stem_id, seed=options.get("seed", 0), progress=False)
        g.save(run, overwrite=True)
    except Exception as e:  # reported per stem; the others go on
        return {"dataset": stem_id, "ok": False, "error": f"{type(e).__name__}: {e}"}
    return {"dataset": stem_id, "ok": True, "summary": g.to_dict(), "seconds": time.perf_counter() - t0}


def _group_rows(summary: dict, run: Path) -> list[dict]:
    rows = []
    for c in summary["conditions_order"]:
        cond = summary["conditions"][c]
        stem = {n: summary["shared"].get(n) or cond[n] for n in ("EI0", "p")}
        rows.append(
            {
                "stem_id": summary["stem_id"],
                "condition": c,
                "species": summary.get("species"),
                "length_m": summary.get("length_m"),
                **_interval_cells(**stem, base_compliance=cond["base_compliance_rad_per_Nm"]),
                "prob_rigid_clamp": cond["prob_rigid_clamp"],
                "sharing": (summary.get("sharing") or {}).get("verdict"),
                "rhat_max": summary["convergence"]["rhat_max"],
                "ess_bulk_min": summary["convergence"]["ess_bulk_min"],
                "seconds": summary["sampler"]["seconds"],
                "run": str(run),
            }
        )
    return rows


def _row(summary: dict, run: Path) -> dict:
    P = summary["parameters"]
    fe = summary.get("fit_error", {})
    return {
        "specimen": summary["specimen"],
        "species": summary.get("species"),
        "length_m": summary.get("length_m"),
        **_interval_cells(EI0=P["EI0"], p=P["p"]),
        "rhat_max": summary["convergence"]["rhat_max"],
        "ess_bulk_min": summary["convergence"]["ess_bulk_min"],
        "force_rmse_N": fe.get("force_rmse_N"),
        "shape_rmse_mm": fe.get("shape_rmse_mm"),
        "seconds": summary.get("sampler", {}).get("seconds"),
        "run": str(run),
    }


def finished_rows(out: Path, kind: str = "runs") -> list[dict]:
    """Survey rows of the finished runs under ``out/runs`` (one per specimen) or ``out/groups`` (one per
    condition of each stem): each with a ``.done`` marker and its summary.json."""
    rows = []
    for done in sorted((Path(out) / kind).glob("*.done")):
        run = done.with_suffix("")
        s = run / "summary.json"
        if s.is_file():
            doc = json.loads(s.read_text())
            rows += _group_rows(doc, run) if kind == "groups" else [_row(doc, run)]
    return rows


def _table_files(path: Path, name: str, columns: list[str], rows) -> None:
    """``name``.csv and ``name``.parquet of ``rows`` (each written atomically)."""
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    from ..dataset.io import write_bytes_atomic, write_text_atomic

    lines = [",".join(columns)]
    for r in rows:
        lines.append(",".join("" if r[c] is None else str(r[c]).replace(",", ";") for c in columns))
    write_text_atomic(path / f"{name}.csv", "\n".join(lines) + "\n")
    buf = io.BytesIO()
    pq.write_table(pa.table({c: [r[c] for r in rows] for c in columns}), buf)
    write_bytes_atomic(path / f"{name}.parquet", buf.getvalue())


@dataclass(frozen=True, eq=False)
class Survey:
    """Every specimen of a folder fitted: one row per finished run, and the failures with their reason."""

    rows: tuple[Mapping, ...]
    failures: Mapping[str, Mapping]
    n_datasets: int
    #: with ``grouped``: one row per condition of each stem fitted jointly (columns as groups.csv)
    group_rows: tuple[Mapping, ...] = ()

    def to_frame(self):
        """The survey as a pandas DataFrame (columns as survey.csv)."""
        import pandas as pd

        return pd.DataFrame([dict(r) for r in self.rows], columns=SURVEY_COLUMNS)

    def to_dict(self) -> dict:
        out = {
            "datasets": self.n_datasets,
            "fitted": len(self.rows),
            "failed": copy.deepcopy(dict(self.failures)),
            "rows": [dict(r) for r in self.rows],
        }
        if self.group_rows:
            out["stems"] = len({r["stem_id"] for r in self.group_rows})
            out["group_rows"] = [dict(r) for r in self.group_rows]
        return out

    def save(self, path) -> Path:
        """Write ``survey.csv``, ``survey.parquet``, ``failures.json`` and, with stems fitted jointly,
        ``groups.csv`` and ``groups.parquet`` into ``path`` (each atomically)."""
        path = Path(path)
        _table_files(path, "survey", SURVEY_COLUMNS, self.rows)
        if self.group_rows:
            _table_files(path, "groups", GROUP_COLUMNS, self.group_rows)
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
    grouped: bool = False,
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
    grouped : bool
        Datasets sharing a ``stem_id`` under two or more conditions are one job each: the stem's joint
        posterior (:func:`bayesrod.fit_group`, forces only; prior and seed as above), saved in
        ``out/groups/<stem_id>`` and tabled per condition in ``Survey.group_rows``. The other datasets
        are fitted one by one; a second dataset of one stem with the same condition is a failure.
    """
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm.auto import tqdm

    from ._common import progress_enabled
    from .group import _safe, group_paths

    if not (isinstance(n_workers, int) and n_workers >= 1):
        raise ValueError(f"n_workers: expected at least 1, got {n_workers!r}")
    options = {"prior": prior, "seed": seed, "use_shapes": use_shapes}
    out = Path(out)
    failures = {}
    stems: dict[str, dict[str, Path]] = {}
    if grouped:
        stems, datasets, problems = group_paths(root)
        singles = set(datasets)
        for path, line in problems:
            if path not in singles:  # a repeated condition: skipped
                failures[path.name] = {"dataset": str(path), "error": line}
    else:
        datasets = find_datasets(root)
    names = {}
    for d in datasets:
        name = json.loads((d / "specimen.json").read_text()).get("specimen") or d.name
        if name in names:
            raise ValueError(f"{d / 'specimen.json'}: field specimen: expected a unique name, got {name!r} twice")
        names[name] = d
    (out / "runs").mkdir(parents=True, exist_ok=True)
    # (folder, name) -> (task, its arguments before the run folder, the source named in a marker or failure)
    jobs = {("runs", n): (fit_one, (str(d),), str(d)) for n, d in names.items()}
    if stems:
        (out / "groups").mkdir(parents=True, exist_ok=True)
        for sid, conds in stems.items():
            paths = {c: str(p) for c, p in conds.items()}
            jobs[("groups", _safe(sid))] = (fit_group_one, (sid, paths), ", ".join(paths.values()))
    todo = {k: j for k, j in jobs.items() if not (out / k[0] / f"{k[1]}.done").is_file()}
    log.info("%d jobs, %d already done, %d to run", len(jobs), len(jobs) - len(todo), len(todo))
    if todo:
        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        try:
            futures = {
                client.submit(fn, *pre, str(out / kind / n), options, key=f"{kind}-{n}", pure=False): (kind, n)
                for (kind, n), (fn, pre, _) in todo.items()
            }
            bar = tqdm(total=len(futures), desc="fitting", unit="job", disable=not progress_enabled(progress))
            for fut in as_completed(futures):
                kind, n = futures[fut]
                try:
                    res = fut.result()
                except Exception as e:  # a worker lost, say
                    res = {"ok": False, "error": f"{type(e).__name__}: {e}"}
                source = todo[(kind, n)][2]
                if res["ok"]:
                    write_json(out / kind / f"{n}.done", {"seconds": res["seconds"], "dataset": source})
                else:
                    failures[n if kind == "runs" else f"stem {n}"] = {"dataset": source, "error": res["error"]}
                    log.warning("%s: failed: %s", n, res["error"])
                bar.update()
            bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows = tuple(MappingProxyType(r) for r in finished_rows(out))
    group_rows = tuple(MappingProxyType(r) for r in finished_rows(out, "groups")) if grouped else ()
    return Survey(rows, MappingProxyType(failures), len(names) + sum(len(c) for c in stems.values()), group_rows)

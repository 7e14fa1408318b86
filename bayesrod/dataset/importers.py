"""Importers that turn raw force-displacement tables into ``bayesrod.dataset/1`` datasets.

The building blocks are generic (counter unwrapping, tare and contact onset by
a hinge fit); :func:`import_blueberry` applies them to the blueberry-cane
tables of ``shared/data/blueberry-canes`` (see docs/data.md). Raw files are
only read.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .io import write_csv, write_json
from .model import FORMAT

GF_TO_N = 9.80665e-3


def unwrap_counter(values, modulus: float = 65536.0) -> np.ndarray:
    """Undo wrap-around of a signed counter (e.g. 16-bit ms timestamps 32767 -> -32768)."""
    v = np.asarray(values, float)
    jumps = np.diff(v)
    fix = np.concatenate(
        [[0.0], np.cumsum(np.where(jumps < -modulus / 2, modulus, 0.0) - np.where(jumps > modulus / 2, modulus, 0.0))]
    )
    return v + fix


@dataclass(frozen=True)
class Onset:
    """Tare and contact onset from a hinge fit F = b + k max(0, x - x_on)."""

    index: int  # first sample in contact
    baseline: float  # force reading with nothing touching (same units as the input)
    slope: float  # initial stiffness (force per unit x)
    observed: bool  # False if contact began at or before the first sample


def hinge_onset(x, force, window_fraction: float = 0.5, min_window: int = 6) -> Onset:
    """Contact onset and tare of a push that starts before contact (or at it).

    Fits the continuous hinge F = b + k max(0, x - x_j) by least squares for
    every candidate sample j on the initial part of the push (until the force
    first exceeds ``window_fraction`` of its rise) and keeps the best j.
    """
    x = np.asarray(x, float)
    F = np.asarray(force, float)
    n = F.size
    if n < 3:
        return Onset(0, float(F[0]) if n else 0.0, 0.0, False)
    f0 = np.median(F[:3])
    above = np.flatnonzero(F > f0 + window_fraction * (F.max() - f0))
    w = int(min(n, max(min_window, above[0] + 1 if above.size else n)))
    xs, Fs = x[:w], F[:w]
    best = (np.inf, 0, f0, 0.0)
    for j in range(w - 2):
        a = np.clip(xs - xs[j], 0, None)
        A = np.stack([np.ones(w), a], axis=1)
        coef, *_ = np.linalg.lstsq(A, Fs, rcond=None)
        sse = float(np.sum((A @ coef - Fs) ** 2))
        if coef[1] > 0 and sse < best[0] - 1e-12:
            best = (sse, j, float(coef[0]), float(coef[1]))
    _, j, b, k = best
    return Onset(int(j), b, k, observed=j > 0)


@dataclass
class TrialReport:
    file: str
    status: str  # "imported" or "rejected"
    reason: str
    height_m: float | None = None
    n_samples: int = 0
    baseline_N: float | None = None
    peak_force_N: float | None = None
    onset_observed: bool | None = None


_NAME = re.compile(r"bush_(\d+)_branch_(\d+)_trial_(\d+)\.csv$")
_COLUMNS = ("Iteration", "Time Stamp", "Load Cell Reading (gf)", "Displacement (mm)", "Height (mm)")


def _read_table(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as fh:
        rows = [r for r in csv.reader(fh) if r]
    header = [h.strip() for h in rows[0]]
    missing = [c for c in _COLUMNS if c not in header]
    if missing:
        raise ValueError(
            f"{path.name}: column {missing[0]}: expected the blueberry header {', '.join(_COLUMNS)}, "
            f"got {', '.join(header)}"
        )
    out = {}
    for c in _COLUMNS:
        j = header.index(c)
        vals = []
        for i, r in enumerate(rows[1:]):
            try:
                vals.append(float(r[j]))
            except (ValueError, IndexError):
                raise ValueError(
                    f"{path.name}, row {i + 1}: column {c}: expected a number, "
                    f"got {r[j] if j < len(r) else 'nothing'!r}"
                ) from None
        out[c] = np.array(vals)
    return out


def import_blueberry_trial(path: Path, length_m: float, min_rise_N: float = 0.5, min_samples: int = 5):
    """Import one trial table. Returns (report, force columns or None)."""
    t = _read_table(path)
    h = float(np.median(t["Height (mm)"])) / 1000.0
    rep = TrialReport(path.name, "rejected", "", height_m=h)
    if not np.all(t["Height (mm)"] == t["Height (mm)"][0]):
        rep.reason = "Height (mm) varies within the file"
        return rep, None
    if not 0 < h < length_m:
        rep.reason = f"height {h:g} m is not below the assumed cane length {length_m:g} m"
        return rep, None
    time_s = unwrap_counter(t["Time Stamp"]) / 1000.0
    if not np.all(np.diff(time_s) > 0):
        rep.reason = "timestamps do not increase even after unwrapping"
        return rep, None
    force_raw = t["Load Cell Reading (gf)"] * GF_TO_N
    disp_m = t["Displacement (mm)"] / 1000.0
    on = hinge_onset(disp_m, force_raw)
    rise = float(force_raw[on.index :].max() - on.baseline)
    rep.baseline_N, rep.onset_observed = on.baseline, on.observed
    if rise < min_rise_N:
        rep.reason = f"no real contact: the force rises by {rise:.2f} N (< {min_rise_N} N) above its baseline"
        return rep, None
    sel = slice(on.index, None)
    if force_raw[sel].size < min_samples:
        rep.reason = f"only {force_raw[sel].size} samples after contact (< {min_samples})"
        return rep, None
    force = force_raw[sel] - on.baseline
    cols = {
        "time_s": time_s[sel] - time_s[0],
        "force_N": force,
        "robot_x_m": disp_m[sel] - disp_m[on.index],
        "raw_force_N": force_raw[sel],
        "raw_displacement_m": disp_m[sel],
        "iteration": t["Iteration"][sel],
    }
    rep.status = "imported"
    rep.n_samples = int(force.size)
    rep.peak_force_N = float(force.max())
    rep.reason = (
        "tared by a hinge fit on the pre-contact samples"
        if on.observed
        else "contact began at or before the first sample: tared with the hinge intercept at the first "
        "sample (a residual force offset is possible)"
    )
    return rep, cols


def import_blueberry(src: Path, out: Path, length_m: float) -> dict:
    """Import every cane under ``src`` (a ``csv_files`` folder or its parent) into ``out``.

    One dataset per cane (``bush{B}-cane{C}``) with one push per trial that made
    contact. Writes ``out/import_report.json`` and returns it.
    """
    src = Path(src)
    if (src / "csv_files").is_dir():
        src = src / "csv_files"
    if not src.is_dir():
        raise ValueError(f"SRC: expected the blueberry-canes folder (or its csv_files/), got {src}")
    if not (length_m > 0 and np.isfinite(length_m)):
        raise ValueError(f"length_m: expected an assumed cane length > 0 m, got {length_m}")
    files = sorted(p for p in src.iterdir() if _NAME.search(p.name))
    if not files:
        raise ValueError(f"SRC: expected files named bush_B_branch_C_trial_T.csv, got none in {src}")
    canes: dict[tuple[int, int], list[Path]] = {}
    for p in files:
        b, c, _ = map(int, _NAME.search(p.name).groups())
        canes.setdefault((b, c), []).append(p)
    report = {"source": str(src), "assumed_length_m": length_m, "canes": []}
    for (b, c), paths in sorted(canes.items()):
        name = f"bush{b}-cane{c}"
        trials, pushes = [], []
        for p in sorted(paths):
            rep, cols = import_blueberry_trial(p, length_m)
            trials.append(vars(rep))
            if cols is None:
                continue
            pid = f"h{round(rep.height_m * 1000):d}"
            if any(e["id"] == pid for e in pushes):
                pid += f"-{len(pushes)}"
            d = out / name / pid
            d.mkdir(parents=True, exist_ok=True)
            write_csv(d / "force.csv", cols)
            pushes.append(
                {
                    "id": pid,
                    "height_m": rep.height_m,
                    "direction": 1,
                    "force": f"{pid}/force.csv",
                    "source_file": p.name,
                }
            )
        entry = {"cane": name, "trials": trials}
        if pushes:
            pushes.sort(key=lambda e: e["height_m"])
            write_json(
                out / name / "specimen.json",
                {
                    "format": FORMAT,
                    "specimen": name,
                    "species": "blueberry",
                    "length_m": length_m,
                    "sensor": {"type": "load_cell", "force_range_N": [0.05, 1000 * GF_TO_N]},
                    "pushes": pushes,
                    "bush": b,
                    "provenance": {
                        "source": (
                            "chelsevanatter/ros2_ws_ROB599_Project@1270e8e4bbe0fa2f760ca3c1c7c906824cf68db1 csv_files/"
                        ),
                        "license": "BSD-3-Clause (see shared/data/blueberry-canes/LICENSE)",
                        "importer": "bayesrod import blueberry",
                        "assumptions": {
                            "length_m": f"{length_m:g} m, user-given (the data hold no cane length)",
                            "base": "clamped at the ground (Height is measured from the ground)",
                            "displacement": "actuator position since contact onset; probe compliance neglected",
                        },
                    },
                },
            )
            entry["status"] = "imported"
            entry["dataset"] = name
        else:
            entry["status"] = "rejected"
            entry["reason"] = "no trial made usable contact: " + "; ".join(t["reason"] for t in trials)
        report["canes"].append(entry)
    write_json(out / "import_report.json", report)
    return report

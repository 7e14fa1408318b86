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
    position: float | None = None  # the hinge's x (between samples), when refined


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


def contact_onset(x, force, min_free: int = 3, f_crit: float = 10.0) -> Onset:
    """Contact onset of a ramp that may start before contact, or already loaded.

    :func:`hinge_onset`, accepted only when the recording really shows the stem free first: at least
    ``min_free`` samples before the hinge and a hinge that fits significantly better than one straight
    line through the same window (F statistic > ``f_crit``). Otherwise the ramp started in contact
    (``observed`` False, index 0, no baseline to tare by).
    """
    x = np.asarray(x, float)
    F = np.asarray(force, float)
    on = hinge_onset(x, F)
    if not on.observed or on.index < min_free:
        return Onset(0, float(F[0]) if F.size else 0.0, on.slope, False)
    f0 = np.median(F[:3])
    above = np.flatnonzero(F > f0 + 0.5 * (F.max() - f0))
    w = int(min(F.size, max(6, above[0] + 1 if above.size else F.size)))
    xs, Fs = x[:w], F[:w]
    A = np.stack([np.ones(w), xs], axis=1)
    line = np.linalg.lstsq(A, Fs, rcond=None)[0]
    sse_line = float(np.sum((A @ line - Fs) ** 2))
    hinge = on.baseline + on.slope * np.clip(xs - xs[on.index], 0, None)
    sse_hinge = float(np.sum((hinge - Fs) ** 2))
    if w <= 4 or sse_hinge <= 0:
        return on
    stat = (sse_line - sse_hinge) / (sse_hinge / (w - 3))
    if stat <= f_crit:
        return Onset(0, float(F[0]), on.slope, False)
    # the contact point lies between samples: refine the hinge's x continuously around the best sample
    from scipy.optimize import minimize_scalar

    def sse(x_on):
        a = np.clip(xs - x_on, 0, None)
        M = np.stack([np.ones(w), a], axis=1)
        c = np.linalg.lstsq(M, Fs, rcond=None)[0]
        return float(np.sum((M @ c - Fs) ** 2)), c

    lo, hi = xs[max(on.index - 1, 0)], xs[min(on.index + 1, w - 1)]
    res = minimize_scalar(lambda v: sse(v)[0], bounds=(min(lo, hi), max(lo, hi)), method="bounded")
    x_on = float(res.x) if res.success and sse(res.x)[0] <= sse_hinge else float(xs[on.index])
    c = sse(x_on)[1]
    first = int(np.searchsorted(xs, x_on, side="left")) if np.all(np.diff(xs) >= 0) else on.index
    return Onset(first, float(c[0]), float(c[1]), True, x_on)


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


def blueberry_documents(src: Path, length_m: float) -> tuple[dict, dict]:
    """Every cane under ``src`` (a ``csv_files`` folder or its parent) as documents; nothing written.

    Returns ``(datasets, report)``: ``datasets`` maps each cane name (``bush{B}-cane{C}``) to
    ``{"specimen": specimen.json document, "files": {relative path: force columns}}`` with one push
    per trial that made contact; ``report`` is the import report (every trial, imported or why not).
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
    datasets: dict[str, dict] = {}
    for (b, c), paths in sorted(canes.items()):
        name = f"bush{b}-cane{c}"
        trials, pushes, files = [], [], {}
        for p in sorted(paths):
            rep, cols = import_blueberry_trial(p, length_m)
            trials.append(vars(rep))
            if cols is None:
                continue
            pid = f"h{round(rep.height_m * 1000):d}"
            if any(e["id"] == pid for e in pushes):
                pid += f"-{len(pushes)}"
            files[f"{pid}/force.csv"] = cols
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
            datasets[name] = {
                "files": files,
                "specimen": {
                    "format": FORMAT,
                    "specimen": name,
                    "species": "blueberry",
                    "length_m": length_m,
                    "length_m_approximate": True,  # a guess: force-only fits sample L (docs/priors.md)
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
                            "length_m": f"{length_m:g} m, a user-given guess (no cane length in the data): approximate",
                            "base": "clamped at the ground (Height is measured from the ground)",
                            "displacement": "actuator position since contact onset; probe compliance neglected",
                        },
                    },
                },
            }
            entry["status"] = "imported"
            entry["dataset"] = name
        else:
            entry["status"] = "rejected"
            entry["reason"] = "no trial made usable contact: " + "; ".join(t["reason"] for t in trials)
        report["canes"].append(entry)
    return datasets, report


def import_blueberry(src: Path, out: Path, length_m: float) -> dict:
    """:func:`blueberry_documents` written into ``out`` (a dataset folder per cane, import_report.json).

    The caller hands an empty folder (the CLI: the temporary folder of an atomic write). Returns the report.
    """
    datasets, report = blueberry_documents(src, length_m)
    out = Path(out)
    for name, doc in datasets.items():
        for rel, cols in doc["files"].items():
            (out / name / rel).parent.mkdir(parents=True, exist_ok=True)
            write_csv(out / name / rel, cols)
        write_json(out / name / "specimen.json", doc["specimen"])
    write_json(out / "import_report.json", report)
    return report


# --------------------------------------------------------------------------- #
# generic rig tables (docs/data.md, "Raw rig tables")
# --------------------------------------------------------------------------- #
#: units of a rig table's columns, to SI (exact conversions: the international inch, pound and ounce,
#: standard gravity for the gram-, kilogram-, pound- and ounce-force)
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "min": 60.0}
FORCE_UNITS = {
    "N": 1.0,
    "mN": 1e-3,
    "kN": 1e3,
    "gf": GF_TO_N,
    "kgf": 1e3 * GF_TO_N,
    "lbf": 0.45359237 * 9.80665,
    "ozf": 0.45359237 / 16 * 9.80665,
}
DISPLACEMENT_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}
ANGLE_UNITS = {"deg": np.pi / 180.0, "rad": 1.0}
#: per-file fields a metadata table may set (the same names as the options)
METADATA_FIELDS = (
    "height_m",
    "length_m",
    "specimen",
    "species",
    "arm_height_m",
    "force_sign",
    "displacement_sign",
    "stem_id",
    "condition",
)


@dataclass(frozen=True)
class Segment:
    """One monotone stretch of a recording: samples ``start`` to ``stop`` (exclusive), loading or unloading."""

    start: int
    stop: int
    loading: bool


def split_cycles(x, tol: float | None = None) -> list[Segment]:
    """Split a displacement series into loading (advancing) and unloading (retreating) stretches.

    A reversal is a turn by more than ``tol`` (default: the series' noise, see
    :func:`bayesrod.dataset.plausibility.reversal_tolerance`) from the running extreme; the turning
    sample belongs to both neighbours, so each stretch starts where the previous one turned.
    """
    from .plausibility import reversal_tolerance

    x = np.asarray(x, float)
    n = x.size
    if n < 2:
        return [Segment(0, n, True)]
    tol = reversal_tolerance(x) if tol is None else tol
    turns, up = [0], None
    ext_i = 0
    for i in range(1, n):
        if up is None:
            if abs(x[i] - x[0]) > tol:
                up = x[i] > x[0]
                ext_i = i
            continue
        if (up and x[i] > x[ext_i]) or (not up and x[i] < x[ext_i]):
            ext_i = i
        elif abs(x[i] - x[ext_i]) > tol:
            turns.append(ext_i)
            up = not up
            ext_i = i
    turns.append(n - 1)
    segs = []
    first_up = True if up is None else (x[turns[1]] >= x[turns[0]])
    for k in range(len(turns) - 1):
        a, b = turns[k], turns[k + 1]
        loading = first_up if k % 2 == 0 else not first_up
        segs.append(Segment(a, b + 1, loading))
    return segs


@dataclass(frozen=True, kw_only=True)
class TableOptions:
    """How to read one kind of rig table (the flags of ``bayesrod import table``).

    ``time`` may be None for a table without a time column: the sample index (0, 1, 2, ... s) is then the
    time, which a forces-only fit never reads (shapes are matched to forces by time)."""

    force: str
    time: str | None = None
    displacement: str | None = None
    angle: str | None = None
    arm_height_m: float | None = None
    time_unit: str = "s"
    force_unit: str = "N"
    displacement_unit: str = "m"
    angle_unit: str = "deg"
    height_m: float | None = None
    length_m: float | None = None
    length_unknown: bool = False
    specimen: str | None = None
    species: str | None = None
    stem_id: str | None = None
    condition: str | None = None
    header_row: int | None = None
    cycles: str = "all"
    force_sign: int = 1
    displacement_sign: int = 1
    tare: str = "auto"
    specimen_column: str | None = None
    stem_id_column: str | None = None
    condition_column: str | None = None
    height_column: str | None = None
    height_unit: str = "m"
    test_column: str | None = None

    def __post_init__(self) -> None:
        for fld, val, allowed in (
            ("time_unit", self.time_unit, TIME_UNITS),
            ("force_unit", self.force_unit, FORCE_UNITS),
            ("displacement_unit", self.displacement_unit, DISPLACEMENT_UNITS),
            ("angle_unit", self.angle_unit, ANGLE_UNITS),
            ("height_unit", self.height_unit, DISPLACEMENT_UNITS),
            ("cycles", self.cycles, ("first", "all")),
            ("tare", self.tare, ("auto", "none")),
        ):
            if val not in allowed:
                raise ValueError(f"{fld}: expected one of {', '.join(allowed)}, got {val!r}")
        if (self.displacement is None) == (self.angle is None):
            raise ValueError(
                "displacement: expected either a displacement column or an angle column with an arm height, "
                f"got {'both' if self.displacement else 'neither'}"
            )
        for fld in ("force_sign", "displacement_sign"):
            if getattr(self, fld) not in (1, -1):
                raise ValueError(f"{fld}: expected +1 or -1, got {getattr(self, fld)!r}")
        if self.height_column is not None and self.height_m is not None:
            raise ValueError(
                f"height_m: expected either one contact height or a height column ({self.height_column!r}), "
                f"got both ({self.height_m:g} m)"
            )

    @property
    def group_columns(self) -> dict[str, str]:
        """The columns that split one table into recordings: {option: header name} (text columns, and the
        height column read as a number)."""
        named = {
            "specimen": self.specimen_column,
            "stem_id": self.stem_id_column,
            "condition": self.condition_column,
            "test": self.test_column,
            "height_m": self.height_column,
        }
        return {k: v for k, v in named.items() if v is not None}


def _file_options(base: TableOptions, meta: dict) -> TableOptions:
    from dataclasses import replace

    kw = {}
    for k in METADATA_FIELDS:
        v = meta.get(k)
        if v in (None, ""):
            continue
        if k in ("height_m", "length_m", "arm_height_m"):
            try:
                v = float(v)
            except ValueError:
                raise ValueError(f"metadata: column {k}: expected a number, got {v!r}") from None
        if k in ("force_sign", "displacement_sign"):
            try:
                v = int(float(v))
            except ValueError:
                raise ValueError(f"metadata: column {k}: expected +1 or -1, got {v!r}") from None
        kw[k] = v
    return replace(base, **kw)


def _positive(name: str, v) -> float:
    if v is None or not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name}: expected a number > 0, got {v!r}")
    return float(v)


def read_recordings(path: Path, opt: TableOptions, meta: dict | None = None) -> list[dict]:
    """The recordings of one table file, each read, converted to SI and split into loading ramps; in memory.

    A file is one recording, unless ``opt`` names columns that split it (:attr:`TableOptions.group_columns`:
    a specimen's, a stem's, a condition's or a test's id, or the contact height): then the rows sharing
    their values, in file order, are one recording each (a long table of many pushes).

    Returns a list of dicts as :func:`import_recording` returns, each with ``group`` ({option: value} of
    the splitting columns; empty for a whole file) and ``options`` (``opt`` with the group's values set, then
    the ``meta`` rows keyed by its stem or specimen: :func:`read_metadata`).
    """
    from dataclasses import replace

    from .tables import read_table

    groups = opt.group_columns
    unit = DISPLACEMENT_UNITS[opt.height_unit]  # the height column's, to metres and back in messages
    cols = [c for c in (opt.time, opt.force) if c] + ([opt.displacement] if opt.displacement else [opt.angle])
    numeric = cols + ([opt.height_column] if opt.height_column else [])
    texts = [c for k, c in groups.items() if k != "height_m"]
    tab = read_table(path, numeric, header_row=opt.header_row, name=str(path), text_columns=texts)
    meta = meta or {}
    if not groups:
        opt = _keyed_options(opt, meta)
        return [{**import_recording(path, opt, tab), "group": {}, "options": opt}]
    keys = list(
        zip(
            *(tab.columns[c] * unit if k == "height_m" else tab.text[c] for k, c in groups.items()),
            strict=True,
        )
    )
    order = list(dict.fromkeys(keys))  # the recordings in the order their first rows appear
    index = {key: j for j, key in enumerate(order)}
    which = np.array([index[k] for k in keys], int)
    out = []
    for j, key in enumerate(order):
        rows = np.flatnonzero(which == j)
        group = {k: (float(v) if k == "height_m" else str(v)) for k, v in zip(groups, key, strict=True)}
        sub = replace(
            tab,
            columns={c: v[rows] for c, v in tab.columns.items()},
            text={c: v[rows] for c, v in tab.text.items()},
            lines=tab.lines[rows],
            skipped=tab.skipped if key == order[0] else (),  # the file's skipped lines, reported once
        )
        gopt = replace(opt, height_column=None, **{k: v for k, v in group.items() if k != "test"})
        gopt = _keyed_options(gopt, meta)
        named = (f"{groups[k]} = {v / unit:g}" if k == "height_m" else f"{groups[k]} = {v}" for k, v in group.items())
        where = f"{path} ({', '.join(named)})"
        if "height_m" in group and not group["height_m"] > 0:
            raise ValueError(
                f"{where}: column {opt.height_column!r}: height_m: expected a number > 0, got {group['height_m']:g}"
            )
        out.append({**import_recording(path, gopt, sub, where=where), "group": group, "options": gopt})
    return out


def import_recording(path: Path, opt: TableOptions, tab, *, where: str | None = None) -> dict:
    """One recording, converted to SI, split into loading ramps; in memory.

    ``tab``: the recording's rows as :func:`read_recordings` read them (a :class:`~.tables.Table`); ``where``
    names the recording in messages (default: the file).

    Returns a dict: ``pushes`` (list of dicts with ``cycle``, ``force`` columns, ``unloading`` columns or
    None, ``preload_N``, ``tared_N``, ``rows`` (first and last file line)), ``report`` (what was done).
    """
    from .plausibility import noise_sd, reversal_tolerance
    from .tables import delimiter_name

    prefix = f"{where}: " if where else ""  # a recording of a long table is named in every message
    where = where or str(path)
    height = _positive("height_m", opt.height_m)
    if opt.length_m is None:
        raise ValueError(
            "length_m: expected the stem length"
            + (" (a rough guess with length_unknown: it centres the prior on L)" if opt.length_unknown else "")
            + ", got none"
        )
    length = _positive("length_m", opt.length_m)
    if not height < length:
        raise ValueError(
            f"{prefix}height_m: expected a contact height below the stem length {length:g} m, got {height:g}"
        )
    if opt.time is None:  # no time column: the sample index, which only shapes (matched by time) would read
        t = np.arange(tab.n_rows, dtype=float)
    else:
        t = tab.columns[opt.time] * TIME_UNITS[opt.time_unit]
    F = opt.force_sign * tab.columns[opt.force] * FORCE_UNITS[opt.force_unit]
    if opt.displacement:
        x = tab.columns[opt.displacement] * DISPLACEMENT_UNITS[opt.displacement_unit]
    else:
        arm = _positive("arm_height_m", opt.arm_height_m)
        a = tab.columns[opt.angle] * ANGLE_UNITS[opt.angle_unit]
        x = arm * np.sin(a - a[0])  # the contact advances by H sin(angle - angle at the start)
    x = opt.displacement_sign * x
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0])
        raise ValueError(
            f"{where}, line {tab.lines[k + 1]}: column {opt.time!r}: expected increasing times, got "
            f"{tab.columns[opt.time][k + 1]:g} after {tab.columns[opt.time][k]:g}"
            + (
                " (two tests in one recording? name the column that tells them apart: option test_column)"
                if prefix
                else ""
            )
        )
    if tab.n_rows < 5:
        raise ValueError(f"{where}: expected at least 5 data rows, got {tab.n_rows}")
    segs = split_cycles(x)
    loads = [s for s in segs if s.loading and s.stop - s.start >= 5]
    tol = reversal_tolerance(x)
    loads = [s for s in loads if x[s.stop - 1] - x[s.start] > 2 * tol]
    if not loads:
        backwards = bool(x[int(np.argmax(F))] < x[0] - 2 * tol)  # the force peaks where the sensor went back
        raise ValueError(
            f"{where}: expected at least one loading ramp (displacement advancing), got none"
            + (
                " (the force rises while the displacement falls: a rig that counts the push as negative needs "
                "option displacement_sign -1)"
                if backwards
                else ""
            )
        )
    if opt.cycles == "first":
        loads = loads[:1]
    pushes = []
    for k, s in enumerate(loads, start=1):
        sl = slice(s.start, s.stop)
        xs, Fs, ts = x[sl], F[sl], t[sl]
        on = contact_onset(xs - xs[0], Fs)
        tare = 0.0
        first = 0
        x_on = xs[0]
        if on.observed:  # pre-contact samples: contact starts at the hinge, tare to its baseline
            first = on.index
            x_on = xs[0] + (on.position if on.position is not None else xs[first] - xs[0])
            tare = on.baseline if opt.tare == "auto" else 0.0
        Fk = Fs[first:] - tare
        sd = noise_sd(Fs)
        preload = float(Fk[0]) if Fk[0] > max(5 * sd, 0.02 * max(Fk.max(), 1e-12)) else 0.0
        nxt = next((u for u in segs if not u.loading and u.start == s.stop - 1), None)
        unload = None
        if nxt is not None and nxt.stop - nxt.start >= 2:
            us = slice(nxt.start, nxt.stop)
            unload = {
                "time_s": t[us] - t[0],
                "force_N": F[us] - tare,
                "robot_x_m": x[us] - x_on,
            }
        pushes.append(
            {
                "cycle": k,
                "force": {"time_s": ts[first:] - t[0], "force_N": Fk, "robot_x_m": xs[first:] - x_on},
                "unloading": unload,
                "preload_N": preload,
                "tared_N": float(tare),
                "rows": [int(tab.lines[s.start + first]), int(tab.lines[s.stop - 1])],
            }
        )
    report = {
        "file": str(path),
        "header_line": tab.header_line,
        "delimiter": delimiter_name(tab.delimiter),
        "decimal": tab.decimal,
        "metadata_lines": list(tab.metadata),
        "rows_read": tab.n_rows,
        "rows_skipped": [{"line": ln, "reason": why} for ln, why in tab.skipped],
        "loading_ramps_found": sum(1 for s in segs if s.loading),
        "pushes": [
            {
                "cycle": p["cycle"],
                "rows": p["rows"],
                "samples": int(p["force"]["force_N"].size),
                "peak_force_N": float(p["force"]["force_N"].max()),
                "preload_N": p["preload_N"],
                "tared_N": p["tared_N"],
            }
            for p in pushes
        ],
    }
    return {"pushes": pushes, "report": report, "height_m": height, "length_m": length}


#: the columns a metadata CSV may key its rows by, in this order of precedence: a file's name, or (for long tables,
#: and files whose stem or specimen a flag names) a stem's id or a specimen's name
METADATA_KEYS = ("file", "stem_id", "specimen")


def read_metadata(path) -> dict[str, dict]:
    """A small CSV mapping files, stems or specimens to options (columns as the options' names).

    Rows are keyed by the first of :data:`METADATA_KEYS` the header names: ``file`` (a file's name, the key
    itself), else ``stem_id`` or ``specimen`` (the key ``"stem_id=<id>"`` or ``"specimen=<name>"``: each
    recording of that stem or specimen takes the row's options, e.g. a length per plant of a long table).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise ValueError(f"metadata: expected a readable CSV file, got {type(e).__name__}: {e}") from None
    rows = list(csv.DictReader(text.splitlines()))
    key = next((k for k in METADATA_KEYS if rows and k in rows[0]), None)
    if key is None:
        raise ValueError(
            f"{path}: metadata: expected a header with a column named {', '.join(METADATA_KEYS[:-1])} or "
            f"{METADATA_KEYS[-1]}, got {', '.join(rows[0]) if rows else 'an empty file'}"
        )
    out = {}
    for i, r in enumerate(rows, start=2):
        name = (r.get(key) or "").strip()
        if not name:
            raise ValueError(f"{path}, line {i}: column {key}: expected a {key.replace('_', ' ')}, got an empty cell")
        out[name if key == "file" else f"{key}={name}"] = {
            k.strip(): (v or "").strip() for k, v in r.items() if k and k != key
        }
    return out


def _keyed_options(opt: TableOptions, meta: dict) -> TableOptions:
    """``opt`` with the metadata rows keyed by its stem's id and its specimen's name applied (in that order)."""
    for key in ("stem_id", "specimen"):
        value = getattr(opt, key)
        if value and f"{key}={value}" in meta:
            opt = _file_options(opt, meta[f"{key}={value}"])
    return opt


@dataclass(frozen=True, eq=False)
class TableImport:
    """Datasets made from raw rig tables (in memory) and what was done to each file; ``save`` writes them."""

    documents: tuple  # (specimen name, specimen.json dict, {relative path: columns dict}) per dataset
    report: dict

    @property
    def specimens(self) -> list[str]:
        return [d[0] for d in self.documents]

    def save(self, out, *, overwrite: bool = False) -> Path:
        """One dataset directory per specimen under ``out`` and ``out/import_report.json`` (atomically)."""
        from .io import atomic_dir

        out = Path(out)
        with atomic_dir(out, overwrite) as tmp:
            for name, doc, files in self.documents:
                for rel, cols in files.items():
                    write_csv(tmp / name / rel, cols)
                write_json(tmp / name / "specimen.json", doc)
            write_json(tmp / "import_report.json", self.report)
        return out


def _expand(files) -> list[Path]:
    out = []
    for f in files:
        p = Path(f)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in (".csv", ".tsv", ".txt", ".dat"))
            if not found:
                raise ValueError(f"{p}: expected table files (.csv, .tsv, .txt, .dat) in the folder, got none")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise ValueError(f"{p}: expected a table file or a folder of them, got no such file or directory")
    return out


def _add_recording(specimens: dict, report: dict, p: Path, rec: dict) -> None:
    """File one recording's pushes under its specimen (``specimens``: name -> options, pushes, files, sources)
    and its report under ``report["files"]``."""
    opt = rec["options"]
    split = {k for k in rec["group"] if k in ("stem_id", "condition")}
    # a long table split by stem or condition: one dataset per stem and condition, named by them
    default = "_".join(v for v in (opt.stem_id, opt.condition) if v) if split else ""
    name = opt.specimen or default or p.stem
    spec = specimens.setdefault(name, {"opt": opt, "pushes": [], "files": {}, "sources": []})
    for k in ("stem_id", "condition"):  # one stem under one condition per dataset (docs/format.md)
        if getattr(spec["opt"], k) != getattr(opt, k):
            raise ValueError(
                f"{p}: {k}: expected the same {k} as the other recordings of {name} "
                f"({getattr(spec['opt'], k)!r}), got {getattr(opt, k)!r}"
            )
    if spec["opt"].length_m != opt.length_m:
        raise ValueError(
            f"{p}: length_m: expected the same stem length as the other recordings of {name} "
            f"({spec['opt'].length_m:g} m), got {opt.length_m:g}"
        )
    if p.name not in spec["sources"]:
        spec["sources"].append(p.name)
    multi = len(rec["pushes"]) > 1
    for push in rec["pushes"]:
        pid = f"h{round(rec['height_m'] * 1000):d}" + (f"-c{push['cycle']}" if multi else "")
        taken = {e["id"] for e in spec["pushes"]}
        base, j = pid, 2
        while pid in taken:
            pid, j = f"{base}-{j}", j + 1
        entry = {
            "id": pid,
            "height_m": rec["height_m"],
            "direction": 1,
            "force": f"{pid}/force.csv",
            "cycle": push["cycle"],
            "source_file": p.name,
            "source_rows": push["rows"],
        }
        if "test" in rec["group"]:
            entry["source_test"] = rec["group"]["test"]
        spec["files"][f"{pid}/force.csv"] = push["force"]
        if push["unloading"] is not None:
            entry["unloading"] = f"{pid}/unloading.csv"
            spec["files"][f"{pid}/unloading.csv"] = push["unloading"]
        if push["preload_N"]:
            entry["preload_N"] = push["preload_N"]
        spec["pushes"].append(entry)
    report["files"].append({**rec["report"], **({"group": rec["group"]} if rec["group"] else {}), "specimen": name})


def import_tables(files, options: TableOptions, metadata=None) -> TableImport:
    """Turn raw rig tables into datasets (one per specimen; one push per loading ramp); nothing written.

    ``files``: table files or folders of them. ``metadata``: None, a CSV path or ``{file name: {field: value}}``
    setting per-file options (:data:`METADATA_FIELDS`); keys ``"stem_id=<id>"`` and ``"specimen=<name>"`` set
    a stem's or a specimen's (:func:`read_metadata`). Each dataset records its source files and the
    options used under ``provenance``.
    """
    from dataclasses import asdict

    meta = read_metadata(metadata) if isinstance(metadata, (str, Path)) else dict(metadata or {})
    paths = _expand(files)
    specimens: dict[str, dict] = {}
    report = {"importer": "bayesrod import table", "options": asdict(options), "files": []}
    for p in paths:
        fmeta = meta.get(p.name, meta.get(str(p), {}))
        for rec in read_recordings(p, _file_options(options, fmeta), meta):
            _add_recording(specimens, report, p, rec)
    docs = []
    for name, spec in specimens.items():
        opt = spec["opt"]
        doc = {"format": FORMAT, "specimen": name}
        if opt.species:
            doc["species"] = opt.species
        doc["length_m"] = opt.length_m
        if opt.length_unknown:
            doc["length_m_approximate"] = True
        if opt.stem_id:
            doc["stem_id"] = opt.stem_id
        if opt.condition:
            doc["condition"] = opt.condition
        doc["pushes"] = sorted(spec["pushes"], key=lambda e: (e["height_m"], e["cycle"]))
        doc["provenance"] = {
            "importer": "bayesrod import table",
            "source_files": spec["sources"],
            "options": {k: v for k, v in asdict(opt).items() if v is not None},
            "assumptions": {
                "length_m": f"{opt.length_m:g} m"
                + (" (a rough guess: the length is unknown)" if opt.length_unknown else ""),
                "displacement": "the sensor's advance since contact onset (or since the first sample of a "
                "ramp that starts loaded); probe compliance neglected",
                **(
                    {"time_s": "no time column: the sample index (0, 1, 2, ... s); shapes cannot be matched"}
                    if opt.time is None
                    else {}
                ),
            },
        }
        docs.append((name, doc, spec["files"]))
    return TableImport(tuple(docs), report)

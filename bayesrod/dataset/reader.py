"""Read and validate datasets in the ``bayesrod.dataset/1`` format (docs/format.md, section 1).

``validate_dataset`` lists every problem found; ``read_dataset`` returns typed,
immutable objects or raises :class:`DatasetError` carrying the same list. Each
problem names the file, the field or column, the row where relevant, what was
expected and what was found. Inputs are only ever read.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..physics.lumped import wire_dx_from_elongation
from .model import (
    FORMAT,
    SHARED_DIAMETER_ERRORS,
    Camera,
    Diameters,
    ForceSeries,
    FrameRecord,
    Push,
    Sensor,
    ShapeFrame,
    Specimen,
)

MAX_PER_COLUMN = 5  # row-level problems listed per file and column before summarising
MM_HINT = 20.0  # metres: a stem or height beyond this is almost surely in millimetres

FORCE_REQUIRED = ("time_s", "force_N", "robot_x_m")
FORCE_OPTIONAL = ("wire_elongation_m",)
SHAPE_REQUIRED = ("time_s", "x_m", "z_m")
SHAPE_OPTIONAL = ("sd_m", "observed")
FRAME_COLUMNS = ("frame", "time_s", "rgb", "depth")


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a dataset."""

    file: str
    field: str
    expected: str
    got: str
    row: int | None = None
    severity: str = "error"

    def __str__(self) -> str:
        where = self.file + (f", row {self.row}" if self.row is not None else "")
        tag = "" if self.severity == "error" else f"{self.severity}: "
        return f"{tag}{where}: {self.field}: expected {self.expected}, got {self.got}"


class DatasetError(ValueError):
    """A dataset could not be read; ``problems`` lists every error found."""

    def __init__(self, problems: list[Problem]):
        self.problems = [p for p in problems if p.severity == "error"]
        more = len(self.problems) - 1
        msg = str(self.problems[0]) if self.problems else "invalid dataset"
        if more > 0:
            msg += f" (and {more} more problem{'s' * (more > 1)}; run `bayesrod validate` to list them)"
        super().__init__(msg)


def _fmt(value) -> str:
    text = (
        repr(value) if isinstance(value, str) else json.dumps(value) if not isinstance(value, float) else f"{value:g}"
    )
    return text if len(text) <= 60 else text[:57] + "..."


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


class _Collector:
    def __init__(self, root: Path):
        self.root = root
        self.problems: list[Problem] = []

    def rel(self, path: Path) -> str:
        try:
            return str(path.relative_to(self.root.parent)) if self.root.parent != path else str(path)
        except ValueError:
            return str(path)

    def add(self, file, field, expected, got, row=None, severity="error"):
        self.problems.append(Problem(str(file), field, expected, got, row, severity))

    @property
    def ok(self) -> bool:
        return not any(p.severity == "error" for p in self.problems)

    # ------------------------------------------------------------------ CSV
    def read_csv(self, path: Path, required, optional=(), text_cols=()) -> dict | None:
        name = self.rel(path)
        if not path.is_file():
            self.add(name, "file", "an existing file", "no such file" if not path.exists() else "a directory")
            return None
        try:
            with path.open(newline="", encoding="utf-8-sig") as fh:
                rows = list(csv.reader(fh))
        except (OSError, UnicodeDecodeError) as exc:
            self.add(name, "file", "a readable UTF-8 CSV file", type(exc).__name__ + ": " + str(exc)[:80])
            return None
        rows = [r for r in rows if any(cell.strip() for cell in r)]
        if not rows:
            self.add(name, "header", "a header row naming the columns", "an empty file")
            return None
        header = [h.strip() for h in rows[0]]
        missing = [c for c in required if c not in header]
        for col in missing:
            self.add(name, f"column {col}", "a column of that name in the header", f"columns {', '.join(header)}")
        dupes = sorted({h for h in header if header.count(h) > 1})
        for col in dupes:
            self.add(name, f"column {col}", "each column once", "it repeated in the header")
        if missing or dupes:
            return None
        body = rows[1:]
        if not body:
            self.add(name, "rows", "at least one data row", "only the header")
            return None
        cols = [c for c in list(required) + list(optional) if c in header]
        idx = {c: header.index(c) for c in cols}
        out: dict[str, np.ndarray] = {}
        for col in cols:
            j = idx[col]
            bad = 0
            values = [] if col in text_cols else np.full(len(body), np.nan)
            for i, row in enumerate(body):
                cell = row[j].strip() if j < len(row) else ""
                if col in text_cols:
                    values.append(cell)
                    if not cell:
                        bad += 1
                        if bad <= MAX_PER_COLUMN:
                            self.add(name, f"column {col}", "a file name", "an empty cell", row=i + 1)
                    continue
                try:
                    v = float(cell)
                except ValueError:
                    v = None
                if v is None or not math.isfinite(v):
                    bad += 1
                    if bad <= MAX_PER_COLUMN:
                        got = "an empty cell" if not cell else f"{cell!r}"
                        self.add(name, f"column {col}", "a finite number", got, row=i + 1)
                else:
                    values[i] = v
            if bad > MAX_PER_COLUMN:
                self.add(name, f"column {col}", "finite numbers", f"{bad - MAX_PER_COLUMN} more bad rows not listed")
            out[col] = values
        short = [i + 1 for i, r in enumerate(body) if len(r) < len(header)]
        if short:
            self.add(name, "row length", f"{len(header)} fields per row", f"fewer in rows {_rows(short)}")
        return out

    def increasing(self, name: str, col: str, t: np.ndarray, strict=True) -> None:
        d = np.diff(t)
        bad = np.flatnonzero(~(d > 0) if strict else ~(d >= 0))
        bad = bad[np.isfinite(d[bad])]
        for k in bad[:MAX_PER_COLUMN]:
            self.add(
                name,
                f"column {col}",
                "strictly increasing values" if strict else "non-decreasing values",
                f"{t[k + 1]:g} after {t[k]:g}",
                row=int(k) + 2,
            )
        if bad.size > MAX_PER_COLUMN:
            self.add(name, f"column {col}", "increasing values", f"{bad.size - MAX_PER_COLUMN} more decreases")


def _rows(rows: list[int]) -> str:
    return ", ".join(map(str, rows[:8])) + (f" and {len(rows) - 8} more" if len(rows) > 8 else "")


# --------------------------------------------------------------------------- #
# specimen.json
# --------------------------------------------------------------------------- #
def _load_json(c: _Collector, path: Path):
    name = c.rel(path)
    if not path.is_file():
        c.add(name, "file", "a specimen.json in the dataset directory", "no such file")
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        c.add(name, "file", "UTF-8 JSON", "undecodable bytes")
    except json.JSONDecodeError as exc:
        c.add(name, "JSON", "valid JSON", f"{exc.msg} at line {exc.lineno} column {exc.colno}")
    except OSError as exc:
        c.add(name, "file", "a readable file", str(exc)[:80])
    return None


def _number(c, name, obj, key, *, required=True, positive=False, default=None, label=None):
    label = label or key
    if key not in obj:
        if required:
            c.add(name, label, "a number", "the field missing")
        return default
    v = obj[key]
    if not _is_number(v):
        c.add(name, label, "a finite number", _fmt(v))
        return default
    if positive and v <= 0:
        c.add(name, label, "a value > 0", _fmt(v))
        return default
    return float(v)


def _parse_sensor(c, name, obj) -> Sensor | None:
    if not isinstance(obj, dict):
        c.add(name, "sensor", "an object", _fmt(obj))
        return None
    stype = obj.get("type", "unknown")
    if not isinstance(stype, str):
        c.add(name, "sensor.type", "a string", _fmt(stype))
        stype = "unknown"
    wl = _number(c, name, obj, "wire_length_m", required=False, positive=True, label="sensor.wire_length_m")
    if wl is not None and wl > MM_HINT:
        c.add(name, "sensor.wire_length_m", "metres", f"{wl:g}, which looks like millimetres")
        wl = None
    fr = obj.get("force_range_N")
    rng = None
    if fr is not None:
        if not isinstance(fr, list) or len(fr) != 2 or not all(_is_number(v) for v in fr) or not 0 <= fr[0] < fr[1]:
            c.add(name, "sensor.force_range_N", "[min, max] with 0 <= min < max", _fmt(fr))
        else:
            rng = (float(fr[0]), float(fr[1]))
    return Sensor(type=stype, wire_length_m=wl, force_range_N=rng)


def _parse_camera(c, name, obj) -> Camera | None:
    if not isinstance(obj, dict):
        c.add(name, "camera", "an object with fx, fy, cx, cy, base_px", _fmt(obj))
        return None
    vals = {}
    for key in ("fx", "fy"):
        vals[key] = _number(c, name, obj, key, positive=True, label=f"camera.{key}")
    for key in ("cx", "cy"):
        vals[key] = _number(c, name, obj, key, label=f"camera.{key}")
    bp = obj.get("base_px")
    if not (isinstance(bp, list) and len(bp) == 2 and all(_is_number(v) for v in bp)):
        c.add(name, "camera.base_px", "[u, v] pixel of the base", _fmt(bp) if "base_px" in obj else "the field missing")
        bp = None
    dss = _number(c, name, obj, "depth_scale_sd", required=False, default=0.0, label="camera.depth_scale_sd")
    if dss is not None and not 0 <= dss < 0.5:
        c.add(name, "camera.depth_scale_sd", "a relative sd in [0, 0.5) (0.01 = 1%)", _fmt(dss))
        return None
    if bp is None or any(v is None for v in vals.values()):
        return None
    return Camera(vals["fx"], vals["fy"], vals["cx"], vals["cy"], (float(bp[0]), float(bp[1])), float(dss or 0.0))


def _safe_path(c, name, root: Path, value, field) -> Path | None:
    if not isinstance(value, str) or not value.strip() or "\x00" in value:  # NUL: no path can hold it
        c.add(name, field, "a relative path (string)", _fmt(value))
        return None
    path = (root / value).resolve()
    if Path(value).is_absolute():
        c.add(name, field, "a path relative to the dataset directory", _fmt(value), severity="warning")
    return path


# --------------------------------------------------------------------------- #
# Per-push files
# --------------------------------------------------------------------------- #
def _read_force(c: _Collector, path: Path, sensor: Sensor | None, length: float | None) -> ForceSeries | None:
    cols = c.read_csv(path, FORCE_REQUIRED, FORCE_OPTIONAL)
    if cols is None:
        return None
    name = c.rel(path)
    t = cols["time_s"]
    if t.size < 2:
        c.add(name, "rows", "at least 2 samples", f"{t.size}")
    c.increasing(name, "time_s", t)
    x = cols["robot_x_m"]
    finite = x[np.isfinite(x)]
    if finite.size and length and np.max(np.abs(finite)) > max(MM_HINT, 10 * length):
        c.add(
            name, "column robot_x_m", "metres", f"values up to {np.max(np.abs(finite)):g}, which looks like millimetres"
        )
    wire = cols.get("wire_elongation_m")
    contact = x
    if wire is not None:
        if sensor is None or sensor.wire_length_m is None:
            c.add(
                name,
                "column wire_elongation_m",
                "sensor.wire_length_m in specimen.json to interpret it",
                "no wire length",
            )
        else:
            neg = np.flatnonzero(wire < -1e-9)
            for k in neg[:MAX_PER_COLUMN]:
                c.add(name, "column wire_elongation_m", "a value >= 0 m", f"{wire[k]:g}", row=int(k) + 1)
            contact = x - wire_dx_from_elongation(np.clip(wire, 0, None), sensor.wire_length_m)
    if not all(np.all(np.isfinite(v)) for v in cols.values()):
        return None
    return ForceSeries(t, cols["force_N"], x, wire, contact)


def _check_plausible(c: _Collector, name: str, push_id: str, force: ForceSeries, sensor, length) -> None:
    """The physical checks of :mod:`bayesrod.dataset.plausibility`, named by file and push."""
    from .plausibility import check_push

    for fld, expected, got, row, severity in check_push(
        push_id, force.force_N, force.contact_x_m, length_m=length, sensor=sensor
    ):
        c.add(f"{name} (push {push_id})", fld, expected, got, row=row, severity=severity)


def _read_shapes(c: _Collector, path: Path, length: float | None) -> tuple[ShapeFrame, ...] | None:
    cols = c.read_csv(path, SHAPE_REQUIRED, SHAPE_OPTIONAL)
    if cols is None:
        return None
    name = c.rel(path)
    t = cols["time_s"]
    c.increasing(name, "time_s", t, strict=False)
    if length:
        for col in ("x_m", "z_m"):
            v = cols[col][np.isfinite(cols[col])]
            if v.size and np.max(np.abs(v)) > max(MM_HINT, 5 * length):
                c.add(
                    name, f"column {col}", "metres", f"values up to {np.max(np.abs(v)):g}, which looks like millimetres"
                )
    sd = cols.get("sd_m")
    if sd is not None:
        bad = np.flatnonzero(~(sd > 0) & np.isfinite(sd))
        for k in bad[:MAX_PER_COLUMN]:
            c.add(name, "column sd_m", "a standard deviation > 0 m", f"{sd[k]:g}", row=int(k) + 1)
    seen = cols.get("observed")
    if seen is not None:
        bad = np.flatnonzero((seen != 0) & (seen != 1) & np.isfinite(seen))
        for k in bad[:MAX_PER_COLUMN]:
            c.add(
                name, "column observed", "1 (seen) or 0 (bridged across an occlusion)", f"{seen[k]:g}", row=int(k) + 1
            )
    if not all(np.all(np.isfinite(v)) for v in cols.values()):
        return None
    seen = np.ones(t.size, bool) if seen is None else seen == 1
    frames = []
    for tv in np.unique(t):
        m = (t == tv) & seen
        b = (t == tv) & ~seen
        bridge = None
        if b.any():  # points bridged across an occlusion: kept for plots, never used as data
            bridge = np.stack([cols["x_m"][b], cols["z_m"][b], sd[b] if sd is not None else np.full(b.sum(), np.nan)])
        frames.append(ShapeFrame(float(tv), cols["x_m"][m], cols["z_m"][m], None if sd is None else sd[m], bridge))
    return tuple(frames)


def _read_frames(c: _Collector, folder: Path, check_images: bool) -> tuple[FrameRecord, ...] | None:
    name = c.rel(folder)
    if not folder.is_dir():
        c.add(name, "frames", "a directory holding index.csv", "no such directory")
        return None
    index = folder / "index.csv"
    cols = c.read_csv(index, FRAME_COLUMNS, text_cols=("rgb", "depth"))
    if cols is None:
        return None
    iname = c.rel(index)
    c.increasing(iname, "time_s", cols["time_s"])
    records = []
    for i in range(len(cols["rgb"])):
        rgb, depth = folder / cols["rgb"][i], folder / cols["depth"][i]
        ok = True
        for col, path, kind in (("rgb", rgb, "rgb"), ("depth", depth, "depth")):
            if not path.is_file():
                c.add(iname, f"column {col}", "an existing PNG file", f"{cols[col][i]!r} (no such file)", row=i + 1)
                ok = False
            elif check_images:
                problem = _check_png(path, kind)
                if problem:
                    c.add(iname, f"column {col}", problem[0], problem[1], row=i + 1)
                    ok = False
        if ok and np.isfinite(cols["frame"][i]) and np.isfinite(cols["time_s"][i]):
            records.append(FrameRecord(int(cols["frame"][i]), float(cols["time_s"][i]), rgb, depth))
    return tuple(records)


def _check_png(path: Path, kind: str):
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        return "a readable PNG image", f"{path.name} (unreadable)"
    if kind == "rgb" and not (img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] in (3, 4)):
        return "an 8-bit RGB PNG", f"{path.name}: dtype {img.dtype}, shape {img.shape}"
    if kind == "depth" and not (img.dtype == np.uint16 and img.ndim == 2):
        return "a 16-bit single-channel depth PNG (mm)", f"{path.name}: dtype {img.dtype}, shape {img.shape}"
    return None


# --------------------------------------------------------------------------- #
# Entry points
# --------------------------------------------------------------------------- #
def _read_diameters(c: _Collector, name: str, root: Path, value, length: float | None) -> Diameters | None:
    """``diameters``: a CSV path (s_m, d_m, sd_m[, flag]) or an object of equal-length lists (docs/format.md)."""
    source = "caliper"
    if isinstance(value, str):
        fp = _safe_path(c, name, root, value, "diameters")
        if fp is None:
            return None
        cols = c.read_csv(
            fp,
            ("s_m", "d_m", "sd_m"),
            ("n_frames", "flag", "source", *SHARED_DIAMETER_ERRORS),
            text_cols=("flag", "source"),
        )
        if cols is None:
            return None
        where = c.rel(fp)
        used = np.array([f == "ok" for f in cols["flag"]]) if "flag" in cols else np.ones(cols["s_m"].size, bool)
        source = cols["source"][0] if "source" in cols and cols["source"] else "frames"
        raw_shared = {}  # per error: (value, field, row); the value of the first row not finite or not the first's
        for k in SHARED_DIAMETER_ERRORS:
            if k in cols:
                v = cols[k]
                off = np.flatnonzero(~(np.isfinite(v) & (v == v[0])))
                row = int(off[0]) + 1 if off.size else None
                raw_shared[k] = (float(v[off[0]] if off.size else v[0]), f"column {k}", row)
    elif isinstance(value, dict):
        where = f"{name}: diameters"
        cols = {}
        for k in ("s_m", "d_m", "sd_m"):
            v = value.get(k)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                v = [v]
            if not isinstance(v, list) or not v or not all(_is_number(x) for x in v):
                c.add(name, f"diameters.{k}", "a list of numbers [m]", _fmt(v) if k in value else "the field missing")
                return None
            cols[k] = np.array(v, float)
        if not cols["s_m"].size == cols["d_m"].size == cols["sd_m"].size:
            c.add(name, "diameters", "s_m, d_m and sd_m of equal length", ", ".join(str(cols[k].size) for k in cols))
            return None
        used = np.ones(cols["s_m"].size, bool)
        source = str(value.get("source", "caliper"))
        raw_shared = {k: (value[k], f"diameters.{k}", None) for k in SHARED_DIAMETER_ERRORS if k in value}
    else:
        c.add(name, "diameters", "a CSV path or an object with s_m, d_m, sd_m lists", _fmt(value))
        return None
    ok = True
    for k, cond, expected in (
        ("d_m", lambda a: a > 0, "> 0 [m]"),
        ("sd_m", lambda a: a > 0, "> 0 [m]"),
        ("s_m", lambda a: a >= 0, ">= 0 [m]"),
    ):
        bad = np.flatnonzero(~cond(cols[k]) & used)
        if bad.size:
            c.add(
                where,
                f"column {k}" if isinstance(value, str) else f"diameters.{k}",
                expected,
                _fmt(float(cols[k][bad[0]])),
                row=int(bad[0]) + 1,
            )
            ok = False
    if length is not None:
        beyond = np.flatnonzero((cols["s_m"] >= length) & used)
        if beyond.size:
            c.add(
                where,
                "s_m",
                f"an arc length below length_m ({length:g} m)",
                _fmt(float(cols["s_m"][beyond[0]])),
                row=int(beyond[0]) + 1,
            )
            ok = False
    big = np.flatnonzero((cols["d_m"] > 0.5) & used)
    if big.size:
        c.add(where, "d_m", "metres", f"{cols['d_m'][big[0]]:g}, which looks like millimetres", row=int(big[0]) + 1)
        ok = False
    if not used.any():
        c.add(where, "flag", "at least one row flagged ok", "none")
        ok = False
    if not ok:
        return None
    shared = _shared_diameter_errors(c, where, raw_shared)
    if shared is None:
        return None
    return Diameters(cols["s_m"][used], cols["d_m"][used], cols["sd_m"][used], source, **shared)


def _shared_diameter_errors(c: _Collector, where: str, raw: dict) -> dict | None:
    """The diameters' shared error sds (docs/format.md): each one finite value >= 0 (a CSV repeats it in every
    row; ``raw`` maps the name to (value, field, row): a row is given where a CSV's value is not finite or not
    the first row's), the scale's and the taper's below 0.5."""
    out = {}
    for k, (v, fld, row) in raw.items():
        if row is not None:
            expected = "one finite value repeated in every row" if row > 1 or np.isfinite(v) else "a finite number"
            c.add(where, fld, expected, _fmt(v), row=row)
        elif not (_is_number(v) and v >= 0):
            c.add(where, fld, "a finite number >= 0", _fmt(v))
        elif k in ("shared_scale_sd", "shared_taper_sd") and v >= 0.5:
            c.add(where, fld, "a relative sd below 0.5 (0.01 = 1%)", _fmt(v))
        else:
            out[k] = float(v)
            continue
        return None
    return out


def _read(path, check_images=True) -> tuple[Specimen | None, list[Problem]]:
    root = Path(path)
    c = _Collector(root)
    if not root.exists():
        c.add(str(root), "dataset", "a dataset directory", "no such file or directory")
        return None, c.problems
    if root.is_file():
        if root.name == "specimen.json":
            root = root.parent
            c.root = root
        else:
            c.add(str(root), "dataset", "a directory holding specimen.json", "a file")
            return None, c.problems
    spath = root / "specimen.json"
    doc = _load_json(c, spath)
    if doc is None:
        return None, c.problems
    name = c.rel(spath)
    if not isinstance(doc, dict):
        c.add(name, "top level", "a JSON object", type(doc).__name__)
        return None, c.problems
    fmt = doc.get("format")
    if fmt != FORMAT:
        c.add(name, "format", f'"{FORMAT}"', _fmt(fmt) if "format" in doc else "the field missing")
    spec = doc.get("specimen")
    if not isinstance(spec, str) or not spec.strip():
        c.add(name, "specimen", "a non-empty name", _fmt(spec) if "specimen" in doc else "the field missing")
        spec = None
    species = doc.get("species")
    if species is not None and not isinstance(species, str):
        c.add(name, "species", "a string", _fmt(species))
        species = None
    length = _number(c, name, doc, "length_m", positive=True)
    if length is not None and length > MM_HINT:
        c.add(name, "length_m", "metres", f"{length:g}, which looks like millimetres")
        length = None
    sensor = _parse_sensor(c, name, doc["sensor"]) if "sensor" in doc else None
    camera = _parse_camera(c, name, doc["camera"]) if "camera" in doc else None
    pushes_doc = doc.get("pushes")
    if not isinstance(pushes_doc, list) or not pushes_doc:
        c.add(
            name, "pushes", "a list of at least one push", _fmt(pushes_doc) if "pushes" in doc else "the field missing"
        )
        pushes_doc = []
    seen: set[str] = set()
    pushes = []
    any_frames = False
    for i, pdoc in enumerate(pushes_doc):
        fld = f"pushes[{i}]"
        if not isinstance(pdoc, dict):
            c.add(name, fld, "an object", _fmt(pdoc))
            continue
        pid = pdoc.get("id")
        if not isinstance(pid, str) or not pid.strip():
            c.add(name, f"{fld}.id", "a non-empty string", _fmt(pid) if "id" in pdoc else "the field missing")
            pid = None
        elif pid in seen:
            c.add(name, f"{fld}.id", "a unique push id", f"{pid!r} again")
        else:
            seen.add(pid)
        h = _number(c, name, pdoc, "height_m", positive=True, label=f"{fld}.height_m")
        if h is not None and length is not None and not h < length:
            hint = ", which looks like millimetres" if h > MM_HINT else ""
            c.add(name, f"{fld}.height_m", f"0 < height_m < length_m ({length:g} m)", f"{h:g}{hint}")
            h = None
        direction = pdoc.get("direction", 1)
        if direction not in (1, -1) or isinstance(direction, bool):
            c.add(name, f"{fld}.direction", "+1 or -1", _fmt(direction))
            direction = 1
        files = {}
        force = None
        if "force" not in pdoc:
            c.add(name, f"{fld}.force", "a force.csv path", "the field missing")
        else:
            fp = _safe_path(c, name, root, pdoc["force"], f"{fld}.force")
            if fp is not None:
                files["force"] = pdoc["force"]
                force = _read_force(c, fp, sensor, length)
                if force is not None and pid:
                    _check_plausible(c, c.rel(fp), pid, force, sensor, length)
        shapes = None
        if pdoc.get("shapes") is not None:
            sp = _safe_path(c, name, root, pdoc["shapes"], f"{fld}.shapes")
            if sp is not None:
                files["shapes"] = pdoc["shapes"]
                shapes = _read_shapes(c, sp, length)
        frames = None
        if pdoc.get("frames") is not None:
            any_frames = True
            fp = _safe_path(c, name, root, pdoc["frames"], f"{fld}.frames")
            if fp is not None:
                files["frames"] = pdoc["frames"]
                frames = _read_frames(c, fp, check_images)
        if pid and h is not None and force is not None:
            extra = {
                k: v for k, v in pdoc.items() if k not in ("id", "height_m", "direction", "force", "shapes", "frames")
            }
            files.update({"extra": extra} if extra else {})
            pushes.append(Push(pid, h, force, int(direction), shapes, frames, files))
    if any_frames and "camera" not in doc:
        c.add(name, "camera", "camera intrinsics, because a push has frames", "the field missing")
    diameters = _read_diameters(c, name, root, doc["diameters"], length) if "diameters" in doc else None
    known = {"format", "specimen", "species", "length_m", "sensor", "camera", "pushes", "diameters"}
    extra = {k: v for k, v in doc.items() if k not in known}
    if not c.ok:
        return None, c.problems
    return (
        Specimen(spec, length, tuple(pushes), species, sensor, camera, root, extra, diameters),
        c.problems,
    )


def validate_dataset(path, *, check_images: bool = True) -> list[Problem]:
    """Every problem found in the dataset at ``path`` (errors and warnings)."""
    return _read(path, check_images)[1]


def read_dataset(path, *, check_images: bool = False) -> Specimen:
    """Read a dataset; raise :class:`DatasetError` (a ValueError) listing the problems."""
    spec, problems = _read(path, check_images)
    if spec is None:
        raise DatasetError(problems)
    return spec


def validate_in_memory(ds) -> list[Problem]:
    """Problems of a dataset built in memory (:meth:`Dataset.from_arrays`): the reader's checks, array by array.

    Problems name the push as ``pushes[i]`` and the array as the column it would be written to.
    """
    probs: list[Problem] = []

    def add(where, fld, expected, got, row=None):
        probs.append(Problem(where, fld, expected, got, row))

    L = ds.length_m
    if not (isinstance(ds.specimen, str) and ds.specimen.strip()):
        add("dataset", "specimen", "a non-empty name", _fmt(ds.specimen))
    if not (np.isfinite(L) and L > 0):
        add("dataset", "length_m", "a number > 0", _fmt(L))
        L = None
    if not ds.pushes:
        add("dataset", "pushes", "a list of at least one push", "none")
    seen = set()
    for i, p in enumerate(ds.pushes):
        where = f"pushes[{i}] ({p.id})"
        if p.id in seen:
            add(where, "id", "a unique push id", f"{p.id!r} again")
        seen.add(p.id)
        if not np.isfinite(p.height_m) or p.height_m <= 0 or (L is not None and p.height_m >= L):
            add(where, "height_m", f"0 < height_m < length_m ({_fmt(L)} m)", _fmt(p.height_m))
        f = p.force
        if len(f) < 2:
            add(where, "rows", "at least 2 samples", str(len(f)))
        for col in ("time_s", "force_N", "robot_x_m"):
            v = getattr(f, col)
            bad = np.flatnonzero(~np.isfinite(v))
            for k in bad[:MAX_PER_COLUMN]:
                add(where, f"column {col}", "a finite number", _fmt(v[k]), row=int(k) + 1)
        dt = np.diff(f.time_s)
        bad = np.flatnonzero(~(dt > 0) & np.isfinite(dt))
        for k in bad[:MAX_PER_COLUMN]:
            add(
                where,
                "column time_s",
                "strictly increasing times",
                f"{f.time_s[k + 1]:g} after {f.time_s[k]:g}",
                row=int(k) + 2,
            )
        from .plausibility import check_push

        for fld, expected, got, row, severity in check_push(
            p.id, f.force_N, f.contact_x_m, length_m=L, sensor=ds.sensor
        ):
            probs.append(Problem(where, fld, expected, got, row, severity))
    return probs

"""Typed, immutable observations (docs/format.md, section 1). No I/O here."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FORMAT = "bayesrod.dataset/1"


def _frozen(a) -> NDArray[np.float64]:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Sensor:
    """Force sensor description. ``force_range_N`` is (min, max) measurable force."""

    type: str = "unknown"
    wire_length_m: float | None = None
    force_range_N: tuple[float, float] | None = None


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics [px] and the clamped base's pixel (u, v).

    ``depth_scale_sd`` is the relative sd of the depth sensor's scale (its calibration; 0 when
    taken as exact): every metric length read from the frames shares it.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    base_px: tuple[float, float]
    depth_scale_sd: float = 0.0


@dataclass(frozen=True)
class ForceSeries:
    """One push's force samples, shape (n,) each, SI units.

    ``contact_x_m`` is the horizontal displacement of the contact point since
    first contact: ``robot_x_m`` minus the wire's lateral deflection when the
    wire elongation is given (eq. wire_half_ext), else ``robot_x_m``.
    """

    time_s: NDArray
    force_N: NDArray
    robot_x_m: NDArray
    wire_elongation_m: NDArray | None = None
    contact_x_m: NDArray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        for name in ("time_s", "force_N", "robot_x_m", "wire_elongation_m", "contact_x_m"):
            val = getattr(self, name)
            if val is not None:
                object.__setattr__(self, name, _frozen(val))
        if self.contact_x_m is None:
            object.__setattr__(self, "contact_x_m", self.robot_x_m)

    def __len__(self) -> int:
        return int(self.time_s.size)


@dataclass(frozen=True)
class ShapeFrame:
    """One observed centerline, base to tip: arrays of shape (k,) [m].

    ``bridge`` (3, b) holds x_m, z_m, sd_m of the points a ``shapes.csv`` marks ``observed = 0``
    (bridged across an occlusion by ``bayesrod extract``): kept for plots, never used as data.
    """

    time_s: float
    x_m: NDArray
    z_m: NDArray
    sd_m: NDArray | None = None
    bridge: NDArray | None = None

    def __post_init__(self) -> None:
        for name in ("x_m", "z_m", "sd_m", "bridge"):
            val = getattr(self, name)
            if val is not None:
                object.__setattr__(self, name, _frozen(val))


@dataclass(frozen=True)
class FrameRecord:
    """One RGB-D frame: file paths (absolute) and time."""

    frame: int
    time_s: float
    rgb: Path
    depth: Path


@dataclass(frozen=True)
class Push:
    """One push at a fixed sensor height."""

    id: str
    height_m: float
    force: ForceSeries
    direction: int = 1
    shapes: tuple[ShapeFrame, ...] | None = None
    frames: tuple[FrameRecord, ...] | None = None
    files: dict = field(default_factory=dict, compare=False)


#: the errors every diameter station shares (fields of :class:`Diameters`; CSV columns or inline keys)
SHARED_DIAMETER_ERRORS = ("shared_offset_sd_m", "shared_scale_sd", "shared_taper_sd")


@dataclass(frozen=True)
class Diameters:
    """Measured stem diameters [m] at arc lengths ``s_m`` (k,) from the base, with their sd (k,).

    From the frames (``bayesrod extract``: a profile along the stem) or from calipers (a few
    stations, often only the base). ``source`` says which (``"frames"``, ``"caliper"`` or free text).
    Only the stations a fit uses: rows flagged other than ``ok`` in a diameters file are left out.

    Errors every station shares, on top of each station's own ``sd_m``: an additive offset of sd
    ``shared_offset_sd_m`` [m] (the width method's bias at the edges; a caliper's zero) and a
    relative scale of sd ``shared_scale_sd`` (the depth sensor's scale; a caliper's calibration), and an
    error in the taper the widths read, of relative sd ``shared_taper_sd`` (each width read as
    d (d / d0)^g with g ~ N(0, shared_taper_sd^2): a lens's blur wide against the stem reads thin stations
    differently from thick ones). They do not average down over stations; the fit marginalises all three
    (docs/inference.md).
    """

    s_m: NDArray
    d_m: NDArray
    sd_m: NDArray
    source: str = "caliper"
    shared_offset_sd_m: float = 0.0
    shared_scale_sd: float = 0.0
    shared_taper_sd: float = 0.0

    def __post_init__(self):
        for k in ("s_m", "d_m", "sd_m"):
            object.__setattr__(self, k, _frozen(getattr(self, k)))
        n = self.s_m.shape
        if self.s_m.ndim != 1 or self.d_m.shape != n or self.sd_m.shape != n or n[0] < 1:
            raise ValueError(
                f"diameters: expected s_m, d_m, sd_m of one equal length >= 1, got shapes "
                f"{self.s_m.shape}, {self.d_m.shape}, {self.sd_m.shape}"
            )
        if not (np.all(self.d_m > 0) and np.all(self.sd_m > 0) and np.all(self.s_m >= 0)):
            raise ValueError("diameters: expected d_m > 0, sd_m > 0 and s_m >= 0 [m] in every row")
        for k in SHARED_DIAMETER_ERRORS:
            v = getattr(self, k)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"diameters.{k}: expected a finite number >= 0, got {v!r}")
            object.__setattr__(self, k, float(v))


@dataclass(frozen=True)
class Dataset:
    """A dataset: one stem and its pushes (docs/format.md). Immutable; ``extra`` keeps unknown top-level keys.

    Read one with :func:`bayesrod.load`, build one from memory with :meth:`from_arrays` or
    :meth:`from_frame`, check it with :meth:`validate`, write it with :meth:`save`.
    """

    specimen: str
    length_m: float
    pushes: tuple[Push, ...]
    species: str | None = None
    sensor: Sensor | None = None
    camera: Camera | None = None
    root: Path | None = None
    extra: dict = field(default_factory=dict, compare=False)
    #: measured diameters along the stem (``diameters`` in specimen.json), or None
    diameters: Diameters | None = None

    @property
    def heights_m(self) -> NDArray:
        """Contact height of every push [m], shape (n_pushes,)."""
        return np.array([p.height_m for p in self.pushes])

    def push(self, push_id: str) -> Push:
        for p in self.pushes:
            if p.id == push_id:
                return p
        raise KeyError(push_id)

    @classmethod
    def from_arrays(
        cls,
        *,
        length_m: float,
        height_m,
        displacement_m,
        force_N,
        time_s=None,
        push_id=None,
        specimen: str = "specimen",
        species: str | None = None,
        force_range_N: tuple[float, float] | None = None,
    ) -> Dataset:
        """A forces-only dataset from arrays in memory.

        Parameters
        ----------
        length_m : float
            Stem length L [m].
        height_m : sequence of float, shape (n_pushes,)
            Contact height of each push [m].
        displacement_m, force_N : sequence of arrays, one (n_i,) array per push
            Horizontal contact displacement since first contact [m] and the measured force [N].
        time_s : sequence of arrays or None
            Sample times [s]; default the sample index.
        push_id : sequence of str or None
            Push ids; default ``h<height in mm>``.
        """
        heights = np.atleast_1d(np.asarray(height_m, dtype=float))
        if heights.ndim != 1:
            raise ValueError(f"height_m: expected one height per push, got shape {heights.shape}")
        n = heights.size
        D_list, F_list = _per_push(displacement_m, n, "displacement_m"), _per_push(force_N, n, "force_N")
        T_list = _per_push(time_s, n, "time_s") if time_s is not None else [None] * n
        ids = list(push_id) if push_id is not None else [f"h{round(h * 1000):d}" for h in heights]
        if len(ids) != n:
            raise ValueError(f"push_id: expected {n} ids (one per height), got {len(ids)}")
        pushes = []
        for i in range(n):
            D, F = D_list[i], F_list[i]
            if D.shape != F.shape:
                raise ValueError(
                    f"force_N[{i}]: expected as many samples as displacement_m[{i}] ({D.size}), got {F.size}"
                )
            T = np.arange(D.size, dtype=float) if T_list[i] is None else T_list[i]
            if T.shape != D.shape:
                raise ValueError(f"time_s[{i}]: expected {D.size} samples, got {T.size}")
            pushes.append(Push(str(ids[i]), float(heights[i]), ForceSeries(T, F, D)))
        sensor = Sensor("unknown", None, tuple(force_range_N)) if force_range_N is not None else None
        return cls(str(specimen), float(length_m), tuple(pushes), species, sensor)

    @classmethod
    def from_frame(
        cls,
        df,
        *,
        length_m: float,
        height: str = "height_m",
        displacement: str = "robot_x_m",
        force: str = "force_N",
        time: str | None = "time_s",
        push: str | None = None,
        specimen: str = "specimen",
        species: str | None = None,
    ) -> Dataset:
        """A forces-only dataset from a long table (pandas DataFrame or a mapping of columns), one row per sample.

        Pushes are the groups of ``push`` (default: of ``height``), in order of first appearance. Column
        names are parameters; a missing column is a ValueError naming it.
        """
        cols = {}
        for role, name in (
            ("height", height),
            ("displacement", displacement),
            ("force", force),
            ("time", time),
            ("push", push),
        ):
            if name is None:
                continue
            if name not in df:
                have = ", ".join(map(str, list(df.keys())))
                raise ValueError(f"{role}: expected a column named {name!r}, got columns {have}")
            cols[role] = np.asarray(df[name])
        key = cols.get("push", cols["height"])
        _, first = np.unique(key, return_index=True)
        groups = [key[i] for i in sorted(first)]
        H, D, F, T, ids = [], [], [], [], []
        for g in groups:
            m = key == g
            hs = np.unique(cols["height"][m].astype(float))
            if hs.size != 1:
                raise ValueError(f"{height}: expected one height per push, got {hs.tolist()} in push {g!r}")
            H.append(float(hs[0]))
            D.append(cols["displacement"][m].astype(float))
            F.append(cols["force"][m].astype(float))
            T.append(cols["time"][m].astype(float) if "time" in cols else None)
            ids.append(str(g) if "push" in cols else None)
        return cls.from_arrays(
            length_m=length_m,
            height_m=H,
            displacement_m=D,
            force_N=F,
            time_s=T if "time" in cols else None,
            push_id=ids if "push" in cols else None,
            specimen=specimen,
            species=species,
        )

    def validate(self) -> list:
        """Every problem found (a list of :class:`~bayesrod.dataset.Problem`; empty when valid).

        A dataset read from disk is checked file by file (as ``bayesrod validate``); one built in memory,
        array by array.
        """
        from .reader import validate_dataset, validate_in_memory

        if self.root is not None and Path(self.root, "specimen.json").is_file():
            return validate_dataset(self.root)
        return validate_in_memory(self)

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write the dataset directory ``path`` (docs/format.md) atomically; returns the path."""
        from .writer import write_dataset

        return write_dataset(self, path, overwrite=overwrite)


#: the name the code used before the public API (kept: old scripts import it)
Specimen = Dataset


def _per_push(values, n: int, name: str) -> list[NDArray]:
    if n == 1 and (
        (isinstance(values, np.ndarray) and values.ndim == 1)
        or (isinstance(values, (list, tuple)) and len(values) and np.isscalar(values[0]))
    ):
        values = [values]  # one push given as one flat array
    try:
        out = [np.asarray(v, dtype=float).ravel() for v in values]
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected one array of numbers per push, got {type(values).__name__}") from None
    if len(out) != n:
        raise ValueError(f"{name}: expected {n} arrays (one per push), got {len(out)}")
    return out

"""Typed, immutable observations (CONTRACT.md section 1). No I/O here."""

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
    """Pinhole intrinsics [px] and the clamped base's pixel (u, v)."""

    fx: float
    fy: float
    cx: float
    cy: float
    base_px: tuple[float, float]


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


@dataclass(frozen=True)
class Specimen:
    """A dataset: one stem and its pushes. ``extra`` keeps unknown top-level keys."""

    specimen: str
    length_m: float
    pushes: tuple[Push, ...]
    species: str | None = None
    sensor: Sensor | None = None
    camera: Camera | None = None
    root: Path | None = None
    extra: dict = field(default_factory=dict, compare=False)

    @property
    def heights_m(self) -> NDArray:
        return np.array([p.height_m for p in self.pushes])

    def push(self, push_id: str) -> Push:
        for p in self.pushes:
            if p.id == push_id:
                return p
        raise KeyError(push_id)

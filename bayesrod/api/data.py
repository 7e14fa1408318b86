"""Datasets in: :func:`load` from disk, :func:`simulate` from the forward model."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dataset.model import Dataset, ForceSeries, Push, Sensor, ShapeFrame
from ..physics.effects import Effects


def _demo_dataset() -> Path:
    from importlib import resources

    return Path(str(resources.files("bayesrod") / "data" / "default"))


#: the bundled twig dataset (three heights, forces and centerlines; what ``bayesrod demo`` fits)
DEMO_DATASET: Path = _demo_dataset()


def load(path) -> Dataset:
    """Read and validate a dataset directory (docs/format.md).

    Raises
    ------
    bayesrod.dataset.DatasetError
        (a ValueError) listing every problem found, each with file, field, row and what was expected.
    """
    from ..dataset import read_dataset

    if not isinstance(path, (str, Path)):
        raise TypeError(f"path: expected a dataset directory path, got {type(path).__name__}")
    return read_dataset(path)


@dataclass(frozen=True)
class SimulatedDataset(Dataset):
    """A simulated dataset in memory; :meth:`save` also writes the noise-free shapes and, if asked, RGB-D frames."""

    simulation: tuple = field(default=(), compare=False, repr=False)
    #: the pushes as simulated: a copy whose pushes were replaced since is saved as what it holds
    built_pushes: tuple = field(default=(), compare=False, repr=False)

    def save(self, path, *, overwrite: bool = False, frames: bool = False, arm: str = "leading") -> Path:
        """Write the dataset directory ``path`` atomically (docs/format.md).

        ``frames=True`` renders RGB-D frames of every push (docs/vision.md); ``arm`` places the bar holding
        the probe: ``leading`` (hides the stem the push bends forward) or ``trailing``.
        """
        from ..dataset.io import atomic_dir
        from ..dataset.simulate import write_simulated

        if arm not in ("leading", "trailing"):
            raise ValueError(f"arm: expected leading or trailing, got {arm!r}")
        cfg, pushes = self.simulation
        if self.pushes is not self.built_pushes or self.length_m != cfg.length_m:
            # changed since it was simulated (dataclasses.replace): write what it holds now, as any dataset
            if frames:
                raise ValueError(
                    "frames: expected the dataset as simulated (frames are rendered from the simulation), got "
                    "one whose pushes or length were changed since"
                )
            return Dataset.save(self, path, overwrite=overwrite)
        camera = None
        if frames:
            from ..vision.render import default_camera

            camera = default_camera(cfg.length_m)
        with atomic_dir(path, overwrite) as tmp:
            extra = {k: self.extra[k] for k in GROUP_KEYS if k in self.extra}
            write_simulated(cfg, list(pushes), tmp, frames=frames, camera=camera, arm=arm, extra=extra)
        return Path(path)


def simulate(
    preset_or_stem: str | Mapping = "twig",
    *,
    seed: int = 0,
    noise: str = "default",
    effects: Effects | Mapping | None = None,
    heights_m: Sequence[float] | None = None,
    progress: bool = False,
    noise_model=None,
    config_overrides: Mapping | None = None,
    noise_rho: float = 0.0,
) -> SimulatedDataset:
    """A synthetic dataset from the forward elastica with measurement noise (docs/data.md).

    Parameters
    ----------
    preset_or_stem : str or mapping
        A preset name (``twig``, ``grass``) or a stem ``{"EI0": .., "p": .., "length_m": .., "heights_m": [..]}``
        (optional ``species``, ``specimen``; the noise then follows the twig preset's).
    seed : int
        Random seed (the same seed gives the same data).
    noise : {"default", "none"}
        The preset's measurement noise, or none.
    effects : Effects or mapping
        Model effects switched on (docs/model.md), e.g. ``{"base_compliance": 40.0}``.
    heights_m : sequence of float or None
        Contact heights [m]; default the preset's (for a stem mapping without ``heights_m``: 0.56, 0.69 and
        0.81 of its length).
    noise_rho : float
        Lag-1 correlation of AR(1) force noise (marginal sd as the preset's), in (-1, 1); 0 is independent.
    noise_model : bayesrod.dataset.simulate.NoiseModel or None
        Explicit noise (overrides ``noise``), e.g. for calibration studies.
    config_overrides : mapping or None
        Further :class:`~bayesrod.dataset.simulate.SimConfig` fields (samples per push, frames, ...).
    """
    from ..dataset.simulate import WIRE_LENGTH, SimConfig, sensor_range, truth_record
    from ..dataset.simulate import simulate as simulate_pushes
    from ..physics.lumped import wire_dx_from_elongation
    from ._common import progress_enabled

    eff = effects if isinstance(effects, Effects) else Effects.from_mapping(dict(effects or {}))
    overrides = {}
    if isinstance(preset_or_stem, str):
        base = preset_or_stem
    elif isinstance(preset_or_stem, Mapping):
        base = "twig"
        stem = dict(preset_or_stem)
        missing = [k for k in ("EI0", "p", "length_m") if k not in stem]
        if missing:
            raise ValueError(f"preset_or_stem: expected keys EI0, p, length_m, got none for {', '.join(missing)}")
        overrides = {k: stem[k] for k in ("EI0", "p", "length_m", "species", "specimen") if k in stem}
        for k in ("EI0", "length_m"):
            if not (np.isfinite(float(overrides[k])) and float(overrides[k]) > 0):
                raise ValueError(f"preset_or_stem.{k}: expected a number > 0, got {overrides[k]!r}")
        if "heights_m" in stem and heights_m is None:
            heights_m = stem["heights_m"]
        if "specimen" not in overrides:
            overrides["specimen"] = f"stem-sim-{seed}"
        if heights_m is None:
            heights_m = tuple(float(overrides["length_m"]) * f for f in (0.56, 0.69, 0.81))
    else:
        raise TypeError(f"preset_or_stem: expected a preset name or a mapping, got {type(preset_or_stem).__name__}")
    if heights_m is not None:
        overrides["heights_m"] = tuple(float(h) for h in heights_m)
    cfg = SimConfig.from_preset(base, seed=seed, noise=noise, effects=eff, **overrides)
    if noise_rho:
        if not (isinstance(noise_rho, (int, float)) and -1 < noise_rho < 1):
            raise ValueError(f"noise_rho: expected a correlation in (-1, 1), got {noise_rho!r}")
        from dataclasses import replace as _replace

        noise_model = _replace(noise_model or cfg.noise, force_rho=float(noise_rho))
    if noise_model is not None or config_overrides:
        from dataclasses import replace

        cfg = replace(
            cfg, **({"noise": noise_model} if noise_model is not None else {}), **dict(config_overrides or {})
        )
    for h in cfg.heights_m:
        if not (np.isfinite(h) and 0 < h < cfg.length_m):
            raise ValueError(f"heights_m: expected 0 < height < length ({cfg.length_m:g} m), got {h:g}")
    sim = simulate_pushes(cfg, progress=progress_enabled(progress))
    pushes = []
    for sp in sim:
        contact = sp.robot_x_m - wire_dx_from_elongation(np.clip(sp.wire_elongation_m, 0, None), WIRE_LENGTH)
        force = ForceSeries(sp.time_s, sp.force_N, sp.robot_x_m, sp.wire_elongation_m, contact)
        frames = []
        sd = cfg.noise.shape_sd_m if cfg.noise.shape_sd_reported_m is None else cfg.noise.shape_sd_reported_m
        for k, t in enumerate(sp.frame_time_s):
            seen = np.isfinite(sp.shapes_obs[k, 0])
            frames.append(
                ShapeFrame(
                    float(t),
                    sp.shapes_obs[k, 0, seen],
                    sp.shapes_obs[k, 1, seen],
                    np.full(seen.sum(), sd) if cfg.noise.shape_sd_m > 0 else None,
                )
            )
        pushes.append(Push(sp.id, float(sp.height_m), force, 1, tuple(frames)))
    truth = truth_record(cfg)  # as the dataset's files record it
    pushes = tuple(pushes)
    return SimulatedDataset(
        specimen=cfg.specimen,
        length_m=cfg.length_m,
        pushes=pushes,
        species=cfg.species,
        sensor=Sensor("wire", WIRE_LENGTH, sensor_range(cfg, sim)),
        extra={"truth": truth},
        simulation=(cfg, tuple(sim)),
        built_pushes=pushes,
    )


#: the specimen.json keys that make datasets one stem under several conditions (docs/format.md)
GROUP_KEYS = ("stem_id", "condition")


def simulate_group(
    preset: str = "twig",
    *,
    conditions: Mapping[str, float],
    stem_id: str = "stem-1",
    seed: int = 0,
    heights_m: Sequence[float] | None = None,
    noise_rho: float | Mapping[str, float] = 0.0,
    stem_change: Mapping[str, float] | None = None,
    config_overrides: Mapping | None = None,
) -> tuple[SimulatedDataset, ...]:
    """One stem pushed under several anchorage conditions (forces; docs/data.md, "A stem under conditions").

    Parameters
    ----------
    preset : str
        The stem (``twig``, ``grass``): EI0, p, L and default heights.
    conditions : mapping of str to float
        Condition name -> base spring stiffness k_b [N m/rad] (``math.inf``: a rigid clamp), in order.
    stem_id : str
        Written to every dataset's specimen.json with its ``condition``.
    seed : int
        Condition i is simulated with seed ``seed + i``: replicates of a study take seeds at least
        ``len(conditions)`` apart (seeds s and s + 1 share all but one condition's noise draws).
    heights_m : sequence of float or None
        Contact heights of every condition; default the preset's.
    noise_rho : float or mapping of str to float
        Lag-1 correlation of the AR(1) force noise: one for every condition, or condition -> correlation
        (conditions not named: 0; rigs whose noise differs between conditions).
    stem_change : mapping of str to float or None
        Condition -> factor on EI0 (the stem itself changed: e.g. ``{"dry": 0.7}``); default 1.
    config_overrides : mapping or None
        Further SimConfig fields (e.g. ``{"n_frames_engaged": 2}`` to skip most shapes).

    Returns
    -------
    tuple of SimulatedDataset
        One per condition; ``extra`` holds ``stem_id``, ``condition`` and the condition's ``truth``.
    """
    import math
    from dataclasses import replace

    from ..physics.presets import get_preset

    if not conditions:
        raise ValueError("conditions: expected at least one condition name -> base stiffness, got none")
    base = get_preset(preset)
    stem_change = dict(stem_change or {})
    unknown = sorted(set(stem_change) - set(conditions))
    if unknown:
        raise ValueError(f"stem_change: expected condition names from conditions, got {unknown[0]!r}")
    rho_of = dict(noise_rho) if isinstance(noise_rho, Mapping) else dict.fromkeys(conditions, noise_rho)
    unknown = sorted(set(rho_of) - set(conditions))
    if unknown:
        raise ValueError(f"noise_rho: expected condition names from conditions, got {unknown[0]!r}")
    out = []
    for i, (cond, kb) in enumerate(conditions.items()):
        kb = float(kb)
        if not kb > 0:
            raise ValueError(f"conditions.{cond}: expected a base stiffness > 0 N m/rad (inf: a clamp), got {kb}")
        ei0 = float(dict(config_overrides or {}).get("EI0", base["EI0"]))  # a stem of the study's own EI0
        change = {"EI0": ei0 * float(stem_change.get(cond, 1.0)), "specimen": f"{stem_id}-{cond}"}
        ds = simulate(
            preset,
            seed=seed + i,
            effects={"base_compliance": kb} if math.isfinite(kb) else None,
            heights_m=heights_m,
            noise_rho=float(rho_of.get(cond, 0.0)),
            config_overrides={**dict(config_overrides or {}), **change},
        )
        out.append(replace(ds, extra={**ds.extra, "stem_id": stem_id, "condition": cond}))
    return tuple(out)


def import_table(files, *, metadata=None, **options):
    """Raw rig tables to datasets (docs/data.md, "Raw rig tables"); nothing written until ``.save(out)``.

    Parameters
    ----------
    files : path or sequence of paths
        Table files (CSV, TSV, semicolon with decimal comma; metadata lines above the header are fine) or
        folders of them.
    metadata : path, mapping or None
        Per-file options: a CSV with a column ``file`` (or ``stem_id`` or ``specimen``: per stem or specimen),
        or ``{file name: {option: value}}`` (keys ``"stem_id=<id>"``, ``"specimen=<name>"`` likewise).
    **options
        As :class:`bayesrod.dataset.importers.TableOptions`: ``force`` and ``time`` (column names; without
        ``time`` the sample index is the time, for forces-only fits), either ``displacement`` or ``angle`` with
        ``arm_height_m``; units ``time_unit`` (s, ms, min), ``force_unit`` (N, mN, kN, gf, kgf, lbf, ozf),
        ``displacement_unit`` (m, cm, mm, um, in), ``angle_unit`` (deg, rad); ``height_m``, ``length_m``,
        ``length_unknown``, ``specimen``, ``species``, ``stem_id``, ``condition``, ``header_row``, ``cycles``
        (``all``: every loading ramp a push; ``first``), ``force_sign`` and ``displacement_sign`` (-1 where the
        rig counts the push as negative), ``tare`` (auto, none). A long table of many pushes:
        ``specimen_column``, ``stem_id_column``, ``condition_column``, ``test_column`` (text ids) and
        ``height_column`` (with ``height_unit``, in place of ``height_m``) name the columns whose values split
        it; rows sharing them are one recording.

    Returns
    -------
    bayesrod.dataset.importers.TableImport
        ``.specimens``, ``.report`` and ``.save(out)``.
    """
    from ..dataset.importers import TableOptions, import_tables

    if isinstance(files, (str, Path)):
        files = [files]
    try:
        opt = TableOptions(**options)
    except TypeError as e:
        raise TypeError(f"options: {e}") from None
    return import_tables(files, opt, metadata)

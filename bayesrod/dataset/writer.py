"""Write a :class:`~bayesrod.dataset.model.Dataset` as a ``bayesrod.dataset/1`` directory (docs/format.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .io import atomic_dir, write_csv, write_json
from .model import FORMAT, SHARED_DIAMETER_ERRORS


def dataset_document(ds) -> dict:
    """specimen.json's content for ``ds`` (push files at ``<id>/force.csv`` and ``<id>/shapes.csv``)."""
    doc = {"format": FORMAT, "specimen": ds.specimen}
    if ds.species is not None:
        doc["species"] = ds.species
    doc["length_m"] = ds.length_m
    if ds.sensor is not None:
        s = {"type": ds.sensor.type}
        if ds.sensor.wire_length_m is not None:
            s["wire_length_m"] = ds.sensor.wire_length_m
        if ds.sensor.force_range_N is not None:
            s["force_range_N"] = list(ds.sensor.force_range_N)
        doc["sensor"] = s
    if ds.camera is not None:
        c = ds.camera
        doc["camera"] = {"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "base_px": list(c.base_px)}
        if c.depth_scale_sd:
            doc["camera"]["depth_scale_sd"] = c.depth_scale_sd
    doc["pushes"] = []
    for p in ds.pushes:
        entry = {"id": p.id, "height_m": p.height_m, "direction": p.direction, "force": f"{p.id}/force.csv"}
        if p.shapes:
            entry["shapes"] = f"{p.id}/shapes.csv"
        entry.update(p.files.get("extra", {}) if isinstance(p.files, dict) else {})
        doc["pushes"].append(entry)
    if ds.diameters is not None:
        doc["diameters"] = "diameters.csv"
    doc.update(ds.extra)
    return doc


def write_dataset(ds, path, *, overwrite: bool = False) -> Path:
    """Write ``ds`` into the directory ``path`` (atomically: all of it or nothing); returns the path.

    Frames are not copied: a dataset written here holds forces and centerlines.
    """
    path = Path(path)
    with atomic_dir(path, overwrite) as tmp:
        for p in ds.pushes:
            f = p.force
            cols = {"time_s": f.time_s, "force_N": f.force_N, "robot_x_m": f.robot_x_m}
            if f.wire_elongation_m is not None:
                cols["wire_elongation_m"] = f.wire_elongation_m
            write_csv(tmp / p.id / "force.csv", cols)
            if p.shapes:
                rows = {"time_s": [], "x_m": [], "z_m": [], "sd_m": []}
                has_sd = all(fr.sd_m is not None for fr in p.shapes)
                for fr in p.shapes:
                    rows["time_s"].append(np.full(fr.x_m.size, fr.time_s))
                    rows["x_m"].append(fr.x_m)
                    rows["z_m"].append(fr.z_m)
                    if has_sd:
                        rows["sd_m"].append(fr.sd_m)
                cols = {k: np.concatenate(v) for k, v in rows.items() if v}
                write_csv(tmp / p.id / "shapes.csv", cols)
        if ds.diameters is not None:
            dm = ds.diameters
            source = np.array([dm.source] * dm.s_m.size, dtype=object)
            cols = {"s_m": dm.s_m, "d_m": dm.d_m, "sd_m": dm.sd_m, "source": source}
            for k in SHARED_DIAMETER_ERRORS:
                if getattr(dm, k):
                    cols[k] = np.full(dm.s_m.size, getattr(dm, k))
            write_csv(tmp / "diameters.csv", cols)
        write_json(tmp / "specimen.json", dataset_document(ds))
    return path

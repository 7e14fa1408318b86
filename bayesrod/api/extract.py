"""``bayesrod.extract``: the vision pipeline over a dataset's frames; returns an :class:`Extraction`.

The per-frame algorithm is :mod:`bayesrod.vision.extract`. ``Extraction.save``
writes a copy of the dataset. The copy holds every input file unchanged; each push with ``frames`` gains
``<push>/shapes_extracted.csv`` (time_s, x_m, z_m, sd_m, observed) and ``shapes`` points
to it; ``observed`` is 1 for points seen in the image and 0 for points of the spline's
bridge across an occlusion (probe, arm), which readers keep apart from the data
(a pre-existing ``shapes`` entry is kept as ``shapes_original``).
``extract_report.json`` lists every frame, its extracted length and the frames
skipped with the reason; ``figures/extract_<push>.png`` overlays mask,
skeleton and centerline on the RGB frame.
"""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from ..dataset.model import Dataset, ShapeFrame
from ..vision.width import DiameterProfile
from ._common import DocResult, plain_json

log = logging.getLogger("bayesrod")


def _load(rec):
    import cv2

    bgr = cv2.imread(str(rec.rgb), cv2.IMREAD_COLOR)
    depth = cv2.imread(str(rec.depth), cv2.IMREAD_UNCHANGED)
    if bgr is None:
        raise ValueError(f"{rec.rgb}: expected an 8-bit RGB PNG, got an unreadable file")
    if depth is None or depth.dtype != np.uint16:
        raise ValueError(
            f"{rec.depth}: expected a 16-bit depth PNG in mm, got {None if depth is None else depth.dtype}"
        )
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), depth


@dataclass(frozen=True, eq=False)
class Extraction(DocResult):
    """Centerlines extracted from a dataset's RGB-D frames.

    ``columns[push_id]`` holds the points of every extracted frame (``time_s``, ``x_m``, ``z_m``, ``sd_m``
    [m] and ``observed``: 1 seen, 0 bridged across an occlusion); ``doc`` is ``extract_report.json``.
    ``dataset`` is the input dataset with these centerlines as its shapes, ready for :func:`bayesrod.fit`.
    """

    source: Dataset = field(repr=False)
    columns: Mapping[str, Mapping[str, NDArray]] = field(repr=False)
    doc: Mapping = field(repr=False)
    examples: Mapping = field(repr=False, default_factory=dict)
    #: the stem's diameter along s, from the silhouettes of every extracted frame (:mod:`bayesrod.vision.width`)
    diameters: DiameterProfile | None = field(repr=False, default=None)

    @property
    def dataset(self) -> Dataset:
        """The input dataset whose pushes with frames carry the extracted centerlines as ``shapes``."""
        pushes = []
        for p in self.source.pushes:
            cols = self.columns.get(p.id)
            if cols is None:
                pushes.append(p)
                continue
            frames = []
            for t in np.unique(cols["time_s"]):
                m = cols["time_s"] == t
                seen = m & (cols["observed"] == 1)
                br = m & (cols["observed"] == 0)
                bridge = np.stack([cols["x_m"][br], cols["z_m"][br], cols["sd_m"][br]]) if br.any() else None
                frames.append(ShapeFrame(float(t), cols["x_m"][seen], cols["z_m"][seen], cols["sd_m"][seen], bridge))
            pushes.append(replace(p, shapes=tuple(frames)))
        out = replace(self.source, pushes=tuple(pushes))
        dp = self.diameters
        if dp is not None and dp.ok.any():
            out = replace(out, diameters=dp.to_diameters())
        return out

    def plot(self, push_id: str | None = None, ax=None):
        """The example frame of a push with mask, skeleton, path and the written points; returns the artists."""
        from ..report.plots import plot_extraction

        if not self.examples:
            raise ValueError("push_id: expected a push with an extracted frame, got none extracted")
        push_id = push_id or next(iter(self.examples))
        if push_id not in self.examples:
            raise ValueError(f"push_id: expected one of {', '.join(self.examples)}, got {push_id!r}")
        rgb, line, _, direction = self.examples[push_id]
        return plot_extraction(rgb, line, ax=ax, camera=_camera_dict(self.source), direction=direction)

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write a copy of the input dataset whose pushes gain ``shapes_extracted.csv`` (atomically).

        The copy holds every input file unchanged (a pre-existing ``shapes`` entry is kept as
        ``shapes_original``), plus ``extract_report.json`` and ``figures/extract_<push>.png``.
        """
        from ..dataset.io import atomic_dir, write_bytes_atomic, write_csv, write_json
        from ..report.figures import render
        from ..report.plots import plot_extraction

        src = Path(self.source.root)
        doc = json.loads((src / "specimen.json").read_text())
        path = Path(path)
        with atomic_dir(path, overwrite) as tmp:
            shutil.copytree(src, tmp, dirs_exist_ok=True)
            for pid, cols in self.columns.items():
                name = f"{pid}/shapes_extracted.csv"
                write_csv(tmp / name, {k: cols[k] for k in ("time_s", "x_m", "z_m", "sd_m", "observed")})
                for pd in doc["pushes"]:
                    if pd["id"] == pid:
                        if pd.get("shapes"):
                            pd["shapes_original"] = pd["shapes"]
                        pd["shapes"] = name
            for pid, (rgb, line, frame, direction) in self.examples.items():

                def draw(ax, rgb=rgb, line=line, frame=frame, direction=direction, pid=pid):
                    plot_extraction(rgb, line, ax=ax, camera=doc.get("camera"), direction=direction)
                    ax.set_title(f"{pid}, frame {frame}: " + ax.get_title())

                write_bytes_atomic(tmp / "figures" / f"extract_{pid}.png", render(draw, 8, 6, dpi=90))
            (tmp / "figures").mkdir(exist_ok=True)
            dp = self.diameters
            if dp is not None and np.isfinite(dp.d_m).any():
                write_csv(tmp / "diameters_extracted.csv", dp.columns())
                if doc.get("diameters") is not None:
                    doc["diameters_original"] = doc["diameters"]
                doc["diameters"] = "diameters_extracted.csv"
            write_json(tmp / "specimen.json", doc)
            write_json(tmp / "extract_report.json", self.to_dict())
        return path


def _camera_dict(ds) -> dict | None:
    c = ds.camera
    return None if c is None else {"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "base_px": list(c.base_px)}


def extract(dataset, *, progress: bool = True, width_colour_model: str = "auto") -> Extraction:
    """Extract centerlines (with per-point sd) from every push with RGB-D frames (docs/vision.md).

    Parameters
    ----------
    dataset : path or Dataset
        A dataset whose pushes have ``frames`` (read from disk: the frames are files).
    progress : bool
        A progress bar, only on a terminal or in a notebook.
    width_colour_model : {"auto", "projection", "unmixing"}
        How the diameter profile reads coverage from colour (:func:`bayesrod.vision.width.width_profile`);
        ``unmixing`` for round stems with strong shading; ``auto`` (default) chooses on the first extracted
        frame (:func:`bayesrod.vision.width.choose_colour_model`) and uses the choice for every frame. The
        choice and why: ``report["diameters"]["colour_model"]``.
    """
    from ..vision.width import COLOUR_CHOICES

    if width_colour_model not in COLOUR_CHOICES:
        raise ValueError(f"width_colour_model: expected one of {', '.join(COLOUR_CHOICES)}, got {width_colour_model!r}")
    from tqdm.auto import tqdm

    from ..vision.extract import ExtractionError, extract_frame
    from ..vision.width import (
        BLUR_RATIO_OK,
        BLUR_WARN_SCALE_SD,
        RESOLVED_PX,
        SPACING_PX,
        THIN_PX,
        ColourChoice,
        blur_scale_sd,
        choose_colour_model,
        combine_profiles,
        thin_scale_sd,
        variant_scale_sd,
        width_profile,
    )
    from ._common import as_dataset, progress_enabled

    spec = as_dataset(dataset)
    camera = _camera_dict(spec)
    pushes = [p for p in spec.pushes if p.frames]
    if not pushes:
        where = Path(spec.root) / "specimen.json" if spec.root is not None else "dataset"
        raise ValueError(f"{where}: expected at least one push with 'frames', got none")
    report = {"dataset": str(Path(spec.root).resolve()) if spec.root else None, "pushes": {}}
    columns, examples = {}, {}
    stations, widths = None, []
    colour = None if width_colour_model == "auto" else ColourChoice(width_colour_model, np.nan, np.nan, 0, "given")
    total = sum(len(p.frames) for p in pushes)
    bar = tqdm(total=total, desc="extracting frames", unit="frame", disable=not progress_enabled(progress), leave=False)
    for push in pushes:
        cols = {"time_s": [], "x_m": [], "z_m": [], "sd_m": [], "observed": []}
        rows, skipped, plane, best = [], [], None, None
        for rec in push.frames:
            rgb, depth = _load(rec)
            try:
                line = extract_frame(
                    rgb, depth, camera, direction=push.direction, plane_depth_m=plane, max_length_m=spec.length_m
                )
            except ExtractionError as e:
                skipped.append({"frame": rec.frame, "time_s": rec.time_s, "reason": str(e)})
                bar.update()
                continue
            plane = plane or line.plane_depth_m  # the plane of the push: from its first good frame
            if stations is None:  # width stations every SPACING_PX of the first extracted frame, over the stem
                stations = np.arange(0.0, spec.length_m, SPACING_PX * plane / np.sqrt(camera["fx"] * camera["fy"]))
            if colour is None:  # auto: chosen on the first extracted frame, kept for every frame
                colour = choose_colour_model(rgb, depth, line, camera, direction=push.direction)
                log.info("width colour model: %s (%s)", colour.model, colour.reason)
            widths.append(
                width_profile(
                    rgb,
                    depth,
                    line,
                    camera,
                    direction=push.direction,
                    s_m=stations,
                    colour_model=colour.model,
                )
            )
            n = line.x_m.size
            cols["time_s"].append(np.full(n, rec.time_s))
            cols["x_m"].append(line.x_m)
            cols["z_m"].append(line.z_m)
            cols["sd_m"].append(line.sd_m)
            cols["observed"].append(line.observed.astype(int))
            rows.append(
                {
                    "frame": rec.frame,
                    "time_s": rec.time_s,
                    "points": n,
                    "bridged": int(n - line.observed.sum()),
                    "length_m": line.length_m,
                }
            )
            if best is None or rec.frame == push.frames[len(push.frames) // 2].frame:
                best = (rgb, line, rec.frame, push.direction)
            bar.update()
        if rows:
            columns[push.id] = MappingProxyType({k: np.concatenate(v) for k, v in cols.items()})
        if best is not None:
            examples[push.id] = best
        report["pushes"][push.id] = {"plane_depth_m": plane, "frames": rows, "skipped": skipped}
        msg = f"{push.id}: {len(rows)}/{len(push.frames)} frames extracted"
        if skipped:
            msg += f"; skipped {', '.join(str(s['frame']) + ' (' + s['reason'] + ')' for s in skipped)}"
        log.info("%s", msg)
    bar.close()
    depth_scale_sd = spec.camera.depth_scale_sd if spec.camera is not None else 0.0
    diameters = combine_profiles(widths, stations, depth_scale_sd=depth_scale_sd) if widths else None
    if diameters is not None:
        flags, counts = np.unique(diameters.flag, return_counts=True)
        report["diameters"] = {
            "stations": int(diameters.s_m.size),
            "flags": {str(f): int(n) for f, n in zip(flags, counts, strict=True)},
            "frames": len(widths),
            "colour_model": colour.to_dict() | {"requested": width_colour_model},
            # the factor each frame's narrow stations were divided by (vision.width.contrast_scale): its spread
            # over frames is an error the stations of a frame share
            "contrast_scale": {
                "median": float(np.median([w.contrast_scale for w in widths])),
                "sd": float(np.std([w.contrast_scale for w in widths])),
                # the contrast fit's blur over the width of the profiles it read: above BLUR_RATIO_OK the
                # contrast, and every narrow station's width, is weakly determined (vision.width)
                "blur_over_width": None if not np.isfinite(diameters.blur_over_width) else diameters.blur_over_width,
                # how far the fit with the thin profiles and the fit without land apart near the switch between
                # them (vision.width.variant_scale_sd), the frames' median
                "variant_spread": diameters.contrast_variant_spread,
            },
            "shared_scale_sd": diameters.shared_scale_sd,
            "shared_taper_sd": diameters.shared_taper_sd,
            # the stem's widest stations [px]: under THIN_PX a resolution term joins the scale error
            "base_width_px": None if not np.isfinite(diameters.base_width_px) else diameters.base_width_px,
        }
        warnings = []
        if blur_scale_sd(diameters.blur_over_width) >= BLUR_WARN_SCALE_SD:
            blurred = (
                f"the lens's blur is {diameters.blur_over_width:.2f} of the width of the narrow stations the stem's "
                f"colour contrast is read from (at most {BLUR_RATIO_OK:g} reads it well): their widths may read "
                f"several per cent off, most often narrow (Young's modulus off by four times that); every width "
                f"now shares a scale error of sd {100 * diameters.shared_scale_sd:.1f}% and the taper read from them "
                f"an error of sd {100 * diameters.shared_taper_sd:.1f}% (docs/validation.md, 'Blur against width', "
                f"'Thin stems' and 'The taper under a wide blur'); a closer or sharper camera avoids it"
            )
            warnings.append(blurred)
        variant = variant_scale_sd(diameters.blur_over_width, diameters.contrast_variant_spread)
        weak = max(blur_scale_sd(diameters.blur_over_width), thin_scale_sd(diameters.base_width_px))
        if variant >= BLUR_WARN_SCALE_SD and variant > weak:
            warnings.append(
                f"the stem's colour contrast, read from the narrow stations with and without the thinnest of them, "
                f"comes out {100 * diameters.contrast_variant_spread:.1f}% apart (the lens's blur is "
                f"{diameters.blur_over_width:.2f} of their width, near the {BLUR_RATIO_OK:g} where the thinnest are "
                f"added): every width now shares a scale error of sd {100 * diameters.shared_scale_sd:.1f}% "
                f"(Young's modulus: four times that; docs/validation.md, 'Session 63'); a closer or sharper camera "
                f"avoids it"
            )
        if np.isfinite(diameters.base_width_px) and diameters.base_width_px < THIN_PX:
            if diameters.base_width_px < RESOLVED_PX:
                what = "no width is used (every station is flagged unresolved)"
            else:
                what = (
                    f"every width shares a resolution scale error of sd "
                    f"{100 * thin_scale_sd(diameters.base_width_px):.1f}% (Young's modulus: four times that)"
                )
            warnings.append(
                f"the stem is only {diameters.base_width_px:.2f} px wide at its widest stations; widths under "
                f"{THIN_PX:g} px carry errors the frames do not show (rendered stems this thin read their base "
                f"mostly 1-5% wide, single pushes up to 34% off; docs/validation.md, 'Thinner than three "
                f"pixels'): {what}; a closer camera, or a caliper's base diameter, avoids it"
            )
        if warnings:
            report["diameters"]["warning"] = "; ".join(warnings)
            for w in warnings:
                log.warning("warning: %s: %s", spec.specimen, w)
        log.info("diameter profile: %d of %d stations measured", int(diameters.ok.sum()), diameters.s_m.size)
    report = plain_json(report)
    return Extraction(spec, MappingProxyType(columns), MappingProxyType(report), MappingProxyType(examples), diameters)

"""``bayesrod extract``: run the vision pipeline over a dataset's frames and write a copy with shapes.

I/O lives here; the per-frame algorithm is :mod:`bayesrod.vision.extract`.
The copy holds every input file unchanged; each push with ``frames`` gains
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
import shutil
from pathlib import Path

import numpy as np

from .dataset import read_dataset
from .io import atomic_dir, write_csv, write_json


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


def plot_extraction(rgb, line, ax=None, camera=None, direction=1):
    """RGB frame with the segmentation (orange), skeleton (blue) and tracked pixel path (cyan).

    With ``camera`` (the specimen's pinhole block) the written points are drawn too: seen points
    yellow, points bridged across an occlusion hollow magenta. Returns the artists drawn.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(8, 6))
    img = ax.imshow(rgb)
    mask = ax.imshow(np.ma.masked_where(~line.mask, line.mask), cmap="autumn", alpha=0.45)
    vv, uu = np.nonzero(line.skeleton)
    sk = ax.plot(uu, vv, ",", color="b")[0]
    (path,) = ax.plot(
        line.path_uv[:, 0], line.path_uv[:, 1], "c-", lw=1.2, label="pixel path (Dijkstra + tip tracking)"
    )
    out = {"image": img, "mask": mask, "skeleton": sk, "path": path}
    if camera is not None:
        u0, v0 = camera["base_px"]
        u = u0 + direction * line.x_m * camera["fx"] / line.plane_depth_m
        v = v0 - line.z_m * camera["fy"] / line.plane_depth_m
        seen = line.observed if line.observed is not None else np.ones(u.size, bool)
        out["seen"] = ax.plot(u[seen], v[seen], "o", ms=2.5, color="yellow", label="centerline points")[0]
        if (~seen).any():
            out["bridged"] = ax.plot(
                u[~seen], v[~seen], "o", ms=4, mfc="none", color="magenta", label="bridged across an occlusion"
            )[0]
    ax.set(title=f"extracted length {line.length_m:.3f} m, plane depth {line.plane_depth_m:.3f} m")
    ax.legend(loc="upper right", fontsize=8)
    ax.axis("off")
    return out


def extract_dataset(dataset, out, *, force: bool = False, progress: bool = True, log=print) -> dict:
    """Extract centerlines from every push with frames; write the dataset copy into ``out`` atomically."""
    from tqdm.auto import tqdm

    from .vision.extract import ExtractionError, extract_frame

    spec = read_dataset(dataset)
    src = Path(dataset)
    doc = json.loads((src / "specimen.json").read_text())
    camera = doc.get("camera")
    pushes = [p for p in spec.pushes if p.frames]
    if not pushes:
        raise ValueError(f"{src / 'specimen.json'}: expected at least one push with 'frames', got none")
    report = {"dataset": str(src.resolve()), "pushes": {}}
    with atomic_dir(out, force) as tmp:
        shutil.copytree(src, tmp, dirs_exist_ok=True)
        figs = tmp / "figures"
        figs.mkdir(exist_ok=True)
        total = sum(len(p.frames) for p in pushes)
        bar = tqdm(total=total, desc="extracting frames", unit="frame", disable=not progress, leave=False)
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
                    best = (rgb, line, rec.frame)
                bar.update()
            name = f"{push.id}/shapes_extracted.csv"
            (tmp / push.id).mkdir(exist_ok=True)
            if rows:
                write_csv(tmp / name, {k: np.concatenate(v) for k, v in cols.items()})
            for pd in doc["pushes"]:
                if pd["id"] == push.id and rows:
                    if pd.get("shapes"):
                        pd["shapes_original"] = pd["shapes"]
                    pd["shapes"] = name
            if best is not None:
                import matplotlib

                matplotlib.use("Agg")
                import matplotlib.pyplot as plt

                fig, ax = plt.subplots(figsize=(8, 6))
                plot_extraction(best[0], best[1], ax=ax, camera=camera, direction=push.direction)
                ax.set_title(f"{push.id}, frame {best[2]}: " + ax.get_title())
                fig.tight_layout()
                fig.savefig(figs / f"extract_{push.id}.png", dpi=90)
                plt.close(fig)
            report["pushes"][push.id] = {"plane_depth_m": plane, "frames": rows, "skipped": skipped}
            msg = f"{push.id}: {len(rows)}/{len(push.frames)} frames extracted"
            if skipped:
                msg += f"; skipped {', '.join(str(s['frame']) + ' (' + s['reason'] + ')' for s in skipped)}"
            log(msg)
        bar.close()
        write_json(tmp / "specimen.json", doc)
        write_json(tmp / "extract_report.json", report)
    return report

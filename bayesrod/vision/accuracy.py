"""Extraction accuracy against a simulated dataset's true centerlines (for tests, scripts and docs/vision.md).

Reads a dataset written by ``bayesrod.simulate(..., ).save(path, frames=True)``, whose pushes name
``truth_shapes`` (the noise-free centerlines) beside their frames.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .extract import extract_frame


def _frames_truth(root):
    import cv2

    root = Path(root)
    spec = json.loads((root / "specimen.json").read_text())
    out = []
    for push in spec["pushes"]:
        truth = {}
        for r in csv.DictReader(open(root / push["truth_shapes"])):
            truth.setdefault(float(r["time_s"]), []).append((float(r["x_m"]), float(r["z_m"])))
        for r in csv.DictReader(open(root / push["frames"] / "index.csv")):
            t = min(truth, key=lambda k, r=r: abs(k - float(r["time_s"])))
            rgb = cv2.cvtColor(cv2.imread(str(root / push["frames"] / r["rgb"])), cv2.COLOR_BGR2RGB)
            dep = cv2.imread(str(root / push["frames"] / r["depth"]), cv2.IMREAD_UNCHANGED)
            out.append((rgb, dep, np.array(truth[t]).T))
    return spec, out


def _densify(x, z, s, per_segment=10):
    xs, zs = [x[:1]], [z[:1]]
    for i in range(1, s.size):
        if s[i] - s[i - 1] < 0.015:  # consecutive 1-cm points; a bigger step is a gap
            f = np.linspace(0, 1, per_segment + 1)[1:]
            xs.append(x[i - 1] + f * (x[i] - x[i - 1]))
            zs.append(z[i - 1] + f * (z[i] - z[i - 1]))
        else:
            xs.append(x[i : i + 1])
            zs.append(z[i : i + 1])
    return np.concatenate(xs), np.concatenate(zs)


def _near(line, keep, tx, tz, tol):
    """Whether each true point (tx, tz) lies within ``tol`` of the extracted points ``keep``, joined."""
    ex, ez = _densify(line.x_m[keep], line.z_m[keep], line.s_m[keep])
    return np.hypot(tx[:, None] - ex[None], tz[:, None] - ez[None]).min(axis=1) < tol


def _hidden(dep, Z, u, v):
    """Whether each pixel (u, v) lies behind something in front of the plane (probe, arm), by the depth map."""
    import cv2
    from scipy.ndimage import map_coordinates

    front = ((dep > 0) & (dep < (Z - 0.03) * 1000)).astype(np.uint8)
    front = cv2.morphologyEx(front, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    front = cv2.dilate(front, np.ones((3, 3), np.uint8))
    return map_coordinates(front, [v, u], order=0) > 0


def frame_metrics(root):
    """Per frame of a simulated dataset with frames: extraction against the true centerline.

    Yields dicts: ``err`` median point-to-curve error [m] of all extracted points and ``err_seen`` of
    those seen in the image, ``false`` fraction of seen points farther than 3 px from it, ``cover``
    fraction of the true arc length within 3 px of the extracted curve (its 1-cm points joined, not
    across gaps; bridges across occlusions count), ``cover_seen`` the same from seen points only,
    ``cover_visible`` the latter over true points not behind an object in front of the plane, ``extent``
    s_max / L, ``bridge_z`` (b,) error / sd_m of each bridged point, ``signed`` (B,) signed normal error
    [px] of seen points every 2 cm of arc length (NaN where no point), ``px`` pixel size [m].
    """
    spec, frames = _frames_truth(root)
    bins = np.arange(0.0, spec["length_m"], 0.02)
    u0, v0 = spec["camera"]["base_px"]
    for rgb, dep, tr in frames:
        line = extract_frame(rgb, dep, spec["camera"], max_length_m=spec["length_m"])
        seen = line.observed
        px = line.plane_depth_m / spec["camera"]["fx"]
        st = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(tr, axis=1)))])
        sd = np.linspace(0, st[-1], 4000)
        tx, tz = np.interp(sd, st, tr[0]), np.interp(sd, st, tr[1])
        dist = np.hypot(line.x_m[:, None] - tx[None], line.z_m[:, None] - tz[None])
        d = dist.min(axis=1)

        near_all, near_seen = (_near(line, keep, tx, tz, 3 * px) for keep in (np.ones(seen.size, bool), seen))
        hidden = _hidden(dep, line.plane_depth_m, u0 + tx / px, v0 - tz / px)
        k = np.argmin(dist, axis=1)
        tdx, tdz = np.gradient(tx, sd), np.gradient(tz, sd)
        e = ((line.x_m - tx[k]) * tdz[k] - (line.z_m - tz[k]) * tdx[k]) / px
        e = np.where(seen, e, np.nan)
        j = np.argmin(np.abs(line.s_m[None, :] - bins[:, None]), axis=1)
        yield {
            "err": float(np.median(d)),
            "err_seen": float(np.median(d[seen])),
            "false": float(np.mean(d[seen] > 3 * px)),
            "cover": float(np.mean(near_all)),
            "cover_seen": float(np.mean(near_seen)),
            "cover_visible": float(np.mean(near_seen[~hidden])),
            "extent": min(float(line.s_m.max()) / spec["length_m"], 1.0),
            "bridge_z": d[~seen] / line.sd_m[~seen],
            "signed": np.where(np.abs(line.s_m[j] - bins) < 0.006, e[j], np.nan),
            "px": px,
        }

"""RGB-D frames to metric centerlines (the seed's section III-C, with classical segmentation).

Per frame:

1. **Plane depth.** The stem lies in the bending plane, at a depth read from
   the valid depth pixels just above the base pixel (median); the plane depth
   of a push is the median over its frames.
2. **Segmentation.** Pixels within a thin depth band around the plane
   (``band_m``, widened by the depth noise) and above the base row; missing
   depth (0) inside the stem is filled by a morphological closing restricted
   to pixels whose colour matches the band's own colour; specks are removed.
   The probe sits in front of the plane and falls outside the band: it leaves
   a gap, bridged below.
3. **Skeleton** (scikit-image) and the 8-connected pixel graph (edge cost =
   pixel distance), plus bridging edges between skeleton end pixels of
   different components closer than ``max_gap_px`` (cost 2x distance: the
   occlusion by the probe).
4. **Dijkstra** (scipy.sparse.csgraph) from the skeleton pixel nearest the
   base to every pixel; the tip is the reachable pixel farthest along the
   path; the path is traced back.
5. **Metric.** u, v to x, z with the plane depth and the pinhole intrinsics:
   x = direction (u - u_base) Z / fx, z = (v_base - v) Z / fy.
6. **B-spline.** A cubic smoothing spline (scipy ``make_splprep``) through the
   path with smoothing set by the pixel noise, resampled at equal arc length;
   points inside a bridged gap are dropped (the contract allows missing
   points). ``sd_m`` is the robust scatter of the path pixels about the spline
   (at least the quantisation 1/sqrt(12) px), in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

QUANT_PX = 1.0 / np.sqrt(12.0)


@dataclass(frozen=True)
class Centerline:
    """One extracted centerline: points at equal arc length from base to tip, in metres."""

    x_m: NDArray
    z_m: NDArray
    sd_m: NDArray
    s_m: NDArray
    path_uv: NDArray  # (k, 2) pixel path from base to tip
    mask: NDArray  # (H, W) bool segmentation
    skeleton: NDArray  # (H, W) bool
    plane_depth_m: float
    length_m: float  # arc length of the extracted centerline


class ExtractionError(ValueError):
    """The stem was not found in a frame (reported and skipped, never invented)."""


def plane_depth(depth_mm: NDArray, base_px, rows: int = 40, half_width: int = 12) -> float:
    """Depth of the bending plane [m] just above the base pixel.

    The stem is the nearest surface in each image row there (background and clutter lie
    behind it), so the plane depth is the median over rows of each row's nearest valid
    reading; a probe in front of the stem covers few rows and does not move the median.
    """
    u0, v0 = (int(round(c)) for c in base_px)
    H, W = depth_mm.shape
    win = depth_mm[max(v0 - rows, 0) : max(v0 - 2, 1), max(u0 - half_width, 0) : min(u0 + half_width + 1, W)]
    win = np.where(win > 0, win.astype(float), np.inf)
    nearest = win.min(axis=1)
    nearest = nearest[np.isfinite(nearest)] / 1000.0
    if nearest.size < 5:
        raise ExtractionError("no depth readings above the base pixel")
    return float(np.median(nearest))


def segment(rgb: NDArray, depth_mm: NDArray, Z: float, base_px, band_m: float = 0.02) -> NDArray:
    """Boolean stem mask (H, W) from the depth band around the plane, refined by colour."""
    import cv2
    from skimage.morphology import remove_small_objects

    H, W = depth_mm.shape
    d = depth_mm.astype(float) / 1000.0
    tol = band_m + 3 * 0.002 * Z**2
    valid = depth_mm > 0
    band = valid & (np.abs(d - Z) < tol)
    v_base = int(round(base_px[1]))
    band[v_base + 2 :, :] = False  # nothing of the stem lies below its base (ground)
    if band.sum() < 10:
        return band
    # colour model of the band; fill missing-depth pixels that match it and touch the band
    lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2LAB).astype(float)
    mu = np.median(lab[band], axis=0)
    spread = np.median(np.abs(lab[band] - mu), axis=0) * 1.4826 + 2.0
    similar = np.all(np.abs(lab - mu) < 4 * spread, axis=-1)
    grown = cv2.dilate(band.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    mask = band | (grown & ~valid & similar)
    mask = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)) > 0
    mask[v_base + 2 :, :] = False
    return remove_small_objects(mask, max_size=15)


def _skeleton_graph(skel: NDArray, max_gap_px: float):
    """Sparse graph over skeleton pixels: 8-neighbour edges and gap bridges between components."""
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree
    from skimage.measure import label

    vv, uu = np.nonzero(skel)
    n = vv.size
    index = -np.ones(skel.shape, int)
    index[vv, uu] = np.arange(n)
    rows, cols, w = [], [], []
    H, W = skel.shape
    for dv, du in ((0, 1), (1, 0), (1, 1), (1, -1)):
        v2, u2 = vv + dv, uu + du
        ok = (v2 < H) & (u2 >= 0) & (u2 < W)
        j = np.full(n, -1)
        j[ok] = index[v2[ok], u2[ok]]
        has = j >= 0
        rows.append(np.arange(n)[has])
        cols.append(j[has])
        w.append(np.full(has.sum(), np.hypot(dv, du)))
    comp = label(skel, connectivity=2)[vv, uu]
    # end pixels (one neighbour) and isolated pixels may bridge to another component
    deg = np.zeros(n, int)
    for r, c in zip(rows, cols, strict=True):
        np.add.at(deg, r, 1)
        np.add.at(deg, c, 1)
    ends = np.flatnonzero(deg <= 1)
    if ends.size > 1:
        tree = cKDTree(np.column_stack([vv, uu]))
        for i in ends:
            for j in tree.query_ball_point([vv[i], uu[i]], max_gap_px):
                if comp[j] != comp[i]:
                    rows.append(np.array([i]))
                    cols.append(np.array([j]))
                    w.append(np.array([2.0 * np.hypot(vv[i] - vv[j], uu[i] - uu[j])]))
    r, c, ww = (np.concatenate(a) for a in (rows, cols, w))
    G = coo_matrix((np.concatenate([ww, ww]), (np.concatenate([r, c]), np.concatenate([c, r]))), shape=(n, n))
    return G.tocsr(), vv, uu


def centerline_pixels(mask: NDArray, base_px, max_gap_px: float = 60.0):
    """Skeleton and the Dijkstra path (k, 2) of (u, v) pixels from the base to the farthest reachable pixel."""
    from scipy.sparse.csgraph import dijkstra
    from skimage.morphology import skeletonize

    skel = skeletonize(mask)
    if skel.sum() < 5:
        raise ExtractionError("no stem skeleton found in the depth band")
    G, vv, uu = _skeleton_graph(skel, max_gap_px)
    d_base = np.hypot(uu - base_px[0], vv - base_px[1])
    src = int(np.argmin(d_base))
    if d_base[src] > max_gap_px:
        raise ExtractionError(f"the stem skeleton starts {d_base[src]:.0f} px from the base pixel")
    dist, pred = dijkstra(G, indices=src, return_predecessors=True)
    reach = np.isfinite(dist)
    # tip: the reachable pixel farthest from the base along the path
    tip = int(np.argmax(np.where(reach, dist, -1)))
    path = [tip]
    while path[-1] != src:
        path.append(int(pred[path[-1]]))
    path = np.array(path[::-1])
    return skel, np.column_stack([uu[path], vv[path]]).astype(float)


def stem_likeness(rgb: NDArray, mask: NDArray) -> NDArray:
    """Per-pixel fraction of stem colour over the local background, alpha in ~[0, 1] (H, W).

    The local background is a 15x15 median of the image (a thin stem vanishes from it);
    alpha is the projection of (pixel - background) onto (stem colour - background), with
    the stem colour taken from the segmented pixels. A sub-pixel tip, whose depth reads the
    background behind it, still shows as alpha ~ its width in pixels.
    """
    import cv2

    img = rgb.astype(float)
    bg = cv2.medianBlur(rgb, 15).astype(float)
    stem = np.median(img[mask], axis=0) if mask.any() else img.reshape(-1, 3).mean(0)
    dirv = stem[None, None, :] - bg
    den = np.maximum(np.sum(dirv * dirv, axis=-1), 400.0)  # a contrast below ~20 levels is not trusted
    return np.sum((img - bg) * dirv, axis=-1) / den


def track_tip(
    alpha: NDArray, uv: NDArray, *, threshold: float = 0.2, max_steps: int = 2000, coast_steps: int = 45
) -> NDArray:
    # max_steps bounds the tracked length (1.5 px per step): extract_frame passes the stem's remaining length
    """Follow the stem beyond the depth-band path along the ridge of ``alpha``; returns added (k, 2) pixels.

    Steps of 1.5 px; each step picks the highest alpha among directions within 35 degrees of the
    current heading (sampled bilinearly), and the heading turns by at most that much per step.
    Where alpha stays below ``threshold`` it coasts straight for up to ``coast_steps`` steps (kept only if
    the stem reappears), then stops; also at the image edge.
    """
    from scipy.ndimage import map_coordinates

    H, W = alpha.shape
    k = min(12, uv.shape[0] - 1)
    if k < 2:
        return np.zeros((0, 2)), np.zeros(0, bool)
    head = uv[-1] - uv[-1 - k]
    head = head / (np.linalg.norm(head) or 1.0)
    pos = uv[-1].astype(float)
    angles = np.deg2rad(np.linspace(-35, 35, 15))
    out, weak, coasted = [], [], []
    for _ in range(max_steps):
        ca, sa = np.cos(angles), np.sin(angles)
        dirs = np.stack([head[0] * ca - head[1] * sa, head[0] * sa + head[1] * ca], axis=1)
        cand = pos[None, :] + 1.5 * dirs
        inside = (cand[:, 0] >= 1) & (cand[:, 0] < W - 2) & (cand[:, 1] >= 1) & (cand[:, 1] < H - 2)
        if not inside.any():
            break
        a = map_coordinates(alpha, [cand[:, 1], cand[:, 0]], order=1)
        a = np.where(inside, a - 0.002 * np.abs(np.rad2deg(angles)), -np.inf)  # prefer going straight
        j = int(np.argmax(a))
        if a[j] < threshold:
            # no stem here (faint, or crossing the arm or clutter): coast straight on -- above the contact the
            # stem carries no moment and is straight -- and keep these steps only if the stem reappears
            pos = pos + 1.5 * head
            # re-acquire: the stem may lie a few pixels beside the straight coast
            normal = np.array([-head[1], head[0]])
            offs = np.arange(-5.0, 5.5, 1.0)
            side = pos[None, :] + offs[:, None] * normal[None, :]
            ok_side = (side[:, 0] >= 1) & (side[:, 0] < W - 2) & (side[:, 1] >= 1) & (side[:, 1] < H - 2)
            a_side = np.where(ok_side, map_coordinates(alpha, [side[:, 1], side[:, 0]], order=1), -np.inf)
            i_best = int(np.argmax(a_side - 0.01 * np.abs(offs)))
            if a_side[i_best] >= threshold and len(weak) >= 2:
                pos = side[i_best]
                out.extend(weak)
                coasted.extend([True] * len(weak))
                weak = []
                out.append(pos)
                coasted.append(False)
                continue
            weak.append(pos)
            if len(weak) >= coast_steps:
                break
        else:
            pos = cand[j]
            head = 0.6 * head + 0.4 * dirs[j]
            head /= np.linalg.norm(head)
            out.extend(weak)
            coasted.extend([True] * len(weak))
            weak = []
            out.append(pos)
            coasted.append(False)
    return np.array(out).reshape(-1, 2), np.array(coasted, bool)


def extract_frame(
    rgb: NDArray,
    depth_mm: NDArray,
    camera: dict,
    *,
    direction: int = 1,
    plane_depth_m: float | None = None,
    spacing_m: float = 0.01,
    band_m: float = 0.02,
    track: bool = True,
    max_length_m: float | None = None,
) -> Centerline:
    """Centerline of one RGB-D frame; raises :class:`ExtractionError` when the stem is not found."""
    from scipy.interpolate import make_splprep

    base = camera["base_px"]
    Z = plane_depth(depth_mm, base) if plane_depth_m is None else plane_depth_m
    mask = segment(rgb, depth_mm, Z, base, band_m)
    if mask.sum() < 10:
        raise ExtractionError("no pixels in the stem's depth band")
    skel, uv = centerline_pixels(mask, base)
    uv = np.vstack([np.asarray(base, float)[None, :], uv])  # the clamped base is known
    unseen = np.zeros(uv.shape[0], bool)
    if track:
        steps = 2000
        if max_length_m is not None:  # the stem is no longer than its length: bound the tracked part
            so_far = float(np.sum(np.hypot(*np.diff(uv, axis=0).T))) * Z / camera["fx"]
            steps = max(int((max_length_m - so_far) * camera["fx"] / Z / 1.5), 0)
        if steps:
            pts, coasted = track_tip(stem_likeness(rgb, mask), uv, max_steps=steps)
            uv = np.vstack([uv, pts])
            unseen = np.concatenate([np.zeros(uv.shape[0] - pts.shape[0], bool), coasted])
    else:
        unseen = np.zeros(uv.shape[0], bool)
    step = np.hypot(*np.diff(uv, axis=0).T)
    gap = step > 2.5  # a bridged occlusion
    keep = np.concatenate([[True], step > 0])
    gap = np.concatenate([[False], gap]) | unseen  # bridged jumps and coasted (unseen) tracker steps
    uv, gap = uv[keep], gap[keep]
    if uv.shape[0] < 6:
        raise ExtractionError(f"the stem path has {uv.shape[0]} pixels, expected at least 6")
    fx, fy = camera["fx"], camera["fy"]
    x = direction * (uv[:, 0] - base[0]) * Z / fx
    z = (base[1] - uv[:, 1]) * Z / fy
    t = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])
    px_m = Z / fx
    spl, _ = make_splprep([x, z], u=t, s=uv.shape[0] * (0.6 * px_m) ** 2, k=3)
    fine = np.linspace(0, t[-1], max(400, 4 * uv.shape[0]))
    xf, zf = spl(fine)
    sf = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xf), np.diff(zf)))])
    length = float(sf[-1])
    if max_length_m is not None:
        length = min(length, float(max_length_m))
    s_out = np.arange(0.0, length + 1e-12, spacing_m)
    u_out = np.interp(s_out, sf, fine)
    xo, zo = spl(u_out)
    # scatter of the path about the spline (robust), never below pixel quantisation
    xs, zs = spl(t)
    resid = np.hypot(x - xs, z - zs)
    sd = max(1.4826 * float(np.median(resid)), QUANT_PX * px_m)
    # drop points inside bridged gaps
    hidden = np.zeros(s_out.size, bool)
    for i in np.flatnonzero(gap):
        s0 = np.interp(t[i - 1], fine, sf)
        s1 = np.interp(t[i], fine, sf)
        hidden |= (s_out > s0) & (s_out < s1)
    return Centerline(xo[~hidden], zo[~hidden], np.full((~hidden).sum(), sd), s_out[~hidden], uv, mask, skel, Z, length)

"""Render synthetic RGB-D frames of a simulated push (``bayesrod.simulate(...).save(path, frames=True)``).

Deliberately hard: the background is cluttered with branches and leaves of
the stem's own colour (at other depths), the probe occludes the stem around
the contact, the tip tapers below a pixel, depth carries noise that grows with
distance and drops out (0) at random pixels and at depth edges.

Camera: pinhole, image plane parallel to the bending plane, which lies at
depth ``Z0``. A point (x, z) of the bending plane projects to
u = u_base + fx * direction * x / Z0, v = v_base - fy * z / Z0.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..dataset.io import write_csv
from ..physics.lumped import stem_diameter

WIDTH, HEIGHT = 640, 480
FOCAL = 600.0
STEM_RGB = np.array([112, 118, 62], float)  # olive-brown


def plane_depth(length_m: float) -> float:
    """Distance of the bending plane so that the stem spans ~80% of the image height."""
    return FOCAL * length_m / (0.8 * HEIGHT)


def default_camera(length_m: float) -> dict:
    """Camera block for specimen.json (docs/format.md, section 1)."""
    return {
        "fx": FOCAL,
        "fy": FOCAL,
        "cx": WIDTH / 2,
        "cy": HEIGHT / 2,
        "base_px": [0.2 * WIDTH, 0.92 * HEIGHT],
        "image_size": [WIDTH, HEIGHT],
    }


def project(x_m, z_m, camera: dict, depth_m: float, direction: int = 1):
    u0, v0 = camera["base_px"]
    return (u0 + camera["fx"] * direction * np.asarray(x_m) / depth_m, v0 - camera["fy"] * np.asarray(z_m) / depth_m)


def _background(rng: np.random.Generator, Z0: float):
    """Static cluttered background: (rgb float HxWx3, depth m HxW)."""
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    rgb = np.empty((HEIGHT, WIDTH, 3))
    sky = np.array([150, 160, 140.0]) + 25 * np.sin(xx / 90.0 + rng.uniform(0, 6))[..., None]
    rgb[:] = sky
    depth = Z0 + 1.5 + 0.5 * (yy / HEIGHT)
    ground = yy > 0.92 * HEIGHT + 6 * np.sin(xx / 40.0)
    rgb[ground] = [95, 80, 55]
    depth[ground] = Z0 - 0.05 + 0.3 * (HEIGHT - yy[ground]) / HEIGHT + 0.1
    # Clutter: branches and leaves of similar colour at other depths.
    for _ in range(int(rng.integers(14, 22))):
        zc = Z0 + rng.uniform(0.25, 1.4)
        col = STEM_RGB + rng.normal(0, 14, 3)
        layer = np.zeros((HEIGHT, WIDTH), np.uint8)
        if rng.random() < 0.6:
            pts = np.cumsum(rng.normal(0, 25, (8, 2)), axis=0) + rng.uniform([0, 0], [WIDTH, HEIGHT])
            cv2.polylines(layer, [pts.astype(np.int32)], False, 255, int(rng.integers(2, 7)), cv2.LINE_AA)
        else:
            c = tuple(int(v) for v in rng.uniform([0, 0], [WIDTH, HEIGHT]))
            ax = (int(rng.integers(8, 30)), int(rng.integers(4, 12)))
            cv2.ellipse(layer, c, ax, float(rng.uniform(0, 180)), 0, 360, 255, -1, cv2.LINE_AA)
        m = layer > 127
        closer = m & (zc < depth)
        rgb[closer] = col
        depth[closer] = zc
    rgb += rng.normal(0, 6, rgb.shape)
    return rgb, depth


def stem_coverage(u, v, width_px, shape, step_px: float = 0.2, return_limb: bool = False):
    """Fraction of each pixel the stem covers: its true width, anti-aliased exactly.

    The stem is the union of discs' cross-sections along the centerline (u, v) (n,) with the local
    width ``width_px`` (n,); a pixel at distance t from the centerline, where the half-width is r,
    is covered by the overlap of [t - 1/2, t + 1/2] with [-r, r] (a 1-px box filter across the
    stem). Summed across the stem the coverage is the width, for every width, sub-pixel ones
    included: the truth the width measurement (:mod:`bayesrod.vision.width`) is checked against.

    With ``return_limb`` also returns cos of the surface's tilt at each pixel centre,
    sqrt(1 - (t / r)^2) (0 beyond the stem): what a round stem's shading follows.
    """
    from scipy.spatial import cKDTree

    H, W = shape
    u, v, w = (np.asarray(a, float) for a in (u, v, width_px))
    seg = np.hypot(np.diff(u), np.diff(v))
    t = np.concatenate([[0.0], np.cumsum(seg)])
    fine = np.arange(0.0, t[-1] + step_px, step_px)
    uf, vf, rf = np.interp(fine, t, u), np.interp(fine, t, v), 0.5 * np.interp(fine, t, w)
    reach = float(rf.max()) + 1.0
    lo_u, hi_u = int(max(np.floor(uf.min() - reach), 0)), int(min(np.ceil(uf.max() + reach), W - 1))
    lo_v, hi_v = int(max(np.floor(vf.min() - reach), 0)), int(min(np.ceil(vf.max() + reach), H - 1))
    alpha = np.zeros(shape)
    limb = np.zeros(shape)
    if hi_u < lo_u or hi_v < lo_v:
        return (alpha, limb) if return_limb else alpha
    vv, uu = np.mgrid[lo_v : hi_v + 1, lo_u : hi_u + 1]
    dist, idx = cKDTree(np.column_stack([uf, vf])).query(
        np.column_stack([uu.ravel(), vv.ravel()]), distance_upper_bound=reach
    )
    near = np.isfinite(dist)
    r = np.zeros(dist.shape)
    r[near] = rf[idx[near]]
    d = np.where(near, dist, np.inf)
    cov = np.clip(np.minimum(d + 0.5, r) - np.maximum(d - 0.5, -r), 0.0, 1.0)
    alpha[lo_v : hi_v + 1, lo_u : hi_u + 1] = cov.reshape(uu.shape)
    if not return_limb:
        return alpha
    x = np.where(r > 0, np.minimum(d, r) / np.where(r > 0, r, 1.0), 1.0)
    limb[lo_v : hi_v + 1, lo_u : hi_u + 1] = np.sqrt(np.clip(1.0 - x**2, 0.0, 1.0)).reshape(uu.shape)
    return alpha, limb


#: the synthetic width scene of :func:`synthetic_stem_frame`: its camera (focal length [px], base pixel), the
#: bending plane's depth [m] and the flat background's colour
SYNTHETIC_CAMERA = {"fx": FOCAL, "fy": FOCAL, "base_px": [128.0, 441.6]}
SYNTHETIC_DEPTH_M = 0.734
SYNTHETIC_BG_RGB = np.array([155.0, 168.0, 146.0])


def synthetic_stem_frame(
    w0: float, p: float, noise: float, seed: int = 1, shaded: bool = False, ramp: float = 0.0, blur: float = 0.6
):
    """One synthetic frame for the width measurement: a gently curved stem of width w0 (1 - s/L)^p [px]
    (x = 0.15 s^2, s up to 0.4 m, L 0.47 m) on a flat background with per-pixel noise of sd ``noise``
    [levels], blurred like a camera (Gaussian of sd ``blur`` [px]; the renderer's 3 x 3 kernel at 0.6);
    ``shaded``: a round stem lit from the camera, its colour falling to 55% of the core's at the limbs;
    ``ramp``: the background brightens by this many levels from the bottom of the image to the top.
    Seen by :data:`SYNTHETIC_CAMERA` at :data:`SYNTHETIC_DEPTH_M`.

    Returns
    -------
    (rgb (480, 640, 3) uint8, the drawn centerline (:class:`~bayesrod.vision.extract.Centerline`), a function
    of arc length s [m] giving the drawn width [px])
    """
    from .extract import Centerline

    H, W, n = HEIGHT, WIDTH, 400
    F, Z = SYNTHETIC_CAMERA["fx"], SYNTHETIC_DEPTH_M
    u0, v0 = SYNTHETIC_CAMERA["base_px"]
    s = np.linspace(0, 0.4, n)
    x, z = 0.15 * s**2, s
    u, v = u0 + F * x / Z, v0 - F * z / Z
    wpx = w0 * (1 - s / 0.47) ** p
    a, limb = stem_coverage(u, v, wpx, (H, W), return_limb=True)
    rng = np.random.default_rng(seed)
    img = SYNTHETIC_BG_RGB + rng.normal(0, noise, (H, W, 3)) + ramp * (1 - np.arange(H) / H)[:, None, None]
    col = STEM_RGB * ((0.55 + 0.45 * limb)[..., None] if shaded else 1.0)
    img = img * (1 - a[..., None]) + col * a[..., None]
    img = cv2.GaussianBlur(np.clip(img, 0, 255).astype(np.uint8), (3, 3) if blur == 0.6 else (0, 0), blur)
    line = Centerline(x, z, np.full(n, 1e-4), s, np.zeros((0, 2)), a > 0.5, a > 0.5, Z, 0.4, np.ones(n, bool))
    return img, line, (lambda ss: np.interp(ss, s, wpx))


ARMS = ("trailing", "leading")
STYLES = ("flat", "shaded")


def render_frame(
    bg_rgb,
    bg_depth,
    xz_m,
    s_m,
    length_m,
    p,
    d0,
    camera,
    Z0,
    probe_xz,
    rng,
    arm="leading",
    exact_width=False,
    style="flat",
    sensor_noise=3.0,
):
    """One RGB (uint8) and depth (uint16 mm) image of the stem centerline ``xz_m`` (2, n).

    ``arm`` places the bar that holds the probe, in front of the stem at the contact
    height: ``"leading"`` (default, used for every validation number) runs it ahead (+x) to
    the image edge, over the part of the stem the push bends forward, a deliberately hard
    occlusion; ``"trailing"`` runs it back (-x), as a rig held from behind the push would
    (the seed's wire anchors lead the contact by the wire's deflection).

    ``exact_width=True`` draws each pixel's exact coverage of the true width (:func:`stem_coverage`, the truth
    of the diameter study); the default draws whole-pixel line widths with a visible sub-pixel tip (what every
    centerline number of docs/vision.md was measured on).

    ``sensor_noise``: sd of the fresh noise every pixel gets in each frame [grey levels] (over a background that
    is the same in every frame of a push).

    ``style`` (with ``exact_width``): ``"flat"`` draws the stem in one colour, ``"shaded"`` as a round stem
    lit from the camera (its colour darkens towards the limbs to 55% of the core's, Lambert) seen through
    a defocused lens (Gaussian blur of sd 1.2 px instead of 0.6): a second look the width method was not
    built on (docs/validation.md).
    """
    if style not in STYLES:
        raise ValueError(f"style: expected one of {STYLES}, got {style!r}")
    if style != "flat" and not exact_width:
        raise ValueError(f"style: expected 'flat' unless exact_width is set, got {style!r}")
    if not (np.isfinite(sensor_noise) and sensor_noise >= 0):
        raise ValueError(f"sensor_noise: expected a noise sd of 0 or more grey levels, got {sensor_noise!r}")
    rgb = bg_rgb.copy()
    depth = bg_depth.copy()
    u, v = project(xz_m[0], xz_m[1], camera, Z0)
    diam = stem_diameter(s_m, d0, p, length_m)
    limb_shade = None  # (H, W, 1) brightness of a shaded stem's colour
    if exact_width:
        alpha, limb = stem_coverage(u, v, diam * FOCAL / Z0, (HEIGHT, WIDTH), return_limb=True)
        if style == "shaded":
            limb_shade = (0.55 + 0.45 * limb)[..., None]
    else:  # the default: whole-pixel line widths, a faint but visible (>= 35%) sub-pixel tip
        stem = np.zeros((HEIGHT, WIDTH), np.uint8)
        for i in range(len(u) - 1):
            w_px = diam[i] * FOCAL / Z0
            thick = max(1, int(round(w_px)))
            shade = 255 if w_px >= 1 else int(255 * max(w_px, 0.35))
            cv2.line(
                stem,
                (int(round(u[i] * 4)), int(round(v[i] * 4))),
                (int(round(u[i + 1] * 4)), int(round(v[i + 1] * 4))),
                shade,
                thick,
                cv2.LINE_AA,
                shift=2,
            )
        alpha = stem / 255.0
    col = STEM_RGB + rng.normal(0, 4, 3)
    if limb_shade is not None:
        col = col * limb_shade
    rgb = rgb * (1 - alpha[..., None]) + col * alpha[..., None]
    depth[alpha > 0.5] = Z0
    if probe_xz is not None:  # the probe occludes the stem around the contact, in front of it
        pu, pv = project(probe_xz[0], probe_xz[1], camera, Z0)
        half_w, half_h = 0.025 * FOCAL / Z0, 0.018 * FOCAL / Z0
        x0, x1 = int(pu - half_w), int(pu + half_w)
        y0, y1 = int(pv - half_h), int(pv + half_h)
        rgb[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = [60, 62, 66]
        depth[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = Z0 - 0.06
        arm_y0, arm_y1 = int(pv - 0.006 * FOCAL / Z0), int(pv + 0.006 * FOCAL / Z0)
        cols = slice(max(x1, 0), None) if arm == "leading" else slice(0, max(x0, 0))
        rgb[max(arm_y0, 0) : max(arm_y1, 0), cols] = [70, 72, 78]
        depth[max(arm_y0, 0) : max(arm_y1, 0), cols] = Z0 - 0.06
    # Sensor noise.
    rgb = np.clip(rgb + rng.normal(0, sensor_noise, rgb.shape), 0, 255).astype(np.uint8)
    rgb = cv2.GaussianBlur(rgb, (3, 3), 0.6) if style == "flat" else cv2.GaussianBlur(rgb, (7, 7), 1.2)
    noisy = depth + rng.normal(0, 0.002, depth.shape) * (depth / 1.0) ** 2
    edges = cv2.Canny(np.clip(depth * 200, 0, 255).astype(np.uint8), 20, 60) > 0
    edges = cv2.dilate(edges.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    missing = (rng.random(depth.shape) < 0.04) | (edges & (rng.random(depth.shape) < 0.3))
    d_mm = np.clip(np.round(noisy * 1000), 1, 65535).astype(np.uint16)
    d_mm[missing] = 0
    return rgb, d_mm


def render_push_frames(cfg, sp, folder: Path, camera: dict, rng: np.random.Generator, arm: str = "leading") -> None:
    """Write ``folder/index.csv`` and one RGB and one depth PNG per simulated frame (``arm``: see render_frame)."""
    if arm not in ARMS:
        raise ValueError(f"arm: expected one of {ARMS}, got {arm!r}")
    folder.mkdir(parents=True, exist_ok=True)
    Z0 = plane_depth(cfg.length_m)
    bg_rgb, bg_depth = _background(rng, Z0)
    d0, taper = cfg.rendered_diameter
    rows = {"frame": [], "time_s": [], "rgb": [], "depth": []}
    robot_speed_x = np.interp(sp.frame_time_s, sp.time_s, sp.robot_x_m)
    for k, t in enumerate(sp.frame_time_s):
        cx = sp.frame_contact_x_m[k]
        if np.isfinite(cx):
            dx_wire = robot_speed_x[k] - cx
            probe = (cx + 0.5 * dx_wire, sp.height_m)
        else:
            probe = (robot_speed_x[k], sp.height_m)
        rgb, dmm = render_frame(
            bg_rgb,
            bg_depth,
            sp.shapes_true[k],
            sp.s_m,
            cfg.length_m,
            taper,
            d0,
            camera,
            Z0,
            probe,
            rng,
            arm,
            cfg.exact_width,
            cfg.render_style,
            cfg.sensor_noise,
        )
        cv2.imwrite(str(folder / f"rgb_{k:03d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(folder / f"depth_{k:03d}.png"), dmm)
        rows["frame"].append(k)
        rows["time_s"].append(t)
        rows["rgb"].append(f"rgb_{k:03d}.png")
        rows["depth"].append(f"depth_{k:03d}.png")
    write_csv(
        folder / "index.csv",
        {k: np.array(v) if k in ("frame", "time_s") else np.array(v, dtype=object) for k, v in rows.items()},
    )

"""The stem's diameter along its extracted centerline, sub-pixel, from the frame's colour.

For every station (equal steps of arc length along a :class:`~bayesrod.vision.extract.Centerline`)
the RGB image is sampled along the centerline's normal (bilinear, 0.25-px steps). Each sample
is a mix of the stem's colour and the background's, rgb = (1 - a) bg + a stem, with ``a`` the
fraction of the pixel the stem covers (anti-aliasing, blur and the sensor's point spread keep
that sum). The stem's width in pixels is the integral of ``a`` across it:

    w = integral a(t) dt,   a(t) = (rgb(t) - bg) . (stem - bg) / |stem - bg|^2,

with ``bg`` the median colour just beyond the stem on each side (each half of the profile uses
its own side) and ``stem`` the median colour of the stem's core at the station (where the stem
is 6 px wide or more; else the frame's stem colour: the most stem-coloured pixel at its widest
stations, extrapolated from its mix with the background by the contrast the profiles' shapes
imply, :func:`contrast_scale`). Whole-pixel counting of the mask would be
off by up to a pixel; the coverage integral is unbiased for any width, sub-pixel ones included.

Metres: w_m = w_px Z |n / f| with the plane depth Z and the focal lengths along the normal n.

Each station's standard deviation combines the pixel noise of ``a`` (measured on the background
samples: a sum over the window's independent pixels) and the error of the two background
medians (which spreads over the whole window). Stations are flagged and not used where:

* ``occluded``: the centerline there is bridged (not seen) or the profile window meets an object
  in front of the plane (the probe, the arm) in the depth map;
* ``cluttered``: samples of the profile that read as stem (coverage above ``CLUTTER_COVERAGE``) over
  at least ``CLUTTER_PX`` lie on pixels whose depth is behind the plane: a branch or leaf of the
  stem's colour behind it, merged into its coverage (on a rendered grass blade such a stick ran along
  the stem's lower quarter and read it 2-5 times too wide);
* ``low_contrast``: the stem's colour is within 6 noise sd of the background's (a pixel's
  coverage scatters by more than 1/6) or within 12 levels of it on either side (a branch of the
  stem's colour passing behind it);
* ``edge``: the window leaves the image;
* ``base``: the first 3 widths of the stem above the base pixel (ground).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..dataset.engagement import robust_noise
from ..dataset.model import SHARED_DIAMETER_ERRORS, Diameters

#: flag names, in the order they are tested (the first that applies is reported)
FLAGS = ("ok", "occluded", "cluttered", "low_contrast", "edge", "base")
COLOUR_MODELS = ("projection", "unmixing")
#: what ``bayesrod extract`` takes: either model, or ``auto`` (:func:`choose_colour_model`, per push)
COLOUR_CHOICES = ("auto", *COLOUR_MODELS)
#: ``auto`` picks unmixing when the two models' widths differ by more than this [px] at a frame's wide
#: stations (naming it shading when by more than SHADING_Z of its standard error too): flat synthetic stems
#: read within 0.03 px alike, shaded ones 0.33-0.58 px apart (tests/test_width.py); the rendered shaded
#: twig 0.45 px apart (docs/validation.md, "Shaded stems")
SHADING_PX = 0.15
SHADING_Z = 4.0
#: ... or by more than this share of those stations' median width, if that is less: on a 3-px stem 0.15 px is
#: 5%, and the rendered shaded grass (seed 5) whose models differed by +0.145 px kept projection and read
#: +0.30 px wide (docs/validation.md, "Thin stems")
SHADING_REL = 0.03
#: unmixing needs stem and background of different chromaticity: cosine of their RGB angle below this
UNMIX_MAX_COS = 0.998
#: ``auto`` compares the models at stations at least this wide [px]: narrower ones are mostly limb and blur
#: (on a 5-px shaded stem the models differ by 0.41 px, on a flat one by -0.02 px at these stations)
WIDE_PX = 3.0
STEP_PX = 0.25  # sample spacing along the normal [px]
SPACING_PX = 3.0  # default station spacing along the centerline [px]
BG_PX = 3.0  # width of each background strip [px]
MARGIN_PX = 3.0  # the window reaches this far beyond the mask's half-width (blur, anti-aliasing)
MASK_REACH_PX = 20.0  # the mask's half-width is looked for at least this far from the centerline [px]
#: sd [px] of the width error all stations of a profile share (the method's bias at the stem's edges:
#: blur, anti-aliasing, the colour model). scripts/width_error_study.py measured its rms over 12 replicates:
#: 0.029 px on the twig, 0.088 px on the grass (heavy-tailed: -0.19 and -0.17 px) at first, hence 0.1 px;
#: with the boxes of the contrast fit tied to the integrals' trend (2026-11-27) 0.011 and 0.027 px (seeds
#: 0-11), the shaded stems 0.026 px (seeds 0-5): 0.05 px, about twice those (docs/validation.md, "Thin stems")
OFFSET_SD_PX = 0.05
OWN_CORE_HALF_PX = 3.0  # a station at least 6 px wide (in the mask) takes the stem colour of its own core
#: the contrast scale reads only profiles of the stem alone (:func:`_clean_profiles`): coverage peak at most
#: PEAK_MAX (a stem's coverage against a frame colour still mixed with the background exceeds 1 by the
#: contrast scale, about 1.04 on the rendered grass) and integral within AREA_REL of a robust cubic trend of
#: the integrals along the stem (a stem's width changes smoothly; clutter crossing a window, or a mask merged
#: with it, does not); of those, the AREA_N_MAX widest by that trend, if at least MIN_AREA_PX wide (a
#: narrower profile's shape is the blur's, and holds no contrast)
PEAK_MAX = 1.25
AREA_REL = 0.3
MIN_AREA_PX = 2.0
AREA_N_MAX = 40
#: and up to THIN_N clean profiles from THIN_MIN_AREA_PX to MIN_AREA_PX wide, evenly spread over that range:
#: their shape is mostly the blur's, so they pin the blur the wide profiles' contrast trades off against. With
#: the wide profiles alone, a 3.1-px stem under a lens blur of sd 1.2 px read 10-20% narrow (flat) or 12-18%
#: (shaded, unmixed); with the thin ones -1% to -10% (both with each box tied to its own integral, before
#: :func:`_box_fit` tied it to the trend; docs/validation.md, "Thin stems")
THIN_MIN_AREA_PX = 0.5
THIN_N = 20
#: a station is ``cluttered`` when its samples of coverage above CLUTTER_COVERAGE (stem, not the blurred
#: edge) on pixels behind the plane's depth band add up to CLUTTER_PX [px] or more
CLUTTER_COVERAGE = 0.75
CLUTTER_PX = 0.5
#: the contrast is read from the shapes of profiles a few pixels wide (:func:`contrast_scale`); where the
#: lens's blur is a large share of their width, the shape hardly depends on the contrast and a misfit of a
#: fraction of a grey level moves it: a synthetic 3.3-px stem under a Gaussian blur of sd 0.6, 0.8, 1.0 and
#: 1.2 px reads -0.7%, -1.8%, -3.9%, -3.6% narrow at ratios (below) of 0.30, 0.37, 0.46, 0.52, and a 5-px
#: stem within +0.7% at 0.21-0.37 (docs/validation.md, "Thin stems"). The ratio of the fitted blur to
#: the median width of the profiles it read: at or below BLUR_RATIO_OK the widths are read as measured; above
#: it every station shares a scale error of sd BLUR_SCALE_SD_SLOPE x (ratio - BLUR_RATIO_OK) (:func:`blur_scale_sd`,
#: added in combine_profiles; with the lens term, the 32 lenses and stems of scripts/blur_width_sweep.py read
#: within 1.645 sd in 94%), and extract warns from BLUR_WARN_SCALE_SD on
BLUR_RATIO_OK = 0.3
BLUR_SCALE_SD_SLOPE = 0.3
#: extract warns when the blur's scale error reaches this sd (the rendered grass sits at ratio 0.30)
BLUR_WARN_SCALE_SD = 0.01
#: the contrast fit models the lens as a Gaussian; under other lenses (a Gaussian cut to a 7 x 7 kernel,
#: disks of radius 1.5 and 2 px, a 3 x 3 box) the 3.3- and 5-px synthetic stems, flat and shaded, read
#: -5.2% to +0.7% at any blur / width, -1.4% to -2.8% at ratios near 0.3: a scale error of this sd, times
#: the share of the ok stations the fit read (:func:`lens_scale_sd`), with the blur term, makes those 32
#: cases' errors over their declared sd rms 1.04, 94% within 1.645 (``python scripts/blur_width_sweep.py``;
#: docs/validation.md, "Thin stems")
LENS_SCALE_SD = 0.01


#: a stem whose widest stations read narrower than THIN_PX [px] (the 95th percentile of the combined ok stations)
#: is read with errors its frames do not show: rendered stems whose widest stations read 1.8-3.0 px (grass drawn
#: 2.0-3.3 px wide at the base, twig 2.4-2.9 px) read their base -7% to +13% off, most +1% to +5% wide (the
#: contrast is read from profiles all about as thin), where 1-2% was declared, and two pushes at 2.0 px -21% and
#: +34%. Below THIN_PX every width shares a resolution scale error of sd THIN_SCALE_SD_SLOPE x (THIN_PX - width)
#: (:func:`thin_scale_sd`; docs/validation.md, "Thinner than three pixels"), and extract warns. From 3.2 px the
#: term made the rendered grass (3.3 px at its base, its widest stations 2.8-3.0 px) cover d0 in 10 of 10 with
#: z rms 0.6: too wide
THIN_PX = 3.0
THIN_SCALE_SD_SLOPE = 0.06  # per px
#: a stem narrower than this at its widest [px] is not resolved: its stations are flagged ``unresolved``
RESOLVED_PX = 1.8


def thin_scale_sd(base_px: float) -> float:
    """Relative sd of the scale error every station shares when the stem's widest stations read ``base_px``
    pixels (0 from :data:`THIN_PX` up, and where no width was read)."""
    if not np.isfinite(base_px) or base_px >= THIN_PX:
        return 0.0
    return THIN_SCALE_SD_SLOPE * (THIN_PX - base_px)


def blur_scale_sd(ratio: float) -> float:
    """Relative sd of the scale error every station shares when the contrast fit's blur is ``ratio`` of the
    width of the profiles it read (0 at or below :data:`BLUR_RATIO_OK`, and where no ratio was read)."""
    return BLUR_SCALE_SD_SLOPE * max(ratio - BLUR_RATIO_OK, 0.0) if np.isfinite(ratio) else 0.0


def lens_scale_sd(borrowed_share: float) -> float:
    """Relative sd of the scale error the lens's shape leaves when a share ``borrowed_share`` (0-1) of the
    ok stations took their width from the contrast fit (:data:`LENS_SCALE_SD`)."""
    return LENS_SCALE_SD * float(np.clip(borrowed_share, 0.0, 1.0)) if np.isfinite(borrowed_share) else 0.0


#: below BLUR_RATIO_OK the contrast fit reads the wide profiles alone, and from VARIANT_RATIO_FROM up it also
#: reads them with the thin ones added (the fit above BLUR_RATIO_OK); how far the two land apart
#: (``ContrastFit.variant_spread``) is a scale error the switch between them leaves. Rendered stems whose blur is
#: 0.27-0.30 of their width read their base +1.5% wide on average for about 1.2% declared (the twig drawn 2.9 px
#: wide and the preset grass, 3.3 px: z rms 1.54 and 1.39 over seeds 410-417) while the two fits landed 1.3-3.9%
#: apart (seeds 400-405); taken as an sd, limited to BLUR_SCALE_SD_SLOPE x (ratio - VARIANT_RATIO_FROM) (at most
#: its value at BLUR_RATIO_OK: above it the wide profiles alone read the blur badly and land 7-22% off on the
#: grass drawn 2.45 px wide), z rms 0.95 and 0.72 on the same seeds (the grass drawn 2.9 px 1.04 -> 0.76, the rest
#: within 0.15 of before)
#: (:func:`variant_scale_sd`; docs/validation.md, "Session 63")
VARIANT_RATIO_FROM = 0.2


def variant_scale_sd(ratio: float, variant_spread: float) -> float:
    """Relative sd of the scale error the choice between the contrast fit's two variants leaves: their
    spread ``variant_spread`` (|log| of their scales' ratio) where the blur is ``ratio`` of the profiles' width,
    limited to ``BLUR_SCALE_SD_SLOPE x (min(ratio, BLUR_RATIO_OK) - VARIANT_RATIO_FROM)`` (0 below
    :data:`VARIANT_RATIO_FROM`, and where either is not a number)."""
    if not (np.isfinite(ratio) and np.isfinite(variant_spread)):
        return 0.0
    cap = BLUR_SCALE_SD_SLOPE * max(min(ratio, BLUR_RATIO_OK) - VARIANT_RATIO_FROM, 0.0)
    return float(min(abs(variant_spread), cap))


def contrast_fit_scale_sd(
    ratio: float, borrowed_share: float, variant_spread: float = 0.0, base_px: float = float("nan")
) -> float:
    """Relative sd of the scale error the contrast fit leaves every station with: the largest of the blur's
    (:func:`blur_scale_sd`), the switch between the fit's variants' on the share of stations that took its scale
    (:func:`variant_scale_sd`) and the resolution's where the widest stations read ``base_px`` pixels
    (:func:`thin_scale_sd`) - three measures of how weakly profiles too thin or too blurred pin the contrast,
    which overlap (added in quadrature instead, the rendered grass drawn 2.45 px wide declared 5.7% for errors
    of rms 3.5%: z rms 0.60 over 8 seeds; docs/validation.md, "Session 63") - with the lens's
    (:func:`lens_scale_sd`) in quadrature."""
    share = float(np.clip(borrowed_share, 0.0, 1.0)) if np.isfinite(borrowed_share) else 0.0
    weak = max(blur_scale_sd(ratio), share * variant_scale_sd(ratio, variant_spread), thin_scale_sd(base_px))
    return float(np.hypot(weak, lens_scale_sd(borrowed_share)))


def frame_scale_sd(wp: WidthProfile) -> float:
    """Relative sd of the scale error one frame's widths ``wp`` declare for the contrast fit and the resolution
    (:func:`contrast_fit_scale_sd`, the widest stations' width the 95th percentile of its ok stations' [px]);
    :func:`combine_profiles` adds the frames' scatter and the depth's."""
    ok = (wp.flag == "ok") & np.isfinite(wp.width_px)
    base_px = float(np.percentile(wp.width_px[ok], 95)) if ok.any() else float("nan")
    return contrast_fit_scale_sd(wp.blur_over_width, wp.borrowed_share, wp.contrast_variant_spread, base_px)


@dataclass(frozen=True)
class WidthProfile:
    """Stem widths along one centerline: stations at arc length ``s_m`` (k,) [m].

    ``width_m`` and ``sd_m`` (k,) [m]; ``width_px`` (k,) [px]; ``flag`` (k,) str from :data:`FLAGS`
    (only ``"ok"`` stations are measurements); ``uv`` (k, 2) the stations' pixels; ``contrast_scale`` the
    factor the widths of stations too narrow for a core colour of their own were divided by
    (:func:`contrast_scale`; 1 where none); ``blur_over_width`` that fit's blur sd over the median width of
    the profiles it read (NaN where none: :func:`contrast_fit`); ``borrowed_share`` the share of the ok
    stations divided by that scale (0 where the fit read none); ``contrast_variant_spread`` that fit's
    ``variant_spread`` (0 where none).
    """

    s_m: NDArray
    width_m: NDArray
    sd_m: NDArray
    width_px: NDArray
    flag: NDArray
    uv: NDArray
    contrast_scale: float = 1.0
    blur_over_width: float = float("nan")
    borrowed_share: float = 0.0
    contrast_variant_spread: float = 0.0


def _sample(img: NDArray, pts: NDArray) -> NDArray:
    """Bilinear samples of a (H, W, C) image at pixel points (..., 2) as (u, v); shape (..., C)."""
    from scipy.ndimage import map_coordinates

    flat = pts.reshape(-1, 2)
    out = np.stack(
        [map_coordinates(img[..., c], [flat[:, 1], flat[:, 0]], order=1, mode="nearest") for c in range(img.shape[2])],
        axis=-1,
    )
    return out.reshape(*pts.shape[:-1], img.shape[2])


def width_profile(
    rgb: NDArray,
    depth_mm: NDArray | None,
    line,
    camera: dict,
    *,
    direction: int = 1,
    s_m: NDArray | None = None,
    spacing_px: float = SPACING_PX,
    colour_model: str = "projection",
) -> WidthProfile:
    """Width of the stem at stations along an extracted centerline (see the module docstring).

    Parameters
    ----------
    rgb : (H, W, 3) uint8 array
    depth_mm : (H, W) uint16 array or None
        Depth in mm (0 = missing); finds occluders in front of the plane. None: not checked.
    line : Centerline
        From :func:`bayesrod.vision.extract.extract_frame` (its ``x_m``, ``z_m``, ``s_m``,
        ``observed``, ``mask`` and ``plane_depth_m``).
    camera : dict
        ``fx``, ``fy``, ``base_px`` (docs/format.md, camera block).
    direction : +1 or -1
        The push direction of the frame (the sign of x in the image).
    s_m : (k,) array, optional
        Stations [m of arc length]; default every ``spacing_px`` pixels along the centerline.
    colour_model : {"projection", "unmixing"}
        How a sample's colour gives the coverage a. ``projection`` (default): onto stem - bg, one stem
        colour across the stem. ``unmixing``: rgb - bg = a (-bg) + (a k) stem by least squares, so a
        round stem's shading k (darker limbs) does not read as coverage; needs stem and background of
        different chromaticity and is noisier (docs/validation.md, "shaded stems").

    Returns
    -------
    WidthProfile
    """
    import cv2
    from scipy.interpolate import CubicSpline

    from .extract import band_around_centre, behind_plane, in_front_of_plane, mask_across, widest_half_px

    if colour_model not in COLOUR_MODELS:
        raise ValueError(f"colour_model: expected one of {', '.join(COLOUR_MODELS)}, got {colour_model!r}")
    fx, fy = float(camera["fx"]), float(camera["fy"])
    u0, v0 = (float(c) for c in camera["base_px"])
    Z = float(line.plane_depth_m)
    if line.s_m.size < 4:
        raise ValueError(f"line: expected a centerline of at least 4 points, got {line.s_m.size}")
    sx, sz = CubicSpline(line.s_m, line.x_m), CubicSpline(line.s_m, line.z_m)
    if s_m is None:
        step_m = spacing_px * Z / np.sqrt(fx * fy)
        s_m = np.arange(0.0, float(line.s_m[-1]) + 1e-12, step_m)
    s_m = np.asarray(s_m, float)
    s_m = s_m[(s_m >= 0) & (s_m <= line.s_m[-1])]
    x, z = sx(s_m), sz(s_m)
    tx, tz = sx(s_m, 1), sz(s_m, 1)
    # to pixels: u = u0 + fx dir x / Z, v = v0 - fy z / Z; the tangent and normal in the image
    u, v = u0 + fx * direction * x / Z, v0 - fy * z / Z
    tu, tv = fx * direction * tx, -fy * tz
    norm = np.maximum(np.hypot(tu, tv), 1e-12)
    nu, nv = -tv / norm, tu / norm
    metres_per_px = Z * np.hypot(nu / fx, nv / fy)
    img = rgb.astype(float)
    H, W = rgb.shape[:2]
    mask = np.asarray(line.mask, bool)
    # the mask's half-width across the stem (nearest samples out to 20 px, or further where the mask is wider:
    # twice its largest inscribed radius at a station, plus 4 px): the window's extent (at least 2 px). A fixed
    # 20 px left a stem over 40 px wide (a thick stalk close to the camera) without background strips: its
    # strips lay on the stem and every station read low_contrast
    reach = max(MASK_REACH_PX, 2.0 * widest_half_px(np.column_stack([u, v]), mask) + 4.0)
    t = np.arange(-reach, reach + 1e-9, STEP_PX)
    left, right = band_around_centre(mask_across(mask, np.column_stack([u, v]), np.column_stack([nu, nv]), t, 0) <= 0.5)
    half_mask = 0.5 * np.maximum(right - left, 0) * STEP_PX
    half = np.maximum(half_mask, 2.0) + MARGIN_PX
    # the frame's stem colour, for stations too narrow to have a core of their own: at the stations of the
    # widest third at least 2.5 px wide, the pixel near the centerline farthest in colour from the local
    # background (an interval of >= 2 px always covers one whole pixel). An interpolated sample on the
    # centerline, or the median of eroded mask pixels, mixes in the background: a 3-px stem came out 15% too wide
    wide = np.flatnonzero(2 * half_mask >= 2.5)
    frame_stem = pick_rgb = pick_bg = None
    if wide.size >= 3:
        top = wide[np.argsort(half_mask[wide])[-max(3, wide.size // 3) :]]
        picks = [c for c in (_purest_pixel(img, u[i], v[i], nu[i], nv[i], half_mask[i]) for i in top) if c is not None]
        if picks:
            pick_rgb, pick_bg = (np.array(x) for x in zip(*picks, strict=True))
            frame_stem = np.median(pick_rgb, axis=0)
    if frame_stem is None:
        core = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        frame_stem = np.median(img[core], axis=0) if core.sum() >= 20 else np.median(img[mask], axis=0)
    occluder = behind = None
    if depth_mm is not None:
        occluder = cv2.dilate(in_front_of_plane(depth_mm, Z).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        behind = behind_plane(depth_mm, Z)
    observed = np.interp(s_m, line.s_m, (line.observed if line.observed is not None else np.ones(line.s_m.size)))
    k = s_m.size
    width_px, sd_px = np.full(k, np.nan), np.full(k, np.nan)
    flag = np.full(k, "ok", dtype=object)
    own_core = half_mask >= OWN_CORE_HALF_PX
    profiles: dict[int, tuple] = {}

    def measure(i: int, stem_rgb: NDArray | None) -> None:
        """Station i's coverage profile, width, sd and flag against the stem colour ``stem_rgb`` (None:
        the median of its own core)."""
        T = half[i]
        tt = np.arange(-(T + BG_PX), T + BG_PX + 1e-9, STEP_PX)
        q = np.stack([u[i] + tt * nu[i], v[i] + tt * nv[i]], axis=-1)
        if q[:, 0].min() < 0 or q[:, 0].max() > W - 1 or q[:, 1].min() < 0 or q[:, 1].max() > H - 1:
            flag[i] = "edge"
            return
        prof = _sample(img, q)
        inner = np.abs(tt) <= T
        bg_l = np.median(prof[tt < -T], axis=0)
        bg_r = np.median(prof[tt > T], axis=0)
        stem = np.median(prof[np.abs(tt) <= half_mask[i] - 1.5], axis=0) if stem_rgb is None else stem_rgb
        a = np.empty(tt.size)
        contrast = []
        for side, bg in ((tt < 0, bg_l), (tt >= 0, bg_r)):
            dcol = stem - bg
            dd = float(dcol @ dcol)
            contrast.append(np.sqrt(dd))
            if colour_model == "unmixing":  # rgb - bg = a (-bg) + (a k) stem: a free of the shading k
                X = np.column_stack([-bg, stem])
                a[side] = np.linalg.lstsq(X, (prof[side] - bg).T, rcond=None)[0][0]
            else:  # projection onto stem - bg: one stem colour across the stem
                a[side] = (prof[side] - bg) @ dcol / max(dd, 1e-12)
        # noise of a: the scatter of the background samples (one value per pixel: 1/STEP_PX samples; the two
        # strips hold 2 BG_PX / STEP_PX = 24 of them)
        bg_a = a[~inner]
        per_px = max(1.4826 * float(np.median(np.abs(bg_a - np.median(bg_a)))), 0.01)
        # window sum over 2T independent pixels, plus each side's background median (BG_PX pixels)
        # carried over that side's T pixels
        width_px[i] = float(np.sum(a[inner]) * STEP_PX)
        sd_px[i] = per_px * np.sqrt(2 * T + 2 * (np.pi / 2) * T**2 / BG_PX)
        profiles[i] = (tt[inner], a[inner])
        flag[i] = "ok"
        if observed[i] < 0.999 or (occluder is not None and _touches(occluder, q)):
            flag[i] = "occluded"
        elif behind is not None and np.sum(_on(behind, q) & (a > CLUTTER_COVERAGE)) * STEP_PX >= CLUTTER_PX:
            flag[i] = "cluttered"
        elif per_px > 1.0 / 6.0 or min(contrast) < 12.0:  # a pixel's coverage known to worse than 1/6
            flag[i] = "low_contrast"
        elif s_m[i] * np.sqrt(fx * fy) / Z < 3 * max(2 * half_mask[i], 1.0) + 2:
            flag[i] = "base"

    def borrowed_fit() -> ContrastFit:
        """The contrast fit of the ok stations that borrowed the frame's colour (scale 1 without any)."""
        borrowed = [i for i in profiles if not own_core[i] and flag[i] == "ok"]
        return contrast_fit([profiles[i] for i in borrowed], s_m[borrowed]) if borrowed else ContrastFit()

    for i in range(k):
        measure(i, None if own_core[i] else frame_stem)
    # stations without a core of their own used the frame's stem colour, which on a stem a few pixels wide
    # is still mixed with the background (blur): their coverage is scaled by the contrast the profiles'
    # shapes imply (:func:`contrast_scale`)
    fit = borrowed_fit()
    scale = fit.scale
    if pick_bg is not None and scale != 1.0:
        # the picked colour c is a mix m stem + (1 - m) b with the background b beside the pick, and the scale
        # is 1 / m: the pure colour is b + scale (c - b). Against a background other than b the mixed colour's
        # contrast is not the stem's contrast times m, and on the grass's sky (a gradient of +-25 levels) the
        # widths came out up to 8% high along a third of the stem: an error the taper fit reads as taper
        stem_pure = np.median(pick_bg + scale * (pick_rgb - pick_bg), axis=0)
        for i in np.flatnonzero(~own_core):
            measure(i, stem_pure)
        fit = borrowed_fit()
        scale = fit.scale
    width_px[~own_core] /= scale
    sd_px[~own_core] /= scale
    ok = flag == "ok"
    borrowed_share = float(np.mean(~own_core[ok])) if fit.width_px > 0 and ok.any() else 0.0
    return WidthProfile(
        s_m=s_m,
        width_m=width_px * metres_per_px,
        sd_m=sd_px * metres_per_px,
        width_px=width_px,
        flag=flag.astype(str),
        uv=np.column_stack([u, v]),
        contrast_scale=float(scale),
        blur_over_width=fit.blur_px / fit.width_px if fit.width_px > 0 else float("nan"),
        borrowed_share=borrowed_share,
        contrast_variant_spread=fit.variant_spread if fit.width_px > 0 else 0.0,
    )


@dataclass(frozen=True)
class ColourChoice:
    """Which colour model reads a push's widths (:func:`choose_colour_model`).

    ``model``: ``projection`` or ``unmixing``; ``shading_px``: median of projection - unmixing widths
    [px] at the frame's wide stations (NaN where there were fewer than ``min_stations``), ``se_px``
    its standard error; ``stations``: how many; ``reason``: one line saying why.
    """

    model: str
    shading_px: float
    se_px: float
    stations: int
    reason: str

    def to_dict(self) -> dict:
        return {
            "model": self.model,
            "shading_px": None if not np.isfinite(self.shading_px) else float(self.shading_px),
            "se_px": None if not np.isfinite(self.se_px) else float(self.se_px),
            "stations": int(self.stations),
            "reason": self.reason,
        }


def choose_colour_model(
    rgb: NDArray, depth_mm: NDArray | None, line, camera: dict, *, direction: int = 1, min_stations: int = 10
) -> ColourChoice:
    """Projection or unmixing for a stem, from the shape of its colour across its wide stations.

    Both models read the same width from a stem of one colour; a round stem lit from the camera, darker
    at its limbs, reads wider (or narrower) by projection, by about half a pixel on a 4-8 px twig. At the
    stations at least ``WIDE_PX`` wide, the two models' widths are compared: projection where their median
    difference is within ``SHADING_PX`` and ``SHADING_REL`` of the width (:func:`colour_verdict`), else
    unmixing where the stem's and background's colours differ in chromaticity enough to unmix
    (``UNMIX_MAX_COS``). A stem too narrow to show shading (fewer than ``min_stations`` wide stations) is
    unmixed where its colours allow: unmixing reads a flat stem as projection does and a shaded one without
    projection's bias (the rendered grass, flat: +0.029 vs +0.025 px; shaded: +0.105 vs +0.216 px;
    docs/validation.md, "Thin stems"); without a chromaticity of its own it keeps projection.

    Returns
    -------
    ColourChoice
    """
    proj = width_profile(rgb, depth_mm, line, camera, direction=direction, colour_model="projection")
    ok = proj.flag == "ok"
    wide = ok & (proj.width_px >= WIDE_PX)
    if wide.sum() < min_stations:
        narrow = f"fewer than {min_stations} stations {WIDE_PX:g} px wide or wider: too narrow to show shading"
        if ok.sum() < min_stations:
            return ColourChoice("projection", np.nan, np.nan, int(wide.sum()), narrow)
        # the widest third of the stem: its colour on the centerline (mixed with the background by the blur;
        # the pure colour unmixes at least as well)
        widest = ok & (proj.width_px >= np.quantile(proj.width_px[ok], 2 / 3))
        cos = _cosine(*_wide_colours(rgb, proj, widest))
        if cos > UNMIX_MAX_COS:
            return ColourChoice(
                "projection",
                np.nan,
                np.nan,
                int(wide.sum()),
                f"{narrow}; stem and background share their chromaticity (cos {cos:.4f}): cannot unmix",
            )
        return ColourChoice("unmixing", np.nan, np.nan, int(wide.sum()), f"{narrow}; unmixing reads either")
    cos = _cosine(*_wide_colours(rgb, proj, wide))
    unmix = width_profile(rgb, depth_mm, line, camera, direction=direction, colour_model="unmixing")
    both = wide & (unmix.flag == "ok")
    d_px = proj.width_px[both] - unmix.width_px[both]
    return colour_verdict(
        d_px, cos, min_stations, width_px=float(np.median(unmix.width_px[both])) if both.any() else np.inf
    )


def colour_verdict(d_px: NDArray, cos: float, min_stations: int = 10, width_px: float = np.inf) -> ColourChoice:
    """The rule of :func:`choose_colour_model` from the stations' width differences ``d_px`` (n,) [px]
    (projection - unmixing), the cosine ``cos`` of the stem's and background's colours in RGB and the
    stations' median width ``width_px`` [px] (:data:`SHADING_REL`; inf: the absolute bound alone)."""
    d = np.asarray(d_px, float)
    n = int(d.size)
    if n < min_stations:
        return ColourChoice("projection", np.nan, np.nan, n, "too few stations read by both models")
    med = float(np.median(d))
    se = float(np.sqrt(np.pi / 2) * 1.4826 * np.median(np.abs(d - med)) / np.sqrt(n))  # the median's se
    if abs(med) <= min(SHADING_PX, SHADING_REL * width_px):
        return ColourChoice("projection", med, se, n, f"the models agree ({med:+.3f} px): a stem of one colour")
    if cos > UNMIX_MAX_COS:
        return ColourChoice(
            "projection",
            med,
            se,
            n,
            f"shading ({med:+.3f} px) but stem and background share their chromaticity (cos {cos:.4f}): cannot unmix",
        )
    if abs(med) <= SHADING_Z * se:  # a difference too noisy to call shading, too large to call agreement
        return ColourChoice(
            "unmixing",
            med,
            se,
            n,
            f"the models differ by {med:+.3f} +- {se:.3f} px, not clearly: unmixing reads either",
        )
    return ColourChoice("unmixing", med, se, n, f"shaded stem: projection reads {med:+.3f} px wider than unmixing")


def _cosine(a: NDArray, b: NDArray) -> float:
    """Cosine of the angle between two colours (3,) in RGB."""
    return float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12))


def _wide_colours(rgb: NDArray, prof: WidthProfile, wide: NDArray) -> tuple[NDArray, NDArray]:
    """Median colour (3,) on the centerline at the ``wide`` stations, and the image's median colour
    (the background's, a stem being a small part of a frame)."""
    uv = prof.uv[wide]
    ui = np.clip(np.round(uv[:, 0]).astype(int), 0, rgb.shape[1] - 1)
    vi = np.clip(np.round(uv[:, 1]).astype(int), 0, rgb.shape[0] - 1)
    img = np.asarray(rgb, float)
    return np.median(img[vi, ui], axis=0), np.median(img.reshape(-1, 3), axis=0)


def _blurred_box(t: NDArray, w: NDArray, sigma: float) -> NDArray:
    """A box of width ``w`` [px] seen through a Gaussian point spread of sd ``sigma`` [px], at offsets t."""
    from scipy.special import ndtr

    return ndtr((t + w / 2) / sigma) - ndtr((t - w / 2) / sigma)


@dataclass(frozen=True)
class ContrastFit:
    """What :func:`contrast_fit` read: the contrast ``scale``, the blur's sd ``blur_px`` [px] and the median
    width ``width_px`` [px] (integral / scale) of the profiles it read; NaN blur and width where it read none.
    ``variant_spread``: |log| of the ratio of the scales read with and without the thin profiles (0 where only
    one was read: :data:`VARIANT_RATIO_FROM`)."""

    scale: float = 1.0
    blur_px: float = float("nan")
    width_px: float = float("nan")
    variant_spread: float = 0.0


def contrast_scale(
    profiles: list, s: NDArray, n_max: int = AREA_N_MAX, *, loss: str = "soft_l1", f_scale: float = 0.1
) -> float:
    """The contrast scale of :func:`contrast_fit` (its ``scale``)."""
    return contrast_fit(profiles, s, n_max, loss=loss, f_scale=f_scale).scale


def contrast_fit(
    profiles: list, s: NDArray, n_max: int = AREA_N_MAX, *, loss: str = "soft_l1", f_scale: float = 0.1
) -> ContrastFit:
    """Contrast of the true stem colour relative to the assumed one, from the shapes of narrow profiles.

    Each profile (t, a) of coverage against the assumed colour is modelled as ``k * box(w_i) *
    Gaussian(sigma)``, the contrast ``k`` and the blur ``sigma`` shared by the frame and each box's width
    tied to the coverage integral, ``w_i = A_i / k``, read off the integrals' smooth trend along the stem
    (:func:`_clean_profiles`; each profile's own integral carries its noise into the tie: :func:`_box_fit`).
    The integral is ``k w`` whatever the point spread, so only ``k`` and the centres are fitted; robust
    least squares over the ``n_max`` widest clean profiles; where the blur is a large share of their
    width, with up to ``THIN_N`` thin ones that pin it. With each profile's width free as well (the fit
    before 2026-11-26) width and contrast traded off, and on the rendered grass the scale came out 2-12%
    low, most on frames with clutter near the stem (docs/validation.md). Returns scale 1 (and no blur)
    when fewer than 5 clean profiles are ``MIN_AREA_PX`` or wider (no shape to read the contrast from).
    Where the blur is a large share of the profiles' width the scale is weakly determined
    (:data:`BLUR_RATIO_OK`). From a blur of :data:`VARIANT_RATIO_FROM` of the width up both fits are read
    (the one with the thin profiles returned only above :data:`BLUR_RATIO_OK`; the one without where that
    one fails) and how far apart they land is returned as ``variant_spread`` (:func:`variant_scale_sd`).

    Parameters
    ----------
    profiles : list of (t, a) pairs of (m_i,) arrays
        Offsets across the stem [px] and coverage against the assumed colour, one pair per station in
        order along the stem.
    s : (n,) array
        The stations' arc length (any unit): where along the stem each profile was taken.
    loss, f_scale : str, float
        The robust loss of the fit and its scale (``scipy.optimize.least_squares``); the defaults are the
        extraction's (scripts/contrast_scale_passes.py compares others).
    """
    trend, wide, thin = contrast_profiles(profiles, s, n_max)
    if len(wide) < 5:
        return ContrastFit()
    fit = _box_fit(profiles, trend, wide, loss, f_scale)
    ratio = fit.blur_px / fit.width_px if fit.width_px > 0 else 0.0
    if ratio <= VARIANT_RATIO_FROM or not thin:
        return fit
    # the blur a large share of the width: the thin profiles pin it (THIN_N); near the switch both fits are read
    # and how far apart they land is kept (variant_scale_sd)
    pinned = _box_fit(profiles, trend, wide + thin, loss, f_scale, len(wide))
    if not (pinned.width_px > 0):
        return fit
    spread = abs(float(np.log(pinned.scale / fit.scale)))
    return replace(pinned if ratio > BLUR_RATIO_OK else fit, variant_spread=spread)


def contrast_profiles(profiles: list, s: NDArray, n_max: int = AREA_N_MAX) -> tuple[NDArray, list, list]:
    """The profiles :func:`contrast_fit` reads (arguments as there): the integrals' smooth trend (n,) [px]
    (:func:`_clean_profiles`), the clean profiles of trend ``MIN_AREA_PX`` or wider, widest first, at most
    ``n_max``, and the thin ones that pin the blur: every max(1, m // THIN_N)-th of the m clean ones of trend
    ``THIN_MIN_AREA_PX`` (inclusive) to ``MIN_AREA_PX``, widest first, at most ``THIN_N`` (none where THIN_N is
    0). Indices into ``profiles``; the probes in scripts/ read the same selection."""
    clean, trend = _clean_profiles(profiles, s)
    order = np.argsort(trend)[::-1]
    wide = [i for i in order if clean[i] and trend[i] >= MIN_AREA_PX][:n_max]
    thin = [i for i in order if clean[i] and THIN_MIN_AREA_PX <= trend[i] < MIN_AREA_PX]
    picked = thin[:: max(1, len(thin) // THIN_N)][:THIN_N] if thin and THIN_N > 0 else []
    return trend, wide, picked


def _box_fit(
    profiles: list, trend: NDArray, use: list, loss: str, f_scale: float, n_wide: int | None = None
) -> ContrastFit:
    """The fit of :func:`contrast_fit` over the profiles ``use`` (indices), each box's width tied to the
    smooth ``trend`` (n,) of the integrals along the stem over k, the first ``n_wide`` (all) of them the
    wide ones whose median width it reports.

    Tied to each profile's own integral instead, the fit is an errors-in-variables one: the integral's noise
    (the background estimate, the pixels' noise summed over the window) widens and narrows the boxes at
    random, and k came out low: on a 1-D stem of 0.3-3.1 px under a blur of sd 1.2 px with pixel noise 3
    the widths read +6.3% on average over 8 draws (+0.2% tied to the true widths, +0.2% to the trend).
    """
    from scipy.optimize import least_squares

    n = len(use)
    t_all = np.concatenate([profiles[i][0] for i in use])
    y_all = np.concatenate([profiles[i][1] for i in use])
    owner = np.repeat(np.arange(n), [profiles[i][0].size for i in use])  # the profile of each sample
    area = _coverage_integrals([profiles[i] for i in use])
    tie = np.asarray(trend, float)[use]

    def resid(x):
        k, sig = np.exp(x[0]), np.exp(x[1])
        return y_all - k * _blurred_box(t_all - x[2:][owner], (tie / k)[owner], sig)

    # a profile's samples depend on k, sigma and its own centre only: with this sparsity the finite-difference
    # Jacobian takes a handful of evaluations instead of one per parameter
    sparsity = np.zeros((y_all.size, 2 + n), bool)
    sparsity[:, :2] = True
    sparsity[np.arange(y_all.size), 2 + owner] = True
    lo = np.concatenate([[np.log(0.5), np.log(0.2)], np.full(n, -2.0)])
    hi = np.concatenate([[np.log(2.0), np.log(3.0)], np.full(n, 2.0)])
    fit = least_squares(
        resid,
        np.concatenate([[0.0, np.log(0.8)], np.zeros(n)]),
        bounds=(lo, hi),
        loss=loss,
        f_scale=f_scale,
        jac_sparsity=sparsity,
    )
    if not fit.success:
        return ContrastFit()
    k = float(np.exp(fit.x[0]))
    return ContrastFit(k, float(np.exp(fit.x[1])), float(np.median(area[:n_wide])) / k)


def _coverage_integrals(profiles: list) -> NDArray:
    """Each profile's coverage integral [px] (n,): its width at the assumed contrast."""
    return np.array([float(np.sum(a)) * STEP_PX for _, a in profiles])


def _clean_profiles(profiles: list, s: NDArray) -> tuple[NDArray, NDArray]:
    """Which profiles (in station order along the stem, at arc lengths ``s`` (n,)) show the stem alone.

    Returns ``clean`` (n,) bool and ``trend`` (n,) [px]: a polynomial in s fitted to the coverage integrals
    with a robust (Cauchy) loss, the stem's smooth width, with one coefficient per 8 profiles up to a cubic
    (from 24 profiles; fewer than 5: no fit, the integrals themselves, none clean). Clean: a coverage peak of
    at most ``PEAK_MAX`` and an integral within ``AREA_REL`` of the trend. Clutter crossing a window, or a mask
    merged with it, reads as more than full coverage or as a sudden wide stem; on the grass such profiles came
    in runs of several stations, which a running median of neighbours (before 2026-11-26) let through.
    """
    area = _coverage_integrals(profiles)
    peak = np.array([float(np.max(a)) if a.size else np.inf for _, a in profiles])
    s = np.asarray(s, float)
    if area.size < 5:
        return np.zeros(area.size, bool), area
    x = (s - s.mean()) / max(float(np.std(s)), 1e-12)
    scale = max(0.1 * float(np.median(np.abs(area))), 1e-3)
    # the Cauchy loss ignores runs of clutter; soft L1 brings it near first
    trend = _robust_poly(x, area, min(4, area.size // 8 + 1), scale, ("soft_l1", "cauchy"))
    return (peak <= PEAK_MAX) & (np.abs(area - trend) <= AREA_REL * np.abs(trend)), trend


def _robust_poly(x: NDArray, y: NDArray, n_coef: int, f_scale: float, losses: tuple[str, ...]) -> NDArray:
    """Fitted values (n,) of a polynomial in ``x`` (n,) with ``n_coef`` coefficients: least squares, then
    robust least squares with each of ``losses`` in turn (scale ``f_scale``), each from the one before."""
    from scipy.optimize import least_squares

    X = np.vander(x, n_coef)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    for loss in losses:
        coef = least_squares(lambda c: X @ c - y, coef, loss=loss, f_scale=f_scale).x
    return X @ coef


def _purest_pixel(img: NDArray, u: float, v: float, nu: float, nv: float, half: float):
    """Colour (3,) of the pixel within 1 px of (u, v) farthest from the background beyond ``half`` + 3 px,
    and that background's colour (3,) (the mean of one pixel on each side); None off the image."""
    H, W = img.shape[:2]
    ui, vi = int(round(u)), int(round(v))
    if not (4 <= ui < W - 4 and 4 <= vi < H - 4):
        return None
    far = half + MARGIN_PX + 1.5
    # the background's pixels, rounded before the bounds check (a point in [W - 0.5, W) rounds to W)
    bg_px = [(int(round(u + sgn * far * nu)), int(round(v + sgn * far * nv))) for sgn in (-1, 1)]
    if any(not (0 <= a < W and 0 <= b < H) for a, b in bg_px):
        return None
    bg = np.mean([img[b, a] for a, b in bg_px], axis=0)
    patch = img[vi - 1 : vi + 2, ui - 1 : ui + 2].reshape(-1, 3)
    return patch[int(np.argmax(np.sum((patch - bg) ** 2, axis=1)))], bg


def _on(mask: NDArray, q: NDArray) -> NDArray:
    """``mask`` (H, W) at the nearest pixel of each point (m, 2) as (u, v): (m,) bool."""
    ui = np.clip(np.round(q[:, 0]).astype(int), 0, mask.shape[1] - 1)
    vi = np.clip(np.round(q[:, 1]).astype(int), 0, mask.shape[0] - 1)
    return mask[vi, ui]


def _touches(mask: NDArray, q: NDArray) -> bool:
    """True when any point (m, 2) as (u, v) falls on a True pixel of ``mask``."""
    return bool(_on(mask, q).any())


@dataclass(frozen=True)
class DiameterProfile:
    """The stem's diameter along its arc length, combined over frames: stations ``s_m`` (k,) [m].

    ``d_m``, ``sd_m`` (k,) [m]: the median width over the frames where the station is ``ok`` and its
    standard deviation (at flagged stations: the median and spread of whatever the frames measured, for
    the record; NaN where nothing was); ``n_frames`` (k,) int; ``flag`` (k,) str: ``ok`` where at least
    ``min_frames`` frames measured it, else the most frequent flag of the frames (``few_frames`` when
    they were ``ok`` but too few; ``unresolved`` where their median width is not above zero: a tip
    thinner than the width's noise). ``shared_offset_sd_m`` [m] and ``shared_scale_sd`` (relative): the
    sd of an offset and of a scale error that every station shares (:data:`OFFSET_SD_PX` pixels at the
    stem's distance; the camera's ``depth_scale_sd``, the standard error of the frames' mean contrast
    scale and the contrast fit's (:func:`contrast_fit_scale_sd`: the largest of the blur's share of the width,
    the spread of the fit's variants near its switch and the resolution, with the lens), added in
    quadrature), which no number
    of stations averages down; ``shared_taper_sd``: the relative sd of an error in the taper the widths read
    (the blur's share again, :func:`blur_scale_sd`: a blur wide against the stem reads its thin stations
    differently from its thick ones). ``blur_over_width``: the frames' median of the contrast fit's blur over the
    width of the profiles it read (NaN where no frame read one). ``base_width_px``: the stem's widest
    stations' width [px] (the 95th percentile of the ok stations; NaN where none): below :data:`THIN_PX` the
    scale error holds a resolution term (:func:`thin_scale_sd`), below :data:`RESOLVED_PX` no station is ok.
    ``contrast_variant_spread``: the frames' median of the contrast fit's ``variant_spread`` (0 where none was
    read; :func:`variant_scale_sd`).
    """

    s_m: NDArray
    d_m: NDArray
    sd_m: NDArray
    n_frames: NDArray
    flag: NDArray
    shared_offset_sd_m: float = 0.0
    shared_scale_sd: float = 0.0
    shared_taper_sd: float = 0.0
    blur_over_width: float = float("nan")
    base_width_px: float = float("nan")
    contrast_variant_spread: float = 0.0

    @property
    def ok(self) -> NDArray:
        return self.flag == "ok"

    def to_diameters(self) -> Diameters:
        """The ``ok`` stations as the dataset's :class:`~bayesrod.dataset.model.Diameters` (source
        ``frames``), with the shared errors."""
        ok = self.ok
        shared = {k: getattr(self, k) for k in SHARED_DIAMETER_ERRORS}
        return Diameters(self.s_m[ok], self.d_m[ok], self.sd_m[ok], "frames", **shared)

    def columns(self) -> dict[str, NDArray]:
        """``diameters_extracted.csv``'s columns (docs/format.md): every station with a number, any flag."""
        rec = np.isfinite(self.d_m)
        cols = {"s_m": self.s_m[rec], "d_m": self.d_m[rec], "sd_m": self.sd_m[rec], "n_frames": self.n_frames[rec]}
        cols["flag"] = self.flag[rec].astype(object)
        return cols | {k: np.full(int(rec.sum()), getattr(self, k)) for k in SHARED_DIAMETER_ERRORS}


#: a combined station is ``off_profile`` when it departs from a robust smooth fit of the profile by more
#: than this many times the larger of its own sd and the profile's noise
OFF_PROFILE_Z = 5.0
#: ... and by more than this fraction of the fitted width (a real taper's stations never jump so far)
OFF_PROFILE_REL = 0.05


def _off_profile(s_m: NDArray, d: NDArray, sd: NDArray, ok: NDArray) -> NDArray:
    """True at ``ok`` stations (k,) whose combined width leaves a robust cubic fit of the profile along s.

    Clutter of the stem's own colour crossing it merges into its mask, and a leaf lying across it
    at the probe does the same, in every frame where the stem barely moves: those stations read wide
    in most frames, so neither the frames' spread nor the station's neighbours (a run of ten stations
    at the base on grass seed 5, read +79% to +98%) give them away. A cubic in s fitted with a
    Cauchy loss (scale: the profile's noise from second differences) follows the stem's smooth taper
    through such runs; a station more than :data:`OFF_PROFILE_Z` sd (its own or the profile's noise,
    whichever is larger) and :data:`OFF_PROFILE_REL` of the fitted width from it is flagged.
    """
    out = np.zeros(ok.shape, bool)
    idx = np.flatnonzero(ok)
    if idx.size < 20:
        return out
    x = (s_m[idx] - s_m[idx].mean()) / max(float(np.ptp(s_m[idx])), 1e-12)
    y = d[idx]
    noise = max(robust_noise(y), 1e-3 * float(np.median(np.abs(y))), 1e-12)
    smooth = _robust_poly(x, y, 4, noise, ("cauchy",))
    resid = np.abs(y - smooth)
    out[idx] = (resid > OFF_PROFILE_Z * np.maximum(sd[idx], noise)) & (resid > OFF_PROFILE_REL * np.abs(smooth))
    return out


#: two frames' samples of a station this far apart [px] (sd of a Gaussian weight) read the same background pixels
SAME_PIXELS_PX = 1.0


def _median_sd(sd: NDArray, n: NDArray) -> NDArray:
    """sd of the median of ``n`` independent values of sd ``sd``: sd sqrt((1 + (pi/2 - 1)(1 - 1/n)) / n); 1 value:
    sd, many: sqrt(pi/2) sd / sqrt(n) (the median's asymptotic efficiency)."""
    n = np.maximum(np.asarray(n, float), 1.0)
    return sd * np.sqrt((1.0 + (np.pi / 2 - 1.0) * (1.0 - 1.0 / n)) / n)


def _independent_frames(uv: NDArray) -> NDArray:
    """Effective number of frames with independent background errors at each station, (k,), from where
    the frames saw it, ``uv`` (n_frames, k, 2) [px] (nan where a frame did not): n^2 / sum_jl c_jl with
    c_jl = exp(-|uv_j - uv_l|^2 / (2 ``SAME_PIXELS_PX``^2)) (the correlation of two frames' background
    errors; 1 for a station that never moved, n for one seen over other pixels in every frame)."""
    from scipy.spatial.distance import pdist

    seen = np.all(np.isfinite(uv), axis=-1)  # (n, k)
    n = seen.sum(axis=0)
    total = n.astype(float)  # c_jj = 1
    for i in range(uv.shape[1]):  # one station at a time, pairs once: no (n, n, k) array for long videos
        d2 = pdist(uv[seen[:, i], i], "sqeuclidean")
        total[i] += 2.0 * np.exp(-0.5 * d2 / SAME_PIXELS_PX**2).sum()
    return n**2 / np.maximum(total, 1.0)


def combine_profiles(
    profiles: list[WidthProfile], s_m: NDArray, min_frames: int = 3, depth_scale_sd: float = 0.0
) -> DiameterProfile:
    """Median over frames of widths measured at the same stations ``s_m`` (k,), with an honest sd.

    The frames of a push share their background, so their errors at a station are correlated and
    do not average down as 1/sqrt(n): the sd is the larger of the frames' spread over sqrt(n), their
    own sd over the square root of the number of frames that saw the station over other pixels
    (:func:`_independent_frames`; 1 where the stem stood still), and the noise the combined profile
    shows along the stem, measured by second differences of neighbouring stations (robust, Rice 1984;
    the true profile is smooth on the scale of a few pixels), which scales every station's sd up when
    it is the larger. A stem whose widest stations read under :data:`THIN_PX` pixels adds a resolution
    term to the shared scale error (:func:`thin_scale_sd`); under :data:`RESOLVED_PX` every station is
    ``unresolved``.
    """
    s_m = np.asarray(s_m, float)
    k = s_m.size
    W = np.full((len(profiles), k), np.nan)
    S = np.full((len(profiles), k), np.nan)
    raw = np.full((len(profiles), k), np.nan)  # every frame's number, flagged or not
    UV = np.full((len(profiles), k, 2), np.nan)  # where each frame saw each station [px]
    flags = np.full((len(profiles), k), "", dtype=object)
    for j, wp in enumerate(profiles):
        idx = np.searchsorted(s_m, wp.s_m)
        hit = (idx < k) & np.isclose(s_m[np.minimum(idx, k - 1)], wp.s_m, rtol=0, atol=1e-9)
        flags[j, idx[hit]] = wp.flag[hit]
        raw[j, idx[hit]] = wp.width_m[hit]
        good = hit & (wp.flag == "ok")
        W[j, idx[good]] = wp.width_m[good]
        S[j, idx[good]] = wp.sd_m[good]
        UV[j, idx[good]] = wp.uv[good]
    n = np.sum(np.isfinite(W), axis=0)
    d = np.full(k, np.nan)
    sd = np.full(k, np.nan)
    ok = n >= min_frames
    if ok.any():
        med = np.nanmedian(W[:, ok], axis=0)
        spread = 1.4826 * np.nanmedian(np.abs(W[:, ok] - med), axis=0)
        own = np.nanmedian(S[:, ok], axis=0)
        # the median of n independent values: about sqrt(pi/2) x the mean's sd (1 for one value). A frame's
        # own error (the background's pixels) averages down only over frames that saw the station over other
        # pixels: near the base, where the stem barely moves, all frames read the same background and agree
        # with each other; their spread over sqrt(n) left the grass's z-scores at rms 1.4-1.9 below s/L 0.3
        # (0.9-1.0 above mid-stem)
        n_eff = _independent_frames(UV[:, ok])
        sd_ok = np.maximum(_median_sd(spread, n[ok]), _median_sd(own, n_eff))
        d[ok], sd[ok] = med, sd_ok
        if ok.sum() >= 8:
            rice = robust_noise(med)
            typical = float(np.median(sd_ok))
            if rice > typical:
                sd[ok] *= rice / typical
    off = _off_profile(s_m, d, sd, ok & (d > 0) & (sd > 0))  # an unresolved tip is flagged as such below
    ok &= ~off
    # flagged stations keep a number (the median of whatever the frames measured) for the record
    other = ~ok & ~off & (np.sum(np.isfinite(raw), axis=0) > 0)
    if other.any():
        d[other] = np.nanmedian(raw[:, other], axis=0)
        sd[other] = 1.4826 * np.nanmedian(np.abs(raw[:, other] - d[other]), axis=0) + 1e-12
    flag = np.full(k, "ok", dtype=object)
    flag[off] = "off_profile"
    for i in np.flatnonzero(~ok & ~off):
        seen = [f for f in flags[:, i] if f]
        if not seen:
            flag[i] = "unseen"
        elif any(f == "ok" for f in seen):
            flag[i] = "few_frames"
        else:
            vals, counts = np.unique(seen, return_counts=True)
            flag[i] = str(vals[np.argmax(counts)])
    # below resolution: at a thin tip the frames' median width can come out at or below zero (the noise of
    # the coverage integral exceeds the width); no diameter to report there
    flag[ok & ~((d > 0) & (sd > 0))] = "unresolved"
    # metres per pixel where the stem was measured (the stations' own widths in both units)
    px = [wp.width_m[wp.flag == "ok"] / wp.width_px[wp.flag == "ok"] for wp in profiles]
    px = np.concatenate(px) if px else np.array([])
    px = px[np.isfinite(px) & (px > 0)]
    offset_sd = OFFSET_SD_PX * float(np.median(px)) if px.size else 0.0
    # the stem's widest stations in pixels: too thin a stem is read with a resolution error, or not at all
    measured = flag == "ok"
    base_px = float(np.percentile(d[measured], 95)) / float(np.median(px)) if measured.any() and px.size else np.nan
    if base_px < RESOLVED_PX:
        flag[measured] = "unresolved"
    # each frame divides its narrow stations by its own contrast scale, so a frame's scale error is shared by all
    # its stations; the median over frames averages it down over frames only, not over stations as the stations'
    # own sd (from the frames' spread at each station, taken as independent along the stem) would have it. The
    # scale error left in the combined profile: the frames' sd of their scales over sqrt(frames). (Taking the
    # frames' sd itself, the error of one frame, made the grass's d0 intervals +-4.5-7% for errors of sd 1.6%,
    # and adding a 2% error of the estimator +-3.7-4.6% for errors of rms 1.1%: twice too wide both;
    # docs/validation.md.)
    n_frames = len(profiles)
    contrast_sd = float(np.std([wp.contrast_scale for wp in profiles])) / np.sqrt(n_frames) if n_frames > 1 else 0.0
    # a blur wide against the stem leaves the contrast weakly determined, the same way in every frame
    ratios = np.array([wp.blur_over_width for wp in profiles], float)
    ratio = float(np.median(ratios[np.isfinite(ratios)])) if np.isfinite(ratios).any() else float("nan")
    # and the lens's shape, which the contrast fit takes for a Gaussian, in the frames' median share of fitted
    # stations
    shares = np.array([wp.borrowed_share for wp in profiles], float)
    # and how far the fit's two variants landed apart near the switch between them
    spreads = np.array([wp.contrast_variant_spread for wp in profiles], float)
    spread = float(np.median(spreads[np.isfinite(spreads)])) if np.isfinite(spreads).any() else 0.0
    fit_sd = contrast_fit_scale_sd(ratio, float(np.median(shares)) if shares.size else 0.0, spread, base_px)
    return DiameterProfile(
        s_m=s_m,
        d_m=d,
        sd_m=sd,
        n_frames=n.astype(int),
        flag=flag.astype(str),
        shared_offset_sd_m=offset_sd,
        shared_scale_sd=float(np.linalg.norm([depth_scale_sd, contrast_sd, fit_sd])),
        # the blur reads thin stations differently from thick ones, so it errs in the taper too (the 3.3- and 5-px
        # synthetic stems under one blur read 2-4% apart: a slope of 0.06-0.1 in relative error per unit of log
        # width, against the blur term's 2-7%; docs/validation.md, "The taper under a wide blur")
        shared_taper_sd=blur_scale_sd(ratio),
        blur_over_width=ratio,
        base_width_px=base_px,
        contrast_variant_spread=spread,
    )

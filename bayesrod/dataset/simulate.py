"""Synthetic datasets from the forward model (``bayesrod simulate``).

A push is simulated as the robot sees it: the sensor advances uniformly in
time from first contact; the wire sensor deflects under the contact force (a
linear-elastic wire of axial stiffness ``WIRE_STIFFNESS``), so the robot's
advance is the contact displacement plus the wire's lateral deflection; the
stem follows the elastica (with any effects) until it slips past the sensor,
after which the force falls to the sensor's bias. Forces carry Gaussian noise;
centerlines are sampled at equal arc length with Gaussian noise and are
occluded around the sensor and missing at the thin tip.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from .._version import __version__
from ..physics import Effects, force_from_displacement
from ..physics.elastica import centerline_at, force_from_displacement_nd
from ..physics.lumped import wire_elongation_from_dx
from ..physics.presets import get_preset
from .io import write_csv, write_json
from .model import FORMAT, Dataset, ForceSeries

WIRE_LENGTH = 0.44  # m, the seed's wire sensor span
WIRE_STIFFNESS = 2000.0  # N/m axial stiffness of the whole wire
ROBOT_SPEED = 0.02  # m/s
FRAME_EVERY = 3  # robot steps between camera frames of a fixed-step push (SimConfig.frame_step_m)
BASE_DIAMETER = {"twig": 0.010, "grass": 0.004}  # of the rendered stems [m], by preset kind


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise of a simulated dataset (all standard deviations)."""

    force_sd_N: float = 0.03
    shape_sd_m: float = 0.0015
    occlusion_half_height_m: float = 0.02  # centerline hidden within this of the sensor height
    tip_missing_fraction: float = 0.03  # thin tip not seen, as a fraction of L
    shape_sd_reported_m: float | None = None  # sd_m written to shapes.csv (default: shape_sd_m)
    force_rho: float = 0.0  # lag-1 correlation of stationary AR(1) force noise (marginal sd force_sd_N)

    @classmethod
    def none(cls) -> NoiseModel:
        return cls(0.0, 0.0, 0.0, 0.0)


DEFAULT_NOISE = {
    "twig": NoiseModel(force_sd_N=0.03, shape_sd_m=0.0015, occlusion_half_height_m=0.02),
    "grass": NoiseModel(force_sd_N=0.015, shape_sd_m=0.001, occlusion_half_height_m=0.008),
}


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a simulated dataset."""

    specimen: str
    species: str
    length_m: float
    EI0: float
    p: float
    heights_m: tuple[float, ...]
    effects: Effects = field(default_factory=Effects)
    noise: NoiseModel = field(default_factory=NoiseModel)
    seed: int = 0
    n_force_engaged: int = 60
    n_force_after: int = 8
    n_frames_engaged: int = 20
    n_frames_after: int = 2
    n_points: int = 80
    # the sensor's range declared in specimen.json [N]; None (default): (0.05, the smallest of
    # SENSOR_CAPACITIES_N that holds the simulated forces with a tenth to spare), so the data never exceed it
    force_range_N: tuple[float, float] | None = None
    # the robot stops after this contact displacement if the stem has not slipped (None: push until the slip)
    max_contact_displacement_m: float | None = None
    # the robot's step between force samples [m]; None (default): n_force_engaged samples spread over the
    # loading branch, a spacing chosen knowing where the stem will slip. A fixed step is what a rig does
    # (the number of engaged samples then depends on the stem): the design the slip term models
    robot_step_m: float | None = None
    # the robot's travel between camera frames [m]; None (default): with robot_step_m, a frame every
    # FRAME_EVERY robot steps (a camera at a fixed rate); without it, n_frames_engaged frames spread up to the
    # slip (again a spacing chosen knowing where the stem will slip: the frames' displacements tell it)
    frame_step_m: float | None = None
    # the rendered stem's diameter d(s) = d0 (1 - s/L)^q (frames only): d0 [m] (None: 1 cm for a twig, 4 mm
    # for a grass) and q (None: q = p, a uniform modulus; q != p is a modulus E(s) ~ (1 - s/L)^(4 (p - q)))
    base_diameter_m: float | None = None
    diameter_taper: float | None = None
    # frames draw each pixel's exact coverage of the true width (the diameter study); default whole-pixel widths
    exact_width: bool = False
    # with exact_width: "flat" (one stem colour) or "shaded" (a round stem's limb darkening, a defocused lens)
    render_style: str = "flat"
    # the frames' sensor noise: sd of each pixel's fresh noise per frame [grey levels]
    sensor_noise: float = 3.0

    @property
    def rendered_diameter(self) -> tuple[float, float]:
        """(d0 [m], taper q) of the stem the frames draw."""
        d0 = self.base_diameter_m or BASE_DIAMETER["grass" if self.p > 1.0 else "twig"]
        return float(d0), float(self.p if self.diameter_taper is None else self.diameter_taper)

    @classmethod
    def from_preset(
        cls, name: str, *, seed: int = 0, noise: str = "default", effects: Effects | None = None, **overrides
    ) -> SimConfig:
        pr = get_preset(name)
        if noise not in ("default", "none"):
            raise ValueError(f"noise: expected default or none, got {noise!r}")
        nm = DEFAULT_NOISE[name] if noise == "default" else NoiseModel.none()
        kw = dict(
            specimen=f"{pr['specimen']}-sim-{seed}",
            species=pr["species"],
            length_m=pr["length_m"],
            EI0=pr["EI0"],
            p=pr["p"],
            heights_m=tuple(pr["heights_m"]),
            effects=effects or Effects(),
            noise=nm,
            seed=seed,
        )
        kw.update(overrides)
        return cls(**kw)


def ar1_noise(rng: np.random.Generator, sd: float, rho: float, n: int) -> np.ndarray:
    """Stationary AR(1) noise of marginal sd ``sd`` and lag-1 correlation ``rho``; iid draws when rho = 0.

    With rho = 0 it consumes exactly the draws ``rng.normal(0, sd, n)`` does (seeded datasets unchanged).
    """
    z = rng.normal(0.0, sd, n)
    if rho == 0.0 or n == 0:
        return z
    if not -1 < rho < 1:
        raise ValueError(f"noise_rho: expected a correlation in (-1, 1), got {rho}")
    out = np.empty(n)
    out[0] = z[0]
    c = np.sqrt(1.0 - rho**2)
    for t in range(1, n):
        out[t] = rho * out[t - 1] + c * z[t]
    return out


def wire_deflection(
    force_N: np.ndarray, wire_length_m: float = WIRE_LENGTH, stiffness: float = WIRE_STIFFNESS
) -> np.ndarray:
    """Lateral wire deflection dx [m] carrying horizontal force F (vectorised bisection).

    F = 2 T sin(alpha), T = k_w * elongation, sin(alpha) = dx / sqrt((L_w/2)^2 + dx^2).
    """
    F = np.clip(np.asarray(force_N, float), 0.0, None)
    a = 0.5 * wire_length_m
    lo, hi = np.zeros_like(F), np.full_like(F, wire_length_m)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        r = np.hypot(a, mid)
        g = 2 * stiffness * wire_elongation_from_dx(mid, wire_length_m) * mid / r
        lo, hi = np.where(g < F, mid, lo), np.where(g < F, hi, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class SimulatedPush:
    """Arrays of one simulated push (before writing)."""

    id: str
    height_m: float
    time_s: np.ndarray
    force_N: np.ndarray
    robot_x_m: np.ndarray
    wire_elongation_m: np.ndarray
    contact_x_m: np.ndarray
    engaged: np.ndarray
    frame_time_s: np.ndarray
    frame_contact_x_m: np.ndarray  # NaN after the slip
    shapes_true: np.ndarray  # (n_frames, 2, n_points) noise-free centerlines
    shapes_obs: np.ndarray  # (n_frames, 2, n_points), NaN where not observed
    s_m: np.ndarray  # (n_points,) arc length of each point


def _loading_branch(cfg: SimConfig, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact (D, F_true) samples of the loading branch from first contact to its end.

    The end (the slip: contact passes the tip, the stem bends over, or the
    force curve turns) is bracketed on a grid and refined once, to ~6e-5 L
    below the model's own end; every sample returned is an exact solve on
    the branch. The solver's cost grows with its iterations, hardly with the
    batch size, so one large grid and one large refinement beat rounds of
    bisection (simulation time 2.5x lower than four rounds of 33).
    """
    L, EI0, p, eff = cfg.length_m, cfg.EI0, cfg.p, cfg.effects
    D_grid = 1.3 * L * np.linspace(0.0, 1.0, 257) ** 1.5  # a call costs its iterations, hardly its size
    sol = force_from_displacement(D_grid, h, EI0, p, L, eff)
    ok = ~sol.slipped
    if ok.sum() < 3:
        raise ValueError(f"height_m: expected a height the stem can be pushed at, got {h:g} m (slips at once)")
    i_lo = int(np.flatnonzero(ok).max())
    keep = ok & (np.arange(D_grid.size) <= i_lo)
    Ds, Fs = [D_grid[keep]], [sol.true_force_N[keep]]
    # one batched refinement of 126 candidates: 0.008 L / 127 ~ 6e-5 L
    cand = np.linspace(D_grid[i_lo], D_grid[min(i_lo + 1, D_grid.size - 1)], 128)[1:-1]
    sol = force_from_displacement(cand, h, EI0, p, L, eff)
    first = int(np.argmax(sol.slipped)) if sol.slipped.any() else cand.size
    Ds.append(cand[:first])
    Fs.append(sol.true_force_N[:first])
    D, F = np.concatenate(Ds), np.concatenate(Fs)
    order = np.argsort(D)
    return D[order], F[order]


def _step_back(D: NDArray, L: float, solve, slipped, tries: int = 12) -> tuple[NDArray, object]:
    """Contact displacements (m) moved back until ``solve`` holds contact at each: 1e-6 L, then 4x more per try.

    Near the branch's end (it folds, or is flat) a displacement the placement table puts on the branch
    may be past it, or its solve ill-conditioned; the nearest one behind it that solves is what a rig
    records there. Returns the displacements and the last solve (``slipped(sol)`` True where none held).
    """
    sol = solve(D)
    for k in range(tries):
        bad = np.asarray(slipped(sol))
        if not bad.any():
            break
        D = np.where(bad, np.maximum(D - 1e-6 * L * 4**k, 0.0), D)
        sol = solve(D)
    return D, sol


def simulate_push(cfg: SimConfig, h: float, rng: np.random.Generator) -> SimulatedPush:
    L, EI0, p, eff = cfg.length_m, cfg.EI0, cfg.p, cfg.effects
    D_branch, F_branch = _loading_branch(cfg, h)
    D_end = D_branch[-1]
    cap = cfg.max_contact_displacement_m
    capped = cap is not None and cap < D_end
    if capped:
        D_end = float(cap)  # the push stops before the slip; the robot then withdraws
    # Robot position over the branch, to place samples at a uniform robot advance: the force is smooth in
    # D (monotone cubic through the exact samples, kinks at yield kept), the wire deflection grows like
    # F^(1/3) near first contact, so robot(D) is built on a fine grid from the exact wire law. Only the
    # placement uses this table: every recorded sample is solved exactly below.
    D_dense = D_end * np.linspace(0.0, 1.0, 3000) ** 1.5
    F_dense = PchipInterpolator(D_branch, F_branch)(D_dense)
    robot_dense = D_dense + wire_deflection(F_dense)
    # Uniform robot advance in time; exact contact displacement at each sample.
    x_slip = robot_dense[-1]
    if cfg.robot_step_m is not None:
        step = float(cfg.robot_step_m)
        n_e = int(np.floor(x_slip / step)) + 1  # every sample up to the slip (or the cap)
        if n_e < 4:
            raise ValueError(
                f"robot_step_m: expected a step giving at least 4 engaged samples at h = {h:g} m (the branch "
                f"ends at a robot advance of {x_slip:.4g} m), got {step:g} m"
            )
    else:
        n_e = cfg.n_force_engaged
        step = x_slip / (n_e - 0.5)
    robot = np.arange(n_e + cfg.n_force_after) * step
    engaged = robot <= x_slip
    D = np.interp(robot[engaged], robot_dense, D_dense)
    D, eng = _step_back(D, L, lambda d: force_from_displacement(d, h, EI0, p, L, eff), lambda r: r.slipped)
    if eng.slipped.any():
        raise RuntimeError(f"simulate: {int(eng.slipped.sum())} engaged samples past the slip at h = {h:g} m")
    back = np.flatnonzero(np.diff(D) <= 0.0)
    if back.size:
        # a sample stepped back behind the one before it lay past the end of the loading branch the placement
        # table smooths over (a fold near the end): the stem slipped before the robot got there, so it and
        # every later sample are past the slip (they had the robot move backwards in time)
        keep = int(back[0]) + 1
        engaged[np.flatnonzero(engaged)[keep:]] = False
        D = D[:keep]
        eng = force_from_displacement(D, h, EI0, p, L, eff)
    dx = wire_deflection(eng.true_force_N)
    robot[engaged] = D + dx  # exact robot position for the exact D (negligibly off uniform)
    force = np.full(robot.size, eff.force_offset)
    force[engaged] = eng.force_N
    wire = np.zeros(robot.size)
    wire[engaged] = wire_elongation_from_dx(dx, WIRE_LENGTH)
    contact = np.full(robot.size, np.nan)
    contact[engaged] = D
    force = force + ar1_noise(rng, cfg.noise.force_sd_N, cfg.noise.force_rho, robot.size)
    time = robot / ROBOT_SPEED
    if capped:
        # the record of a push that stops short ends where the robot turns back (a dataset's push is one
        # loading ramp, docs/format.md): no samples after it, which would read as a slip at the cap. The
        # noise is drawn for them all the same, so the random stream (and every later draw) is unchanged
        robot, force, wire, contact, time, engaged = (a[engaged] for a in (robot, force, wire, contact, time, engaged))
    # Frames: a camera clock of its own on the same time base.
    t_slip = robot[engaged][-1] / ROBOT_SPEED
    frame_step = cfg.frame_step_m or (FRAME_EVERY * cfg.robot_step_m if cfg.robot_step_m is not None else None)
    if frame_step is not None:  # a camera at a fixed rate: the number of frames before the slip depends on the stem
        t_frames = np.arange(0.3, t_slip * ROBOT_SPEED / frame_step, 1.0) * frame_step / ROBOT_SPEED
    else:
        t_frames = (np.arange(cfg.n_frames_engaged) + 0.3) * t_slip / cfg.n_frames_engaged
    D_frames = np.interp(t_frames * ROBOT_SPEED, robot_dense, D_dense)
    nd = eff.nondim(L, EI0)
    # A frame before the slip whose solve fails lies where the branch's end is flat or folds (e.g. the stem
    # bent over until it is nearly horizontal at the sensor: the force is flat to 1e-8 over the last cm and
    # the contact ill-conditioned, scripts/sbc_geometry.py seed 57). It steps back like the force samples;
    # left as it was, its shape would be the unloaded stem's while its time said engaged.
    D_frames, _ = _step_back(
        D_frames, L, lambda d: force_from_displacement_nd(d / L, h / L, p, nd), lambda r: r["slipped"]
    )
    keep = np.ones(D_frames.size, bool)
    keep[1:] = np.diff(D_frames) > 0  # one stepped back behind the frame before it: the camera's clock ran forward
    t_frames, D_frames = t_frames[keep], D_frames[keep]
    nf = t_frames.size
    t_after = t_slip + (np.arange(1, cfg.n_frames_after + 1)) * 2 * step / ROBOT_SPEED
    t_all = np.concatenate([t_frames, t_after])
    D_all = np.concatenate([D_frames, np.zeros(t_after.size)])
    frames = force_from_displacement_nd(D_all / L, h / L, p, nd, keep_shape=True)
    grid_nd = frames["grid"]
    # each frame's exact time for its exact contact displacement (the camera clock, off uniform by the
    # placement table's error only)
    F_frames = frames["f"][:nf] * EI0 / L**2
    if not np.all(np.isfinite(F_frames)):
        raise RuntimeError(f"simulate: {int(np.sum(~np.isfinite(F_frames)))} frames past the slip at h = {h:g} m")
    t_all[:nf] = (D_frames + wire_deflection(F_frames)) / ROBOT_SPEED
    s = np.linspace(0.0, L, cfg.n_points)
    true = np.moveaxis(centerline_at(grid_nd, s / L), -1, 0) * L  # (frames, 2, points)
    obs = true + rng.normal(0.0, cfg.noise.shape_sd_m, true.shape)
    hide = np.abs(true[:, 1, :] - h) < cfg.noise.occlusion_half_height_m
    hide[:, s > L * (1 - cfg.noise.tip_missing_fraction)] = True
    hide[:, 0] = False
    obs[np.repeat(hide[:, None, :], 2, axis=1)] = np.nan
    frame_contact = np.concatenate([D_frames, np.full(t_after.size, np.nan)])
    return SimulatedPush(
        id=f"h{round(h * 1000):d}",
        height_m=h,
        time_s=time,
        force_N=force,
        robot_x_m=robot,
        wire_elongation_m=wire,
        contact_x_m=contact,
        engaged=engaged,
        frame_time_s=t_all,
        frame_contact_x_m=frame_contact,
        shapes_true=true,
        shapes_obs=obs,
        s_m=s,
    )


def simulate(cfg: SimConfig, progress: bool = False) -> list[SimulatedPush]:
    """Simulate every push of ``cfg`` (deterministic for a given seed)."""
    from tqdm.auto import tqdm

    rng = np.random.default_rng(cfg.seed)
    heights = tqdm(cfg.heights_m, desc="simulating pushes", unit="push", disable=not progress, leave=False)
    pushes, seen = [], {}
    for h in heights:
        sp = simulate_push(cfg, h, rng)
        seen[sp.id] = seen.get(sp.id, 0) + 1
        if seen[sp.id] > 1:  # the same height pushed again: a unique id (h450, h450-2, ...)
            sp = replace(sp, id=f"{sp.id}-{seen[sp.id]}")
        pushes.append(sp)
    return pushes


#: capacities [N] of the force sensor a simulated rig declares (:func:`sensor_range`)
SENSOR_CAPACITIES_N = (8.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0)


def sensor_range(cfg: SimConfig, pushes: list[SimulatedPush]) -> tuple[float, float]:
    """The force range [N] the simulated sensor declares: ``cfg.force_range_N`` when set, else from 0.05 N
    to the smallest of :data:`SENSOR_CAPACITIES_N` at least 1.1 times the largest simulated force (a
    sensor that held the push: a declared range the data exceed reads as saturation, and ``design``
    judges heights against it)."""
    if cfg.force_range_N is not None:
        return (float(cfg.force_range_N[0]), float(cfg.force_range_N[1]))
    peak = 1.1 * max((float(np.max(sp.force_N, initial=0.0)) for sp in pushes), default=0.0)
    top = next((c for c in SENSOR_CAPACITIES_N if c >= peak), None)
    return (0.05, top if top is not None else float(10 ** np.ceil(np.log10(peak))))


def truth_record(cfg: SimConfig) -> dict:
    """What a simulated dataset records of its truth (specimen.json ``truth``; the API's ``extra["truth"]``):
    EI0 [N m^2], p, the effects, the noise (the AR(1) correlation ``force_rho`` only where there is one) and the
    seed."""
    noise = {"force_sd_N": cfg.noise.force_sd_N, "shape_sd_m": cfg.noise.shape_sd_m}
    if cfg.noise.force_rho:
        noise["force_rho"] = cfg.noise.force_rho
    return {"EI0": cfg.EI0, "p": cfg.p, "effects": cfg.effects.to_mapping(), "noise": noise, "seed": cfg.seed}


def write_simulated(
    cfg: SimConfig,
    pushes: list[SimulatedPush],
    out: Path,
    *,
    frames: bool = False,
    camera: dict | None = None,
    arm: str = "leading",
    extra: dict | None = None,
) -> None:
    """Write a ``bayesrod.dataset/1`` directory (into ``out``, which must exist).

    ``arm`` places the probe's holder in the rendered frames (``bayesrod.vision.render.render_frame``);
    ``extra``: further top-level keys of specimen.json (``stem_id``, ``condition``).
    """
    doc = {
        "format": FORMAT,
        "specimen": cfg.specimen,
        "species": cfg.species,
        "length_m": cfg.length_m,
        "sensor": {"type": "wire", "wire_length_m": WIRE_LENGTH, "force_range_N": list(sensor_range(cfg, pushes))},
        "pushes": [],
        "truth": {**truth_record(cfg), "generator": f"bayesrod simulate {__version__}"},
    }
    if frames:  # the drawn stem's diameter and the Young's modulus it implies (E0 = 64 EI0 / (pi d0^4))
        d0, q = cfg.rendered_diameter
        doc["truth"].update(base_diameter_m=d0, diameter_taper=q, youngs_modulus_Pa=64.0 * cfg.EI0 / (np.pi * d0**4))
    doc.update(extra or {})
    if frames and camera is not None:
        doc["camera"] = camera
    for sp in pushes:
        d = out / sp.id
        d.mkdir(parents=True, exist_ok=True)
        write_csv(
            d / "force.csv",
            {
                "time_s": sp.time_s,
                "force_N": sp.force_N,
                "robot_x_m": sp.robot_x_m,
                "wire_elongation_m": sp.wire_elongation_m,
            },
        )
        entry = {"id": sp.id, "height_m": sp.height_m, "direction": 1, "force": f"{sp.id}/force.csv"}
        rows = {"time_s": [], "x_m": [], "z_m": []}
        sd = []
        for k, t in enumerate(sp.frame_time_s):
            seen = np.isfinite(sp.shapes_obs[k, 0])
            rows["time_s"].append(np.full(seen.sum(), t))
            rows["x_m"].append(sp.shapes_obs[k, 0, seen])
            rows["z_m"].append(sp.shapes_obs[k, 1, seen])
            reported = cfg.noise.shape_sd_reported_m
            sd.append(np.full(seen.sum(), cfg.noise.shape_sd_m if reported is None else reported))
        cols = {k: np.concatenate(v) for k, v in rows.items()}
        if cfg.noise.shape_sd_m > 0:
            cols["sd_m"] = np.concatenate(sd)
        write_csv(d / "shapes.csv", cols)
        entry["shapes"] = f"{sp.id}/shapes.csv"
        write_csv(
            d / "truth_shapes.csv",
            {
                "time_s": np.repeat(sp.frame_time_s, sp.s_m.size),
                "s_m": np.tile(sp.s_m, sp.frame_time_s.size),
                "x_m": sp.shapes_true[:, 0, :].ravel(),
                "z_m": sp.shapes_true[:, 1, :].ravel(),
                # exact contact displacement of the frame; -1 after the slip (unloaded stem)
                "contact_x_m": np.repeat(np.nan_to_num(sp.frame_contact_x_m, nan=-1.0), sp.s_m.size),
            },
        )
        entry["truth_shapes"] = f"{sp.id}/truth_shapes.csv"
        if frames:
            from ..vision.render import render_push_frames

            render_push_frames(
                cfg, sp, d / "frames", camera, np.random.default_rng([cfg.seed, round(sp.height_m * 1e6)]), arm
            )
            entry["frames"] = f"{sp.id}/frames"
        doc["pushes"].append(entry)
    write_json(out / "specimen.json", doc)


def started_loaded(ds: Dataset, preloads_m) -> Dataset:
    """The dataset as a rig that began recording ``preloads_m[j]`` [m] into push j would have written it.

    Each push keeps its samples from where the contact displacement reaches the preload on, with the
    displacements counted from there (the preload is lost to the record, as on a rig), and the frames
    taken from that moment on. For studies of the preload nuisance (docs/inference.md, "Preloads"); the
    truth is set by the simulator, independently of the fit's tables.

    Parameters
    ----------
    ds : Dataset
    preloads_m : sequence of float, shape (n_pushes,)
        Contact displacement already made when recording began, per push [m] (0: the push as it is).
    """
    if len(preloads_m) != len(ds.pushes):
        raise ValueError(f"preloads_m: expected one per push ({len(ds.pushes)}), got {len(preloads_m)}")
    pushes = []
    for push, delta in zip(ds.pushes, preloads_m, strict=True):
        f = push.force
        keep = f.contact_x_m >= delta
        if not keep.any():
            raise ValueError(f"preloads_m: expected a preload inside push {push.id}, got {delta} m past its end")
        wire = None if f.wire_elongation_m is None else f.wire_elongation_m[keep]
        force = ForceSeries(
            f.time_s[keep], f.force_N[keep], f.robot_x_m[keep] - delta, wire, f.contact_x_m[keep] - delta
        )
        frames = None if push.shapes is None else tuple(s for s in push.shapes if s.time_s >= f.time_s[keep][0])
        pushes.append(replace(push, force=force, shapes=frames))
    return replace(ds, pushes=tuple(pushes))

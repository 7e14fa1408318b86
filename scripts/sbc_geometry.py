"""Simulation-based calibration over geometries and effects, on data the slow reference solver made.

    python scripts/sbc_geometry.py --replicates 60 --jobs 2 --out sbc-geometry

Each replicate draws, from its seed:

* the stem: EI0, p and the force noise from scripts/sbc_prior.json (as scripts/sbc.py);
* the geometry: L uniform in [0.5, 1.5] m, one, two or three contact heights with h/L in [0.35, 0.8];
* the data: forces only, or forces and centerlines (alternating with each cycle of the effects, so each
  effect is seen both ways);
* one model effect or none, cycling through none, base_compliance, rest_curvature, force_offset, base_tilt
  and contact_friction (``--effects`` may add yield; self_weight cannot be fitted), its value drawn from the
  same prior's effect block; the effect is switched on in the simulation *and fitted*. A yield replicate is
  forces only (the fit refuses centerlines with yield).

The pushes are placed by bayesrod's simulator with a fixed robot step of 0.01 L (``--step-l``; the
simulator's default spreads 60 samples knowing where each push slips, so the robot positions alone give
the slip away, a design no likelihood models: docs/validation.md), then every recorded force and every
frame's centerline is solved again by ``bayesrod.physics.reference`` (adaptive DOP853 + brentq, not the
fast path the fit uses) and the simulator's noise is added back to the reference values. The fit is
``bayesrod.fit`` with the same prior. For EI0, p, the force noise and the effect it records the rank of
the truth among 99 thinned posterior draws and whether the 90% interval covers it, and from the fit's own
``table_check`` the largest shift its tables would cause at the posterior median (``table_shift_sd``, Laplace
sds; ``table_shift_worst``, the parameter it moves most) and whether it narrowed its effect axis
and its p grid (``effect_axis_zoom``, ``p_axis_zoom``: none, kept or refused), decided by the check at the
sampler's start
(``table_shift_start_sd``; ``bayesrod.api.calibration.table_columns``). Writes
``sbc_geometry.csv`` (resumable: rows already there are not recomputed) and ``sbc_geometry.md`` (coverage
per parameter and per case, with the binomial range of 90% coverage and a chi-square test of the rank
histogram) into --out.

A seed fixes its case and its noise draws whatever the effect cycle: runs over the same seeds with other
``--effects`` (the yield study's odd seeds 1-79 and the main study's 0-119) share their noise draws, so a lean
they show together is one piece of evidence, not two. ``scripts/sbc_noise_draws.py`` reports how large a seed
set's force-noise draws came out before any fit (seeds 0-119 drew them small: docs/validation.md, session 61).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _study import calibration_stats, run_pending  # noqa: E402

from bayesrod import simulate  # noqa: E402
from bayesrod.api.calibration import fit_for_calibration, rank_columns  # noqa: E402
from bayesrod.api.fitting import TABLE_SHIFT_WARN_SD  # noqa: E402
from bayesrod.dataset.model import ShapeFrame  # noqa: E402
from bayesrod.dataset.simulate import NoiseModel  # noqa: E402
from bayesrod.inference.priors import load_prior  # noqa: E402
from bayesrod.physics import force_from_displacement  # noqa: E402
from bayesrod.physics import reference as R  # noqa: E402

PRIOR = str(Path(__file__).with_name("sbc_prior.json"))
EFFECTS = (None, "base_compliance", "rest_curvature", "force_offset", "base_tilt", "contact_friction")
#: the cycle before contact friction joined it: the base-spring and table studies of docs/validation.md draw their
#: cases from it (its base-compliance seeds are 1 mod 5)
EFFECTS_BEFORE_FRICTION = EFFECTS[:-1]
#: every effect ``--effects`` accepts: the default cycle (EFFECTS, kept so earlier seeds draw the same cases) and yield
ALL_EFFECTS = EFFECTS + ("yield",)
PARAMS = ("EI0", "p", "sigma_force_N", "effect")
FIELDS = (
    ["seed", "length_m", "n_heights", "shapes", "effect", "rhat_max", "max_ref_vs_fast_N", "n_fast_fallback"]
    + [f"{k}_{s}" for k in PARAMS for s in ("true", "median", "rank", "covered")]
    + ["table_shift_sd", "table_shift_worst", "effect_axis_zoom", "table_shift_start_sd", "error", "p_axis_zoom"]
)
N_RANK = 99


def draw_case(seed: int, effects: tuple = EFFECTS) -> dict:
    rng = np.random.default_rng(50_000 + seed)
    pr = load_prior(PRIOR)
    L = float(rng.uniform(0.5, 1.5))
    n_h = int(rng.integers(1, 4))
    eta = np.sort(rng.uniform(0.35, 0.8, n_h))
    while n_h > 1 and np.min(np.diff(eta)) < 0.05:  # distinct heights
        eta = np.sort(rng.uniform(0.35, 0.8, n_h))
    effect = effects[seed % len(effects)]
    case = {
        "EI0": float(pr.get("EI0").draw(rng, 1)[0]),
        "p": float(pr.get("p").draw(rng, 1)[0]),
        "sigma_force_N": float(pr.get("sigma_force_N").draw(rng, 1)[0]),
        "length_m": L,
        "heights_m": tuple(float(e * L) for e in eta),
        # forces only and with centerlines alternate per cycle of effects, so each effect gets both (but yield,
        # whose fit takes forces only)
        "shapes": bool((seed // len(effects)) % 2) and effect != "yield",
        "effect": effect,
    }
    if effect is not None:
        case["effect_value"] = float(pr.get(effect).draw(rng, 1)[0])
    return case


#: the case's own force noise, centerlines at 1.5 mm (simulate_case's default)
CASE_NOISE = "case"
#: the centerline points' noise sd of every case [m]
CASE_SHAPE_SD_M = 0.0015


def simulate_case(
    seed: int,
    case: dict,
    *,
    prefix: str = "sbcg",
    noise=CASE_NOISE,
    frames: int | None = None,
    step_l: float | None = 0.01,
    cap_l: float | None = None,
):
    """The simulator's dataset of a case from :func:`draw_case`: its stem, heights, effect and value.

    ``noise``: a :class:`NoiseModel`, or the case's force sd with centerlines at 1.5 mm; ``frames``: engaged
    frames per push (None: the simulator's default); ``step_l``: the robot's step as a fraction of L (None:
    60 samples spread knowing the slip); ``cap_l``: every push stops at this fraction of L (None: at its
    slip). The specimen is named ``{prefix}-{seed}``."""
    if noise is CASE_NOISE:
        noise = NoiseModel(
            force_sd_N=case["sigma_force_N"], shape_sd_m=CASE_SHAPE_SD_M, shape_sd_reported_m=CASE_SHAPE_SD_M
        )
    stem = {k: case[k] for k in ("EI0", "p", "length_m", "heights_m")} | {"specimen": f"{prefix}-{seed}"}
    switched = {case["effect"]: case["effect_value"]} if case["effect"] else {}
    extra = {} if frames is None else {"n_frames_engaged": frames}
    if cap_l is not None:  # a stop at a fixed fraction of L tells nothing about the stem; a stop at the slip does
        extra["max_contact_displacement_m"] = cap_l * case["length_m"]
    if step_l is not None:
        extra["robot_step_m"] = step_l * case["length_m"]
    return simulate(stem, seed=seed, noise_model=noise, effects=switched, config_overrides=extra)


def _reference_forces(d: np.ndarray, eta: float, p: float, nd: dict, m_yield: float) -> np.ndarray:
    """Nondimensional forces at contact displacements ``d`` (since first contact) by the reference solver.

    A base that yields at the nondimensional moment ``m_yield`` (inf: never) is a perfectly plastic hinge: the
    horizontal force at height eta holds the base moment at f eta, so a monotone push is elastic up to the
    displacement where the elastic force reaches m_yield / eta (solved force-first by the reference) and
    holds that force beyond it (the base rotating plastically)."""
    d_yield = np.inf
    if np.isfinite(m_yield):
        at_yield = R.solve_force(m_yield / eta, eta, p, nd)
        if at_yield["found"]:  # else the elastic branch ends before the base yields
            d_yield = at_yield["xi_c"] - R.solve_force(0.0, eta, p, nd)["xi_c"]
    return np.array([m_yield / eta if di >= d_yield else R.solve_displacement(di, eta, p, nd)["f"] for di in d])


def engaged_forces(sp, cfg) -> np.ndarray:
    """The noise-free sensor force [N] (offset included) of a simulated push ``sp`` of ``cfg`` at its engaged
    samples, by the fast path the simulator used: the recorded force minus it is the simulator's noise."""
    D = sp.contact_x_m[sp.engaged]
    return force_from_displacement(D, sp.height_m, cfg.EI0, cfg.p, cfg.length_m, cfg.effects).force_N


def reference_dataset(ds, case: dict):
    """The simulated dataset with every force and centerline solved again by the reference solver."""
    cfg, sim = ds.simulation
    L, EI0, p, eff = cfg.length_m, cfg.EI0, cfg.p, cfg.effects
    nd = {k: float(v) for k, v in eff.nondim(L, EI0).items()}
    m_yield = nd.pop("m_yield")  # the reference's rod has no yield: applied by _reference_forces
    pushes, worst, n_fallback = [], 0.0, 0
    for push, sp in zip(ds.pushes, sim, strict=True):
        eng = sp.engaged
        D = sp.contact_x_m[eng]
        fast = engaged_forces(sp, cfg)
        ref = _reference_forces(D / L, sp.height_m / L, p, nd, m_yield) * EI0 / L**2
        ref = ref + eff.force_offset
        # the last sample can lie within ~1e-6 L of the branch end, past the reference's own end: keep the
        # fast value there (counted)
        past = ~np.isfinite(ref)
        n_fallback += int(past.sum())
        ref[past] = fast[past]
        worst = max(worst, float(np.max(np.abs(ref - fast))))
        force = np.array(push.force.force_N, float)
        force[eng] = ref + (force[eng] - fast)  # the simulator's noise on the reference value
        frames = list(push.shapes or ())
        if case["shapes"]:
            frames = []
            for k, fr in enumerate(push.shapes):
                Dk = sp.frame_contact_x_m[k]
                seen = np.isfinite(sp.shapes_obs[k, 0])
                if not np.isfinite(Dk):
                    frames.append(fr)
                    continue
                f = R.solve_displacement(Dk / L, sp.height_m / L, p, nd)["f"] if Dk > 0 else 0.0
                if not np.isfinite(f):  # a frame within ~1e-3 L of the slip, past the reference's own: keep it
                    n_fallback += 1
                    frames.append(fr)
                    continue
                xz = R.shape_at_force(f, sp.height_m / L, p, sp.s_m / L, nd) * L
                noise = sp.shapes_obs[k] - sp.shapes_true[k]
                obs = xz + noise
                frames.append(ShapeFrame(fr.time_s, obs[0, seen], obs[1, seen], fr.sd_m))
        pushes.append(replace(push, force=replace(push.force, force_N=force), shapes=tuple(frames)))
    return replace(ds, pushes=tuple(pushes)), worst, n_fallback


#: the sampler's budget of every replicate's fit (scripts/table_check_line.py stops the same fit at its start)
FIT_BUDGET = {"target_ess": 400, "max_steps": 8000}


def replicate_dataset(seed: int, case: dict, step_l: float | None = 0.01, cap_l: float | None = None) -> tuple:
    """A replicate's data as its fit reads them: simulated (``step_l``, ``cap_l`` as :func:`replicate`; the
    default step is the command line's), then re-solved by the reference solver; returns (dataset, the largest
    |reference - fast| force [N], the samples the reference left to the fast solver)."""
    ds = simulate_case(seed, case, frames=None if case["shapes"] else 2, step_l=step_l, cap_l=cap_l)
    return reference_dataset(ds, case)


def replicate(
    seed: int, cap_l: float | None = None, slip: bool = False, step_l: float | None = None, effects: tuple = EFFECTS
) -> dict:
    """One replicate; ``cap_l``: every push stops at this fraction of the stem length (None: at the slip, the
    simulator's default); ``slip``: the fit uses where each push slipped (``bayesrod.fit(slip=True)``);
    ``step_l``: the robot's step between samples as a fraction of L (None: the simulator's default, 60
    samples spread over each push knowing where it will slip, a design that depends on the stem)."""
    case = draw_case(seed, effects)
    row = {"seed": seed, "length_m": case["length_m"], "n_heights": len(case["heights_m"])}
    row |= {"shapes": case["shapes"], "effect": case["effect"] or "none"}
    try:
        ds, worst, n_fallback = replicate_dataset(seed, case, step_l=step_l, cap_l=cap_l)
        res = fit_for_calibration(
            ds,
            PRIOR,
            seed=seed,
            use_shapes=case["shapes"],
            n_rank=N_RANK,
            effects=(case["effect"],) if case["effect"] else (),
            slip=slip,
            **FIT_BUDGET,
        )
    except Exception as e:  # a failed replicate is recorded (a row without numbers), never dropped
        print(f"seed {seed}: {type(e).__name__}: {e}", file=sys.stderr)
        return row | {"rhat_max": float("nan"), "max_ref_vs_fast_N": float("nan"), "error": f"{type(e).__name__}: {e}"}
    row |= {"rhat_max": res["rhat_max"], "max_ref_vs_fast_N": worst}
    row |= {"n_fast_fallback": n_fallback, "error": ""}
    row |= {
        k: res[k]
        for k in ("table_shift_sd", "table_shift_worst", "effect_axis_zoom", "table_shift_start_sd", "p_axis_zoom")
    }
    truth = {"EI0": case["EI0"], "p": case["p"], "sigma_force_N": case["sigma_force_N"]}
    names = {"EI0": "EI0", "p": "p", "sigma_force_N": "sigma_force_N", "effect": case["effect"]}
    if case["effect"]:
        truth["effect"] = case["effect_value"]
    for k in PARAMS:
        if k in truth and names[k] in res:
            row |= rank_columns(res[names[k]], truth[k], k)
    return row


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def summarise(rows: list[dict], out: Path) -> str:
    ok = [r for r in rows if np.isfinite(_num(r.get("rhat_max")))]
    refused = [r for r in rows if "DatasetError" in str(r.get("error", ""))]
    lines = [
        f"SBC over geometries and effects: {len(ok)} replicates ({len(refused)} datasets refused by the dataset "
        f"checks, {len(rows) - len(ok) - len(refused)} other failures), data re-solved "
        "by the reference solver, prior scripts/sbc_prior.json, 99 posterior draws per replicate "
        "(scripts/sbc_geometry.py).",
        "",
        "| parameter | cases | replicates | 90% coverage | binomial 95% range | misses: truth above / below | "
        f"mean rank (uniform {N_RANK / 2:g}) +- se | rank chi2 p (10 bins) |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def row_for(k, sel, label):
        vals = [r for r in sel if str(r.get(f"{k}_covered", "")) in ("True", "False", "1", "0")]
        if not vals:
            return
        c = calibration_stats(
            [str(r[f"{k}_covered"]) in ("True", "1") for r in vals], [_num(r[f"{k}_rank"]) for r in vals], N_RANK
        )
        lines.append(
            f"| {k} | {label} | {c['n']} | {c['coverage']:.2f} | {c['lo']:.2f}-{c['hi']:.2f} | {c['above']} / "
            f"{c['below']} | {c['mean_rank']:.1f} +- {c['se']:.1f} | {c['chi2_p']:.2f} |"
        )

    for k in PARAMS:
        row_for(k, ok, "all")
    for eff in ("none",) + ALL_EFFECTS[1:]:
        sel = [r for r in ok if r["effect"] == eff]
        for k in PARAMS:
            row_for(k, sel, f"effect {eff}")
    for shapes in ("False", "True"):
        sel = [r for r in ok if str(r["shapes"]) == shapes]
        for k in ("EI0", "p"):
            row_for(k, sel, "forces and shapes" if shapes == "True" else "forces only")
    for n_h in ("1", "2", "3"):
        sel = [r for r in ok if str(r["n_heights"]) == n_h]
        for k in ("EI0", "p"):
            row_for(k, sel, f"{n_h} height(s)")
    for n_h in ("1", "2", "3"):  # the two splits together: where a skew of the ranks sits
        for shapes in ("False", "True"):
            sel = [r for r in ok if str(r["n_heights"]) == n_h and str(r["shapes"]) == shapes]
            kind = "forces and shapes" if shapes == "True" else "forces only"
            for k in ("EI0", "p"):
                row_for(k, sel, f"{n_h} height(s), {kind}")
    checked = [r for r in ok if np.isfinite(_num(r.get("table_shift_sd")))]  # rows since session 66
    if checked:
        warned = [r for r in checked if _num(r["table_shift_sd"]) > TABLE_SHIFT_WARN_SD]
        missed = [r for r in warned if any(str(r.get(f"{k}_covered")) in ("False", "0") for k in PARAMS)]
        zoomed = sum(r.get("effect_axis_zoom") == "kept" for r in checked)
        p_zoomed = sum(r.get("p_axis_zoom") == "kept" for r in checked)  # a column since session 72
        lines += [
            "",
            f"The fit's own table check (rows that record it, {len(checked)}): {len(warned)} warned (tables move the "
            f"median by more than {TABLE_SHIFT_WARN_SD:g} sd; {len(missed)} of them missed a parameter), the effect "
            f"axis narrowed around the start in {zoomed}, the p grid in {p_zoomed}.",
        ]
    worst = max((_num(r["max_ref_vs_fast_N"]) for r in ok), default=float("nan"))
    rh = max((_num(r["rhat_max"]) for r in ok), default=float("nan"))
    lines += ["", f"Largest |reference - fast| force over all replicates: {worst:.2e} N; largest R-hat {rh:.3f}."]
    text = "\n".join(lines) + "\n"
    (out / "sbc_geometry.md").write_text(text)
    return text


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--replicates", type=int, default=60)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("sbc-geometry"))
    ap.add_argument(
        "--cap-l",
        type=float,
        default=None,
        help="stop every push at this fraction of the stem length instead of at the slip (e.g. 0.3: below every "
        "slip of the prior's one-height cases, 0.33-0.98 L)",
    )
    ap.add_argument("--slip", action="store_true", help="fit with the slip term (bayesrod.fit(slip=True))")
    ap.add_argument(
        "--step-l",
        type=float,
        default=0.01,
        help="the robot's step between force samples as a fraction of L (default 0.01, as a rig pushes); 0: the "
        "simulator's default design, 60 samples per push spread knowing where it slips (the CSVs before 2026-11-26)",
    )
    ap.add_argument(
        "--effects",
        default=",".join(EFFECTS[1:]),
        help="the effects the replicates cycle through after 'none' (comma separated; default all of "
        f"{', '.join(EFFECTS[1:])}; yield may be added); contact_friction's likelihood tables take tens of minutes "
        "per replicate",
    )
    ap.add_argument(
        "--only",
        choices=["all", "forces", "one-height-forces"],
        default="all",
        help="replicates to run: all, only the forces-only ones, or only the one-height forces-only ones",
    )
    ap.add_argument(
        "--skip-none",
        action="store_true",
        help="leave out the replicates without an effect (e.g. --effects base_compliance --skip-none: only springs)",
    )
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    csv = args.out / "sbc_geometry.csv"
    seeds = range(args.first_seed, args.first_seed + args.replicates)
    effects = (None, *[e for e in args.effects.split(",") if e])
    bad = [e for e in effects[1:] if e not in ALL_EFFECTS]
    if bad:
        ap.error(f"--effects: expected names among {', '.join(ALL_EFFECTS[1:])}, got {', '.join(bad)}")
    if args.only != "all" or args.skip_none:
        cases = {s: draw_case(s, effects) for s in seeds}
        keep = {
            "all": lambda c: True,
            "forces": lambda c: not c["shapes"],
            "one-height-forces": lambda c: not c["shapes"] and len(c["heights_m"]) == 1,
        }[args.only]
        seeds = [s for s, c in cases.items() if keep(c) and not (args.skip_none and c["effect"] is None)]
    from bayesrod.dataset.io import read_rows

    fn = partial(replicate, cap_l=args.cap_l, slip=args.slip, step_l=args.step_l or None, effects=effects)
    for row in run_pending(csv, FIELDS, list(seeds), fn, done_key=lambda r: int(r["seed"]), workers=args.jobs):
        cov = " ".join(f"{k}:{row.get(f'{k}_covered', '-')}" for k in PARAMS)
        print(f"seed {row['seed']} ({row['effect']}, {row['n_heights']} h, shapes {row['shapes']}): {cov}", flush=True)
    print(summarise(read_rows(csv), args.out))


if __name__ == "__main__":
    main()

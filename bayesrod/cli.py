"""Command line: ``bayesrod <command> ...`` (CONTRACT.md section 2).

I/O lives here and in the readers; the physics never sees a file. Bad input
ends with one line ``bayesrod <command>: error: <message>`` on stderr and a
non-zero exit, never a traceback (set BAYESROD_DEBUG=1 to see one).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from . import __version__  # noqa: F401  (re-exported for --version)
from ._parse import parse_values
from .physics import Effects, force_from_displacement, k_theta, k_x
from .physics.effects import parse_effect_assignments
from .presets import PRESETS, get_preset

EXIT_BAD_INPUT = 2

_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {}


def _command(name: str):
    def deco(fn):
        _COMMANDS[name] = fn
        return fn

    return deco


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors in the same one-line form."""

    def error(self, message: str) -> None:  # noqa: D401
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bayesrod", description="Bayesian stiffness of plant stems (tapered Kirchhoff rod).")
    parser.add_argument("--version", action="version", version=f"bayesrod {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("predict", help="forward elastica: force at given contact displacements")
    p.add_argument("--preset", choices=sorted(PRESETS), help="take EI0, p and length from a published specimen")
    p.add_argument("--EI0", type=float, help="base flexural rigidity [N m^2]")
    p.add_argument("--p", type=float, help="taper exponent of EI(s) = EI0 (1 - s/L)^(4p)")
    p.add_argument("--length", type=float, help="stem length L [m]")
    p.add_argument("--posterior", metavar="RUN", help="a fit's run directory (credible bands instead of values)")
    p.add_argument("--height", type=float, required=True, help="sensor height h [m], 0 < h < L")
    p.add_argument(
        "--displacement",
        required=True,
        help="contact displacement(s) since first contact [m]: X, X,Y,Z or start:stop:num",
    )
    p.add_argument("--effect", action="append", metavar="NAME=VALUE", help="add a model effect (repeatable)")
    p.add_argument("--json", action="store_true", help="print JSON (CONTRACT.md section 3) instead of a table")
    v = sub.add_parser("validate", help="check a dataset and list every problem found")
    v.add_argument("dataset", help="dataset directory (holding specimen.json)")
    v.add_argument("--json", action="store_true", help="print the problems as JSON")

    sm = sub.add_parser("simulate", help="write a synthetic dataset from the forward model")
    sm.add_argument("--preset", required=True, choices=sorted(PRESETS), help="published specimen to simulate")
    sm.add_argument("--out", required=True, help="output dataset directory")
    sm.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sm.add_argument("--noise", default="default", choices=["default", "none"], help="measurement noise")
    sm.add_argument("--frames", action="store_true", help="also render RGB-D video frames")
    sm.add_argument(
        "--arm",
        default="leading",
        choices=["trailing", "leading"],
        help="with --frames: the bar holding the probe leads the push, hiding the stem the push bends "
        "forward (default), or trails it",
    )
    sm.add_argument("--effect", action="append", metavar="NAME=VALUE", help="add a model effect (repeatable)")
    sm.add_argument("--heights", help="override the preset's heights [m]: X,Y,Z or start:stop:num")
    sm.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ex = sub.add_parser("extract", help="vision pipeline: RGB-D frames to centerlines (shapes with sd_m)")
    ex.add_argument("dataset", help="dataset directory whose pushes have frames")
    ex.add_argument("--out", required=True, help="directory for the copy of the dataset with extracted shapes")
    ex.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ex.add_argument("--quiet", action="store_true", help="no progress bar")
    fm = sub.add_parser("fit-many", help="fit every dataset of a folder on a Dask cluster; survey table")
    fm.add_argument("root", metavar="DIR_OF_DATASETS", help="folder whose sub-directories are datasets")
    fm.add_argument("--out", required=True, help="output folder (runs/, survey.csv, survey.parquet)")
    fm.add_argument("--scheduler", metavar="ADDRESS", help="existing Dask scheduler (default: a local cluster)")
    fm.add_argument("--workers", type=int, default=2, help="local cluster workers (default 2)")
    fm.add_argument("--prior", default="default", help="prior name or JSON file")
    fm.add_argument("--seed", type=int, default=0, help="random seed of every fit (default 0)")
    fm.add_argument("--forces-only", action="store_true", help="ignore centerlines")
    fm.add_argument("--quiet", action="store_true", help="no progress bar")
    cp = sub.add_parser("compare", help="compare species: hierarchical model over fitted specimens")
    cp.add_argument("inputs", nargs="+", metavar="RUN_OR_DATASET", help="fit run directories or datasets")
    cp.add_argument("--out", required=True, help="output directory (compare.json, figures/)")
    cp.add_argument("--height", type=float, help="also contrast k_theta at this contact height [m]")
    cp.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    cp.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    im = sub.add_parser("import", help="turn raw force-displacement tables into datasets")
    im.add_argument("kind", choices=["blueberry"], help="table layout (see docs/data.md)")
    im.add_argument("src", help="folder of raw tables")
    im.add_argument("--out", required=True, help="output folder (one dataset per specimen)")
    im.add_argument(
        "--length-m",
        type=float,
        required=True,
        help="assumed stem length [m]: the blueberry tables hold none (an explicit assumption)",
    )
    im.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ft = sub.add_parser("fit", help="posterior of EI0, p and noise for a dataset (emcee)")
    ft.add_argument("dataset", help="dataset directory")
    ft.add_argument("--out", required=True, help="run directory to write")
    ft.add_argument("--prior", default="default", help="prior name (default, grass, woody) or JSON file")
    ft.add_argument(
        "--effects",
        default="",
        help="comma list of effects to fit: force_offset and at most one of base_compliance, rest_curvature, "
        "base_tilt, contact_friction; yield (with --forces-only)",
    )
    ft.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    ft.add_argument("--forces-only", action="store_true", help="ignore centerlines")
    ft.add_argument("--shapes-only", action="store_true", help="ignore forces")
    ft.add_argument(
        "--shape-weight",
        default="auto",
        metavar="auto|W",
        help="power on the centerline likelihood: auto (default) = n_eff/n measured from the residuals' "
        "correlation along the stem and between frames; 1 treats every point as independent",
    )
    ft.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    ft.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ft.add_argument("--quiet", action="store_true", help="no progress bars")

    de = sub.add_parser("design", help="rank contact heights for the next push by expected information gain")
    de.add_argument("source", metavar="DATASET_OR_RUN", help="fit run directory, or a dataset (fitted first)")
    de.add_argument("--out", required=True, help="output directory (design.json, figures/design.png)")
    de.add_argument("--candidates", metavar="START:STOP:NUM", help="heights to rank [m] (default 0.05L:0.95L:19)")
    de.add_argument("--displacement", type=float, help="planned contact displacement [m] (default: the data's)")
    de.add_argument("--samples", type=int, help="planned force samples (default: the data's median per push)")
    de.add_argument(
        "--force-range", metavar="LOW,HIGH", help="sensor range [N] (default: the dataset's sensor.force_range_N)"
    )
    de.add_argument("--confidence", type=float, default=0.9, help="P(peak force in range) required (default 0.9)")
    de.add_argument(
        "--target",
        default="params",
        choices=["params", "ei", "k_theta"],
        help="information about (log EI0, p) (default), the EI(s) band, or k_theta at --target-height",
    )
    de.add_argument("--target-height", type=float, help="height [m] for --target k_theta")
    de.add_argument(
        "--method",
        choices=["nmc", "gaussian"],
        help="nested Monte Carlo (default for params) or linearised (default and only choice for ei, k_theta)",
    )
    de.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    de.add_argument("--forces-only", action="store_true", help="when fitting a dataset first: ignore centerlines")
    de.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    de.add_argument("--quiet", action="store_true", help="no progress bar")

    dg = sub.add_parser("diagnose", help="residual analysis: which missing effect explains the misfit; refit")
    dg.add_argument("dataset", help="dataset directory")
    dg.add_argument("--out", required=True, help="output directory (diagnose.json, figures/, report.html)")
    dg.add_argument("--candidates", help="comma list of effects to test (default: the whole catalog)")
    dg.add_argument("--forces-only", action="store_true", help="ignore centerlines")
    dg.add_argument("--alpha", type=float, default=0.01, help="family-wise test level per round (default 0.01)")
    dg.add_argument(
        "--min-heldout-gain",
        type=float,
        default=0.10,
        help="relative drop of the leave-one-height-out force error an effect must bring (default 0.10)",
    )
    dg.add_argument("--force", action="store_true", help="replace a non-empty --out directory")

    dm = sub.add_parser("demo", help="the whole story on the bundled dataset: fit, bands, report")
    dm.add_argument("--out", default="bayesrod-demo", help="output directory (default ./bayesrod-demo)")
    dm.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    dm.add_argument(
        "--dataset",
        help="run the story on this dataset instead of the bundled one (frames are extracted first)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return _COMMANDS[args.command](args)
    except (ValueError, TypeError, OSError, KeyError) as exc:
        if os.environ.get("BAYESROD_DEBUG"):
            raise
        message = str(exc) if not isinstance(exc, KeyError) else f"missing key {exc}"
        print(f"bayesrod {args.command}: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"bayesrod {args.command}: interrupted", file=sys.stderr)
        return 130


# --------------------------------------------------------------------------- #
# predict
# --------------------------------------------------------------------------- #
def _rod_from_args(args: argparse.Namespace) -> tuple[float, float, float]:
    values = {"EI0": args.EI0, "p": args.p, "length": args.length}
    if args.preset:
        preset = get_preset(args.preset)
        defaults = {"EI0": preset["EI0"], "p": preset["p"], "length": preset["length_m"]}
        values = {k: (v if v is not None else defaults[k]) for k, v in values.items()}
    missing = [f"--{k}" for k, v in values.items() if v is None]
    if missing:
        raise ValueError(f"{', '.join(missing)}: expected a value (or --preset, or --posterior RUN), got none")
    for key, val in values.items():
        if not math.isfinite(val):
            raise ValueError(f"--{key}: expected a finite number, got {val}")
    if values["EI0"] <= 0:
        raise ValueError(f"--EI0: expected a flexural rigidity > 0 N m^2, got {values['EI0']}")
    if values["p"] < 0:
        raise ValueError(f"--p: expected a taper exponent >= 0, got {values['p']}")
    if values["length"] <= 0:
        raise ValueError(f"--length: expected a stem length > 0 m, got {values['length']}")
    return values["EI0"], values["p"], values["length"]


def _check_height(h: float, length: float) -> None:
    if not (math.isfinite(h) and 0 < h < length):
        raise ValueError(f"--height: expected 0 < height < length ({length:g} m), got {h:g}")


def _check_displacements(D: np.ndarray) -> None:
    if np.any(D < 0):
        raise ValueError(f"--displacement: expected values >= 0 m, got {D[D < 0][0]:g}")


@_command("predict")
def cmd_predict(args: argparse.Namespace) -> int:
    effects = parse_effect_assignments(args.effect)
    D = parse_values(args.displacement, "--displacement")
    _check_displacements(D)
    if args.posterior:
        result = predict_posterior(args.posterior, args.height, D, effects)
        if args.json:
            print(json.dumps(result, indent=2))
        else:
            _print_posterior_prediction(result)
        return 0
    EI0, p, L = _rod_from_args(args)
    _check_height(args.height, L)
    result = predict_point(EI0, p, L, args.height, D, effects)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        _print_prediction(result, EI0, p, L, effects)
    return 0


def predict_point(EI0: float, p: float, L: float, h: float, D: np.ndarray, effects: Effects) -> dict:
    """The ``predict --json`` document for one parameter set (CONTRACT.md section 3)."""
    sol = force_from_displacement(D, h, EI0, p, L, effects)
    points = []
    for i, d in enumerate(D):
        slipped = bool(sol.slipped[i])
        points.append(
            {
                "displacement_m": float(d),
                "force_N": None if slipped else float(sol.force_N[i]),
                "contact_s_m": None if slipped else float(sol.contact_s_m[i]),
                "slipped": slipped,
                "yielded": bool(sol.yielded[i]),
            }
        )
    return {
        "height_m": float(h),
        "k_theta_Nm_per_rad": float(k_theta(h, EI0, p, L, effects.base_compliance)),
        "k_x_N_per_m": float(k_x(h, EI0, p, L, effects.base_compliance)),
        "model": {"EI0": EI0, "p": p, "length_m": L, "effects": effects.to_mapping()},
        "points": points,
    }


def _load_run_samples(run: str) -> dict:
    path = Path(run) / "samples.npz"
    if not path.is_file():
        raise ValueError(f"--posterior: expected a fit run directory holding samples.npz, got {run}")
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def predict_posterior(run: str, h: float, D: np.ndarray, effects: Effects, n_draws: int = 400) -> dict:
    """``predict --posterior``: force and stiffness bands from a fit's posterior draws."""
    from .inference.summary import predictive_forces, quantiles

    samples = _load_run_samples(run)
    L = float(samples.pop("length_m"))
    _check_height(h, L)
    rng = np.random.default_rng(0)
    n = samples["EI0"].size
    idx = rng.choice(n, size=min(n_draws, n), replace=False)
    EI0, p = samples["EI0"][idx], samples["p"][idx]
    pred = predictive_forces(samples, idx, D, h, L, effects)
    F = pred["force_N"]
    slip_prob = pred["slipped"].mean(axis=0)
    kb = samples["base_compliance"][idx] if "base_compliance" in samples else effects.base_compliance
    kt = k_theta(h, EI0, p, L, kb)
    kx = k_x(h, EI0, p, L, kb)

    def q(x):
        qq = quantiles(x)
        return {k: (None if not np.isfinite(v) else float(v)) for k, v in qq.items()}

    points = []
    for i, d in enumerate(D):
        col = F[:, i]
        ok = np.isfinite(col)
        points.append(
            {
                "displacement_m": float(d),
                "force_N": q(col[ok]) if ok.sum() >= 2 else None,
                "contact_s_m": q(pred["contact_s_m"][ok, i]) if ok.sum() >= 2 else None,
                "slipped": bool(slip_prob[i] > 0.5),
                "slip_probability": float(slip_prob[i]),
            }
        )
    return {
        "height_m": float(h),
        "k_theta_Nm_per_rad": q(kt),
        "k_x_N_per_m": q(kx),
        "posterior": {"run": str(run), "draws": int(idx.size), "length_m": L},
        "points": points,
    }


def _print_posterior_prediction(result: dict) -> None:
    kt, kx = result["k_theta_Nm_per_rad"], result["k_x_N_per_m"]
    print(
        f"Posterior prediction from {result['posterior']['run']} ({result['posterior']['draws']} draws), "
        f"L = {result['posterior']['length_m']:g} m, h = {result['height_m']:g} m"
    )
    print(
        f"k_theta = {kt['median']:.4g} [{kt['q05']:.4g}, {kt['q95']:.4g}] N m/rad,  "
        f"k_x = {kx['median']:.4g} [{kx['q05']:.4g}, {kx['q95']:.4g}] N/m  (median [90% interval])"
    )
    print(f"{'displacement [m]':>17} {'force median [N]':>17} {'90% interval [N]':>22}  P(slipped)")
    for pt in result["points"]:
        f = pt["force_N"]
        band = f"[{f['q05']:.4f}, {f['q95']:.4f}]" if f else "-"
        med = f"{f['median']:.4f}" if f else "-"
        print(f"{pt['displacement_m']:17.4f} {med:>17} {band:>22}  {pt['slip_probability']:.2f}")


def _print_prediction(result: dict, EI0: float, p: float, L: float, effects: Effects) -> None:
    eff = ", ".join(f"{k}={v:g}" for k, v in effects.to_mapping().items()) or "none"
    print(f"Tapered rod: EI0 = {EI0:g} N m^2, p = {p:g}, L = {L:g} m, effects: {eff}")
    print(
        f"Contact height h = {result['height_m']:g} m:  k_theta = {result['k_theta_Nm_per_rad']:.4g} N m/rad,  "
        f"k_x = {result['k_x_N_per_m']:.4g} N/m  (small-deflection, eqs. kdist/kx)"
    )
    print(f"{'displacement [m]':>17} {'force [N]':>11} {'contact s [m]':>14}  note")
    for pt in result["points"]:
        if pt["slipped"]:
            print(f"{pt['displacement_m']:17.4f} {'-':>11} {'-':>14}  slipped past the sensor")
        else:
            note = "base yielded" if pt["yielded"] else ""
            print(f"{pt['displacement_m']:17.4f} {pt['force_N']:11.4f} {pt['contact_s_m']:14.4f}  {note}")


# --------------------------------------------------------------------------- #
# validate, simulate
# --------------------------------------------------------------------------- #
@_command("validate")
def cmd_validate(args: argparse.Namespace) -> int:
    from .dataset import validate_dataset

    problems = validate_dataset(args.dataset)
    errors = [p for p in problems if p.severity == "error"]
    if args.json:
        print(
            json.dumps(
                {"dataset": args.dataset, "valid": not errors, "problems": [dict(vars(p)) for p in problems]}, indent=2
            )
        )
    else:
        for prob in problems:
            print(prob, file=sys.stderr if prob.severity == "error" else sys.stdout)
        if errors:
            print(f"{args.dataset}: {len(errors)} problem{'s' * (len(errors) > 1)} found", file=sys.stderr)
        else:
            print(f"{args.dataset}: valid bayesrod.dataset/1" + (f" ({len(problems)} warnings)" if problems else ""))
    return 1 if errors else 0


@_command("simulate")
def cmd_simulate(args: argparse.Namespace) -> int:
    from .io import atomic_dir, check_out_dir
    from .simulate import SimConfig, simulate, write_simulated
    from .vision.render import default_camera

    effects = parse_effect_assignments(args.effect)
    check_out_dir(args.out, args.force)
    overrides = {}
    if args.heights:
        overrides["heights_m"] = tuple(parse_values(args.heights, "--heights"))
    cfg = SimConfig.from_preset(args.preset, seed=args.seed, noise=args.noise, effects=effects, **overrides)
    for h in cfg.heights_m:
        _check_height(h, cfg.length_m)
    pushes = simulate(cfg, progress=sys.stderr.isatty())
    with atomic_dir(args.out, args.force) as tmp:
        write_simulated(
            cfg,
            pushes,
            tmp,
            frames=args.frames,
            camera=default_camera(cfg.length_m) if args.frames else None,
            arm=args.arm,
        )
    eff = ", ".join(f"{k}={v:g}" for k, v in effects.to_mapping().items()) or "none"
    print(
        f"wrote {args.out}: {cfg.specimen}, {len(pushes)} pushes at "
        f"{', '.join(f'{h:g}' for h in cfg.heights_m)} m, noise {args.noise}, effects {eff}"
        + (", with RGB-D frames" if args.frames else "")
    )
    return 0


@_command("extract")
def cmd_extract(args: argparse.Namespace) -> int:
    from .extraction import extract_dataset
    from .io import check_out_dir

    check_out_dir(args.out, args.force)
    extract_dataset(args.dataset, args.out, force=args.force, progress=not args.quiet and sys.stderr.isatty())
    print(f"wrote {args.out}: shapes_extracted.csv per push, extract_report.json, figures/extract_*.png")
    return 0


@_command("fit-many")
def cmd_fit_many(args: argparse.Namespace) -> int:
    from .survey import fit_many

    if args.workers < 1:
        raise ValueError(f"--workers: expected at least 1, got {args.workers}")
    res = fit_many(
        args.root,
        args.out,
        scheduler=args.scheduler,
        n_workers=args.workers,
        options={"prior": args.prior, "seed": args.seed, "use_shapes": not args.forces_only},
        progress=not args.quiet and sys.stderr.isatty(),
    )
    print(
        f"wrote {args.out}: {res['fitted']} of {res['datasets']} specimens in survey.csv / survey.parquet"
        + (f"; {len(res['failed'])} failed (failures.json)" if res["failed"] else "")
    )
    return 1 if res["failed"] else 0


@_command("compare")
def cmd_compare(args: argparse.Namespace) -> int:
    from .compare import compare
    from .io import check_out_dir

    check_out_dir(args.out, args.force)
    res = compare(args.inputs, args.out, height_m=args.height, seed=args.seed, force=args.force)
    for c in res["contrasts"]:
        if c["parameter"] == "EI0":
            print(
                f"EI0 {c['a']} / {c['b']}: {c['ratio_median']:.3g} [{c['ratio_q05']:.3g}, {c['ratio_q95']:.3g}] "
                f"(90%), P({c['a']} stiffer) = {c['prob_a_greater']:.3f}"
            )
    print(f"wrote {args.out}/compare.json and figures/forest.png")
    return 0


@_command("import")
def cmd_import(args: argparse.Namespace) -> int:
    from .dataset import validate_dataset
    from .importers import import_blueberry
    from .io import atomic_dir, check_out_dir

    check_out_dir(args.out, args.force)
    with atomic_dir(args.out, args.force) as tmp:
        report = import_blueberry(args.src, tmp, args.length_m)
        for cane in report["canes"]:
            if cane["status"] == "imported":
                errors = [p for p in validate_dataset(tmp / cane["dataset"]) if p.severity == "error"]
                if errors:
                    raise ValueError(f"imported dataset {cane['dataset']} does not validate: {errors[0]}")
    n_ok = sum(c["status"] == "imported" for c in report["canes"])
    n_tr = sum(t["status"] == "imported" for c in report["canes"] for t in c["trials"])
    n_all = sum(len(c["trials"]) for c in report["canes"])
    print(
        f"imported {n_ok} of {len(report['canes'])} canes ({n_tr} of {n_all} trials) into {args.out}, "
        f"assumed cane length {args.length_m:g} m"
    )
    for cane in report["canes"]:
        for t in cane["trials"]:
            if t["status"] != "imported":
                print(f"  {cane['cane']}: {t['file']} rejected: {t['reason']}")
        if cane["status"] != "imported":
            print(f"  {cane['cane']} rejected: {cane['reason']}")
    print(f"details: {Path(args.out) / 'import_report.json'}")
    return 0


@_command("fit")
def cmd_fit(args: argparse.Namespace) -> int:
    from .fit import fit_dataset
    from .io import check_out_dir

    if args.forces_only and args.shapes_only:
        raise ValueError("--forces-only, --shapes-only: expected at most one, got both")
    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    if not args.resume:
        check_out_dir(args.out, args.force)
        if args.force and Path(args.out).is_dir():
            import shutil

            shutil.rmtree(args.out)
    summary = fit_dataset(
        args.dataset,
        args.out,
        prior=args.prior,
        effects=effects,
        seed=args.seed,
        use_forces=not args.shapes_only,
        use_shapes=not args.forces_only,
        resume=args.resume,
        progress=not args.quiet,
        shape_weight=_shape_weight(args.shape_weight),
    )
    _print_fit(summary, args.out)
    return 0


def _shape_weight(text: str) -> str | float:
    if text == "auto":
        return "auto"
    try:
        w = float(text)
    except ValueError:
        w = float("nan")
    if not 0 < w <= 1:
        raise ValueError(f"--shape-weight: expected auto or a number in (0, 1], got {text!r}")
    return w


def _print_fit(summary: dict, out) -> None:
    for name, q in summary["parameters"].items():
        print(f"  {name:>15} = {q['median']:.4g}  [{q['q05']:.4g}, {q['q95']:.4g}]  (median [90% interval])")
    for row in summary["k_theta"]:
        print(f"  k_theta({row['height_m']:g} m) = {row['median']:.4g}  [{row['q05']:.4g}, {row['q95']:.4g}] N m/rad")
    c = summary["convergence"]
    print(f"  R-hat max {c['rhat_max']:.4f}, bulk ESS min {c['ess_bulk_min']:.0f}, {summary['sampler']['seconds']:g} s")
    print(f"wrote {out}/summary.json, posterior.nc, report.html")


@_command("design")
def cmd_design(args: argparse.Namespace) -> int:
    from .design import run_design
    from .io import check_out_dir

    check_out_dir(args.out, args.force)
    rng = None
    if args.force_range:
        try:
            rng = [float(v) for v in args.force_range.split(",")]
        except ValueError:
            rng = None
        if rng is None or len(rng) != 2:
            raise ValueError(f"--force-range: expected LOW,HIGH in N, got {args.force_range!r}")
    method = args.method or ("nmc" if args.target == "params" else "gaussian")
    res = run_design(
        args.source,
        args.out,
        candidates=args.candidates,
        displacement_m=args.displacement,
        n_samples=args.samples,
        force_range_N=rng,
        confidence=args.confidence,
        target=args.target,
        target_height_m=args.target_height,
        method=method,
        seed=args.seed,
        forces_only=args.forces_only,
        progress=not args.quiet,
    )
    for r in res["candidates"]:
        g = r["expected_information_gain_nats"]
        mark = "*" if r["height_m"] == res["recommended_height_m"] else " "
        why = "" if r["feasible"] else f"  infeasible: {r['reason']}"
        print(f" {mark} h = {r['height_m']:.3f} m  EIG {'-' if g is None else f'{g:.3f}'} nats{why}")
    if res["recommended_height_m"] is None:
        print(f"no feasible height among the candidates; wrote {args.out}/design.json", file=sys.stderr)
        return 1
    print(f"recommended next height: {res['recommended_height_m']:.3f} m; wrote {args.out}/design.json")
    return 0


@_command("diagnose")
def cmd_diagnose(args: argparse.Namespace) -> int:
    from .diagnosis import run_diagnose
    from .inference.diagnose import CATALOG
    from .io import check_out_dir

    check_out_dir(args.out, args.force)
    cands = CATALOG
    if args.candidates:
        cands = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
        bad = [c for c in cands if c not in CATALOG]
        if bad or not cands:
            raise ValueError(f"--candidates: expected effects from {', '.join(CATALOG)}, got {args.candidates!r}")
    if not (0 < args.alpha < 1):
        raise ValueError(f"--alpha: expected a level in (0, 1), got {args.alpha}")
    doc = run_diagnose(
        args.dataset,
        args.out,
        candidates=cands,
        use_shapes=not args.forces_only,
        alpha=args.alpha,
        min_heldout_gain=args.min_heldout_gain,
        force=args.force,
        log=lambda msg: print(f"  {msg}", flush=True),
    )
    b, a = doc["before"], doc["after"]
    print(f"added effects: {', '.join(doc['added_effects']) or 'none'}")
    for k in ("force_rmse_N", "shape_rmse_mm", "heldout_force_rmse_N"):
        if b[k] is not None:
            print(f"  {k:>22}: {b[k]:.4g} -> {a[k]:.4g}")
    if doc["unexplained_structure"]:
        print("  unexplained structure remains in the residuals (see report.html)")
    print(f"wrote {args.out}/diagnose.json and report.html")
    return 0


@_command("demo")
def cmd_demo(args: argparse.Namespace) -> int:
    from importlib import resources

    from .fit import fit_dataset
    from .io import check_out_dir

    check_out_dir(args.out, args.force)
    if args.force and Path(args.out).is_dir():
        import shutil

        shutil.rmtree(args.out)
    dataset = Path(args.dataset) if args.dataset else resources.files("bayesrod") / "data" / "default"
    from .dataset import read_dataset

    spec = read_dataset(dataset)
    if any(p.frames for p in spec.pushes):
        from .extraction import extract_dataset

        print(f"bayesrod demo: extracting centerlines from the frames of {dataset} ...")
        rep = extract_dataset(dataset, Path(args.out) / "extracted", log=lambda *a: None)
        n = sum(len(p["frames"]) for p in rep["pushes"].values())
        print(f"  {n} frames extracted into {Path(args.out) / 'extracted'}")
        dataset = Path(args.out) / "extracted"
    else:
        print(f"bayesrod demo: {dataset} has no RGB-D frames (centerlines are given); no extraction needed")
    print(f"bayesrod demo: fitting {dataset} ...")
    summary = fit_dataset(str(dataset), Path(args.out) / "fit", seed=0)
    _print_fit(summary, Path(args.out) / "fit")
    truth = summary.get("truth")
    if truth:
        print(f"  (simulated truth: EI0 = {truth['EI0']:g} N m^2, p = {truth['p']:g})")
    print(f"report: {(Path(args.out) / 'fit' / 'report.html').resolve()}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

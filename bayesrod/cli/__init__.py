"""Command line: ``bayesrod <command> ...`` (docs/cli.md, docs/format.md).

Each command is parse -> call the public API (:mod:`bayesrod.api`) -> save/print.
Only this module knows flag names: errors from the library name the parameter
(``prior: expected ...``) and :func:`main` shows it as the flag (``--prior``).
Bad input ends with one line ``bayesrod <command>: error: <message>`` on stderr
and a non-zero exit, never a traceback (set BAYESROD_DEBUG=1 to see one).
Progress and log lines go to stderr (``--quiet`` silences them); results to
stdout, as JSON with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from .._version import __version__
from ..dataset.importers import ANGLE_UNITS, DISPLACEMENT_UNITS, FORCE_UNITS, TIME_UNITS
from ..physics.effects import parse_effect_assignments
from ..physics.presets import PRESETS
from ..vision.width import COLOUR_CHOICES
from .parse import parse_values

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
    v = sub.add_parser("validate", help="check a dataset and list every problem found")
    v.add_argument("dataset", help="dataset directory (holding specimen.json)")

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
    sm.add_argument(
        "--noise-rho", type=float, default=0.0, help="lag-1 correlation of AR(1) force noise (default 0: independent)"
    )
    sm.add_argument("--effect", action="append", metavar="NAME=VALUE", help="add a model effect (repeatable)")
    sm.add_argument("--heights", help="override the preset's heights [m]: X,Y,Z or start:stop:num")
    sm.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ex = sub.add_parser("extract", help="vision pipeline: RGB-D frames to centerlines (shapes with sd_m)")
    ex.add_argument("dataset", help="dataset directory whose pushes have frames")
    ex.add_argument("--out", required=True, help="directory for the copy of the dataset with extracted shapes")
    ex.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    ex.add_argument(
        "--width-colour-model",
        choices=COLOUR_CHOICES,
        default="auto",
        help="how the diameter profile reads coverage from colour: unmixing for round stems with strong shading; "
        "auto (default) chooses from the stem's wide stations on the first frame (extract_report.json says which)",
    )
    fm = sub.add_parser("fit-many", help="fit every dataset of a folder on a Dask cluster; survey table")
    fm.add_argument("root", metavar="DIR_OF_DATASETS", help="folder whose sub-directories are datasets")
    fm.add_argument("--out", required=True, help="output folder (runs/, survey.csv, survey.parquet)")
    fm.add_argument("--scheduler", metavar="ADDRESS", help="existing Dask scheduler (default: a local cluster)")
    fm.add_argument("--workers", type=int, default=2, help="local cluster workers (default 2)")
    fm.add_argument("--prior", default="default", help="prior name or JSON file")
    fm.add_argument("--seed", type=int, default=0, help="random seed of every fit (default 0)")
    fm.add_argument("--forces-only", action="store_true", help="ignore centerlines")
    fm.add_argument(
        "--grouped",
        action="store_true",
        help="datasets sharing a stem_id: one joint fit per stem (as fit-group) in OUT/groups, tabled in groups.csv",
    )
    fg = sub.add_parser(
        "fit-group", help="one stem under several conditions: a joint posterior separating stem and anchorage"
    )
    fg.add_argument("root", metavar="DIR", help="folder of datasets whose specimen.json name a stem_id and condition")
    fg.add_argument("--out", required=True, help="output folder (<stem_id>/summary.json, groups.json)")
    fg.add_argument("--prior", default="default", help="prior name or JSON file of EI0, p and the noise")
    fg.add_argument(
        "--shared",
        default="EI0,p",
        help="parameters shared by the conditions: of EI0, p (the stem) and sigma_force_N, rho_force (the force "
        "noise, where one rig recorded them all); default EI0,p; '' for none",
    )
    fg.add_argument(
        "--pooled",
        default="auto",
        help="noise parameters the conditions pool (each keeps its own; their Fisher z a normal population of sd "
        "--pool-spread about an unknown centre): rho_force, '' for none, or auto (default: rho_force with AR(1) "
        "noise unless --shared names it)",
    )
    fg.add_argument(
        "--pool-spread",
        type=float,
        default=0.25,
        help="sd of the pooled correlations' Fisher z about their centre (default 0.25)",
    )
    fg.add_argument("--force-noise", default="ar1", choices=["iid", "ar1"], help="force noise per condition")
    fg.add_argument(
        "--force-offsets",
        action="store_true",
        help="a load-cell offset per condition, integrated out (prior sd 5%% of its peak force)",
    )
    fg.add_argument("--no-sharing-check", action="store_true", help="skip the held-out check of the sharing")
    fg.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    fg.add_argument("--max-steps", type=int, default=6000, help="sampling budget per ensemble (default 6000)")
    fg.add_argument("--target-ess", type=float, default=400.0, help="bulk ESS target of EI0 and p (default 400)")
    fg.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    cp = sub.add_parser("compare", help="compare species: hierarchical model over fitted specimens")
    cp.add_argument("inputs", nargs="+", metavar="RUN_OR_DATASET", help="fit run directories or datasets")
    cp.add_argument("--out", required=True, help="output directory (compare.json, figures/)")
    cp.add_argument("--height", type=float, help="also contrast k_theta at this contact height [m]")
    cp.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    cp.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    im = sub.add_parser("import", help="turn raw force-displacement tables into datasets")
    im.add_argument(
        "kind",
        choices=["blueberry", "table"],
        help="blueberry: the blueberry-cane tables; "
        "table: any delimited rig table with the columns named by flags (docs/data.md)",
    )
    im.add_argument(
        "src",
        nargs="+",
        metavar="SRC",
        help="folder of raw tables (blueberry), or table files and folders of them (table)",
    )
    im.add_argument("--out", required=True, help="output folder (one dataset per specimen)")
    im.add_argument("--length-m", type=float, help="stem length [m] (blueberry: required, an explicit assumption)")
    im.add_argument(
        "--length-unknown",
        action="store_true",
        help="table: the length is a rough guess (marked length_m_approximate in specimen.json)",
    )
    im.add_argument(
        "--time",
        metavar="COL",
        help="table: the time column's header name (without it, the sample index is the time: forces only)",
    )
    im.add_argument(
        "--force",
        nargs="?",
        const=True,
        default=False,
        metavar="COL",
        help="table: the force column's header name (--force COL); alone, as for every command: replace a "
        "non-empty --out directory",
    )
    im.add_argument("--force-column", metavar="COL", help="table: the force column (same as --force COL)")
    im.add_argument(
        "--replace", action="store_true", help="replace a non-empty --out directory (same as a bare --force)"
    )
    im.add_argument("--displacement", metavar="COL", help="table: the sensor's displacement column")
    im.add_argument("--angle", metavar="COL", help="table: a rotating arm's angle column (with --arm-height)")
    im.add_argument(
        "--arm-height",
        type=float,
        metavar="H",
        help="table: the rotating arm's length from its pivot "
        "to the probe [m]: the contact advances by H sin(angle - angle at the start)",
    )
    im.add_argument("--time-unit", default="s", choices=list(TIME_UNITS), help="table: time unit (default s)")
    im.add_argument("--force-unit", default="N", choices=list(FORCE_UNITS), help="table: force unit (default N)")
    im.add_argument(
        "--displacement-unit", default="m", choices=list(DISPLACEMENT_UNITS), help="table: default m (um: micrometres)"
    )
    im.add_argument("--angle-unit", default="deg", choices=list(ANGLE_UNITS), help="table: default deg")
    im.add_argument("--height-m", type=float, help="table: contact height on the stem [m]")
    im.add_argument(
        "--specimen", help="table: specimen name (default: the file name); files sharing it form one dataset"
    )
    im.add_argument("--species", help="table: species")
    im.add_argument(
        "--stem-id", help="table: the stem's id: datasets sharing it are one stem under several conditions (fit-group)"
    )
    im.add_argument("--condition", help="table: the condition of this stem (e.g. intact, cut1); see fit-group")
    im.add_argument(
        "--metadata",
        metavar="CSV",
        help="table: a CSV with a column file (or stem_id, or specimen: per stem or specimen) and any of height_m, "
        "length_m, specimen, species, arm_height_m, force_sign, displacement_sign, stem_id, condition",
    )
    im.add_argument(
        "--stem-id-column",
        metavar="COL",
        help="table: a long table of many pushes: the column naming each row's stem (rows sharing the values of "
        "every --*-column are one recording; docs/data.md)",
    )
    im.add_argument("--condition-column", metavar="COL", help="table: a long table: the column naming the condition")
    im.add_argument("--specimen-column", metavar="COL", help="table: a long table: the column naming the specimen")
    im.add_argument(
        "--test-column", metavar="COL", help="table: a long table: the column naming each test (one push or cycle run)"
    )
    im.add_argument(
        "--height-column",
        metavar="COL",
        help="table: a long table: the column of the contact height (in place of --height-m)",
    )
    im.add_argument(
        "--height-unit", default="m", choices=list(DISPLACEMENT_UNITS), help="table: the height column's unit"
    )
    im.add_argument(
        "--header-row",
        type=int,
        metavar="N",
        help="table: 1-based line of the header (default: the first line naming the columns)",
    )
    im.add_argument(
        "--cycles",
        default="all",
        choices=["first", "all"],
        help="table: every loading ramp of a load/unload recording as a push (default), or the first only",
    )
    im.add_argument(
        "--force-sign",
        type=int,
        default=1,
        choices=[1, -1],
        help="table: -1 when the load cell reads the push as negative",
    )
    im.add_argument(
        "--displacement-sign",
        type=int,
        default=1,
        choices=[1, -1],
        help="table: -1 when the rig counts the push's displacement (or arm angle) as negative",
    )
    im.add_argument(
        "--tare",
        default="auto",
        choices=["auto", "none"],
        help="table: subtract the force baseline "
        "before contact when the recording shows it (auto, default) or keep the readings",
    )
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
    ft.add_argument(
        "--force-noise",
        default="iid",
        choices=["iid", "ar1"],
        help="force noise model: independent (iid, default) or AR(1) per push with its lag-1 correlation "
        "rho_force fitted (real pushes: drift, stick-slip, vibration)",
    )
    ft.add_argument(
        "--preload",
        action="store_true",
        help="fit each push's preload (the displacement already made when recording began; it moves the push's "
        "frames too)",
    )
    ft.add_argument(
        "--length",
        default="auto",
        choices=["auto", "known", "unknown"],
        help="stem length: sample it (unknown; prior uniform on [L/1.5, 1.5 L] or the prior file's length_m), "
        "fix it (known), or sample it when specimen.json marks it length_m_approximate (auto, default); forces only",
    )
    ft.add_argument(
        "--height-sd",
        type=float,
        default=0.0,
        metavar="M",
        help="sd of each push's contact-height error [m] (e.g. 0.003); each push's error is sampled; forces only",
    )
    ft.add_argument(
        "--force-offsets",
        action="store_true",
        help="fit a load-cell offset per push (prior N(0, 5%% of the push's peak force))",
    )
    ft.add_argument(
        "--diameter",
        choices=("auto", "shared", "free", "off"),
        default="auto",
        help="the measured diameters (specimen.json 'diameters', written by extract): shared = uniform modulus, "
        "geometry and bending share p; free = the diameter's own taper (tests uniform modulus); off = ignored; "
        "auto (default) = shared when the dataset has diameters. With diameters the summary reports Young's modulus",
    )
    ft.add_argument(
        "--slip",
        action="store_true",
        help="use where each push slipped off the probe: the model's slip must lie there (docs/inference.md)",
    )
    ft.add_argument("--max-steps", type=int, default=8000, help="sampling budget per ensemble (default 8000)")
    ft.add_argument(
        "--target-ess", type=float, default=1000.0, help="stop once EI0 and p have this bulk ESS (default 1000)"
    )
    ft.add_argument(
        "--workers",
        type=int,
        default=1,
        help="processes that build the likelihood's tables (default 1); worth it with contact_friction, whose "
        "tables take minutes per height; the draws are the same whatever the number",
    )
    ft.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    ft.add_argument("--force", action="store_true", help="replace a non-empty --out directory")

    de = sub.add_parser("design", help="rank contact heights for the next push by expected information gain")
    de.add_argument(
        "source",
        metavar="DATASET_OR_RUN",
        help="fit run directory, a fit-group stem directory (RUN/<stem_id>, with --condition), or a dataset "
        "(fitted first)",
    )
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
    de.add_argument("--condition", help="with a fit-group stem: the condition whose next push is planned (e.g. intact)")
    de.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    de.add_argument("--forces-only", action="store_true", help="when fitting a dataset first: ignore centerlines")
    de.add_argument("--force", action="store_true", help="replace a non-empty --out directory")

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
        help="relative drop of the held-out force error (true refits) an effect must bring (default 0.10)",
    )
    dg.add_argument(
        "--heldout-alpha",
        type=float,
        default=0.02,
        help="level of the bootstrap test (under the fitted AR noise) of the held-out gain (default %(default)s)",
    )
    dg.add_argument(
        "--force-noise",
        default="ar1",
        choices=["ar1", "iid"],
        help="force noise of every fit and test: AR(1) per push (default) or independent",
    )
    dg.add_argument(
        "--preload",
        choices=["auto", "yes", "no"],
        default="auto",
        help="fit each push's preload (auto: when a push starts loaded)",
    )
    dg.add_argument(
        "--length",
        default="known",
        choices=["known", "unknown", "auto"],
        help="stem length: hold it (known, default), fit it in every model within [L/1.5, 1.5 L] (unknown), or "
        "fit it when specimen.json marks it length_m_approximate (auto); fitting needs forces only",
    )
    dg.add_argument(
        "--height-sd",
        type=float,
        default=0.0,
        metavar="M",
        help="sd of each push's contact-height error [m] (e.g. 0.003): fitted in every model under its prior "
        "(default 0: heights exact)",
    )
    dg.add_argument(
        "--workers", type=int, default=2, help="processes for the candidate fits and held-out refits (default 2)"
    )
    dg.add_argument("--force", action="store_true", help="replace a non-empty --out directory")

    dm = sub.add_parser("demo", help="the whole story on the bundled dataset: fit, bands, report")
    dm.add_argument("--out", default="bayesrod-demo", help="output directory (default ./bayesrod-demo)")
    dm.add_argument("--force", action="store_true", help="replace a non-empty --out directory")
    dm.add_argument(
        "--dataset",
        help="run the story on this dataset instead of the bundled one (frames are extracted first)",
    )
    for cmd in sub.choices.values():  # every command: quiet, and its result as JSON on stdout
        cmd.add_argument("--quiet", action="store_true", help="no progress bars or log lines (errors still shown)")
        cmd.add_argument("--json", action="store_true", help="print the result as JSON on stdout (docs/format.md)")
    return parser


#: library parameter names -> the flags that set them, for error messages
FLAGS = {
    "effect": "--effect",
    "effects": "--effects",
    "preset": "--preset",
    "prior": "--prior",
    "noise": "--noise",
    "candidates": "--candidates",
    "target": "--target",
    "target_height_m": "--target-height",
    "method": "--method",
    "sensor": "--force-range",
    "displacement_m": "--displacement",
    "height_m": "--height",
    "heights_m": "--heights",
    "EI0": "--EI0",
    "p": "--p",
    "length_m": "--length-m",
    "shape_weight": "--shape-weight",
    "alpha": "--alpha",
    "heldout_alpha": "--heldout-alpha",
    "min_heldout_gain": "--min-heldout-gain",
    "n_workers": "--workers",
    "shared": "--shared",
    "pooled": "--pooled",
    "pool_spread": "--pool-spread",
    "stem_id": "--stem-id",
    "condition": "--condition",
    "checkpoint": "--resume",
    "arm": "--arm",
    "max_steps": "--max-steps",
    "force_noise": "--force-noise",
    "preload": "--preload",
    "length": "--length",
    "height_sd_m": "--height-sd",
    "force_offsets": "--force-offsets",
    "diameter": "--diameter",
    "slip": "--slip",
    "noise_rho": "--noise-rho",
    "target_ess": "--target-ess",
    "time_unit": "--time-unit",
    "force_unit": "--force-unit",
    "displacement_unit": "--displacement-unit",
    "angle_unit": "--angle-unit",
    "arm_height_m": "--arm-height",
    "header_row": "--header-row",
    "cycles": "--cycles",
    "force_sign": "--force-sign",
    "displacement_sign": "--displacement-sign",
    "tare": "--tare",
    "metadata": "--metadata",
    "specimen_column": "--specimen-column",
    "stem_id_column": "--stem-id-column",
    "condition_column": "--condition-column",
    "test_column": "--test-column",
    "height_column": "--height-column",
    "height_unit": "--height-unit",
}


#: where one command spells a parameter's flag differently
_COMMAND_FLAGS = {"predict": {"length_m": "--length"}, "import": {"height_m": "--height-m"}}


def _flag_message(message: str, command: str) -> str:
    """A library error ``name: ...`` shown with the flag that sets ``name``, and every ``option name`` it
    suggests shown as that flag."""
    flags = {**FLAGS, **_COMMAND_FLAGS.get(command, {})}
    message = re.sub(r"\boption (\w+)", lambda m: flags.get(m.group(1), m.group(0)), message)
    name, sep, rest = message.partition(":")
    if sep and name in flags:
        return f"{flags[name]}:{rest}"
    return message


def main(argv: Sequence[str] | None = None) -> int:
    from ..dataset.io import OutputExistsError

    parser = build_parser()
    args = parser.parse_args(argv)
    _setup_logging(args.quiet)
    try:
        return _COMMANDS[args.command](args)
    except OutputExistsError as exc:
        if os.environ.get("BAYESROD_DEBUG"):
            raise
        print(f"bayesrod {args.command}: error: --out: {exc} (add --force to replace it)", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (ValueError, TypeError, OSError, KeyError) as exc:
        if os.environ.get("BAYESROD_DEBUG"):
            raise
        message = str(exc) if not isinstance(exc, KeyError) else f"missing key {exc}"
        print(f"bayesrod {args.command}: error: {_flag_message(message, args.command)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"bayesrod {args.command}: interrupted", file=sys.stderr)
        return 130


class _StderrHandler(logging.Handler):
    """Log lines to the current sys.stderr (looked up at each line, so captured streams work)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            print(f"  {record.getMessage()}", file=sys.stderr, flush=True)
        except Exception:  # pragma: no cover - logging must never break a command
            self.handleError(record)


def _setup_logging(quiet: bool) -> None:
    logger = logging.getLogger("bayesrod")
    for h in list(logger.handlers):
        if isinstance(h, _StderrHandler):
            logger.removeHandler(h)
    logger.addHandler(_StderrHandler())
    logger.setLevel(logging.WARNING if quiet else logging.INFO)
    logger.propagate = False


def _progress(args) -> bool:
    return not args.quiet


def _emit_json(doc) -> None:
    from ..dataset.io import json_default

    print(json.dumps(doc, indent=2, default=json_default))


def _prepare_out(args) -> Path:
    """Refuse a non-empty --out unless --force (checked before any computing)."""
    from ..dataset.io import check_out_dir

    return check_out_dir(args.out, getattr(args, "force", False))


# --------------------------------------------------------------------------- #
# predict
# --------------------------------------------------------------------------- #
@_command("predict")
def cmd_predict(args: argparse.Namespace) -> int:
    from ..api import predict

    effects = parse_effect_assignments(args.effect)
    D = parse_values(args.displacement, "--displacement")
    if args.posterior:
        res = predict(args.height, D, posterior=args.posterior, effects=effects).to_dict()
        _emit_json(res) if args.json else _print_posterior_prediction(res)
        return 0
    if args.posterior is None and args.preset is None and None in (args.EI0, args.p, args.length):
        missing = [f for f, v in (("--EI0", args.EI0), ("--p", args.p), ("--length", args.length)) if v is None]
        raise ValueError(f"{', '.join(missing)}: expected a value (or --preset, or --posterior RUN), got none")
    res = predict(
        args.height, D, EI0=args.EI0, p=args.p, length_m=args.length, preset=args.preset, effects=effects
    ).to_dict()
    _emit_json(res) if args.json else _print_prediction(res)
    return 0


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


def _print_prediction(result: dict) -> None:
    m = result["model"]
    eff = ", ".join(f"{k}={v:g}" for k, v in m["effects"].items()) or "none"
    print(f"Tapered rod: EI0 = {m['EI0']:g} N m^2, p = {m['p']:g}, L = {m['length_m']:g} m, effects: {eff}")
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
# validate, simulate, extract, import
# --------------------------------------------------------------------------- #
@_command("validate")
def cmd_validate(args: argparse.Namespace) -> int:
    from ..dataset import validate_dataset

    problems = validate_dataset(args.dataset)
    errors = [p for p in problems if p.severity == "error"]
    if args.json:
        _emit_json({"dataset": args.dataset, "valid": not errors, "problems": [dict(vars(p)) for p in problems]})
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
    from ..api import simulate

    effects = parse_effect_assignments(args.effect)
    _prepare_out(args)
    heights = tuple(parse_values(args.heights, "--heights")) if args.heights else None
    ds = simulate(
        args.preset,
        noise_rho=args.noise_rho,
        seed=args.seed,
        noise=args.noise,
        effects=effects,
        heights_m=heights,
        progress=_progress(args),
    )
    ds.save(args.out, overwrite=args.force, frames=args.frames, arm=args.arm)
    eff = ", ".join(f"{k}={v:g}" for k, v in effects.to_mapping().items()) or "none"
    if args.json:
        _emit_json(
            {
                "out": str(args.out),
                "specimen": ds.specimen,
                "heights_m": list(ds.heights_m),
                "noise": args.noise,
                "effects": effects.to_mapping(),
                "frames": args.frames,
            }
        )
        return 0
    print(
        f"wrote {args.out}: {ds.specimen}, {len(ds.pushes)} pushes at "
        f"{', '.join(f'{h:g}' for h in ds.heights_m)} m, noise {args.noise}, effects {eff}"
        + (", with RGB-D frames" if args.frames else "")
    )
    return 0


@_command("extract")
def cmd_extract(args: argparse.Namespace) -> int:
    from ..api import extract

    _prepare_out(args)
    res = extract(args.dataset, progress=_progress(args), width_colour_model=args.width_colour_model)
    res.save(args.out, overwrite=args.force)
    if args.json:
        _emit_json({"out": str(args.out), **res.to_dict()})
        return 0
    print(f"wrote {args.out}: shapes_extracted.csv per push, extract_report.json, figures/extract_*.png")
    return 0


@_command("import")
def cmd_import(args: argparse.Namespace) -> int:
    # --force is both the force column (--force COL) and, bare, the contract's "replace --out"
    args.force_col = args.force if isinstance(args.force, str) else args.force_column
    args.force = args.force is True or args.replace
    if args.kind == "table":
        return _import_table(args)
    from ..dataset import validate_dataset
    from ..dataset.importers import import_blueberry
    from ..dataset.io import atomic_dir

    if len(args.src) != 1:
        raise ValueError(f"SRC: expected one blueberry-canes folder, got {len(args.src)} paths")
    if args.length_m is None:
        raise ValueError("--length-m: expected an assumed cane length [m] (the blueberry tables hold none), got none")
    _prepare_out(args)
    with atomic_dir(args.out, args.force) as tmp:
        report = import_blueberry(args.src[0], tmp, args.length_m)
        for cane in report["canes"]:
            if cane["status"] == "imported":
                errors = [p for p in validate_dataset(tmp / cane["dataset"]) if p.severity == "error"]
                if errors:
                    raise ValueError(f"imported dataset {cane['dataset']} does not validate: {errors[0]}")
    if args.json:
        _emit_json(report)
        return 0
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


def _import_table(args: argparse.Namespace) -> int:
    from ..api import import_table
    from ..dataset import validate_dataset

    if not args.force_col:
        raise ValueError("--force: expected the column's header name, got none")
    out = _prepare_out(args)
    res = import_table(
        args.src,
        time=args.time,
        force=args.force_col,
        displacement=args.displacement,
        angle=args.angle,
        arm_height_m=args.arm_height,
        time_unit=args.time_unit,
        force_unit=args.force_unit,
        displacement_unit=args.displacement_unit,
        angle_unit=args.angle_unit,
        height_m=args.height_m,
        length_m=args.length_m,
        length_unknown=args.length_unknown,
        specimen=args.specimen,
        species=args.species,
        stem_id=args.stem_id,
        condition=args.condition,
        metadata=args.metadata,
        header_row=args.header_row,
        specimen_column=args.specimen_column,
        stem_id_column=args.stem_id_column,
        condition_column=args.condition_column,
        test_column=args.test_column,
        height_column=args.height_column,
        height_unit=args.height_unit,
        cycles=args.cycles,
        force_sign=args.force_sign,
        displacement_sign=args.displacement_sign,
        tare=args.tare,
    )
    res.save(out, overwrite=args.force)
    problems = {name: validate_dataset(out / name) for name in res.specimens}
    if args.json:
        _emit_json({**res.report, "problems": {k: [dict(vars(p)) for p in v] for k, v in problems.items()}})
    else:
        for f in res.report["files"]:
            pushes = ", ".join(
                f"cycle {p['cycle']} (rows {p['rows'][0]}-{p['rows'][1]}, peak {p['peak_force_N']:.3g} N"
                + (f", preload {p['preload_N']:.3g} N" if p["preload_N"] else "")
                + ")"
                for p in f["pushes"]
            )
            skipped = f"; {len(f['rows_skipped'])} lines skipped" if f["rows_skipped"] else ""
            print(
                f"{f['file']}: header at line {f['header_line']} ({f['delimiter']}-separated, decimal "
                f"{f['decimal']!r}){skipped} -> {f['specimen']}: {pushes}"
            )
        for name, probs in problems.items():
            for prob in probs:
                print(f"  {name}: {prob}", file=sys.stderr if prob.severity == "error" else sys.stdout)
        print(
            f"wrote {len(res.specimens)} dataset{'s' * (len(res.specimens) > 1)} into {args.out} "
            f"(details: {out / 'import_report.json'})"
        )
    return 1 if any(p.severity == "error" for v in problems.values() for p in v) else 0


# --------------------------------------------------------------------------- #
# fit, fit-many, demo
# --------------------------------------------------------------------------- #
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


def _fit_and_save(
    dataset,
    out: Path,
    args,
    *,
    seed: int,
    use_forces=True,
    use_shapes=True,
    prior=None,
    effects=(),
    shape_weight="auto",
    max_steps=8000,
    target_ess=1000.0,
    force_noise="iid",
    preload=False,
    **nuisances,
):
    """Fit with the API, checkpointing into ``out/chains.h5``, then save the run into ``out``."""
    from ..api import fit

    post = fit(
        dataset,
        prior=prior,
        effects=effects,
        seed=seed,
        progress=_progress(args),
        use_forces=use_forces,
        use_shapes=use_shapes,
        shape_weight=shape_weight,
        checkpoint=out / "chains.h5",
        max_steps=max_steps,
        target_ess=target_ess,
        force_noise=force_noise,
        preload=preload,
        **nuisances,
    )
    post.save(out, overwrite=True)
    return post


@_command("fit")
def cmd_fit(args: argparse.Namespace) -> int:
    if args.forces_only and args.shapes_only:
        raise ValueError("--forces-only, --shapes-only: expected at most one, got both")
    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    out = Path(args.out)
    if not args.resume:
        _prepare_out(args)
        if args.force and out.is_dir():
            import shutil

            shutil.rmtree(out)
    elif out.is_dir() and (out / "summary.json").is_file() and not (out / "chains.h5").is_file():
        raise ValueError(f"--resume: expected an interrupted run (chains.h5) in {out}, got a finished run without one")
    post = _fit_and_save(
        args.dataset,
        out,
        args,
        seed=args.seed,
        use_forces=not args.shapes_only,
        use_shapes=not args.forces_only,
        prior=args.prior,
        effects=effects,
        shape_weight=_shape_weight(args.shape_weight),
        max_steps=args.max_steps,
        target_ess=args.target_ess,
        force_noise=args.force_noise,
        preload=args.preload,
        length=args.length,
        height_sd_m=args.height_sd,
        force_offsets=args.force_offsets,
        diameter=args.diameter,
        slip=args.slip,
        n_workers=args.workers,
    )
    _print_fit(post.to_dict(), out, args)
    return 0


def _print_fit(summary: dict, out, args) -> None:
    if args.json:
        _emit_json(summary)
        return
    for name, q in summary["parameters"].items():
        print(f"  {name:>15} = {q['median']:.4g}  [{q['q05']:.4g}, {q['q95']:.4g}]  (median [90% interval])")
    for row in summary["k_theta"]:
        print(f"  k_theta({row['height_m']:g} m) = {row['median']:.4g}  [{row['q05']:.4g}, {row['q95']:.4g}] N m/rad")
    y = summary.get("youngs_modulus")
    if y:
        e = y["E_Pa"]
        print(
            f"  Young's modulus E0 = {e['median'] / 1e9:.4g}  [{e['q05'] / 1e9:.4g}, {e['q95'] / 1e9:.4g}] GPa "
            f"(64 EI0 / (pi d0^4); {y['model']} modulus)"
        )
        if "uniform_modulus" in y:
            m = y["modulus_taper"]
            print(
                f"  uniform modulus {y['uniform_modulus']}: p - p_geom = {m['median']:.3g}  "
                f"[{m['q05']:.3g}, {m['q95']:.3g}]"
            )
            if y["uniform_modulus"] == "rejected" and y.get("source") == "frames":
                print("  (frame widths reject 1 uniform stem in 10 at this level: confirm with calipers; report.html)")
    c = summary["convergence"]
    print(f"  R-hat max {c['rhat_max']:.4f}, bulk ESS min {c['ess_bulk_min']:.0f}, {summary['sampler']['seconds']:g} s")
    print(f"wrote {out}/summary.json, posterior.nc, report.html")


@_command("fit-many")
def cmd_fit_many(args: argparse.Namespace) -> int:
    from ..api import fit_many

    res = fit_many(
        args.root,
        args.out,
        scheduler=args.scheduler,
        n_workers=args.workers,
        prior=args.prior,
        seed=args.seed,
        use_shapes=not args.forces_only,
        progress=_progress(args),
        grouped=args.grouped,
    )
    res.save(args.out)
    if args.json:
        _emit_json(res.to_dict())
    else:
        stems = len({r["stem_id"] for r in res.group_rows})
        print(
            f"wrote {args.out}: {len(res.rows)} specimens in survey.csv / survey.parquet"
            + (f", {stems} stems jointly in groups.csv / groups.parquet" if args.grouped else "")
            + f" ({res.n_datasets} datasets)"
            + (f"; {len(res.failures)} failed (failures.json)" if res.failures else "")
        )
    return 1 if res.failures else 0


@_command("fit-group")
def cmd_fit_group(args: argparse.Namespace) -> int:
    from ..api import fit_groups

    out = _prepare_out(args)
    shared = tuple(x.strip() for x in args.shared.split(",") if x.strip())
    pooled = "auto" if args.pooled == "auto" else tuple(x.strip() for x in args.pooled.split(",") if x.strip())
    study = fit_groups(
        args.root,
        args.prior,
        shared=shared,
        pooled=pooled,
        pool_spread=args.pool_spread,
        force_noise=args.force_noise,
        force_offsets=args.force_offsets,
        sharing=not args.no_sharing_check,
        seed=args.seed,
        max_steps=args.max_steps,
        target_ess=args.target_ess,
        progress=_progress(args),
    )
    study.save(out, overwrite=True)
    if args.json:
        _emit_json({sid: g.to_dict() for sid, g in study.fits.items()} | {"problems": list(study.problems)})
        return 1 if study.problems else 0
    for sid, g in study.fits.items():
        _print_group(sid, g.to_dict())
    for p in study.problems:
        print(f"  problem: {p}", file=sys.stderr)
    print(f"wrote {out}/groups.json and one folder per stem")
    return 1 if study.problems else 0


@_command("demo")
def cmd_demo(args: argparse.Namespace) -> int:
    from ..api import DEMO_DATASET, extract, load

    _prepare_out(args)
    out = Path(args.out)
    if args.force and out.is_dir():
        import shutil

        shutil.rmtree(out)
    dataset = Path(args.dataset) if args.dataset else DEMO_DATASET
    say = (lambda *a: None) if args.json else print
    ds = load(dataset)
    if any(p.frames for p in ds.pushes):
        say(f"bayesrod demo: extracting centerlines from the frames of {dataset} ...")
        ex = extract(ds, progress=_progress(args))
        ex.save(out / "extracted")
        n = sum(len(p["frames"]) for p in ex.to_dict()["pushes"].values())
        say(f"  {n} frames extracted into {out / 'extracted'}")
        dataset = out / "extracted"
    else:
        say(f"bayesrod demo: {dataset} has no RGB-D frames (centerlines are given); no extraction needed")
    say(f"bayesrod demo: fitting {dataset} ...")
    post = _fit_and_save(dataset, out / "fit", args, seed=0)
    summary = post.to_dict()
    _print_fit(summary, out / "fit", args)
    if args.json:
        return 0
    truth = summary.get("truth")
    if truth:
        print(f"  (simulated truth: EI0 = {truth['EI0']:g} N m^2, p = {truth['p']:g})")
    print(f"report: {(out / 'fit' / 'report.html').resolve()}")
    return 0


# --------------------------------------------------------------------------- #
# compare, design, diagnose
# --------------------------------------------------------------------------- #
@_command("compare")
def cmd_compare(args: argparse.Namespace) -> int:
    from ..api import compare
    from ..api.compare import _as_posterior, _is_run, expand_inputs

    out = _prepare_out(args)
    posts, fitted = [], []
    for path in expand_inputs(args.inputs):
        if _is_run(path):
            posts.append(_as_posterior(path))  # a fit, or a stem of fit-group
        elif (path / "specimen.json").is_file():
            logging.getLogger("bayesrod").info("%s: a dataset; fitting it first", path)
            from ..api import fit

            post = fit(path, seed=args.seed, progress=False)
            posts.append(post)
            fitted.append(post)
        else:
            raise ValueError(
                f"{path}: expected a fit run or a fit-group stem (summary.json + samples.npz) or a dataset "
                "(specimen.json)"
            )
    res = compare(posts, height_m=args.height, seed=args.seed)
    res.save(out, overwrite=args.force)
    for post in fitted:
        post.save(out / "fits" / post.specimen)
    if args.json:
        _emit_json(res.to_dict())
        return 0
    for c in res.contrasts:
        if c["parameter"] == "EI0":
            print(
                f"EI0 {c['a']} / {c['b']}: {c['ratio_median']:.3g} [{c['ratio_q05']:.3g}, {c['ratio_q95']:.3g}] "
                f"(90%), P({c['a']} stiffer) = {c['prob_a_greater']:.3f}"
            )
    for cond, block in res.to_dict().get("anchorage", {}).items():
        for c in block["contrasts"]:
            print(
                f"base compliance, {cond}: {c['a']} - {c['b']} = {c['difference_median']:.3g} "
                f"[{c['difference_q05']:.3g}, {c['difference_q95']:.3g}] rad/(N m) (90%), "
                f"P({c['a']} softer base) = {c['prob_a_greater']:.3f}"
            )
    print(f"wrote {args.out}/compare.json and figures/forest.png")
    return 0


def _design_source(args, out: Path):
    """The posterior to design from: a run (or fit-group stem) as it is, or a dataset fitted first into OUT/fit."""
    src = Path(args.source)
    if (src / "samples.npz").is_file():
        return src, None  # the API loads a run or a fit-group stem
    if (src / "specimen.json").is_file():
        logging.getLogger("bayesrod").info("%s: a dataset; fitting it into %s first", src, out / "fit")
        from ..api import fit

        return None, fit(src, seed=args.seed, use_shapes=not args.forces_only, progress=_progress(args))
    raise ValueError(f"{src}: expected a fit run (samples.npz) or a dataset (specimen.json)")


@_command("design")
def cmd_design(args: argparse.Namespace) -> int:
    from ..api import design

    out = _prepare_out(args)
    rng = None
    if args.force_range:
        try:
            rng = [float(v) for v in args.force_range.split(",")]
        except ValueError:
            rng = None
        if rng is None or len(rng) != 2:
            raise ValueError(f"--force-range: expected LOW,HIGH in N, got {args.force_range!r}")
    loaded, fitted = _design_source(args, out)
    post = loaded or fitted
    heights = parse_candidates(args.candidates) if args.candidates else None
    res = design(
        post,
        heights,
        sensor=rng,
        displacement_m=args.displacement,
        n_samples=args.samples,
        confidence=args.confidence,
        target=args.target,
        target_height_m=args.target_height,
        method=args.method,
        condition=args.condition,
        seed=args.seed,
        progress=_progress(args),
    )
    res.save(out, overwrite=args.force)
    if fitted is not None:
        fitted.save(out / "fit")
    doc = res.to_dict()
    if args.json:
        _emit_json(doc)
    else:
        for r in doc["candidates"]:
            g = r["expected_information_gain_nats"]
            mark = "*" if r["height_m"] == doc["recommended_height_m"] else " "
            why = "" if r["feasible"] else f"  infeasible: {r['reason']}"
            print(f" {mark} h = {r['height_m']:.3f} m  EIG {'-' if g is None else f'{g:.3f}'} nats{why}")
    if doc["recommended_height_m"] is None:
        print(f"no feasible height among the candidates; wrote {args.out}/design.json", file=sys.stderr)
        return 1
    if not args.json:
        print(f"recommended next height: {doc['recommended_height_m']:.3f} m; wrote {args.out}/design.json")
    return 0


def parse_candidates(text: str):
    """``start:stop:num`` heights for ``design --candidates``."""
    import numpy as np

    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f"--candidates: expected start:stop:num (metres, metres, count), got {text!r}") from None
    if n < 1 or not (np.isfinite(a) and np.isfinite(b)):
        raise ValueError(f"--candidates: expected num >= 1 and finite heights, got {text!r}")
    return np.linspace(a, b, n)


@_command("diagnose")
def cmd_diagnose(args: argparse.Namespace) -> int:
    from ..api import diagnose
    from ..inference.diagnose import CATALOG

    out = _prepare_out(args)
    cands = CATALOG
    if args.candidates:
        cands = tuple(c.strip() for c in args.candidates.split(",") if c.strip())
    res = diagnose(
        args.dataset,
        candidates=cands,
        use_shapes=not args.forces_only,
        alpha=args.alpha,
        min_heldout_gain=args.min_heldout_gain,
        heldout_alpha=args.heldout_alpha,
        force_noise=args.force_noise,
        preload={"auto": "auto", "yes": True, "no": False}[args.preload],
        length=args.length,
        height_sd_m=args.height_sd,
        n_workers=args.workers,
    )
    res.save(out, overwrite=args.force)
    doc = res.to_dict()
    if args.json:
        _emit_json(doc)
        return 0
    _print_diagnosis(doc)
    print(f"wrote {args.out}/diagnose.json and report.html")
    return 0


def _print_group(sid: str, d: dict) -> None:
    """One stem's joint fit in a few lines: the shared parameters, the sharing verdict, each condition's base
    compliance (median [q05, q95]); its warnings on stderr."""
    sh = ", ".join(f"{k} {v['median']:.4g} [{v['q05']:.4g}, {v['q95']:.4g}]" for k, v in d["shared"].items())
    print(f"{sid}: {sh}" + (f"; sharing {d['sharing']['verdict']}" if d["sharing"] else ""))
    for c, row in d["conditions"].items():
        q = row["base_compliance_rad_per_Nm"]
        print(f"  {c:>12}: base compliance {q['median']:.3g} [{q['q05']:.3g}, {q['q95']:.3g}] rad/(N m)")
    for w in d["warnings"]:
        print(f"  warning: {w}", file=sys.stderr)


def _print_diagnosis(doc: dict) -> None:
    """diagnose.json's story in a few lines: the effects added, the nuisances fitted, each error before -> after."""
    from ..report.html import alternatives_text

    b, a = doc["before"], doc["after"]
    print(f"added effects: {', '.join(doc['added_effects']) or 'none'}")
    if alt := alternatives_text(doc.get("alternatives", {})):
        print(f"  {alt.strip()}")
    if doc["fitted"].get("preload_m"):
        print(f"  preload per push [mm]: {', '.join(f'{1000 * v:.3g}' for v in doc['fitted']['preload_m'])}")
    if doc["settings"]["length"] == "unknown":
        lo, hi = doc["settings"]["length_bounds_m"]
        print(f"  stem length fitted: {doc['fitted']['length_m']:.3g} m (within [{lo:.3g}, {hi:.3g}] m)")
    if doc["fitted"].get("height_error_m"):
        dh = ", ".join(f"{1000 * v:+.3g}" for v in doc["fitted"]["height_error_m"])
        print(f"  contact-height error per push [mm]: {dh}")
    for k in ("force_rmse_N", "shape_rmse_mm", "heldout_force_rmse_N"):
        if b[k] is not None:
            print(f"  {k:>22}: {b[k]:.4g} -> {a[k]:.4g}")
    if doc["unexplained_structure"]:
        print("  unexplained structure remains in the residuals (see report.html)")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

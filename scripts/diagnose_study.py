"""Does `bayesrod diagnose` find the effect nobody declared, and leave clean data alone? (issue 9)

    python scripts/diagnose_study.py --out diagnose-study [--clean 10] [--workers 1] [--forces-only]
    python scripts/diagnose_study.py --out sw7 --clean 0 --effects "" --size self_weight=7
    python scripts/diagnose_study.py --out ar --forces-only --noise-rho 0.9 --clean 50 --replicates 50 --workers 2

Simulated twig datasets (three heights, forces and centerlines, default noise):
one per catalog effect at a material size (EFFECTS below), never declared to
the diagnosis, and ``--clean`` replicates without any effect. Each is run
through the whole loop (every catalog effect tested). Records which effects
were added, the fitted value, and the errors before and after, in-sample and
leave-one-height-out. Writes diagnose_study.csv (resumable) and
diagnose_study.md (the tables in docs/validation.md).
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from itertools import zip_longest
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.io import append_rows, read_rows
from bayesrod.inference.diagnose import CATALOG, ForwardModel, diagnose
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects

# material sizes on the twig (L = 0.8 m, EI0 = 2.63 N m^2, heights 0.45-0.65 m)
EFFECTS = {
    "base_compliance": 8.0,  # N m/rad: about the rod's own k_theta at these heights
    "rest_curvature": 0.3,  # 1/m: the unloaded tip 9.6 cm off vertical
    "base_tilt": 0.05,  # rad
    "contact_friction": 0.3,
    "force_offset": 0.1,  # N, about 3 force-noise sd
    "self_weight": 5.0,  # N/m at the base (w0 L^3/EI0 = 0.97; at 2 N/m the forces move by less than the noise)
    "yield": 3.0,  # N m, about half the largest base moment of the h = 0.45 m push
}
FIELDS = ["case", "effect", "value", "seed", "added", "fitted", "force_before", "force_after"]
FIELDS += ["heldout_before", "heldout_after", "shape_before", "shape_after", "unexplained", "top_statistic"]
FIELDS += ["noise_rho", "rho_fitted", "seconds", "alternatives", "cpu_seconds"]
#: since session 52: per held-out push of the final model, its height, force RMSE and the refit's parameters
#: (diagnose.json's after.per_push): which height's refit drifts when the held-out error scatters
FIELDS += ["heldout_after_per_push"]


def one(job) -> dict:
    case, effect, value, seed, forces_only, rho = job
    eff = Effects.from_mapping({effect: value} if effect else {})
    # 8 frames per push (about 1900 centerline points): the shape signatures, at a third of the cost
    spec = bayesrod.simulate(
        "twig",
        seed=seed,
        effects=eff,
        noise_rho=rho,
        config_overrides={"specimen": f"diag-{case}", "n_frames_engaged": 8},
    )
    model = ForwardModel(prepare_data(spec, use_shapes=not forces_only), spec.length_m)
    t0, c0 = time.perf_counter(), time.process_time()
    # "outside:<effect>": the effect is simulated but not a candidate (outside the catalog the loop knows)
    outside = case.startswith("outside")
    r = diagnose(model, candidates=[c for c in CATALOG if not (outside and c == effect)])
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    b, a = r["before"], r["after"]
    first = max((c for c in r["candidates"] if c["round"] == 1), key=lambda c: c["statistic"])
    return {
        "case": case,
        "effect": effect or "none",
        "value": value,
        "seed": seed,
        "added": ",".join(r["added_effects"]),
        "fitted": json.dumps({k: np.round(v, 5).tolist() for k, v in r["fitted"].items()}),
        "force_before": b["force_rmse_N"],
        "force_after": a["force_rmse_N"],
        "heldout_before": b["heldout_force_rmse_N"],
        "heldout_after": a["heldout_force_rmse_N"],
        "shape_before": b["shape_rmse_mm"],
        "shape_after": a["shape_rmse_mm"],
        "unexplained": int(r["unexplained_structure"]),
        "top_statistic": f"{first['effect']}:{first['statistic']:.3g}",
        "noise_rho": rho,
        "rho_fitted": r["noise"].get("rho_force", 0.0),
        "seconds": round(seconds, 1),
        # added effect (or pair) -> candidates the data cannot tell from it (diagnose.json `alternatives`)
        "alternatives": json.dumps(r.get("alternatives", {})),
        # CPU time of the case's process: unlike the wall time, not inflated by a paused or shared machine
        "cpu_seconds": round(cpu, 1),
        "heldout_after_per_push": json.dumps(
            [
                {
                    "height_m": u["height_m"],
                    "force_rmse_N": round(u["force_rmse_N"], 5),
                    "refit": {k: np.round(v, 5).tolist() for k, v in u["refit"].items()},
                }
                for u in a.get("per_push") or []
            ]
        ),
    }


def alternatives_named(rows) -> str:
    """How many rows' diagnoses named a candidate the data cannot tell from the added effect, and which.

    Counted over the rows that recorded the column (studies before session 33 did not): "-" when none did.
    """
    known = [json.loads(r["alternatives"]) for r in rows if r.get("alternatives")]
    if not known:
        return "-"
    named = sorted({x for a in known for v in a.values() for x in v})
    hits = sum(any(a.values()) for a in known)
    return f"{hits}/{len(known)}" + (f" ({', '.join(named)})" if named else "")


def _median_seconds(rows) -> str:
    """Median CPU seconds per case where recorded (wall seconds, marked "wall", for older rows only)."""
    cpu = sorted(float(r["cpu_seconds"]) for r in rows if r.get("cpu_seconds"))
    if cpu:
        return f"{cpu[len(cpu) // 2]:.0f} cpu ({len(cpu)})"
    wall = sorted(float(r.get("seconds") or 0) for r in rows)
    return f"{wall[len(wall) // 2]:.0f} wall"


def tables(rows) -> str:
    outside = [r for r in rows if r["case"].startswith("outside")]
    eff = [r for r in rows if r["effect"] != "none" and not r["case"].startswith("outside")]
    clean = [r for r in rows if r["effect"] == "none"]
    out = [
        "| effect (size) | added | fitted | held-out force RMSE before -> after [N] | change | "
        "shape RMSE before -> after [mm] | unexplained structure |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in eff:
        hb, ha = float(r["heldout_before"]), float(r["heldout_after"])
        fitted = json.loads(r["fitted"]).get(r["effect"])
        sb = "-" if r["shape_before"] in ("", "None") else f"{float(r['shape_before']):.3g}"
        sa = "-" if r["shape_after"] in ("", "None") else f"{float(r['shape_after']):.3g}"
        out.append(
            f"| {r['effect']} ({float(r['value']):g}) | {r['added'] or 'none'} | "
            f"{'-' if fitted is None else f'{fitted:.4g}'} | {hb:.4f} -> {ha:.4f} | {100 * (ha - hb) / hb:+.0f}% | "
            f"{sb} -> {sa} | {'yes' if int(r['unexplained']) else 'no'} |"
        )
    out += [
        "",
        "| effect | replicates | attributed | added exactly it | false attributions | "
        "median held-out change | unexplained | alternatives named | median s (cases) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for e in sorted({r["effect"] for r in eff}):
        rr = [r for r in eff if r["effect"] == e]
        hit = sum(e in r["added"].split(",") for r in rr)
        exact = sum(r["added"] == e for r in rr)
        wrong = sorted({x for r in rr for x in r["added"].split(",") if x and x != e})
        ch = [100 * (float(r["heldout_after"]) / float(r["heldout_before"]) - 1) for r in rr]
        out.append(
            f"| {e} | {len(rr)} | {hit}/{len(rr)} | {exact}/{len(rr)} | {', '.join(wrong) or 'none'} | "
            f"{sorted(ch)[len(ch) // 2]:+.0f}% | {sum(int(r['unexplained']) for r in rr)}/{len(rr)} | "
            f"{alternatives_named(rr)} | "
            f"{_median_seconds(rr)} |"
        )
    if outside:
        out += [
            "",
            f"Yield simulated but not a candidate: unexplained structure flagged in "
            f"{sum(int(r['unexplained']) for r in outside)}/{len(outside)}; added: "
            f"{', '.join(r['added'] or 'none' for r in outside)}.",
        ]
    if clean:
        n_add = sum(bool(r["added"]) for r in clean)
        flagged = sum(int(r["unexplained"]) for r in clean)
        out += [
            "",
            f"Clean replicates: {len(clean) - n_add}/{len(clean)} with no effect added "
            f"({', '.join(r['added'] for r in clean if r['added']) or 'none added anywhere'}); "
            f"unexplained structure flagged in {flagged}/{len(clean)}.",
        ]
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="diagnose-study")
    ap.add_argument("--clean", type=int, default=10)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--forces-only", action="store_true")
    ap.add_argument("--effects", help='comma list (default: the whole catalog; "" for clean replicates only)')
    ap.add_argument(
        "--effects-first", action="store_true", help="in each round-robin turn, the effect cases before the clean ones"
    )
    ap.add_argument("--size", action="append", default=[], help="EFFECT=VALUE: another size (case EFFECT@VALUE)")
    ap.add_argument("--noise-rho", type=float, default=0.0, help="AR(1) correlation of the simulated force noise")
    ap.add_argument("--replicates", type=int, default=1, help="seeds per effect case (default 1)")
    ap.add_argument(
        "--outside", type=int, default=0, help="replicates with yield simulated but not a candidate (default 0)"
    )
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "diagnose_study.csv"
    done = {r["case"] for r in read_rows(csv)}
    names = list(EFFECTS) if args.effects is None else [e for e in args.effects.split(",") if e]
    sizes = {e: EFFECTS[e] for e in names}
    for item in args.size:
        name, _, value = item.partition("=")
        if name not in EFFECTS:
            ap.error(f"--size {item}: unknown effect {name!r}; expected one of {sorted(EFFECTS)}")
        sizes[name] = float(value)
    rho = args.noise_rho
    groups = [
        [(f"clean-{s}", None, 0.0, 100 + s, args.forces_only, rho) for s in range(args.clean)],
        [(f"outside-{s}", "yield", EFFECTS["yield"], 200 + s, args.forces_only, rho) for s in range(args.outside)],
    ]
    effect_jobs = [
        [
            (f"{e if v == EFFECTS[e] else f'{e}@{v:g}'}" + (f"-{k}" if k else ""), e, v, 11 + k, args.forces_only, rho)
            for k in range(args.replicates)
        ]
        for e, v in sizes.items()
    ]
    # round-robin over the groups (clean, outside, each effect): a study cut short (it resumes) has
    # some replicates of every case; --effects-first: the effect cases, then the rest
    groups = effect_jobs + groups if args.effects_first else groups + effect_jobs
    jobs = [j for row in zip_longest(*groups) for j in row if j is not None]
    todo = [j for j in jobs if j[0] not in done]
    with ProcessPoolExecutor(args.workers) as ex:
        # rows are written as their cases finish (a slow case must not hold back the finished ones: a
        # run cut short keeps every case it completed)
        finished = (f.result() for f in as_completed([ex.submit(one, j) for j in todo]))
        for r in append_rows(csv, FIELDS, finished, new_file=not done):
            print(f"{r['case']}: added [{r['added']}] held-out {r['heldout_before']:.4f} -> {r['heldout_after']:.4f}")
    text = tables(read_rows(csv))
    (out / "diagnose_study.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

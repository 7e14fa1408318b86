"""Replicate study of ``bayesrod.fit_group`` on simulated brace-root series (issue 23).

    python scripts/group_study.py --out group-study --replicates 30 --workers 2 [--heights 0.55]
        [--pooled auto|rho_force|''] [--rho 0.9 | --rho intact=0.3,cut1=0.6,cut2=0.9,cut3=0.97]

Each replicate is one stem (the twig: L = 0.8 m) with realistic spread -- EI0 log-normal around
2.63 N m^2 (log-sd 0.3), p uniform on [0.3, 0.6] -- pushed under four conditions with AR(1)
force noise (rho 0.9), forces only: ``intact`` (a clamp) and three cuts leaving 0.88, 0.64 and
0.49 of the clamped translational stiffness at 0.55 m (each ratio +-0.04 uniform; the published
brace-root means). Every ``--stem-change-every``-th replicate is instead a stem that itself softened
(EI0 x 0.7 in the last two conditions, the base unchanged). Per replicate: the joint fit
(``fit_group``: AR(1) noise, prior ``woody``), whether the shared EI0's 90% interval covers the
truth, each cut's base-compliance interval covers its truth, P(cut3 softer than intact), the
sharing verdict, and the apparent EI0 drop of separate plain fits (MAP per condition) for contrast.
``--rho`` gives the conditions differing noise correlations (a rig whose noise changes between pushes), and the
table then adds whether each condition's rho interval covers its own. Writes group_study.csv (resumable) and
group_study.md (the tables of docs/validation.md).
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import bayesrod
from bayesrod.dataset.io import append_rows, read_rows
from bayesrod.inference.group import GroupLikelihood, GroupPosterior, start_point
from bayesrod.inference.priors import load_prior
from bayesrod.inference.summary import SENSITIVITY_WARN
from bayesrod.physics import k_x

L, H_REF = 0.80, 0.55
RATIOS = {"cut1": 0.88, "cut2": 0.64, "cut3": 0.49}
FIELDS = ["rep", "kind", "heights", "EI0", "p", "EI0_med", "EI0_q05", "EI0_q95", "EI0_cover"]
FIELDS += [f"C_{c}_{k}" for c in RATIOS for k in ("true", "med", "q05", "q95", "cover")]
FIELDS += [f"D_{c}_{k}" for c in RATIOS for k in ("med", "q05", "q95", "cover")]
FIELDS += ["prob_cut3_softer", "sharing", "rmse_joint", "rmse_separate", "apparent_drop_cut3", "rhat", "seconds"]
CONDITIONS = ("intact", *RATIOS)
FIELDS += [f"rho_{c}_{k}" for c in CONDITIONS for k in ("true", "med", "q05", "q95", "cover")]
#: since session 52: each condition's rho prior sensitivity and the largest of the compliances'
#: (summary.json's identifiability.correlation_prior_sensitivity)
FIELDS += [f"rho_{c}_prior_sens" for c in CONDITIONS] + ["C_prior_sens_max"]


def stem(rep: int, kind: str = "base") -> tuple[float, float, dict, dict]:
    """Replicate ``rep``'s stem and anchorage (``kind`` base: the anchorage changes; stem: it does not):
    EI0, p, the conditions (name -> base spring [N m/rad], inf: a clamp) and each cut's true base
    compliance [rad/(N m)]."""
    rng = np.random.default_rng(1000 + rep)
    EI0 = 2.63 * math.exp(0.3 * rng.standard_normal())
    p = float(rng.uniform(0.3, 0.6))
    kx = float(k_x(H_REF, EI0, p, L))
    conds = {"intact": math.inf}
    truth_C = {}
    for c, r in RATIOS.items():
        r = r + float(rng.uniform(-0.04, 0.04))
        kb = kx * H_REF**2 * r / (1.0 - r)
        conds[c] = kb if kind == "base" else math.inf
        truth_C[c] = 1.0 / kb if kind == "base" else 0.0
    return EI0, p, conds, truth_C


#: simulate_group seeds condition i with seed + i: replicate r's data come from seed r x SEED_STRIDE, so no two
#: replicates share a condition's noise (before session 51 the stride was 1: replicates r and r + 1 shared three
#: of their four conditions' noise draws; ``--seed-stride 1`` reproduces those runs)
SEED_STRIDE = len(CONDITIONS)


def replicate_data(rep: int, kind: str, heights, rho=0.9, stride: int = SEED_STRIDE) -> tuple:
    """The datasets of replicate ``rep`` (``kind`` base: the anchorage changes; stem: the stem softens;
    ``rho`` the noise correlation, one or per condition; ``stride``: simulate_group's seed is ``rep x stride``),
    its EI0 and p, and each cut's true base compliance."""
    EI0, p, conds, truth_C = stem(rep, kind)
    change = {"cut2": 0.7, "cut3": 0.7} if kind == "stem" else None
    dss = bayesrod.simulate_group(
        "twig",
        conditions=conds,
        seed=rep * stride,
        heights_m=heights,
        noise_rho=rho,
        stem_change=change,
        config_overrides={"n_frames_engaged": 2, "EI0": EI0, "p": p},
    )
    return dss, EI0, p, truth_C


def one(job) -> dict:
    rep, kind, heights, ess, options, rho, stride = job
    t0 = time.perf_counter()
    dss, EI0, p, truth_C = replicate_data(rep, kind, heights, rho, stride)
    g = bayesrod.fit_group(
        list(dss), prior="woody", progress=False, target_ess=ess, max_steps=5000, seed=rep, **options
    )
    d = g.to_dict()
    row = {"rep": rep, "kind": kind, "heights": " ".join(f"{h:g}" for h in heights), "EI0": EI0, "p": p}
    q = d["shared"]["EI0"]
    row.update(EI0_med=q["median"], EI0_q05=q["q05"], EI0_q95=q["q95"], EI0_cover=int(q["q05"] <= EI0 <= q["q95"]))
    for c in RATIOS:
        qc = d["conditions"][c]["base_compliance_rad_per_Nm"]
        row.update(
            {
                f"C_{c}_true": truth_C[c],
                f"C_{c}_med": qc["median"],
                f"C_{c}_q05": qc["q05"],
                f"C_{c}_q95": qc["q95"],
                f"C_{c}_cover": int(qc["q05"] <= truth_C[c] <= qc["q95"]),
            }
        )
    for c in RATIOS:  # the contrast cut - intact: what the brace-root question asks
        (ct,) = [x for x in d["contrasts"] if x["a"] == "intact" and x["b"] == c]
        qd = ct["compliance_difference_rad_per_Nm"]
        row.update(
            {
                f"D_{c}_med": qd["median"],
                f"D_{c}_q05": qd["q05"],
                f"D_{c}_q95": qd["q95"],
                f"D_{c}_cover": int(qd["q05"] <= truth_C[c] <= qd["q95"]),
            }
        )
    (ct,) = [c for c in d["contrasts"] if c["a"] == "intact" and c["b"] == "cut3"]
    row["prob_cut3_softer"] = ct["prob_b_softer"]
    row["sharing"] = d["sharing"]["verdict"]
    row["rmse_joint"] = d["sharing"]["heldout_force_rmse_joint_N"]
    row["rmse_separate"] = d["sharing"]["heldout_force_rmse_separate_N"]
    # separate plain fits (MAP, EI0 and p per condition, no base spring): the apparent EI0 drop of cut3
    sep = GroupLikelihood({x.extra["condition"]: x for x in dss}, load_prior("woody"), shared=(), anchorage=False)
    post = GroupPosterior(sep)
    nat = post.to_natural(start_point(post))
    row["apparent_drop_cut3"] = 1.0 - float(nat["EI0__cut3"][0] / nat["EI0__intact"][0])
    row["rhat"] = d["convergence"]["rhat_max"]
    for c in CONDITIONS:  # each condition's noise correlation against its own truth
        r_true = rho.get(c, 0.0) if isinstance(rho, dict) else rho
        qr = d["conditions"][c].get("rho_force")
        if qr is not None:
            row.update({f"rho_{c}_true": r_true, f"rho_{c}_med": qr["median"], f"rho_{c}_q05": qr["q05"]})
            row.update({f"rho_{c}_q95": qr["q95"], f"rho_{c}_cover": int(qr["q05"] <= r_true <= qr["q95"])})
    sens = d["identifiability"].get("correlation_prior_sensitivity")
    if sens is not None:
        row.update({f"rho_{c}_prior_sens": sens["rho_force"][c]["prior"] for c in CONDITIONS})
        soft = [v["prior"] for v in sens["base_compliance_rad_per_Nm"].values() if v is not None]  # None: a clamp
        row["C_prior_sens_max"] = max(soft) if soft else float("nan")
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def _z(row, truth: str, q: str) -> float:
    half = (float(row[f"{q}_q95"]) - float(row[f"{q}_q05"])) / 2.0
    return (float(row[f"{q}_med"]) - float(row[truth])) / (half / 1.645)


def table(rows) -> str:
    out = []
    for kind in ("base", "stem"):
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        n = len(rs)
        cov = np.mean([int(r["EI0_cover"]) for r in rs])
        drop = [float(r["apparent_drop_cut3"]) for r in rs]
        shared = [int(r["sharing"] == "supported") for r in rs]
        out.append(
            f"**{'anchorage changed (stem unchanged)' if kind == 'base' else 'stem softened 30% in cut2, cut3'}**"
            f" ({n} replicates, heights {rs[0]['heights']} m)\n"
        )
        out.append("| quantity | value |")
        out.append("|---|---|")
        out.append(f"| shared EI0 90% interval covers the truth | {cov:.0%} ({int(cov * n)}/{n}) |")
        if kind == "base":
            for c in RATIOS:
                cc = np.mean([int(r[f"C_{c}_cover"]) for r in rs])
                out.append(f"| base compliance of {c}: 90% interval covers the truth | {cc:.0%} |")
                dc = np.mean([int(r[f"D_{c}_cover"]) for r in rs])
                out.append(f"| compliance difference {c} - intact: 90% interval covers the truth | {dc:.0%} |")
            # calibration of the width: z = (median - truth) / (90% half-width / 1.645); rms 1 when calibrated
            zc = [_z(r, f"C_{c}_true", f"C_{c}") for r in rs for c in RATIOS]
            out.append(f"| cut compliances: z rms (1 when right) | {math.sqrt(np.mean(np.square(zc))):.2f} |")
        zE = [_z(r, "EI0", "EI0") for r in rs]
        out.append(f"| shared EI0: z rms | {math.sqrt(np.mean(np.square(zE))):.2f} |")
        med_w = np.median([float(r["EI0_q95"]) / float(r["EI0_q05"]) for r in rs])
        out.append(f"| median width of the shared EI0 interval (q95/q05) | {med_w:.3f} |")
        out.append(
            f"| P(cut3 softer at the base than intact): median | "
            f"{np.median([float(r['prob_cut3_softer']) for r in rs]):.3f} |"
        )
        out.append(
            f"| apparent EI0 drop of cut3 in separate fits: median [min, max] | "
            f"{np.median(drop):.0%} [{min(drop):.0%}, {max(drop):.0%}] |"
        )
        out.append(f"| sharing supported | {np.mean(shared):.0%} ({sum(shared)}/{n}) |")
        for c in CONDITIONS:
            got = [r for r in rs if r.get(f"rho_{c}_cover") not in (None, "")]
            if got:
                rc = [int(r[f"rho_{c}_cover"]) for r in got]
                mid = np.median([float(r[f"rho_{c}_med"]) for r in got])
                out.append(
                    f"| noise rho of {c} (true {float(got[0][f'rho_{c}_true']):g}): 90% interval covers, median"
                    f" of the medians | {np.mean(rc):.0%} ({sum(rc)}/{len(rc)}), {mid:.3f} |"
                )
        sens = [r for r in rs if r.get("rho_intact_prior_sens") not in (None, "")]
        if sens:
            x = [max(float(r[f"rho_{c}_prior_sens"]) for c in CONDITIONS) for r in sens]
            warned = sum(v > SENSITIVITY_WARN for v in x)
            cs = [float(r["C_prior_sens_max"]) for r in sens if r["C_prior_sens_max"] not in ("", "nan")]
            out.append(
                f"| rho prior sensitivity, the stem's largest: median [min, max]; stems warned (> "
                f"{SENSITIVITY_WARN:g}) | {np.median(x):.2f} [{min(x):.2f}, {max(x):.2f}]; {warned}/{len(x)} |"
            )
            if cs:
                out.append(
                    f"| compliances' sensitivity to it, the stem's largest: median [max] | {np.median(cs):.2f} "
                    f"[{max(cs):.2f}] |"
                )
        out.append(f"| median wall time per stem | {np.median([float(r['seconds']) for r in rs]):.0f} s |")
        out.append(
            f"| R-hat max: median [max] | {np.median([float(r['rhat']) for r in rs]):.3f} "
            f"[{max(float(r['rhat']) for r in rs):.3f}] |"
        )
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="group-study")
    ap.add_argument("--replicates", type=int, default=30)
    ap.add_argument("--stem-change-every", type=int, default=5, help="every k-th replicate: the stem softened")
    ap.add_argument("--heights", default="0.55", help="contact heights [m], comma separated")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--target-ess", type=float, default=200.0)
    ap.add_argument("--shared", default="EI0,p", help="fit_group's shared (comma list)")
    ap.add_argument("--pooled", default="auto", help="fit_group's pooled (comma list, '' for none; default auto)")
    ap.add_argument("--rho", default="0.9", help="the noise's AR(1) correlation: one, or condition=rho,... for each")
    ap.add_argument(
        "--seed-stride",
        type=int,
        default=SEED_STRIDE,
        help=f"replicate r is simulated from seed r x stride (default {SEED_STRIDE}: no shared noise; 1: as before "
        "session 51)",
    )
    args = ap.parse_args()
    if "=" in args.rho:
        rho = {k: float(v) for k, v in (x.split("=") for x in args.rho.split(","))}
        unknown = sorted(set(rho) - set(CONDITIONS))
        if unknown:
            raise SystemExit(f"--rho: expected conditions from {', '.join(CONDITIONS)}, got {unknown[0]!r}")
    else:
        rho = float(args.rho)
    options = {"shared": tuple(x for x in args.shared.split(",") if x)}
    options["pooled"] = "auto" if args.pooled == "auto" else tuple(x for x in args.pooled.split(",") if x)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "group_study.csv"
    done = {int(r["rep"]) for r in read_rows(csv)}
    heights = [float(h) for h in args.heights.split(",")]
    jobs = [
        (
            r,
            "stem" if (r + 1) % args.stem_change_every == 0 else "base",
            heights,
            args.target_ess,
            options,
            rho,
            args.seed_stride,
        )
        for r in range(args.replicates)
        if r not in done
    ]
    with ProcessPoolExecutor(args.workers) as ex:
        for r in append_rows(csv, FIELDS, ex.map(one, jobs), new_file=not done):
            print(
                f"rep {r['rep']} ({r['kind']}): EI0 cover {r['EI0_cover']}, sharing {r['sharing']}, {r['seconds']} s",
                flush=True,
            )
    text = table(read_rows(csv))
    (out / "group_study.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

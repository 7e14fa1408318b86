"""Choose where to push next: the loop fit -> design -> push -> fit, run on the simulator.

    python examples/choose_next_height.py [--out choose-next] [--pushes 2]

A simulated twig (the seed's published EI0 and p) is pushed once at 0.44 m.
Each round fits what has been measured (forces only, for speed), asks
`design` for the most informative feasible height (sensor range 0.05-8 N,
pushes stopped at 100 mm), "pushes" there with the simulator, and refits.
The 90% interval on p narrows round by round. With a real robot, replace
`push_at` by your measurement and add the push to your dataset.

The same from the shell, one round:

    bayesrod fit DATASET --out run1 --forces-only
    bayesrod design run1 --out design1          # reads design1/design.json
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from bayesrod.design import run_design
from bayesrod.fit import fit_dataset
from bayesrod.simulate import SimConfig, simulate, write_simulated


def push_at(heights: list[float], folder: Path) -> Path:
    """The 'experiment': the same stem and noise seed, pushed at ``heights`` (earlier pushes are unchanged)."""
    cfg = SimConfig.from_preset(
        "twig", seed=4, heights_m=tuple(heights), max_contact_displacement_m=0.10, n_frames_engaged=2
    )
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    write_simulated(cfg, simulate(cfg), folder)
    return folder


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="choose-next")
    ap.add_argument("--pushes", type=int, default=2, help="further pushes to choose (default 2)")
    args = ap.parse_args()
    out = Path(args.out)
    heights = [0.44]
    quiet = lambda *a: None  # noqa: E731
    for rnd in range(args.pushes + 1):
        ds = push_at(heights, out / f"round{rnd}" / "dataset")
        run = out / f"round{rnd}" / "fit"
        if run.exists():
            shutil.rmtree(run)
        s = fit_dataset(ds, run, use_shapes=False, progress=False, log=quiet)
        q = s["parameters"]["p"]
        print(
            f"round {rnd}: pushed at {', '.join(f'{h:.3f}' for h in heights)} m -> p = {q['median']:.3f} "
            f"[{q['q05']:.3f}, {q['q95']:.3f}] (90% width {q['q95'] - q['q05']:.4f}; truth 0.43)"
        )
        if rnd == args.pushes:
            break
        d = run_design(run, out / f"round{rnd}" / "design", progress=False, log=quiet)
        best = d["recommended_height_m"]
        if best is None:
            print("no feasible height left; stopping")
            break
        rejected = [c for c in d["candidates"] if not c["feasible"]]
        print(f"  design: next push at {best:.3f} m ({len(rejected)} of {len(d['candidates'])} heights infeasible)")
        heights.append(round(best, 4))
    print(f"wrote {out}/ (each round: dataset/, fit/, design/design.json)")
    print(json.dumps({"heights_pushed_m": heights}))


if __name__ == "__main__":
    main()

"""How large the force-noise draws of an SBC's seeds came out, before any fit: a control for the noise sd's ranks.

    python scripts/sbc_noise_draws.py --first-seed 0 --replicates 120
    python scripts/sbc_noise_draws.py --first-seed 1 --replicates 80 --step 2 --effects yield

For each seed, the case of ``scripts/sbc_geometry.py`` (the same draws: ``draw_case``, ``simulate_case``) is
simulated (no fit, no reference solve: the noise is the simulator's either way) and the engaged samples' noise
is compared with the sd the case drew: u = (sum of squared noise / sd^2 - n) / sqrt(2 n), a chi-square of n
degrees of freedom standardised, so mean 0 and sd 1 over seeds whose draws are what they should be. A seed set
whose draws came out small (u's mean below 0 by several standard errors) makes the noise sd's SBC ranks lean
high (the truth above most posterior draws) with a posterior that is right: the lean is in the data. Prints u's
mean +- standard error over all seeds and by number of heights; writes nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from sbc_geometry import ALL_EFFECTS, EFFECTS, draw_case, engaged_forces, simulate_case  # noqa: E402


def noise_draw(seed: int, effects: tuple) -> tuple[int, int, float] | None:
    """(number of heights, engaged samples n, standardised chi-square u) of one seed's force noise; None
    where the case cannot be simulated (a height its rest shape never crosses, as the SBC records)."""
    case = draw_case(seed, effects)
    try:
        ds = simulate_case(seed, case, frames=2)
    except ValueError:
        return None
    cfg, sim = ds.simulation
    noise = [
        np.asarray(push.force.force_N, float)[sp.engaged] - engaged_forces(sp, cfg)
        for push, sp in zip(ds.pushes, sim, strict=True)
    ]
    e = np.concatenate(noise) / case["sigma_force_N"]
    n = e.size
    return len(case["heights_m"]), n, float((np.sum(e**2) - n) / np.sqrt(2.0 * n))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--replicates", type=int, default=120, help="seeds first-seed .. first-seed + replicates - 1")
    ap.add_argument("--step", type=int, default=1, help="every step-th seed (2 with --effects yield: its odd seeds)")
    ap.add_argument(
        "--effects",
        default=",".join(EFFECTS[1:]),
        help="the effect cycle after 'none', as sbc_geometry.py's --effects (it decides which seeds are "
        "forces only; contact_friction's cases are simulated like any other)",
    )
    args = ap.parse_args(argv)
    effects = (None, *[e for e in args.effects.split(",") if e])
    bad = [e for e in effects[1:] if e not in ALL_EFFECTS]
    if bad:
        ap.error(f"--effects: expected names among {', '.join(ALL_EFFECTS[1:])}, got {', '.join(bad)}")
    seeds = range(args.first_seed, args.first_seed + args.replicates, args.step)
    rows = [r for r in (noise_draw(s, effects) for s in seeds) if r is not None]
    if not rows:
        raise SystemExit("no seed could be simulated")
    heights, n, u = (np.array(c, float) for c in zip(*rows, strict=True))

    def line(sel, label):
        k = int(sel.sum())
        if k:
            se = u[sel].std(ddof=1) / np.sqrt(k) if k > 1 else float("nan")
            print(f"{label}: {k} seeds, median {np.median(n[sel]):.0f} samples, u {u[sel].mean():+.3f} +- {se:.3f}")

    print(f"seeds {seeds.start}-{seeds.stop - 1} (step {args.step}), {len(rows)} simulated; u is 0 +- 1 per seed")
    line(np.ones(u.size, bool), "all")
    for h in (1, 2, 3):
        line(heights == h, f"{h} height(s)")


if __name__ == "__main__":
    main()

"""Fast (linearised) EIG against nested Monte Carlo on a real one-push posterior (docs/validation.md).

    python scripts/design_eig_check.py

Simulates the twig pushed once at h = 0.48 m (pushes stopped at 100 mm, sensor
range [0.05, 8] N), fits it on forces only (default prior), and prints both
estimators of the expected information gain for 18 candidate heights.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from bayesrod.api.calibration import fit_for_calibration
from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated
from bayesrod.inference.design import PushPlan, design_heights


def main() -> None:
    cfg = SimConfig.from_preset("twig", seed=1, heights_m=(0.48,), max_contact_displacement_m=0.10, n_frames_engaged=2)
    with tempfile.TemporaryDirectory() as tmp:
        write_simulated(cfg, simulate(cfg), Path(tmp))
        f = fit_for_calibration(tmp, "default", seed=0, use_shapes=False, target_ess=1000, n_rank=4000)
    samples = {k: f[k]["draws"] for k in f["names"]}
    print(f"posterior: EI0 90% {f['EI0']['q'][[0, 2]]}, p 90% {f['p']['q'][[0, 2]]}")
    plan = PushPlan(0.10, 60, (0.05, 8.0))
    hs = np.linspace(0.08, 0.76, 18)
    t0 = time.perf_counter()
    fast = design_heights(samples, cfg.length_m, hs, plan, method="gaussian", n_draws=800)
    t1 = time.perf_counter()
    ref = design_heights(samples, cfg.length_m, hs, plan, method="nmc", n_draws=400, n_inner=4000)
    t2 = time.perf_counter()
    print(f"time for {hs.size} heights: linearised {t1 - t0:.1f} s, nested MC {t2 - t1:.1f} s")
    print("| h [m] | feasible | EIG linearised [nats] | EIG nested MC [nats] (se) |")
    print("|---|---|---|---|")
    for a, b in zip(fast["candidates"], ref["candidates"], strict=True):
        print(
            f"| {a['height_m']:.2f} | {'yes' if a['feasible'] else 'no'} | {a['expected_information_gain_nats']:.2f} "
            f"| {b['expected_information_gain_nats']:.2f} ({b['eig_standard_error_nats']:.2f}) |"
        )
    a, b = fast["recommended_height_m"], ref["recommended_height_m"]
    print(f"recommended: linearised {a:.3f} m, nested MC {b:.3f} m")


if __name__ == "__main__":
    main()

"""From the bundled dataset to bands at a height never pushed, in Python only.

    python examples/quickstart.py [RUN_DIR]

Loads the bundled twig dataset (three heights, forces and centerlines), fits it,
prints the posterior table, the EI(s) and k_theta(h) bands and the force band at
an unseen height, then (only if RUN_DIR is given) saves the run and reloads it.
About 40 s.
"""

import sys

import numpy as np

import bayesrod

ds = bayesrod.load(bayesrod.DEMO_DATASET)
print(f"{ds.specimen}: {len(ds.pushes)} pushes at {ds.heights_m} m, L = {ds.length_m} m")
post = bayesrod.fit(ds, seed=0, progress=False)
print(post.summary()[["median", "q05", "q95", "r_hat", "ess_bulk"]])
print("ArviZ:", type(post.idata).__name__, list(post.idata.posterior.data_vars))

ei = post.ei_band(np.linspace(0, 0.7, 8))
print(f"EI(s) {ei.level:.0%} band [N m^2]:")
for s, lo, med, hi in zip(ei.x, ei.lower, ei.median, ei.upper, strict=True):
    print(f"  s = {s:.2f} m: {med:.3f} [{lo:.3f}, {hi:.3f}]")
kt = post.k_theta_band([0.45, 0.60])
print(f"k_theta(0.60 m) = {kt.median[1]:.3f} [{kt.lower[1]:.3f}, {kt.upper[1]:.3f}] N m/rad (never pushed)")
fb = post.predict_force(0.60, [0.02, 0.05, 0.10])
for d, lo, med, hi in zip(fb.x, fb.lower, fb.median, fb.upper, strict=True):
    print(f"  h = 0.60 m, D = {d:.2f} m: F = {med:.3f} [{lo:.3f}, {hi:.3f}] N")

if len(sys.argv) > 1:
    post.save(sys.argv[1], overwrite=True)
    again = bayesrod.Posterior.load(sys.argv[1])
    same = np.array_equal(again.k_theta_band([0.6]).median, post.k_theta_band([0.6]).median)
    print(f"saved to {sys.argv[1]} and reloaded: identical numbers: {same}")

"""Fit forces you already hold in memory (a table from your rig), no files needed.

    python examples/fit_from_arrays.py

Here the 'measurements' come from the forward model of a stem (EI0 = 1.8 N m^2,
p = 0.5, L = 0.9 m) pushed at two heights, with 0.03 N of noise. With your own
data, pass your arrays (metres, newtons) or a DataFrame to Dataset.from_frame.
About 15 s.
"""

import numpy as np

import bayesrod

rng = np.random.default_rng(1)
L, heights = 0.9, [0.5, 0.7]
D = [np.linspace(0.0, 0.12, 40), np.linspace(0.0, 0.2, 40)]
F = [
    bayesrod.force_from_displacement(d, h, 1.8, 0.5, L).force_N + rng.normal(0, 0.03, d.size)
    for d, h in zip(D, heights, strict=True)
]
ds = bayesrod.Dataset.from_arrays(length_m=L, height_m=heights, displacement_m=D, force_N=F, specimen="my-stem")
problems = ds.validate()
print("problems:", problems or "none")
post = bayesrod.fit(ds, seed=1, progress=False, target_ess=400)
print(post.summary()[["median", "q05", "q95"]])
print("truth: EI0 = 1.8, p = 0.5, sigma_force_N = 0.03")

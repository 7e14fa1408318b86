"""Predict the force a stem exerts when pushed at a height never pushed.

    python examples/predict_new_height.py

First with the seed paper's published twig parameters (one rod: numbers), then
over a posterior (a fit of simulated forces: 90% bands), with the
small-deflection stiffnesses k_theta and k_x of eqs. (kdist) and (kx).
About 15 s.
"""

import numpy as np

import bayesrod

D = np.linspace(0.0, 0.40, 5)  # contact displacement since first contact [m]
one = bayesrod.predict(0.60, D, preset="twig").to_dict()
print(f"twig, h = 0.60 m: k_theta = {one['k_theta_Nm_per_rad']:.3f} N m/rad, k_x = {one['k_x_N_per_m']:.2f} N/m")
for pt in one["points"]:
    state = "slipped past the sensor" if pt["slipped"] else f"F = {pt['force_N']:.3f} N"
    print(f"  D = {pt['displacement_m']:.2f} m: {state}")

ds = bayesrod.simulate("twig", seed=5, heights_m=[0.45, 0.65], config_overrides={"n_frames_engaged": 2})
post = bayesrod.fit(ds, use_shapes=False, progress=False, target_ess=300)
band = post.predict_force(0.60, D)
for d, lo, med, hi, ps in zip(band.x, band.lower, band.median, band.upper, band.slip_probability, strict=True):
    print(f"  posterior, D = {d:.2f} m: F = {med:.3f} [{lo:.3f}, {hi:.3f}] N, P(slipped) = {ps:.2f}")

"""Predict the force a stem exerts when pushed at a height never pushed.

    python examples/predict_new_height.py

Uses the forward model with the seed paper's published twig parameters, then
the small-deflection stiffnesses k_theta and k_x of eqs. (kdist) and (kx).
"""

import numpy as np

from bayesrod import PRESETS, force_from_displacement, k_theta, k_x

twig = PRESETS["twig"]
L, EI0, p = twig["length_m"], twig["EI0"], twig["p"]
h = 0.60  # m, between the published 0.55 and 0.65 m
D = np.linspace(0.0, 0.40, 9)  # contact displacement since first contact [m]
sol = force_from_displacement(D, h, EI0, p, L)
print(f"twig, h = {h} m: k_theta = {k_theta(h, EI0, p, L):.3f} N m/rad, k_x = {k_x(h, EI0, p, L):.2f} N/m")
for d, f, s_c, slipped in zip(D, sol.force_N, sol.contact_s_m, sol.slipped, strict=True):
    state = "slipped past the sensor" if slipped else f"F = {f:.3f} N, contact at s = {s_c:.3f} m"
    print(f"  D = {d:.3f} m: {state}")

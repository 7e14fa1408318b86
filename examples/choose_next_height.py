"""Choose where to push next: fit one push, rank candidate heights, push there, refit.

    python examples/choose_next_height.py

The 'experiment' is the simulator (the twig preset, pushed up to 10 cm); each
round fits forces only, asks bayesrod.design for the height with the largest
expected information gain that the sensor can measure, and pushes there.
About a minute.
"""

import numpy as np

import bayesrod

heights = [0.44]
for rnd in range(2):
    ds = bayesrod.simulate(
        "twig", seed=4, heights_m=heights, config_overrides={"max_contact_displacement_m": 0.10, "n_frames_engaged": 2}
    )
    post = bayesrod.fit(ds, use_shapes=False, progress=False, target_ess=400)
    q = post.summary().loc["p"]
    print(f"round {rnd}: heights {heights} -> p = {q['median']:.3f} [{q['q05']:.3f}, {q['q95']:.3f}] (truth 0.43)")
    d = bayesrod.design(post, np.linspace(0.2, 0.75, 6), progress=False)
    if d.recommended_height_m is None:
        print("no feasible height left")
        break
    print(f"  next push at {d.recommended_height_m:.3f} m")
    heights.append(round(d.recommended_height_m, 4))

"""Compare two species: fit 2 + 2 simulated specimens (stand-ins for yours), then a hierarchical contrast.

    python examples/compare_species.py

Each species is the grass preset with its own EI0 (one 1.5x stiffer) and a
between-specimen spread; fits are forces only. With real data, load one
dataset per specimen with ``species`` set in specimen.json (or use
``bayesrod.fit_many`` on a folder). About a minute.
"""

import numpy as np

import bayesrod

rng = np.random.default_rng(1)
posts = {}
for species, EI0 in (("meadow", 0.112), ("verge", 0.168)):
    posts[species] = []
    for j in range(2):
        stem = {
            "EI0": EI0 * np.exp(rng.normal(0, 0.2)),
            "p": 1.6,
            "length_m": 0.47,
            "heights_m": [0.09, 0.11, 0.14],
            "species": species,
            "specimen": f"{species}-{j}",
        }
        ds = bayesrod.simulate(stem, seed=10 * j + len(species), config_overrides={"n_frames_engaged": 2})
        posts[species].append(bayesrod.fit(ds, prior="grass", use_shapes=False, progress=False, target_ess=400))
res = bayesrod.compare(posts, height_m=0.1)
for c in res.contrasts:
    print(
        f"{c['parameter']:>8} {c['a']}/{c['b']}: {c['ratio_median']:.3g} [{c['ratio_q05']:.3g}, {c['ratio_q95']:.3g}]"
        f"  P({c['a']} greater) = {c['prob_a_greater']:.2f}"
    )

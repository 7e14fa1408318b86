"""Noise-free brace-root series: how far is the group likelihood's MAP from the truth? (issue 23: table bias)

    python scripts/group_table_bias.py 7 4 6 0

Each argument is a replicate of scripts/group_study.py (the same stem and cuts: EI0, p and the three
compliances drawn from seed 1000 + rep), simulated without noise at 0.45 and 0.65 m; the MAP of the
joint likelihood (``start_point``: grid start, then L-BFGS-B) against the truth. The shared EI0's
posterior sd in that study is about 0.25%, so a MAP off by much less than that rules the tables out
as the cause of the study's misses.
"""

import sys
import time

from group_study import stem

import bayesrod
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference.group import GroupLikelihood, GroupPosterior, start_point
from bayesrod.inference.priors import load_prior

for rep in [int(a) for a in sys.argv[1:]]:
    EI0, p, conds, _ = stem(rep)  # scripts/group_study.py's replicate
    over = {"n_frames_engaged": 2, "EI0": EI0, "p": p, "noise": NoiseModel.none()}
    dss = bayesrod.simulate_group("twig", conditions=conds, seed=rep, heights_m=[0.45, 0.65], config_overrides=over)
    t = time.time()
    post = GroupPosterior(GroupLikelihood({x.extra["condition"]: x for x in dss}, load_prior("woody")))
    nat = post.to_natural(start_point(post))
    e, q = float(nat["EI0"][0]), float(nat["p"][0])
    print(
        f"rep {rep}: truth EI0 {EI0:.4f} p {p:.4f}; MAP EI0 {e:.4f} ({100 * (e / EI0 - 1):+.3f}%) p {q:.4f}; "
        f"{time.time() - t:.0f} s",
        flush=True,
    )

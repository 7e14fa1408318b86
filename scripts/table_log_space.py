"""The table likelihood's MLE shift with the force table read linearly and in log space, from one build per case.

    python scripts/table_log_space.py [--only contact_friction] [--shapes] [--workers 2]

Each case is scripts/table_accuracy.py's noise-free twig (three heights, exact forces; the effect on at the
given value). The likelihood is built once; its MLE shift from the truth in Laplace sds (as
:func:`bayesrod.api.calibration.table_shift_on` computes it) is found with the force table read linearly and
in log space (``FORCE_LOG_FLOOR``; not possible where the table holds a negative force). As shipped only a
friction axis is read in log space (``LOG_FORCE_EFFECTS``). About 1-5 min per case; 49 min for
contact_friction on its 49 nodes (27 min with 25; both beside another job). docs/validation.md, sessions 46-47.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from table_accuracy import CASES  # the same cases (scripts/ is on the path of a script run from it)

from bayesrod.api._common import as_dataset
from bayesrod.api.calibration import mle_shift
from bayesrod.api.data import simulate
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference import likelihood as LK
from bayesrod.inference.priors import load_prior


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma list of case names")
    ap.add_argument("--shapes", action="store_true", help="forces and centerlines (default: forces only)")
    ap.add_argument("--workers", type=int, default=1, help="processes building the tables (the same tables)")
    a = ap.parse_args(argv)
    only = {c for c in a.only.split(",") if c}
    for name, effect, value in CASES:
        if only and name not in only:
            continue
        t = time.perf_counter()
        effects = {effect: value} if effect else {}
        ds = simulate("twig", seed=1, noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0), effects=effects)
        truth = {"EI0": ds.extra["truth"]["EI0"], "p": ds.extra["truth"]["p"], **effects}
        with LK.table_workers(a.workers, progress=True):
            lik = LK.build_likelihood(
                as_dataset(ds), load_prior("woody"), (effect,) if effect else (), use_shapes=a.shapes
            )
        shipped = "linear" if LK.force_log_table(lik.f_table, lik.axis) is None else "log space"
        lik._force_log_table()  # fill the cache, keyed to this table, then set it by hand: read linearly
        lik._f_log = None
        lin = mle_shift(lik, truth)["shift_in_sd"]
        log = None
        if lik.f_table.min() >= 0.0:  # read in log space, whatever the axis
            lik._f_log = np.log(lik.f_table + LK.FORCE_LOG_FLOOR)
            log = mle_shift(lik, truth)["shift_in_sd"]
        print(
            f"{name} ({'forces + shapes' if a.shapes else 'forces'}): shift [sd] of log EI0, p"
            f"{', ' + effect if effect else ''}: linear {np.round(lin, 3).tolist()}, log space "
            f"{'- (a negative force)' if log is None else np.round(log, 3).tolist()}; as shipped: {shipped}; "
            f"{time.perf_counter() - t:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()

"""The table likelihood's MLE shift with the force table read linearly and in log space, from one build per case.

    python scripts/table_log_space.py [--only contact_friction] [--shapes]

Each case is scripts/table_accuracy.py's noise-free twig (three heights, exact forces; the effect on at the
given value). The likelihood is built once; its MLE shift from the truth in Laplace sds (as
:func:`bayesrod.api.calibration.table_shift_on` computes it) is found with the force table read linearly and
in log space (``FORCE_LOG_FLOOR``; not possible where the table holds a negative force). As shipped only a
friction axis is read in log space (``LOG_FORCE_EFFECTS``). About 1-5 min per case; 25 min for
contact_friction (its tables). docs/validation.md, session 46.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bayesrod.api._common import as_dataset
from bayesrod.api.calibration import TABLE_STUDY_NOISE
from bayesrod.api.data import simulate
from bayesrod.dataset.simulate import NoiseModel
from bayesrod.inference import likelihood as LK
from bayesrod.inference.priors import load_prior

CASES = [
    ("plain", None, 0.0),
    ("base_compliance", "base_compliance", 20.0),
    ("rest_curvature", "rest_curvature", 0.3),
    ("base_tilt", "base_tilt", 0.05),
    ("contact_friction", "contact_friction", 0.3),
]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma list of case names")
    ap.add_argument("--shapes", action="store_true", help="forces and centerlines (default: forces only)")
    a = ap.parse_args(argv)
    only = {c for c in a.only.split(",") if c}
    for name, effect, value in CASES:
        if only and name not in only:
            continue
        t = time.perf_counter()
        effects = {effect: value} if effect else {}
        ds = simulate("twig", seed=1, noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0), effects=effects)
        truth = {"EI0": ds.extra["truth"]["EI0"], "p": ds.extra["truth"]["p"], **effects}
        lik = LK.build_likelihood(as_dataset(ds), load_prior("woody"), (effect,) if effect else (), use_shapes=a.shapes)
        lik._force_log_table()
        shipped = "log space" if lik._f_log is not None else "linear"
        lik._f_log = None  # the cache stays keyed to this table: read linearly
        lin = _shift_on_built(lik, truth)
        log = None
        if lik.f_table.min() >= 0.0:  # read in log space, whatever the axis
            lik._f_log = np.log(lik.f_table + LK.FORCE_LOG_FLOOR)
            log = _shift_on_built(lik, truth)
        print(
            f"{name} ({'forces + shapes' if a.shapes else 'forces'}): shift [sd] of log EI0, p"
            f"{', ' + effect if effect else ''}: linear {np.round(lin, 3).tolist()}, log space "
            f"{'- (a negative force)' if log is None else np.round(log, 3).tolist()}; as shipped: {shipped}; "
            f"{time.perf_counter() - t:.0f} s",
            flush=True,
        )


def _shift_on_built(lik, truth: dict) -> np.ndarray:
    """table_shift_on's shift, on an already built likelihood."""
    from scipy.optimize import minimize

    from bayesrod.api.calibration import _hessian

    effect = next((k for k in truth if k not in ("EI0", "p")), None)
    value = float(truth[effect]) if effect else 0.0
    fixed = {"sigma_force_N": TABLE_STUDY_NOISE[0], "sigma_shape_m": TABLE_STUDY_NOISE[1], "shape_sd_scale": 1.0}

    def loglik(x) -> float:
        params = {"EI0": np.exp(x[:1]), "p": x[1:2], **{k: np.array([v]) for k, v in fixed.items()}}
        if effect:
            params[effect] = x[2:3]
        return float(lik.log_likelihood(params)[0]) if lik.in_table(params)[0] else -np.inf

    x0 = np.array([np.log(truth["EI0"]), truth["p"]] + ([value] if effect else []))
    res = minimize(lambda x: -loglik(x), x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-10})
    step = np.array([1e-4, 1e-4] + ([1e-4 * max(abs(value), 1.0)] if effect else []))
    sd = np.sqrt(np.diag(np.linalg.inv(-_hessian(loglik, res.x, step))))
    return (res.x - x0) / sd


if __name__ == "__main__":
    main()

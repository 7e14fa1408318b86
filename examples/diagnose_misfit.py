"""Find what the model misses: a stem whose base is not a perfect clamp.

    python examples/diagnose_misfit.py

The simulated twig sits on a rotational base spring (40 N m/rad) that nobody
declared; bayesrod.diagnose finds the residual structure, attributes it, adds
the effect and reports the error before and after. About a minute.
"""

import bayesrod

ds = bayesrod.simulate("twig", seed=2, effects={"base_compliance": 40.0}, config_overrides={"n_frames_engaged": 2})
res = bayesrod.diagnose(ds, use_shapes=False, candidates=("base_compliance", "force_offset", "rest_curvature"))
doc = res.to_dict()
print("added effects:", ", ".join(res.added_effects) or "none", "| fitted:", doc["fitted"])
for k in ("force_rmse_N", "heldout_force_rmse_N"):
    print(f"  {k}: {doc['before'][k]:.4g} -> {doc['after'][k]:.4g}")
print("unexplained structure left:", res.unexplained_structure)

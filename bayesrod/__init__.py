"""bayesrod: how stiff is this plant stem, and how sure are we?

The public API (docs/api.md); everything else may change between versions::

    import bayesrod
    ds = bayesrod.load("my-stem")                 # or bayesrod.simulate("twig"), Dataset.from_arrays(...)
    post = bayesrod.fit(ds)                       # an immutable Posterior
    post.summary(); post.ei_band(s); post.k_theta_band(h); post.predict_force(h, D)
    post.save("run")                              # only save()/report() write files

Layers (each imports only those before it): physics -> dataset, vision -> inference
-> report -> api -> cli.
"""

from ._version import __version__
from .api import (
    DEMO_DATASET,
    Band,
    Comparison,
    Design,
    Diagnosis,
    Extraction,
    ForceBand,
    GroupFit,
    GroupStudy,
    Posterior,
    Prediction,
    SimulatedDataset,
    Survey,
    compare,
    design,
    diagnose,
    extract,
    fit,
    fit_group,
    fit_groups,
    fit_many,
    import_table,
    load,
    predict,
    simulate,
    simulate_group,
)
from .dataset import Dataset, DatasetError, Problem
from .physics import Effects, contact_from_force, flexural_rigidity, force_from_displacement, k_theta, k_x
from .physics.presets import PRESETS

__all__ = [
    "DEMO_DATASET",
    "PRESETS",
    "Band",
    "Comparison",
    "Dataset",
    "DatasetError",
    "Design",
    "Diagnosis",
    "Effects",
    "Extraction",
    "ForceBand",
    "GroupFit",
    "GroupStudy",
    "Posterior",
    "Prediction",
    "Problem",
    "SimulatedDataset",
    "Survey",
    "__version__",
    "compare",
    "contact_from_force",
    "design",
    "diagnose",
    "extract",
    "fit",
    "fit_group",
    "fit_groups",
    "fit_many",
    "import_table",
    "flexural_rigidity",
    "force_from_displacement",
    "k_theta",
    "k_x",
    "load",
    "predict",
    "simulate",
    "simulate_group",
]

"""The public API: datasets in, posteriors and their bands out, designs, comparisons, diagnoses.

Every function here computes and returns an immutable result object; only the
objects' ``save()`` / ``report()`` write files. See docs/api.md.
"""

from .bands import Band, ForceBand
from .compare import Comparison, compare
from .data import DEMO_DATASET, SimulatedDataset, import_table, load, simulate, simulate_group
from .design import Design, design
from .diagnose import Diagnosis, diagnose
from .extract import Extraction, extract
from .fitting import Posterior, fit
from .group import GroupFit, GroupStudy, fit_group, fit_groups
from .predict import Prediction, predict
from .survey import Survey, fit_many

__all__ = [
    "DEMO_DATASET",
    "Band",
    "Comparison",
    "Design",
    "Diagnosis",
    "Extraction",
    "ForceBand",
    "GroupFit",
    "GroupStudy",
    "Posterior",
    "Prediction",
    "SimulatedDataset",
    "Survey",
    "compare",
    "design",
    "diagnose",
    "extract",
    "fit",
    "fit_group",
    "fit_groups",
    "fit_many",
    "import_table",
    "load",
    "predict",
    "simulate",
    "simulate_group",
]

"""Datasets (docs/format.md, section 1): typed observations, reader/validator, engagement."""

from .engagement import Engagement, detect_engagement
from .model import FORMAT, Camera, Dataset, ForceSeries, FrameRecord, Push, Sensor, ShapeFrame, Specimen
from .reader import DatasetError, Problem, read_dataset, validate_dataset, validate_in_memory

__all__ = [
    "FORMAT",
    "Camera",
    "Dataset",
    "DatasetError",
    "Engagement",
    "ForceSeries",
    "FrameRecord",
    "Problem",
    "Push",
    "Sensor",
    "ShapeFrame",
    "Specimen",
    "detect_engagement",
    "read_dataset",
    "validate_dataset",
    "validate_in_memory",
]

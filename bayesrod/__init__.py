"""bayesrod: how stiff is this plant stem, and how sure are we?

Public API (everything else may change):
"""

from .physics import (
    Effects,
    contact_from_force,
    flexural_rigidity,
    force_from_displacement,
    k_theta,
    k_x,
)
from .presets import PRESETS

__version__ = "0.1.0"

__all__ = [
    "Effects",
    "PRESETS",
    "contact_from_force",
    "flexural_rigidity",
    "force_from_displacement",
    "k_theta",
    "k_x",
    "__version__",
]

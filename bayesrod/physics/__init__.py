"""Pure physics: arrays in, arrays out. Never imports I/O, plotting, emcee or the CLI."""

from .effects import EFFECT_NAMES, Effects
from .elastica import (
    ContactSolution,
    ForceSolution,
    contact_from_force,
    contact_from_force_nd,
    force_from_displacement,
    force_from_displacement_nd,
)
from .lumped import flexural_rigidity, k_theta, k_x, ktheta_nd, kx_nd, stem_diameter

__all__ = [
    "EFFECT_NAMES",
    "Effects",
    "ContactSolution",
    "ForceSolution",
    "contact_from_force",
    "contact_from_force_nd",
    "force_from_displacement",
    "force_from_displacement_nd",
    "flexural_rigidity",
    "stem_diameter",
    "k_theta",
    "k_x",
    "ktheta_nd",
    "kx_nd",
]

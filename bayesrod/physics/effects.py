"""Model effects beyond the seed paper's clamped, straight, frictionless rod.

Each effect has the name docs/format.md gives it. Values are SI; an effect that is
absent takes its neutral value (the seed model). The forward solver works with
the nondimensional groups returned by :meth:`Effects.nondim`.

| name               | unit    | meaning (push frame: x positive in the push direction)            |
|--------------------|---------|--------------------------------------------------------------------|
| ``base_compliance``| N m/rad | stiffness k_b of a rotational spring at the base; inf = clamped     |
| ``rest_curvature`` | 1/m     | uniform natural curvature kappa0 (M = EI (theta' - kappa0))        |
| ``base_tilt``      | rad     | angle of the unloaded base tangent from vertical                   |
| ``contact_friction``| 1      | vertical traction mu*F at the contact, along the stem's slide     |
| ``force_offset``   | N       | sensor bias: measured force = true force + offset                  |
| ``self_weight``    | N/m     | weight per length at the base, tapering as (1 - s/L)^(2p)          |
| ``yield``          | N m     | base yield moment: elastic-perfectly-plastic base hinge            |
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

EFFECT_NAMES: tuple[str, ...] = (
    "base_compliance",
    "rest_curvature",
    "base_tilt",
    "contact_friction",
    "force_offset",
    "self_weight",
    "yield",
)

# Python attribute for each contract name ("yield" is a keyword).
_ATTR = {name: ("yield_moment" if name == "yield" else name) for name in EFFECT_NAMES}

EFFECT_UNITS: dict[str, str] = {
    "base_compliance": "N m/rad",
    "rest_curvature": "1/m",
    "base_tilt": "rad",
    "contact_friction": "1",
    "force_offset": "N",
    "self_weight": "N/m",
    "yield": "N m",
}


@dataclass(frozen=True)
class Effects:
    """Switchable effects of the forward model (all SI; defaults are neutral).

    Parameters
    ----------
    base_compliance : float
        Rotational base-spring stiffness k_b [N m/rad]; ``inf`` is a clamp (A6).
    rest_curvature : float
        Uniform rest curvature kappa0 [1/m], positive toward +x.
    base_tilt : float
        Unloaded base tangent angle from vertical [rad], positive toward +x.
    contact_friction : float
        Coefficient mu: the contact also applies an upward force mu*F.
    force_offset : float
        Additive sensor bias [N] on the measured force.
    self_weight : float
        Weight per unit length at the base w0 [N/m]; w(s) = w0 (1-s/L)^(2p).
    yield_moment : float
        Base yield moment M_y [N m]; ``inf`` means no yield.
    """

    base_compliance: float = math.inf
    rest_curvature: float = 0.0
    base_tilt: float = 0.0
    contact_friction: float = 0.0
    force_offset: float = 0.0
    self_weight: float = 0.0
    yield_moment: float = math.inf

    def __post_init__(self) -> None:
        for fld in fields(self):
            value = getattr(self, fld.name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise TypeError(f"effect {fld.name}: expected a number, got {value!r}")
            if math.isnan(float(value)):
                raise ValueError(f"effect {fld.name}: expected a number, got NaN")
        if not self.base_compliance > 0:
            raise ValueError(f"effect base_compliance: expected a stiffness > 0 N m/rad, got {self.base_compliance}")
        if not self.yield_moment > 0:
            raise ValueError(f"effect yield: expected a moment > 0 N m, got {self.yield_moment}")
        if self.self_weight < 0:
            raise ValueError(f"effect self_weight: expected >= 0 N/m, got {self.self_weight}")
        if not -1.0 < self.contact_friction < 1.0:
            raise ValueError(f"effect contact_friction: expected a coefficient in (-1, 1), got {self.contact_friction}")
        if not abs(self.base_tilt) < math.pi / 4:
            raise ValueError(f"effect base_tilt: expected |tilt| < pi/4 rad, got {self.base_tilt}")

    @classmethod
    def from_mapping(cls, values: dict[str, Any] | None) -> Effects:
        """Build from ``{contract_name: value}``; unknown names raise ValueError."""
        values = dict(values or {})
        unknown = sorted(set(values) - set(EFFECT_NAMES))
        if unknown:
            raise ValueError(f"effect name: expected one of {', '.join(EFFECT_NAMES)}, got {', '.join(unknown)}")
        kwargs = {}
        for name, value in values.items():
            try:
                kwargs[_ATTR[name]] = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"effect {name}: expected a number, got {value!r}") from None
        return cls(**kwargs)

    def to_mapping(self) -> dict[str, float]:
        """Non-neutral effects as ``{contract_name: value}``."""
        neutral = Effects()
        return {
            name: float(getattr(self, _ATTR[name]))
            for name in EFFECT_NAMES
            if getattr(self, _ATTR[name]) != getattr(neutral, _ATTR[name])
        }

    @property
    def active(self) -> tuple[str, ...]:
        """Contract names of the non-neutral effects."""
        return tuple(self.to_mapping())

    def nondim(self, length: float, EI0: Any) -> dict[str, np.ndarray]:
        """Nondimensional groups for the solver (arrays broadcast with ``EI0``).

        Returns keys ``c_base`` (= EI0/(k_b L)), ``kappa0`` (= kappa0 L),
        ``tilt``, ``mu``, ``f_offset`` (= offset L^2/EI0), ``w0`` (= w0 L^3/EI0)
        and ``m_yield`` (= M_y L/EI0).
        """
        EI0 = np.asarray(EI0, dtype=float)
        L = float(length)
        return {
            "c_base": EI0 / (self.base_compliance * L),
            "kappa0": np.full_like(EI0, self.rest_curvature * L),
            "tilt": np.full_like(EI0, self.base_tilt),
            "mu": np.full_like(EI0, self.contact_friction),
            "f_offset": self.force_offset * L**2 / EI0,
            "w0": self.self_weight * L**3 / EI0,
            "m_yield": self.yield_moment * L / EI0,
        }


def parse_effect_assignments(items: list[str] | None) -> Effects:
    """Parse CLI ``NAME=VALUE`` strings into :class:`Effects` (ValueError on bad input)."""
    values: dict[str, str] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise ValueError(f"effect: expected NAME=VALUE, got {item!r}")
        if name.strip() in values:
            raise ValueError(f"effect: effect {name.strip()!r} given twice")
        values[name.strip()] = value.strip()
    return Effects.from_mapping(values)

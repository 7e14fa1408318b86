"""Published specimen parameters of the seed paper (section IV-B), used as presets."""

from __future__ import annotations

from types import MappingProxyType

PRESETS = MappingProxyType(
    {
        "twig": MappingProxyType(
            {
                "specimen": "twig",
                "species": "woody twig (seed paper)",
                "length_m": 0.80,
                "EI0": 2.63,
                "p": 0.43,
                "heights_m": (0.45, 0.55, 0.65),
            }
        ),
        "grass": MappingProxyType(
            {
                "specimen": "grass",
                "species": "artificial grass (seed paper)",
                "length_m": 0.47,
                "EI0": 0.112,
                "p": 1.60,
                "heights_m": (0.09, 0.11, 0.14),
            }
        ),
    }
)


def get_preset(name: str) -> MappingProxyType:
    """Preset by name; ValueError listing the known names otherwise."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"preset: expected one of {', '.join(PRESETS)}, got {name!r}") from None

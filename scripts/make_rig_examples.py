"""Write the small synthetic rig tables of examples/rigs/ (docs/data.md, "Raw rig tables").

    python scripts/make_rig_examples.py [OUTDIR]

Three device types, each from the forward elastica of a known stem (the truth is
in examples/rigs/TRUTH.json) with sensor noise, written the way such devices
export (our own synthetic files, no vendor's):

- ``darling_arm.txt``: a rotating-arm gauge: a metadata block, tab-separated,
  time in ms, load in N, arm angle in degrees; three load/unload cycles; the
  recording starts with the stem already pressed (a preload).
- ``utm_instron.csv``: a universal testing machine: metadata lines, a header and
  a units row, comma-separated, time in s, extension in mm, load in kN; starts
  before contact (a few unloaded samples, a load-cell offset).
- ``handheld_gauge.csv``: a hand-held force gauge on a slide: semicolons and
  decimal commas, time in s, force in N, travel in cm; starts before contact.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import bayesrod

TRUTH = {"EI0": 1.8, "p": 0.5, "length_m": 0.9}


def force(D, h):
    sol = bayesrod.force_from_displacement(np.clip(D, 0, None), h, TRUTH["EI0"], TRUTH["p"], TRUTH["length_m"])
    return np.where(D > 0, sol.force_N, 0.0)


def darling(rng) -> str:
    h, arm = 0.5, 0.5  # contact height on the stem and the arm's pivot-to-probe length [m]
    D0 = 0.012  # already pressed 12 mm when the recording starts
    # three cycles: out to 60, 75, 90 mm of contact travel and back to the start
    legs = [np.linspace(0, a, 40) for a in (0.060, 0.075, 0.090)]
    path = np.concatenate([np.concatenate([leg, leg[::-1][1:]]) for leg in legs])
    angle = np.degrees(np.arcsin(path / arm)) + 3.0  # the arm starts at 3 degrees
    D = D0 + path
    F = force(D, h) + rng.normal(0, 0.02, D.size)
    t = np.arange(D.size) * 50.0  # ms
    lines = [
        "DARLING-style rotating arm (synthetic example, bayesrod)",
        "Site: test plot 3",
        "Stem: A-07",
        "Arm length [m]: 0.50",
        "Contact height [m]: 0.50",
        "",
        "Time [ms]\tLoad [N]\tArm angle [deg]",
    ]
    lines += [f"{a:.0f}\t{b:.4f}\t{c:.4f}" for a, b, c in zip(t, F, angle, strict=True)]
    return "\n".join(lines) + "\n"


def instron(rng) -> str:
    h = 0.6
    ext = np.linspace(0, 0.10, 401)  # m of crosshead travel (0.25 mm steps); contact at 8 mm
    D = ext - 0.008
    F = force(D, h) + 0.05 + rng.normal(0, 0.01, D.size)  # N; 0.05 N load-cell offset
    t = np.arange(D.size) * 0.25
    lines = [
        '"Test method: stem bending, synthetic"',
        '"Sample: B-12"',
        '"Date: 2026-06-01"',
        '"Time","Extension","Load"',
        '"(s)","(mm)","(kN)"',
    ]
    lines += [f"{a:.3f},{1000 * b:.4f},{c / 1000:.7f}" for a, b, c in zip(t, ext, F, strict=True)]
    return "\n".join(lines) + "\n"


def handheld(rng) -> str:
    h = 0.4
    travel = np.linspace(0, 0.05, 60)  # m; contact at 4 mm
    D = travel - 0.004
    F = force(D, h) + rng.normal(0, 0.03, D.size)
    t = np.arange(D.size) * 0.1
    lines = ["Zeit [s];Kraft [N];Weg [cm]"]
    lines += [f"{a:.2f};{b:.3f};{100 * c:.3f}".replace(".", ",") for a, b, c in zip(t, F, travel, strict=True)]
    return "\n".join(lines) + "\n"


def field_push(rng) -> str:
    """A field gauge pushed by hand at one height: recording starts pressed 8 mm (a preload), the base
    yields at 1.1 N m (the push softens: the force levels off), AR(1) noise (rho 0.9: hand tremor)."""
    from bayesrod.dataset.simulate import ar1_noise

    h, D0 = 0.45, 0.008
    travel = np.linspace(0, 0.11, 150)
    D = D0 + travel
    eff = bayesrod.physics.Effects(yield_moment=1.1)
    F = bayesrod.force_from_displacement(D, h, TRUTH["EI0"], TRUTH["p"], TRUTH["length_m"], eff).force_N
    F = F + ar1_noise(rng, 0.04, 0.9, D.size)
    t = np.arange(D.size) * 0.05
    lines = ["# field gauge export (synthetic example, bayesrod)", "t_s,force_N,travel_mm"]
    lines += [f"{a:.2f},{b:.4f},{1000 * c:.3f}" for a, b, c in zip(t, F, travel, strict=True)]
    return "\n".join(lines) + "\n"


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "examples" / "rigs")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(24)
    (out / "darling_arm.txt").write_text(darling(rng))
    (out / "utm_instron.csv").write_text(instron(rng))
    (out / "handheld_gauge.csv").write_text(handheld(rng))
    (out / "field_push.csv").write_text(field_push(np.random.default_rng(19)))
    heights = {"darling_arm.txt": 0.5, "utm_instron.csv": 0.6, "handheld_gauge.csv": 0.4, "field_push.csv": 0.45}
    truth = {
        **TRUTH,
        "heights_m": heights,
        "preload_displacement_m": {"darling_arm.txt": 0.012, "field_push.csv": 0.008},
        "effects": {"field_push.csv": {"yield": 1.1}},
        "force_noise_rho": {"field_push.csv": 0.9},
    }
    (out / "TRUTH.json").write_text(json.dumps(truth, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

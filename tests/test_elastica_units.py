"""The forward solver's input checks and defaults, each on a case made by hand (found by the session-40
mutation run of bayesrod/physics/elastica.py: docs/validation.md, "elastica.py, the first half whole")."""

import numpy as np
import pytest

import bayesrod
from bayesrod.physics import Effects
from bayesrod.physics.elastica import centerline_at, contact_from_force_nd, force_from_displacement_nd


@pytest.mark.parametrize(
    ("kw", "field", "got"),
    [
        # the first offending value is named, not a valid one and not two: 0 is refused for EI0, kept for p and D
        ({"EI0": [0.5, 0.0, -1.0]}, "EI0", r"got \[0\.\]"),
        ({"p": [0.5, 0.0, -0.2, -0.3]}, "p", r"got \[-0\.2\]"),
        ({"displacement_m": [0.5, 0.0, -0.01, -0.02]}, "displacement_m", r"got \[-0\.01\]"),
    ],
)
def test_a_refused_input_names_its_field_and_its_first_offending_value(kw, field, got):
    args = {"displacement_m": 0.01, "height_m": 0.5, "EI0": 2.6, "p": 0.4, "length_m": 1.0} | kw
    with pytest.raises(ValueError, match=rf"^{field}: expected .*{got}"):
        bayesrod.force_from_displacement(**args)


def test_a_height_the_rest_shape_never_reaches_is_refused_naming_that_height():
    """A rest curvature of 3 rad over the length curls the stem below 0.34 L: of the heights 0.2 L and 0.5 L
    the second is named (as h/L), and the error is a ValueError, not a crash of its own message."""
    eff = Effects(rest_curvature=3.0).nondim(1.0, 2.0)
    with pytest.raises(ValueError, match=r"^height_m: expected a height the unloaded stem reaches, got h/L = 0\.5 "):
        force_from_displacement_nd(np.array([0.01, 0.01]), np.array([0.2, 0.5]), 0.0, eff)
    assert contact_from_force_nd(np.array([0.0]), 0.2, 0.0, eff)["found"].all()  # 0.2 L is reached


def test_the_solvers_return_no_centerline_unless_asked():
    """keep_shape defaults to False: the grids (n + 1 nodes per solve) are built only when asked for."""
    assert "grid" not in contact_from_force_nd(np.array([0.5]), 0.5, 0.4)
    assert "grid" not in force_from_displacement_nd(np.array([0.05]), 0.5, 0.4)
    assert bayesrod.contact_from_force(1.0, 0.5, 2.6, 0.4, 1.0).shape_xz_m is None
    assert bayesrod.force_from_displacement(0.05, 0.5, 2.6, 0.4, 1.0).shape_xz_m is None
    assert "grid" in contact_from_force_nd(np.array([0.5]), 0.5, 0.4, keep_shape=True)


def test_centerline_at_clips_arc_lengths_to_the_stem():
    """Arc lengths below 0 read the base, above 1 the tip (not an extrapolation of the end segments)."""
    grid = contact_from_force_nd(np.array([1.0]), 0.5, 0.4, keep_shape=True)["grid"][..., 0]  # (n + 1, 3)
    got = centerline_at(grid, np.array([-0.2, 0.0, 1.0, 1.3]))
    np.testing.assert_allclose(got[..., 0], got[..., 1], atol=1e-15)
    np.testing.assert_allclose(got[..., 3], got[..., 2], atol=1e-15)
    np.testing.assert_allclose(got[..., 2], grid[-1, :2], atol=1e-12)

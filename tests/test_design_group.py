"""design from one condition of a stem's joint fit (issue 23): with one height pushed per condition, stem
and anchorage are confounded, and design recommends the second height that separates them.

The GroupFit is made from known draws on the confounding ridge (as ``test_design.py``'s ridge test, but
reached through a saved fit-group stem and the CLI): each draw's base compliance gives the pushed height
(0.5 m) the same small-deflection stiffness, EI0 from 2 to 5 N m^2.
"""

import json
from types import MappingProxyType

import numpy as np
import pytest

import bayesrod
from bayesrod.api.group import GroupFit
from bayesrod.cli import main
from bayesrod.physics import force_from_displacement

L, H1, P = 0.8, 0.5, 0.43


def _ridge_stem(n=2000) -> GroupFit:
    d = 1e-4
    per_unit_EI0 = force_from_displacement(np.array([d]), H1, 1.0, P, L).force_N[0] / d
    total = 1 / (2.63 * per_unit_EI0) + H1**2 / 8.0  # the cut condition: rod in series with an 8 N m/rad spring
    rng = np.random.default_rng(1)
    EI0 = np.exp(rng.uniform(np.log(2.0), np.log(5.0), n))
    samples = {
        "EI0": EI0,
        "p": P + 0.005 * rng.standard_normal(n),
        # compliance [rad/(N m)] = 1 / k_b: each draw's base takes up what its stem does not
        "base_compliance_rad_per_Nm__cut": (total - 1 / (EI0 * per_unit_EI0)) / H1**2,
        "base_compliance_rad_per_Nm__intact": np.zeros(n),  # a clamp
        "sigma_force_N__cut": np.full(n, 0.03),
        "sigma_force_N__intact": np.full(n, 0.03),
    }
    conds = {c: {"k_theta": [{"height_m": H1}]} for c in ("intact", "cut")}
    doc = {"stem_id": "s1", "conditions_order": ["intact", "cut"], "conditions": conds, "length_m": L}
    return GroupFit("s1", ("intact", "cut"), MappingProxyType(samples), MappingProxyType(doc))


def test_design_of_a_condition_separates_stem_from_base(tmp_path, capsys):
    stem = _ridge_stem()
    stem.save(tmp_path / "run" / "s1")
    args = ["design", str(tmp_path / "run" / "s1"), "--out", str(tmp_path / "d"), "--condition", "cut"]
    args += ["--candidates", "0.3:0.7:3", "--displacement", "0.04", "--samples", "30", "--quiet"]
    assert main(args) == 0
    doc = json.loads((tmp_path / "d" / "design.json").read_text())
    eig = {c["height_m"]: c["expected_information_gain_nats"] for c in doc["candidates"]}
    assert doc["parameters"] == ["log_EI0", "p", "base_compliance_coordinate"]
    assert doc["source"] == "s1/cut" and doc["pushed_heights_m"] == [H1]
    # the pushed height teaches almost nothing more; 0.3 m separates them (the ridge test's 0.014 vs 2.50)
    assert eig[0.5] < 0.2 and eig[0.3] > 1.5
    assert doc["recommended_height_m"] == 0.3
    assert "recommended next height: 0.300 m" in capsys.readouterr().out


def test_design_of_a_group_needs_a_known_condition(tmp_path, capsys):
    stem = _ridge_stem(n=200)
    with pytest.raises(ValueError, match="condition: expected one of intact, cut .*got none"):
        bayesrod.design(stem, displacement_m=0.04)
    with pytest.raises(ValueError, match="condition: expected one of intact, cut, got 'wet'"):
        bayesrod.design(stem, condition="wet", displacement_m=0.04)
    stem.save(tmp_path / "s1")
    assert main(["design", str(tmp_path / "s1"), "--out", str(tmp_path / "d"), "--displacement", "0.04"]) == 2
    err = capsys.readouterr().err
    assert "condition: expected one of intact, cut" in err and "Traceback" not in err


def test_a_conditions_draws_are_its_own_with_a_clamp_as_an_infinitely_stiff_spring():
    """design of one condition takes the stem's shared draws and that condition's own noise and base: the base
    spring is 1/compliance, and a zero compliance (an intact clamp) an infinitely stiff spring, not none."""
    from bayesrod.api.design import _group_draws

    stem = _ridge_stem(n=200)
    S = dict(stem.samples) | {"sigma_force_N__intact": np.full(200, 0.05)}  # the conditions' noise differs
    stem = GroupFit("s1", stem.conditions, MappingProxyType(S), stem.doc)
    for cond, sigma in (("cut", 0.03), ("intact", 0.05)):
        samples, length, pushed, plan, source = _group_draws(stem, cond)
        np.testing.assert_array_equal(samples["EI0"], S["EI0"])
        np.testing.assert_array_equal(samples["p"], S["p"])
        np.testing.assert_array_equal(samples["sigma_force_N"], np.full(200, sigma))
        assert (length, pushed, plan, source) == (L, [H1], {}, f"s1/{cond}")
    k_b = _group_draws(stem, "cut")[0]["base_compliance"]
    np.testing.assert_allclose(k_b, 1.0 / S["base_compliance_rad_per_Nm__cut"], rtol=1e-12)
    assert np.all(np.isposinf(_group_draws(stem, "intact")[0]["base_compliance"]))

"""compare over stems fitted under several conditions (issue 23): genotypes contrasted on the shared stem
parameters and, per condition, on the anchorage.

The stems are GroupFit objects made from known draws (no sampling of the rod), so the truth is set here:
two genotypes, three stems each, the same stem (EI0 2.6 N m^2, p 0.43) and the same intact base, and a
base that genotype B loses far more of when its roots are cut (compliance 0.08 against 0.03 rad/(N m)).
"""

import json
from types import MappingProxyType

import numpy as np
import pytest

import bayesrod
from bayesrod.api.group import GroupFit, GroupStudy
from bayesrod.cli import main

TRUE_CUT = {"A": 0.03, "B": 0.08}


def _stem(sid, species, rng, n=2000, shared=("EI0", "p")):
    EI0 = 2.6 * np.exp(0.08 * rng.standard_normal())  # stem-to-stem spread
    cut = TRUE_CUT[species] + 0.005 * rng.standard_normal()
    intact = 0.01 + 0.002 * rng.standard_normal()
    samples = {
        "EI0": EI0 * np.exp(0.03 * rng.standard_normal(n)),
        "p": 0.43 + 0.01 * rng.standard_normal(n),
        "base_compliance_rad_per_Nm__intact": np.abs(intact + 0.003 * rng.standard_normal(n)),
        "base_compliance_rad_per_Nm__cut": cut + 0.005 * rng.standard_normal(n),
    }
    doc = {
        "stem_id": sid,
        "conditions_order": ["intact", "cut"],
        "shared": {k: {"median": float(np.median(samples[k]))} for k in shared},
        "species": species,
        "length_m": 0.8,
    }
    return GroupFit(sid, ("intact", "cut"), MappingProxyType(samples), MappingProxyType(doc))


@pytest.fixture(scope="module")
def stems():
    rng = np.random.default_rng(3)
    return [_stem(f"{g}{k}", g, rng) for g in "AB" for k in range(3)]


def test_a_stem_without_shared_parameters_or_species_is_refused(stems):
    rng = np.random.default_rng(0)
    own_p = _stem("C0", "A", rng, shared=("EI0",))
    with pytest.raises(ValueError, match="stem C0: field shared: expected EI0 and p shared .* got p fitted"):
        bayesrod.compare([*stems, own_p])
    no_species = _stem("C1", "A", rng)
    doc = dict(no_species.doc, species=None)
    bare = GroupFit("C1", no_species.conditions, no_species.samples, MappingProxyType(doc))
    with pytest.raises(ValueError, match="stem C1: field species"):
        bayesrod.compare([*stems, bare])


def test_genotypes_differ_at_the_cut_base_not_in_the_stem(stems, tmp_path, capsys):
    """Through the CLI on a saved fit-group study (groups.json and one folder per stem standing for all its
    stems; one compare run serves every check, it samples three hierarchical models)."""
    GroupStudy(MappingProxyType({s.stem_id: s for s in stems}), ()).save(tmp_path / "groups")
    loaded = GroupFit.load(tmp_path / "groups" / "B1")
    assert loaded.species == "B" and loaded.conditions == ("intact", "cut")
    np.testing.assert_array_equal(loaded.samples["p"], stems[4].samples["p"])
    args = ["compare", str(tmp_path / "groups"), "--out", str(tmp_path / "cmp"), "--seed", "1", "--height", "0.4"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    res = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    c = res["anchorage"]["cut"]["contrasts"][0]  # the printout is compare.json's, median then q05, q95
    line = f"base compliance, cut: A - B = {c['difference_median']:.3g} [{c['difference_q05']:.3g}, "
    assert line + f"{c['difference_q95']:.3g}] rad/(N m) (90%), P(A softer base) = {c['prob_a_greater']:.3f}" in printed
    assert set(res["anchorage"]) == {"intact", "cut"}
    assert res["groups"] == {"A": ["A0", "A1", "A2"], "B": ["B0", "B1", "B2"]}
    ei0 = next(c for c in res["contrasts"] if c["parameter"] == "EI0")
    assert ei0["ratio_q05"] < 1 < ei0["ratio_q95"]  # the same stem
    kt = next(c for c in res["contrasts"] if c["parameter"] == "k_theta")  # at 0.4 m of the stems' 0.8 m length
    assert kt["height_m"] == 0.4 and kt["ratio_q05"] < 1 < kt["ratio_q95"], kt
    cut = res["anchorage"]["cut"]["contrasts"][0]
    assert (cut["a"], cut["b"], cut["condition"], cut["parameter"]) == ("A", "B", "cut", "base_compliance_rad_per_Nm")
    for cond in ("intact", "cut"):  # each condition's model says how well it converged
        conv = res["anchorage"][cond]["convergence"]
        assert set(conv) == {"rhat_max", "ess_bulk_min"} and conv["rhat_max"] < 1.05 and conv["ess_bulk_min"] > 400
    # B's cut base is softer: A - B = -0.05 rad/(N m), covered, and excluding zero
    assert cut["difference_q05"] < -0.05 < cut["difference_q95"] < 0
    assert cut["prob_a_greater"] < 0.01
    intact = res["anchorage"]["intact"]["contrasts"][0]
    assert intact["difference_q05"] < 0 < intact["difference_q95"]  # the intact bases agree
    for g, truth in TRUE_CUT.items():
        band = res["anchorage"]["cut"]["species"][g]["base_compliance_rad_per_Nm"]
        assert band["q05"] < truth < band["q95"]
        assert band["q95"] - band["q05"] < 0.03  # three stems of spread 0.005 pin the mean, not the prior
    # the stems' spread about their genotype's mean at the cut base: 0.005 rad/(N m) (not a genotype's mean)
    spread = res["anchorage"]["cut"]["between_stem_sd_rad_per_Nm"]
    assert spread["q05"] < 0.005 < spread["q95"] and spread["median"] < 0.015, spread


def test_fit_group_refuses_conditions_of_different_species():
    D = [np.linspace(0.0, 0.03, 20)]
    F = [30.0 * D[0]]
    kw = dict(length_m=0.8, height_m=[0.5], displacement_m=D, force_N=F)
    a = bayesrod.Dataset.from_arrays(species="A", **kw)
    b = bayesrod.Dataset.from_arrays(species="B", **kw)
    with pytest.raises(ValueError, match="species: expected one species for the conditions of stem s1, got intact"):
        bayesrod.fit_group({"intact": a, "cut": b}, stem_id="s1", progress=False)

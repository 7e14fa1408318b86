"""Species comparison: the hierarchical model finds real differences and not false ones."""

import json

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.inference.hierarchical import SpecimenPosterior, contrasts, sample_species

TAU = (0.3, 0.08)  # realistic between-specimen spread: EI0 +-35%, p +-0.08


def _species(rng, name, EI0, p, n, L=0.8, meas=(0.01, 0.005)):
    out = []
    for j in range(n):
        theta = np.array([np.log(EI0), p]) + rng.normal(0, TAU)
        m = theta + rng.normal(0, meas)
        out.append(SpecimenPosterior(f"{name}-{j}", name, L, m + rng.normal(0, meas, (1500, 2))))
    return out


def test_twofold_difference_is_found():
    rng = np.random.default_rng(0)
    sp = _species(rng, "stiff", 5.26, 0.43, 4) + _species(rng, "soft", 2.63, 0.43, 3, L=0.7)
    fit = sample_species(sp, seed=1)
    c = {x["parameter"]: x for x in contrasts(fit, sp, 0.4)}
    # species are sorted: "soft" is a, "stiff" is b
    assert c["EI0"]["ratio_q05"] <= 0.5 <= c["EI0"]["ratio_q95"] and c["EI0"]["ratio_q95"] < 1.0, c["EI0"]
    assert c["EI0"]["prob_a_greater"] < 0.05
    assert c["p"]["difference_q05"] <= 0 <= c["p"]["difference_q95"]
    assert "k_theta" in c and fit["rhat_max"] < 1.02
    # the sampler stops when converged, not before and not at its cap
    assert fit["rhat_max"] <= 1.01 and fit["ess_bulk_min"] >= 1000 and 1000 <= fit["n_steps"] < 3000
    assert fit["n_steps"] >= 50 * fit["autocorr_time_max"]


def _null_hits(n_rep):
    hits = 0
    for r in range(n_rep):
        rng = np.random.default_rng(100 + r)
        sp = _species(rng, "A", 2.63, 0.43, 4) + _species(rng, "B", 2.63, 0.43, 4)
        c = contrasts(sample_species(sp, seed=r, n_steps=1500), sp)[0]
        hits += c["ratio_q05"] <= 1.0 <= c["ratio_q95"]
    return hits


@pytest.mark.slow  # 50 s; the null check at 20 replications is slow too
def test_same_species_split_in_two_rarely_differs():
    """8 replications of two groups of 4 from one species: P(<= 5 of 8 | 90%) = 3.8%."""
    assert _null_hits(8) >= 6


@pytest.mark.slow
def test_same_species_split_in_two_rarely_differs_20_replications():
    """The issue's check: over 20 replications the 90% interval for the ratio contains 1 in >= 85%."""
    assert _null_hits(20) >= 17


def _fake_run(path, specimen, species, draws, L=0.8, d0=None):
    path.mkdir(parents=True)
    (path / "summary.json").write_text(json.dumps({"specimen": specimen, "species": species, "length_m": L}))
    extra = {} if d0 is None else {"d0_m": d0}
    np.savez(path / "samples.npz", length_m=L, EI0=np.exp(draws[:, 0]), p=draws[:, 1], **extra)


def test_modulus_model_finds_a_thickness_difference():
    """Two species of equal EI0 whose stems differ 1.2x in diameter: E differs by 1.2^4 = 2.07x. The log-E
    species model (compare's, with its prior and steps) finds that ratio and its direction."""
    from bayesrod.inference.hierarchical import PRIOR_LOG_E, modulus_contrasts

    rng = np.random.default_rng(4)
    sp = []
    for name, d0 in (("thick", 0.012), ("thin", 0.010)):
        for j in range(4):
            logE = np.log(64 * 2.6 / (np.pi * d0**4)) + rng.normal(0, 0.2)  # between-specimen spread
            sp.append(SpecimenPosterior(f"{name}-{j}", name, 0.8, (logE + rng.normal(0, 0.03, 1500))[:, None]))
    fit = sample_species(sp, seed=1, prior=PRIOR_LOG_E, n_steps=1500)
    (c,) = modulus_contrasts(fit)
    assert (c["a"], c["b"], c["parameter"]) == ("thick", "thin", "E")
    assert c["ratio_q05"] <= 1 / 1.2**4 <= c["ratio_q95"] and c["ratio_q95"] < 1.0, c
    assert c["prob_a_greater"] < 0.05 and fit["rhat_max"] < 1.02


def test_compare_takes_youngs_modulus_only_from_fits_that_all_have_diameters(tmp_path):
    import bayesrod
    from bayesrod.api.compare import _moduli

    rng = np.random.default_rng(4)
    draws = np.column_stack([np.log(2.6) + rng.normal(0, 0.01, 300), 0.43 + rng.normal(0, 0.005, 300)])
    _fake_run(tmp_path / "a", "a", "x", draws, d0=0.01 * np.exp(rng.normal(0, 0.005, 300)))
    _fake_run(tmp_path / "b", "b", "y", draws)
    fits = [(bayesrod.Posterior.load(tmp_path / n), None) for n in ("a", "b")]
    with_E, warnings = _moduli(fits)
    assert with_E is None and len(warnings) == 1 and "not compared" in warnings[0] and "b fitted without" in warnings[0]
    with_E, warnings = _moduli(fits[:1])
    (m,) = with_E
    E = 64 * np.exp(draws[:, 0]) / (np.pi * 0.01**4)
    assert np.median(m.draws[:, 0]) == pytest.approx(np.log(np.median(E)), abs=0.01) and warnings == []
    assert _moduli(fits[1:]) == (None, [])


def test_compare_cli_writes_contract_json_and_warns(tmp_path, capsys):
    rng = np.random.default_rng(3)
    runs = []
    for s in _species(rng, "oak", 5.0, 0.4, 3) + _species(rng, "reed", 1.0, 1.2, 1):
        d0 = np.full(len(s.draws), 0.01 if s.species == "oak" else 0.006)  # calipers: Young's modulus too
        _fake_run(tmp_path / s.specimen, s.specimen, s.species, s.draws, d0=d0)
        runs.append(str(tmp_path / s.specimen))
    out = tmp_path / "cmp"
    assert main(["compare", *runs, "--out", str(out), "--height", "0.3"]) == 0
    res = json.loads((out / "compare.json").read_text())
    assert res["groups"] == {"oak": ["oak-0", "oak-1", "oak-2"], "reed": ["reed-0"]}
    for c in res["contrasts"]:
        assert {"a", "b", "parameter", "ratio_median", "ratio_q05", "ratio_q95", "prob_a_greater"} <= set(c)
    ei0 = next(c for c in res["contrasts"] if c["parameter"] == "EI0")
    assert ei0["ratio_q05"] > 1.0  # oak (a) stiffer than reed
    line = f"EI0 oak / reed: {ei0['ratio_median']:.3g} [{ei0['ratio_q05']:.3g}, {ei0['ratio_q95']:.3g}] (90%)"
    assert line + f", P(oak stiffer) = {ei0['prob_a_greater']:.3f}" in capsys.readouterr().out
    E = next(c for c in res["contrasts"] if c["parameter"] == "E")  # E ~ EI0 / d0^4: 5 x 0.6^4 = 0.65
    assert E["ratio_q05"] < 0.65 < E["ratio_q95"] and set(res["species"]["reed"]) >= {"E_Pa", "EI0"}
    assert "log_E" in res["between_specimen_sd"]
    lonely = [w for w in res["warnings"] if "one specimen only" in w]
    assert len(lonely) == 1 and lonely[0].startswith("reed: "), res["warnings"]  # reed's, not oak's (3 specimens)
    kt = [c for c in res["contrasts"] if c["parameter"] == "k_theta"]  # --height 0.3: k_theta contrasted there
    assert len(kt) == 1 and kt[0]["height_m"] == 0.3 and kt[0]["ratio_q05"] > 1.0, kt
    import cv2

    forest = cv2.imread(str(out / "figures" / "forest.png")).astype(int)  # drawn, not an empty frame:
    assert np.mean(forest.max(axis=2) - forest.min(axis=2) > 40) > 0.001  # its coloured marks (measured 0.35%)
    capsys.readouterr()
    assert main(["compare", runs[0], runs[1], "--out", str(tmp_path / "x")]) == 2  # one species only
    assert "at least 2 species" in capsys.readouterr().err


def test_compare_needs_species(tmp_path, capsys):
    d = np.column_stack([np.log(np.full(100, 2.0)), np.full(100, 0.4)])
    _fake_run(tmp_path / "a", "a", None, d)
    _fake_run(tmp_path / "b", "b", "x", d)
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "species" in err and "Traceback" not in err
    assert f"{tmp_path / 'a'}: field species" in err  # the run that lacks it
    assert not (tmp_path / "o").exists()  # nothing half-written


def test_compare_reports_each_species_and_the_spread_between_specimens_from_its_draws(tmp_path, monkeypatch):
    """compare.json's per-species numbers: EI0 (exp of the species mean of log EI0), p, E (the log-E model's),
    the between-specimen sds and the convergence of both models; each the summary of the draws it names
    (an index or an exp off would pass the contrasts' tests) and each covering the truth the specimens were
    drawn from (oak EI0 5 N m^2, p 0.4, d0 10 mm; reed 1 N m^2, p 1.2, 6 mm; spreads TAU in log EI0 and p)."""
    import importlib

    import bayesrod
    from bayesrod.inference.summary import credible_interval

    cmp_module = importlib.import_module("bayesrod.api.compare")  # the package exports the function of its name
    fits = []

    def spy(*a, **k):  # the log-E model's R-hat made the worse, so the report must take it from there
        assert k["seed"] == 1 + len(fits), k  # the run's seed (and seed + 1) reaches both models: reproducible
        fits.append(sample_species(*a, **k))
        if len(fits) == 2:
            fits[-1] = fits[-1] | {"rhat_max": fits[-1]["rhat_max"] + 0.5}
        return fits[-1]

    monkeypatch.setattr(cmp_module, "sample_species", spy)
    rng = np.random.default_rng(3)
    runs, truth = [], {"oak": (5.0, 0.4, 0.01), "reed": (1.0, 1.2, 0.006)}
    for s in _species(rng, "oak", 5.0, 0.4, 3) + _species(rng, "reed", 1.0, 1.2, 2):
        _fake_run(tmp_path / s.specimen, s.specimen, s.species, s.draws, d0=np.full(len(s.draws), truth[s.species][2]))
        runs.append(tmp_path / s.specimen)
    res = bayesrod.compare(runs, seed=1)
    doc, (fit, fit_E) = res.to_dict(), fits
    assert fit["species"] == fit_E["species"] == ["oak", "reed"]
    for g, sp in enumerate(fit["species"]):
        got, (EI0, p, d0) = doc["species"][sp], truth[sp]
        assert got["n_specimens"] == {"oak": 3, "reed": 2}[sp]
        assert got["EI0"] == pytest.approx(credible_interval(np.exp(fit["mu"][:, g, 0])), rel=1e-12)
        assert got["p"] == pytest.approx(credible_interval(fit["mu"][:, g, 1]), rel=1e-12)
        assert got["E_Pa"] == pytest.approx(credible_interval(np.exp(fit_E["mu"][:, g, 0])), rel=1e-12)
        E = 64 * EI0 / (np.pi * d0**4)
        for k, v in (("EI0", EI0), ("p", p), ("E_Pa", E)):
            assert got[k]["q05"] < v < got[k]["q95"], (sp, k, got[k])
    sd = doc["between_specimen_sd"]
    assert sd["log_EI0"] == pytest.approx(credible_interval(fit["tau"][:, 0]), rel=1e-12)
    assert sd["p"] == pytest.approx(credible_interval(fit["tau"][:, 1]), rel=1e-12)
    assert sd["log_E"] == pytest.approx(credible_interval(fit_E["tau"][:, 0]), rel=1e-12)
    for k, v in (("log_EI0", TAU[0]), ("p", TAU[1]), ("log_E", TAU[0])):  # d0 is the same within a species
        assert sd[k]["q05"] < v < sd[k]["q95"], (k, sd[k])
    # the run's convergence is the worse of the two models'
    assert doc["convergence"] == {
        "rhat_max": max(fit["rhat_max"], fit_E["rhat_max"]),
        "ess_bulk_min": min(fit["ess_bulk_min"], fit_E["ess_bulk_min"]),
    }
    assert fit["rhat_max"] != fit_E["rhat_max"] and fit["ess_bulk_min"] != fit_E["ess_bulk_min"]
    assert min(fit["ess_bulk_min"], fit_E["ess_bulk_min"]) >= 1000  # both models reach the sampler's target ESS
    # saved, it refuses to overwrite a non-empty directory unless asked (nothing lost)
    from bayesrod.dataset.io import OutputExistsError

    out = res.save(tmp_path / "cmp")
    (out / "mine.txt").write_text("a user's note")
    with pytest.raises(OutputExistsError):
        res.save(out)
    res.save(out, overwrite=True)
    assert json.loads((out / "compare.json").read_text())["species"] == json.loads(json.dumps(doc["species"]))
    assert not (out / "mine.txt").exists()


def test_compare_takes_species_from_a_mapping_and_refuses_a_specimen_twice_or_a_folder_that_is_no_run(
    tmp_path, monkeypatch
):
    """``compare({species: [runs]})``: the mapping's species, not the runs' own, group the specimens (what the
    species model is handed is recorded and the run stopped there); a specimen given twice, or a folder
    without summary.json and samples.npz, is refused with its field and the path."""
    import importlib

    import bayesrod

    cmp_module = importlib.import_module("bayesrod.api.compare")
    handed = []

    class Stop(Exception):
        pass

    def record(per, **kw):
        handed.append([(s.specimen, s.species) for s in per])
        raise Stop

    monkeypatch.setattr(cmp_module, "sample_species", record)
    rng = np.random.default_rng(3)
    runs = {}
    for s in _species(rng, "oak", 5.0, 0.4, 2) + _species(rng, "reed", 1.0, 1.2, 2):
        _fake_run(tmp_path / s.specimen, s.specimen, "unlabelled", s.draws)
        runs[s.specimen] = tmp_path / s.specimen
    with pytest.raises(Stop):
        bayesrod.compare({"A": [runs["oak-0"], runs["reed-1"]], "B": [str(runs["oak-1"]), runs["reed-0"]]})
    assert sorted(handed[0]) == [("oak-0", "A"), ("oak-1", "B"), ("reed-0", "B"), ("reed-1", "A")]
    with pytest.raises(ValueError, match="specimen: expected each specimen once, got oak-0 more than once"):
        bayesrod.compare({"A": [runs["oak-0"], runs["oak-1"]], "B": [runs["oak-0"], runs["reed-0"]]})
    # without diameters only the (log EI0, p) model runs: its convergence is the run's (a stand-in fit, exact)
    fake = {"species": ["A", "B"], "rhat_max": 1.004, "ess_bulk_min": 1234.0}
    fake |= {"mu": rng.normal([[0.5, 0.4], [0.0, 1.2]], 0.05, (800, 2, 2)), "tau": np.full((800, 2), 0.1)}
    monkeypatch.setattr(cmp_module, "sample_species", lambda per, **kw: fake)
    doc = bayesrod.compare({"A": [runs["oak-0"], runs["oak-1"]], "B": [runs["reed-0"], runs["reed-1"]]}).to_dict()
    assert doc["convergence"] == {"rhat_max": 1.004, "ess_bulk_min": 1234.0} and "E_Pa" not in doc["species"]["A"]
    # at the level it states: the EI0 contrast's interval is the 5% and 95% quantiles of the draws' ratio
    assert doc["level"] == 0.9 and doc["method"].startswith("normal-normal hierarchical model")
    ei0 = next(c for c in doc["contrasts"] if c["parameter"] == "EI0")
    ratio = np.exp(fake["mu"][:, 0, 0] - fake["mu"][:, 1, 0])
    assert [ei0["ratio_q05"], ei0["ratio_q95"]] == pytest.approx(np.quantile(ratio, [0.05, 0.95]), rel=1e-12)
    # with diameters the log-E model runs too, on the mapping's species as well
    seen = []
    monkeypatch.setattr(
        cmp_module, "sample_species", lambda per, **kw: seen.append({s.specimen: s.species for s in per}) or fake
    )
    for name in ("oak-0", "reed-0"):
        s = _species(rng, name[:-2], 1.0, 0.5, 1)[0]
        _fake_run(tmp_path / f"d-{name}", f"d-{name}", "unlabelled", s.draws, d0=np.full(len(s.draws), 0.008))
    bayesrod.compare({"A": [tmp_path / "d-oak-0"], "B": [tmp_path / "d-reed-0"]})
    assert seen == [{"d-oak-0": "A", "d-reed-0": "B"}] * 2  # the (log EI0, p) model's, then the log-E model's
    half = tmp_path / "half"  # a run that never finished: its summary without samples
    half.mkdir()
    (half / "summary.json").write_text(json.dumps({"specimen": "half", "species": "A", "length_m": 0.8}))
    for bad in (half, tmp_path / "nothing"):
        with pytest.raises(ValueError, match=f"{bad}: expected a bayesrod.Posterior"):
            bayesrod.compare([runs["oak-0"], runs["reed-0"], bad])


def test_compare_expands_a_fit_many_output_and_a_fit_group_output_into_their_runs(tmp_path):
    """A fit-many output stands for its finished runs and stems (a ``.done`` marker each; unfinished ones
    left out), a fit-group output (groups.json) for its stems, in order; any other path is itself."""
    from bayesrod.api.compare import expand_inputs

    many = tmp_path / "many"
    for kind, names in (("runs", ("b", "a", "unfinished")), ("groups", ("m7",))):
        for n in names:
            (many / kind / n).mkdir(parents=True)
            if n != "unfinished":
                (many / kind / f"{n}.done").touch()
    (many / "survey.csv").write_text("specimen\n")
    group = tmp_path / "group"
    group.mkdir()
    (group / "groups.json").write_text(json.dumps({"stems": {"stem 1": "stem_1", "s2": "s2"}, "problems": []}))
    plain = tmp_path / "run"
    got = expand_inputs([many, str(group), plain])
    runs, groups = many / "runs", many / "groups"
    assert got == [runs / "a", runs / "b", groups / "m7", group / "stem_1", group / "s2", plain]
    assert expand_inputs([plain, many]) == [plain, runs / "a", runs / "b", groups / "m7"]  # the paths before it kept
    assert expand_inputs([tmp_path / "many" / "runs"]) == [runs]  # without survey.csv: a path like any other
    (many / "survey.csv").unlink()
    assert expand_inputs([many]) == [many]


def test_compare_says_why_it_leaves_the_anchorage_out():
    """Stems fitted under several conditions: no condition name in common, or one species only: no anchorage
    contrasts, and a warning that says which (compare reports it beside the stem contrasts)."""
    import importlib
    from types import MappingProxyType

    from bayesrod.api.group import GroupFit

    anchorage = importlib.import_module("bayesrod.api.compare")._anchorage

    def stem(sid, species, conditions):
        doc = {"stem_id": sid, "species": species, "shared": {"EI0": {}, "p": {}}, "length_m": 0.8}
        return GroupFit(sid, conditions, MappingProxyType({}), MappingProxyType(doc))

    apart = [(stem("a", "A", ("intact", "cut")), None), (stem("b", "B", ("wet", "dry")), None)]
    assert anchorage(apart, 0) == ({}, ["anchorage not compared: the stems share no condition name"])
    alike = [(stem("a", "A", ("intact", "cut")), None), (stem("b", "A", ("intact",)), None)]
    msg = "anchorage not compared: the stems fitted under several conditions are of one species"
    assert anchorage(alike, 0) == ({}, [msg])
    assert anchorage([(object(), "A")], 0) == ({}, [])  # no stem under several conditions: nothing to say


def test_the_log_e_posteriors_are_checked_against_half_the_species_priors_sd(tmp_path):
    """compare warns where a specimen's log-E posterior is not small against the prior: sd over 0.3 x half the
    log-E species prior's sd (3.0 / 2 = 1.5: threshold 0.45). A specimen at sd 0.40 passes, one at 0.50 is named."""
    from bayesrod.api.compare import _moduli
    from bayesrod.api.group import load_run

    z = np.random.default_rng(2).standard_normal(4000)
    z = (z - z.mean()) / z.std()
    fits = []
    for name, sd in (("narrow", 0.40), ("wide", 0.50)):
        draws = np.column_stack([np.full(z.size, np.log(2.0)), np.full(z.size, 0.5)])
        _fake_run(tmp_path / name, name, "oak", draws, d0=0.01 * np.exp(-z * sd / 4))  # log E = ... - 4 log d0
        fits.append((load_run(tmp_path / name), None))
    moduli, warnings = _moduli(fits)
    assert [float(np.sqrt(m.cov[0, 0])) for m in moduli] == pytest.approx([0.40, 0.50], rel=1e-3)
    assert len(warnings) == 1 and warnings[0].startswith("wide: posterior sd of log E (0.5)"), warnings

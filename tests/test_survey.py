"""fit-many on a 2-worker Dask LocalCluster: same summaries as sequential fits, restartable, failures isolated."""

import json
import shutil

import pytest

from bayesrod.cli import main

from .conftest import make_dataset

pytest.importorskip("dask.distributed")


@pytest.fixture(scope="module")
def survey_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("survey")
    make_dataset(root / "a", "grass", seed=11, n_frames_engaged=2)
    make_dataset(root / "c", "grass", seed=13, n_frames_engaged=2)
    bad = root / "d"
    shutil.copytree(root / "a", bad)
    spec = json.loads((bad / "specimen.json").read_text())
    spec["specimen"] = "broken"
    spec["length_m"] = -1  # invalid: this one must fail alone
    (bad / "specimen.json").write_text(json.dumps(spec))
    return root


@pytest.mark.slow  # 2.5 minutes (two Dask runs); the restart logic
def test_fit_many_matches_sequential_and_restarts(survey_root, tmp_path):
    import bayesrod

    out = tmp_path / "out"
    rc = main(["fit-many", str(survey_root), "--out", str(out), "--workers", "2", "--forces-only", "--quiet"])
    assert rc == 1  # one dataset failed; the others finished
    failures = json.loads((out / "failures.json").read_text())
    assert list(failures) == ["broken"] and "length_m" in failures["broken"]["error"]
    lines = (out / "survey.csv").read_text().strip().splitlines()
    assert len(lines) == 3 and lines[0].startswith("specimen,species")
    import pyarrow.parquet as pq

    assert pq.read_table(out / "survey.parquet").num_rows == 2

    # same seed, same answer as a sequential fit in this process
    seq = bayesrod.fit(survey_root / "c", use_shapes=False, progress=False).to_dict()
    par = json.loads((out / "runs" / "grass-sim-13" / "summary.json").read_text())
    assert par["parameters"]["EI0"] == seq["parameters"]["EI0"]
    assert par["parameters"]["p"] == seq["parameters"]["p"]

    # "kill" one specimen midway: its marker and summary gone; rerun fits only that one
    (out / "runs" / "grass-sim-11.done").unlink()
    (out / "runs" / "grass-sim-11" / "summary.json").unlink()
    before = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*/summary.json")}
    rc = main(["fit-many", str(survey_root), "--out", str(out), "--workers", "2", "--forces-only", "--quiet"])
    assert rc == 1
    after = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*/summary.json")}
    assert all(after[p] == t for p, t in before.items())  # finished ones not refitted
    assert (out / "runs" / "grass-sim-11.done").is_file()
    assert len((out / "survey.csv").read_text().strip().splitlines()) == 3


def test_fit_many_bad_root(tmp_path, capsys):
    assert main(["fit-many", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such directory" in capsys.readouterr().err


def _group_summary(sid="m1", shared=("EI0", "p")):
    """A fit-group summary.json with the documented keys (numbers made up)."""

    def q(m):
        return {"median": m, "q05": 0.9 * m, "q95": 1.1 * m}

    conds = {
        c: {
            "base_compliance_rad_per_Nm": q(v),
            "prob_rigid_clamp": pr,
            **({} if "p" in shared else {"p": q(0.4 + v)}),
        }
        for c, v, pr in (("intact", 0.001, 0.6), ("cut", 0.05, 0.0))
    }
    return {
        "stem_id": sid,
        "conditions_order": ["intact", "cut"],
        "shared": {n: q(m) for n, m in (("EI0", 2.6), ("p", 0.43)) if n in shared},
        "conditions": conds,
        "sharing": {"verdict": "supported"},
        "species": "maize",
        "length_m": 0.8,
        "convergence": {"rhat_max": 1.004, "ess_bulk_min": 512.0},
        "sampler": {"seconds": 12.5},
    }


@pytest.mark.parametrize("shared", [("EI0", "p"), ("EI0",)])
def test_group_rows_are_one_per_condition_and_save_as_groups_tables(tmp_path, shared):
    import pyarrow.parquet as pq

    from bayesrod.api.survey import GROUP_COLUMNS, SURVEY_COLUMNS, Survey, _group_rows

    rows = _group_rows(_group_summary(shared=shared), tmp_path / "groups" / "m1")
    assert [r["condition"] for r in rows] == ["intact", "cut"] and all(list(r) == GROUP_COLUMNS for r in rows)
    cut = rows[1]
    assert cut["EI0_median"] == 2.6 and cut["base_compliance_median"] == 0.05 and cut["prob_rigid_clamp"] == 0.0
    assert cut["p_median"] == (0.43 if "p" in shared else 0.45)  # the condition's own p where it is not shared
    assert cut["sharing"] == "supported" and cut["species"] == "maize" and cut["seconds"] == 12.5
    assert (cut["EI0_q05"], cut["EI0_q95"]) == pytest.approx((0.9 * 2.6, 1.1 * 2.6), rel=1e-12)
    assert (cut["base_compliance_q05"], cut["base_compliance_q95"]) == pytest.approx((0.045, 0.055), rel=1e-12)
    Survey((), {}, 2, tuple(rows)).save(tmp_path)
    lines = (tmp_path / "groups.csv").read_text().splitlines()
    assert lines[0] == ",".join(GROUP_COLUMNS) and len(lines) == 3 and lines[2].startswith("m1,cut,maize,0.8,2.6,")
    assert pq.read_table(tmp_path / "groups.parquet").num_rows == 2
    assert (tmp_path / "survey.csv").read_text().strip() == ",".join(SURVEY_COLUMNS)
    Survey((), {}, 1).save(tmp_path / "plain")
    assert not (tmp_path / "plain" / "groups.csv").exists()  # no stems fitted jointly: no groups table


@pytest.mark.slow  # 3.5 min beside two studies: a Dask cluster, a joint fit and a single fit, then a rerun
def test_fit_many_grouped_fits_stems_jointly_and_the_rest_alone(tmp_path):
    import math

    import bayesrod

    data = tmp_path / "data"
    quiet = {"noise_rho": 0.9, "config_overrides": {"n_frames_engaged": 2}}
    for d in bayesrod.simulate_group(
        "twig", conditions={"intact": math.inf, "cut": 10.0}, heights_m=[0.45, 0.65], seed=4, stem_id="m7", **quiet
    ):
        d.save(data / d.specimen)
    alone = bayesrod.simulate_group(
        "twig", conditions={"intact": math.inf}, heights_m=[0.5], seed=9, stem_id="m8", **quiet
    )[0]
    alone.save(data / "m8-only")
    shutil.copytree(data / next(p.name for p in data.iterdir() if p.name.endswith("cut")), data / "zz-repeat")
    out = tmp_path / "out"
    argv = ["fit-many", str(data), "--out", str(out), "--workers", "2", "--grouped", "--quiet", "--prior", "woody"]
    assert main(argv) == 1  # the repeated condition is a failure; the rest finished
    failures = json.loads((out / "failures.json").read_text())
    assert list(failures) == ["zz-repeat"] and "expected one dataset per condition" in failures["zz-repeat"]["error"]
    joint = json.loads((out / "groups" / "m7" / "summary.json").read_text())
    assert joint["stem_id"] == "m7" and set(joint["conditions"]) == {"intact", "cut"}
    assert (out / "groups" / "m7.done").is_file() and len(list((out / "runs").glob("*.done"))) == 1
    rows = (out / "groups.csv").read_text().strip().splitlines()
    assert len(rows) == 3 and {r.split(",")[1] for r in rows[1:]} == {"intact", "cut"}
    assert all(r.startswith("m7,") and r.endswith(str(out / "groups" / "m7")) for r in rows[1:])
    assert len((out / "survey.csv").read_text().strip().splitlines()) == 2  # the single-condition stem, alone
    before = (out / "groups" / "m7" / "summary.json").stat().st_mtime_ns
    assert main(argv) == 1
    assert (out / "groups" / "m7" / "summary.json").stat().st_mtime_ns == before  # done: not refitted
    from bayesrod.api.compare import expand_inputs

    assert out / "groups" / "m7" in expand_inputs([out])


def test_a_survey_row_is_its_runs_summary():
    """survey.csv's row of one fit: each interval's three quantiles, convergence, fit error and time, as the
    run's summary.json has them."""
    from pathlib import Path

    from bayesrod.api.survey import SURVEY_COLUMNS, _row

    summary = {
        "specimen": "s1",
        "species": "oak",
        "length_m": 0.8,
        "parameters": {"EI0": {"median": 2.6, "q05": 2.4, "q95": 2.9}, "p": {"median": 0.43, "q05": 0.4, "q95": 0.47}},
        "convergence": {"rhat_max": 1.004, "ess_bulk_min": 512.0},
        "fit_error": {"force_rmse_N": 0.031, "shape_rmse_mm": 1.2},
        "sampler": {"seconds": 12.5},
    }
    row = _row(summary, Path("runs") / "s1")
    assert list(row) == SURVEY_COLUMNS
    assert [row[f"EI0_{q}"] for q in ("median", "q05", "q95")] == [2.6, 2.4, 2.9]
    assert [row[f"p_{q}"] for q in ("median", "q05", "q95")] == [0.43, 0.4, 0.47]
    assert (row["rhat_max"], row["ess_bulk_min"]) == (1.004, 512.0)
    assert (row["force_rmse_N"], row["shape_rmse_mm"]) == (0.031, 1.2)
    assert (row["specimen"], row["species"], row["length_m"], row["seconds"]) == ("s1", "oak", 0.8, 12.5)
    assert row["run"] == str(Path("runs") / "s1")

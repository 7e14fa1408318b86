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

"""Real-data importer on the blueberry canes (shared/data) and its building blocks."""

import json

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.dataset import read_dataset, validate_dataset
from bayesrod.dataset.importers import hinge_onset, unwrap_counter

from .conftest import BLUEBERRY


def test_unwrap_counter_16_bit():
    t = np.arange(0, 200000, 500.0)
    wrapped = (t + 32768) % 65536 - 32768
    np.testing.assert_allclose(unwrap_counter(wrapped) - unwrap_counter(wrapped)[0], t - t[0])


def test_hinge_onset_recovers_tare_and_onset():
    rng = np.random.default_rng(0)
    x = np.arange(80) * 0.5e-3
    F = -0.7 + 120 * np.clip(x - x[12], 0, None) + rng.normal(0, 0.01, x.size)
    on = hinge_onset(x, F)
    assert on.observed and abs(on.index - 12) <= 1
    assert on.baseline == pytest.approx(-0.7, abs=0.02)
    assert on.slope == pytest.approx(120, rel=0.05)


@pytest.mark.skipif(not BLUEBERRY.is_dir(), reason="shared/data/blueberry-canes not beside the repository")
def test_all_blueberry_canes_import_and_validate(tmp_path):
    out = tmp_path / "bb"
    assert main(["import", "blueberry", str(BLUEBERRY), "--out", str(out), "--length-m", "1.6"]) == 0
    report = json.loads((out / "import_report.json").read_text())
    assert len(report["canes"]) == 18
    for cane in report["canes"]:
        assert cane["status"] in ("imported", "rejected")
        for trial in cane["trials"]:
            assert trial["status"] == "imported" or trial["reason"]
        if cane["status"] == "rejected":
            assert cane["reason"]
            continue
        ds = out / cane["dataset"]
        assert [p for p in validate_dataset(ds) if p.severity == "error"] == []
        spec = read_dataset(ds)
        assert spec.extra["provenance"]["assumptions"]["length_m"].startswith("1.6 m")
        for push in spec.pushes:
            assert push.force.robot_x_m[0] == 0.0 and np.all(np.diff(push.force.time_s) > 0)
            assert 0.5 < push.height_m < 1.2
    trials = {t["file"]: t for c in report["canes"] for t in c["trials"]}
    assert trials["bush_4_branch_1_trial_1.csv"]["status"] == "rejected"  # never makes real contact
    assert sum(t["status"] == "imported" for t in trials.values()) >= 50
    # tare: with an observed onset the first engaged force is near zero
    spec = read_dataset(out / "bush1-cane2")
    assert abs(spec.pushes[-1].force.force_N[0]) < 0.3


@pytest.mark.skipif(not BLUEBERRY.is_dir(), reason="shared/data/blueberry-canes not beside the repository")
def test_cane_length_must_exceed_heights(tmp_path, capsys):
    assert main(["import", "blueberry", str(BLUEBERRY), "--out", str(tmp_path / "o"), "--length-m", "0.7"]) == 0
    report = json.loads((tmp_path / "o" / "import_report.json").read_text())
    reasons = [t["reason"] for c in report["canes"] for t in c["trials"] if t["status"] == "rejected"]
    assert any("not below the assumed cane length" in r for r in reasons)


def test_importer_bad_source(tmp_path, capsys):
    assert main(["import", "blueberry", str(tmp_path), "--out", str(tmp_path / "o"), "--length-m", "1.6"]) == 2
    assert "SRC" in capsys.readouterr().err


def test_a_blueberry_trial_converts_its_units_and_counts_time_and_travel_from_contact(tmp_path):
    """A trial written in the rig's own units (ms stamps from an arbitrary origin that wrap at 16 bits, gf not
    zeroed, mm): seconds from the first sample, newtons tared by the baseline, metres from the contact (runs
    without the shared data, which the other importer tests need)."""
    from bayesrod.dataset.importers import GF_TO_N, import_blueberry_trial

    n = 80
    stamp = (30000 + 500.0 * np.arange(n) + 32768) % 65536 - 32768  # wraps after 6 samples
    travel_mm = 323.0 + 0.5 * np.arange(n)
    contact = 12  # at 329 mm; 40 gf baseline, 300 gf per mm after
    load_gf = 40.0 + 300.0 * np.clip(travel_mm - travel_mm[contact], 0, None) + 0.3 * np.sin(np.arange(n))
    rows = np.column_stack([np.arange(2.0, n + 2), stamp, load_gf, travel_mm, np.full(n, 765.0)])
    path = tmp_path / "bush_9_branch_1_trial_1.csv"
    header = "Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)"
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.6g")
    rep, cols = import_blueberry_trial(path, length_m=1.6)
    assert rep.status == "imported" and rep.height_m == 0.765 and rep.onset_observed
    k = n - cols["time_s"].size
    assert abs(k - contact) <= 1
    np.testing.assert_allclose(cols["time_s"], 0.5 * np.arange(k, n), atol=1e-9)  # seconds from the first sample
    np.testing.assert_allclose(cols["robot_x_m"], (travel_mm[k:] - travel_mm[k]) / 1000.0, atol=1e-12)
    assert rep.baseline_N == pytest.approx(40.0 * GF_TO_N, abs=0.01)
    np.testing.assert_allclose(cols["force_N"], (load_gf[k:] - 40.0) * GF_TO_N, atol=0.01)
    assert GF_TO_N == 9.80665e-3

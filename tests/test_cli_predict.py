"""`bayesrod predict` as a user runs it (docs/format.md, sections 2 and 3)."""

import json
import subprocess
import sys

import pytest

from bayesrod.cli import main


def run(*args):
    return subprocess.run([sys.executable, "-m", "bayesrod.cli", *args], capture_output=True, text=True)


def test_predict_json_contract(capsys):
    rc = main(
        [
            "predict",
            "--EI0",
            "2.63",
            "--p",
            "0.43",
            "--length",
            "0.8",
            "--height",
            "0.45",
            "--displacement",
            "0.01,0.05",
            "--json",
        ]
    )
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["height_m"] == 0.45
    assert doc["k_theta_Nm_per_rad"] == pytest.approx(7.5875, rel=1e-4)
    assert doc["k_x_N_per_m"] == pytest.approx(63.740, rel=1e-4)
    pt = doc["points"][0]
    assert set(pt) >= {"displacement_m", "force_N", "contact_s_m", "slipped"}
    assert pt["force_N"] == pytest.approx(0.6371, rel=1e-3) and pt["contact_s_m"] == pytest.approx(0.4501, abs=1e-4)


def test_predict_range_and_slip_is_null(capsys):
    rc = main(["predict", "--preset", "twig", "--height", "0.65", "--displacement", "0:0.6:4", "--json"])
    assert rc == 0
    pts = json.loads(capsys.readouterr().out)["points"]
    assert [p["displacement_m"] for p in pts] == pytest.approx([0, 0.2, 0.4, 0.6])
    assert pts[0]["force_N"] == 0.0
    assert pts[-1]["slipped"] is True and pts[-1]["force_N"] is None


def test_predict_effect_flag_changes_force(capsys):
    main(
        [
            "predict",
            "--preset",
            "twig",
            "--height",
            "0.45",
            "--displacement",
            "0.01",
            "--json",
            "--effect",
            "force_offset=0.5",
        ]
    )
    assert json.loads(capsys.readouterr().out)["points"][0]["force_N"] == pytest.approx(1.1371, rel=1e-3)


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--EI0", "-1", "--p", "0.4", "--length", "0.8", "--height", "0.4", "--displacement", "0.1"], "--EI0"),
        (["--EI0", "1", "--p", "0.4", "--length", "0.8", "--height", "0.8", "--displacement", "0.1"], "--height"),
        (["--EI0", "1", "--p", "-2", "--length", "0.8", "--height", "0.4", "--displacement", "0.1"], "--p"),
        (["--EI0", "1", "--p", "0.4", "--length", "0.8", "--height", "0.4", "--displacement", "a"], "--displacement"),
        (
            ["--EI0", "1", "--p", "0.4", "--length", "0.8", "--height", "0.4", "--displacement", "-0.1"],
            "--displacement",
        ),
        (["--EI0", "1", "--p", "0.4", "--height", "0.4", "--displacement", "0.1"], "--length"),
        (["--preset", "twig", "--height", "0.4", "--displacement", "0.1", "--effect", "tilt=1"], "effect"),
        (["--EI0", "nan", "--p", "0.4", "--length", "0.8", "--height", "0.4", "--displacement", "0.1"], "--EI0"),
    ],
)
def test_predict_bad_input_one_clear_line(args, needle, capsys):
    try:  # in-process (an uncaught exception fails the test); argparse's errors exit
        code = main(["predict", *args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code != 0
    assert needle in err
    assert len(err.strip().splitlines()) <= 2  # usage line + message at most


def test_predict_bad_input_in_a_real_process_prints_no_traceback():
    res = run("predict", "--EI0", "-1", "--p", "0.4", "--length", "0.8", "--height", "0.4", "--displacement", "0.1")
    assert res.returncode != 0
    assert "Traceback" not in res.stderr
    assert "--EI0" in res.stderr
    assert len(res.stderr.strip().splitlines()) <= 2

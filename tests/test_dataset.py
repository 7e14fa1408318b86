"""Dataset reader and validator: every kind of breakage named, nothing crashes."""

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayesrod.cli import main
from bayesrod.dataset import DatasetError, read_dataset, validate_dataset


def _edit_json(ds, fn):
    path = ds / "specimen.json"
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def _edit_csv(path, fn):
    lines = path.read_text().splitlines()
    path.write_text("\n".join(fn(lines)) + "\n")


def _cli_validate(ds):
    return subprocess.run([sys.executable, "-m", "bayesrod.cli", "validate", str(ds)], capture_output=True, text=True)


def test_simulated_dataset_reads(twig_noisy):
    assert [p for p in validate_dataset(twig_noisy) if p.severity == "error"] == []
    spec = read_dataset(twig_noisy)
    assert spec.length_m == 0.8 and len(spec.pushes) == 3
    push = spec.pushes[0]
    assert push.force.force_N.flags.writeable is False
    assert len(push.shapes) == 22 and push.shapes[0].sd_m is not None
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        push.height_m = 1.0  # frozen


def _mm_length(doc):
    doc["length_m"] = 800


CASES = [
    ("missing force file", lambda ds: (ds / "h450" / "force.csv").unlink(), "force.csv", "no such file"),
    (
        "missing column",
        lambda ds: _edit_csv(ds / "h450" / "force.csv", lambda L: [L[0].replace("force_N", "forc_N")] + L[1:]),
        "force_N",
        "column",
    ),
    (
        "non-numeric",
        lambda ds: _edit_csv(ds / "h550" / "force.csv", lambda L: L[:5] + ["0.1,abc,0.2,0"] + L[6:]),
        "row 5",
        "'abc'",
    ),
    (
        "NaN",
        lambda ds: _edit_csv(ds / "h550" / "force.csv", lambda L: L[:3] + ["0.1,nan,0.2,0"] + L[4:]),
        "row 3",
        "finite number",
    ),
    (
        "time not increasing",
        lambda ds: _edit_csv(ds / "h650" / "force.csv", lambda L: L[:10] + [L[8]] + L[11:]),
        "time_s",
        "strictly increasing",
    ),
    (
        "height outside",
        lambda ds: _edit_json(ds, lambda d: d["pushes"][1].update(height_m=0.95)),
        "height_m",
        "0 < height_m < length_m",
    ),
    ("length in mm", lambda ds: _edit_json(ds, _mm_length), "length_m", "millimetres"),
    ("duplicate id", lambda ds: _edit_json(ds, lambda d: d["pushes"][2].update(id="h450")), "pushes[2].id", "unique"),
    (
        "camera missing",
        lambda ds: _edit_json(ds, lambda d: d["pushes"][0].update(frames="h450")),
        "camera",
        "camera intrinsics",
    ),
    ("bad json", lambda ds: (ds / "specimen.json").write_text('{"format": '), "specimen.json", "valid JSON"),
    ("wrong format", lambda ds: _edit_json(ds, lambda d: d.update(format="other/2")), "format", "bayesrod.dataset/1"),
    ("no pushes", lambda ds: _edit_json(ds, lambda d: d.update(pushes=[])), "pushes", "at least one"),
    (
        "shape sd negative",
        lambda ds: _edit_csv(
            ds / "h450" / "shapes.csv", lambda L: L[:2] + [L[2].rsplit(",", 1)[0] + ",-0.001"] + L[3:]
        ),
        "sd_m",
        "> 0",
    ),
    (
        "observed not 0/1",
        lambda ds: _edit_csv(
            ds / "h450" / "shapes.csv", lambda L: [L[0] + ",observed"] + [x + ",1" for x in L[1:4]] + [L[4] + ",2"]
        ),
        "observed",
        "1 (seen) or 0",
    ),
]


@pytest.mark.parametrize("name,breaker,needle,expected", CASES, ids=[c[0] for c in CASES])
def test_validate_names_each_problem(twig_copy, name, breaker, needle, expected, capsys):
    breaker(twig_copy)
    problems = [str(p) for p in validate_dataset(twig_copy) if p.severity == "error"]
    assert any(needle in p and expected in p for p in problems), problems
    with pytest.raises(DatasetError):
        read_dataset(twig_copy)
    assert main(["validate", str(twig_copy)]) != 0  # in-process: an uncaught exception fails the test
    assert needle in capsys.readouterr().err


def test_validate_in_a_real_process_prints_no_traceback(twig_copy):
    """One bad dataset as a shell sees it: exit code and message, no traceback."""
    _, breaker, needle, _ = CASES[0]
    breaker(twig_copy)
    res = _cli_validate(twig_copy)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert needle in res.stderr


def test_unreadable_png_and_missing_frame(twig_copy):
    frames = twig_copy / "h450" / "frames"
    frames.mkdir()
    (frames / "rgb0.png").write_bytes(b"not a png at all")
    import cv2

    cv2.imwrite(str(frames / "d0.png"), np.zeros((4, 4), np.uint16))
    (frames / "index.csv").write_text("frame,time_s,rgb,depth\n0,0.0,rgb0.png,d0.png\n1,0.1,rgb1.png,d0.png\n")

    def add(d):
        d["pushes"][0]["frames"] = "h450/frames"
        d["camera"] = {"fx": 600, "fy": 600, "cx": 320, "cy": 240, "base_px": [128, 441]}

    _edit_json(twig_copy, add)
    problems = [str(p) for p in validate_dataset(twig_copy)]
    assert any("row 1" in p and "unreadable" in p for p in problems), problems
    assert any("row 2" in p and "no such file" in p for p in problems), problems


def test_every_problem_listed_not_just_the_first(twig_copy):
    _edit_json(twig_copy, lambda d: (d["pushes"][1].update(height_m=-1), d["pushes"][2].update(id="h450")))
    (twig_copy / "h450" / "shapes.csv").unlink()
    problems = validate_dataset(twig_copy)
    fields = {p.field for p in problems}
    assert {"pushes[1].height_m", "pushes[2].id", "file"} <= fields


def test_inputs_never_modified(twig_noisy):
    before = {p: p.read_bytes() for p in twig_noisy.rglob("*") if p.is_file()}
    validate_dataset(twig_noisy)
    read_dataset(twig_noisy)
    assert before == {p: p.read_bytes() for p in twig_noisy.rglob("*") if p.is_file()}


# --------------------------------------------------------------------------- #
# Fuzzing: any mutation of the files gives a dataset or a clear DatasetError
# --------------------------------------------------------------------------- #
_text = st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=40)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(line=st.integers(0, 70), new=_text, which=st.sampled_from(["h450/force.csv", "h550/shapes.csv"]))
def test_fuzz_csv_lines(twig_copy, line, new, which):
    path = twig_copy / which
    original = path.read_text()
    lines = original.splitlines()
    lines[min(line, len(lines) - 1)] = new
    path.write_text("\n".join(lines))
    try:
        read_dataset(twig_copy)
    except DatasetError as exc:
        assert str(exc)
    finally:
        path.write_text(original)


_json = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers() | _text,
    lambda children: st.lists(children, max_size=3) | st.dictionaries(_text, children, max_size=3),
    max_leaves=8,
)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    key=st.sampled_from(["format", "specimen", "species", "length_m", "sensor", "camera", "pushes", "x"]),
    value=_json,
    push_key=st.sampled_from(["id", "height_m", "direction", "force", "shapes", "frames"]),
    push_value=_json,
)
def test_fuzz_specimen_json(twig_copy, key, value, push_key, push_value):
    path = twig_copy / "specimen.json"
    original = path.read_text()
    doc = json.loads(original)
    doc[key] = value
    if isinstance(doc.get("pushes"), list) and doc["pushes"] and isinstance(doc["pushes"][0], dict):
        doc["pushes"][0][push_key] = push_value
    path.write_text(json.dumps(doc))
    try:
        read_dataset(twig_copy)
    except DatasetError as exc:
        assert str(exc)
    finally:
        path.write_text(original)


def test_bridged_points_are_kept_apart_from_the_data(twig_copy):
    """shapes.csv rows with observed = 0 (bridged across an occlusion) are not data points."""
    path = twig_copy / "h450" / "shapes.csv"
    lines = path.read_text().splitlines()
    t0 = lines[1].split(",")[0]
    first = [i for i, x in enumerate(lines) if i and x.split(",")[0] == t0]
    flags = ["0" if i in first[2:5] else "1" for i in range(1, len(lines))]
    path.write_text(
        "\n".join([lines[0] + ",observed"] + [x + "," + f for x, f in zip(lines[1:], flags, strict=True)]) + "\n"
    )
    frame = read_dataset(twig_copy).pushes[0].shapes[0]
    assert frame.bridge is not None and frame.bridge.shape == (3, 3)
    assert frame.x_m.size == len(first) - 3
    xs = np.array([float(lines[i].split(",")[1]) for i in first])
    np.testing.assert_array_equal(frame.bridge[0], xs[2:5])
    assert not np.isin(frame.x_m, xs[2:5]).any()


def test_append_rows_resumes_a_file_written_before_a_column_was_added(tmp_path):
    """A study resumed after its script gained a column keeps its old rows (new cells empty)."""
    from bayesrod.dataset.io import append_rows, read_rows

    path = tmp_path / "study.csv"
    list(append_rows(path, ["case", "x"], [{"case": "a", "x": 1}], new_file=True))
    list(append_rows(path, ["case", "x", "extra"], [{"case": "b", "x": 2, "extra": "e"}], new_file=False))
    rows = read_rows(path)
    assert [r["case"] for r in rows] == ["a", "b"]
    assert list(rows[0]) == ["case", "x", "extra"]
    assert rows[0]["extra"] == "" and rows[1]["extra"] == "e"
    with pytest.raises(ValueError, match="gone"):
        list(append_rows(path, ["case", "x"], [], new_file=False))


def test_a_path_with_a_nul_character_is_a_dataset_error_not_a_traceback(twig_copy):
    """Found by test_fuzz_specimen_json in a fresh clone (session 57): pathlib raised ValueError("embedded null
    byte") from inside the reader."""
    path = twig_copy / "specimen.json"
    doc = json.loads(path.read_text())
    doc["pushes"][0]["force"] = "\x00"
    path.write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match=r"pushes\[0\]\.force"):
        read_dataset(twig_copy)

"""Raw rig tables in: the table reader, `import table`, load/unload cycles, plausibility before a fit."""

import json
import shutil
import string
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bayesrod
from bayesrod.cli import main
from bayesrod.dataset import DatasetError, read_dataset, validate_dataset
from bayesrod.dataset.importers import split_cycles
from bayesrod.dataset.tables import read_table

REPO = Path(__file__).resolve().parents[1]
RIGS = REPO / "examples" / "rigs"
TRUTH = json.loads((RIGS / "TRUTH.json").read_text())

ARM = [
    "--time",
    "Time [ms]",
    "--time-unit",
    "ms",
    "--force",
    "Load [N]",
    "--angle",
    "Arm angle [deg]",
    "--arm-height",
    "0.5",
    "--height-m",
    "0.5",
    "--length-m",
    "0.9",
    "--specimen",
    "A-07",
]
UTM = [
    "--time",
    "Time",
    "--force",
    "Load",
    "--force-unit",
    "kN",
    "--displacement",
    "Extension",
    "--displacement-unit",
    "mm",
    "--height-m",
    "0.6",
    "--length-m",
    "0.9",
]
HAND = [
    "--time",
    "Zeit [s]",
    "--force",
    "Kraft [N]",
    "--displacement",
    "Weg [cm]",
    "--displacement-unit",
    "cm",
    "--height-m",
    "0.4",
    "--length-m",
    "0.9",
    "--specimen",
    "hh",
]


def _import(tmp_path, name, flags, *extra):
    out = tmp_path / name
    code = main(["import", "table", str(RIGS / name), "--out", str(out), *flags, *extra])
    return code, out


def test_rotating_arm_with_three_cycles_and_a_preload_imports_and_fits(tmp_path, capsys):
    code, out = _import(tmp_path, "darling_arm.txt", ARM)
    assert code == 0, capsys.readouterr().err
    ds = read_dataset(out / "A-07")
    assert [p.id for p in ds.pushes] == ["h500-c1", "h500-c2", "h500-c3"]
    doc = json.loads((out / "A-07" / "specimen.json").read_text())
    assert [p["cycle"] for p in doc["pushes"]] == [1, 2, 3]
    assert all(p["preload_N"] > 0.2 for p in doc["pushes"])  # the recording starts pressed
    assert all((out / "A-07" / p["unloading"]).is_file() for p in doc["pushes"])
    assert doc["provenance"]["source_files"] == ["darling_arm.txt"] and doc["provenance"]["options"]["angle"]
    for p in ds.pushes:  # each push is one loading ramp: the displacement only advances
        assert np.all(np.diff(p.force.robot_x_m) > -1e-4)
    warn = [str(p) for p in validate_dataset(out / "A-07")]
    assert any("preload" in w for w in warn) and not any(p.severity == "error" for p in validate_dataset(out / "A-07"))
    plain = bayesrod.fit(out / "A-07", use_shapes=False, progress=False, target_ess=150, max_steps=500)  # a verdict
    check = plain.to_dict()["model_check"]
    assert check["verdict"] == "misfit"  # a preloaded push is not the plain model ...
    assert check["pushes_starting_loaded"] == ["h500-c1", "h500-c2", "h500-c3"]  # ... and the user is told why
    assert "start loaded: fit each push's preload" in check["message"], check["message"]
    pre = bayesrod.fit(out / "A-07", use_shapes=False, progress=False, target_ess=150, max_steps=1500, preload=True)
    s = pre.summary()
    truth = TRUTH["preload_displacement_m"]["darling_arm.txt"]
    for name in [n for n in s.index if n.startswith("preload_m_")]:
        assert abs(s.loc[name, "median"] - truth) < 0.001, s
    assert s.loc["EI0", "q05"] <= TRUTH["EI0"] <= s.loc["EI0", "q95"], s
    assert pre.to_dict()["model_check"]["verdict"] == "ok"
    # --cycles first keeps the first ramp only
    code, first = _import(tmp_path / "f", "darling_arm.txt", ARM, "--cycles", "first")
    assert code == 0 and len(read_dataset(first / "A-07").pushes) == 1


@pytest.mark.parametrize("name,flags", [("utm_instron.csv", UTM), ("handheld_gauge.csv", HAND)])
def test_device_tables_round_trip_and_recover_EI0(tmp_path, name, flags, capsys):
    code, out = _import(tmp_path, name, flags)
    assert code == 0, capsys.readouterr().err
    ds_dir = next(p for p in out.iterdir() if p.is_dir())
    ds = read_dataset(ds_dir)
    assert len(ds.pushes) == 1 and ds.pushes[0].height_m == TRUTH["heights_m"][name]
    post = bayesrod.fit(ds, use_shapes=False, progress=False, target_ess=200, max_steps=2000)
    q = post.summary().loc["EI0"]
    assert q["q05"] <= TRUTH["EI0"] <= q["q95"], q
    assert q["q95"] / q["q05"] < 3  # an interval that says something


@pytest.mark.parametrize(
    "time_unit,force_unit,disp_unit",
    [("ms", "lbf", "in"), ("min", "ozf", "um"), ("s", "kgf", "cm"), ("s", "mN", "mm")],
)
def test_every_unit_converts_to_the_same_push(tmp_path, time_unit, force_unit, disp_unit):
    """One push written in SI and again in other units (a US testing machine's lbf and inches, ...) imports
    to the same forces, displacements and times; the factors are the exact ones (international inch and
    pound, standard gravity)."""
    from bayesrod.dataset.importers import DISPLACEMENT_UNITS, FORCE_UNITS, TIME_UNITS

    assert FORCE_UNITS["lbf"] == pytest.approx(4.4482216152605, rel=1e-13)
    assert FORCE_UNITS["ozf"] == pytest.approx(0.27801385095378, rel=1e-13)
    assert FORCE_UNITS["kgf"] == 9.80665 and DISPLACEMENT_UNITS["in"] == 0.0254 and TIME_UNITS["min"] == 60.0
    t = np.linspace(0.0, 6.0, 61)
    x = 0.01 * t  # 10 mm/s, contact at 10 mm (the load cell reads 0.05 N before it)
    F = 0.05 + 25.0 * np.clip(x - 0.01, 0.0, None)
    tables = {}
    for name, (tu, fu, du) in {"si": ("s", "N", "m"), "other": (time_unit, force_unit, disp_unit)}.items():
        path = tmp_path / f"{name}.csv"
        cols = np.column_stack([t / TIME_UNITS[tu], F / FORCE_UNITS[fu], x / DISPLACEMENT_UNITS[du]])
        np.savetxt(path, cols, delimiter=",", header="t,load,travel", comments="", fmt="%.15g")
        opts = dict(time="t", force="load", displacement="travel", height_m=0.5, length_m=0.9, specimen=name)
        imp = bayesrod.import_table(path, time_unit=tu, force_unit=fu, displacement_unit=du, **opts)
        tables[name] = read_dataset(imp.save(tmp_path / f"out-{name}") / name).pushes[0].force
    a, b = tables["si"], tables["other"]
    for col in ("time_s", "force_N", "robot_x_m"):
        np.testing.assert_allclose(getattr(b, col), getattr(a, col), rtol=1e-9, atol=1e-12)
    assert a.force_N.max() == pytest.approx(25.0 * 0.05, abs=0.01)  # tared, counted from contact
    assert a.robot_x_m.max() == pytest.approx(0.05, abs=1e-3)


def test_instron_units_row_is_skipped_and_reported(tmp_path):
    code, out = _import(tmp_path, "utm_instron.csv", UTM)
    rep = json.loads((out / "import_report.json").read_text())["files"][0]
    assert rep["header_line"] == 4 and rep["delimiter"] == "comma" and len(rep["metadata_lines"]) == 3
    assert rep["rows_skipped"] == [{"line": 5, "reason": "column 'Time': '(s)' is not a finite number"}]


def test_handheld_semicolons_and_decimal_commas(tmp_path):
    code, out = _import(tmp_path, "handheld_gauge.csv", HAND)
    rep = json.loads((out / "import_report.json").read_text())["files"][0]
    assert rep["delimiter"] == "semicolon" and rep["decimal"] == ","
    ds = read_dataset(out / "hh")
    assert 0.03 < ds.pushes[0].force.robot_x_m.max() < 0.05  # cm converted to m, onset removed


def test_metadata_table_and_folder_make_one_dataset_per_specimen(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for k in range(2):
        shutil.copy(RIGS / "handheld_gauge.csv", src / f"push{k}.csv")
    meta = tmp_path / "meta.csv"
    meta.write_text("file,height_m,specimen,species\npush0.csv,0.4,s1,oak\npush1.csv,0.5,s1,oak\n")
    out = tmp_path / "out"
    flags = [f for f in HAND if f not in ("--height-m", "0.4", "--specimen", "hh")]
    assert main(["import", "table", str(src), "--out", str(out), *flags, "--metadata", str(meta)]) == 0
    ds = read_dataset(out / "s1")
    assert ds.species == "oak" and sorted(p.height_m for p in ds.pushes) == [0.4, 0.5]


def test_bare_force_still_replaces_out(tmp_path):
    code, out = _import(tmp_path, "handheld_gauge.csv", HAND)
    assert code == 0
    code, _ = _import(tmp_path, "handheld_gauge.csv", HAND)
    assert code == 2  # out not empty
    code, _ = _import(tmp_path, "handheld_gauge.csv", HAND, "--replace")
    assert code == 0


def test_import_errors_are_one_line(tmp_path, capsys):
    no_height = [f for f in HAND if f not in ("--height-m", "0.4")]
    code, _ = _import(tmp_path, "handheld_gauge.csv", no_height)
    err = capsys.readouterr().err
    assert code == 2 and "--height-m: expected a number > 0, got None" in err and "Traceback" not in err
    no_length = [f for f in HAND if f not in ("--length-m", "0.9")]
    code, _ = _import(tmp_path / "l", "handheld_gauge.csv", no_length)
    err = capsys.readouterr().err
    assert code == 2 and "--length-m: expected the stem length, got none" in err
    bad = [*HAND]
    bad[bad.index("Kraft [N]")] = "Force"
    code, _ = _import(tmp_path / "b", "handheld_gauge.csv", bad)
    err = capsys.readouterr().err
    assert code == 2 and "expected a header row naming the columns" in err and "'Force'" in err


# --------------------------------------------------------------------------- cycles and plausibility
def _push_dataset(tmp_path, F, x, name="ds"):
    d = tmp_path / name
    (d / "p1").mkdir(parents=True)
    t = np.arange(len(F)) * 0.1
    lines = ["time_s,force_N,robot_x_m"] + [f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(t, F, x, strict=True)]
    (d / "p1" / "force.csv").write_text("\n".join(lines) + "\n")
    doc = {
        "format": "bayesrod.dataset/1",
        "specimen": "s",
        "length_m": 0.9,
        "pushes": [{"id": "p1", "height_m": 0.5, "force": "p1/force.csv"}],
    }
    (d / "specimen.json").write_text(json.dumps(doc))
    return d


def _ramp(n=60, rng=None):
    rng = rng or np.random.default_rng(0)
    x = np.linspace(0, 0.06, n)
    return bayesrod.force_from_displacement(x, 0.5, 1.8, 0.5, 0.9).force_N + rng.normal(0, 0.01, n), x


def test_a_clean_push_is_valid(tmp_path):
    F, x = _ramp()
    assert not [p for p in validate_dataset(_push_dataset(tmp_path, F, x)) if p.severity == "error"]


def test_an_unsplit_cycled_recording_is_refused_naming_the_row(tmp_path, capsys):
    F, x = _ramp(40)
    Fc = np.concatenate([F, F[::-1][1:], F[1:]])
    xc = np.concatenate([x, x[::-1][1:], x[1:]])
    d = _push_dataset(tmp_path, Fc, xc)
    errs = [str(p) for p in validate_dataset(d) if p.severity == "error"]
    assert len(errs) == 1 and "push p1" in errs[0] and "reverses" in errs[0] and "row 4" in errs[0], errs
    row = int(errs[0].split("row ")[1].split(":")[0])
    assert 41 <= row <= 44  # the first samples of the unloading leg
    assert main(["fit", str(d), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "reverses" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    segs = split_cycles(xc)
    assert [s.loading for s in segs] == [True, False, True]


@pytest.mark.parametrize(
    "case,needle",
    [
        ("zero", "never loaded the stem"),
        ("flipped", "negative forces"),
        ("huge", "no stem push is larger"),
        ("far", "the stem slips long before"),
    ],
)
def test_implausible_pushes_are_refused_naming_the_push(tmp_path, capsys, case, needle):
    F, x = _ramp()
    F, x = {"zero": (0 * F, x), "flipped": (-F, x), "huge": (np.full_like(F, 1e308), x), "far": (F, x * 100)}[case]
    d = _push_dataset(tmp_path, F, x)
    errs = [str(p) for p in validate_dataset(d) if p.severity == "error"]
    assert errs and all("(push p1)" in e for e in errs) and any(needle in e for e in errs), errs
    with pytest.raises(DatasetError, match=needle):
        bayesrod.fit(d, progress=False)
    assert main(["validate", str(d)]) == 1
    assert main(["fit", str(d), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert needle in err and "p grid" not in err and "Traceback" not in err


def test_a_preloaded_start_is_a_warning_not_an_error(tmp_path):
    F, x = _ramp()
    d = _push_dataset(tmp_path, F[10:], x[10:] - x[10])
    probs = validate_dataset(d)
    assert [p.severity for p in probs] == ["warning"] and "preload" in str(probs[0])


def test_in_memory_datasets_get_the_same_checks():
    F, x = _ramp()
    ds = bayesrod.Dataset.from_arrays(length_m=0.9, height_m=[0.5], displacement_m=[x], force_N=[-F])
    assert any("negative forces" in str(p) for p in ds.validate())


# --------------------------------------------------------------------------- the reader, fuzzed
_TEXT = st.text(alphabet=string.ascii_letters + " :=#-_/()", min_size=0, max_size=30)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    delim=st.sampled_from([",", ";", "\t", "|"]),
    comma_decimal=st.booleans(),
    n_meta=st.integers(0, 5),
    meta=st.lists(_TEXT, min_size=5, max_size=5),
    values=st.lists(
        st.tuples(
            st.floats(-1e6, 1e6, allow_nan=False),
            st.floats(-1e6, 1e6, allow_nan=False),
            st.floats(-1e6, 1e6, allow_nan=False),
        ),
        min_size=1,
        max_size=30,
    ),
    garbage=st.lists(st.tuples(st.integers(0, 40), _TEXT), max_size=4),
    extra_col_first=st.booleans(),
)
def test_table_reader_never_shifts_a_column(delim, comma_decimal, n_meta, meta, values, garbage, extra_col_first):
    dec = "," if comma_decimal and delim != "," else "."

    def cell(v):
        s = repr(float(v))
        return s.replace(".", ",") if dec == "," else s

    names = ["time", "force", "disp"]
    header = (["note"] if extra_col_first else []) + names
    rows = [((["x"] if extra_col_first else []) + [cell(a), cell(b), cell(c)]) for a, b, c in values]
    lines = [m for m in meta[:n_meta] if not any(n in m for n in names)]
    lines.append(delim.join(header))
    body = [delim.join(r) for r in rows]
    for pos, junk in sorted(garbage, reverse=True):
        body.insert(min(pos, len(body)), junk)
    text = "\n".join(lines + body) + "\n"
    # every written row is numeric and the garbage lines hold no digits: the reader must find them all
    tab = read_table(text, ["disp", "time", "force"], name="fuzz")
    got = np.column_stack([tab.columns["time"], tab.columns["force"], tab.columns["disp"]])
    want = np.array(values, float)
    # every row read is one of the written rows, in order, with its columns in place
    j = 0
    for r in got:
        while j < len(want) and not np.allclose(want[j], r, rtol=1e-12, atol=0):
            j += 1
        assert j < len(want), (r, want)
        j += 1
    assert tab.n_rows == len(values)


def test_stem_and_condition_come_from_the_importer_and_group_the_datasets(tmp_path, capsys):
    """A brace-root style series imported without hand edits: per-file stem_id and condition from --metadata."""
    import shutil

    from bayesrod.api.group import find_groups

    src = tmp_path / "src"
    src.mkdir()
    for cond in ("intact", "cut1"):
        shutil.copy(RIGS / "utm_instron.csv", src / f"stalk7_{cond}.csv")
    meta = tmp_path / "meta.csv"
    meta.write_text(
        "file,stem_id,condition,specimen\n"
        "stalk7_intact.csv,stalk7,intact,stalk7-intact\n"
        "stalk7_cut1.csv,stalk7,cut1,stalk7-cut1\n"
    )
    out = tmp_path / "out"
    code = main(["import", "table", str(src), "--out", str(out), *UTM, "--metadata", str(meta)])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "stalk7-cut1" / "specimen.json").read_text())
    assert doc["stem_id"] == "stalk7" and doc["condition"] == "cut1"
    groups, problems = find_groups(out)
    assert list(groups) == ["stalk7"] and sorted(groups["stalk7"]) == ["cut1", "intact"] and problems == []


# --------------------------------------------------------------------------- long tables of many pushes
def _long_table(path, recordings, header, sep=";"):
    """One table holding many recordings: each is (leading id cells, force, position in mm); its time restarts
    at 0. Returns the file line of each recording's first data row."""
    lines, first = [sep.join(header), sep.join("" for _ in header)], []  # a blank-celled units row, skipped
    for ids, F, x_mm in recordings:
        first.append(len(lines) + 1)
        lines += [
            sep.join([*ids, f"{0.1 * i:.2f}", f"{f:.6f}", f"{x:.4f}"])
            for i, (f, x) in enumerate(zip(F, x_mm, strict=True))
        ]
    path.write_text("\n".join(lines) + "\n")
    return first


def test_a_long_table_splits_into_one_dataset_per_stem_and_condition(tmp_path, capsys):
    """A brace-root style long table (plant, treatment, time, load, position: two plants, two treatments, one
    push each, in one file) imports into one dataset per plant and treatment, grouped for fit-group, every
    force as written, every row traced to its line; a row without its plant is skipped and reported."""
    from bayesrod.api.group import find_groups

    rng = np.random.default_rng(3)
    recs = []
    for plant in ("P1", "P2"):
        for treat, EI in (("intact", 1.8), ("cut", 1.1)):
            x = np.linspace(0.0, 0.05, 40)
            F = bayesrod.force_from_displacement(x, 0.5, EI, 0.5, 0.9).force_N + rng.normal(0, 0.005, x.size)
            recs.append(((plant, treat), F, 1000 * x))
    src = tmp_path / "series.csv"
    first = _long_table(src, recs, ["Plant", "Treatment", "Time (s)", "Load (N)", "Position (mm)"])
    text = src.read_text().splitlines()
    text.insert(first[2] + 3, ";cut;9.99;0.5;1.0")  # a row without its plant, amid P2's intact push
    src.write_text("\n".join(text) + "\n")
    out = tmp_path / "out"
    flags = ["--time", "Time (s)", "--force", "Load (N)", "--displacement", "Position (mm)"]
    flags += ["--displacement-unit", "mm", "--height-m", "0.5", "--length-m", "0.9"]
    code = main(
        ["import", "table", str(src), "--out", str(out), *flags, "--stem-id-column", "Plant"]
        + ["--condition-column", "Treatment"]
    )
    assert code == 0, capsys.readouterr().err
    groups, problems = find_groups(out)
    assert problems == [] and {k: sorted(v) for k, v in groups.items()} == {
        "P1": ["cut", "intact"],
        "P2": ["cut", "intact"],
    }
    for k, ((plant, treat), F, _) in enumerate(recs):
        ds = read_dataset(out / f"{plant}_{treat}")
        assert (ds.extra["stem_id"], ds.extra["condition"]) == (plant, treat)
        (push,) = ds.pushes
        np.testing.assert_allclose(push.force.force_N, F, atol=5e-7)
        doc = json.loads((out / f"{plant}_{treat}" / "specimen.json").read_text())
        start, end = first[k] + (k >= 3), first[k] + len(F) - 1 + (k >= 2)  # the inserted row shifts the rest
        assert doc["pushes"][0]["source_rows"] == [start, end]
    report = json.loads((out / "import_report.json").read_text())
    skipped = [r for f in report["files"] for r in f["rows_skipped"]]
    assert [r["line"] for r in skipped] == [2, first[2] + 4]  # the units row and the row without a plant
    assert "column 'Plant'" in skipped[1]["reason"] and "empty" in skipped[1]["reason"]
    assert [f["group"] for f in report["files"]][1] == {"stem_id": "P1", "condition": "cut"}


def test_a_long_table_with_a_height_column_makes_one_dataset_of_several_heights(tmp_path, capsys):
    """One stem pushed at three heights (in cm, a column), twice at 50 cm (a test column): one dataset, four
    pushes at their heights, each naming its test; a height given twice, or a height of 0, is refused in one
    line naming the file, the column and the recording."""
    recs = []
    for test, h_cm in (("t1", 40), ("t2", 50), ("t3", 50), ("t4", 60)):
        x = np.linspace(0.0, 0.04, 30)
        F = bayesrod.force_from_displacement(x, h_cm / 100, 1.8, 0.5, 0.9).force_N
        recs.append(((test, str(h_cm)), F, 1000 * x))
    src = tmp_path / "heights.csv"
    _long_table(src, recs, ["Test", "Height (cm)", "Time (s)", "Load (N)", "Position (mm)"], sep=",")
    flags = ["--time", "Time (s)", "--force", "Load (N)", "--displacement", "Position (mm)"]
    flags += ["--displacement-unit", "mm", "--length-m", "0.9", "--specimen", "stem9"]
    out = tmp_path / "out"
    long = ["--test-column", "Test", "--height-column", "Height (cm)", "--height-unit", "cm"]
    assert main(["import", "table", str(src), "--out", str(out), *flags, *long]) == 0, capsys.readouterr().err
    doc = json.loads((out / "stem9" / "specimen.json").read_text())
    got = [(p["id"], p["height_m"], p["source_test"]) for p in doc["pushes"]]
    assert got == [("h400", 0.4, "t1"), ("h500", 0.5, "t2"), ("h500-2", 0.5, "t3"), ("h600", 0.6, "t4")]
    assert doc["provenance"]["source_files"] == ["heights.csv"]  # once, for its four recordings
    assert main(["import", "table", str(src), "--out", str(tmp_path / "o2"), *flags, *long, "--height-m", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "--height-m: expected either one contact height or a height column ('Height (cm)'), got both" in err
    src.write_text(src.read_text().replace("t4,60,", "t4,0,"))
    assert main(["import", "table", str(src), "--out", str(tmp_path / "o3"), *flags, *long]) == 2
    err = capsys.readouterr().err
    assert "heights.csv (Test = t4, Height (cm) = 0): column 'Height (cm)': height_m: expected a number > 0" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    src.write_text(src.read_text().replace("t4,0,", "t4,-60,"))  # named as the column holds it, in cm
    assert main(["import", "table", str(src), "--out", str(tmp_path / "o4"), *flags, *long]) == 2
    assert "(Test = t4, Height (cm) = -60)" in capsys.readouterr().err


def test_two_tests_of_one_stem_without_a_test_column_are_refused_at_the_row_where_time_restarts(tmp_path, capsys):
    x = np.linspace(0.0, 0.04, 30)
    F = bayesrod.force_from_displacement(x, 0.5, 1.8, 0.5, 0.9).force_N
    src = tmp_path / "twice.csv"
    first = _long_table(src, [(("S1",), F, 1000 * x)] * 2, ["Stem", "Time (s)", "Load (N)", "Position (mm)"])
    flags = ["--time", "Time (s)", "--force", "Load (N)", "--displacement", "Position (mm)", "--displacement-unit"]
    flags += ["mm", "--height-m", "0.5", "--length-m", "0.9", "--stem-id-column", "Stem"]
    assert main(["import", "table", str(src), "--out", str(tmp_path / "o"), *flags]) == 2
    err = capsys.readouterr().err
    assert (
        f"twice.csv (Stem = S1), line {first[1]}: column 'Time (s)': expected increasing times, got 0 after 2.9" in err
    )
    assert "--test-column" in err and len(err.strip().splitlines()) == 1


def test_a_table_without_time_and_a_rig_counting_the_push_as_negative(tmp_path, capsys):
    """Force and displacement only, the displacement falling as the push advances: refused with the flag that
    fixes it named; with --displacement-sign -1 and no --time, the same push as the positive table's, the
    sample index as its time and the assumption recorded."""
    x = np.linspace(0.0, 0.04, 30)
    F = bayesrod.force_from_displacement(x, 0.5, 1.8, 0.5, 0.9).force_N
    for name, sign in (("pos.csv", 1), ("neg.csv", -1)):
        lines = ["Load (N),Stroke (mm)"] + [f"{f:.6f},{sign * 1000 * d:.4f}" for f, d in zip(F, x, strict=True)]
        (tmp_path / name).write_text("\n".join(lines) + "\n")
    flags = ["--force", "Load (N)", "--displacement", "Stroke (mm)", "--displacement-unit", "mm"]
    flags += ["--height-m", "0.5", "--length-m", "0.9"]
    assert main(["import", "table", str(tmp_path / "neg.csv"), "--out", str(tmp_path / "bad"), *flags]) == 2
    err = capsys.readouterr().err
    assert "expected at least one loading ramp" in err and "needs --displacement-sign -1" in err
    outs = {}
    for name, extra in (("pos.csv", []), ("neg.csv", ["--displacement-sign", "-1"])):
        out = tmp_path / f"out-{name}"
        assert main(["import", "table", str(tmp_path / name), "--out", str(out), *flags, *extra]) == 0
        outs[name] = read_dataset(out / Path(name).stem).pushes[0].force
    for col in ("time_s", "force_N", "robot_x_m"):
        np.testing.assert_array_equal(getattr(outs["neg.csv"], col), getattr(outs["pos.csv"], col))
    np.testing.assert_array_equal(outs["pos.csv"].time_s, np.arange(30.0))
    doc = json.loads((tmp_path / "out-neg.csv" / "neg" / "specimen.json").read_text())
    assert "sample index" in doc["provenance"]["assumptions"]["time_s"]
    assert doc["provenance"]["options"]["displacement_sign"] == -1


def test_a_long_tables_stems_take_their_own_length_and_species_from_metadata_keyed_by_stem(tmp_path, capsys):
    """Plants of different lengths in one long table: a metadata CSV keyed by stem_id gives each its own length
    and species (every condition of the plant); a CSV naming none of file, stem_id, specimen is refused."""
    recs = []
    for plant, L in (("P1", 0.9), ("P2", 1.1)):
        for treat in ("intact", "cut"):
            x = np.linspace(0.0, 0.04, 30)
            recs.append(((plant, treat), bayesrod.force_from_displacement(x, 0.5, 1.8, 0.5, L).force_N, 1000 * x))
    src = tmp_path / "series.csv"
    _long_table(src, recs, ["Plant", "Treatment", "Time (s)", "Load (N)", "Position (mm)"])
    meta = tmp_path / "plants.csv"
    meta.write_text("stem_id,length_m,species\nP1,0.9,Zea mays\nP2,1.1,Zea mays\n")
    flags = ["--time", "Time (s)", "--force", "Load (N)", "--displacement", "Position (mm)", "--displacement-unit"]
    flags += ["mm", "--height-m", "0.5", "--stem-id-column", "Plant", "--condition-column", "Treatment"]
    out = tmp_path / "out"
    assert main(["import", "table", str(src), "--out", str(out), *flags, "--metadata", str(meta)]) == 0
    for plant, L in (("P1", 0.9), ("P2", 1.1)):
        for treat in ("intact", "cut"):
            ds = read_dataset(out / f"{plant}_{treat}")
            assert ds.length_m == L and ds.species == "Zea mays" and ds.extra["stem_id"] == plant
    meta.write_text("plant,length_m\nP1,0.9\n")
    assert main(["import", "table", str(src), "--out", str(tmp_path / "o2"), *flags, "--metadata", str(meta)]) == 2
    assert (
        "expected a header with a column named file, stem_id or specimen, got plant, length_m"
        in capsys.readouterr().err
    )


def test_the_unit_factors_are_the_exact_si_ones():
    """Every factor the importer offers, against its definition (the round trip above writes its files
    with the same table, so it cannot see a wrong factor by itself)."""
    from bayesrod.dataset.importers import ANGLE_UNITS, DISPLACEMENT_UNITS, FORCE_UNITS, TIME_UNITS

    assert TIME_UNITS == {"s": 1.0, "ms": 1e-3, "min": 60.0}
    g, lb = 9.80665, 0.45359237
    want = {"N": 1.0, "mN": 1e-3, "kN": 1e3, "gf": g / 1e3, "kgf": g, "lbf": lb * g, "ozf": lb * g / 16}
    assert FORCE_UNITS == pytest.approx(want, rel=1e-15)
    assert DISPLACEMENT_UNITS == pytest.approx({"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254}, rel=1e-15)
    assert ANGLE_UNITS == pytest.approx({"deg": np.pi / 180, "rad": 1.0}, rel=1e-15)


def test_a_rotating_arm_advances_the_contact_by_its_length_times_the_sine_of_its_turn(tmp_path):
    """A 0.4 m arm turned from 10 to 50 degrees: the contact advances 0.4 (sin(a - 10 deg)), not the arc
    0.4 (a - 10 deg) (8% apart at the end of the turn)."""
    t = np.linspace(0.0, 4.0, 81)
    a = 10.0 + 10.0 * t  # degrees
    x = 0.4 * np.sin(np.radians(a - 10.0))
    F = 0.05 + 8.0 * np.clip(x - 0.02, 0.0, None)
    path = tmp_path / "arm.csv"
    np.savetxt(path, np.column_stack([t, F, a]), delimiter=",", header="t,load,angle", comments="", fmt="%.15g")
    opts = dict(time="t", force="load", angle="angle", arm_height_m=0.4, height_m=0.4, length_m=0.9, specimen="arm")
    imp = bayesrod.import_table(path, **opts)
    push = read_dataset(imp.save(tmp_path / "out") / "arm").pushes[0].force
    assert push.robot_x_m.max() == pytest.approx(x.max() - 0.02, abs=2e-3)  # counted from contact at 0.02 m
    assert 0.4 * np.radians(40.0) - 0.02 - push.robot_x_m.max() > 0.02  # the arc would be 0.259 m


@pytest.mark.parametrize("tare", ["auto", "none"])
def test_load_unload_cycles_share_the_recordings_clock_the_contact_origin_and_the_tare(tmp_path, tare):
    """Two load/unload cycles of a sensor reading 0.05 N before contact (at 10 mm, 25 N/m after): each loading
    ramp and its unloading.csv are counted from the contact's position and the recording's first time (3 s),
    and both are tared by the baseline, unless ``tare="none"`` (then the 0.05 N stays, reported as a preload)."""
    up = np.linspace(0.0, 0.06, 61)
    x = np.concatenate([up, up[::-1][1:], up[1:], up[::-1][1:]])
    t = 3.0 + 0.1 * np.arange(x.size)
    F = 0.05 + 25.0 * np.clip(x - 0.01, 0.0, None) + 1e-4 * np.sin(np.arange(x.size))
    path = tmp_path / "cycles.csv"
    np.savetxt(path, np.column_stack([t, F, x]), delimiter=",", header="t,load,travel", comments="", fmt="%.15g")
    opts = dict(time="t", force="load", displacement="travel", height_m=0.5, length_m=0.9, specimen="c", tare=tare)
    out = bayesrod.import_table(path, **opts).save(tmp_path / "out") / "c"
    doc = json.loads((out / "specimen.json").read_text())
    offset = 0.05 if tare == "none" else 0.0
    for k, (push, entry) in enumerate(zip(read_dataset(out).pushes, doc["pushes"], strict=True)):
        f, start = push.force, 1.0 + 12.0 * k  # contact at 10 mm: 1 s into each 12 s cycle
        assert f.time_s[0] == pytest.approx(start, abs=0.06) and f.time_s[-1] == pytest.approx(start + 5.0, abs=1e-9)
        assert f.robot_x_m[0] == pytest.approx(0.0, abs=1e-3) and f.robot_x_m[-1] == pytest.approx(0.05, abs=1e-3)
        assert f.force_N[0] == pytest.approx(offset, abs=2e-3)
        assert f.force_N[-1] == pytest.approx(1.25 + offset, abs=2e-3)
        assert entry.get("preload_N", 0.0) == pytest.approx(offset, abs=2e-3)
        u = np.genfromtxt(out / entry["unloading"], delimiter=",", names=True)
        assert u["time_s"][[0, -1]] == pytest.approx([start + 5.0, start + 11.0], abs=1e-9)
        assert u["robot_x_m"][[0, -1]] == pytest.approx([0.05, -0.01], abs=1e-3)
        assert u["force_N"][[0, -1]] == pytest.approx([1.25 + offset, offset], abs=2e-3)


def test_the_reader_skips_non_finite_cells_and_rows_of_another_width_and_reads_decimal_commas_anywhere():
    """A cell reading nan or inf is no measurement; a row with more fields than the header is not read by position;
    the decimal mark is read from up to 200 rows (a table whose first rows are whole numbers still has its commas
    read); a tie between comma and dot decimals reads commas (a dot decimal parses either way); a header naming a
    column twice is refused."""
    from bayesrod.dataset.tables import read_table

    t = read_table("t;F\n0;0\n1;nan\n2;inf\n3;1;9\n4;2\n", ["t", "F"], name="rig.csv")
    np.testing.assert_array_equal(t.columns["t"], [0.0, 4.0])
    assert t.skipped == (
        (3, "column 'F': 'nan' is not a finite number"),
        (4, "column 'F': 'inf' is not a finite number"),
        (5, "3 fields, the header has 2"),
    )
    rows = "".join(f"{k};{k}\n" for k in range(5)) + "5;2,5\n6;3,25\n"  # whole numbers first, then commas
    t = read_table("t;F\n" + rows, ["t", "F"], name="rig.csv")
    assert t.decimal == "," and t.columns["F"][-2:].tolist() == [2.5, 3.25] and not t.skipped
    t = read_table("t;F\n0,5;1.5\n", ["t", "F"], name="rig.csv")  # one of each: both read
    assert t.decimal == "," and (t.columns["t"][0], t.columns["F"][0]) == (0.5, 1.5)
    assert read_table("t;F\n0;1\n1;2\n", ["t", "F"], name="rig.csv").decimal == "."  # whole numbers say nothing
    with pytest.raises(ValueError, match=r"rig.csv, line 1: column 'F': expected each column once, got it twice"):
        read_table("t;F;F\n0;1;2\n", ["t", "F"], name="rig.csv")

"""scripts/mutant_sweep.py, the survivor classifier of the solver's core: it applies a diff where mutmut made
it and calls a changed number changed (a classifier that called everything "same" would hide missing tests)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("mutant_sweep", REPO / "scripts" / "mutant_sweep.py")
M = importlib.util.module_from_spec(spec)
spec.loader.exec_module(M)

SOURCE = """def _a(x):
    y = x + 1
    return y


def _b(x):
    y = x + 1
    return y
""".splitlines(keepends=True)


def test_a_diff_is_applied_inside_its_own_function_only():
    diff = ["-    y = x + 1", "+    y = x - 1"]
    (way,) = M.candidates(SOURCE, "pkg.mod.x__b__mutmut_3", diff)
    assert way[1] == "    y = x + 1\n" and way[6] == "    y = x - 1\n"
    (way,) = M.candidates(SOURCE, "pkg.mod.x__a__mutmut_1", diff)
    assert way[1] == "    y = x - 1\n" and way[6] == "    y = x + 1\n"
    assert M.candidates(SOURCE, "pkg.mod.x__a__mutmut_1", ["-    y = x * 2", "+    y = x"]) == []
    with pytest.raises(ValueError, match="mutant"):
        M.candidates(SOURCE, "not-a-mutant", diff)


def test_compare_tells_changed_flags_values_and_nans_from_round_off():
    ref = {"a/found": np.array([True, False]), "a/f": np.array([1.0, np.nan])}
    assert M.compare(ref, {"a/found": ref["a/found"], "a/f": np.array([1.0 + 1e-12, np.nan])}, 1e-9)[0]
    assert not M.compare(ref, {"a/found": np.array([True, True]), "a/f": ref["a/f"]}, 1e-9)[0]
    assert not M.compare(ref, {"a/found": ref["a/found"], "a/f": np.array([1.0 + 1e-6, np.nan])}, 1e-9)[0]
    assert not M.compare(ref, {"a/found": ref["a/found"], "a/f": np.array([1.0, 2.0])}, 1e-9)[0]
    assert not M.compare(ref, {"a/found": ref["a/found"]}, 1e-9)[0]

"""Every example runs as a user would start it (examples/), from an empty directory."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: run with ``pytest -m slow``: examples of a minute or more (several fits, or shapes), and fit_from_arrays
#: (about 30 s, which the default run's 10-minute budget could not hold on 2026-11-25)
SLOW_EXAMPLES = {
    "choose_next_height.py",
    "compare_species.py",
    "diagnose_misfit.py",
    "fit_from_arrays.py",
    "predict_new_height.py",
    "quickstart.py",
    "stem_conditions.py",
}


@pytest.mark.parametrize(
    "script",
    [
        pytest.param(p.name, marks=[pytest.mark.slow] if p.name in SLOW_EXAMPLES else [])
        for p in sorted((REPO / "examples").glob("*.py"))
    ],
)
def test_examples_run(script, tmp_path):
    """Every example runs as a user would start it, from an empty directory, and writes nothing there."""
    res = subprocess.run(
        [sys.executable, str(REPO / "examples" / script)], cwd=tmp_path, capture_output=True, text=True, timeout=900
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() and list(tmp_path.iterdir()) == []

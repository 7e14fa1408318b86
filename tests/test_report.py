"""The HTML report renders in headless Chromium with its figures (issue 6); skipped without Chromium."""

import importlib.util
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("check_report_render", REPO / "scripts" / "check_report_render.py")
render = importlib.util.module_from_spec(spec)
spec.loader.exec_module(render)

needs_chromium = pytest.mark.skipif(render.chromium() is None, reason="chromium not installed (apt install chromium)")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    import bayesrod

    out = tmp_path_factory.mktemp("run") / "run"
    bayesrod.fit(
        REPO / "bayesrod" / "data" / "default", use_shapes=False, progress=False, target_ess=450, max_steps=3000
    ).save(out)
    return out


def test_report_is_self_contained(run_dir):
    html = (run_dir / "report.html").read_text()
    assert len(re.findall(r'<img [^>]*src="data:image/png;base64,', html)) >= 4
    assert 'src="http' not in html and "Assumptions" in html and "Converged" in html


@needs_chromium
def test_report_renders_with_figures(run_dir, tmp_path):
    res = render.check(run_dir / "report.html", tmp_path / "shot.png")
    assert res["ok"], res
    broken = tmp_path / "broken.html"
    broken.write_text(re.sub(r"base64,[A-Za-z0-9+/=]*", "base64,", (run_dir / "report.html").read_text()))
    assert not render.check(broken)["ok"]  # the check can fail


def test_the_report_reads_the_fits_own_convergence_verdict(run_dir):
    """The verdict is summary.json's ``converged`` (R-hat with the ensembles as chains, the walkers' guard, ESS,
    50 tau, no walker stuck), with its message when not; R-hat and ESS alone only where a summary lacks it."""
    import json

    from bayesrod.report.html import fit_report

    s = json.loads((run_dir / "summary.json").read_text())
    conv = {**s["convergence"], "rhat_max": 1.002, "ess_bulk_min": 5000.0}
    msg = "not converged within 3000 steps (2 walker(s) stuck in a far worse region): rerun"
    told = fit_report({**s, "convergence": {**conv, "converged": False, "message": msg}}, {})
    assert "Not converged" in told and "2 walker(s) stuck" in told and "Converged:" not in told
    assert "Converged:" in fit_report({**s, "convergence": {**conv, "converged": True}}, {})
    old = {k: v for k, v in conv.items() if k not in ("converged", "message")}
    assert "Converged:" in fit_report({**s, "convergence": old}, {})
    assert "Not converged" in fit_report({**s, "convergence": {**old, "rhat_max": 1.02}}, {})


def test_the_reports_tables_are_the_summarys_numbers_under_the_level_it_states(run_dir):
    """Each posterior and k_theta row shows summary.json's median, q05 and q95 in that order under the headers
    the level gives (5% and 95% at 0.9); the modulus table in GPa and mm."""
    import json

    from bayesrod.report.html import _modulus_section, fit_report

    s = json.loads((run_dir / "summary.json").read_text())
    html = fit_report(s, {})
    assert "Posterior (median and 90% credible interval)" in html
    assert html.count("<th>median</th><th>5%</th><th>95%</th>") >= 2
    cells = re.findall(r"<tr><td>([^<]*)</td><td>([^<]*)</td><td>([^<]*)</td><td>([^<]*)</td>", html)
    rows = {c[0]: c[1:] for c in cells}
    for k, v in s["parameters"].items():
        assert rows[k] == tuple(f"{v[q]:.4g}" for q in ("median", "q05", "q95")), k
    for r in s["k_theta"]:
        assert rows[f"{r['height_m']:g}"] == tuple(f"{r[q]:.4g}" for q in ("median", "q05", "q95"))
    wide = fit_report({**s, "level": 0.8}, {})
    assert "80% credible" in wide and "<th>10%</th><th>90%</th>" in wide
    ym = {
        "E_Pa": {"median": 9.1e9, "q05": 8.2e9, "q95": 1.01e10},
        "d0_m": {"median": 0.0102, "q05": 0.0099, "q95": 0.0105},
        "model": "uniform",
        "source": "calipers",
    }
    table = _modulus_section(ym, 5.0, 95.0)
    assert "<td>E0 (base)</td><td>9.1</td><td>8.2</td><td>10.1</td><td>GPa</td>" in table
    assert "<td>d0 (base diameter)</td><td>10.2</td><td>9.9</td><td>10.5</td><td>mm</td>" in table

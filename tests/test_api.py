"""The public API: fit returns an immutable Posterior, computing never writes, the CLI is a thin shell."""

import ast
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bayesrod
from bayesrod.cli import main

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "bayesrod"


@pytest.fixture(scope="module")
def post(twig_noisy):
    # the same arguments as the CLI run of test_api_and_cli_give_identical_summaries, which compares with it
    return bayesrod.fit(twig_noisy, use_shapes=False, progress=False, seed=5, max_steps=600, target_ess=100)


def test_public_names_resolve_and_are_documented():
    doc = (REPO / "docs" / "api.md").read_text()
    for name in bayesrod.__all__:
        assert hasattr(bayesrod, name), name
        if not name.startswith("__"):
            assert f"`{name}" in doc or f"{name}(" in doc or f".{name}" in doc, f"{name} missing from docs/api.md"


def test_posterior_is_immutable(post):
    with pytest.raises(dataclasses.FrozenInstanceError):
        post.length_m = 1.0
    with pytest.raises(ValueError):
        post.samples["EI0"][0] = 1.0
    with pytest.raises(TypeError):
        post.samples["EI0"] = np.zeros(3)
    d = post.to_dict()
    d["parameters"]["EI0"]["median"] = -1
    assert post.to_dict()["parameters"]["EI0"]["median"] > 0


def test_summary_frame_matches_summary_json(post):
    df = post.summary()
    doc = post.to_dict()["parameters"]
    assert list(df.index) == list(doc)
    for name, q in doc.items():
        assert df.loc[name, "median"] == pytest.approx(q["median"], rel=1e-12)
        assert df.loc[name, "q05"] == pytest.approx(q["q05"], rel=1e-12)
        assert df.loc[name, "q95"] == pytest.approx(q["q95"], rel=1e-12)
    wide = post.summary(level=0.5)
    assert {"q25", "q75"} <= set(wide.columns) and wide.attrs["level"] == 0.5


def test_the_summarys_sampler_and_data_records_are_the_run_the_draws_came_from(post):
    # summary.json's sampler section describes the chains the posterior holds: its walkers make the chains, its
    # steps less its burn-in make the draws, one autocorrelation time per sampled parameter, and the burn-in is
    # the rule the sampler states (a third of the steps, at least 5 autocorrelation times, at most half)
    data = post.to_dict()["data"]  # forces only: every engaged force sample counted, no centerline, no weight
    assert data["n_force"] == sum(d.F_N.size for d in post.likelihood.force_data) > 0
    assert data["n_shape_points"] == 0 and "shape_weight" not in data
    assert post.to_dict()["truth"] == json.loads(json.dumps(post.dataset.extra["truth"]))  # simulated: the truth
    rec = post.to_dict()["sampler"]
    n_chains, n_draws = (post.idata.posterior.sizes[k] for k in ("chain", "draw"))
    assert rec["ensembles"] * rec["walkers_per_ensemble"] == n_chains
    assert rec["steps"] - rec["burn_in"] == n_draws
    assert len(rec["autocorr_time"]) == len(post.samples)  # EI0, p and the noise sd, each sampled
    steps, tau = rec["steps"], max(rec["autocorr_time"])
    assert rec["burn_in"] == int(min(max(steps // 3, 5 * tau), steps // 2))
    assert 0 < rec["acceptance"] < 1 and rec["burn_in"] > 0
    assert post.to_dict()["convergence"]["walkers_restarted"] == 0  # a healthy run moves no walker


@pytest.mark.parametrize("level", [0.5, 0.9, 0.99])
def test_bands_use_the_level_they_state(post, level):
    """Every band's lower/upper are the (1 -/+ level)/2 quantiles of the quantity over the draws."""
    EI0, p, L = post.samples["EI0"], post.samples["p"], post.length_m
    lo_q, hi_q = (1 - level) / 2, (1 + level) / 2
    s = np.array([0.0, 0.3, 0.6])
    b = post.ei_band(s, level=level)
    assert b.level == level
    EI = bayesrod.flexural_rigidity(s[None], EI0[:, None], p[:, None], L)
    np.testing.assert_allclose(b.lower, np.quantile(EI, lo_q, axis=0), rtol=1e-12)
    np.testing.assert_allclose(b.upper, np.quantile(EI, hi_q, axis=0), rtol=1e-12)
    h = np.array([0.3, 0.5])
    k = post.k_theta_band(h, level=level)
    kt = bayesrod.k_theta(h[None], EI0[:, None], p[:, None], L)
    np.testing.assert_allclose(k.lower, np.quantile(kt, lo_q, axis=0), rtol=1e-12)
    np.testing.assert_allclose(k.median, np.median(kt, axis=0), rtol=1e-12)
    np.testing.assert_allclose(k.upper, np.quantile(kt, hi_q, axis=0), rtol=1e-12)
    rec = k.to_records()
    assert rec.dtype.names == ("height_m", "lower", "median", "upper")


def test_force_band_covers_truth_at_an_unseen_height(post):
    fb = post.predict_force(0.6, [0.02, 0.05], level=0.9)
    true_f = bayesrod.force_from_displacement(np.array([0.02, 0.05]), 0.6, 2.63, 0.43, 0.8).force_N
    assert np.all(fb.lower <= true_f) and np.all(true_f <= fb.upper)
    assert np.all(fb.slip_probability == 0) and fb.height_m == 0.6
    narrow = post.predict_force(0.6, [0.02, 0.05], level=0.5)
    assert np.all(narrow.upper - narrow.lower < fb.upper - fb.lower)


def test_band_inputs_are_checked(post):
    with pytest.raises(ValueError, match="height_m: expected 0 < value < L"):
        post.k_theta_band([0.9])
    with pytest.raises(ValueError, match="level: expected"):
        post.ei_band([0.1], level=90)
    with pytest.raises(ValueError, match="displacement_m"):
        post.predict_force(0.5, [-0.01])


def test_save_load_round_trip_is_identical(post, tmp_path):
    run = post.save(tmp_path / "run")
    again = bayesrod.Posterior.load(run)
    for k, v in post.samples.items():
        np.testing.assert_array_equal(again.samples[k], v)
    assert again.to_dict() == post.to_dict()
    h = [0.3, 0.55]
    np.testing.assert_array_equal(again.k_theta_band(h).upper, post.k_theta_band(h).upper)
    np.testing.assert_array_equal(again.predict_force(0.6, [0.03]).median, post.predict_force(0.6, [0.03]).median)
    assert {"summary.json", "posterior.nc", "samples.npz", "config.json", "report.html"} <= {
        p.name for p in run.iterdir()
    }
    with pytest.raises(ValueError, match="not empty"):
        post.save(run)


def test_api_and_cli_give_identical_summaries(post, twig_noisy, tmp_path):
    run = tmp_path / "cli"
    budget = ["--max-steps", "600", "--target-ess", "100"]
    assert main(["fit", str(twig_noisy), "--out", str(run), "--forces-only", "--seed", "5", "--quiet", *budget]) == 0
    cli = json.loads((run / "summary.json").read_text())
    assert post.config["seed"] == 5 and not post.config["use_shapes"]  # the fixture is the API side
    assert cli["parameters"] == post.to_dict()["parameters"]
    assert cli["k_theta"] == post.to_dict()["k_theta"]


def test_api_calls_leave_the_matplotlib_backend_alone(post, tmp_path):
    import matplotlib

    before = matplotlib.get_backend()
    post.save(tmp_path / "r")  # every figure and the report
    assert matplotlib.get_backend() == before
    offenders = [p for p in PKG.rglob("*.py") if "matplotlib.use(" in p.read_text()]
    assert not offenders


def test_plot_methods_take_an_axes_and_return_what_they_drew(post):
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    art = post.plot_k_theta(ax=ax)
    assert art["band"] in ax.collections
    axes = Figure().subplots(1, 2)
    assert post.plot_residuals(axes=axes)["force"]


def test_computing_writes_nothing(twig_noisy, tmp_path):
    """fit, bands, design and predict run in an empty working directory and leave it empty."""
    code = (
        "import bayesrod, numpy as np\n"
        f"post = bayesrod.fit({str(twig_noisy)!r}, use_shapes=False, progress=True, target_ess=50, max_steps=300)\n"
        "post.ei_band(np.linspace(0, 0.7, 5)); post.k_theta_band([0.5]); post.predict_force(0.6, [0.02])\n"
        "post.report_html()\n"
        "bayesrod.predict(0.6, [0.02], posterior=post)\n"
        "print('ok')\n"
    )
    cwd = tmp_path / "empty"
    cwd.mkdir()
    res = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert list(cwd.iterdir()) == []
    assert "\r" not in res.stderr and "it/s" not in res.stderr  # no progress bar when nobody watches


def test_dataset_from_arrays_and_frame():
    D = [np.linspace(0, 0.05, 5), np.linspace(0, 0.06, 6)]
    F = [2 * d for d in D]
    ds = bayesrod.Dataset.from_arrays(length_m=0.8, height_m=[0.4, 0.6], displacement_m=D, force_N=F)
    assert [p.id for p in ds.pushes] == ["h400", "h600"] and ds.validate() == []
    rows = {
        "h": np.repeat([0.4, 0.6], [5, 6]),
        "x": np.concatenate(D),
        "f": np.concatenate(F),
        "t": np.concatenate([np.arange(5.0), np.arange(6.0)]),
    }
    ds2 = bayesrod.Dataset.from_frame(rows, length_m=0.8, height="h", displacement="x", force="f", time="t")
    np.testing.assert_array_equal(ds2.pushes[1].force.force_N, F[1])
    with pytest.raises(ValueError, match="force: expected a column named 'F'"):
        bayesrod.Dataset.from_frame(rows, length_m=0.8, height="h", displacement="x", force="F", time="t")
    with pytest.raises(ValueError, match=r"force_N\[0\]: expected as many samples"):
        bayesrod.Dataset.from_arrays(length_m=0.8, height_m=[0.4], displacement_m=[[0, 1]], force_N=[[0, 1, 2]])
    bad = bayesrod.Dataset.from_arrays(length_m=0.8, height_m=[0.9], displacement_m=[[0, 0.1]], force_N=[[0, np.nan]])
    probs = [str(p) for p in bad.validate()]
    assert any("height_m" in p for p in probs) and any("force_N" in p and "row 2" in p for p in probs), probs


def test_every_public_result_saves_without_overwriting_unless_asked():
    """Nothing lost: each public result class with a ``save`` refuses a non-empty directory by default
    (``overwrite=False``; the behaviour itself is tested per class: Posterior above, Design, Comparison)."""
    import inspect

    savers = [getattr(bayesrod, n) for n in bayesrod.__all__ if inspect.isclass(getattr(bayesrod, n))]
    savers = [c for c in savers if callable(getattr(c, "save", None))]
    assert {"Posterior", "Dataset", "Design", "Comparison", "Diagnosis", "GroupFit", "Extraction"} <= {
        c.__name__ for c in savers
    }
    for cls in savers:
        params = inspect.signature(cls.save).parameters
        if "overwrite" in params:
            assert params["overwrite"].default is False, cls.__name__


def test_dataset_save_round_trips(tmp_path):
    ds = bayesrod.simulate("twig", seed=3, heights_m=[0.5], config_overrides={"n_frames_engaged": 2})
    ds.save(tmp_path / "ds")
    back = bayesrod.load(tmp_path / "ds")
    np.testing.assert_allclose(back.pushes[0].force.force_N, ds.pushes[0].force.force_N, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(back.pushes[0].force.contact_x_m, ds.pushes[0].force.contact_x_m, atol=1e-9)
    plain = bayesrod.Dataset.from_arrays(length_m=0.8, height_m=[0.4], displacement_m=[[0, 0.01]], force_N=[[0, 1.0]])
    plain.save(tmp_path / "plain")
    assert bayesrod.load(tmp_path / "plain").pushes[0].height_m == 0.4


# ----------------------------------------------------------------------------- layering
LAYER = {"_version": 0, "physics": 0, "dataset": 1, "vision": 1, "inference": 2, "report": 3, "api": 4, "cli": 5}


def _layer(mod: str) -> int:
    parts = mod.split(".")
    if len(parts) == 1 or parts[1] in ("__init__", "__main__"):
        return 6  # the package face and `python -m bayesrod`
    return LAYER[parts[1]]


def _imports(path: Path):
    mod = ".".join(path.relative_to(REPO).with_suffix("").parts)
    pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
                names = [target] if node.module else [f"{target}.{a.name}" for a in node.names]
            else:
                names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for n in names:
            if n == "bayesrod" or n.startswith("bayesrod."):
                yield mod, n


def test_layers_import_only_downward():
    """physics -> dataset, vision -> inference -> report -> api -> cli; lazy imports count too."""
    bad = []
    for path in PKG.rglob("*.py"):
        for mod, target in _imports(path):
            if target.split(".")[1:2] in (["__init__"], []):
                if _layer(mod) < 6:
                    bad.append((mod, target))
                continue
            if _layer(target) > _layer(mod):
                bad.append((mod, target))
    assert not bad, bad


def test_the_import_graph_check_can_fail(tmp_path):
    fake = PKG / "physics" / "_layer_probe.py"
    fake.write_text("from ..api import fit\n")
    try:
        with pytest.raises(AssertionError):
            test_layers_import_only_downward()
    finally:
        fake.unlink()


def test_no_module_below_the_cli_knows_a_flag():
    from bayesrod.cli import build_parser

    flags = set()
    for action in build_parser()._subparsers._group_actions[0].choices.values():
        flags |= {o for a in action._actions for o in a.option_strings if o.startswith("--")}
    flags -= {"--help"}
    bad = []
    for path in PKG.rglob("*.py"):
        if "cli" in path.relative_to(PKG).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                bad += [(path.name, f) for f in flags if f"{f}:" in node.value or f"{f} " in node.value]
    assert not bad, bad


def test_the_cli_defaults_of_diagnose_are_the_apis():
    """A flag's default that differs from the function's silently gives shell and notebook users two tools."""
    import inspect

    from bayesrod.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0].choices["diagnose"]
    params = inspect.signature(bayesrod.diagnose).parameters
    shared = [a for a in sub._actions if a.dest in params and params[a.dest].default is not inspect.Parameter.empty]
    assert {a.dest for a in shared} >= {"alpha", "min_heldout_gain", "heldout_alpha", "force_noise"}
    for a in shared:  # a flag defaulting to None passes nothing: the function's own default applies
        assert a.default is None or a.default == params[a.dest].default, a.dest


def test_progress_only_on_a_terminal(monkeypatch):
    from bayesrod.api._common import progress_enabled

    class Tty:
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stderr", Tty())
    assert progress_enabled(True) and not progress_enabled(False)
    monkeypatch.setattr(sys, "stderr", open(os.devnull, "w"))
    assert not progress_enabled(True)


def test_summary_json_intervals_are_the_stated_quantiles_of_the_draws(post):
    """summary.json's q05/q95 (parameters and k_theta) are the 5% and 95% quantiles of the draws, by np.quantile."""
    doc = post.to_dict()
    assert doc["level"] == 0.9
    for name, q in doc["parameters"].items():
        x = post.samples[name]
        assert q["q05"] == pytest.approx(np.quantile(x, 0.05), rel=1e-12), name
        assert q["median"] == pytest.approx(np.quantile(x, 0.5), rel=1e-12), name
        assert q["q95"] == pytest.approx(np.quantile(x, 0.95), rel=1e-12), name
    EI0, p = post.samples["EI0"], post.samples["p"]
    for row in doc["k_theta"]:
        k = bayesrod.k_theta(row["height_m"], EI0, p, post.length_m)
        assert row["q05"] == pytest.approx(np.quantile(k, 0.05), rel=1e-12)
        assert row["q95"] == pytest.approx(np.quantile(k, 0.95), rel=1e-12)


def test_posterior_width_matches_the_laplace_width_and_the_noise_is_recovered(post, twig_noisy):
    """A well-identified case (three heights, iid noise, forces): the posterior sd of log EI0 and p is within
    25% of the Laplace sd (inverse Hessian of the log posterior at its mode, by finite differences), and the
    fitted force noise covers the simulator's. An interval too wide (or too narrow) fails as surely as an
    off-centre one."""
    from scipy.optimize import minimize

    from bayesrod.api.calibration import _hessian
    from bayesrod.inference.likelihood import LogPosterior
    from bayesrod.inference.priors import load_prior

    lp = LogPosterior(post.likelihood, load_prior(post.config["prior"]))
    theta = lp.to_sample({k: post.samples[k] for k in lp.names})
    best = theta[np.argmax(lp.log_prob(theta[:: max(1, len(theta) // 4000)]))]
    mode = minimize(lambda t: -lp.log_prob(t), best, method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-9}).x
    H = _hessian(lambda t: float(np.squeeze(lp.log_prob(t))), mode, 1e-4 * np.maximum(np.abs(mode), 1.0))
    laplace_sd = np.sqrt(np.diag(np.linalg.inv(-H)))
    sd = np.std(theta, axis=0)
    for i, name in enumerate(lp.names[:2]):  # log EI0 and p in the sampling space
        assert 0.8 < sd[i] / laplace_sd[i] < 1.25, (name, sd[i], laplace_sd[i])
    truth = bayesrod.load(twig_noisy).extra["truth"]["noise"]["force_sd_N"]
    q = post.summary().loc["sigma_force_N"]
    assert q["q05"] <= truth <= q["q95"], (q, truth)
    assert q["q95"] / q["q05"] < 1.6  # and the interval says something


def test_the_posterior_puts_the_truth_where_the_data_s_own_noise_put_it(post, twig_noisy):
    """Per replicate, not per coverage count: with iid Gaussian noise e and a model close to linear over the
    posterior's width, the least-squares shift the noise alone makes, z = (J'J)^-1 J'e / sd (J: the noise-free
    forces' derivatives in log EI0 and p at the truth, by the solver straight, not through the likelihood's tables),
    places the truth at the posterior quantile Phi(-z) (the default prior is flat over the width). The truth's
    normal score in the posterior within 0.2 of -z: a posterior off-centre by a third of its sd fails, whatever
    coverage would say (measured: -0.19 for -0.25 and +0.04 for -0.02; scripts/sbc_noise_draws.py --projection
    reads SBC replicates the same way, docs/validation.md, session 73)."""
    from scipy import stats

    from bayesrod.dataset.engagement import detect_engagement
    from bayesrod.physics.effects import Effects
    from bayesrod.physics.elastica import force_from_displacement

    ds = bayesrod.load(twig_noisy)
    truth = ds.extra["truth"]
    assert truth["effects"] == {}  # the plain rod
    engaged = [detect_engagement(push.force.force_N).mask for push in ds.pushes]

    def forces(x) -> np.ndarray:
        return np.concatenate(
            [
                force_from_displacement(
                    push.force.contact_x_m[m], push.height_m, float(np.exp(x[0])), float(x[1]), ds.length_m, Effects()
                ).force_N
                for push, m in zip(ds.pushes, engaged, strict=True)
            ]
        )

    x0 = np.array([np.log(truth["EI0"]), truth["p"]])
    noise = np.concatenate([push.force.force_N[m] for push, m in zip(ds.pushes, engaged, strict=True)]) - forces(x0)
    sd = truth["noise"]["force_sd_N"]
    assert 0.9 < np.sqrt(np.mean(noise**2)) / sd < 1.1  # the residual at the truth is the simulator's noise
    J = np.stack([(forces(x0 + 1e-6 * u) - forces(x0 - 1e-6 * u)) / 2e-6 for u in np.eye(2)], axis=1)
    A = J.T @ J
    z = np.linalg.solve(A, J.T @ noise) / (sd * np.sqrt(np.diag(np.linalg.inv(A))))
    for k, zk in zip(("EI0", "p"), z, strict=True):
        q = float(np.mean(np.asarray(post.samples[k]) < truth[k]))
        assert 0.001 < q < 0.999, (k, q)
        assert stats.norm.ppf(q) == pytest.approx(-zk, abs=0.2), (k, stats.norm.ppf(q), -zk)


def test_the_noise_posterior_is_the_exact_marginal_of_the_least_squares_fit(post):
    """The force noise's posterior against its exact answer: for Gaussian noise and a model that is close to
    linear in (log EI0, p) over the posterior's width (three heights, forces only), integrating them out leaves
    p(sigma | data) proportional to sigma^-(n - 2) exp(-RSS / (2 sigma^2)) (the half-normal prior, scale 0.5 N,
    is flat to 2e-3 over it), RSS the least-squares residual sum. Its 5/50/95% quantiles within 2% (the
    posterior's own sd is 5%), the sd of log sigma within 15%: a noise posterior too wide, too narrow or shifted
    fails (measured: within 0.22% and a ratio of 1.001; docs/validation.md, session 61)."""
    from scipy.optimize import minimize

    lik = post.likelihood
    n = lik.n_force

    def rss(x) -> float:
        one = {"EI0": np.exp([x[0]]), "p": np.array([x[1]]), "sigma_force_N": np.array([1.0])}
        return -2.0 * float(lik.log_likelihood(one)[0]) - n * np.log(2.0 * np.pi)

    x0 = [np.log(np.median(post.samples["EI0"])), float(np.median(post.samples["p"]))]
    best = minimize(rss, x0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12}).fun
    sd = np.asarray(post.samples["sigma_force_N"])
    grid = np.linspace(0.5 * sd.min(), 1.5 * sd.max(), 20001)
    log_p = -(n - 2) * np.log(grid) - best / (2.0 * grid**2)
    cdf = np.cumsum(np.exp(log_p - log_p.max()))
    cdf /= cdf[-1]
    exact = grid[np.searchsorted(cdf, [0.05, 0.5, 0.95])]
    np.testing.assert_allclose(np.quantile(sd, [0.05, 0.5, 0.95]), exact, rtol=0.02)
    weight = np.diff(cdf, prepend=0.0)
    mean_log = np.sum(weight * np.log(grid))
    exact_log_sd = np.sqrt(np.sum(weight * (np.log(grid) - mean_log) ** 2))
    assert 0.85 < np.std(np.log(sd)) / exact_log_sd < 1.15, (np.std(np.log(sd)), exact_log_sd)


def test_a_table_check_that_cannot_solve_is_reported_not_raised(twig_noisy, monkeypatch):
    """The per-fit table check solves the rod exactly at the posterior median; where such a solve fails
    (a ValueError from the solver) the fit still returns, and summary.json says the tables were not checked."""

    def cannot(lik, point):
        raise ValueError("height_m: expected a height the unloaded stem reaches, got h/L = 0.9")

    monkeypatch.setattr("bayesrod.api.fitting.table_check", cannot)
    post = bayesrod.fit(twig_noisy, use_shapes=False, progress=False, seed=1, max_steps=300, target_ess=50)
    assert post.to_dict()["table_check"] == {
        "message": "not checked: height_m: expected a height the unloaded stem reaches, got h/L = 0.9"
    }


def test_fit_hands_its_seed_budget_and_checkpoint_to_the_sampler(twig_noisy, monkeypatch, tmp_path):
    # the sampler's own stopping rule and seeding: tests/test_sampler.py; here that fit passes the user's on
    from bayesrod.inference import sampler

    class Sampled(Exception):
        pass

    asked, starts = {}, []

    def record(post, theta0, **options):
        asked.update(options)
        raise Sampled

    def start(post, rng, **kw):
        starts.append(rng.bit_generator.state["state"])
        return sampler.find_start(post, rng, **kw)

    monkeypatch.setattr("bayesrod.api.fitting.run_ensembles", record)
    monkeypatch.setattr("bayesrod.api.fitting.find_start", start)
    ckpt = tmp_path / "chains.h5"
    with pytest.raises(Sampled):
        bayesrod.fit(
            twig_noisy, use_shapes=False, progress=False, seed=7, max_steps=1234, target_ess=321.0, checkpoint=ckpt
        )
    assert asked == {"seed": 7, "backend_path": ckpt, "progress": False, "max_steps": 1234, "target_ess": 321.0}
    assert starts == [np.random.default_rng(7).bit_generator.state["state"]]  # the start drawn with the seed


def test_a_table_check_past_a_tenth_of_an_sd_reaches_the_summary_and_the_warnings(
    twig_noisy, monkeypatch, bayesrod_warnings
):
    # the threshold itself: tests/test_inference.py (table_warning); here that its message is what the user reads
    from bayesrod.api.fitting import table_warning

    check = {
        "max_error_over_sigma": 0.5,
        "shift_in_sd": {"log EI0": 0.3, "p": -0.02},
        "n_samples": 10,
        "laplace_sd": {"log EI0": 0.1, "p": 1.0},  # wide: no window narrower than 0.8 of the p grid
    }
    monkeypatch.setattr("bayesrod.api.fitting.table_check", lambda lik, point: dict(check))
    post = bayesrod.fit(twig_noisy, use_shapes=False, progress=False, seed=1, max_steps=300, target_ess=50)
    got = dict(post.to_dict()["table_check"])
    start = got.pop("at_start")  # the same (stand-in) check at the start and between p nodes: nothing narrowed
    assert start["shift_in_sd"] == start["between_p_nodes"]["shift_in_sd"] == check["shift_in_sd"]
    assert got == check | {"message": table_warning(check)} and "by 0.3 sd" in got["message"]
    assert any(got["message"] in m for m in bayesrod_warnings), bayesrod_warnings


def test_the_fit_commands_printout_is_the_summarys_numbers(capsys):
    """`bayesrod fit` prints each parameter, k_theta and Young's modulus (in GPa) as summary.json has them:
    median, then q05 and q95 in that order."""
    from types import SimpleNamespace

    from bayesrod.cli import _print_fit

    summary = {
        "parameters": {
            "EI0": {"median": 2.63, "q05": 2.41, "q95": 2.87},
            "p": {"median": 0.43, "q05": 0.4, "q95": 0.47},
        },
        "k_theta": [{"height_m": 0.5, "median": 10.5, "q05": 9.75, "q95": 11.25}],
        "youngs_modulus": {
            "E_Pa": {"median": 9.1e9, "q05": 8.2e9, "q95": 1.01e10},
            "model": "free",
            "uniform_modulus": "consistent",
            "modulus_taper": {"median": 0.012, "q05": -0.021, "q95": 0.044},
        },
        "convergence": {"rhat_max": 1.0031, "ess_bulk_min": 1698.0},
        "sampler": {"seconds": 26.9},
    }
    _print_fit(summary, None, SimpleNamespace(json=False))
    out = capsys.readouterr().out
    assert "EI0 = 2.63  [2.41, 2.87]" in out and "p = 0.43  [0.4, 0.47]" in out
    assert "k_theta(0.5 m) = 10.5  [9.75, 11.25] N m/rad" in out
    assert "Young's modulus E0 = 9.1  [8.2, 10.1] GPa" in out
    assert "uniform modulus consistent: p - p_geom = 0.012  [-0.021, 0.044]" in out
    assert "R-hat max 1.0031, bulk ESS min 1698, 26.9 s" in out


def test_predict_from_a_posterior_prints_the_results_numbers(capsys):
    """`bayesrod predict RUN`'s table: k_theta and k_x, then each displacement's median force, its 90% interval
    (q05 before q95) and the slip probability, as the result holds them."""
    from bayesrod.cli import _print_posterior_prediction

    result = {
        "posterior": {"run": "runs/s1", "draws": 400, "length_m": 0.8},
        "height_m": 0.5,
        "k_theta_Nm_per_rad": {"median": 10.5, "q05": 9.75, "q95": 11.25},
        "k_x_N_per_m": {"median": 42.5, "q05": 40.25, "q95": 44.75},
        "points": [
            {
                "displacement_m": 0.01,
                "force_N": {"median": 0.4251, "q05": 0.4013, "q95": 0.4489},
                "slip_probability": 0.0,
            },
            {"displacement_m": 0.3, "force_N": None, "slip_probability": 1.0},
        ],
    }
    _print_posterior_prediction(result)
    out = capsys.readouterr().out
    assert "from runs/s1 (400 draws), L = 0.8 m, h = 0.5 m" in out
    assert "k_theta = 10.5 [9.75, 11.25] N m/rad,  k_x = 42.5 [40.25, 44.75] N/m" in out
    rows = out.strip().splitlines()[-2:]
    assert rows[0].split() == ["0.0100", "0.4251", "[0.4013,", "0.4489]", "0.00"]
    assert rows[1].split() == ["0.3000", "-", "-", "1.00"]

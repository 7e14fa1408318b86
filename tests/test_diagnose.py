"""Diagnosis (issue 9): undeclared effects are found, clean data are left alone, structure is flagged."""

import json

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.dataset import read_dataset
from bayesrod.inference.diagnose import Diagnoser, ForwardModel, _cut, diagnose
from bayesrod.inference.likelihood import prepare_data
from bayesrod.physics import Effects, force_from_displacement

from .conftest import make_dataset

FAST = ("force_offset", "base_compliance", "yield")  # effects whose forward solves are quick
# the whole catalog on forces and shapes: scripts/diagnose_study.py (table in docs/validation.md)


def _model(path, shapes=False):
    spec = read_dataset(path)
    return ForwardModel(prepare_data(spec, use_shapes=shapes), spec.length_m)


SPECS = {
    "clean": (21, Effects()),
    "offset": (22, Effects(force_offset=0.1)),
    "compliance": (23, Effects(base_compliance=8.0)),
    "yield": (24, Effects(yield_moment=3.0)),
}


class _Lazy(dict):
    """Simulated twig datasets, made on first use (two pushes, forces only, 30 samples each: quick fits)."""

    def __init__(self, root):
        super().__init__()
        self.root = root

    def __missing__(self, name):
        seed, eff = SPECS[name]
        kw = dict(seed=seed, effects=eff, n_frames_engaged=2, n_force_engaged=30, heights_m=(0.45, 0.6))
        self[name] = make_dataset(self.root / name, "twig", **kw)
        return self[name]


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    return _Lazy(tmp_path_factory.mktemp("diag"))


def test_forward_model_matches_the_physics_and_holds_past_the_slip(datasets):
    m = _model(datasets["clean"])
    F, _, _ = m.predict(np.log(2.63), 0.43, {})
    d = m.data[0]
    ref = force_from_displacement(d.D_m, d.height_m, 2.63, 0.43, m.length_m).force_N
    # read off a cubic spline through 32 solves per push: within 1e-5 of the peak force
    assert np.max(np.abs(F[: d.D_m.size] - ref)) < 1e-5 * np.max(np.abs(ref))


@pytest.mark.slow
def test_score_statistic_is_chi2_sized_on_clean_data_and_large_for_the_missing_effect(datasets):
    dg = Diagnoser(_model(datasets["clean"]))
    fit = dg.fit((), dg.start())
    clean = dg.score(fit, "force_offset")["statistic"]
    assert clean < 10.8  # chi^2_1 at p = 0.001
    dg2 = Diagnoser(_model(datasets["offset"]))
    fit2 = dg2.fit((), dg2.start())
    assert dg2.score(fit2, "force_offset")["statistic"] > 3 * 10.8  # far beyond the 0.001 quantile


@pytest.mark.parametrize(
    "case, effect, value",
    [("offset", "force_offset", 0.1), pytest.param("compliance", "base_compliance", 8.0, marks=pytest.mark.slow)],
)
def test_undeclared_effect_is_attributed_and_held_out_error_drops(datasets, case, effect, value):
    r = diagnose(_model(datasets[case]), candidates=FAST)
    assert r["added_effects"] == [effect]
    assert r["fitted"][effect] == pytest.approx(value, rel=0.15)
    b, a = r["before"]["heldout_force_rmse_N"], r["after"]["heldout_force_rmse_N"]
    assert a < 0.7 * b, (b, a)
    assert not r["unexplained_structure"]


def test_clean_data_get_no_effect(datasets):
    r = diagnose(_model(datasets["clean"]), candidates=FAST)
    assert r["added_effects"] == []
    assert r["after"] == r["before"]
    assert not r["unexplained_structure"]


@pytest.mark.slow
def test_structure_no_candidate_explains_is_flagged_not_forced(datasets):
    """Yield present, but only the offset may be tested: nothing fits, and the diagnosis says so."""
    r = diagnose(_model(datasets["yield"]), candidates=("force_offset",))
    assert r["unexplained_structure"]
    assert any(b["structured"] and b["kind"] == "force" for b in r["structure_after"])


def test_diagnose_cli_writes_contract_json_and_report(datasets, tmp_path, capsys):
    out = tmp_path / "dg"
    args = ["diagnose", str(datasets["offset"]), "--out", str(out), "--forces-only", "--candidates", "force_offset"]
    assert main(args) == 0
    doc = json.loads((out / "diagnose.json").read_text())
    assert set(doc) >= {"added_effects", "candidates", "before", "after", "unexplained_structure"}
    for c in doc["candidates"]:
        assert set(c) >= {"effect", "statistic", "selected"}
    for k in ("shape_rmse_mm", "force_rmse_N", "heldout_force_rmse_N"):
        assert k in doc["before"] and k in doc["after"]
    assert doc["before"]["shape_rmse_mm"] is None  # --forces-only
    assert doc["added_effects"] == ["force_offset"]
    assert doc["after"]["heldout_force_rmse_N"] < 0.7 * doc["before"]["heldout_force_rmse_N"]
    assert (out / "figures" / "residuals.png").is_file() and (out / "figures" / "statistics.png").is_file()
    assert "data:image/png;base64" in (out / "report.html").read_text()
    assert "added effects: force_offset" in capsys.readouterr().out


@pytest.mark.slow
def test_undeclared_yield_is_attributed(datasets):
    r = diagnose(_model(datasets["yield"]), candidates=FAST)
    assert r["added_effects"][0] == "yield"
    assert r["fitted"]["yield"] == pytest.approx(3.0, rel=0.05)
    assert r["after"]["heldout_force_rmse_N"] < 0.3 * r["before"]["heldout_force_rmse_N"]


def test_diagnose_cli_bad_candidates_in_one_line(datasets, tmp_path, capsys):
    assert main(["diagnose", str(datasets["clean"]), "--out", str(tmp_path / "x"), "--candidates", "gravity"]) == 2
    err = capsys.readouterr().err
    assert "--candidates: expected effects from" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


# ---------------------------------------------------------------- issue 19: true refits, AR(1) noise
def test_heldout_error_is_a_true_refit_without_the_push(datasets):
    """Each held-out push is predicted by a full fit to the other pushes: no steps from the full fit."""
    m = _model(datasets["clean"])
    dg = Diagnoser(m)
    fit = dg.fit((), dg.start())
    summary, errs = dg.heldout(fit)
    assert summary["heldout"] == "leave-one-height-out"
    for k, (row, e) in list(enumerate(zip(summary["per_push"], errs, strict=True)))[:1]:
        rest = ForwardModel([d for j, d in enumerate(m.data) if j != k], m.length_m)
        own = Diagnoser(rest).fit((), fit.x)
        held = ForwardModel([m.data[k]], m.length_m)
        expect = held.F_obs - held.forces(own.x[None], ())[0]
        np.testing.assert_allclose(e.errors_N, expect, rtol=1e-6, atol=1e-9)
        assert row["force_rmse_N"] == pytest.approx(np.sqrt(np.mean(expect**2)), rel=1e-6)
        # the full fit's own prediction of the push (no refit, or the in-sample error) is another number
        assert not np.allclose(e.errors_N, fit.r_force[m.force_push == k], rtol=1e-3, atol=0)


def test_one_push_holds_out_the_last_third(datasets):
    m = _model(datasets["clean"])
    one = ForwardModel([m.data[0]], m.length_m)
    dg = Diagnoser(one)
    fit = dg.fit((), dg.start())
    summary, errs = dg.heldout(fit)
    assert summary["heldout"] == "last third of the push"
    n = m.data[0].D_m.size
    n_train = int(np.ceil(2 * n / 3))
    assert errs[0].errors_N.size == n - n_train
    train = ForwardModel([_cut(m.data[0], np.arange(n_train), np.zeros(0, int))], m.length_m)
    own = Diagnoser(train).fit((), fit.x)
    F = one.forces(own.x[None], ())[0][n_train:]
    np.testing.assert_allclose(errs[0].errors_N, one.F_obs[n_train:] - F, rtol=1e-6, atol=1e-9)


def test_ar1_log_likelihood_is_the_exact_gaussian_density():
    """Diagnoser.loglik with AR(1) forces equals the dense multivariate normal (two pushes)."""
    from scipy.stats import multivariate_normal

    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(0)
    pushes = [
        PushData(
            f"h{k}",
            0.5,
            np.linspace(0.001, 0.02, n),
            rng.normal(size=n),
            np.zeros(0),
            np.zeros(0, int),
            *(np.zeros(0),) * 2,
            None,
        )
        for k, n in enumerate((7, 5))
    ]
    dg = Diagnoser(ForwardModel(pushes, 0.8))
    rf = np.concatenate([d.F_N for d in pushes])
    sf, rho = 0.7, 0.85
    dense = 0.0
    for d in pushes:
        n = d.F_N.size
        lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        cov = sf**2 / (1 - rho**2) * rho**lag
        dense += multivariate_normal(np.zeros(n), cov).logpdf(d.F_N)
    const = -0.5 * rf.size * np.log(2 * np.pi)
    assert dg.loglik(rf, np.zeros(0), (sf, rho, 1.0)) + const == pytest.approx(dense, rel=1e-10)
    # the profile recovers the correlation of long AR(1) residuals
    from bayesrod.dataset.simulate import ar1_noise

    r = ar1_noise(rng, 1.0, 0.9, 4000)
    long = ForwardModel(
        [
            PushData(
                "h", 0.5, np.linspace(0.001, 0.02, 4000), r, np.zeros(0), np.zeros(0, int), *(np.zeros(0),) * 2, None
            )
        ],
        0.8,
    )
    assert Diagnoser(long).profile_noise(r, np.zeros(0))[1] == pytest.approx(0.9, abs=0.02)
    assert Diagnoser(long, "iid").profile_noise(r, np.zeros(0))[1] == 0.0


@pytest.mark.parametrize("coords", [{}, {"yield": np.log(2.0)}, {"base_compliance": 0.3}])
def test_spline_forces_match_the_direct_solve_on_long_pushes(coords):
    """150 samples per push, read off 32 solves: plain, a yield onset mid-push, a soft base."""
    from bayesrod.inference.likelihood import PushData

    D = np.linspace(0.0, 0.25, 150)
    empty = np.zeros(0)
    pushes = [
        PushData(f"h{h}", h, D, np.zeros(D.size), empty, empty.astype(int), empty, empty, None) for h in (0.45, 0.6)
    ]
    m = ForwardModel(pushes, 0.8)
    F = m.predict(np.log(2.63), 0.43, coords, shapes=False)[0]
    from bayesrod.inference.diagnose import effects_from_coords

    eff = effects_from_coords(coords, 2.63, 0.8)
    ref = np.concatenate([force_from_displacement(D, d.height_m, 2.63, 0.43, 0.8, eff).force_N for d in pushes])
    assert np.all(np.isfinite(ref))
    tol = 1e-5 if "yield" not in coords else 1e-4  # each branch its own spline, the kink's interval solved
    assert np.max(np.abs(F - ref)) < tol * np.max(np.abs(ref))


def test_structure_test_holds_its_level_under_ar1_noise_and_fails_without_the_correction():
    """Pure AR(1) residuals (rho 0.95): the whitened F test flags no block in 95%+ of pushes; without the
    whitening (the correlated-noise correction dropped) nearly every push is flagged."""
    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit
    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(5)
    n, pushes = 120, []
    for k in range(40):
        r = ar1_noise(rng, 0.05, 0.95, n)
        e = np.zeros(0)
        pushes.append(PushData(f"h{k}", 0.5, np.linspace(0.0, 0.05, n), r, e, e.astype(int), e, e, None))
    m = ForwardModel(pushes, 0.8)
    r = m.F_obs
    sig = 0.05 * np.sqrt(1 - 0.95**2)

    def flagged(rho, sigma):
        fit = MapFit((), np.zeros(2), sigma, 1.0, r, np.zeros(0), np.zeros((r.size, 2)), 0.0, rho)
        return sum(b["structured"] for b in Diagnoser(m).structure(fit)["blocks"])

    assert flagged(0.95, sig) <= 2  # 40 pushes at alpha 1e-3 (and a material size): ~0 expected
    assert flagged(0.0, 0.05) >= 30


def test_heldout_bootstrap_p_values_are_uniform_when_the_effect_is_absent():
    """Linear model, AR(1) noise (rho 0.9), an effect column that is absent: the observed held-out gains come
    from exact GLS refits (dense covariance, written here independently); the bootstrap p-values are uniform."""
    from bayesrod.dataset.simulate import ar1_noise
    from bayesrod.inference.diagnose import MapFit, null_heldout_gain
    from bayesrod.inference.likelihood import PushData

    rng = np.random.default_rng(11)
    n, rho, sig = 60, 0.9, 0.02
    D = np.linspace(0.001, 0.05, n) / 0.05
    e = np.zeros(0)
    pushes = [PushData(f"h{k}", 0.4 + 0.1 * k, D, np.zeros(n), e, e.astype(int), e, e, None) for k in range(3)]
    m = ForwardModel(pushes, 0.8)
    push = m.force_push
    scale = 1.0 + 0.3 * push  # the heights differ
    J0 = np.column_stack([D[np.arange(3 * n) % n] * scale, (D[np.arange(3 * n) % n] ** 2) * scale**2])
    G = (D[np.arange(3 * n) % n] ** 3) * scale**3
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    Cinv_block = np.linalg.inv(sig**2 / (1 - rho**2) * rho**lag)

    def gls(X, y, rows):
        A = np.zeros((X.shape[1],) * 2)
        b = np.zeros(X.shape[1])
        for k in np.unique(push[rows]):
            s = rows & (push == k)
            A += X[s].T @ Cinv_block @ X[s]
            b += X[s].T @ Cinv_block @ y[s]
        return np.linalg.solve(A, b)

    dg = Diagnoser(m)
    pv = []
    for _ in range(150):
        y = J0 @ np.array([1.0, -0.3]) + np.concatenate(
            [ar1_noise(rng, sig / np.sqrt(1 - rho**2), rho, n) for _ in range(3)]
        )
        allrows = np.ones(3 * n, bool)
        X1 = np.column_stack([J0, G])
        r0 = y - J0 @ gls(J0, y, allrows)
        r1 = y - X1 @ gls(X1, y, allrows)
        sq0 = sq1 = 0.0
        for k in range(3):
            train, held = push != k, push == k
            sq0 += np.sum((y[held] - J0[held] @ gls(J0, y, train)) ** 2)
            sq1 += np.sum((y[held] - X1[held] @ gls(X1, y, train)) ** 2)
        gain = 1 - np.sqrt(sq1 / sq0)
        mk = lambda r: MapFit((), np.zeros(2), sig, 1.0, r, np.zeros(0), J0, 0.0, rho, J0)  # noqa: E731
        pv.append(null_heldout_gain(dg, mk(r0), mk(r1), gain, n_draws=400, seed=len(pv)))
    pv = np.array(pv)
    assert 0.01 <= np.mean(pv < 0.05) <= 0.11, np.mean(pv < 0.05)
    assert 0.38 <= np.mean(pv < 0.5) <= 0.62, np.mean(pv < 0.5)

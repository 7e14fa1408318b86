"""The likelihood's force curves spread over processes (``table_workers``; docs/performance.md).

A friction curve searches the base moment at every force, and near a fold of the force curve that search takes
other paths in batches of other sizes: the branch end of one curve solved in a batch with another differed from
the same curve solved alone by 0.02 L (the cases below). Friction curves are therefore solved one per call,
whatever the workers, so a curve depends on its own height, effect and p grid only.
"""

from __future__ import annotations

import numpy as np
import pytest

import bayesrod
from bayesrod.inference import likelihood as LK
from bayesrod.inference.likelihood import ForceCurves, check_workers, table_workers

# eta 0.6 at mu 0.2 beside eta 0.45 at mu 0.35, five p nodes, 40 forces: batched together the first curve's branch
# end read 0.662 where alone it reads 0.682 at p 0.6 (measured; two curves of 4 s each alone)
ETAS, MUS, P_GRID, N_F = np.array([0.6, 0.45]), np.array([0.2, 0.35]), np.linspace(0.3, 0.7, 5), 40
D = np.linspace(0.0, 0.9, 46)


def _fresh_cache(monkeypatch):
    monkeypatch.setattr(LK, "_CURVE_CACHE", {})


def _same(a: ForceCurves, b: ForceCurves) -> None:
    np.testing.assert_array_equal(a.d_end, b.d_end)
    np.testing.assert_array_equal(a.d_early, b.d_early)
    np.testing.assert_array_equal(a.force(D), b.force(D))


@pytest.mark.slow  # 29 s: five friction curves, two in worker processes (docs/validation.md, "The slow tier")
def test_friction_curves_are_their_own_whatever_the_batch_and_the_workers(monkeypatch):
    _fresh_cache(monkeypatch)
    serial = ForceCurves.batch(ETAS, P_GRID, N_F, {"mu": MUS})
    alone = ForceCurves._solve(ETAS[:1], P_GRID, N_F, {"mu": MUS[:1]})[0]
    _same(serial[0], alone)  # fails where the two curves share one batched solve (0.02 L apart)
    _fresh_cache(monkeypatch)
    with table_workers(2):
        spread = ForceCurves.batch(ETAS, P_GRID, N_F, {"mu": MUS})
    for a, b in zip(serial, spread, strict=True):
        _same(a, b)
    assert [c.effects_nd for c in spread] == [{"mu": 0.2}, {"mu": 0.35}]


def test_plain_curves_over_workers_are_the_one_batch_bit_for_bit(monkeypatch):
    etas, pg = np.linspace(0.3, 0.8, 5), np.linspace(0.0, 3.0, 13)
    _fresh_cache(monkeypatch)
    serial = ForceCurves.batch(etas, pg, 60)
    _fresh_cache(monkeypatch)
    with table_workers(2):
        spread = ForceCurves.batch(etas, pg, 60)
    for a, b in zip(serial, spread, strict=True):
        _same(a, b)


def test_the_workers_hold_inside_the_block_only_and_are_checked():
    assert LK._TABLE_BUILD.get() == (1, False)
    with table_workers(3, progress=True) as n:
        assert n == 3 and LK._TABLE_BUILD.get() == (3, True)
        with table_workers(1):
            assert LK._TABLE_BUILD.get() == (1, False)
        assert LK._TABLE_BUILD.get() == (3, True)
    assert LK._TABLE_BUILD.get() == (1, False)
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match=r"n_workers: expected an integer >= 1, got"):
            with table_workers(bad):
                pass


def test_fit_checks_its_workers_before_any_work(twig_noisy):
    with pytest.raises(ValueError, match=r"^n_workers: expected an integer >= 1, got 0$"):
        bayesrod.fit(twig_noisy, n_workers=0, progress=False)


def test_fit_builds_its_tables_under_the_workers_it_was_given(monkeypatch, twig_noisy):
    seen = []

    def spy(*args, **kwargs):
        seen.append(LK._TABLE_BUILD.get()[0])
        raise ValueError("stop here")

    monkeypatch.setattr("bayesrod.api.fitting.build_likelihood", spy)
    with pytest.raises(ValueError, match="stop here"):
        bayesrod.fit(twig_noisy, n_workers=2, progress=False)
    assert seen == [2]


def test_the_cli_passes_workers_and_names_the_flag_in_its_errors(tmp_path, capsys, monkeypatch, twig_noisy):
    from bayesrod.cli import main

    got = {}

    def fake_fit(dataset, **kwargs):
        got.update(kwargs)
        check_workers(kwargs["n_workers"])  # the library's own check, as fit runs it first
        raise ValueError("stop here")

    monkeypatch.setattr("bayesrod.api.fit", fake_fit)
    assert main(["fit", str(twig_noisy), "--out", str(tmp_path / "a"), "--workers", "3"]) != 0
    assert got["n_workers"] == 3
    capsys.readouterr()
    assert main(["fit", str(twig_noisy), "--out", str(tmp_path / "b"), "--workers", "0"]) != 0
    err = capsys.readouterr().err
    assert "--workers: expected an integer >= 1, got 0" in err, err
    assert main(["fit", str(twig_noisy), "--out", str(tmp_path / "c")]) != 0
    assert got["n_workers"] == 1

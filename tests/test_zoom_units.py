"""The fit's narrowing of its tables (bayesrod.api.fitting: zoom_decision, _zoom_tables, _zoom_edge), one rule at a
time on stand-ins: no table is built. The fits that zoom for real are in tests/test_inference.py
(``test_a_fit_narrows_a_coarse_effect_axis_around_its_start``, ``..._p_grid_around_its_start``); these cover what
they do not reach (session 74's mutation run of the target ``p_zoom``: docs/validation.md)."""

from types import SimpleNamespace

import numpy as np
import pytest

from bayesrod.api import fitting


def _zoom(lo, hi, lo0=0.0, hi0=3.0, kept=True):
    return {"kept": kept, "p_range_before": [lo0, hi0], "p_range": [lo, hi]}


def test_zoom_edge_counts_the_draws_next_to_each_inner_end_of_a_window_and_says_so():
    """Draws within ZOOM_EDGE_SHARE (2%) of the window of an end the window cut (not the prior's own end) are
    counted, from either end, and a message warns that the window may cut the posterior."""
    assert fitting.ZOOM_EDGE_SHARE == 0.02
    p = np.array([1.005, 1.5, 1.5, 1.5, 1.5, 1.5, 1.5, 1.995])  # one within 0.02 of each end of [1, 2]
    out = fitting._zoom_edge(None, {"p": p}, "p_axis_zoom", _zoom(1.0, 2.0))
    assert out["draws_at_edge"] == pytest.approx(2 / 8)
    assert out["message"].startswith("25.00% of the draws lie at an end of the narrowed p (in [1, 2])")
    # one end only
    low = fitting._zoom_edge(None, {"p": p[:-1]}, "p_axis_zoom", _zoom(1.0, 2.0))
    high = fitting._zoom_edge(None, {"p": p[1:]}, "p_axis_zoom", _zoom(1.0, 2.0))
    assert low["draws_at_edge"] == pytest.approx(1 / 7) and high["draws_at_edge"] == pytest.approx(1 / 7)
    # draws just beyond the band (farther than 2% of the window from an end) are not at the edge
    clear = fitting._zoom_edge(None, {"p": np.array([1.021, 1.5, 1.979])}, "p_axis_zoom", _zoom(1.0, 2.0))
    assert clear == {"draws_at_edge": 0.0}
    # an end the window shares with the prior's range is the prior's, not the window's: not counted
    at_prior = np.array([0.001, 1.0, 1.999])
    assert fitting._zoom_edge(None, {"p": at_prior}, "p_axis_zoom", _zoom(0.0, 2.0))["draws_at_edge"] == 1 / 3
    at_prior = np.array([0.001, 1.0, 2.999])
    assert fitting._zoom_edge(None, {"p": at_prior}, "p_axis_zoom", _zoom(0.0, 3.0)) == {"draws_at_edge": 0.0}
    # a zoom refused leaves nothing to count
    assert fitting._zoom_edge(None, {"p": p}, "p_axis_zoom", _zoom(1.0, 2.0, kept=False)) == {}


def test_zoom_decision_makes_no_window_where_the_tables_cannot_be_checked(monkeypatch):
    """Where the start's table check cannot be made (preloads, geometry, yield: table_check gives None; or an exact
    solve the tables never needed raises), the decision narrows nothing and says which windows it did not make."""
    lik = SimpleNamespace(axis=None)
    monkeypatch.setattr(fitting, "_check_between_nodes", lambda lik, point: (None, None, None))
    assert fitting.zoom_decision(lik, {"EI0": 1.0, "p": 0.5}) == ({}, None, {"effect_window": None, "p_window": None})

    def raise_(lik, point):
        raise ValueError("no exact solve")

    monkeypatch.setattr(fitting, "_check_between_nodes", raise_)
    assert fitting.zoom_decision(lik, {"EI0": 1.0, "p": 0.5}) == ({}, None, {"effect_window": None, "p_window": None})


class _Post:
    def __init__(self, lik, finite=True):
        self.likelihood, self.finite = lik, finite

    def to_natural(self, theta):
        return {"EI0": np.array([2.0]), "p": np.array([0.5])}

    def to_sample(self, point):
        return np.array([[np.log(point["EI0"]), point["p"]]])

    def log_prob(self, theta):
        return 0.0 if self.finite else -np.inf


def _run_zoom(monkeypatch, after, finite=True):
    """_zoom_tables on stand-ins: the first check asks for a p window (shift 2 sd), the narrowed tables' check is
    ``after`` (a shift in sd, or None where it cannot be made); ``finite`` whether the narrowed posterior has the
    start in its support."""
    lik = SimpleNamespace(axis=None, p_grid=np.linspace(0.0, 3.0, 61), shape_weight=0.37)
    zlik = SimpleNamespace(axis=None, p_grid=np.linspace(0.4, 0.6, 61), shape_weight=1.0)
    before = {"shift_in_sd": {"p": 2.0}}
    decisions = iter(
        [
            (dict(before), before, {"effect_window": None, "p_window": (0.4, 0.6)}),
            ({}, None if after is None else {"shift_in_sd": {"p": after}}, {"effect_window": None, "p_window": None}),
        ]
    )
    monkeypatch.setattr(fitting, "zoom_decision", lambda lik_, point: next(decisions))
    monkeypatch.setattr(fitting, "build_likelihood", lambda spec, pr, effects, **options: zlik)
    monkeypatch.setattr(fitting, "LogPosterior", lambda lik_, pr: _Post(lik_, finite))
    config = {}
    post = _Post(lik)
    theta0 = np.array([np.log(2.0), 0.5])
    at_start, zoomed = fitting._zoom_tables(SimpleNamespace(specimen="s"), None, (), config, post, theta0)
    records, lik_out, post_out, theta_out = zoomed
    return records["p_axis_zoom"], config, lik_out, post_out is post, theta_out


def test_narrowed_tables_are_kept_only_where_their_check_improves_and_keep_the_shape_weight(monkeypatch):
    """The zoom is kept (config records its window, the narrowed likelihood samples, with the first's centerline
    weight) only where the narrowed tables' worst shift is smaller than the first's; a worse check, one that cannot
    be made, or a start outside the narrowed support keeps the first tables."""
    zoom, config, lik, same_post, _ = _run_zoom(monkeypatch, after=0.01)
    assert zoom["kept"] and not same_post and config == {"p_window": [0.4, 0.6]}
    assert zoom["shift_in_sd_before"] == {"p": 2.0} and zoom["shift_in_sd_after"] == {"p": 0.01}
    assert zoom["p_range"] == [0.4, 0.6] and zoom["p_range_before"] == [0.0, 3.0] and zoom["nodes"] == 61
    assert lik.p_grid[0] == 0.4 and lik.shape_weight == 0.37  # the narrowed tables, the first's centerline weight
    for after, finite in ((3.0, True), (2.0, True), (None, True), (0.01, False)):  # 2.0: no better than before
        zoom, config, lik, same_post, theta = _run_zoom(monkeypatch, after=after, finite=finite)
        assert not zoom["kept"] and lik.p_grid[0] == 0.0 and same_post and config == {}, (after, finite)
        assert zoom["shift_in_sd_after"] == (None if after is None or not finite else {"p": after})
        np.testing.assert_array_equal(theta, [np.log(2.0), 0.5])

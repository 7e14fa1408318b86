"""The forward solver's scalar root search on functions whose roots are known (bayesrod.physics.elastica).

``_illinois`` (Newton-probed regula falsi for small batches, plain Illinois rounds for large ones) and
``_bracket_and_solve`` (expansion from a guess, then the root search; NaN past a branch end) are what every
force and contact solve of the elastica runs through. Here they solve increasing functions with exact
roots: each root to the solver's tolerance, in a bounded number of rounds (a round is one batched call of
the function, the cost that counts: one march costs about the same for 1 or 100 problems). The round
bounds are the counts of the current code plus a margin of about a third; a search that loses its
superlinear convergence (a broken Illinois halving, a Newton step from the wrong side) needs several times
as many.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayesrod.physics import elastica as el


def assert_roots(x, r):
    """Each root to the search's tolerance: 1e-13 relative above 1, absolute below (2e-13 allowed)."""
    assert np.all(np.abs(x - r) <= 2e-13 * np.maximum(1.0, np.abs(r))), np.max(np.abs(x - r))


ROOTS = np.random.default_rng(7).uniform(0.2, 3.0, 600)

#: increasing functions g(x) - g(r) with root r: mild, convex and concave
FAMILIES = {
    "cubic": lambda x: x**3 + x,
    "exp": lambda x: np.expm1(3.0 * x),
    "sqrt": np.sqrt,
}


def _counted(g, roots, calls):
    def fun(x, i):
        calls.append(np.size(x))
        return g(x) - g(roots[i])

    return fun


def _brackets(roots, seed=0):
    """Brackets as the expansion leaves them: the root within a factor 1.01-1.6 of either end."""
    rng = np.random.default_rng(seed)
    return roots / rng.uniform(1.01, 1.6, roots.size), roots * rng.uniform(1.01, 1.6, roots.size)


# (family, batch size) -> most rounds: the Newton-probed path (5 problems) and the plain one (600)
ROUNDS = {
    ("cubic", 5): 8,
    ("exp", 5): 12,
    ("sqrt", 5): 6,
    ("cubic", 600): 12,
    ("exp", 600): 17,
    ("sqrt", 600): 10,
}


@pytest.mark.parametrize(("family", "n"), sorted(ROUNDS))
def test_illinois_finds_known_roots_to_its_tolerance_in_few_rounds(family, n):
    g, r = FAMILIES[family], ROOTS[:n]
    assert (n <= el.NEWTON_BATCH) == (n == 5)  # both paths of the search are exercised
    lo, hi = _brackets(r)
    calls: list[int] = []
    fun = _counted(g, r, calls)
    idx = np.arange(n)
    glo, ghi = fun(lo, idx), fun(hi, idx)
    calls.clear()
    lo0 = lo.copy()
    x = el._illinois(fun, lo, hi, glo, ghi)
    assert_roots(x, r)
    assert len(calls) <= ROUNDS[family, n], len(calls)
    # the small batch takes a Newton probe beside each candidate (two points per problem per round), the
    # large one plain rounds until few problems are left
    assert calls[0] == (2 * n if n <= el.NEWTON_BATCH else n)
    np.testing.assert_array_equal(lo, lo0)  # the caller's brackets are not narrowed in place


def test_illinois_on_a_wide_bracket_and_a_root_at_its_end():
    """A bracket [0, 10] around a convex function (the regula falsi point starts next to 0), and a
    problem whose root is the bracket's upper end (g(hi) = 0: the answer at once)."""
    g = FAMILIES["cubic"]
    r = np.array([0.3, 1.1, 2.9, 10.0])
    calls: list[int] = []
    fun = _counted(g, r, calls)
    idx = np.arange(r.size)
    lo, hi = np.zeros(r.size), np.full(r.size, 10.0)
    x = el._illinois(fun, lo, hi, fun(lo, idx), fun(hi, idx))
    assert_roots(x, r)
    assert len(calls) <= 2 + 14


def test_illinois_treats_nan_past_a_branch_end_as_too_far():
    """The function is NaN above c (the branch ends there) and the root lies below c: the NaN points
    count as above the root (``_too_far``) and the search converges on the root."""
    c = np.array([1.05, 1.5, 2.0])
    r = np.array([1.0, 1.2, 0.4])

    def fun(x, i):
        return np.where(x <= c[i], np.sqrt(x) - np.sqrt(r[i]), np.nan)

    idx = np.arange(r.size)
    lo, hi = 0.5 * r, c * 1.5
    ghi = el._too_far(fun(hi, idx))
    assert np.all(np.isinf(ghi))
    # capped as the search caps the values it retains
    x = el._illinois(fun, lo, hi, fun(lo, idx), np.minimum(ghi, 1e300))
    assert_roots(x, r)


def test_bracket_and_solve_expands_from_guesses_above_and_below_the_root():
    """Guesses 100x below and 100x above the root (the expansion grows the bracket from the guess,
    with 0 as its lower end); a cap ``x_max`` below the root reports no root there."""
    g = FAMILIES["cubic"]
    r = np.array([0.5, 2.0, 40.0, 0.01])
    fun = _counted(g, r, [])
    for guess in (r / 100, r * 100):
        x, ok = el._bracket_and_solve(fun, guess)
        assert ok.all()
        assert_roots(x, r)
    x, ok = el._bracket_and_solve(fun, r / 100, x_max=1.0)
    np.testing.assert_array_equal(ok, r < 1.0)
    assert np.all(np.isnan(x[~ok]))
    assert_roots(x[ok], r[ok])


def test_bracket_and_solve_finds_a_root_at_any_point_of_the_first_expansion_round():
    """One round tries the guess times 1, 1.6, 2.56 and 4.1 (``EXPAND_POINTS`` growths): the root between any
    two of them, and past the last, is the root. (Taking the point before the last as the bracket's top when the
    last one stopped returned that point, 2.56 x the guess, as the root: the guesses 100x off never land there.)"""
    g = FAMILIES["cubic"]
    r = np.full(6, 2.0)
    guess = r / np.array([1.3, 2.0, 3.3, 4.0, 5.0, 8.0])
    x, ok = el._bracket_and_solve(_counted(g, r, []), guess)
    assert ok.all()
    assert_roots(x, r)


def test_bracket_and_solve_takes_the_first_root_along_a_folding_branch():
    """g rises to a peak at x = 1 and falls back (the force-displacement curve folding): a target below
    the peak has two roots; the search keeps the loading branch's, the smaller."""
    target = np.array([0.2, 0.75, 0.9])

    def fun(x, i):
        return x * np.exp(1.0 - x) - target[i]

    # the smaller root of x e^(1-x) = t, by bisection on [0, 1] (where the function rises)
    lo, hi = np.zeros(3), np.ones(3)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        up = fun(mid, np.arange(3)) >= 0
        hi, lo = np.where(up, mid, hi), np.where(up, lo, mid)
    x, ok = el._bracket_and_solve(fun, np.full(3, 0.05))
    assert ok.all()
    np.testing.assert_allclose(x, hi, rtol=1e-12, atol=0)


def test_locate_starts_from_the_secant_of_the_step_and_converges_in_few_newton_steps(monkeypatch):
    """``_locate`` (the contact inside the step that crossed it) starts from the secant of the step's ends and
    needs few Newton steps: on a curled uniform rod (zeta = sin(k s) / k) the partial step to a height
    crossed inside the step, in at most 4 steps of the stepper (the secant end, then Newton); a start at the
    step's end or at 0 (a wrong secant) takes more, and 8 Newton steps hide it from the answer alone."""
    n, k = 48, 2.0
    eta = np.sin(k * 20.4 / n) / k  # crossed inside step 20 (sigma 20/48 to 21/48), zeta increasing there
    P, _ = el._problem(eta, 0.0, None)
    P = el._prepare(P)
    s0, h = 20 / n, 1 / n
    Y0 = np.array([[(1 - np.cos(k * s0)) / k], [np.sin(k * s0) / k], [k * s0], [k]])
    calls = []
    step = el._step

    def counted(*a):
        calls.append(1)
        return step(*a)

    monkeypatch.setattr(el, "_step", counted)
    y, d = el._locate(Y0, s0, np.zeros(1), P, 1, P["eta"], np.array([h]))
    np.testing.assert_allclose(s0 + d, np.arcsin(k * eta) / k, rtol=1e-13)
    np.testing.assert_allclose(y[1], eta, rtol=1e-14)
    assert len(calls) <= 4, len(calls)
    # with a force on the step (the contact's load), against bisection on the stepper itself
    f = np.array([3.0])
    lo, hi = 0.0, h
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if step(Y0, s0, mid, f, P, 1.0)[1, 0] < eta else (lo, mid)
    calls.clear()
    y, d = el._locate(Y0, s0, f, P, 1, P["eta"], np.array([h]))
    np.testing.assert_allclose(d, 0.5 * (lo + hi), rtol=1e-12)
    assert len(calls) <= 4, len(calls)

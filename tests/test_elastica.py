"""Forward elastica against analytic solutions and an independent solve_ivp reference."""

import numpy as np
import pytest

from bayesrod.physics import (
    Effects,
    contact_from_force,
    contact_from_force_nd,
    force_from_displacement,
    force_from_displacement_nd,
    k_x,
)
from bayesrod.physics import reference as R
from bayesrod.physics.presets import PRESETS


# --------------------------------------------------------------------------- #
# Bisshopp & Drucker (1945): uniform cantilever, tip load P L^2/EI = 1 and 2
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("length", [1.0, 1.5, 3.0])
def test_bisshopp_drucker(length):
    sol = force_from_displacement([0.30172, 0.49346], [0.94357, 0.83936], 1.0, 0.0, length)
    assert not sol.slipped.any()
    np.testing.assert_allclose(sol.force_N, [1.0, 2.0], atol=1e-4)
    # The contact sits at s = 1 m: the published tip of the unit-length rod.
    np.testing.assert_allclose(sol.contact_s_m, [1.0, 1.0], atol=1e-4)


def test_bisshopp_drucker_force_to_shape():
    sol = contact_from_force([1.0, 2.0], [0.94357, 0.83936], 1.0, 0.0, 2.0)
    np.testing.assert_allclose(sol.contact_x_m, [0.30172, 0.49346], atol=2e-5)
    np.testing.assert_allclose(sol.contact_s_m, [1.0, 1.0], atol=2e-5)


# --------------------------------------------------------------------------- #
# Small deflection: k_x = 3 EI / h^3 for constant EI, eq. kx for the taper
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("EI,h,L", [(1.0, 0.5, 1.0), (0.2, 0.1, 0.47), (3.0, 0.7, 0.8)])
def test_small_deflection_uniform(EI, h, L):
    D = 1e-5 * h
    sol = force_from_displacement(D, h, EI, 0.0, L)
    np.testing.assert_allclose(sol.force_N / D, 3 * EI / h**3, rtol=1e-4)


@pytest.mark.parametrize("preset", ["twig", "grass"])
def test_small_deflection_taper(preset):
    pr = PRESETS[preset]
    h = np.array(pr["heights_m"])
    D = 1e-5 * h
    sol = force_from_displacement(D, h, pr["EI0"], pr["p"], pr["length_m"])
    np.testing.assert_allclose(sol.force_N / D, k_x(h, pr["EI0"], pr["p"], pr["length_m"]), rtol=1e-4)


# --------------------------------------------------------------------------- #
# Published twig and grass: agreement with the reference up to slip
# --------------------------------------------------------------------------- #
def _branch_end(eta, p, eff=None):
    d = np.linspace(0, 1.2, 241)
    r = force_from_displacement_nd(d, eta, p, eff)
    return d[~r["slipped"]].max()


@pytest.mark.parametrize("preset", ["twig", "grass"])
def test_forces_agree_with_reference_up_to_slip(preset):
    pr = PRESETS[preset]
    L, EI0, p = pr["length_m"], pr["EI0"], pr["p"]
    for h in pr["heights_m"]:
        eta = h / L
        d_end = _branch_end(eta, p)
        d = d_end * np.array([0.002, 0.05, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.97])
        fast = force_from_displacement(d * L, h, EI0, p, L)
        assert not fast.slipped.any()
        # the reference at its default rtol 1e-12: at 0.97 of the branch end the force is flat to 1e-7 and the
        # push must be located to ~1e-10 in force; at rtol 1e-10 the reference lost that point on grass (NaN
        # with scipy 1.17.1, 2026-11-25), at 1e-12 it costs 20% more
        ref = np.array([R.solve_displacement(x, eta, p)["f"] for x in d]) * EI0 / L**2
        np.testing.assert_allclose(fast.force_N, ref, rtol=1e-6)


def test_force_to_contact_agrees_with_reference():
    rng = np.random.default_rng(3)
    eta = rng.uniform(0.1, 0.9, 25)
    p = rng.uniform(0.0, 2.0, 25)
    # forces up to ~60% of the small-deflection scale at that height
    f = rng.uniform(0.0, 0.6, 25) * 2.0 / eta**2 / (1 + 2 * p * eta)
    fast = contact_from_force_nd(f, eta, p)
    for i in range(25):
        ref = R.solve_force(f[i], eta[i], p[i])
        assert fast["found"][i] == ref["found"]
        if ref["found"]:
            np.testing.assert_allclose(fast["xi_c"][i], ref["xi_c"], rtol=1e-8, atol=1e-12)
            np.testing.assert_allclose(fast["sig_c"][i], ref["sig_c"], rtol=1e-8)


def test_slip_reported_not_invented():
    pr = PRESETS["twig"]
    L, EI0, p, h = pr["length_m"], pr["EI0"], pr["p"], 0.65
    d_end = _branch_end(h / L, p) * L
    sol = force_from_displacement([0.5 * d_end, 1.05 * d_end, 3.0], h, EI0, p, L)
    assert list(sol.slipped) == [False, True, True]
    assert np.isnan(sol.force_N[1:]).all() and np.isfinite(sol.force_N[0])
    # every state of a slipped push is a float NaN (not None in an object array), every other one a number
    nd = force_from_displacement_nd(np.array([0.5, 1.05]) * d_end / L, h / L, p)
    for k in ("f", "f_measured", "sig_c", "xi_c", "phi_c", "m0"):
        assert nd[k].dtype == np.float64 and np.isfinite(nd[k][0]) and np.isnan(nd[k][1]), k
    # the reference agrees that 5% past the branch end there is no contact, and 5% before it there is
    # (rtol 1e-9 is ample for a yes/no; at the default 1e-12 the bisection to the branch end took 25 s)
    assert R.solve_displacement(1.05 * d_end / L, h / L, p, rtol=1e-9)["slipped"]
    assert not R.solve_displacement(0.95 * d_end / L, h / L, p, rtol=1e-9)["slipped"]


def test_force_increases_monotonically_along_branch():
    for eta, p in [(0.56, 0.43), (0.81, 0.43), (0.19, 1.6), (0.3, 0.0)]:
        d = np.linspace(0, 0.99 * _branch_end(eta, p), 100)
        f = force_from_displacement_nd(d, eta, p)["f"]
        # strictly rising, except a plateau flat to round-off where the stem lies
        # horizontal at the sensor just before it slips
        assert np.all(np.diff(f) > -1e-9 * f.max())
        assert np.all(np.diff(f[: len(f) // 2]) > 0)


# --------------------------------------------------------------------------- #
# Nondimensional structure and batching
# --------------------------------------------------------------------------- #
def test_EI0_is_a_pure_scale_and_length_scales():
    base = force_from_displacement(0.05, 0.45, 2.63, 0.43, 0.8)
    stiffer = force_from_displacement(0.05, 0.45, 5.26, 0.43, 0.8)
    np.testing.assert_allclose(stiffer.force_N, 2 * base.force_N, rtol=1e-12)
    # L -> 2L, h -> 2h, D -> 2D: f = F L^2/EI0 unchanged, so F scales by 1/4
    big = force_from_displacement(0.10, 0.90, 2.63, 0.43, 1.6)
    np.testing.assert_allclose(big.force_N, base.force_N / 4, rtol=1e-10)
    np.testing.assert_allclose(big.contact_s_m, 2 * base.contact_s_m, rtol=1e-10)


def test_batching_matches_single_solves():
    D = np.linspace(0.0, 0.2, 4)[None, :]
    h = np.array([0.45, 0.55, 0.65])[:, None]
    batch = force_from_displacement(D, h, 2.63, 0.43, 0.8)
    assert batch.force_N.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            one = force_from_displacement(D[0, j], h[i, 0], 2.63, 0.43, 0.8)
            np.testing.assert_allclose(batch.force_N[i, j], one.force_N, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("eff", [None, {"kappa0": 0.3}, {"c_base": 0.05}, {"tilt": 0.05}])
def test_shape_grid_matches_reference(eff):
    # with each effect the reference's centerline (what the SBC simulates frames from) is the fast one: its rest
    # curvature and its base rotation under the moment f eta were untested (session 68)
    f, eta, p = 1.5, 0.5625, 0.43
    res = contact_from_force_nd(f, eta, p, eff, n_steps=64, keep_shape=True)
    sig = np.linspace(0, 1, 65)
    ref = R.shape_at_force(f, eta, p, sig, eff)
    np.testing.assert_allclose(res["grid"][:, 0], ref[0], atol=1e-8)
    np.testing.assert_allclose(res["grid"][:, 1], ref[1], atol=1e-8)
    if eff:  # the effect moves the centerline by far more than the tolerance
        plain = R.shape_at_force(f, eta, p, sig)
        assert np.max(np.abs(ref[0] - plain[0])) > 1e-3


def test_the_reference_shape_refuses_the_force_of_a_push_past_its_slip():
    """solve_displacement gives f = NaN past the slip; the shape at it is refused by name, not deep in scipy
    (sbc_geometry.py crashed on a frame 1e-3 L past the reference's slip)."""
    past = R.solve_displacement(0.9, 0.5625, 0.43)
    assert past["slipped"] and not np.isfinite(past["f"])
    with pytest.raises(ValueError, match="f: expected a finite"):
        R.shape_at_force(past["f"], 0.5625, 0.43, np.linspace(0, 1, 5))


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"EI0": -1.0}, "EI0"),
        ({"EI0": 0.0}, "EI0"),  # each bound itself is outside
        ({"p": -0.1}, "p"),
        ({"height_m": 0.9}, "height_m"),
        ({"height_m": 0.8}, "height_m"),
        ({"height_m": 0.0}, "height_m"),
        ({"length_m": 0.0}, "length_m"),
        ({"displacement_m": -0.1}, "displacement_m"),
        ({"displacement_m": float("nan")}, "displacement_m"),
        ({"displacement_m": float("inf")}, "displacement_m"),
    ],
)
def test_impossible_inputs_raise_value_error(kwargs, field):
    args = {"displacement_m": 0.1, "height_m": 0.45, "EI0": 2.63, "p": 0.43, "length_m": 0.8}
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        force_from_displacement(**args)


@pytest.mark.parametrize("points", [(1, 1), (4, 7)])
def test_root_search_finds_roots_next_to_the_branch_end(points, monkeypatch):
    """The bracketing of direction (b) (several points per round, or plain expansion and bisection)
    finds a root just short of the branch end and reports none just past it, to machine precision."""
    from bayesrod.physics import elastica as el

    monkeypatch.setattr(el, "EXPAND_POINTS", points[0])
    monkeypatch.setattr(el, "BOUNDARY_SECTIONS", points[1])
    x_end = 1.7  # the branch ends here (NaN beyond); t(x) = sqrt-fold-like rise to t(x_end) = 1
    t_end = 1.0
    gap = np.array([0.5, 1e-3, 1e-6, -1e-9, -1e-3])  # target below (+) or above (-) t_end; root 1e-12 from it
    target = t_end - gap
    rounds = []

    def fun(x, i):
        rounds.append(x.size)
        t = t_end - np.sqrt(np.maximum(x_end - x, 0.0) / x_end)
        return np.where(x <= x_end, t - target[i], np.nan)

    x, ok = el._bracket_and_solve(fun, np.full(gap.size, 0.01))
    np.testing.assert_array_equal(ok, gap > 0)
    exact = x_end * (1.0 - gap[gap > 0] ** 2)
    np.testing.assert_allclose(x[ok], exact, rtol=1e-12, atol=0)
    if points != (1, 1):  # each round does the work of several: fewer rounds than bisection's ~60
        assert len(rounds) < 35


@pytest.mark.parametrize("p", [0.0, 0.43, [0.2, 1.0, 3.0, 4.0]])
@pytest.mark.parametrize("sig", [0.0, 0.5, 0.99, 1.0])
def test_plain_fast_step_matches_the_general_step(p, sig):
    """The one-step-size path (stage dot products, taper at all stages at once) against the general path."""
    from bayesrod.physics import elastica as E

    rng = np.random.default_rng(3)
    B = 4
    P = E._prepare(E._problem(np.full(B, 0.6), np.broadcast_to(np.asarray(p, float), B), None)[0])
    Y = np.vstack([rng.uniform(0, 0.3, (2, B)), rng.uniform(-0.5, 1.2, (1, B)), rng.uniform(-1, 1, (1, B))])
    f, active = rng.uniform(0.1, 3.0, B), np.array([1.0, 0.0, 1.0, 1.0])
    h = 1.0 / 48 if sig < 1.0 else 1e-4
    if sig > 0.9:
        Y[3], active = 0.0, np.zeros(B)  # above the contact (near a tapered tip): no load, no moment
    assert P["_plain"]
    fast = E._step_plain(Y, sig, h, f, P, active)
    np.testing.assert_allclose(fast, E._step_general(Y, sig, h, f, P, active), rtol=1e-11, atol=1e-14)
    _assert_step_takes_the_fast_path(E, (Y, sig, h, f, P, active), fast)


@pytest.mark.parametrize("p", [0.43, [0.2, 1.0, 2.0, 0.0]])
def test_plain_step_per_element_matches_the_general_step(p):
    """Per-element step sizes and positions (the partial steps that locate a contact), plain rod."""
    from bayesrod.physics import elastica as E

    rng = np.random.default_rng(4)
    B = 4
    P = E._prepare(E._problem(np.full(B, 0.6), np.broadcast_to(np.asarray(p, float), B), None)[0])
    Y = np.vstack([rng.uniform(0, 0.3, (2, B)), rng.uniform(-0.5, 1.2, (1, B)), rng.uniform(-1, 1, (1, B))])
    f, active = rng.uniform(0.1, 3.0, B), np.array([1.0, 0.0, 1.0, 1.0])
    sig, h = np.array([0.0, 0.3, 0.55, 0.7]), np.array([0.02, 0.0, 0.005, 0.013])
    for s, a in [(sig, active), (0.4, 1.0)]:
        fast = E._step_plain_each(Y, s, h, f, P, a)
        np.testing.assert_allclose(fast, E._step_general(Y, s, h, f, P, a), rtol=1e-11, atol=1e-14)
        _assert_step_takes_the_fast_path(E, (Y, s, h, f, P, a), fast)


def _assert_step_takes_the_fast_path(E, args, numpy_fast):
    """_step takes the compiled loop when numba is there (and it matches the numpy fast path to round-off), else
    the numpy fast path itself."""
    got = E._step(*args)
    if E._compiled.step is None:
        np.testing.assert_array_equal(got, numpy_fast)
    else:
        np.testing.assert_array_equal(got, E._step_compiled(*args))
        np.testing.assert_allclose(got, numpy_fast, rtol=1e-11, atol=1e-14)  # a tangent spun to 1570 rad: 1e-12


def test_the_compiled_step_is_there_unless_switched_off():
    """numba is a dependency: the suite runs the compiled loop users get, unless BAYESROD_NO_JIT asks for numpy."""
    import os

    from bayesrod.physics import _compiled

    assert (_compiled.step is None) == bool(os.environ.get("BAYESROD_NO_JIT"))


@pytest.mark.skipif("not __import__('bayesrod.physics._compiled').physics._compiled.step")
def test_the_step_compiles_where_no_cache_can_be_written():
    """A read-only install with no writable home: numba finds no cache location and raises at decoration; bayesrod
    must still import and compile (in the process) rather than fail on import."""
    import subprocess
    import sys

    code = (
        "import numba.core.caching as c; c.CacheImpl._locator_classes = []\n"
        "import numpy as np\n"
        "from bayesrod.physics import elastica as E, _compiled\n"
        "assert _compiled.step is not None\n"
        "print(float(E.force_from_displacement_nd(np.array([0.1]), 0.5, 0.4)['f'][0]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert abs(float(out.stdout) - 1.8143987) < 1e-6


@pytest.mark.skipif("not __import__('bayesrod.physics._compiled').physics._compiled.step")
@pytest.mark.parametrize("B", [0, 1, 7, 300])
@pytest.mark.parametrize("taper", [0.43, 0.25, "per-rod"])  # 0.25: 4p = 1, where a test of p4 == 1 would hide
def test_compiled_step_matches_the_numpy_step_on_every_element(B, taper):
    """The compiled loop against the numpy paths, one step size and one per element, on batches with rods past
    the contact (no load), at the tip (sigma = 1), with NaN and infinite states (which must stay NaN, not raise),
    and a non-contiguous state array."""
    from bayesrod.physics import elastica as E

    rng = np.random.default_rng(11 + B)
    p = rng.uniform(0.0, 2.0, B) if taper == "per-rod" else taper
    P = E._prepare(E._problem(np.full(B, 0.6), np.broadcast_to(np.asarray(p, float), B), None)[0])
    n = 2 * B
    wide = np.vstack([rng.uniform(0, 0.3, (2, n)), rng.uniform(-1.5, 1.5, (1, n)), rng.uniform(-1, 1, (1, n))])
    Y = wide[:, ::2]  # a view with stride 2
    if B >= 7:
        Y[2, 3], Y[3, 4], Y[2, 5] = np.nan, np.inf, -np.inf
    f, active = rng.uniform(0.0, 4.0, B), (rng.uniform(size=B) < 0.7).astype(float)
    for sig, h in [(0.3, 1.0 / 48), (1.0 - 1.0 / 48, 1.0 / 48), (1.0, 1e-4)]:
        Ys = Y.copy() if sig < 0.9 else np.vstack([Y[:3], np.zeros((1, B))])  # near the tip: above the contact
        want = E._step_plain(Ys, sig, h, f, P, active if sig < 0.9 else 0.0)
        got = E._step_compiled(Ys, sig, h, f, P, active if sig < 0.9 else 0.0)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    sig_b, h_b = rng.uniform(0.0, 0.6, B), rng.uniform(0.0, 0.03, B)
    for sig, h, a in [(sig_b, h_b, active), (0.4, h_b, 1.0), (sig_b, 0.01, 0.0)]:
        want = E._step_plain_each(Y, sig, h, f, P, a)
        got = E._step_compiled(Y, sig, h, f, P, a)
        # round-off grows with the turn of the tangent (a rod near a tapered tip spins by thousands of radians)
        turn = np.nan_to_num(np.abs(want[2] - Y[2]), nan=0.0, posinf=0.0)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        miss, size = (np.nan_to_num(np.abs(a), nan=0.0, posinf=0.0) for a in (got - want, want))
        assert np.all(miss <= 1e-13 * size + 1e-14 * (1.0 + turn)), miss.max()


@pytest.mark.skipif("not __import__('bayesrod.physics._compiled').physics._compiled.step")
@pytest.mark.parametrize("B", [1, 9, 300])
@pytest.mark.parametrize(
    "eff",
    [{"kappa0": 0.4}, {"mu": 0.3}, {"w0": 0.8}, {"kappa0": -0.3, "mu": 0.2, "w0": 1.5}, "per-rod"],
    ids=["rest-curvature", "friction", "weight", "all", "per-rod"],
)
@pytest.mark.parametrize("taper", [0.43, 0.25, "per-rod"])
def test_compiled_general_step_matches_the_numpy_general_step(B, eff, taper):
    """The compiled loop's general path against _step_general (and _rhs), each effect alone, all three, and
    different effects per rod (some rods plain): one step size and one per element, below and past the tip."""
    from bayesrod.physics import elastica as E

    rng = np.random.default_rng(21 + B)
    p = rng.uniform(0.0, 1.5, B) if taper == "per-rod" else taper
    if eff == "per-rod":
        eff = {k: rng.uniform(0.0, 1.0, B) * (rng.uniform(size=B) < 0.5) for k in ("kappa0", "mu", "w0")}
    P = E._prepare(E._problem(np.full(B, 0.6), np.broadcast_to(np.asarray(p, float), B), eff)[0])
    assert not P["_plain"]
    Y = np.vstack([rng.uniform(0, 0.3, (2, B)), rng.uniform(-1.5, 1.5, (1, B)), rng.uniform(-1, 1, (1, B))])
    f, active = rng.uniform(0.0, 4.0, B), (rng.uniform(size=B) < 0.7).astype(float)
    cases = [(0.3, 1.0 / 48, active), (1.0 - 1.0 / 48, 1.0 / 48, active), (1.0, 1e-4, 0.0)]
    cases += [(rng.uniform(0.0, 0.6, B), rng.uniform(0.0, 0.03, B), active), (0.4, rng.uniform(0.0, 0.03, B), 1.0)]
    for sig, h, a in cases:
        Ys = Y if np.max(sig) < 0.9 else np.vstack([Y[:3], np.zeros((1, B))])  # near the tip: above the contact
        a = a if np.max(sig) < 0.9 else 0.0
        want = E._step_general(Ys, sig, h, f, P, a)
        got = E._step_compiled(Ys, sig, h, f, P, a)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        turn = np.nan_to_num(np.abs(want[2] - Ys[2]), nan=0.0, posinf=0.0)
        miss, size = (np.nan_to_num(np.abs(x), nan=0.0, posinf=0.0) for x in (got - want, want))
        assert np.all(miss <= 1e-13 * size + 1e-14 * (1.0 + turn)), (sig, miss.max())


def _curled_arc(n=48, sweep=2.6):
    """March grid (n + 1, 3, 1) of a circular arc of unit length turning past horizontal (sweep > pi/2): the
    centerline rises to its top and comes down again, as a stem pushed over would."""
    theta = np.linspace(0.0, sweep, n + 1)
    r = 1.0 / sweep  # the radius that makes the arc's length 1
    return np.stack([r * (1.0 - np.cos(theta)), r * np.sin(theta), theta], axis=1)[..., None]


def _centerline_grids(case: str, n_p: int, n_f: int) -> np.ndarray:
    """March grids (n + 1, 3, C): "elastica", pushed stems at h/L 0.56 for n_p values of p in [0, 1.5] and
    n_f forces in [0.2, 2.5] (those with contact); "curled", :func:`_curled_arc`."""
    if case == "curled":
        return _curled_arc()
    p = np.linspace(0.0, 1.5, n_p)[:, None]
    r = contact_from_force_nd(np.linspace(0.2, 2.5, n_f)[None, :], 0.56, p, keep_shape=True)
    return r["grid"].reshape(r["grid"].shape[0], 3, -1)[..., r["found"].ravel()]


@pytest.mark.parametrize("case", ["elastica", "curled"])
def test_centerline_at_heights_matches_a_fine_resampling(case):
    """The Newton-on-Hermite reading of x(z) against the obvious one: resample the same Hermite centerline
    at 20001 arc lengths and interpolate linearly in height on its running maximum (error ~1e-9 there);
    also below the base, above the top, and on a centerline that curls over and comes down."""
    from bayesrod.physics.elastica import centerline_at, centerline_x_at_heights

    grid = _centerline_grids(case, n_p=7, n_f=6)
    z = np.linspace(-0.05, 1.0, 301)  # from below the base to the rest height: bent stems end below it
    x, cos_phi = centerline_x_at_heights(grid, z)
    sig = np.linspace(0.0, 1.0, 20001)
    xz = centerline_at(grid, sig)
    tilt = np.gradient(xz[1], sig, axis=0) / np.hypot(np.gradient(xz[0], sig, axis=0), np.gradient(xz[1], sig, axis=0))
    for j in range(grid.shape[-1]):
        top = np.maximum.accumulate(xz[1, :, j])
        inside = (z >= 0.0) & (z < top[-1])
        np.testing.assert_allclose(x[j], np.interp(z, top, xz[0, :, j]), rtol=0, atol=1e-8)
        np.testing.assert_allclose(cos_phi[j, inside], np.interp(z, top, tilt[:, j])[inside], rtol=0, atol=1e-6)
        # below the base: the base; above the top: the tip, its exact tangent (the reference's one-sided
        # difference there is 3e-5 off)
        np.testing.assert_allclose(x[j, z < 0], 0.0, atol=1e-12)
        np.testing.assert_allclose(cos_phi[j, z < 0], 1.0, atol=1e-12)
        np.testing.assert_allclose(x[j, z >= top[-1]], grid[-1, 0, j], atol=1e-12)
        np.testing.assert_allclose(cos_phi[j, z >= top[-1]], np.cos(grid[-1, 2, j]), atol=1e-12)
    assert (z[None, :] > grid[:, 1].max(axis=0)[:, None]).any()  # some heights lie above a bent stem's top


@pytest.mark.parametrize("case", ["elastica", "curled"])
def test_normal_offsets_match_the_nearest_point_of_a_fine_resampling(case):
    """The Newton-on-Hermite nearest point against the obvious one: resample the same Hermite centerline
    at 20001 arc lengths, take the nearest sample and project the gap on its normal. Points up to 0.05 L
    off every part of the curve, near its top where it curls over too, some 0.15 L off (where Newton's
    second-order term matters), some beyond the tip and below the base (the nearest point is the end);
    and against the horizontal gap at the point's height, (x - x(z)) cos phi, for small horizontal
    offsets of an upright stem."""
    from bayesrod.physics.elastica import centerline_at, centerline_normal_offsets, centerline_x_at_heights

    rng = np.random.default_rng(3)
    grid = _centerline_grids(case, n_p=4, n_f=3)
    sig = np.linspace(0.0, 1.0, 20001)
    xz = centerline_at(grid, sig)  # (2, 20001, C)
    tx, tz = (np.gradient(xz[i], sig, axis=0) for i in (0, 1))
    norm = np.hypot(tx, tz)
    for j in range(grid.shape[-1]):
        # beside the curve (its last segment too), a few farther off, then beyond the tip and below the base
        on = np.concatenate([rng.uniform(0.0, 1.0, 200), rng.uniform(0.2, 0.8, 30), np.ones(15), np.zeros(5)])
        base = centerline_at(grid[..., j : j + 1], on)[:, :, 0]
        ang = rng.uniform(0, 2 * np.pi, on.size)
        r = np.concatenate([rng.uniform(0.0, 0.05, 200), rng.uniform(0.1, 0.15, 30), rng.uniform(0.0, 0.05, 20)])
        ang[-20:-5] = grid[-1, 2, j] + rng.uniform(-0.3, 0.3, 15)  # beyond the tip, along its tangent
        ang[-20:-5] = np.pi / 2 - ang[-20:-5]  # phi from the vertical, as an angle from the x axis
        ang[-5:] = -np.pi / 2 + rng.uniform(-0.3, 0.3, 5)  # below the base
        px, pz = base + r * np.array([np.cos(ang), np.sin(ang)])
        got = centerline_normal_offsets(grid[..., j : j + 1], px, pz)[0]
        d2 = (xz[0, :, j, None] - px) ** 2 + (xz[1, :, j, None] - pz) ** 2
        k = np.argmin(d2, axis=0)
        ux, uz = tx[k, j] / norm[k, j], tz[k, j] / norm[k, j]
        for end, node in ((0, 0), (sig.size - 1, -1)):  # at the ends, the exact tangent (one-sided: 3e-5 off)
            ux[k == end], uz[k == end] = np.sin(grid[node, 2, j]), np.cos(grid[node, 2, j])
        ref = (px - xz[0, k, j]) * uz - (pz - xz[1, k, j]) * ux
        np.testing.assert_allclose(got, ref, rtol=0, atol=2e-6)
        assert np.all(np.abs(got) <= np.sqrt(d2[k, np.arange(on.size)]) + 1e-12)  # never beyond the nearest sample
    if case == "elastica":  # small horizontal offsets: the horizontal gap at the height, to second order
        z = np.linspace(0.05, 0.5, 40)
        x, c = centerline_x_at_heights(grid, z)
        dx = rng.uniform(-2e-3, 2e-3, z.size)
        for j in range(grid.shape[-1]):
            got = centerline_normal_offsets(grid[..., j : j + 1], x[j] + dx, z)[0]
            np.testing.assert_allclose(got, dx * c[j], rtol=0, atol=2e-5)


def test_normal_offsets_of_many_centerlines_at_once_are_those_of_each_alone():
    """Batched over 1200 centerlines the nearest nodes are searched in chunks of points (a memory bound);
    every point of every chunk gets the offset it gets from its centerline alone."""
    from bayesrod.physics.elastica import centerline_normal_offsets

    grid = _centerline_grids("elastica", n_p=4, n_f=3)
    many = np.repeat(grid, -(-1200 // grid.shape[-1]), axis=2)[..., :1200]
    many = many * (1.0 + 1e-3 * np.arange(1200))[None, None, :]  # 1200 different centerlines
    rng = np.random.default_rng(5)
    px, pz = rng.uniform(0.0, 0.6, 400), rng.uniform(0.0, 0.9, 400)
    assert 4_000_000 // (1200 * many.shape[0]) < px.size / 3  # several chunks
    got = centerline_normal_offsets(many, px, pz)
    for c in range(0, 1200, 97):
        np.testing.assert_array_equal(got[c], centerline_normal_offsets(many[..., c : c + 1], px, pz)[0])


@pytest.mark.parametrize(
    "nd",
    [{"m_yield": 0.35}, {"m_yield": 0.32, "w0": 0.32}, {"m_yield": 0.3, "mu": 0.2}],
    ids=["plain", "self-weight", "friction"],
)
def test_plastic_branch_is_the_elastic_rod_on_a_base_turned_by_the_plastic_rotation(nd):
    """Beyond yield the base moment stays at the yield moment and the base has turned by phi_plastic. The
    same rod solved force-first with its base tilted by that angle (the base_tilt path, another piece of
    code) must reach the target displacement with base moment m_yield; for the plain rod the force is
    m_yield / eta exactly (the base moment of a horizontal force at height eta)."""
    from bayesrod.physics.elastica import force_from_displacement_nd

    eta, p = 0.625, 0.43
    d = np.array([0.02, 0.14, 0.26])
    r = force_from_displacement_nd(d, eta, p, nd)
    y = r["yielded"] & np.isfinite(r["f"])
    assert list(y) == [False, True, True]  # elastic first, then plastic
    assert np.all(np.diff(r["phi_plastic"][y]) > 0)  # the base keeps turning
    elastic = {k: v for k, v in nd.items() if k != "m_yield"}
    d0 = float(contact_from_force_nd(0.0, eta, p, elastic)["xi_c"])
    for f, phi, target in zip(r["f"][y], r["phi_plastic"][y], d[y], strict=True):
        c = contact_from_force_nd(f, eta, p, {**elastic, "tilt": phi})
        assert float(c["xi_c"]) - d0 == pytest.approx(target, abs=1e-9)
        assert float(c["m0"]) == pytest.approx(nd["m_yield"], abs=1e-9)
    if nd.keys() == {"m_yield"}:
        np.testing.assert_allclose(r["f"][y], nd["m_yield"] / eta, rtol=1e-12)


def test_dimensional_solutions_report_every_field_in_si_units_and_round_trip():
    """force_from_displacement and contact_from_force on the same rod: every field of one matches the other
    (displacement, force, contact arc length and angle, centerline), the base moment is F h (statics of a
    horizontal force at height h), and a force the yielding base cannot carry is not 'found'."""
    from bayesrod.physics import Effects
    from bayesrod.physics.elastica import DEFAULT_STEPS

    EI0, p, L, h = 2.63, 0.43, 0.8, 0.5
    D = np.array([0.02, 0.08, 0.15])
    a = force_from_displacement(D, h, EI0, p, L, keep_shape=True)
    np.testing.assert_array_equal(a.displacement_m, D)
    b = contact_from_force(a.true_force_N, h, EI0, p, L, keep_shape=True)
    np.testing.assert_allclose(b.force_N, a.true_force_N, rtol=1e-15)
    np.testing.assert_allclose(b.contact_x_m, D, atol=1e-9)
    np.testing.assert_allclose(b.contact_s_m, a.contact_s_m, atol=1e-9)
    np.testing.assert_allclose(b.contact_angle_rad, a.contact_angle_rad, atol=1e-9)
    assert np.all(a.contact_angle_rad > 0) and np.all(np.diff(a.contact_angle_rad) > 0)
    np.testing.assert_allclose(b.base_moment_Nm, a.true_force_N * h, rtol=1e-9)
    assert a.shape_xz_m.shape == b.shape_xz_m.shape == (DEFAULT_STEPS + 1, 2, 3)
    np.testing.assert_allclose(a.shape_xz_m, b.shape_xz_m, atol=1e-9)
    # the centerline is in metres: its last node is the tip, at arc length L from the base
    np.testing.assert_allclose(
        np.sum(np.hypot(*np.diff(a.shape_xz_m, axis=0).transpose(1, 0, 2)), axis=0), L, rtol=1e-3
    )
    assert b.found.all()
    c = contact_from_force(a.true_force_N, h, EI0, p, L, Effects(yield_moment=0.5 * a.true_force_N[1] * h))
    np.testing.assert_array_equal(c.found, [True, False, False])  # beyond the yield moment: no elastic contact
    assert force_from_displacement(D, h, EI0, p, L).shape_xz_m is None


def test_secant_k_theta_is_F_h_over_the_contact_rotation_from_rest_with_its_effects_and_steps():
    """F h / (angle(F) - angle(0)) written out from contact_from_force, with a rest curvature and a base spring
    (so the rest angle is not zero and the effects change the number). (The step count passed on cannot be
    seen here: 12 steps and the default 48 agree to 4e-11.)"""
    from bayesrod.physics import Effects
    from bayesrod.physics.elastica import contact_from_force, secant_k_theta

    eff = Effects(rest_curvature=0.4, base_compliance=30.0)
    F, h = np.array([0.5, 2.0]), 0.45
    ks = secant_k_theta(F, h, 2.63, 0.43, 0.8, eff, n_steps=12)
    on = contact_from_force(F, h, 2.63, 0.43, 0.8, eff, n_steps=12)
    rest = contact_from_force(np.zeros(2), h, 2.63, 0.43, 0.8, eff, n_steps=12)
    assert abs(rest.contact_angle_rad[0]) > 0.05  # the rest curvature tilts the contact before any push
    np.testing.assert_allclose(ks, F * h / (on.contact_angle_rad - rest.contact_angle_rad), rtol=1e-12)
    plain = secant_k_theta(F, h, 2.63, 0.43, 0.8, n_steps=12)
    assert np.all(plain > 1.05 * ks)  # the base spring softens it
    far = secant_k_theta([2.0, 500.0], h, 2.63, 0.43, 0.8)
    assert np.isfinite(far[0]) and np.isnan(far[1])  # no contact at 500 N: NaN, not a number


def test_contact_from_force_nd_reports_yield_per_element_of_a_batch():
    from bayesrod.physics import Effects

    f = np.array([[0.5, 1.0, 2.0], [2.5, 3.0, 3.5]])
    m_y = 1.2 * 0.8 / 2.63  # M_y L / EI0
    res = contact_from_force_nd(f, 0.5625, 0.43, Effects(yield_moment=1.2).nondim(0.8, 2.63))
    assert res["yielded"].shape == f.shape
    assert res["yielded"].any() and not res["yielded"].all()
    elastic = contact_from_force_nd(f, 0.5625, 0.43)  # the moment the clamp would carry without yield
    np.testing.assert_array_equal(res["yielded"], elastic["m0"] > m_y)


def test_a_height_the_rest_shape_never_reaches_is_named_in_a_batch():
    """With kappa0 L = 3 the unloaded stem curls over at z = L/3: h/L = 0.3 is reached, 0.6 is not, and the
    error names the one that is not (the second of the batch)."""
    from bayesrod.physics import Effects

    eff = Effects(rest_curvature=3.0).nondim(1.0, 1.0)
    ok = force_from_displacement_nd(0.01, 0.3, 0.0, eff)
    assert np.isfinite(ok["f"]) and ok["f"] > 0
    with pytest.raises(ValueError, match=r"^height_m: expected a height the unloaded stem reaches, got h/L = 0\.6 "):
        force_from_displacement_nd(0.01, np.array([0.3, 0.6]), 0.0, eff)


def test_a_yielded_push_keeps_the_shape_of_its_plastic_solution():
    """With keep_shape, a displacement past the yield returns the centerline of the plastic solution: its
    base leaves at the plastic rotation and it passes through the contact the force was solved for."""
    from bayesrod.physics import Effects
    from bayesrod.physics.elastica import centerline_x_at_heights

    eff = Effects(yield_moment=0.8).nondim(0.8, 2.63)
    res = force_from_displacement_nd(np.array([0.02, 0.15]), 0.5625, 0.43, eff, keep_shape=True)
    assert not res["yielded"][0] and res["yielded"][1] and res["phi_plastic"][1] > 0.01
    grid = res["grid"]  # (n + 1, 3, 2): xi, zeta, phi
    np.testing.assert_allclose(grid[0, 2, :], res["phi_plastic"], atol=1e-12)  # the base's tangent angle
    x, _ = centerline_x_at_heights(grid, np.array([0.5625]))
    np.testing.assert_allclose(x[:, 0], res["xi_c"], atol=1e-6)


@pytest.mark.parametrize("keep", [False, True])
@pytest.mark.parametrize("at", [30.5, 30.25, 30.8])
def test_march_finds_a_contact_height_the_rod_only_reaches_inside_one_step(keep, at):
    """A uniform rod under a constant moment (no force) curls into a circle of curvature k: zeta(s) =
    sin(k s) / k peaks at 1/k where the tangent turns horizontal. With that peak in the middle of a step
    of the 48-step march, a contact height between the step ends' zeta and the peak is crossed and left
    again inside the step: the march's peak check must find it, at s = asin(k eta) / k (before the peak),
    xi = (1 - cos(k s)) / k, phi = k s. The peak in the middle of the step and off it (the step's ends then
    read different heights)."""
    from bayesrod.physics import elastica as el

    n = 48
    k = np.pi / (2 * (at / n))  # the peak at sigma = at / 48, inside step 30
    ends = np.sin(k * np.array([30, 31]) / n) / k  # zeta at the step's ends, both below the peak 1/k
    eta = 0.5 * (ends.max() + 1.0 / k)
    assert ends.max() < eta < 1.0 / k
    P, _ = el._problem(eta, 0.0, None)
    out = el._march(np.zeros(1), np.array([k]), np.zeros(1), P, n, keep)
    s = np.arcsin(k * eta) / k
    assert out["found"][0]
    np.testing.assert_allclose(out["sig_c"], s, rtol=1e-9)
    np.testing.assert_allclose(out["xi_c"], (1 - np.cos(k * s)) / k, rtol=1e-8)
    np.testing.assert_allclose(out["phi_c"], k * s, rtol=1e-9)


def test_without_effects_the_measured_force_is_the_true_force():
    """``effects_nd`` None or without a force offset: no sensor offset (f_measured = f); with one, f plus it."""
    from bayesrod.physics import elastica as E

    d = np.array([0.01, 0.05])
    plain = E.force_from_displacement_nd(d, 0.6, 0.43)
    np.testing.assert_array_equal(plain["f_measured"], plain["f"])
    tilted = E.force_from_displacement_nd(d, 0.6, 0.43, {"tilt": 0.02})
    np.testing.assert_array_equal(tilted["f_measured"], tilted["f"])
    offset = E.force_from_displacement_nd(d, 0.6, 0.43, {"f_offset": 0.3})
    np.testing.assert_allclose(offset["f_measured"], plain["f"] + 0.3, rtol=1e-14)


@pytest.mark.parametrize(
    "effects",
    [Effects(contact_friction=0.3), Effects(self_weight=0.5), Effects(yield_moment=1.0)],
    ids=["friction", "weight", "yield"],
)
def test_forces_without_an_equilibrium_return_no_moment_and_no_shape(effects):
    """Past the branch end (or past yield) there is no stem to read: its base moment and shape are NaN, not the
    search's last try (a march balancing nothing, which with friction or weight changed from one search path to
    another: mutants of the moment search changed only those)."""
    F = np.geomspace(0.5, 60.0, 12)
    sol = contact_from_force(F, 0.45, 2.6, 0.43, 0.8, effects, keep_shape=True)
    assert sol.found.any() and not sol.found.all()
    assert np.all(np.isfinite(sol.base_moment_Nm[sol.found])) and np.all(np.isnan(sol.base_moment_Nm[~sol.found]))
    assert np.all(np.isfinite(sol.shape_xz_m[..., sol.found]))
    assert np.all(np.isnan(sol.shape_xz_m[..., ~sol.found]))


def test_a_nearly_uniform_stem_is_solved_alike_by_the_reference():
    """p = 0.005 (the default prior reaches p = 0): EI = (1 - s)^0.02, 1% below EI0 at s = 0.4; the reference's
    taper must not fall back to a uniform stem."""
    f, eta, p = 1.5, 0.5625, 0.005
    ref, fast = R.solve_force(f, eta, p), contact_from_force_nd(f, eta, p)
    assert ref["xi_c"] == pytest.approx(float(fast["xi_c"]), rel=1e-8)
    uniform = R.solve_force(f, eta, 0.0)
    assert abs(uniform["xi_c"] - ref["xi_c"]) > 1e-4 * ref["xi_c"]

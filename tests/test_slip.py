"""Where a push slipped: the window the data give and the likelihood's term for it (docs/inference.md, "The slip")."""

import numpy as np
import pytest
from scipy.special import log_ndtr

import bayesrod
from bayesrod.dataset.simulate import _loading_branch
from bayesrod.inference.likelihood import ForceCurves, build_likelihood, prepare_data
from bayesrod.inference.priors import load_prior


@pytest.fixture(scope="module")
def one_height():
    return bayesrod.simulate("twig", seed=4, heights_m=[0.5], config_overrides={"n_frames_engaged": 2})


def test_the_slip_window_brackets_the_simulated_slip_within_one_robot_step(one_height):
    cfg, (sim,) = one_height.simulation
    D_slip = _loading_branch(cfg, 0.5)[0][-1]  # the simulator's branch end
    (d,) = prepare_data(one_height, use_shapes=False)
    step = np.diff(sim.robot_x_m[:3])[0]
    assert d.engaged_to_m < D_slip <= d.slipped_by_m
    assert d.slipped_by_m - d.engaged_to_m == pytest.approx(step, rel=0.02)
    assert d.engaged_to_m == pytest.approx(np.max(sim.contact_x_m[sim.engaged]), rel=1e-12)


def test_a_push_stopped_short_says_only_how_far_the_stem_held():
    """A simulated push capped before its slip ends where the robot turns back: no slip seen."""
    ds = bayesrod.simulate(
        "twig", seed=4, heights_m=[0.5], config_overrides={"n_frames_engaged": 2, "max_contact_displacement_m": 0.1}
    )
    (d,) = prepare_data(ds, use_shapes=False)
    assert np.isnan(d.slipped_by_m) and d.engaged_to_m == pytest.approx(0.1, rel=0.02)
    lik = build_likelihood(ds, load_prior("default"), use_shapes=False, slip=True)
    assert np.isinf(lik.slip_hi_m).all()


def test_slip_term_is_the_probability_that_the_window_meets_the_model_slip_range(one_height):
    """log Phi((D_end - lo)/tau) + log Phi((hi - D_early)/tau): the model's slip lies between where the force
    first comes within SLIP_FORCE_REL of the branch end's (D_early) and the end (D_end), both solved directly
    at each p. Flat where the two ranges meet, falling by nats where the model slips before the window."""
    pr = load_prior("default")
    lik = build_likelihood(one_height, pr, use_shapes=False, slip=True)
    p = np.array([0.33, 0.4, 0.43, 0.47, 0.55])
    (c,) = ForceCurves.batch(np.array([0.5 / lik.L]), p)
    D_end, D_early = c.d_end * lik.L, c.d_early * lik.L
    lo, hi, tau = lik.slip_lo_m[0], lik.slip_hi_m[0], lik.slip_scale_m[0]
    want = log_ndtr((D_end - lo) / tau) + log_ndtr((hi - D_early) / tau)
    # the tables' slip displacements within 0.1 tau of the direct solves (measured: at most 0.3 mm, tau 4.8 mm)
    np.testing.assert_allclose(lik.L * lik._interp(lik.slip_table, p, None)[:, 0], D_end, atol=0.1 * tau)
    np.testing.assert_allclose(lik.slip_displacement_m({"p": p}, early=True)[:, 0], D_early, atol=0.1 * tau)
    np.testing.assert_allclose(lik.slip_loglik(p, None), want, atol=0.05)
    assert tau == pytest.approx(0.5 * (hi - lo), rel=0.02)  # half the last robot step
    assert np.all(D_early < D_end - 2 * tau)  # the range is wider than the window's softening here
    # the simulated p (0.43) and its neighbours meet the window; at 0.55 the model slips before it
    assert np.all(want[:3] > -0.3) and want[-1] < -2


@pytest.mark.parametrize(
    "stem",
    [
        {"EI0": 2.6, "p": 0.43, "length_m": 1.0, "heights_m": (0.5,), "specimen": "twig-like", "span_m": 0.1074},
        # SBC seed 240's stem: its branch ends on a plateau (D 0.51 m at 99.9% of the end force, 0.77 m at
        # the end), so the end's displacement is ill-conditioned and a solver stops anywhere along it
        {
            "EI0": 1.0706,
            "p": 0.5273,
            "length_m": 0.94379,
            "heights_m": (0.33622,),
            "specimen": "plateau",
            "span_m": 0.2563,
        },
    ],
    ids=["fold", "plateau"],
)
def test_the_model_slip_range_holds_the_simulators_slip_and_starts_where_the_force_is_within_its_tolerance(stem):
    """The simulator ends a push where force_from_displacement stops solving; the likelihood's range
    [d_early, d_end] (ForceCurves, the other solve direction) must hold it, and force_from_displacement at
    d_early must read (1 - SLIP_FORCE_REL) of the force at d_end."""
    from bayesrod.inference.likelihood import SLIP_FORCE_REL
    from bayesrod.physics.elastica import force_from_displacement

    sim_stem = {k: v for k, v in stem.items() if k != "span_m"}
    ds = bayesrod.simulate(sim_stem, seed=1, config_overrides={"robot_step_m": 0.01 * stem["length_m"]})
    cfg, _ = ds.simulation
    L, (h,) = stem["length_m"], stem["heights_m"]
    D_sim = _loading_branch(cfg, h)[0][-1]
    (c,) = ForceCurves.batch(np.array([h / L]), np.array([stem["p"]]))
    D_early, D_end = c.d_early[0] * L, c.d_end[0] * L
    # the end itself is ill-conditioned on the plateau (dF/dD ~ 0): the two solvers' ends differ by up to a
    # few mm either way (measured 0.45 mm past d_end on the fold case; docs/validation.md), the start is not
    assert D_early <= D_sim <= D_end + 1e-3 * L
    # both stems end on a plateau: 99.9% of the end force 0.107 m and 0.256 m before its end (measured)
    assert D_end - D_early == pytest.approx(stem["span_m"], rel=0.02)
    F = force_from_displacement(np.array([D_early, D_sim]), h, stem["EI0"], stem["p"], L).true_force_N
    F_end = c._interp[0](c.d_end[0]) * stem["EI0"] / L**2
    assert F[0] == pytest.approx((1 - SLIP_FORCE_REL) * F_end, rel=1e-6)
    assert F[1] == pytest.approx(F_end, rel=SLIP_FORCE_REL)


def test_the_slip_term_adds_to_the_likelihood_and_stays_out_of_held_out_refits(one_height):
    pr = load_prior("default")
    on = build_likelihood(one_height, pr, use_shapes=False, slip=True)
    off = build_likelihood(one_height, pr, use_shapes=False)
    params = {"EI0": np.array([2.6, 2.7]), "p": np.array([0.4, 0.5]), "sigma_force_N": np.array([0.05, 0.05])}
    np.testing.assert_allclose(
        on.log_likelihood(params) - off.log_likelihood(params), on.slip_loglik(params["p"], None), rtol=1e-12
    )
    keep = np.arange(on.n_force) < 2 * on.n_force // 3  # the last third held out, the slip with it
    np.testing.assert_allclose(
        on.restricted(keep).log_likelihood(params), off.restricted(keep).log_likelihood(params), rtol=1e-12
    )
    assert not build_likelihood(one_height, pr, ("yield",), use_shapes=False, slip=True).slip


def test_the_summary_reports_the_data_slip_window_beside_the_model_slip(one_height):
    from bayesrod.api.fitting import _slip_report

    lik = build_likelihood(one_height, load_prior("default"), use_shapes=False, slip=True)
    p = np.random.default_rng(0).normal(0.43, 0.02, 500)
    (row,) = _slip_report(lik, {"EI0": np.full(500, 2.6), "p": p})
    assert row["push"] == lik.data[0].id and row["slipped_by_m"] == lik.slip_hi_m[0]
    assert row["engaged_to_m"] == lik.slip_lo_m[0]
    D = lik.slip_displacement_m({"p": p})[:, 0]
    assert row["model_slip_m"]["median"] == pytest.approx(np.median(D), rel=1e-3)
    assert row["engaged_to_m"] < row["model_slip_m"]["median"] < row["slipped_by_m"]
    early = lik.slip_displacement_m({"p": p}, early=True)[:, 0]
    assert row["model_slip_from_m"]["median"] == pytest.approx(np.median(early), rel=1e-3)
    assert row["model_slip_from_m"]["q95"] < row["engaged_to_m"]  # the range starts well before the window


def test_a_rig_with_a_fixed_robot_step_samples_until_the_slip_and_the_window_holds_it():
    """robot_step_m: the samples sit at multiples of the step whatever the stem; as many engage as reach the slip."""
    ds = bayesrod.simulate(
        "twig", seed=4, heights_m=[0.5], config_overrides={"n_frames_engaged": 2, "robot_step_m": 0.012}
    )
    cfg, (sim,) = ds.simulation
    np.testing.assert_allclose(np.diff(sim.robot_x_m), 0.012, rtol=1e-4)  # D + wire: off by its table
    D_slip = _loading_branch(cfg, 0.5)[0][-1]
    (d,) = prepare_data(ds, use_shapes=False)
    assert sim.engaged.sum() == np.sum(sim.robot_x_m <= sim.robot_x_m[sim.engaged][-1])
    assert d.engaged_to_m < D_slip <= d.slipped_by_m and d.slipped_by_m - d.engaged_to_m == pytest.approx(0.012)
    with pytest.raises(ValueError, match="robot_step_m"):
        bayesrod.simulate("twig", seed=4, heights_m=[0.5], config_overrides={"robot_step_m": 0.5})


def test_a_fixed_step_rig_films_at_a_fixed_rate_whatever_the_stem():
    """With robot_step_m the camera takes a frame every FRAME_EVERY robot steps up to the slip: the frames'
    displacements no longer come from spreading a fixed number over the push, a spacing that told where the
    stem would slip (the SBC's skew with centerlines)."""
    from bayesrod.dataset.simulate import FRAME_EVERY, ROBOT_SPEED

    step = 0.012
    sims = []
    for stiff in (2.0, 0.5):  # the softer stem slips at another robot advance (p sets it, and so do heights)
        stem = {"EI0": 2.63 * stiff, "p": 0.43 if stiff > 1 else 0.9, "length_m": 0.8, "heights_m": [0.5]}
        ds = bayesrod.simulate(stem, seed=4, config_overrides={"robot_step_m": step})
        sims.append(ds.simulation[1][0])
    counts = []
    for sim in sims:
        t_slip = sim.time_s[sim.engaged][-1]
        before = sim.frame_time_s[sim.frame_time_s <= t_slip]
        # the camera clock: frame k at robot advance (k + 0.3) x the frame step, up to the wire's shift of D
        travel = (np.arange(before.size) + 0.3) * FRAME_EVERY * step
        np.testing.assert_allclose(before * ROBOT_SPEED, travel, atol=0.2 * step)
        counts.append(before.size)
    assert counts[0] != counts[1]  # as many frames as the push lasts


def test_fit_with_slip_writes_the_window_and_the_model_slip_and_only_then(one_height, tmp_path):
    """Through the public fit: summary.json ``data.slip`` holds the data's window and the posterior's slip,
    config.json records ``slip``; a fit without the term writes neither."""
    import json

    kw = {"use_shapes": False, "progress": False, "seed": 3, "max_steps": 400, "target_ess": 50}
    post = bayesrod.fit(one_height, slip=True, **kw)
    out = post.save(tmp_path / "run", figures=False)
    summary = json.loads((out / "summary.json").read_text())
    assert json.loads((out / "config.json").read_text())["slip"] is True
    (row,) = summary["data"]["slip"]
    (d,) = prepare_data(one_height, use_shapes=False)
    assert row["push"] == d.id and row["engaged_to_m"] == d.engaged_to_m and row["slipped_by_m"] == d.slipped_by_m
    m = row["model_slip_m"]
    assert m["q05"] < m["median"] < m["q95"] and d.engaged_to_m - 0.01 < m["median"] < d.slipped_by_m + 0.01
    plain_post = bayesrod.fit(one_height, **kw)
    plain = plain_post.to_dict()
    assert "slip" not in plain["data"]
    # no calibration caution either way: one height, forces only, ending at the slip, the plain fit's 90%
    # intervals covered EI0 and p in 89 and 87 of 98 fresh simulated replicates (docs/validation.md, session 61)
    assert "calibration" not in plain and "calibration" not in summary
    assert "Intervals likely too narrow" not in plain_post.report_html(pngs={})


def test_the_slip_term_reads_the_tabled_effect_and_moves_its_window_with_the_preload(one_height):
    """With a base spring the model's slip is the branch end of the rod on that spring (solved directly at the
    walker's p and spring); a preload moves each push's window (lo, hi] by the preload: the recorded
    displacement starts that far into the push."""
    pr = load_prior("default")
    lik = build_likelihood(one_height, pr, ("base_compliance",), use_shapes=False, slip=True, n_effect=9)
    p = np.array([0.4, 0.45])
    params = {"EI0": np.array([2.6, 2.6]), "p": p, "base_compliance": np.array([20.0, 8.0])}
    u = lik.effect_coordinate(params)
    assert np.all((u > 0.05) & (u < 0.95))
    want = [
        ForceCurves.batch(np.array([0.5 / lik.L]), p[w : w + 1], effects_nd=lik.axis.nondim(u[w : w + 1]))[0].d_end[0]
        for w in range(2)
    ]
    tau = lik.slip_scale_m[0]
    np.testing.assert_allclose(lik.slip_displacement_m(params)[:, 0], lik.L * np.array(want), atol=0.1 * tau)
    plain = lik.L * lik._interp(lik.slip_table, p, np.zeros(2))[:, 0]
    assert np.all(np.abs(lik.L * np.array(want) - plain) > 3 * tau)  # the spring moves the slip by more than the window
    lo, hi = lik.slip_lo_m[0], lik.slip_hi_m[0]
    D_s = lik.slip_displacement_m(params)[:, 0]
    D_e = lik.slip_displacement_m(params, early=True)[:, 0]
    want_e = [
        ForceCurves.batch(np.array([0.5 / lik.L]), p[w : w + 1], effects_nd=lik.axis.nondim(u[w : w + 1]))[0].d_early[0]
        for w in range(2)
    ]
    np.testing.assert_allclose(D_e, lik.L * np.array(want_e), atol=0.1 * tau)
    np.testing.assert_allclose(
        lik.slip_loglik(p, u), log_ndtr((D_s - lo) / tau) + log_ndtr((hi - D_e) / tau), rtol=1e-12
    )
    pre = build_likelihood(one_height, pr, use_shapes=False, slip=True, preload=True)
    D_s = pre.slip_displacement_m(params)[:, 0]
    D_e = pre.slip_displacement_m(params, early=True)[:, 0]
    shift = np.array([[0.004], [0.012]])
    want = log_ndtr((D_s - lo - shift[:, 0]) / tau) + log_ndtr((hi + shift[:, 0] - D_e) / tau)
    np.testing.assert_allclose(pre.slip_loglik(p, None, shift), want, rtol=1e-12)
    # and in the likelihood, with each push's preload read from the parameters
    from scipy.stats import norm

    (name,) = pre.preload_names
    both = {**params, "sigma_force_N": np.array([0.05, 0.08]), name: shift[:, 0]}
    r = pre.F_obs - both["EI0"][:, None] / pre.L**2 * pre.predict_nd_force_preloaded(p, shift)
    force = norm.logpdf(r, 0.0, both["sigma_force_N"][:, None]).sum(axis=1)
    np.testing.assert_allclose(pre.log_likelihood(both), force + want, rtol=1e-12)


def _window(robot, force, slip_index, contact=None):
    """_slip_window of a hand-made push: contact displacement = robot position (no wire) unless given,
    engaged up to ``slip_index``."""
    from types import SimpleNamespace

    from bayesrod.dataset.engagement import Engagement
    from bayesrod.inference.likelihood import _slip_window

    robot, n = np.asarray(robot, float), len(robot)
    mask = np.arange(n) < (n if slip_index is None else slip_index)
    contact = robot if contact is None else np.asarray(contact, float)
    push = SimpleNamespace(contact_x_m=contact, robot_x_m=robot, force_N=np.asarray(force, float))
    return _slip_window(push, Engagement(mask, 0.0, 0.01, slip_index))


def test_the_slip_window_by_hand_with_a_stalled_robot_and_a_two_sample_push():
    # the robot advanced 0.01 m a sample and the force fell at sample 4: held to 0.03, slipped by 0.04
    w = _window([0.0, 0.01, 0.02, 0.03, 0.04], [0.0, 1.0, 2.0, 3.0, 0.0], 4)
    assert w == pytest.approx({"engaged_to_m": 0.03, "slip_step_m": 0.01, "slipped_by_m": 0.04})
    # the robot stood still for the last engaged sample (the contact crept on): no step to read (NaN), and no
    # slip where the robot had not moved on when the force fell
    w = _window([0.0, 0.01, 0.02, 0.02, 0.02], [0.0, 1.0, 2.0, 3.0, 0.0], 4, contact=[0.0, 0.01, 0.02, 0.025, 0.0])
    assert np.isnan(w["slip_step_m"]) and w["engaged_to_m"] == 0.025 and "slipped_by_m" not in w
    # two engaged samples: the step is the first one's (k = 1 reads R[1] - R[0])
    w = _window([0.0, 0.01, 0.02], [0.0, 1.0, 0.0], 2)
    assert w == pytest.approx({"engaged_to_m": 0.01, "slip_step_m": 0.01, "slipped_by_m": 0.02})


def test_without_a_robot_step_the_slip_softening_is_half_a_percent_of_the_displacement():
    from types import SimpleNamespace

    from bayesrod.inference.likelihood import RodLikelihood

    lik = object.__new__(RodLikelihood)
    lik.data = [SimpleNamespace(D_m=np.ones(3), engaged_to_m=0.5, slipped_by_m=np.nan, slip_step_m=np.nan)]
    lik.geometry, lik.effects = False, ()
    lik._init_slip(True)
    assert lik.slip_scale_m == pytest.approx([0.0025]) and np.isinf(lik.slip_hi_m).all()

"""`bayesrod simulate`: agrees with the forward model and an independent integration."""

import json
import subprocess
import sys

import numpy as np
import pytest

from bayesrod.cli import main
from bayesrod.dataset import detect_engagement, read_dataset, validate_dataset
from bayesrod.physics import EFFECT_NAMES, Effects, force_from_displacement
from bayesrod.physics import reference as R

from .conftest import make_dataset


def test_noise_free_forces_match_predict_and_reference(twig_clean):
    spec = read_dataset(twig_clean)
    for push in spec.pushes:
        eng = detect_engagement(push.force.force_N)
        D = push.force.contact_x_m[eng.mask]
        F = push.force.force_N[eng.mask]
        pred = force_from_displacement(D, push.height_m, 2.63, 0.43, 0.8)
        np.testing.assert_allclose(F, pred.force_N, rtol=1e-4, atol=1e-9)
        for i in np.linspace(1, D.size - 2, 4).astype(int):  # independent solve_ivp integration
            ref = R.solve_displacement(D[i] / 0.8, push.height_m / 0.8, 0.43)["f"] * 2.63 / 0.8**2
            assert F[i] == pytest.approx(ref, rel=1e-4)


def test_samples_at_a_uniform_robot_advance_and_frames_on_their_clock(twig_clean):
    """The placement table (a cubic through exact branch samples) only places samples: the robot
    advances uniformly to 1% of a step, and each frame's time is its exact robot position."""
    import csv

    from bayesrod.dataset.simulate import ROBOT_SPEED, wire_deflection

    spec = read_dataset(twig_clean)
    for push in spec.pushes:
        eng = detect_engagement(push.force.force_N)
        steps = np.diff(push.force.robot_x_m[eng.mask])
        assert np.ptp(steps) < 0.01 * steps.mean()
        np.testing.assert_allclose(push.force.time_s * ROBOT_SPEED, push.force.robot_x_m, rtol=1e-9, atol=1e-12)
        rows = list(csv.DictReader(open(twig_clean / push.id / "truth_shapes.csv")))
        t_D = sorted({(float(r["time_s"]), float(r["contact_x_m"])) for r in rows if float(r["contact_x_m"]) > 0})
        t, D = np.array(t_D).T
        F = force_from_displacement(D, push.height_m, 2.63, 0.43, 0.8).force_N
        np.testing.assert_allclose(t * ROBOT_SPEED, D + wire_deflection(F), rtol=0, atol=1e-7)


def test_noise_free_centerlines_within_0p1_mm(twig_clean):
    import csv

    spec = read_dataset(twig_clean)
    push = spec.push("h550")
    rows = list(csv.DictReader(open(twig_clean / "h550" / "truth_shapes.csv")))
    D_of = {float(r["time_s"]): float(r["contact_x_m"]) for r in rows}
    s = np.linspace(0, 0.8, 80)
    for frame in push.shapes[:20:6]:
        D = D_of[frame.time_s]  # the simulator's exact contact displacement for this frame
        F = float(force_from_displacement(D, push.height_m, 2.63, 0.43, 0.8).force_N)
        ref = R.shape_at_force(F * 0.8**2 / 2.63, push.height_m / 0.8, 0.43, s / 0.8) * 0.8
        assert np.max(np.hypot(frame.x_m - ref[0], frame.z_m - ref[1])) < 1e-4


def test_truth_shapes_match_independent_integration_to_0p1_mm(twig_clean):
    import csv

    spec = read_dataset(twig_clean)
    push = spec.push("h450")
    rows = list(csv.DictReader(open(twig_clean / "h450" / "truth_shapes.csv")))
    t0 = float(rows[0]["time_s"])
    frame = [r for r in rows if float(r["time_s"]) == t0]
    x = np.array([float(r["x_m"]) for r in frame])
    z = np.array([float(r["z_m"]) for r in frame])
    s = np.array([float(r["s_m"]) for r in frame])
    # contact displacement of that frame from the shape itself (x where z crosses h)
    D = np.interp(push.height_m, z[z < push.height_m + 0.05], x[z < push.height_m + 0.05])
    F = float(force_from_displacement(D, push.height_m, 2.63, 0.43, 0.8).force_N)
    ref = R.shape_at_force(F * 0.8**2 / 2.63, push.height_m / 0.8, 0.43, s / 0.8) * 0.8
    assert np.max(np.hypot(x - ref[0], z - ref[1])) < 1e-4


def test_default_noise_is_realistic_and_engagement_found(twig_noisy):
    spec = read_dataset(twig_noisy)
    truth = json.loads((twig_noisy / "specimen.json").read_text())["truth"]
    for push in spec.pushes:
        eng = detect_engagement(push.force.force_N)
        assert eng.slip_index == 60  # n_force_engaged of the simulator
        assert eng.noise_N == pytest.approx(truth["noise"]["force_sd_N"], rel=0.35)
        seen = np.concatenate([f.z_m for f in push.shapes[:20]])
        assert not np.any(np.abs(seen - push.height_m) < 0.015)  # occluded around the sensor


def test_the_simulated_sensor_holds_the_simulated_forces(twig_noisy):
    """The declared range is the smallest capacity holding the pushes' forces with a tenth to spare (the twig
    at 0.45 m peaks near 15 N: 20 N), so validate does not read the simulator's own data as saturated; the
    bundled dataset declares the same; a range set in the configuration is kept."""
    from bayesrod import DEMO_DATASET
    from bayesrod.dataset.simulate import SimConfig, sensor_range

    for path in (twig_noisy, DEMO_DATASET):
        spec = read_dataset(path)
        peak = max(float(np.max(p.force.force_N)) for p in spec.pushes)
        assert spec.sensor.force_range_N == (0.05, 20.0)
        assert 10.0 < 1.1 * peak <= 20.0
        assert not [q for q in validate_dataset(path) if "sensor range" in str(q)]
    cfg = SimConfig.from_preset("twig")
    assert sensor_range(cfg, []) == (0.05, 8.0)
    assert sensor_range(SimConfig.from_preset("twig", force_range_N=(0.1, 5.0)), []) == (0.1, 5.0)
    from types import SimpleNamespace

    for peak, top in ((7.2, 8.0), (7.5, 10.0), (1500.0, 10000.0)):  # a tenth to spare; past the list, a power of 10
        assert sensor_range(cfg, [SimpleNamespace(force_N=np.array([0.0, peak]))]) == (0.05, top)


def test_engagement_with_unzeroed_sensor(tmp_path):
    ds = make_dataset(tmp_path / "off", "grass", seed=3, effects=Effects(force_offset=0.8))
    for push in read_dataset(ds).pushes:
        eng = detect_engagement(push.force.force_N)
        assert eng.slip_index == 60
        assert eng.baseline_N == pytest.approx(0.8, abs=0.05)


_SLOW_EFFECTS = {"self_weight", "contact_friction"}  # ~60 s and ~15 s per push (nested base-moment solves)


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n in _SLOW_EFFECTS else n for n in EFFECT_NAMES]
)
def test_every_effect_simulates_and_validates(tmp_path, name):
    value = {
        "base_compliance": 3.0,
        "rest_curvature": 0.3,
        "base_tilt": 0.05,
        "contact_friction": 0.3,
        "force_offset": 0.3,
        "self_weight": 1.0,
        "yield": 1.2,
    }[name]
    rc = main(
        [
            "simulate",
            "--preset",
            "twig",
            "--out",
            str(tmp_path / name),
            "--effect",
            f"{name}={value}",
            "--heights",
            "0.55",
        ]
    )
    assert rc == 0
    assert [p for p in validate_dataset(tmp_path / name) if p.severity == "error"] == []
    doc = json.loads((tmp_path / name / "specimen.json").read_text())
    assert doc["truth"]["effects"] == {name: value}
    plain = make_dataset(tmp_path / "plain", "twig", seed=0, heights_m=(0.55,))
    f_eff = read_dataset(tmp_path / name).pushes[0].force.force_N[:60]
    f_plain = read_dataset(plain).pushes[0].force.force_N[:60]
    assert np.max(np.abs(f_eff - f_plain)) > 0.05  # the effect is visible in the data


def test_seed_determinism_and_out_refused(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    one = ["--heights", "0.09"]  # one push is enough to show determinism
    assert main(["simulate", "--preset", "grass", "--out", str(a), "--seed", "5", *one]) == 0
    assert main(["simulate", "--preset", "grass", "--out", str(b), "--seed", "5", *one]) == 0
    assert (a / "h90" / "force.csv").read_text() == (b / "h90" / "force.csv").read_text()
    res = subprocess.run(
        [sys.executable, "-m", "bayesrod.cli", "simulate", "--preset", "grass", "--out", str(a)],
        capture_output=True,
        text=True,
    )
    assert res.returncode != 0 and "not empty" in res.stderr and "Traceback" not in res.stderr


def test_frames_render_and_validate(tmp_path):
    ds = make_dataset(tmp_path / "f", "grass", seed=4, frames=True, n_frames_engaged=3, n_frames_after=1)
    assert [p for p in validate_dataset(ds) if p.severity == "error"] == []
    spec = read_dataset(ds)
    import cv2

    rec = spec.pushes[0].frames[0]
    rgb = cv2.imread(str(rec.rgb), cv2.IMREAD_UNCHANGED)
    depth = cv2.imread(str(rec.depth), cv2.IMREAD_UNCHANGED)
    assert rgb.dtype == np.uint8 and rgb.shape == (480, 640, 3)
    assert depth.dtype == np.uint16 and (depth == 0).mean() > 0.02  # missing depth exists


def test_a_fixed_step_push_whose_branch_folds_near_its_end_stays_a_forward_record(tmp_path):
    """A stiff base spring at high p (scripts/sbc_geometry.py, seed 1): the placement table smooths over a
    fold at the branch's end, so the last nominal sample had to step back 17 mm behind the one before it
    and the robot went backwards in time (the dataset check refused it). Such samples are past the slip."""
    from bayesrod import simulate
    from bayesrod.dataset.simulate import NoiseModel

    L = 1.4434205437073184  # the case exactly as scripts/sbc_geometry.py draws it (rounded, it does not fold)
    stem = {"EI0": 1.204674544531278, "p": 1.0342550349236301, "length_m": L, "heights_m": (0.5069502412767372,)}
    noise = NoiseModel(force_sd_N=0.01855241488948748, shape_sd_m=0.0015, shape_sd_reported_m=0.0015)
    ds = simulate(
        stem | {"specimen": "fold"},
        seed=1,
        noise_model=noise,
        effects={"base_compliance": 1.3955766867559811},
        config_overrides={"n_frames_engaged": 2, "robot_step_m": 0.01 * L},
    )
    _, (sim,) = ds.simulation
    assert np.all(np.diff(sim.time_s) > 0) and np.all(np.diff(sim.robot_x_m) > 0)
    assert np.all(np.diff(sim.contact_x_m[sim.engaged]) > 0)
    n = int(sim.engaged.sum())
    assert n >= 4 and np.array_equal(sim.engaged, np.arange(sim.engaged.size) < n)  # engaged up to the slip only
    ds.save(tmp_path / "fold")
    assert [p for p in validate_dataset(tmp_path / "fold") if p.severity == "error"] == []


def test_every_engaged_frame_shows_the_stem_at_its_contact_even_where_the_branch_end_is_flat():
    """Rest curvature -0.53 at one height (scripts/sbc_geometry.py, seed 57): the stem bends over until it
    is nearly horizontal at the sensor, the force is flat to 1e-8 over the last centimetre and the
    contact's solve ill-conditioned there. A frame 1.4 mm before the slip failed its solve and was
    recorded, engaged, with the unloaded stem's shape 0.67 m away; the table likelihood then moved the
    MLE by -660 sd. Each engaged frame's centerline must pass through its contact point."""
    from bayesrod import simulate
    from bayesrod.dataset.simulate import NoiseModel

    L = 1.420548171281834
    stem = {"EI0": 4.755345846741793, "p": 0.5919057926626894, "length_m": L, "heights_m": (0.9226659119616725,)}
    ds = simulate(
        stem | {"specimen": "flat-end"},
        seed=57,
        noise_model=NoiseModel(force_sd_N=0.0, shape_sd_m=0.0, shape_sd_reported_m=0.0015),
        effects={"rest_curvature": -0.5256909007510875},
        config_overrides={"robot_step_m": 0.01 * L},
    )
    _, (sim,) = ds.simulation
    h = sim.height_m
    rest = sim.shapes_true[-1]  # after the slip: the unloaded stem
    assert np.isnan(sim.frame_contact_x_m[-1])
    x_rest = float(np.interp(h, rest[1], rest[0]))  # its rest shape rises monotonically through h
    t_last = sim.time_s[sim.engaged][-1]
    on = np.isfinite(sim.frame_contact_x_m)
    assert on.sum() >= 20 and np.all(sim.frame_time_s[on] <= t_last) and np.all(np.diff(sim.frame_time_s) > 0)
    s_fine = np.linspace(0.0, L, 20001)
    for k in np.flatnonzero(on):
        x = np.interp(s_fine, sim.s_m, sim.shapes_true[k, 0])
        z = np.interp(s_fine, sim.s_m, sim.shapes_true[k, 1])
        # nearest point, not the crossing of z = h: near horizontal at the sensor, the crossing is ill-posed
        gap = np.min(np.hypot(x - (x_rest + sim.frame_contact_x_m[k]), z - h))
        assert gap < 2e-3, (k, gap)


def test_step_back_moves_each_failed_displacement_back_by_1e6_L_then_4x_more_per_try_and_gives_up_after_12():
    """The schedule the simulator's docstring states (dataset/simulate.py, ``_step_back``): a displacement
    whose solve fails moves back by 1e-6 L, then 4x more per try, never below 0, others stay; after 12
    tries the last solve is returned as failed."""
    from bayesrod.dataset.simulate import _step_back

    L = 0.8
    D0 = np.array([0.10, 0.30, 0.5, 20.0])
    step = 1e-6 * L * np.cumsum(4.0 ** np.arange(13))  # total move after 1, 2, ... tries
    limit = np.array([0.2, 0.30 - step[1] - 1e-9, -1.0, 10.0])  # 3 tries; never; the 13th try would hold
    assert 20.0 - step[11] > 10.0 > 20.0 - step[12]
    calls = []

    def solve(D):
        calls.append(D.copy())
        return D

    D, sol = _step_back(D0.copy(), L, solve, lambda d: d > limit)
    np.testing.assert_allclose(D, [0.10, 0.30 - step[2], 0.0, 20.0 - step[11]], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(sol > limit, [False, False, True, True])
    assert len(calls) == 13  # the first solve and 12 tries
    assert all(c[0] == 0.10 for c in calls)


def test_a_simulated_dataset_records_one_truth_on_disk_and_in_memory(twig_noisy):
    """specimen.json's ``truth`` (``bayesrod simulate``) and the in-memory dataset's (``bayesrod.simulate``) are the
    same record: the preset's EI0 and p, its effects, its noise (the AR(1) correlation only where there is one)
    and the seed; the file adds the generator."""
    import bayesrod
    from bayesrod.dataset.simulate import SimConfig

    written = json.loads((twig_noisy / "specimen.json").read_text())["truth"]
    assert written.pop("generator").startswith("bayesrod simulate ")
    cfg = SimConfig.from_preset("twig", seed=2)
    mem = bayesrod.simulate("twig", seed=2).extra["truth"]
    assert written == json.loads(json.dumps(mem))
    assert mem == {
        "EI0": cfg.EI0,
        "p": cfg.p,
        "effects": {},
        "noise": {"force_sd_N": cfg.noise.force_sd_N, "shape_sd_m": cfg.noise.shape_sd_m},
        "seed": 2,
    }
    rho = bayesrod.simulate("twig", seed=3, heights_m=[0.5], noise_rho=0.5).extra["truth"]
    assert rho["noise"]["force_rho"] == 0.5 and rho["seed"] == 3

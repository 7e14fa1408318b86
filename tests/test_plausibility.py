"""The plausibility checks, function by function (bayesrod/dataset/plausibility.py; docs/data.md, "Plausibility").

The end-to-end refusals (validate, fit, the CLI) are in tests/test_tables.py; here each threshold is held where it
sits, so that a check moved or weakened fails a test (12 of 14 one-line changes of these checks passed the tests
before this file: docs/validation.md, "Session 68").
"""

from types import SimpleNamespace

import numpy as np
import pytest

from bayesrod.dataset.plausibility import (
    MAX_CONTACT_TRAVEL_L,
    MAX_PHYSICAL_FORCE_N,
    check_push,
    first_reversal,
    noise_sd,
    reversal_tolerance,
)


def _rng():
    return np.random.default_rng(0)  # each test its own draws, whatever runs before it


def _ramp(n=200, peak=2.0, sd=0.01, start=0.0):
    """A push: displacement 0-0.1 m, force rising linearly from ``start`` to ``peak`` [N] with white noise."""
    x = np.linspace(0.0, 0.1, n)
    return start + (peak - start) * x / 0.1 + _rng().normal(0.0, sd, n), x


def _problems(F, x, length_m=0.9, sensor=None):
    """check_push's problems as (field, severity, got, row), ``expected`` left out"""
    return [(f, sev, got, row) for f, _, got, row, sev in check_push("p1", F, x, length_m=length_m, sensor=sensor)]


def test_the_noise_sd_is_the_sample_to_sample_sd_of_a_ramp():
    # second differences of white noise of sd s have sd s sqrt(6): the MAD scaled by 0.6745 and sqrt(6) reads s
    for sd in (0.01, 0.2):
        got = noise_sd(np.linspace(0.0, 50.0, 4000) + _rng().normal(0.0, sd, 4000))
        assert got == pytest.approx(sd, rel=0.06), (sd, got)
    assert noise_sd(np.array([0.0, 1.0, 0.0, 1.0])) > 0  # four samples suffice
    assert noise_sd(np.array([0.0, 1.0, 0.0])) == 0.0


def test_a_push_reverses_when_it_steps_back_more_than_its_tolerance():
    x = np.linspace(0.0, 1.0, 101)  # noise-free: the tolerance is half a percent of the span
    assert reversal_tolerance(x) == pytest.approx(0.005, rel=1e-12)
    back = x.copy()
    back[60:] -= 0.011  # a step back of 0.011 - 0.01 = 0.001 below the running maximum: within tolerance
    assert first_reversal(back) is None
    back[60:] -= 0.01  # 0.011 below the maximum: a reversal at the first sample past it
    assert first_reversal(back) == 60
    (fld, severity, _, row), *_ = _problems(np.linspace(0.0, 2.0, 101), back)  # named at its 1-based row
    assert (fld, severity, row) == ("column robot_x_m", "error", 61)
    noisy = x + _rng().normal(0.0, 0.004, x.size)  # 5 noise sds (0.02) exceed half a percent of the span
    assert reversal_tolerance(noisy) == pytest.approx(5 * noise_sd(noisy), rel=1e-12) and 5 * noise_sd(noisy) > 0.01


def test_forces_or_displacements_beyond_any_stem_are_errors_in_either_sign():
    F, x = _ramp()
    for spike in (2 * MAX_PHYSICAL_FORCE_N, -2 * MAX_PHYSICAL_FORCE_N):  # one sample in a wrong unit, either sign
        bad = np.where(np.arange(F.size) == 5, spike, F)
        assert _problems(bad, x) == [("column force_N", "error", f"{spike:g} N", 6)]  # 6: the sample's 1-based row
    far = -x * (MAX_CONTACT_TRAVEL_L * 0.9 / 0.1) * 1.5  # a displacement to -4.5 L
    (fld, severity, got, row), *_ = _problems(F, far)
    assert (fld, severity) == ("column robot_x_m", "error") and row == int(np.argmax(np.abs(far) > 2.7)) + 1


def test_mostly_negative_loaded_forces_are_a_sign_error_a_few_are_not():
    F, x = _ramp()
    flipped = F.copy()
    flipped[: int(0.7 * F.size)] *= -1  # 70% of the loaded samples negative
    assert any(p[0] == "column force_N" and "negative forces" in p[2] for p in _problems(flipped, x))
    some = F.copy()
    some[: int(0.3 * F.size)] *= -1
    assert not any("negative forces" in p[2] for p in _problems(some, x))


def test_a_push_that_never_loads_the_stem_is_an_error_one_that_starts_loaded_a_warning():
    F, x = _ramp(peak=0.001, sd=0.001)  # a rise within the noise
    assert [(p[0], p[1]) for p in _problems(F, x)] == [("column force_N", "error")]
    held = np.full(200, 1.0) + _rng().normal(0.0, 0.001, 200)  # held at 1 N from the first sample: the probe's preload
    assert [(p[1], p[3]) for p in _problems(held, x)] == [("warning", 1)]
    assert "preload" in _problems(held, x)[0][2]
    small, x = _ramp(peak=2.0, sd=0.001, start=0.1)  # a preload of 5% of the peak (the threshold: 2%)
    assert [(p[1], p[3]) for p in _problems(small, x)] == [("warning", 1)]
    assert _problems(*_ramp(peak=2.0, sd=0.001, start=0.02)) == []  # 1% of the peak: a start at rest
    F, x = _ramp(peak=2.0)
    at_floor = SimpleNamespace(force_range_N=(float(F.max()), 50.0))  # a peak at the sensor's floor: nothing felt
    assert [(p[1], "sensor floor" in p[2]) for p in _problems(F, x, sensor=at_floor)] == [("error", True)]


def test_forces_above_the_declared_sensor_range_are_a_warning_naming_the_first_row():
    F, x = _ramp(peak=2.0, sd=0.0)
    sensor = SimpleNamespace(force_range_N=(0.0, 1.5))  # 2 N peak: the last quarter of the push above 1.5 N
    (fld, severity, got, row), *rest = _problems(F, x, sensor=sensor)
    above = F > 1.5
    assert (fld, severity, rest) == ("column force_N", "warning", [])
    assert row == int(np.argmax(above)) + 1 and got.startswith(f"{int(above.sum())} samples above it")
    assert _problems(F, x, sensor=SimpleNamespace(force_range_N=(0.0, 2.5))) == []

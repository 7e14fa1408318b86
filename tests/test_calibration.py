"""Small simulation-based calibration (the full study: scripts/sbc.py, docs/validation.md)."""

from pathlib import Path

import numpy as np
import pytest

from bayesrod.api.calibration import sbc_replicate

PRIOR = str(Path(__file__).resolve().parents[1] / "scripts" / "sbc_prior.json")


@pytest.mark.slow  # 3 minutes: run with `pytest -m slow`; the full study is scripts/sbc.py
def test_small_sbc_forces_only():
    """4 replicates drawn from the prior: 90% intervals of EI0 and p cover the truth.

    8 intervals at nominal 90%: P(at most 5 covered) = 3.8%, so a calibrated posterior fails
    about once in 26 seeds (the test is seeded, so deterministic here); intervals half as wide as
    they should be (nominal ~60%) fail with probability 0.68. The full study: scripts/sbc.py.
    """
    rows = [sbc_replicate(seed, PRIOR, use_shapes=False, target_ess=200) for seed in range(100, 104)]
    covered = sum(r["EI0_covered"] + r["p_covered"] for r in rows)
    assert covered >= 6, rows
    for k in ("EI0", "p"):
        ranks = np.array([r[f"{k}_rank"] for r in rows])
        assert 0 <= ranks.min() and ranks.max() <= 99
        assert not np.all(ranks == 0) and not np.all(ranks == 99)  # truth not always outside the draws
    assert max(r["rhat_max"] for r in rows) < 1.05


def test_the_tables_move_the_plain_rods_estimate_by_under_a_twentieth_of_its_sd():
    """The likelihood tables against exact solves (noise-free twig: the exact MLE is the truth): the
    table MLE of log EI0 and p within 0.05 Laplace sd of the truth (measured 0.010 and 0.011; every
    effect and the shape axes: scripts/table_accuracy.py, docs/validation.md)."""
    from bayesrod.api.calibration import table_shift

    out = table_shift()
    assert out["names"] == ["log EI0", "p"]
    assert np.all(np.abs(out["shift_in_sd"]) <= 0.05), out
    # the sd is the twig's (0.03 N force noise, three heights): a wrong Hessian would not pass
    assert 5e-4 < out["laplace_sd"][0] < 5e-3 and 5e-4 < out["laplace_sd"][1] < 5e-3, out

import functools
import logging
import os
import shutil
from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

from bayesrod.dataset.simulate import SimConfig, simulate, write_simulated

# two xdist workers on two cores: one BLAS thread each (two each oversubscribe the machine), also in
# the subprocesses the tests start
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
threadpool_limits(1)

REPO = Path(__file__).resolve().parents[1]


def pytest_sessionstart(session):
    """Start every test session with an empty force-curve cache. A plain run starts empty anyway; mutmut
    (scripts/mutation.py) forks each mutant's session from a process whose clean run filled the cache, and
    cached curves would hide a mutant of the solves behind them."""
    from bayesrod.inference import likelihood

    likelihood._CURVE_CACHE.clear()


BLUEBERRY = REPO.parent / "shared" / "data" / "blueberry-canes"


@pytest.fixture()
def coarse_length_axis(monkeypatch):
    """The stem-length table axis on 13 nodes instead of the fit's 49, for tests of what the geometry tables are
    wired to (which caution, which geometry a walker's yield reads, the axes off-node on pushes short of their
    branch ends), not of the axis's accuracy at a branch end: that is
    tests/test_nuisances.py::test_the_length_axis_reads_a_push_to_its_branch_end_between_nodes. Every such test
    passes on either; 13 nodes build in about a quarter of the time."""
    monkeypatch.setattr("bayesrod.inference.likelihood.LENGTH_NODES", 13)


def make_dataset(path: Path, preset="twig", **kw) -> Path:
    frames = kw.pop("frames", False)
    arm = kw.pop("arm", "leading")
    cfg = SimConfig.from_preset(preset, **kw)
    path.mkdir(parents=True, exist_ok=True)
    camera = None
    if frames:
        from bayesrod.vision.render import default_camera

        camera = default_camera(cfg.length_m)
    write_simulated(cfg, list(_simulated(cfg)), path, frames=frames, camera=camera, arm=arm)
    return path


@functools.lru_cache(maxsize=16)
def _simulated(cfg: SimConfig) -> tuple:
    """The pushes of ``cfg`` (deterministic in its seed), solved once per test process: several tests
    write the same stem (the plain twig beside every effect of test_simulate)."""
    return tuple(simulate(cfg))


@pytest.fixture(scope="session")
def twig_clean(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("twig_clean") / "ds", "twig", seed=1, noise="none")


@pytest.fixture(scope="session")
def twig_noisy(tmp_path_factory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("twig_noisy") / "ds", "twig", seed=2)


@pytest.fixture()
def twig_copy(twig_noisy, tmp_path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(twig_noisy, dst)
    return dst


@pytest.fixture()
def bayesrod_warnings():
    """The messages the package's logger emits at WARNING and above during a test, read by a handler on that
    logger (a CLI test earlier in the same process stops its propagation to pytest's caplog)."""
    seen = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = lambda record: seen.append(record.getMessage())
    logger = logging.getLogger("bayesrod")
    logger.addHandler(handler)
    yield seen
    logger.removeHandler(handler)


@pytest.fixture()
def no_polish(monkeypatch):
    """The sampler's start without its Nelder-Mead polish (``minimize`` returning no finite value): what
    ``find_start`` returns is then its best candidate, after the preload profile."""
    import bayesrod.inference.sampler as sampler

    class Failed:
        fun, x = float("inf"), None

    monkeypatch.setattr(sampler, "minimize", lambda *a, **k: Failed())

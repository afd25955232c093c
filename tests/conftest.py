import os
from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
# absorber optima shared by this run's processes (workers, CLI and service subprocesses), kept
# out of the user's own cache
os.environ.setdefault("POSEDYN_CACHE_DIR", str(ROOT / "build" / "test-cache"))
# one BLAS thread per test process (make test sets it before Python starts; this covers a bare
# pytest): two xdist workers on two cores would otherwise oversubscribe them, and a threaded BLAS
# sums in a run-dependent order, so a modal fit (seed 003's B1 table) could land on either of two
# nearly tied stability branches from one run to the next
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
threadpool_limits(1)
DATASETS = ROOT / "datasets"


@pytest.fixture(scope="session")
def datasets() -> Path:
    return DATASETS


@pytest.fixture(scope="session")
def model_dir(tmp_path_factory) -> Path:
    """A pose model trained on seed 004's positions (the service tests use it)."""
    from tests.zenoh_helpers import train_model

    return train_model(tmp_path_factory.mktemp("model") / "hou2023")


# The longest files first: `make test` runs files on two workers (--dist loadfile, and
# --no-loadscope-reorder so that xdist >= 3.8 keeps this order rather than its own by test
# count), which take them in collection order; starting with the long ones keeps one worker from
# finishing a long file alone at the end. Seconds on one worker, 2026-12-04, in the comments.
LONGEST_FIRST = (
    "test_stability_multiscale.py",  # 141
    "test_gap.py",  # 105
    "test_hopf_islands.py",  # 87
    "test_gap_sle.py",  # 75
    "test_service_limits.py",  # 73, the memory test on both cores
    "test_sweep.py",  # 72
    "test_gap_statistics.py",  # 70
    "test_absorber_mrf_tuning.py",  # 45 (17 with build/test-cache's absorber optima)
    "test_stability.py",  # 43
    "test_service.py",  # 34
    "test_robust_schedule.py",  # 28
    "test_field_plan.py",  # 27
    "test_stability_ranges.py",  # 24
    "test_winding_count.py",  # 24
    "test_flip_islands.py",  # 19
    "test_gpr.py",  # 18
    "test_absorber_schedule.py",  # 16
    "test_service_security.py",  # 13
)


_PREFETCH = pytest.StashKey()


def pytest_configure(config):
    """Under xdist, the controller starts the Chromium install the report test needs, if any."""
    if not hasattr(config, "workerinput") and config.getoption("numprocesses", None):
        from tests.browser import prefetch_chromium

        config.stash[_PREFETCH] = prefetch_chromium()


def pytest_unconfigure(config):
    proc = config.stash.get(_PREFETCH, None)
    if proc is not None:
        proc.wait(timeout=1500)


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))  # stable: each file's own order kept

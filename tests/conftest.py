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


# The longest files first: `make test` runs files on two workers (--dist loadfile), which take
# them in collection order; starting with the long ones keeps one worker from finishing a long
# file alone at the end (it saved about a minute of a ten-minute run).
LONGEST_FIRST = ("test_sweep.py", "test_gap.py", "test_cli_json.py", "test_absorber_mrf_tuning.py", "test_robust_schedule.py",
                 "test_service_limits.py", "test_service.py", "test_service_security.py", "test_stability_multiscale.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))  # stable: each file's own order kept

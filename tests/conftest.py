import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# absorber optima shared by this run's processes (workers, CLI and service subprocesses), kept
# out of the user's own cache
os.environ.setdefault("POSEDYN_CACHE_DIR", str(ROOT / "build" / "test-cache"))
DATASETS = ROOT / "datasets"


@pytest.fixture(scope="session")
def datasets() -> Path:
    return DATASETS


@pytest.fixture(scope="session")
def model_dir(tmp_path_factory) -> Path:
    """A pose model trained on seed 004's positions (the service tests use it)."""
    from tests.zenoh_helpers import train_model

    return train_model(tmp_path_factory.mktemp("model") / "hou2023")

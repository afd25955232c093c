"""Where the shipped data live: the one place that names files under `datasets/`.

Resolved from the environment variable POSEDYN_DATASETS when set, else from the installed
`posedyn_datasets` package (a wheel carries `datasets/` under that name), else from the
source tree next to this package."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path


def datasets_dir() -> Path:
    """The folder holding the shipped data (see the module docstring for the search order)."""
    if os.environ.get("POSEDYN_DATASETS"):
        return Path(os.environ["POSEDYN_DATASETS"])
    spec = importlib.util.find_spec("posedyn_datasets")
    if spec is not None and spec.submodule_search_locations:
        return Path(list(spec.submodule_search_locations)[0])
    return Path(__file__).resolve().parents[2] / "datasets"


DATASETS = datasets_dir()
SHIPPED_TWIN = DATASETS / "robots/kr_r2700_twin.toml"
SEED004_CUT = DATASETS / "seeds/hou2023_cut.toml"
SEED004_ABSORBER = DATASETS / "seeds/hou2023_mrf_absorber.toml"
SEED000_ACTUATOR = DATASETS / "seeds/sahu2024_active_damping.toml"

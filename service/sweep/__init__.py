"""Workspace sweeps: what a sweep is (`spec`), one chunk of poses through the per-pose chain
(`chunk`), chunks on Dask, written as they finish and resumable (`runner`), and the
self-contained HTML report (`report`)."""

from service.sweep.chunk import compute_chunk, representative_lobes
from service.sweep.report import write_report
from service.sweep.runner import SweepOutcome, run_sweep
from service.sweep.spec import RESULT_COLUMNS, SweepSpec, read_sweep_poses

__all__ = ["RESULT_COLUMNS", "SweepOutcome", "SweepSpec", "compute_chunk", "read_sweep_poses", "representative_lobes", "run_sweep", "write_report"]

"""posedyn: pose-dependent tool-tip dynamics of milling robots, chatter prediction and the
per-pose schedules (absorber field, controller gains) that suppress it."""

from posedyn.errors import InputError
from posedyn.table import Mode, ModalTable, PoseSet

__version__ = "0.1.0"
__all__ = ["InputError", "Mode", "ModalTable", "PoseSet", "__version__"]

"""posedyn: the core. Pose-dependent tool-tip dynamics of milling robots and chatter.

Data types (`table`: modes, poses, modal tables; `dynamics`: the tool-tip modal model;
`errors`), file formats (`io`), the robot and its twin (`robot`), pose models (`posemodel`),
stability (`stability`), surface location error (`sle`), modal identification from FRFs
(`identify`) and the gap workflow's statistics (`gap`). Imports no other project package."""

from posedyn.errors import InputError
from posedyn.table import Mode, ModalTable, PoseSet

__version__ = "0.1.0"
__all__ = ["InputError", "Mode", "ModalTable", "PoseSet", "__version__"]

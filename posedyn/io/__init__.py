"""File formats at the edge of the library: modal-test tables (`modal_csv`), FRFs (`frf`),
parameter files (`params`), cuts (`cut`), pose grids (`grid`), twin files (`twin_file`),
measurement campaigns (`measurements`), model directories (`model_dir`), atomic writes
(`atomic`) and where the shipped data live (`shipped`)."""

from posedyn.io.modal_csv import concat_tables, format_modal_table, parse_modal_table, read_modal_table, read_pose_table, write_modal_table
from posedyn.io.params import flatten, read_params

__all__ = ["concat_tables", "read_pose_table", "format_modal_table", "parse_modal_table", "read_modal_table", "write_modal_table", "read_params", "flatten"]

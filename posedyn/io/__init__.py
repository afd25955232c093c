"""File formats at the edge of the library: modal-test tables (CSV) and parameter files (TOML)."""

from posedyn.io.modal_csv import concat_tables, format_modal_table, parse_modal_table, read_modal_table, read_pose_table, write_modal_table
from posedyn.io.params import flatten, read_params

__all__ = ["concat_tables", "read_pose_table", "format_modal_table", "parse_modal_table", "read_modal_table", "write_modal_table", "read_params", "flatten"]

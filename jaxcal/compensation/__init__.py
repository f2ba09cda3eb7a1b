"""Compliance error compensation: corrected joint commands so that the robot under a
process wrench lands on its programmed path, with the accuracy calibration leaves."""

from ._path import (
    COMMAND_COLUMNS as COMMAND_COLUMNS,
    Compensation as Compensation,
    compensate as compensate,
    read_path as read_path,
    write_commands as write_commands,
)
from ._plot import plot_compensation as plot_compensation
from ._solve import (
    RowCompensation as RowCompensation,
    pose_error as pose_error,
)
from ._tree import (
    compensate_row as compensate_row,
    compensate_tree_row as compensate_tree_row,
    landing_error as landing_error,
)

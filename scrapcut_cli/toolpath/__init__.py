"""Cutting set-points: normals, standoff, torch orientation, collision check, speeds, timing.

The recipe is :func:`make_cutting_path`; the path file format lives in :mod:`.pathfile`.
"""

from scrapcut_cli.toolpath.path import CuttingPath
from scrapcut_cli.toolpath.pathfile import (
    SCHEMA,
    path_from_dict,
    path_to_dict,
    read_path_file,
    write_path_csv,
    write_path_file,
    write_path_tum,
)
from scrapcut_cli.toolpath.review import ReviewPath, write_review_mcap
from scrapcut_cli.toolpath.setpoints import make_cutting_path
from scrapcut_cli.toolpath.speeds import SpeedTable, load_speed_table

__all__ = [
    "SCHEMA",
    "CuttingPath",
    "ReviewPath",
    "SpeedTable",
    "load_speed_table",
    "make_cutting_path",
    "path_from_dict",
    "path_to_dict",
    "read_path_file",
    "write_path_csv",
    "write_path_file",
    "write_path_tum",
    "write_review_mcap",
]

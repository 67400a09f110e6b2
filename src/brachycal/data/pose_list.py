"""Pose lists for pivot calibration: ``[name,]m00,m01,…,m33`` — one row-major 4×4 per row.

A header row naming the columns (``m00``…``m33``, optionally a first key column such as
``timestamp_ns``) is expected. Each matrix must be a rigid transform (bottom row 0 0 0 1, rotation
orthonormal to 1e-4): anything else is refused with its row, since a pivot fit on scaled or
sheared matrices would be silently wrong.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from brachycal.data.csv_log import read_table, to_float
from brachycal.errors import InputError
from brachycal.se3 import FloatArray

COLUMNS = [f"m{i}{j}" for i in range(4) for j in range(4)]
ORTHONORMAL_TOL = 1e-4


def read_pose_list(path: str | os.PathLike[str]) -> tuple[list[str], FloatArray, list[int]]:
    """``(names (N,), T (N, 4, 4), rows (N,))``; names are the first column's values, or row numbers."""
    path = Path(path)
    header, rows, records = read_table(path, COLUMNS)
    values = to_float(path, header, rows, records, COLUMNS)
    T = values.reshape(-1, 4, 4)
    extra = [h for h in header if h not in COLUMNS]
    names = [fields[header.index(extra[0])] for fields in records] if extra else [str(r) for r in rows]
    for row, matrix in zip(rows, T, strict=True):
        if not np.all(np.isfinite(matrix)):
            raise InputError("matrix has a non-finite value", file=path, row=row)
        if np.abs(matrix[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-9:
            raise InputError("bottom row must be 0 0 0 1 (a homogeneous transform)", file=path, row=row)
        R = matrix[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > ORTHONORMAL_TOL or np.linalg.det(R) < 0:
            raise InputError("rotation part is not a proper orthonormal matrix", file=path, row=row)
    return names, T, rows

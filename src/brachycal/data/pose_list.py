"""Pose lists for pivot calibration: ``[name,]m00,m01,…,m33`` — one row-major 4×4 per row.

A header row naming the columns (``m00``…``m33``, optionally a first key column such as
``timestamp_ns``) is expected. Each matrix must be a rigid transform
(:func:`brachycal.validate.check_transform` within :data:`ORTHONORMAL_TOL`: finite, bottom row
0 0 0 1, rotation orthonormal with determinant +1): anything else is refused with its row, since
a pivot fit on scaled or sheared matrices would be silently wrong.
"""

from __future__ import annotations

import os
from pathlib import Path

from brachycal.data.formats.csv_log import read_table, to_float
from brachycal.se3 import FloatArray
from brachycal.validate import MAX_POSITION_M, check_positions, check_transform

COLUMNS = [f"m{i}{j}" for i in range(4) for j in range(4)]
#: Largest deviation from a rigid transform accepted in a pose list (``|RᵀR − I|`` entries,
#: ``|det R − 1|`` and the bottom row): trackers write poses with 6 or more significant digits
#: (~1e-6 off); a deviation ε moves a tip r from the marker by at most ~1.5·ε·r, so 1e-4 keeps a
#: 0.3 m tool's tip within ~0.05 mm, while a scaled or sheared matrix is far off.
ORTHONORMAL_TOL = 1e-4


def read_pose_list(path: str | os.PathLike[str]) -> tuple[list[str], FloatArray, list[int]]:
    """``(names (N,), T (N, 4, 4), rows (N,))``; names are the first column's values, or row numbers."""
    path = Path(path)
    header, rows, records = read_table(path, COLUMNS)
    values = to_float(path, header, rows, records, COLUMNS)
    T = values.reshape(-1, 4, 4)
    # m or mm (the caller says which): beyond MAX_POSITION_M in millimetres is no pose in either.
    check_positions(
        T[:, :3, 3],
        "",
        limit=MAX_POSITION_M * 1e3,
        unit="(m or mm)",
        file=path,
        rows=rows,
        columns=["m03", "m13", "m23"],
    )
    extra = [h for h in header if h not in COLUMNS]
    names = [fields[header.index(extra[0])] for fields in records] if extra else [str(r) for r in rows]
    for row, matrix in zip(rows, T, strict=True):
        check_transform(matrix, "matrix", file=path, row=row, tolerance=ORTHONORMAL_TOL)
    return names, T, rows

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

import numpy as np

from brachycal.data.formats.csv_log import table_blocks, to_float
from brachycal.se3 import FloatArray, rigidity_error
from brachycal.validate import MAX_POSITION_M, check_positions, check_transform

COLUMNS = [f"m{i}{j}" for i in range(4) for j in range(4)]
#: Largest deviation from a rigid transform accepted in a pose list (``|RᵀR − I|`` entries,
#: ``|det R − 1|`` and the bottom row): trackers write poses with 6 or more significant digits
#: (~1e-6 off); a deviation ε moves a tip r from the marker by at most ~1.5·ε·r, so 1e-4 keeps a
#: 0.3 m tool's tip within ~0.05 mm, while a scaled or sheared matrix is far off.
ORTHONORMAL_TOL = 1e-4


def read_pose_list(path: str | os.PathLike[str]) -> tuple[list[str], FloatArray, list[int]]:
    """``(names (N,), T (N, 4, 4), rows (N,))``; names are the first column's values, or row numbers.

    Read a block of rows at a time (:func:`~brachycal.data.formats.csv_log.table_blocks`): memory
    is the matrices and names, not every field as a Python string.
    """
    path = Path(path)
    names: list[str] = []
    rows: list[int] = []
    blocks: list[FloatArray] = []
    for header, block_rows, records in table_blocks(path, COLUMNS):
        T = to_float(path, header, block_rows, records, COLUMNS).reshape(-1, 4, 4)
        _check_matrices(path, T, block_rows)
        blocks.append(T)
        extra = [h for h in header if h not in COLUMNS]
        key = header.index(extra[0]) if extra else None
        names += [fields[key] for fields in records] if key is not None else [str(r) for r in block_rows]
        rows += block_rows
    return names, np.concatenate(blocks), rows


def _check_matrices(path: Path, T: FloatArray, rows: list[int]) -> None:
    """Refuse the first of the matrices ``T`` (N, 4, 4) that is no pose: a translation beyond
    any measurable position, or not a rigid transform within :data:`ORTHONORMAL_TOL`, naming its row."""
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
    off, det, last_row = rigidity_error(T)  # all at once; the first matrix refused is named by its row
    bad = np.flatnonzero((off > ORTHONORMAL_TOL) | (np.abs(det - 1.0) > ORTHONORMAL_TOL) | (last_row > ORTHONORMAL_TOL))
    if bad.size:
        k = int(bad[0])
        check_transform(T[k], "matrix", file=path, row=rows[k], tolerance=ORTHONORMAL_TOL)

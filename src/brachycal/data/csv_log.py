"""CSV tables of joints: joint logs ``time,<joint names…>`` (``docs/conventions.md``), tables of
configurations, and time columns; joint columns in any order.

Extra columns are ignored (``torso_joint_b2`` is checked against ``torso_joint_b1``). The file is
read in one pass; numbers are converted in bulk by NumPy, and only when that fails is the bad
field searched for, so that the message can name its row and column.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from brachycal.data.joint_log import JointLog, configurations_from_columns, joint_columns, joint_log_from_columns
from brachycal.errors import InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray


def read_table(path: Path, required: list[str]) -> tuple[list[str], list[int], list[list[str]]]:
    """Header, row numbers and raw fields of a CSV file with one header row.

    Returns ``(header, rows, records)``; ``rows[i]`` is the file row of ``records[i]`` (header =
    row 1); blank lines are skipped. Checks the header (no duplicates, ``required`` present) and
    that every row has as many fields as the header.
    """
    try:
        handle = path.open(newline="")
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    with handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader, [])]
            if not header:
                raise InputError("empty file; expected a header row", file=path)
            for k, name in enumerate(header):
                if name in header[:k]:
                    raise InputError("column appears twice", file=path, row=1, column=name)
            for name in required:
                if name not in header:
                    raise InputError(f"no {name!r} column in the header", file=path, row=1)
            rows, records = [], []
            for fields in reader:
                if not fields or (len(fields) == 1 and not fields[0].strip()):
                    continue
                if len(fields) != len(header):
                    raise InputError(
                        f"has {len(fields)} fields, the header has {len(header)}", file=path, row=reader.line_num
                    )
                rows.append(reader.line_num)
                records.append(fields)
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"not a readable CSV file ({exc})", file=path) from None
    return header, rows, records


def to_float(
    path: Path, header: list[str], rows: list[int], records: list[list[str]], columns: list[str]
) -> np.ndarray:
    """``(N, len(columns))`` floats of the named columns; names the row and column of a bad field."""
    index = [header.index(c) for c in columns]
    text = [[fields[k] for k in index] for fields in records]
    try:
        return np.array(text, dtype=str).astype(float).reshape(len(records), len(columns))
    except ValueError:
        for row, fields in zip(rows, text, strict=True):
            for column, field in zip(columns, fields, strict=True):
                try:
                    float(field)
                except ValueError:
                    raise InputError(f"{field!r} is not a number", file=path, row=row, column=column) from None
        raise


def unique_names(path: Path, header: list[str], rows: list[int], records: list[list[str]], column: str) -> list[str]:
    """The values of ``column`` (``sample``, ``point``), stripped: each non-empty and each once.

    Raises:
        InputError: an empty name, or a name that appears twice (naming both rows).
    """
    k = header.index(column)
    names = [fields[k].strip() for fields in records]
    seen: dict[str, int] = {}
    for row, name in zip(rows, names, strict=True):
        if not name:
            raise InputError(f"empty {column} name", file=path, row=row, column=column)
        if name in seen:
            raise InputError(
                f"{column} {name!r} appears twice (also row {seen[name]})", file=path, row=row, column=column
            )
        seen[name] = row
    return names


def read_csv_log(path: str | os.PathLike[str], robot: Robot) -> JointLog:
    """Read and validate a CSV joint log.

    Args:
        path: CSV file with a header row ``time,<joint names…>``; time in seconds, joints in
            radians.
        robot: the model the joints belong to.

    Returns:
        the validated :class:`JointLog`; its ``rows`` are file rows (header = row 1).

    Raises:
        InputError: one line naming the file, row and column of the first problem.
    """
    path = Path(path)
    header, rows, records = read_table(path, ["time"])
    joints = joint_columns(robot, header)
    data = to_float(path, header, rows, records, ["time", *joints])
    return joint_log_from_columns(robot, joints, data[:, 0], data[:, 1:], source=str(path), rows=rows)


def table_configurations(
    path: Path, robot: Robot, header: list[str], rows: list[int], records: list[list[str]]
) -> FloatArray:
    """``(N, nq)`` configurations from the joint columns of a table read by :func:`read_table`.

    Columns that are not joints (:func:`~brachycal.data.joint_log.joint_columns`) are ignored;
    the joints are validated by :func:`~brachycal.data.joint_log.configurations_from_columns`.
    """
    names = joint_columns(robot, header)
    values = to_float(path, header, rows, records, names)
    return configurations_from_columns(robot, names, values, source=str(path), rows=rows)


def read_configurations(path: str | os.PathLike[str], robot: Robot) -> tuple[list[int], FloatArray]:
    """Configurations from a CSV file whose header names the joints, one per row (radians; a joint
    log works: its time column is ignored): ``(rows (N,) file rows, Q (N, nq) in the robot's order)``.

    Raises:
        InputError: the file has no rows, or a joint is missing, not a number or out of its limits
            (naming the row and column).
    """
    path = Path(path)
    header, rows, records = read_table(path, [])
    if not records:
        raise InputError("no configurations", file=path)
    return rows, table_configurations(path, robot, header, rows, records)


def read_times(path: str | os.PathLike[str]) -> FloatArray:
    """``(M,)`` the ``time`` column of a CSV file, seconds (e.g. the time stamps of ultrasound frames)."""
    path = Path(path)
    header, rows, records = read_table(path, ["time"])
    return to_float(path, header, rows, records, ["time"])[:, 0]

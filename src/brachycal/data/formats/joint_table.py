"""Joint tables without a time column: one still configuration per row (a touch, a measured pose).

Recordings of still poses often carry no time: a robot touched a fixed point, the operator saved
the joint angles, once per touch (MUKCa's ``hole_0.csv``: 7 numbers a row, no header). Two forms
are read, both as *samples* numbered 1, 2, ... in the order of their rows:

- **no header**: every row holds one number per configuration coordinate of the robot, in the
  robot's configuration order (``brachycal model`` lists it; radians, metres for prismatic
  joints). A file whose first non-blank line is all numbers is such a table (:func:`still_table_kind`).
- **a header naming the joints** (any order, extra columns ignored) but no ``time`` column: read
  as :func:`~brachycal.data.formats.csv_log.configuration_blocks` reads a table of configurations.

The file is read whole through the input gate (:mod:`brachycal.inputs`), at most
:data:`~brachycal.inputs.MAX_TABLE_BYTES`; every value is checked as a joint log's are
(:func:`~brachycal.data.joint_log.configurations_from_columns`: finite, not degrees, inside the
limits). A refusal is one line naming the file, the row (file line, from 1) and the joint.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brachycal.data.formats.csv_log import TRUNCATED
from brachycal.data.joint_log import configurations_from_columns
from brachycal.errors import InputError
from brachycal.inputs import MAX_TABLE_BYTES, open_input, read_input_text
from brachycal.se3 import FloatArray
from brachycal.validate import all_number_texts, number_from_text

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot

__all__ = ["JointTable", "read_joint_table", "still_table_kind"]

#: Longest first line looked at to tell a header from numbers (bytes).
_FIRST_LINE_BYTES = 1 << 20


@dataclass(frozen=True)
class JointTable:
    """Still configurations read from a table without a time column.

    Attributes:
        q: ``(N, nq)`` configurations in the robot's joint order, radians (metres for prismatic joints).
        rows: ``(N,)`` file rows (lines, from 1) of the samples.
        source: the file, for messages.
    """

    q: FloatArray
    rows: np.ndarray
    source: str

    @property
    def samples(self) -> np.ndarray:
        """``(N,)`` sample numbers 1, 2, ..., N in row order."""
        return np.arange(1, len(self.q) + 1)


def still_table_kind(path: str | os.PathLike[str]) -> str | None:
    """What the CSV file's first non-blank line says it is: ``"no header"`` (all numbers: a table for
    :func:`read_joint_table`), ``"named"`` (a header without a ``time`` column: a table of named
    configurations), or None (a header with ``time``: a joint log).

    Raises:
        InputError: the file cannot be read (naming it: a folder, a device), or it holds nothing but blank lines.
    """
    with open_input(path) as handle:
        for raw in iter(lambda: handle.readline(_FIRST_LINE_BYTES), b""):
            line = raw.decode("utf-8", "replace").removeprefix("\ufeff").split("\r")[0].strip()  # CR-only line ends too
            if line:
                fields = [field.strip().strip('"') for field in line.split(",")]
                if all_number_texts([field for field in fields if field]):  # a blank field is a bad number
                    return "no header"
                return None if "time" in fields else "named"
    raise InputError("empty file: no configurations and no header", file=path)


def read_joint_table(path: str | os.PathLike[str], robot: Robot) -> JointTable:
    """Configurations from a CSV file without a header: one row per sample, one column per
    coordinate of ``robot`` in its configuration order (``robot.joint_names``).

    Raises:
        InputError: one line naming the file (and the row and joint): not a readable file (a folder,
            too large, not UTF-8), no rows, a row with another number of fields than the robot has
            coordinates, a last line without a newline (a cut file), a field that is not a number,
            a value not finite, in degrees (|value| > 2π) or outside the joint's limits.
    """
    path = Path(path)
    try:
        text = read_input_text(path, max_bytes=MAX_TABLE_BYTES)
    except UnicodeDecodeError as exc:
        raise InputError(f"not a UTF-8 text file ({exc})", file=path) from None
    names = list(robot.joint_names)
    rows: list[int] = []
    records: list[list[str]] = []
    try:
        for number, fields in enumerate(csv.reader(io.StringIO(text, newline="")), start=1):
            if not fields or (len(fields) == 1 and not fields[0].strip()):
                continue
            if len(fields) != len(names):
                raise InputError(
                    f"has {len(fields)} fields, expected {len(names)}: one per coordinate of the robot, in its order "
                    f"({names[0]}, ..., {names[-1]}; brachycal model lists them)",
                    file=path,
                    row=number,
                )
            rows.append(number)
            records.append(fields)
    except csv.Error as exc:
        raise InputError(f"not a readable CSV file ({exc})", file=path) from None
    if records and text.rstrip(" \t") and not text.rstrip(" \t").endswith(("\n", "\r")):
        raise InputError(TRUNCATED, file=path, row=rows[-1])
    if not records:
        raise InputError("empty file: no configurations (one row per sample, no header)", file=path)
    values = np.empty((len(records), len(names)))
    for i, (row, fields) in enumerate(zip(rows, records, strict=True)):
        for k, field in enumerate(fields):
            x = number_from_text(field.strip())
            if x is None:
                raise InputError(f"{field!r} is not a number", file=path, row=row, column=names[k])
            values[i, k] = x
    q = configurations_from_columns(robot, names, values, source=str(path), rows=np.asarray(rows))
    return JointTable(q, np.asarray(rows, dtype=np.int64), str(path))

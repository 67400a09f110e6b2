"""Touch folders: an arm's touches of fixed points, one folder per *place*.

A place folder holds ``hole_0.csv``, ``hole_1.csv``, … (MUKCa's layout): one file per fixed point,
one row per touch, the arm's joint values (radians; metres for a prismatic joint) in the arm's
joint order, comma-separated, no header and no time column. Other files in the folder are ignored
(MUKCa's ``hole_k_pose.csv``, ``comments.txt``). The folder's name is the place's.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brachycal.data.formats.csv_log import read_bare_table
from brachycal.errors import InputError
from brachycal.se3 import FloatArray

#: A point's file name: ``hole_<k>.csv``.
POINT_FILE = re.compile(r"hole_(\d+)\.csv")
#: Largest joint value accepted (radians or metres): a table in degrees, or of other numbers, is refused.
MAX_JOINT_VALUE = 2 * np.pi
#: Points per place at most, and touches per point at least.
MAX_POINTS = 100
MIN_TOUCHES = 2


@dataclass(frozen=True)
class TouchFolder:
    """One place's touches as read.

    Attributes:
        name: the place (the folder's name).
        tables: per point ``k`` (file ``hole_k.csv``), ``(N_k, columns)`` joint values.
        files: the files read, per point.
    """

    name: str
    tables: tuple[FloatArray, ...]
    files: tuple[Path, ...]


def read_touch_table(path: str | os.PathLike[str], joints: tuple[str, ...]) -> FloatArray:
    """``(N, len(joints))`` joint values of one point's touches (module docstring).

    Raises:
        InputError: not a readable table of ``len(joints)`` numbers per row; a value beyond
            :data:`MAX_JOINT_VALUE`; fewer than :data:`MIN_TOUCHES` touches.
    """
    path = Path(path)
    rows, values = read_bare_table(path, list(joints))
    if len(values) < MIN_TOUCHES:
        raise InputError(f"has {len(values)} touch(es); at least {MIN_TOUCHES} are needed", file=path)
    beyond = np.abs(values) > MAX_JOINT_VALUE
    if beyond.any():
        i, j = np.argwhere(beyond)[0]
        raise InputError(
            f"joint value {values[i, j]:g} is beyond ±{MAX_JOINT_VALUE:.4f} (radians expected)",
            file=path,
            row=rows[i],
            column=joints[j],
        )
    return values


def read_touch_folder(path: str | os.PathLike[str], joints: tuple[str, ...]) -> TouchFolder:
    """One place folder (module docstring): its ``hole_k.csv`` files, ``k = 0, 1, …`` without gaps.

    Raises:
        InputError: not a folder, no ``hole_0.csv``, two files of one point (``hole_1.csv`` and
            ``hole_01.csv``), a gap in the numbering, a bad table.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise InputError("not a folder of touches (hole_0.csv, hole_1.csv, …)", file=folder)
    try:
        names = sorted(os.listdir(folder))
    except OSError as exc:
        raise InputError(f"cannot list the folder ({exc.strerror})", file=folder) from None
    by_number: dict[int, str] = {}
    for name in names:
        match = POINT_FILE.fullmatch(name)
        if match is None:
            continue
        k = int(match.group(1))
        if k in by_number:
            raise InputError(f"{by_number[k]} and {name} both name point {k}: keep one", file=folder)
        by_number[k] = name
    numbers = sorted(by_number)
    if not numbers:
        raise InputError("no touch table (hole_0.csv, hole_1.csv, …) in the folder", file=folder)
    if len(numbers) > MAX_POINTS:
        raise InputError(f"{len(numbers)} touch tables; at most {MAX_POINTS} points per place", file=folder)
    if numbers != list(range(len(numbers))):
        missing = min(set(range(max(numbers) + 1)) - set(numbers))
        raise InputError(f"hole_{missing}.csv is missing: the tables are numbered from 0 without gaps", file=folder)
    files = tuple(folder / by_number[k] for k in numbers)
    tables = tuple(read_touch_table(f, joints) for f in files)
    return TouchFolder(folder.resolve().name, tables, files)

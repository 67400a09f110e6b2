"""The pose table written by ``brachycal fk``: ``time,frame,x,y,z,qx,qy,qz,qw``.

Positions in metres in ``base_link``; unit quaternions in ROS order (x, y, z, w) with qw ≥ 0;
one row per (time, frame), frames in the order asked for.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.csv_log import read_table, to_float
from brachycal.files import atomic_open
from brachycal.se3 import FloatArray, make_transform, to_position_quaternion

HEADER = ("time", "frame", "x", "y", "z", "qx", "qy", "qz", "qw")


def write_pose_table(
    path: str | os.PathLike[str],
    time: ArrayLike,
    frames: Sequence[str],
    T_base_frames: ArrayLike,
    *,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
) -> Path:
    """Write poses atomically.

    Args:
        path: output CSV.
        time: ``(N,)`` seconds.
        frames: ``(F,)`` frame names.
        T_base_frames: ``(F, N, 4, 4)`` poses ``T_base_frame``, metres.
        force: replace an existing file.
        progress: called with the number of samples written after each block.
    """
    time = np.asarray(time, dtype=float)
    poses = np.asarray(T_base_frames, dtype=float)
    position, quat = to_position_quaternion(poses)  # (F, N, 3), (F, N, 4)
    numbers = np.concatenate([position, quat], axis=-1)  # (F, N, 7)
    row = "%.9f,{frame},%.9f,%.9f,%.9f,%.12f,%.12f,%.12f,%.12f\n"
    templates = [row.replace("{frame}", f) for f in frames]
    block = 10_000
    with atomic_open(path, force=force) as handle:
        handle.write(",".join(HEADER) + "\n")
        for start in range(0, len(time), block):
            stop = min(start + block, len(time))
            lines = [templates[k] % (time[i], *numbers[k, i]) for i in range(start, stop) for k in range(len(frames))]
            handle.write("".join(lines))
            if progress is not None:
                progress(stop - start)
    return Path(path)


def read_pose_table(path: str | os.PathLike[str]) -> tuple[FloatArray, list[str], FloatArray]:
    """Read a pose table back: ``(time (R,), frame (R,), T_base_frame (R, 4, 4))``, one per row."""
    from scipy.spatial.transform import Rotation

    path = Path(path)
    header, rows, records = read_table(path, list(HEADER))
    numbers = to_float(path, header, rows, records, [h for h in HEADER if h != "frame"])
    frames = [fields[header.index("frame")] for fields in records]
    R = Rotation.from_quat(numbers[:, 4:8]).as_matrix()
    return numbers[:, 0], frames, make_transform(R, numbers[:, 1:4])

"""``brachycal fk``: poses of tool frames from a joint log, streamed block by block.

The log is read, checked, computed and written in blocks (:data:`brachycal.data.formats.csv_log.BLOCK_BYTES`
of a CSV file, :data:`brachycal.data.formats.bags.BLOCK_MESSAGES` messages of a bag), so memory does not
grow with the log's length; with ``--times`` it grows with the number of requested times only.
The pose table is staged and moved into place only when every block has been written.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_robot_option, load_robot, output_file, progress_bar
from brachycal.cli.option_types import finite_float, name_list
from brachycal.io import OutputSet

if TYPE_CHECKING:
    import numpy as np

    from brachycal.data.pose_table import BackgroundPoseWriter
    from brachycal.model import Robot

DEFAULT_TOPIC = (
    "/joint_states"  # = brachycal.data.formats.bags.DEFAULT_TOPIC, here so that --help imports no data module
)

HELP = "poses of tool frames in base_link for every sample of a joint log"
DESCRIPTION = """\
Computes the pose of each requested frame in the robot's base frame (the SDA10F's base_link) for
every sample of a joint log and writes the pose table: time,frame,x,y,z,qx,qy,qz,qw (metres; unit
quaternion x,y,z,w, qw >= 0 unless --quaternion-continuity).

LOG is a CSV file (header 'time,<joint names>', radians, columns in any order), a ROS 1 .bag
file, or a ROS 2 bag folder (sqlite3 or MCAP) with sensor_msgs/JointState messages. With --times,
the joint log is interpolated linearly to those times (e.g. the timestamps of ultrasound frames).
The log is streamed: read, checked, computed and written in blocks, in memory that does not grow
with its length.

A CSV file without a time column is a table of still configurations (touches): either no header,
one number per coordinate of the robot in its configuration order ('brachycal model' lists it),
or a header naming the joints. Its rows are samples 1, 2, ...: the pose table's first column is
then 'sample' instead of 'time'.

The robot is any robot (--robot NAME|FILE, --urdf FILE); frames are its links and tool frames.
The bundled SDA10F's: needle_tip, top_model_tip (right flange), probe_tip, us_image (left
flange), arm_right_link_tool0, arm_left_link_tool0, and every vendor link.

examples:
  brachycal fk examples/joint_log.csv --frames needle_tip,probe_tip --out poses.csv
  brachycal fk examples/joints.csv --frames needle_tip --out still_poses.csv
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "fk", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "log",
        metavar="LOG",
        help="joint log (CSV file, ROS 1 .bag, or ROS 2 bag folder), or a CSV table of still configurations",
    )
    parser.add_argument(
        "--frames",
        required=True,
        type=name_list(),
        metavar="A,B,...",
        help="comma-separated frame names, each once, e.g. needle_tip,probe_tip",
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="pose table to write")
    parser.add_argument(
        "--times", metavar="CSV", help="evaluate at these times: a CSV file with a 'time' column (seconds)"
    )
    parser.add_argument(
        "--lag-s",
        type=finite_float(unit="s"),
        default=0.0,
        metavar="L",
        help="with --times: clock lag of the joint log behind those times (brachycal temporal's lag_s); the log is "
        "read at t + L, and the table keeps the times t as given (default 0)",
    )
    parser.add_argument("--topic", default=DEFAULT_TOPIC, help=f"JointState topic in a bag (default {DEFAULT_TOPIC})")
    parser.add_argument(
        "--quaternion-continuity",
        action="store_true",
        help="give each frame's quaternion the sign closest to the previous row's (no jump from q to -q where a "
        "frame turns through qw = 0; for plots and interpolation) instead of qw >= 0 on every row; each "
        "frame's first row keeps qw >= 0",
    )
    add_robot_option(parser, any_arm=True)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def _check_log_folder(path: Path) -> None:
    """A folder given as the joint log must be a ROS 2 bag (a CSV log is a file)."""
    from brachycal.data.formats.bags import is_bag  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    if path.is_dir() and not is_bag(path):
        raise InputError("is a folder without metadata.yaml: neither a CSV joint log nor a ROS 2 bag", file=path)


def _still_table(path: Path) -> str | None:
    """The kind of table of still configurations ``path`` is
    (:func:`~brachycal.data.formats.joint_table.still_table_kind`), or None for a joint log (a bag, or
    a CSV file with a time column)."""
    from brachycal.data.formats.bags import is_bag  # lazy: start-up (the command's run only)
    from brachycal.data.formats.joint_table import still_table_kind  # lazy: start-up (the command's run only)

    if is_bag(path):
        return None
    return still_table_kind(path)


def still_blocks(path: Path, robot: Robot, kind: str) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(sample numbers (N,), q (N, nq))`` blocks of a table of still configurations, samples numbered
    1, 2, ... in row order: a table without a header read whole (bounded), a named one streamed."""
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.data.formats.csv_log import configuration_blocks  # lazy: start-up (the command's run only)
    from brachycal.data.formats.joint_table import read_joint_table  # lazy: start-up (the command's run only)

    if kind == "no header":
        table = read_joint_table(path, robot)
        yield table.samples.astype(float), table.q
        return
    done = 0
    for _, Q in configuration_blocks(path, robot):
        yield np.arange(done + 1, done + 1 + len(Q), dtype=float), Q
        done += len(Q)


def log_blocks(path: Path, robot: Robot, topic: str, quiet: bool) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(time (N,) s, q (N, nq) rad)`` blocks of a checked joint log (CSV or bag), with a progress bar
    over the bytes (CSV) or messages (bag) read."""
    from brachycal.data.formats.bags import bag_log_blocks, is_bag  # lazy: start-up (the command's run only)
    from brachycal.data.formats.csv_log import csv_log_blocks  # lazy: start-up (the command's run only)

    if quiet:  # no bar: tqdm not even imported
        bag = is_bag(path)
        for block, q in bag_log_blocks(path, robot, topic) if bag else csv_log_blocks(path, robot):
            yield block.time, q
        return
    if is_bag(path):
        with progress_bar(0, "reading bag", quiet, unit="message") as bar:

            def total(n: int) -> None:
                bar.total = n
                bar.refresh()

            for block, q in bag_log_blocks(path, robot, topic, progress=bar.update, total=total):
                yield block.time, q
        return
    # Bytes, not rows: the rows of a CSV file are known only once it is read.
    with progress_bar(path.stat().st_size, "reading log", quiet, unit="B") as bar:
        for block, q in csv_log_blocks(path, robot, progress=bar.update):
            yield block.time, q


def run(args: argparse.Namespace) -> int:
    from brachycal.data import read_times  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.data.pose_table import BackgroundPoseWriter, PoseTableWriter
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    if args.lag_s != 0.0 and args.times is None:
        raise InputError("--lag-s applies to --times (the frames' times on another clock)")
    robot = load_robot(args, any_arm=True)
    frames = args.frames  # names checked by argparse (none empty, no repeats)
    for frame in frames:
        robot.frame_id(frame)
    out = Path(args.out)
    with OutputSet(force=args.force, inputs=[args.log, args.times]) as outputs:
        staged = outputs.claim(out, label="--out")
        if not Path(args.log).exists():  # here, not when the first block is asked for: before --times is read
            raise InputError("no such file or folder", file=args.log)
        _check_log_folder(Path(args.log))
        still = _still_table(Path(args.log))
        if still is not None and args.times is not None:
            raise InputError("--times: this table has no time column (one still configuration per row)", file=args.log)
        if still is None:
            blocks = log_blocks(Path(args.log), robot, args.topic, args.quiet)
        else:
            blocks = still_blocks(Path(args.log), robot, still)
        times = read_times(args.times) if args.times else None
        with open(staged, "wb") as handle:
            # Formatted and written in a thread while the next block is computed (BackgroundPoseWriter).
            index = "time" if still is None else "sample"
            table = PoseTableWriter(handle, frames, continuity=args.quaternion_continuity, index=index)
            writer = BackgroundPoseWriter(table)
            with writer:
                _compute(robot, frames, blocks, times, writer, args.log, lag_s=args.lag_s)
            samples = len(times) if times is not None else writer.writer.rows // len(frames)
    if not args.quiet:
        print(f"wrote {samples * len(frames)} poses ({samples} samples x {len(frames)} frames) to {out}")
    return 0


def _compute(
    robot: Robot,
    frames: list[str],
    blocks: Iterator[tuple[np.ndarray, np.ndarray]],
    times: np.ndarray | None,
    writer: BackgroundPoseWriter,
    source: str,
    lag_s: float = 0.0,
) -> None:
    """Poses of ``frames`` for every sample of ``blocks`` (or at ``times`` ``(M,)`` s, interpolated at
    ``times + lag_s`` on the log's clock and written with ``times``), to ``writer``."""
    from brachycal.data.joint_log import interpolate_blocks  # lazy: start-up (the command's run only)

    if times is None:
        for time, q in blocks:
            writer.write(time, robot.fk_frames(frames, q))
        return
    Q = interpolate_blocks(blocks, times + lag_s, source=source)
    step = 16_384  # poses of this many times at once: a few MB
    for start in range(0, len(times), step):
        writer.write(times[start : start + step], robot.fk_frames(frames, Q[start : start + step]))

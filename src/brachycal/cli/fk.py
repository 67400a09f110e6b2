"""``brachycal fk``: poses of tool frames from a joint log."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_urdf_option, load_robot, progress_bar
from brachycal.data import DEFAULT_TOPIC, read_joint_log, read_times, write_pose_table
from brachycal.files import OutputSet
from brachycal.validate import name_list

HELP = "poses of tool frames in base_link for every sample of a joint log"
DESCRIPTION = """\
Computes the pose of each requested frame in base_link for every sample of a joint log and
writes the pose table: time,frame,x,y,z,qx,qy,qz,qw (metres; unit quaternion x,y,z,w, qw >= 0).

LOG is a CSV file (header 'time,<joint names>', radians, columns in any order), a ROS 1 .bag
file, or a ROS 2 bag folder with sensor_msgs/JointState messages. With --times, the joint log is
interpolated linearly to those times (e.g. the timestamps of ultrasound frames).

frames of the bundled SDA10F: needle_tip, top_model_tip (right flange), probe_tip, us_image
(left flange), arm_right_link_tool0, arm_left_link_tool0, and every vendor link.

example:
  brachycal fk examples/joint_log.csv --frames needle_tip,probe_tip --out poses.csv
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "fk", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("log", metavar="LOG", help="joint log: CSV file, ROS 1 .bag, or ROS 2 bag folder")
    parser.add_argument(
        "--frames",
        required=True,
        type=name_list(),
        metavar="A,B,...",
        help="comma-separated frame names, each once, e.g. needle_tip,probe_tip",
    )
    parser.add_argument("--out", required=True, metavar="CSV", help="pose table to write")
    parser.add_argument(
        "--times", metavar="CSV", help="evaluate at these times: a CSV file with a 'time' column (seconds)"
    )
    parser.add_argument("--topic", default=DEFAULT_TOPIC, help=f"JointState topic in a bag (default {DEFAULT_TOPIC})")
    add_urdf_option(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    robot = load_robot(args)
    frames = args.frames  # names checked by argparse (none empty, no repeats)
    for frame in frames:
        robot.frame_id(frame)
    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out, label="--out")
        log = read_joint_log(args.log, robot, args.topic)
        if args.times:
            times = read_times(args.times)
            Q = log.interpolate(times)
        else:
            times, Q = log.time, log.q
        with progress_bar(len(times), "forward kinematics", args.quiet) as bar:
            poses = robot.fk_frames(frames, Q, progress=bar.update)
        with progress_bar(len(times), "writing", args.quiet) as bar:
            write_pose_table(staged, times, frames, poses, force=args.force, progress=bar.update)
    if not args.quiet:
        print(f"wrote {len(times) * len(frames)} poses ({len(times)} samples x {len(frames)} frames) to {out}")
    return 0

"""``brachycal model``: what the robot model contains."""

from __future__ import annotations

import argparse

from brachycal.cli.common import add_robot_option, load_robot, tool_frame_parents

HELP = "joints, limits and tool frames of the robot model"


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("model", help=HELP, description=HELP + ".")
    add_robot_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.se3 import to_xyz_rpy  # lazy: start-up (the command's run only)

    robot = load_robot(args)
    print(f"model: {robot.source}")
    print(f"{robot.nq} controlled axes, in configuration order (radians):")
    for name, lo, hi, vel in zip(robot.joint_names, robot.lower, robot.upper, robot.velocity_limit, strict=True):
        print(
            f"  {name:22s} [{lo:+.4f}, {hi:+.4f}] rad  ({np.degrees(lo):+7.1f}..{np.degrees(hi):+6.1f} deg)"
            f"  max {vel:.3f} rad/s"
        )
    print("tool frames (parent -> frame: xyz in mm, rpy in deg):")
    for frame in tool_frame_parents(args):
        if robot.model.existFrame(frame):
            parent, T = robot.tool_transform(frame)
            xyz, rpy = to_xyz_rpy(T)
            print(
                f"  {parent} -> {frame}: xyz = {np.array2string(xyz * 1e3, precision=3)}"
                f"  rpy = {np.array2string(np.degrees(rpy), precision=3)}"
            )
    return 0

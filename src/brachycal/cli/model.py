"""``brachycal model``: what the robot model contains."""

from __future__ import annotations

import argparse
import math

from brachycal.cli.common import add_robot_option, load_robot

HELP = "joints, limits, arms and tool frames of the robot model (any robot)"


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("model", help=HELP, description=HELP + ".")
    add_robot_option(parser, any_arm=True)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    robot = load_robot(args, any_arm=True)
    print(f"model: {robot.source}")
    print(f"{robot.nq} controlled axes, in configuration order (radians; metres for prismatic joints):")
    for k, name in enumerate(robot.joint_names):
        limits = _limits(
            float(robot.lower[k]), float(robot.upper[k]), float(robot.velocity_limit[k]), robot.in_metres[k]
        )
        print(f"  {name:22s} {limits}")
    if robot.arms:
        print("arms (base -> flange -> tool: joints, root to flange):")
        for arm in robot.arms:
            tool = f" -> {arm.tool}" if arm.tool else ""
            print(f"  {arm.name}: {arm.base} -> {arm.flange}{tool}: {', '.join(arm.joints)}")
    else:
        print("arms: none named (a URDF without a description: docs/robots.md, 'Any arm')")
    if robot.has_rig:
        _print_tool_frames(robot)
    return 0


def _limits(lower: float, upper: float, velocity: float, in_metres: bool) -> str:
    """One coordinate's limits and top speed, in its own unit: radians (and degrees) for an angle,
    metres (and millimetres) for a prismatic joint's position."""
    if in_metres:
        return (
            f"[{lower:+.4f}, {upper:+.4f}] m    ({lower * 1e3:+7.1f}..{upper * 1e3:+6.1f} mm)   max {velocity:.3f} m/s"
        )
    deg = 180.0 / math.pi
    return f"[{lower:+.4f}, {upper:+.4f}] rad  ({lower * deg:+7.1f}..{upper * deg:+6.1f} deg)  max {velocity:.3f} rad/s"


def _print_tool_frames(robot: object) -> None:
    """The dual-arm rig's tool frames, each on its parent: xyz in mm, rpy in deg."""
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.model import Robot  # lazy: start-up (the command's run only)
    from brachycal.se3 import to_xyz_rpy  # lazy: start-up (the command's run only)

    assert isinstance(robot, Robot)
    print("tool frames (parent -> frame: xyz in mm, rpy in deg):")
    for frame in robot.rig.tool_frame_parents:
        if robot.model.existFrame(frame):
            parent, T = robot.tool_transform(frame)
            xyz, rpy = to_xyz_rpy(T)
            print(
                f"  {parent} -> {frame}: xyz = {np.array2string(xyz * 1e3, precision=3)}"
                f"  rpy = {np.array2string(np.degrees(rpy), precision=3)}"
            )

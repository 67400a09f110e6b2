"""``brachycal export``: a calibration result in the formats labs use (URDF, Slicer, PLUS, ROS)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import (
    add_method_option,
    add_quiet_option,
    add_robot_option,
    command_inputs,
    load_robot,
    method_said,
    print_next,
    robot_words,
)

if TYPE_CHECKING:
    from brachycal.io import OutputSet
    from brachycal.model import Robot

HELP = "export a result: calibrated URDF, 3D Slicer/ITK transforms, PLUS CoordinateDefinitions, ROS static TFs"
DESCRIPTION = """\
Writes into DIR: <robot>_calibrated.urdf (sda10f_calibrated.urdf for the default robot; tool
joints replaced and, for a result that corrected the robot, its corrected joint origins; loads in
ROS/MoveIt, Pinocchio, MuJoCo) with a meshes/ folder holding a copy of every mesh it names (the
folder is self-contained: copy it anywhere), ImageToProbe.tfm / ProbeToLeftFlange.tfm /
NeedleTipToRightFlange.tfm (3D Slicer and ITK transform files, millimetres; ImageToProbe maps
pixels and carries the spacing, its third column the mean spacing as PLUS writes it; the flanges
are named Left/Right when the robot's flange links say their side, else Probe/Needle),
PlusCoordinateDefinitions.xml (a PLUS <CoordinateDefinitions> element) and static_transforms.yaml
(ROS static transforms with the static_transform_publisher command for ROS 2 and for ROS 1).
The URDF records the result it was written from and the corrections it carries: given back with
--urdf and the same result, locate, plan and export apply nothing twice.

--ros-package NAME also writes DIR/NAME/, a ROS 2 (ament_cmake) description package: package.xml,
CMakeLists.txt, urdf/ (package://NAME/meshes/... URIs), meshes/, config/static_transforms.yaml and
launch/NAME.launch.py (robot_state_publisher with the calibrated URDF; publish_robot:=false
starts one static_transform_publisher per calibrated transform instead).

--method defaults to the best image calibration in the result: the whole chain's if present
(chain+robot, then chain), else the registration with the lowest leave-one-out RMSE (ties in Table
II's order). --robot must be the robot the result was calibrated with (the result records it).

example:
  brachycal export twin_result.json --out calibration_exports
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "export", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("result", metavar="RESULT", help="calibration result (JSON)")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder to write")
    add_method_option(parser, "the result")
    parser.add_argument(
        "--ros-package",
        metavar="NAME",
        help="also write DIR/NAME/, a ROS 2 description package (lowercase letters, digits, underscores)",
    )
    add_robot_option(parser)
    parser.add_argument("--force", action="store_true", help="replace existing files")
    add_quiet_option(parser, "next: line")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # lazy: start-up (the command's run only)
    from brachycal.export import check_ros_package_name, export_files, ros_package_files
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    if args.ros_package is not None:
        check_ros_package_name(args.ros_package)
    # The robot names the files (<robot>_calibrated.urdf, the flanges' .tfm): loaded before the claims.
    robot = load_robot(args)
    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs:
        for name in export_files(robot.rig):
            outputs.claim(Path(args.out) / name, make_parents=True)
        if args.ros_package is not None:
            for name in ros_package_files(robot.rig, args.ros_package):
                outputs.claim(Path(args.out) / args.ros_package / name, make_parents=True)
        said = _run(args, robot, outputs)
    print(f"exported method: {said}")
    for path in outputs.written:
        print(f"wrote {path}")
    # The calibration is in use: before each procedure, a check of a few samples says whether it still holds.
    print_next(
        f"brachycal verify {args.result} CHECK_SESSION{robot_words(args)} --out check_record.json", quiet=args.quiet
    )
    return 0


def _run(args: argparse.Namespace, robot: Robot, outputs: OutputSet) -> str:
    """Write every export of the result into ``outputs`` (``robot``: the one of --robot/--urdf);
    returns which image calibration it exported, in words (:func:`method_said`)."""
    from brachycal.calibration import read_result  # lazy: start-up (the command's run only)
    from brachycal.export import write_exports, write_ros_package  # lazy: start-up (the command's run only)

    stored = read_result(args.result)
    calibration = stored.calibration(args.method)
    software = stored.software_robot(robot)  # refuses another robot; corrections applied once
    record = stored.export_record(calibration.method)
    write_exports(software, calibration, args.out, force=args.force, outputs=outputs, record=record)
    if args.ros_package is not None:
        write_ros_package(
            software, calibration, args.out, args.ros_package, force=args.force, outputs=outputs, record=record
        )
    return method_said(stored, args.method)

"""``brachycal export``: a calibration result in the formats labs use (URDF, Slicer, PLUS, ROS)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_robot_option, load_robot
from brachycal.errors import InputError

if TYPE_CHECKING:
    from brachycal.files import OutputSet
    from brachycal.model import Robot

HELP = "export a result: calibrated URDF, 3D Slicer/ITK transforms, PLUS CoordinateDefinitions, ROS static TFs"
DESCRIPTION = """\
Writes into DIR: <robot>_calibrated.urdf (sda10f_calibrated.urdf for the default robot; tool
joints replaced and, for a result that identified the robot, its corrected joint origins; loads in
ROS/MoveIt, Pinocchio, MuJoCo), ImageToProbe.tfm / ProbeToLeftFlange.tfm /
NeedleTipToRightFlange.tfm (3D Slicer and ITK transform files, millimetres; ImageToProbe maps
pixels and carries the spacing; the flanges are named Left/Right when the robot's flange links
say their side, else Probe/Needle), PlusCoordinateDefinitions.xml (a PLUS <CoordinateDefinitions>
element) and static_transforms.yaml (ROS static transforms with the static_transform_publisher
command for each). --robot must be the robot the result was calibrated with (the result records it).

example:
  brachycal export result.json --out calibration_exports
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.calibration.labels import ALL_LABELS

    parser = sub.add_parser(
        "export", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("result", metavar="RESULT", help="calibration result (JSON)")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder to write")
    parser.add_argument(
        "--method",
        choices=tuple(ALL_LABELS),
        help="which image calibration (default: chain if present, else kabsch)",
    )
    add_robot_option(parser)
    parser.add_argument("--force", action="store_true", help="replace existing files")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.export import export_files
    from brachycal.files import OutputSet

    # The robot names the files (<robot>_calibrated.urdf, the flanges' .tfm): loaded before the claims.
    robot = load_robot(args)
    with OutputSet(force=args.force) as outputs:
        for name in export_files(robot.rig):
            outputs.claim(Path(args.out) / name, make_parents=True)
        _run(args, robot, outputs)
    for path in outputs.written:
        print(f"wrote {path}")
    return 0


def _run(args: argparse.Namespace, robot: Robot, outputs: OutputSet) -> None:
    """Write every export of the result into ``outputs`` (``robot``: the one of --robot/--urdf)."""
    from brachycal.calibration import read_result
    from brachycal.export import write_exports

    stored = read_result(args.result)
    method = args.method or ("chain" if "chain" in stored.image else "kabsch")
    if method not in stored.image:
        raise InputError(f"the result has no method {method!r} (it has {', '.join(stored.image)})", file=args.result)
    software = stored.software_robot(robot)  # refuses another robot; corrections applied once
    write_exports(
        software, stored.T_ER_Ntip, stored.T_EL_Ptip, stored.image[method], args.out, force=args.force, outputs=outputs
    )

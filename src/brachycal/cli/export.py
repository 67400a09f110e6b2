"""``brachycal export``: a calibration result in the formats labs use (URDF, Slicer, PLUS, ROS)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_urdf_option, load_robot
from brachycal.errors import InputError

if TYPE_CHECKING:
    from brachycal.files import OutputSet

HELP = "export a result: calibrated URDF, 3D Slicer/ITK transforms, PLUS CoordinateDefinitions, ROS static TFs"
DESCRIPTION = """\
Writes into DIR: sda10f_calibrated.urdf (tool joints replaced; loads in ROS/MoveIt, Pinocchio,
MuJoCo), ImageToProbe.tfm / ProbeToLeftFlange.tfm / NeedleTipToRightFlange.tfm (3D Slicer and
ITK transform files, millimetres; ImageToProbe maps pixels and carries the spacing),
PlusCoordinateDefinitions.xml (a PLUS <CoordinateDefinitions> element) and static_transforms.yaml
(ROS static transforms with the static_transform_publisher command for each).

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
    add_urdf_option(parser)
    parser.add_argument("--force", action="store_true", help="replace existing files")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.export import EXPORT_FILES
    from brachycal.files import OutputSet

    with OutputSet(force=args.force) as outputs:
        for name in EXPORT_FILES:
            outputs.claim(Path(args.out) / name, make_parents=True)
        _run(args, outputs)
    for path in outputs.written:
        print(f"wrote {path}")
    return 0


def _run(args: argparse.Namespace, outputs: OutputSet) -> None:
    """Write every export of the result into ``outputs``."""
    from brachycal.calibration import read_result
    from brachycal.export import write_exports

    stored = read_result(args.result)
    method = args.method or ("chain" if "chain" in stored.image else "kabsch")
    if method not in stored.image:
        raise InputError(f"the result has no method {method!r} (it has {', '.join(stored.image)})", file=args.result)
    robot = stored.software_robot(load_robot(args))
    write_exports(
        robot, stored.T_ER_Ntip, stored.T_EL_Ptip, stored.image[method], args.out, force=args.force, outputs=outputs
    )

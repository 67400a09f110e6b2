"""``brachycal locate``: where an image point is in base_link, through the calibrated chain."""

from __future__ import annotations

import argparse
import sys

from brachycal.cli.common import add_method_option, add_robot_option, load_robot, method_said
from brachycal.cli.option_types import number_list
from brachycal.validate import MAX_IMAGE_PX, check_pixel

HELP = "map an image pixel to base_link through the calibrated chain (targeting)"
DESCRIPTION = """\
Computes p_R = T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ (u*s_u, v*s_v, 0): the point of the robot's
base frame that pixel (u, v) shows, with the robot at configuration q (EL: the probe arm's flange).
RESULT is a calibration result file (brachycal calibrate); JOINTS is a CSV file whose header names
the robot's joints (radians; the SDA10F's 15), one configuration per row (a joint log works; its
time column is ignored). Prints the header line,x_m,y_m,z_m, then one line per configuration: its
line in JOINTS (the header is line 1, as a text editor counts) and the point in the robot's base
frame, metres; one line on stderr names the method, the frame and the unit.
--method defaults to the best image calibration in the result: the whole chain's if present
(chain+robot, then chain), else the registration with the lowest leave-one-out RMSE (ties in
Table II's order), as for export.
--robot must be the robot the result was calibrated with (the result records it).

example:
  brachycal locate twin_result.json examples/joints.csv --uv 540,300
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "locate", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("result", metavar="RESULT", help="calibration result (JSON)")
    parser.add_argument("joints", metavar="JOINTS", help="CSV of configurations (joint-name columns, radians)")
    uv = number_list(count=2, low=-0.5, high=MAX_IMAGE_PX, unit="px")
    parser.add_argument(
        "--uv",
        required=True,
        type=uv,
        metavar="U,V",
        help=f"pixel: column u, row v, {uv.rule}, inside the result's image (-0.5 <= u <= width - 0.5, likewise v)",
    )
    add_method_option(parser, "the result")
    add_robot_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.calibration import read_result  # lazy: start-up (the command's run only)
    from brachycal.calibration.result import locate  # lazy: start-up (the command's run only)
    from brachycal.data.formats.csv_log import configuration_blocks  # lazy: start-up (the command's run only)

    stored = read_result(args.result)
    # The result knows its images' size (older result files do not: then argparse's bound stands).
    uv = check_pixel(args.uv, "--uv", size_px=stored.image_size_px)[None]
    calibration = stored.calibration(args.method)
    robot = stored.software_robot(load_robot(args))
    # Streamed: one block of rows read, located and printed at a time (a joint log may be long).
    # The header is printed with the first block, so a file refused at once prints nothing. The
    # unit is in the column names (a plain CSV header); the method and frame on stderr, one line.
    header = "line,x_m,y_m,z_m\n"  # line: of JOINTS, as an editor counts (the header is line 1)
    for rows, Q in configuration_blocks(args.joints, robot):
        P = locate(robot, Q, uv, calibration)
        if header:
            said = method_said(stored, args.method)
            print(
                f"brachycal locate: method {said}; frame {robot.rig.base}; unit m; result {args.result}; "
                f"line: of {args.joints} (its header is line 1)",
                file=sys.stderr,
            )
        sys.stdout.write(
            header + "".join(f"{r},{p[0]:.9f},{p[1]:.9f},{p[2]:.9f}\n" for r, p in zip(rows, P.tolist(), strict=True))
        )
        header = ""
    return 0

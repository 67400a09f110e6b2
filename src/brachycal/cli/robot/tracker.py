"""``brachycal robot identify tracker``: an arm's joint geometry identified from an external tracker's
measurements of a marker on it (options and run; the parser is ``robot identify``'s)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from brachycal.calibration.robot.tracker import TrackerIdentification

DESCRIPTION = """\
tracker: INPUT is one CSV table, one row per posture: the joint values and where an external tracker
(a laser tracker, motion capture) saw a marker on the arm, its 3-D position and optionally its
orientation. --columns names the columns (a small TOML file: format, joints, [position] columns
and unit m or mm, optional [orientation] columns, kind rotation_vector, rpy or quaternion_xyzw,
unit rad or deg; docs/robot_identification.md). The tracker's frame and the marker's place on the
flange are unknown and fitted. Three models are scored by leave-one-out over postures (each
predicted by a fit made without it): frames (the URDF as it is), offsets (joint zeros), joints
(every joint-origin component the data can see). A richer model is kept only if it predicts
held-out postures better by more than its standard error (--model forces one). Writes
DIR/robot.urdf (the chosen model's joints) and DIR/identification.json (figures, frames,
corrections). Default prior: 1 mm / 0.1 deg per joint origin.

example (FIGAROH's UR10, 6-D poses):
  brachycal robot identify tracker calibration.csv --columns ur10_columns.toml \\
      --urdf ur10_robot.urdf --flange wrist_3_link --out ur10
"""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The tracker protocol's own options."""
    from brachycal.calibration.robot.tracker import TRACKER_MODELS  # lazy: start-up (the command's run only)

    group = parser.add_argument_group("tracker")
    group.add_argument("--columns", metavar="FILE", help="tracker: the table's column spec (TOML)")
    group.add_argument(
        "--flange", metavar="FRAME", help="tracker: the frame the marker is on (default: the last joint column's)"
    )
    group.add_argument(
        "--model",
        choices=("auto", *TRACKER_MODELS),
        default="auto",
        help="tracker: the model to return (default auto: the richest the held-out postures support)",
    )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path  # lazy: start-up (the command's run only)

    import numpy as np  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.tracker import TRACKER_ACCURACY, identify_tracker_file
    from brachycal.calibration.robot_accuracy import RobotAccuracy  # lazy: start-up (the command's run only)
    from brachycal.cli.common import command_inputs  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, write_json  # lazy: start-up (the command's run only)
    from brachycal.model import Robot  # lazy: start-up (the command's run only)

    if len(args.folders) != 1:
        raise InputError(f"tracker: give one table, got {len(args.folders)} inputs")
    if args.columns is None:
        raise InputError("tracker: --columns FILE is required (the table's column spec)")
    for name in ("tool_frame", "train", "distance_mm", "dynamics"):
        if getattr(args, name, None) is not None:
            raise InputError(f"--{name.replace('_', '-')} is for the touches protocol, not tracker")
    accuracy = TRACKER_ACCURACY
    if args.robot_accuracy_mm is not None or args.robot_accuracy_deg is not None:
        mm = args.robot_accuracy_mm if args.robot_accuracy_mm is not None else TRACKER_ACCURACY.translation_sd_m * 1e3
        deg = (
            args.robot_accuracy_deg
            if args.robot_accuracy_deg is not None
            else float(np.degrees(TRACKER_ACCURACY.rotation_sd_rad))
        )
        accuracy = RobotAccuracy(
            mm * 1e-3, float(np.radians(deg)), source=f"--robot-accuracy-mm {mm:g} --robot-accuracy-deg {deg:g}"
        )
    out = Path(args.out)
    with OutputSet(force=args.force, inputs=[*command_inputs(args, "columns"), *args.folders]) as outputs:
        urdf_path = outputs.claim(out / "robot.urdf", make_parents=True, label="--out robot.urdf")
        json_path = outputs.claim(out / "identification.json", make_parents=True, label="--out identification.json")
        nominal = Robot.load(args.urdf)
        result = identify_tracker_file(
            nominal,
            args.folders[0],
            args.columns,
            accuracy,
            flange=args.flange,
            model=None if args.model == "auto" else args.model,
        )
        result.fit.robot(nominal).write_urdf(urdf_path, force=True)
        write_json(json_path, result.as_json(), force=True)
    print_report(result)
    print(f"wrote {out / 'robot.urdf'} and {out / 'identification.json'}")
    return 0


def print_report(result: TrackerIdentification) -> None:
    """Per model: held-out (leave-one-out) first, then training; the choice and why."""
    data = result.data
    print(
        f"{len(data.Q)} postures, {'6-D' if data.six_d else '3-D'} marker on {data.flange}: "
        "marker position error per coordinate, leave-one-out (held out) / training"
    )
    for line in result.summary():
        print("  " + line)
    sigma = result.fit.sigma
    noise = f"tracker noise {sigma['position'] * 1e3:.3f} mm"
    if "orientation" in sigma:
        noise += f", {float(sigma['orientation']) * 180 / 3.141592653589793:.3f} deg"
    print(f"{noise}; {len(result.fit.parameters)} joint corrections estimated")

"""``brachycal robot identify tracker``: an arm's joint geometry identified from an external tracker's
measurements of a marker on it, judged by leave-one-out over postures."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from brachycal.calibration.robot.tracker import TrackerIdentification

HELP = "any arm: a tracker's 3-D or 6-D measurements of a marker on it; judged by leave-one-out"
#: The protocol takes any robot (a single arm, a URDF), not only the dual-arm rig.
ANY_ARM = True
DESCRIPTION = """\
Identifies an arm's joint geometry from TABLE, one CSV table, one row per posture: the joint values
and where an external tracker (a laser tracker, motion capture) saw a marker on the arm, its 3-D
position and optionally its orientation. --columns names the columns (a small TOML file: format,
joints, [position] columns and unit m or mm, optional [orientation] columns, kind rotation_vector,
rpy or quaternion_xyzw, unit rad or deg; docs/robots.md). The tracker's frame and the marker's
place on the flange are unknown and fitted. Three models are scored by leave-one-out over postures
(each predicted by a fit made without it): frames (the URDF as it is), offsets (joint zeros),
joints (every joint-origin component the data can see). A richer model is kept only if it predicts
held-out postures better by more than its standard error (--model forces one). Writes
DIR/robot.urdf (the chosen model's joints) and DIR/identification.json (figures, frames,
corrections). Default prior: 1 mm / 0.1 deg per joint origin (--robot-accuracy-mm,
--robot-accuracy-deg); --prior evidence instead chooses, per model, the SDs the postures' own
evidence makes most likely, searched from the stated ones: on all postures for the written fit and,
for the held-out figures, inside each leave-one-out fold from its own postures (tens of fits per
fold). Printed: per model the held-out (leave-one-out) error first, the training error second;
then the choice and which combinations of corrections the postures determine.

The robot: --robot NAME|FILE (a bundled arm: panda, ur5, ur10; a brachycal-robot/1 description;
a URDF file) or --urdf FILE.

The first example runs on the bundled tracker table (`brachycal examples examples` copies it): a
UR10 off its URDF by 0.5 mm / 0.05 deg per joint-origin axis, a 6-D marker on its flange
(examples/tracker/truth.json holds the truth); the second on FIGAROH's UR10 (6-D poses), its
table and URDF made from FIGAROH's data as docs/robots.md shows.

example:
  brachycal robot identify tracker examples/tracker/table.csv --columns examples/tracker/columns.toml \\
      --robot ur10 --out tracker_identified

on FIGAROH's UR10:
  brachycal robot identify tracker calibration.csv --columns ur10_columns.toml \\
      --robot ur10_robot.urdf --flange wrist_3_link --out ur10
"""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The tracker protocol's own options (the robot, --out and --force: :mod:`brachycal.cli.robot.identify`)."""
    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.defaults import TRACKER_ACCURACY, TRACKER_MODELS, TRACKER_PRIORS
    from brachycal.cli.common import add_robot_accuracy_options  # lazy: start-up (the command's run only)

    parser.add_argument("table", metavar="TABLE", help="the tracker table (CSV, one row per posture)")
    parser.add_argument("--columns", required=True, metavar="SPEC", help="the table's column spec (TOML)")
    parser.add_argument(
        "--flange", metavar="FRAME", help="the frame the marker is on (default: the last joint column's)"
    )
    parser.add_argument(
        "--model",
        choices=("auto", *TRACKER_MODELS),
        default="auto",
        help="the model to return (default auto: the richest the held-out postures support)",
    )
    parser.add_argument(
        "--prior",
        choices=TRACKER_PRIORS,
        default="stated",
        help="stated: the stated accuracy is the prior; evidence: per model, the prior's SDs the postures "
        "make most likely, searched from the stated accuracy (each leave-one-out fold chooses its own "
        "from its postures; tens of fits per fold)",
    )
    add_robot_accuracy_options(parser, "the prior of the corrections", zero=False, default=TRACKER_ACCURACY)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.tracker import TRACKER_ACCURACY, identify_from_tracker, tracker_data, tracker_fits
    from brachycal.cli.common import (  # lazy: start-up (the command's run only)
        command_inputs,
        load_robot,
        progress_bar,
        robot_accuracy,
    )
    from brachycal.data.formats.tracker_table import (  # lazy: start-up (the command's run only)
        read_tracker_columns,
        read_tracker_table,
    )
    from brachycal.io import OutputSet, write_json  # lazy: start-up (the command's run only)

    accuracy = robot_accuracy(args, TRACKER_ACCURACY)
    from brachycal.cli.robot.report import claim_outputs  # lazy: start-up (the command's run only)

    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "columns", "table")) as outputs:
        urdf_path, json_path = claim_outputs(outputs, out)
        nominal = load_robot(args, any_arm=True)
        data = tracker_data(nominal, read_tracker_table(args.table, read_tracker_columns(args.columns)), args.flange)
        model = None if args.model == "auto" else args.model
        # Per model, its fit on all postures and one leave-one-out fold per posture; with the
        # evidence each of them is a search of tens of fits.
        unit = "search" if args.prior == "evidence" else "fit"
        with progress_bar(tracker_fits(len(data.Q), model=model), "leave-one-out", args.quiet, unit=unit) as bar:
            result = identify_from_tracker(data, accuracy, model=model, prior=args.prior, progress=bar.update)
        result.fit.robot(nominal).write_urdf(urdf_path, force=True)
        write_json(json_path, result.as_json(), force=True)
    print_report(result)
    print(f"wrote {out / 'robot.urdf'} and {out / 'identification.json'}")
    return 0


def print_report(result: TrackerIdentification) -> None:
    """Per model: held-out (leave-one-out) first, then training; the choice and why; the
    identifiability in short."""
    # lazy: start-up (the command's run only)
    from brachycal.cli.robot.report import print_identifiability, print_prior

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
        noise += f", {math.degrees(sigma['orientation']):.3f} deg"
    print(f"{noise}; {len(result.fit.parameters)} joint corrections estimated")
    accuracy = result.fit.arm.accuracy
    if accuracy is not None and result.fit.parameters:
        print_prior(accuracy)
    print_identifiability(result.fit.arm.identifiability, result.fit.arm.joint_names)

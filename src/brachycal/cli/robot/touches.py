"""``brachycal robot identify touches``: an arm's joint geometry (and the tool's tip) identified
from touches of fixed points by a tool on the flange, judged on held-out places."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from brachycal.calibration.robot.touches import TouchReport
    from brachycal.model import Robot

HELP = "any arm: touches of fixed points by a tool on the flange; judged on held-out places"
#: The protocol takes any robot (a single arm, a URDF), not only the dual-arm rig.
ANY_ARM = True
DESCRIPTION = """\
Identifies an arm's joint geometry (every joint origin's translation and rotation, and the tool's
tip) from touches: a tool on the flange (a ball, a sharp tip) touches fixed points (sockets,
divots) from many postures. Each FOLDER is one place (the points somewhere in the workspace):
hole_0.csv, hole_1.csv, ... one per point, one row per touch, the arm's joint values in radians in
the arm's joint order, no header. The fit uses the --train places; every other place is held out
and judged: per point, the mean distance of the tool tip from its mean (forward kinematics of each
touch), averaged over the points, and with --distance-mm the error of the distance between points
0 and 1. Held-out places are printed first: they say how the calibrated robot does elsewhere;
then the training places, then which combinations of corrections the touches determine.

The robot: --robot NAME|FILE (a bundled arm: panda, ur5, ur10; a brachycal-robot/1 description;
a URDF file) or --urdf FILE. --tool-frame names the touching tip's frame (fixed to the flange);
default the arm's tool when the description names one.

The stated accuracy (--robot-accuracy-mm, --robot-accuracy-deg) is the prior of the corrections:
state the arm's own figures (a Panda's joints are off their URDF by tenths of a millimetre).
--robot-tilt-deg gives the tilt of the joints' axes a prior of its own (machined bearing seats
tilt less than encoders are off their zero).
--prior choose picks the setting (the stated accuracy, the evidence's prior, the evidence's with the
axes' tilt apart) by leave-one-place-out over the training places alone (two at least; with one the
stated accuracy is kept), and prints the choice and why.
With --dynamics NAME|FILE (the same arm with masses: a bundled arm such as panda, whose URDF has
them, or a URDF file; refused when its joints or masses do not fit the arm), joint compliance under
gravity is fitted too; a URDF cannot carry it, so the written URDF is a second fit of the geometry
alone. Every figure printed first is the written URDF's; the compliance fit's is beside it,
labelled "with compliance, not in the URDF".

Writes DIR/robot.urdf (the identified joints, the tip written into the tool frame) and
DIR/identification.json (corrections, tip, noise level, compliance, figures per place).

The first example runs on the bundled touches (`brachycal examples examples` copies them): a
Panda off its URDF by 0.3 mm / 0.05 deg per joint-origin axis, its ball tool (panda_hand_tcp)
touching two sockets 50 mm apart at three places (front, left, right; examples/touches/truth.json
holds the truth), trained on front and judged on the others. The second runs on MUKCa's real
Franka Panda touches, from $BRACHYCAL_REFERENCE/mukca_touches.

examples:
  brachycal robot identify touches examples/touches/front examples/touches/left examples/touches/right \\
      --robot panda --tool-frame panda_hand_tcp --train front --distance-mm 50 \\
      --robot-accuracy-mm 0.3 --robot-accuracy-deg 0.05 --out touches_identified
  brachycal robot identify touches $BRACHYCAL_REFERENCE/mukca_touches/data/panda_2_clean/front_center \\
      $BRACHYCAL_REFERENCE/mukca_touches/data/panda_2_clean/back_left \\
      $BRACHYCAL_REFERENCE/mukca_touches/data/panda_2_clean/mid_right \\
      --robot $BRACHYCAL_REFERENCE/mukca_touches/urdf/panda.urdf --tool-frame ball_link \\
      --train front_center --distance-mm 50 --robot-accuracy-mm 0.3 --robot-accuracy-deg 0.1 --out panda_2
"""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The touches protocol's own options (the robot, --out and --force: :mod:`brachycal.cli.robot.identify`)."""
    from brachycal.cli.common import add_robot_accuracy_options  # lazy: start-up (the command's run only)
    from brachycal.cli.option_types import finite_float  # lazy: start-up (the command's run only)

    parser.add_argument("folders", nargs="+", metavar="FOLDER", help="place folders (hole_0.csv, hole_1.csv, ...)")
    parser.add_argument(
        "--train", required=True, metavar="PLACE[,PLACE]", help="the places to identify from (folder names)"
    )
    parser.add_argument(
        "--tool-frame",
        metavar="FRAME",
        help="the touching tip's frame (fixed to the flange; default: the arm's tool in its description)",
    )
    parser.add_argument(
        "--distance-mm",
        type=finite_float(low=0.0, high=10_000.0, low_open=True, unit="mm"),
        metavar="MM",
        help="the known distance between points 0 and 1 of every place (a machined block), in (0, 10000] mm",
    )
    parser.add_argument(
        "--dynamics",
        metavar="NAME|FILE",
        help="the same arm with masses, to fit joint compliance under gravity: a bundled arm "
        "(panda, ur5, ur10: their URDFs have the masses), a brachycal-robot/1 description or a URDF file",
    )
    parser.add_argument(
        "--prior",
        choices=("stated", "evidence", "choose"),
        default="stated",
        help="stated: the stated accuracy is the prior; evidence: the prior's SDs (and the compliance's) "
        "that the training places' own data make most likely, searched from the stated accuracy "
        "(tens of fits); choose: stated, evidence or evidence with the axes' tilt apart, whichever "
        "leave-one-place-out over the training places supports (a setting replaces the stated accuracy "
        "only if better by more than its standard error; two training places at least, else the stated "
        "accuracy is kept; hundreds of fits). The held-out places are never used",
    )
    from brachycal.calibration.robot.defaults import TOUCHES_ACCURACY  # lazy: start-up (the command's run only)

    add_robot_accuracy_options(parser, "the prior of the corrections", zero=False, default=TOUCHES_ACCURACY)
    parser.add_argument(
        "--robot-tilt-deg",
        type=finite_float(low=0.0, high=1.0, low_open=True, unit="deg"),
        metavar="SD",
        help="the tilt of each joint's axis (its origin's rotation about the two axes across it) its own "
        "prior SD, in (0, 1] deg (default: --robot-accuracy-deg's); --robot-accuracy-deg keeps the "
        "rotation about the axis and the zero offset",
    )


def tool_frame(args: argparse.Namespace, nominal: Robot) -> str:
    """--tool-frame, else the robot's only arm's tool (a description's ``tool``)."""
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    if args.tool_frame is not None:
        return str(args.tool_frame)
    arms = nominal.arms
    if len(arms) == 1 and arms[0].tool is not None:
        return arms[0].tool
    raise InputError("--tool-frame is required: the robot names no single arm with a tool (the touching tip's frame)")


def dynamics_robot(name: str, nominal: Robot, tool: str) -> Robot:
    """The robot of --dynamics, resolved as --robot resolves its NAME|FILE (a bundled arm, a
    description, a URDF file), checked to be ``nominal``'s arm to ``tool`` with its masses
    (:func:`~brachycal.calibration.robot.arm_fit.check_dynamics`); a refusal names the option."""
    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.arm_fit import check_dynamics
    from brachycal.calibration.robot.touches import arm_joints  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.model.description import load_robot  # lazy: start-up (the command's run only)

    joints = arm_joints(nominal, nominal.tool_transform(tool)[0])  # an unknown tool is --tool-frame's
    try:
        dynamics = load_robot(name)
        check_dynamics(dynamics, nominal, joints)
    except InputError as exc:
        raise InputError(f"--dynamics: {exc}") from None
    return dynamics


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace  # lazy: start-up (the command's run only)
    from pathlib import Path  # lazy: start-up (the command's run only)

    from brachycal.calibration.robot.touches import (  # lazy: start-up (the command's run only)
        TOUCHES_ACCURACY,
        identify_touch_folders,
    )
    from brachycal.cli.common import (  # lazy: start-up (the command's run only)
        command_inputs,
        load_robot,
        progress_bar,
        robot_accuracy,
    )
    from brachycal.cli.robot.report import claim_outputs  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, write_json  # lazy: start-up (the command's run only)

    out = Path(args.out)
    with OutputSet(force=args.force, inputs=[*command_inputs(args, "dynamics"), *args.folders]) as outputs:
        urdf_path, json_path = claim_outputs(outputs, out)
        nominal = load_robot(args, any_arm=True)
        tool = tool_frame(args, nominal)
        dynamics = dynamics_robot(args.dynamics, nominal, tool) if args.dynamics is not None else None
        train = [name.strip() for name in args.train.split(",")]
        accuracy = robot_accuracy(args, TOUCHES_ACCURACY)
        if args.robot_tilt_deg is not None:
            accuracy = replace(
                accuracy,
                tilt_sd_rad=math.radians(args.robot_tilt_deg),
                source=f"{accuracy.source}; --robot-tilt-deg {args.robot_tilt_deg:g}",
            )
        # The fits' number is not known ahead with the evidence (tens per search): a count, no end.
        with progress_bar(None, "identifying", args.quiet, unit="fit") as bar:
            report = identify_touch_folders(
                nominal,
                args.folders,
                tool,
                train,
                accuracy,
                distance_m=args.distance_mm * 1e-3 if args.distance_mm is not None else None,
                dynamics=dynamics,
                prior=args.prior,
                progress=bar.update,
            )
        report.calibrated_robot(nominal).write_urdf(urdf_path, force=True)
        write_json(json_path, report.as_json(), force=True)
    print_report(report)
    print(f"wrote {out / 'robot.urdf'} and {out / 'identification.json'}")
    return 0


def print_report(report: TouchReport) -> None:
    """Held-out places first, then the training places: scatter (and distance error) in mm of the
    nominal and the written URDF (with compliance, its figure beside, labelled not in the URDF);
    then the setting chosen, the noise, the tip and the identifiability in short."""
    # lazy: start-up (the command's run only)
    from brachycal.cli.robot.report import print_identifiability, print_prior

    fit = report.urdf_result.fit
    compliance = bool(report.result.compliant)

    def line(name: str) -> str:
        a, b, c = report.nominal[name], report.identified[name], report.geometry_only[name]
        text = f"  {name:16s} {a.mean_scatter_m * 1e3:8.3f} -> {c.mean_scatter_m * 1e3:6.3f} mm"
        if compliance:
            text += f" (with compliance, not in the URDF: {b.mean_scatter_m * 1e3:6.3f})"
        for (i, j), e in c.distance_error_m.items():
            text += f"   distance {i}-{j}: {a.distance_error_m[(i, j)] * 1e3:6.3f} -> {e * 1e3:6.3f} mm"
        return text

    held = report.held_out
    if held:
        headline = report.headline()
        beside = headline["with_compliance_not_in_urdf_mm"]
        print(
            f"held-out places ({len(held)}): tip scatter, nominal URDF -> written URDF; "
            f"mean {headline['nominal_urdf_mm']:.3f} -> {headline['written_urdf_mm']:.3f} mm"
            + (f" (with compliance, not in the URDF: {beside:.3f})" if beside is not None else "")
        )
        for name in held:
            print(line(name))
    else:
        print("held-out places: none (every place was used to identify; give --train a subset to judge)")
    print(f"training places ({len(report.train)}):")
    for name in report.train:
        print(line(name))
    if report.choice is not None:
        for text in report.choice.summary():
            print(text)
    print(
        f"touch noise {fit.sigma['touch'] * 1e3:.3f} mm; "
        f"tip {', '.join(f'{v * 1e3:.3f}' for v in report.urdf_result.tip)} mm "
        f"in {report.urdf_result.flange} (the written URDF's); {fit.selection.size} corrections free"
    )
    if fit.accuracy is not None:
        print_prior(fit.accuracy)
    print_identifiability(fit.identifiability, fit.joint_names)

"""``brachycal plan excitation SESSION``: extra poses that identify the robot where the session does not.

Light at import (``plan excitation --help`` must not load the calibration): the options here, the
work in :func:`run`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from brachycal.cli.common import (
    add_robot_accuracy_options,
    add_robot_option,
    command_inputs,
    output_file,
    robot_accuracy,
)
from brachycal.cli.option_types import finite_float
from brachycal.cli.plan.options import add_safety_options
from brachycal.errors import InputError

NAME = "plan-excitation"
HELP = "plan extra poses that identify the robot where a recorded session does not"
DESCRIPTION = """\
Identifies the robot on the recorded SESSION (whole chain + robot geometry, the stated accuracy
--robot-accuracy-mm/-deg as the prior, as 'calibrate --solve chain --identify-robot') and chooses
extra poses that lower the predicted RMS landing error most per robot minute: samples of the same
pixels with the arms in other configurations (elbow swivels, torso turns), to append to the
session's samples.csv (extra touches are not offered: a session's touches.csv cannot hold them
yet). Prints the predicted RMS landing error without and with them and the extra minutes, and
writes them to --out (controller joint order, radians and degrees, what each pose is). When they
would improve the prediction by less than its own uncertainty (or 1 %), says that the session is
enough and writes nothing.

example:
  brachycal plan excitation run/built_session --excitation-minutes 5 --robot-accuracy-mm 0.1 \\
      --robot-accuracy-deg 0.01 --out excitation.csv
"""


def add_excitation_minutes_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, when: str) -> None:
    """``--excitation-minutes``: the extra robot time the excitation poses may take (``plan``, ``design``)."""
    # lazy: start-up (the command's run only)
    from brachycal.planning.robot_time import DEFAULT_BUDGET_MINUTES, MAX_BUDGET_MINUTES

    minutes = finite_float(low=0.0, high=MAX_BUDGET_MINUTES, low_open=True, unit="min")
    parser.add_argument(
        "--excitation-minutes",
        type=minutes,
        metavar="MIN",
        default=DEFAULT_BUDGET_MINUTES,
        help=f"{when}: extra robot time for the excitation poses, {minutes.rule} (default {DEFAULT_BUDGET_MINUTES:g})",
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal plan excitation",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("session", metavar="SESSION", help="the recorded session folder")
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="excitation poses to write")
    e = parser.add_argument_group("excitation")
    add_excitation_minutes_option(e, "budget")
    add_robot_accuracy_options(e, "identification", zero=False, note=" (the identification's prior)")
    t = parser.add_argument_group("robot and safety")
    add_robot_option(t)
    add_safety_options(t)
    o = parser.add_argument_group("output")
    o.add_argument("--force", action="store_true", help="replace existing outputs")
    o.add_argument("--quiet", action="store_true", help="no progress output")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Identify, choose, print and (if worth it) write the excitation poses."""
    from brachycal.calibration import calibrate  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.identification import choose_and_identify
    from brachycal.cli.common import load_robot  # lazy: start-up (the command's run only)
    from brachycal.data.session import read_session  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)
    from brachycal.planning import Thresholds  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.planning.excitation import plan_excitation, write_excitation

    thresholds = Thresholds(
        collision_margin_m=args.collision_margin_mm * 1e-3, joint_margin_rad=float(np.radians(args.joint_margin_deg))
    )
    accuracy = robot_accuracy(args)
    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "session")) as outputs:
        staged = outputs.claim(out, label="--out")
        robot = load_robot(args)
        rig = robot.rig
        if not rig.shared_joints and max(len(rig.needle_arm.joints), len(rig.probe_arm.joints)) <= 6:
            raise InputError(
                f"robot {rig.name!r} can reach a sample only one way: no arm with more than 6 axes (no "
                "self-motion) and no joint shared by both arms, so it has no excitation poses to offer"
            )
        session = read_session(args.session, robot)
        initial = calibrate(session, robot, ("scaled_uv",))
        choice, identified = choose_and_identify(session, robot, initial, accuracy)
        plan = plan_excitation(identified, session, robot, args.excitation_minutes, thresholds=thresholds)
        kinds = [c.observation.kind for c in plan.chosen]
        improvement = 1.0 - plan.rms_after_mm / plan.rms_before_mm
        print(
            f"robot identified on {args.session} ({choice.model} image model; prior "
            f"{accuracy.translation_sd_m * 1e3:g} mm / {np.degrees(accuracy.rotation_sd_rad):g}° per joint); "
            f"{plan.candidates} reachable candidate poses scored"
        )
        print(
            f"predicted RMS landing error: session alone {plan.rms_before_mm:.3f} mm; with "
            f"{kinds.count('touch')} touches and {kinds.count('sample')} samples ({plan.minutes:.1f} extra robot "
            f"minutes of {plan.budget_minutes:g}) {plan.rms_after_mm:.3f} mm ({100 * improvement:.1f} % lower; "
            f"the prediction's own uncertainty is {100 * plan.resolution:.1f} %, worth recording from "
            f"{100 * plan.minimum_improvement:.1f} %)"
        )
        if not plan.worth_it:
            outputs.release(out)
            best = 1.0 - plan.best_rms_mm / plan.rms_before_mm
            print(
                f"the session already determines the robot to {plan.rms_before_mm:.3f} mm predicted; no excitation "
                f"poses within {plan.budget_minutes:g} min would improve it by more than {100 * best:.1f} % "
                f"({plan.best_rms_mm:.3f} mm; worth recording from {100 * plan.minimum_improvement:.1f} %): "
                "nothing written"
            )
            return 0
        write_excitation(plan, robot, staged, force=args.force)
    print(f"wrote {out}")
    return 0

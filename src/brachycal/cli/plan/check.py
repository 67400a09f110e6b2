"""``brachycal plan check``: the few poses of a check before each procedure (``brachycal verify``).

Light at import (``plan check --help`` must not load the planner): the options here, the work in
:func:`run`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_quiet_option, command_inputs, output_file, print_next, robot_words
from brachycal.cli.option_types import bounded_int
from brachycal.cli.plan.options import (
    add_grid_options,
    add_imaging_options,
    add_tool_options,
    planner_settings,
    planning_robot,
)
from brachycal.errors import InputError

NAME = "plan-check"
HELP = "plan the few poses of a check before each procedure (brachycal verify)"
DESCRIPTION = """\
Plans the sample grid as 'brachycal plan' does (the same grid, imaging and tool options), then
keeps only --poses of its poses (default 8) for a check before each procedure ('brachycal verify'):
a greedy Bayesian D-optimal pick on the sensitivity of each pose's check residual to the needle
tip, the probe mount (with its image) and the image scale, so that every part of the chain is seen;
ordered to shorten the motion. Writes them as a plan CSV (for 'brachycal session build --plan') and
prints the robot minutes at the paper's 10 s per sample, plus 30 s for each optional single touch
on rtip1 (--touches: probe, the probe's alone, default: it tells a probe remount from an image
change, needle changes showing in the samples; both, the needle's too; none). The default, 8
samples and the probe's touch, takes 1.9 minutes. The documentation (The commands in detail, "Before each procedure")
shows the check end to end.

example:
  brachycal plan check --out check_plan.csv --force
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.planning.check_poses import (  # lazy: start-up (planning's package; only this parser)
        CHECK_POSES_RANGE,
        DEFAULT_CHECK_POSES,
        DEFAULT_TOUCHES,
        TOUCH_CHOICES,
    )
    from brachycal.planning.spec import PlanSpec  # lazy: start-up (only this parser)

    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal plan check",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="plan file to write")
    c = parser.add_argument_group("check")
    count = bounded_int(low=CHECK_POSES_RANGE[0], high=CHECK_POSES_RANGE[1])
    c.add_argument(
        "--poses", type=count, metavar="N", help=f"how many poses, {count.rule} (default {DEFAULT_CHECK_POSES})"
    )
    c.add_argument(
        "--touches",
        choices=list(TOUCH_CHOICES),
        help=f"which tools touch rtip1 once, 30 s each (default {DEFAULT_TOUCHES})",
    )
    defaults = PlanSpec()
    add_grid_options(parser.add_argument_group("grid"), defaults)
    add_imaging_options(parser.add_argument_group("imaging"), defaults)
    add_tool_options(parser.add_argument_group("tools and safety"))
    o = parser.add_argument_group("output")
    o.add_argument("--force", action="store_true", help="replace existing outputs")
    add_quiet_option(o)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Plan the grid, pick the check's poses, print and write them."""
    from brachycal.cli.common import progress_bar  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)
    from brachycal.planning import plan_poses, write_plan  # lazy: start-up (the command's run only)
    from brachycal.planning.check_poses import (  # lazy: start-up (the command's run only)
        DEFAULT_CHECK_POSES,
        DEFAULT_TOUCHES,
        SECONDS_PER_SAMPLE,
        SECONDS_PER_TOUCH,
        nominal_calibration,
        plan_check,
    )

    spec, settings, thresholds = planner_settings(args)  # every option checked before any work
    count = args.poses or DEFAULT_CHECK_POSES
    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs:
        staged = outputs.claim(out, label="--out")
        robot, spec = planning_robot(args, spec)
        with progress_bar(args.points**3, "planning", args.quiet, unit="point") as bar:
            full = plan_poses(
                robot, spec, settings=settings, thresholds=thresholds, speed_scale=args.speed_scale, progress=bar.update
            )
        if len(full.poses) < count:
            raise InputError(
                f"only {len(full.poses)} of {args.points**3} grid points have a verified pose, fewer than the "
                f"{count} the check needs: move or shrink the cube"
            )
        # The robot's tool frames (the result's with --result) and the plan's spacing (--spacing-mm's).
        calibration = nominal_calibration(robot, spec.spacing_m)
        touches = args.touches or DEFAULT_TOUCHES
        check = plan_check(full, robot, calibration, count=count, touches=touches)
        write_plan(check.plan, robot, staged, force=args.force)
    names = ", ".join(p.point.name for p in check.plan.poses)
    print(
        f"check: {count} of the {len(full.poses)} grid poses ({names}), chosen greedily for the largest "
        f"log det of the needle-tip, probe-mount and image-scale information (prior 1 mm / 1 deg / 1 %): "
        f"{check.log_det[-1]:.1f}"
    )
    tools = " and ".join(check.touch_tools) + " on rtip1" if check.touch_tools else "none"
    print(
        f"robot time: {count} samples x {SECONDS_PER_SAMPLE:g} s + {check.motion_s:.0f} s of motion + "
        f"{check.touches} touch{'' if check.touches == 1 else 'es'} x {SECONDS_PER_TOUCH:g} s ({tools}) = "
        f"{check.robot_minutes:.1f} min ({(count * SECONDS_PER_SAMPLE + check.motion_s) / 60:.1f} min without touches)"
    )
    print("wrote " + ", ".join(map(str, outputs.written)))
    touches_option = f" --touches {touches}" if touches != DEFAULT_TOUCHES else ""
    # Before each procedure the lab records a check at these poses, builds it and verifies it.
    print_next(
        f"brachycal session build JOINT_LOG --check --marks MARKS --images IMAGES --plan {out} "
        f"--template SESSION_TOML --out CHECK_SESSION{touches_option}",
        f"brachycal verify {args.result or 'RESULT'} CHECK_SESSION --calibration-session SESSION{robot_words(args)} "
        "--out check_record.json",
        quiet=args.quiet,
    )
    return 0

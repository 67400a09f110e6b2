"""``brachycal plan --verify``: the few poses of a check before each procedure (``brachycal verify``).

Light at import (``plan --help`` must not load the planner): the options here, the work in
:func:`run_check_plan`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import command_inputs
from brachycal.errors import InputError
from brachycal.validate import bounded_int

if TYPE_CHECKING:
    from brachycal.planning import IKSettings, PlanSpec, Thresholds

EPILOG_CHECK = """\
With --verify: plans the sample grid as above, then keeps only --verify-poses of its poses (default
8) for a check before each procedure ('brachycal verify'): a greedy Bayesian D-optimal pick on the
sensitivity of each pose's check residual to the needle tip, the probe mount (with its image) and
the image scale, so that every part of the chain is seen; ordered to shorten the motion. Writes
them as a plan CSV (for 'brachycal session build --plan') and prints the robot minutes at the
paper's 10 s per sample, plus 30 s for each optional single touch on rtip1 (--verify-touches:
probe, the probe's alone, default: it tells a probe remount from an image change, needle changes
showing in the samples; both, the needle's too; none). The default, 8 samples and the probe's
touch, takes 1.9 minutes. For
instance 'brachycal plan --verify --out check_plan.csv' (the README's section "Before each
procedure" shows the check end to end).
"""


def add_check_options(group: argparse._ArgumentGroup) -> None:
    """``--verify``, ``--verify-poses``, ``--verify-touches``."""
    from brachycal.planning.check_poses import CHECK_POSES_RANGE, DEFAULT_CHECK_POSES, DEFAULT_TOUCHES, TOUCH_CHOICES

    group.add_argument(
        "--verify", action="store_true", help="plan the few poses of a pre-procedure check instead (see below)"
    )
    count = bounded_int(low=CHECK_POSES_RANGE[0], high=CHECK_POSES_RANGE[1])
    group.add_argument(
        "--verify-poses",
        type=count,
        metavar="N",
        help=f"with --verify: how many poses, {count.rule} (default {DEFAULT_CHECK_POSES})",
    )
    group.add_argument(
        "--verify-touches",
        choices=list(TOUCH_CHOICES),
        help=f"with --verify: which tools touch rtip1 once, 30 s each (default {DEFAULT_TOUCHES})",
    )


def check_check_options(args: argparse.Namespace) -> None:
    """Refuse options that do not go with (or without) ``--verify``."""
    if not args.verify:
        for option in ("verify_poses", "verify_touches"):
            if getattr(args, option) is not None:
                raise InputError(f"--{option.replace('_', '-')} goes with --verify")
        return
    if args.excitation is not None:
        raise InputError("--verify and --excitation plan different poses: pass one")
    if args.figure:
        raise InputError("--verify writes no figure: do not pass --figure")


def run_check_plan(args: argparse.Namespace, planner: tuple[PlanSpec, IKSettings, Thresholds]) -> int:
    """Plan the grid, pick the check's poses, print and write them (``planner``: the spec, IK
    settings and check thresholds from ``plan``'s options)."""
    from brachycal.cli.common import progress_bar
    from brachycal.cli.plan.grid import planning_robot
    from brachycal.io import OutputSet
    from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
    from brachycal.planning import plan_poses, write_plan
    from brachycal.planning.check_poses import (
        DEFAULT_CHECK_POSES,
        DEFAULT_TOUCHES,
        SECONDS_PER_SAMPLE,
        SECONDS_PER_TOUCH,
        plan_check,
    )

    spec, settings, thresholds = planner
    count = args.verify_poses or DEFAULT_CHECK_POSES
    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs:
        staged = outputs.claim(out, label="--out")
        robot, spec = planning_robot(args, spec)
        with progress_bar(args.points**3, "planning", args.quiet) as bar:
            full = plan_poses(
                robot, spec, settings=settings, thresholds=thresholds, speed_scale=args.speed_scale, progress=bar.update
            )
        if len(full.poses) < count:
            raise InputError(
                f"only {len(full.poses)} of {args.points**3} grid points have a verified pose, fewer than the "
                f"{count} the check needs: move or shrink the cube"
            )
        T_ER_Ntip = robot.tool_transform(NEEDLE_TIP)[1]
        T_EL_Ptip = robot.tool_transform(PROBE_TIP)[1]
        T_Ptip_I = robot.tool_transform(US_IMAGE)[1]
        touches = args.verify_touches or DEFAULT_TOUCHES
        check = plan_check(full, robot, T_ER_Ntip, T_EL_Ptip, T_Ptip_I, spec.spacing_m, count=count, touches=touches)
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
    return 0

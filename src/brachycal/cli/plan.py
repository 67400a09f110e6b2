"""``brachycal plan``: the calibration sample poses, solved with mink and checked with Pinocchio."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np

from brachycal.calibration import read_result
from brachycal.cli.common import add_urdf_option, load_robot, parse_numbers, progress_bar
from brachycal.errors import InputError
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.planning import IKSettings, PlanSpec, RectFOV, SectorFOV, Thresholds, plan_poses
from brachycal.planning.output import infeasible_path, write_infeasible, write_plan
from brachycal.reporting.plan_figure import plot_plan

HELP = "plan the calibration sample poses (a grid of needle-tip targets) with mink IK"
DESCRIPTION = """\
Plans one dual-arm pose per needle-tip target of a grid (default: the paper's 4 x 4 x 4 points
in a 40 mm cube). The cube is aligned with the image: two axes in the image plane (lateral u,
depth v), one along its normal. For each point the right arm puts the needle tip on it with the
needle along the insertion direction, and the left arm puts the probe so that the tip shows at
the planned pixel, inside the field of view. Both arms and the torso are solved together with
mink (joint and velocity limits, collision avoidance with a margin); every pose is then checked
independently with Pinocchio and Coal (tip error < 0.01 mm, needle direction < 0.05 deg, tip
within 0.01 mm of the image plane, inside the field of view, joint margin, clearance). Poses
are ordered to shorten the robot's motion (nearest neighbour + 2-opt), and the motion time at
the vendor's velocity limits is reported against a raster order.

Writes the plan CSV (controller joint order, radians and degrees, expected pixel per pose) and
a figure (grid and image coverage). If any point has no verified pose, the points and reasons
are listed and nothing is written (exit code 2) unless --allow-partial, which writes the plan
and <plan>_infeasible.csv. Tool frames: the URDF's nominal ones, or a calibration's (--result).

example:
  brachycal plan --out plan.csv
  brachycal plan --result result.json --centre-mm 800,100,1050 --edge-mm 30 --out plan.csv
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "plan", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    d = PlanSpec()
    parser.add_argument("--out", required=True, metavar="CSV", help="plan file to write")
    g = parser.add_argument_group("grid")
    g.add_argument("--centre-mm", default="800,100,1050", metavar="X,Y,Z", help="cube centre in base_link (mm)")
    g.add_argument("--edge-mm", type=float, default=40.0, help="cube edge (mm, default 40)")
    g.add_argument("--points", type=int, default=4, help="grid points per axis (default 4: 64 poses)")
    g.add_argument(
        "--insertion",
        default=",".join(f"{x:.6f}" for x in d.insertion_dir),
        metavar="DX,DY,DZ",
        help="needle direction in base_link (default: forward, 35 deg towards the left)",
    )
    i = parser.add_argument_group("imaging")
    i.add_argument("--image-depth", default="1,0,0", metavar="DX,DY,DZ", help="image +v (depth) in base_link")
    i.add_argument("--image-lateral", default="0,0,1", metavar="DX,DY,DZ", help="image +u (lateral) in base_link")
    i.add_argument("--centre-px", default="540,221", metavar="U,V", help="pixel where the cube centre shows")
    i.add_argument("--spacing-mm", metavar="SU,SV", help="pixel spacing (default: the result's, else 0.19,0.19)")
    i.add_argument("--fov", choices=("sector", "rect"), default="sector", help="field of view shape")
    i.add_argument("--sector-apex-px", default="540,0", metavar="U,V", help="sector apex (default 540,0)")
    i.add_argument("--sector-depth-mm", type=float, default=70.0, help="sector depth (default 70)")
    i.add_argument("--sector-angle-deg", type=float, default=120.0, help="sector opening (default 120)")
    i.add_argument("--rect-px", default="0,1079,0,719", metavar="U0,U1,V0,V1", help="rectangle (with --fov rect)")
    t = parser.add_argument_group("tools and safety")
    t.add_argument("--result", metavar="JSON", help="plan with a calibration result's tool frames")
    t.add_argument("--method", default="kabsch", help="which image calibration of --result (default kabsch)")
    add_urdf_option(t)
    t.add_argument("--collision-margin-mm", type=float, default=10.0, help="minimum link clearance (default 10)")
    t.add_argument("--joint-margin-deg", type=float, default=3.0, help="minimum distance to joint limits")
    t.add_argument("--speed-scale", type=float, default=1.0, help="fraction of vendor speed for motion times")
    o = parser.add_argument_group("output")
    o.add_argument("--figure", metavar="PNG", help="figure path (default: next to --out, .png)")
    o.add_argument("--allow-partial", action="store_true", help="write the plan even if some points are infeasible")
    o.add_argument("--force", action="store_true", help="replace existing outputs")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    figure = Path(args.figure) if args.figure else out.with_suffix(".png")
    for path in (out, figure, infeasible_path(out)):
        if path.exists() and not args.force:
            raise InputError("already exists; pass --force to replace it", file=path)
    robot = load_robot(args)
    spacing = np.array([0.19e-3, 0.19e-3])
    if args.result:
        stored = read_result(args.result)
        if args.method not in stored.image:
            raise InputError(f"the result has no method {args.method!r}", file=args.result)
        image = stored.image[args.method]
        robot = stored.software_robot(robot).with_tool_transform(NEEDLE_TIP, stored.T_ER_Ntip)
        robot = robot.with_tool_transform(PROBE_TIP, stored.T_EL_Ptip)
        robot = robot.with_tool_transform(US_IMAGE, image.T_Ptip_I)
        spacing = image.spacing_m
    if args.spacing_mm:
        spacing = parse_numbers(args.spacing_mm, "--spacing-mm", 2) * 1e-3
    if args.fov == "sector":
        fov = SectorFOV(
            tuple(parse_numbers(args.sector_apex_px, "--sector-apex-px", 2)),
            args.sector_depth_mm * 1e-3,
            np.radians(args.sector_angle_deg),
        )
    else:
        u0, u1, v0, v1 = parse_numbers(args.rect_px, "--rect-px", 4)
        fov = RectFOV((u0, u1), (v0, v1))
    spec = PlanSpec(
        cube_centre_m=parse_numbers(args.centre_mm, "--centre-mm", 3) * 1e-3,
        edge_m=args.edge_mm * 1e-3,
        points_per_axis=args.points,
        insertion_dir=parse_numbers(args.insertion, "--insertion", 3),
        image_depth_dir=parse_numbers(args.image_depth, "--image-depth", 3),
        image_lateral_dir=parse_numbers(args.image_lateral, "--image-lateral", 3),
        centre_px=tuple(parse_numbers(args.centre_px, "--centre-px", 2)),
        spacing_m=spacing,
        fov=fov,
    )
    if not 0 < args.speed_scale <= 1:
        raise InputError(f"--speed-scale must be in (0, 1], got {args.speed_scale}")
    margin = args.collision_margin_mm * 1e-3
    settings = IKSettings(collision_margin_m=margin + 2e-3, joint_margin_rad=np.radians(args.joint_margin_deg) + 0.01)
    thresholds = Thresholds(collision_margin_m=margin, joint_margin_rad=np.radians(args.joint_margin_deg))
    n = args.points**3
    with progress_bar(n, "planning", args.quiet) as bar:
        plan = plan_poses(
            robot, spec, settings=settings, thresholds=thresholds, speed_scale=args.speed_scale, progress=bar.update
        )
    _report(plan)
    if plan.infeasible and not args.allow_partial:
        counts = Counter(reason for item in plan.infeasible for reason in item.reasons)
        summary = ", ".join(f"{k}: {v}" for k, v in counts.most_common())
        raise InputError(
            f"{len(plan.infeasible)} of {n} grid points have no verified pose ({summary}); "
            "move or shrink the cube, or pass --allow-partial"
        )
    write_plan(plan, robot, out, force=args.force)
    written = [str(out)]
    if plan.infeasible:
        written.append(str(write_infeasible(plan, infeasible_path(out), force=args.force)))
    written.append(str(plot_plan(plan, figure)))
    print("wrote " + ", ".join(written))
    return 0


def _report(plan) -> None:
    n = len(plan.poses) + len(plan.infeasible)
    print(f"planned {len(plan.poses)} of {n} poses in {plan.solve_time_s:.2f} s")
    for item in plan.infeasible:
        p = item.point
        print(
            f"  infeasible {p.name} at ({', '.join(f'{x * 1e3:.1f}' for x in p.p_base)}) mm, "
            f"pixel ({p.uv_px[0]:.0f}, {p.uv_px[1]:.0f}): {'+'.join(item.reasons)} — {item.detail}"
        )
    if plan.poses:
        checks = [pose.check for pose in plan.poses]
        print(
            f"  worst tip error {max(c.position_error_m for c in checks) * 1e3:.6f} mm, needle direction "
            f"{np.degrees(max(c.direction_error_rad for c in checks)):.6f} deg, image plane "
            f"{max(c.plane_distance_m for c in checks) * 1e3:.6f} mm"
        )
        print(
            f"  smallest clearance {plan.min_clearance_m * 1e3:.1f} mm, smallest joint margin "
            f"{np.degrees(min(c.joint_margin_rad for c in checks)):.1f} deg"
        )
        m = plan.motion_time_s
        print(
            f"  motion at {plan.speed_scale:g} x vendor speed: optimised {m['optimised']:.1f} s, "
            f"serpentine {m['serpentine']:.1f} s, raster {m['raster']:.1f} s"
        )

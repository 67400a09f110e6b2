"""The options ``brachycal plan`` and ``plan check`` share (the grid, the image, the tools and
margins) and what they make: the planner's inputs (:func:`planner_settings`) and the robot to plan
with (:func:`planning_robot`). Light at import: ``plan --help`` loads no planner.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from brachycal.cli.common import add_method_option, add_robot_option, load_robot, method_said
from brachycal.cli.option_types import bounded_int, direction, finite_float, number_list, spacing_mm
from brachycal.errors import InputError
from brachycal.planning.spec import EDGE_RANGE_M, MAX_CENTRE_M, MAX_SECTOR_DEPTH_M, PlanSpec, RectFOV, SectorFOV
from brachycal.validate import MAX_GRID_POINTS, MAX_IMAGE_PX

if TYPE_CHECKING:
    from brachycal.model.robot import Robot
    from brachycal.planning import IKSettings, Thresholds


def _pair(values) -> str:
    """Numbers as an option's text: ``540,221``."""
    return ",".join(f"{float(v):g}" for v in values)


def _mm_pair(values_m) -> str:
    return _pair(float(v) * 1e3 for v in values_m)


def add_grid_options(g: argparse._ArgumentGroup, d: PlanSpec) -> None:
    """``--centre-mm``, ``--edge-mm``, ``--points``, ``--insertion`` (defaults: ``d``'s)."""
    centre = number_list(count=3, low=-MAX_CENTRE_M * 1e3, high=MAX_CENTRE_M * 1e3, unit="mm")
    g.add_argument(
        "--centre-mm",
        type=centre,
        metavar="X,Y,Z",
        help=f"cube centre in the robot's base frame, {centre.rule} (default: the robot's workspace; "
        f"sda10f {_mm_pair(d.cube_centre_m)})",
    )
    edge = finite_float(low=EDGE_RANGE_M[0] * 1e3, high=EDGE_RANGE_M[1] * 1e3, unit="mm")
    edge_mm = f"{d.edge_m * 1e3:g}"
    g.add_argument("--edge-mm", type=edge, default=edge_mm, help=f"cube edge, {edge.rule} (default {edge_mm})")
    points = bounded_int(low=2, high=MAX_GRID_POINTS)
    n = d.points_per_axis
    g.add_argument(
        "--points", type=points, default=n, help=f"grid points per axis, {points.rule} (default {n}: {n**3} poses)"
    )
    g.add_argument(
        "--insertion",
        type=direction,
        metavar="DX,DY,DZ",
        help="needle direction in the robot's base frame (default: the robot's workspace; sda10f: forward, "
        "35 deg towards the left)",
    )


def add_imaging_options(i: argparse._ArgumentGroup, d: PlanSpec) -> None:
    """Where the cube shows in the image and the field of view (defaults: ``d``'s)."""
    sector_fov, rect_fov = SectorFOV(), RectFOV()
    i.add_argument(
        "--image-depth",
        type=direction,
        metavar="DX,DY,DZ",
        help="image +v (depth) in the robot's base frame (default: the robot's workspace; "
        f"sda10f {_pair(d.image_depth_dir)})",
    )
    i.add_argument(
        "--image-lateral",
        type=direction,
        metavar="DX,DY,DZ",
        help="image +u (lateral) in the robot's base frame, not parallel to --image-depth (default: the robot's "
        f"workspace; sda10f {_pair(d.image_lateral_dir)})",
    )
    pixel = number_list(count=2, low=-0.5, high=MAX_IMAGE_PX, unit="px")
    i.add_argument(
        "--centre-px",
        type=pixel,
        default=_pair(d.centre_px),
        metavar="U,V",
        help=f"pixel where the cube centre shows, {pixel.rule} (default {_pair(d.centre_px)})",
    )
    i.add_argument(
        "--spacing-mm",
        type=spacing_mm,
        metavar="SU,SV",
        help=f"pixel spacing, {spacing_mm.rule} (default: the result's, else {_mm_pair(d.spacing_m)})",
    )
    i.add_argument("--fov", choices=("sector", "rect"), default="sector", help="field of view shape")
    apex = number_list(count=2, low=-MAX_IMAGE_PX, high=MAX_IMAGE_PX, unit="px")
    i.add_argument(
        "--sector-apex-px",
        type=apex,
        default=_pair(sector_fov.apex_px),
        metavar="U,V",
        help=f"sector apex, {apex.rule} (default {_pair(sector_fov.apex_px)})",
    )
    depth = finite_float(low=0.0, high=MAX_SECTOR_DEPTH_M * 1e3, low_open=True, unit="mm")
    depth_mm, angle_deg = sector_fov.radius_m * 1e3, float(np.degrees(sector_fov.angle_rad))
    i.add_argument(
        "--sector-depth-mm", type=depth, default=depth_mm, help=f"sector depth, {depth.rule} (default {depth_mm:g})"
    )
    angle = finite_float(low=0.0, high=180.0, low_open=True, unit="deg")
    i.add_argument("--sector-angle-deg", type=angle, help=f"sector opening, {angle.rule} (default {angle_deg:g})")
    rect = number_list(count=4, low=-0.5, high=MAX_IMAGE_PX, unit="px")
    i.add_argument(
        "--rect-px",
        type=rect,
        default=_pair((*rect_fov.u_range_px, *rect_fov.v_range_px)),
        metavar="U0,U1,V0,V1",
        help=f"rectangle (with --fov rect), U0 < U1 and V0 < V1, {rect.rule}",
    )


def add_tool_options(t: argparse._ArgumentGroup) -> None:
    """``--result``, ``--method``, ``--robot``/``--urdf``, the safety margins and ``--speed-scale``."""
    t.add_argument("--result", metavar="JSON", help="plan with a calibration result's tool frames")
    add_method_option(t, "--result")
    add_robot_option(t)
    add_safety_options(t)
    speed = finite_float(low=0.0, high=1.0, low_open=True)
    t.add_argument(
        "--speed-scale",
        type=speed,
        default=1.0,
        help=f"fraction of vendor speed for motion times, {speed.rule} (default 1)",
    )


def add_safety_options(t: argparse._ArgumentGroup) -> None:
    """``--collision-margin-mm`` and ``--joint-margin-deg``: what every planned pose keeps."""
    from brachycal.planning.pose_checks import (  # lazy: start-up (the options' ranges; planning's package)
        MAX_COLLISION_MARGIN_M,
        MAX_JOINT_MARGIN_RAD,
        MIN_COLLISION_MARGIN_M,
        MIN_JOINT_MARGIN_RAD,
    )

    clearance = finite_float(low=MIN_COLLISION_MARGIN_M * 1e3, high=MAX_COLLISION_MARGIN_M * 1e3, unit="mm")
    t.add_argument(
        "--collision-margin-mm",
        type=clearance,
        default=10.0,
        help=f"minimum link clearance, {clearance.rule} (default 10)",
    )
    joint = finite_float(low=np.degrees(MIN_JOINT_MARGIN_RAD), high=np.degrees(MAX_JOINT_MARGIN_RAD), unit="deg")
    t.add_argument(
        "--joint-margin-deg",
        type=joint,
        default=3.0,
        help=f"minimum distance to joint limits, {joint.rule} (default 3; the floor keeps encoder noise from "
        "reading a planned pose past a limit)",
    )


def planning_robot(args: argparse.Namespace, spec: PlanSpec) -> tuple[Robot, PlanSpec]:
    """The robot to plan with (``--robot``) and ``spec``: with ``--result``, the robot carries the
    calibration's tool frames and corrections, and its image spacing unless ``--spacing-mm`` gave one."""
    robot = load_robot(args)
    if not args.result:
        return robot, spec
    from brachycal.calibration import read_result  # lazy: start-up (the command's run only)

    stored = read_result(args.result)
    calibration = stored.calibration(args.method)
    robot = calibration.robot(stored.software_robot(robot))
    print(f"planning with method: {method_said(stored, args.method)}")
    if args.spacing_mm is None:
        spec = replace(spec, spacing_m=calibration.spacing_m)
    return robot, spec


def planner_settings(args: argparse.Namespace) -> tuple[PlanSpec, IKSettings, Thresholds]:
    """The planner's inputs from the options (each already range-checked by argparse), with the
    checks that involve two options; the spacing is --spacing-mm's or the scanner's nominal
    (:data:`~brachycal.imaging.DEFAULT_SPACING_M`; a --result's replaces it once the result is read).

    Raises:
        InputError: naming the options that do not go together.
    """
    from brachycal.imaging import DEFAULT_SPACING_M  # lazy: start-up (the command's run only)
    from brachycal.planning import IKSettings, Thresholds  # lazy: start-up (the command's run only)

    # Unset geometry is the robot's workspace (the SDA10F's are PlanSpec's defaults).
    if getattr(args, "robot", None) is None:
        workspace = PlanSpec()
    else:
        from brachycal.model.description import load_description  # lazy: start-up (the command's run only)

        workspace = PlanSpec.for_workspace(load_description(args.robot).workspace)
    centre_m = workspace.cube_centre_m if args.centre_mm is None else args.centre_mm * 1e-3
    insertion = workspace.insertion_dir if args.insertion is None else args.insertion
    image_depth = workspace.image_depth_dir if args.image_depth is None else args.image_depth
    image_lateral = workspace.image_lateral_dir if args.image_lateral is None else args.image_lateral
    if np.linalg.norm(np.cross(image_depth, image_lateral)) < 1e-6:
        raise InputError("--image-depth and --image-lateral are parallel; the image plane needs two directions")
    if args.fov == "sector":
        fov: SectorFOV | RectFOV = SectorFOV(
            tuple(args.sector_apex_px),
            args.sector_depth_mm * 1e-3,
            # Unset: SectorFOV's own default, exactly (not a round trip through degrees).
            SectorFOV().angle_rad if args.sector_angle_deg is None else np.radians(args.sector_angle_deg),
        )
    else:
        u0, u1, v0, v1 = args.rect_px
        if not (u0 < u1 and v0 < v1):
            raise InputError(f"--rect-px must be U0,U1,V0,V1 with U0 < U1 and V0 < V1, got {u0:g},{u1:g},{v0:g},{v1:g}")
        fov = RectFOV((u0, u1), (v0, v1))
    spacing_m = np.array(DEFAULT_SPACING_M) if args.spacing_mm is None else args.spacing_mm * 1e-3
    spec = PlanSpec(
        cube_centre_m=centre_m,
        edge_m=args.edge_mm * 1e-3,
        points_per_axis=args.points,
        insertion_dir=insertion,
        image_depth_dir=image_depth,
        image_lateral_dir=image_lateral,
        centre_px=tuple(args.centre_px),
        spacing_m=spacing_m,
        fov=fov,
    )
    margin = args.collision_margin_mm * 1e-3
    joint_margin = np.radians(args.joint_margin_deg)
    # The IK keeps a little more than the check demands, so its poses pass the check.
    settings = IKSettings(collision_margin_m=margin + 2e-3, joint_margin_rad=joint_margin + 0.01)
    thresholds = Thresholds(collision_margin_m=margin, joint_margin_rad=joint_margin)
    return spec, settings, thresholds

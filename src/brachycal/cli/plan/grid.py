"""``brachycal plan``: the calibration sample poses, solved with mink and checked with Pinocchio."""

from __future__ import annotations

import argparse
import contextlib
import pickle
import subprocess
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brachycal.cli.common import (
    add_method_option,
    add_robot_option,
    command_inputs,
    load_robot,
    output_file,
    progress_bar,
)
from brachycal.errors import InputError
from brachycal.planning.spec import EDGE_RANGE_M, MAX_CENTRE_M, MAX_SECTOR_DEPTH_M, PlanSpec, RectFOV, SectorFOV
from brachycal.validate import (
    MAX_GRID_POINTS,
    MAX_IMAGE_PX,
    bounded_int,
    direction,
    finite_float,
    number_list,
    spacing_mm,
)

if TYPE_CHECKING:
    from brachycal.io import OutputSet
    from brachycal.model.robot import Robot
    from brachycal.planning import IKSettings, Plan, Thresholds

HELP = "plan the calibration sample poses (a grid of needle-tip targets) with mink IK"
DESCRIPTION = """\
Plans one dual-arm pose per needle-tip target of a grid (default: the paper's 4 x 4 x 4 points
in a 40 mm cube). The cube is aligned with the image: two axes in the image plane (lateral u,
depth v), one along its normal. For each point the needle arm (the SDA10F's right) puts the needle
tip on it with the needle along the insertion direction, and the probe arm puts the probe so that
the tip shows at the planned pixel, inside the field of view. Both arms (and the SDA10F's torso)
are solved together with
mink (joint and velocity limits, collision avoidance with a margin); every pose is then checked
independently with Pinocchio and Coal (tip error < 0.01 mm, needle direction < 0.05 deg, tip
within 0.01 mm of the image plane, inside the field of view, joint margin, clearance). Poses
are ordered to shorten the robot's motion (nearest neighbour + 2-opt), and the motion time at
the vendor's velocity limits is reported against a raster order.

Writes the plan CSV (controller joint order, radians and degrees, expected pixel per pose) and
a figure (grid and image coverage). If any point has no verified pose, the points and reasons
are listed and nothing is written (exit code 2) unless --allow-partial, which writes the plan
and <plan>_infeasible.csv. Tool frames: the URDF's nominal ones, or a calibration's (--result).
The robot (--robot, default sda10f) gives the arms, the ready stance the robot starts from, the
collision pairs, the controller's joint order and the default cube centre and directions (its
workspace; docs/robots.md).

example:
  brachycal plan --out plan.csv
  brachycal plan --robot baxter --out baxter_plan.csv
  brachycal plan --result result.json --centre-mm 800,100,1050 --edge-mm 30 --out plan_30mm.csv
"""


def _pair(values) -> str:
    """Numbers as an option's text: ``540,221``."""
    return ",".join(f"{float(v):g}" for v in values)


def _mm_pair(values_m) -> str:
    return _pair(float(v) * 1e3 for v in values_m)


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "plan", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="plan file to write")
    defaults = PlanSpec()  # the planner's defaults are the options' defaults (one home)
    _grid_options(parser.add_argument_group("grid"), defaults)
    _imaging_options(parser.add_argument_group("imaging"), defaults)
    _tool_options(parser.add_argument_group("tools and safety"))
    o = parser.add_argument_group("output")
    o.add_argument("--figure", metavar="PNG", help="figure path (default: --out with .png; never --out itself)")
    o.add_argument("--allow-partial", action="store_true", help="write the plan even if some points are infeasible")
    o.add_argument("--force", action="store_true", help="replace existing outputs")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    from brachycal.cli.plan.excitation import EPILOG, add_excitation_options

    add_excitation_options(parser.add_argument_group("excitation poses (robot identification)"))
    from brachycal.cli.plan.check import EPILOG_CHECK, add_check_options

    add_check_options(parser.add_argument_group("check before each procedure (brachycal verify)"))
    parser.epilog = EPILOG + "\n" + EPILOG_CHECK
    parser.set_defaults(run=run)


def _grid_options(g: argparse._ArgumentGroup, d: PlanSpec) -> None:
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


def _imaging_options(i: argparse._ArgumentGroup, d: PlanSpec) -> None:
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


def _tool_options(t: argparse._ArgumentGroup) -> None:
    from brachycal.planning.pose_checks import (
        MAX_COLLISION_MARGIN_M,
        MAX_JOINT_MARGIN_RAD,
        MIN_COLLISION_MARGIN_M,
        MIN_JOINT_MARGIN_RAD,
    )

    t.add_argument("--result", metavar="JSON", help="plan with a calibration result's tool frames")
    add_method_option(t, "--result")
    add_robot_option(t)
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
    speed = finite_float(low=0.0, high=1.0, low_open=True)
    t.add_argument(
        "--speed-scale",
        type=speed,
        default=1.0,
        help=f"fraction of vendor speed for motion times, {speed.rule} (default 1)",
    )


def run(args: argparse.Namespace) -> int:
    from brachycal.cli.plan.check import check_check_options, run_check_plan
    from brachycal.cli.plan.excitation import check_excitation_options, run_excitation
    from brachycal.io import OutputSet

    check_check_options(args)
    if args.verify:
        return run_check_plan(args, _settings(args))
    check_excitation_options(args)
    if args.excitation is not None:
        return run_excitation(args)
    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs, _FigureProcess() as drawer:
        _run(args, outputs, drawer)
    print("wrote " + ", ".join(map(str, outputs.written)))
    return 0


def planning_robot(args: argparse.Namespace, spec: PlanSpec) -> tuple[Robot, PlanSpec]:
    """The robot to plan with (``--robot``) and ``spec``: with ``--result``, the robot carries the
    calibration's tool frames and corrections, and its image spacing unless ``--spacing-mm`` gave one."""
    robot = load_robot(args)
    if not args.result:
        return robot, spec
    from brachycal.calibration import read_result
    from brachycal.export import calibrated_robot

    stored = read_result(args.result)
    image = stored.image[stored.method(args.method)]
    robot = calibrated_robot(stored.software_robot(robot), stored.T_ER_Ntip, stored.T_EL_Ptip, image)
    if args.spacing_mm is None:
        spec = replace(spec, spacing_m=image.spacing_m)
    return robot, spec


def _run(args: argparse.Namespace, outputs: OutputSet, drawer: _FigureProcess) -> None:
    """Plan and write the plan, its figure (drawn by ``drawer``) and (with infeasible points) their
    list into ``outputs``."""
    from brachycal.planning import infeasible_path, plan_poses, write_infeasible, write_plan
    from brachycal.reporting import plan_text

    spec, settings, thresholds = _settings(args)  # every option checked before any work
    out = Path(args.out)
    figure = Path(args.figure) if args.figure else out.with_suffix(".png")
    staged_plan = outputs.claim(out, label="--out")
    staged_infeasible = outputs.claim(infeasible_path(out), label="the list of infeasible points")
    staged_figure = outputs.claim(figure, label="--figure" if args.figure else "the figure (--out with .png)")
    drawer.start()  # loads matplotlib in a second process while this one plans
    robot, spec = planning_robot(args, spec)
    n = args.points**3
    with progress_bar(n, "planning", args.quiet) as bar:
        plan = plan_poses(
            robot, spec, settings=settings, thresholds=thresholds, speed_scale=args.speed_scale, progress=bar.update
        )
    print(plan_text(plan))
    if plan.infeasible and not args.allow_partial:
        counts = Counter(reason for item in plan.infeasible for reason in item.reasons)
        summary = ", ".join(f"{k}: {v}" for k, v in counts.most_common())
        raise InputError(
            f"{len(plan.infeasible)} of {n} grid points have no verified pose ({summary}); "
            "move or shrink the cube, or pass --allow-partial"
        )
    drawer.draw(plan, staged_figure)  # while the plan is written here
    write_plan(plan, robot, staged_plan, force=args.force)
    if plan.infeasible:
        write_infeasible(plan, staged_infeasible, force=args.force)
    else:
        outputs.release(infeasible_path(out))
    drawer.wait(figure)


class _FigureProcess:
    """The plan's figure, drawn by a second process that loads matplotlib while this one plans.

    Importing matplotlib with its 3D axes (~0.4 s) and drawing the figure (~0.5 s) would add to the
    planning (~1 s with its imports); on two cores the second process takes them off the command's
    path. The figure is drawn by :func:`brachycal.reporting.plot_plan`, as before, into the staging
    path of the command's :class:`~brachycal.io.OutputSet` (committed with the plan or not at
    all). The process (this Python, ``-c``; the plan goes to it pickled on its stdin, the outcome
    comes back on its stdout) ignores Ctrl-C, which the command handles by ending it, and prints
    nothing: its failure is raised here. Where it cannot start or dies, the figure is drawn here.
    """

    def __init__(self) -> None:
        self._process: subprocess.Popen[bytes] | None = None
        self._job: tuple[Plan, Path] | None = None

    def __enter__(self) -> _FigureProcess:
        return self

    def start(self) -> None:
        import signal
        import threading

        in_main_thread = threading.current_thread() is threading.main_thread()
        # Ctrl-C reaches both processes; the child inherits "ignore" from here, so only this one reacts.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main_thread else None
        try:
            # A spawned process, not a fork: a forked copy of this command (its signal handlers, its
            # locks, pytest's state when run in-process) could hang where a fresh interpreter cannot.
            self._process = subprocess.Popen(
                [sys.executable, "-c", "from brachycal.cli.plan.grid import _draw_in_child; _draw_in_child()"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
            )
        except OSError:  # no process to be had (limits): draw here instead
            self._process = None
        finally:
            if in_main_thread:
                signal.signal(signal.SIGINT, previous)

    def draw(self, plan: Plan, staged_figure: Path) -> None:
        """Start drawing ``plan`` into ``staged_figure``; :meth:`wait` for it."""
        self._job = (plan, staged_figure)
        if self._process is not None and self._process.stdin is not None:
            try:
                with self._process.stdin as pipe:
                    pickle.dump(self._job, pipe)
            except OSError:  # it died (BrokenPipeError): wait() draws here
                pass

    def wait(self, figure: Path) -> None:
        """Until the figure is drawn (``figure``: its destination, for an error).

        Raises:
            OSError: writing the figure failed (as drawing it here would).
            OutputError: drawing it failed otherwise.
        """
        import warnings

        from brachycal.errors import OutputError

        assert self._job is not None, "draw() first"
        reply = b""
        if self._process is not None and self._process.stdout is not None:
            with self._process.stdout as pipe:
                reply = pipe.read()
        if not reply:  # no process, or it could not start brachycal or died: draw here, as before
            from brachycal.reporting import plot_plan  # (only then: matplotlib takes ~0.4 s to load)

            plot_plan(*self._job)
            return
        outcome, warned = pickle.loads(reply)
        for message in warned:  # its warnings, shown as this command shows its own
            warnings.warn(message, UserWarning, stacklevel=2)
        if isinstance(outcome, OSError):
            raise outcome
        if outcome is not None:
            raise OutputError(f"could not draw the figure: {outcome}", file=figure)

    def __exit__(self, *exc: object) -> None:
        """End the drawing process: at once if the command failed, else once it has exited."""
        process = self._process
        if process is None:
            return
        if exc[0] is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=10)  # it has answered (wait() returned): it is exiting
        if process.poll() is None:
            process.terminate()  # SIGTERM: it removes its half-written file and exits, quietly
        process.wait()
        for pipe in (process.stdin, process.stdout):
            if pipe is not None:
                pipe.close()


def _draw_in_child() -> None:
    """The drawing process: import matplotlib now, then draw the plan sent on stdin.

    Writes ``(None or the error, [warning messages])`` pickled on stdout; prints nothing else.
    SIGTERM (the command failed or was stopped) becomes SystemExit, so that a half-written figure
    file is removed on the way out.
    """
    import signal
    import warnings

    inbox, outbox = sys.stdin.buffer, sys.stdout.buffer
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the command's: it ends this process
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(143))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            import select

            from brachycal.reporting import plot_plan
            from brachycal.reporting.plan_plot import warm_up_plan_figure

            try:
                waiting = not select.select([inbox], [], [], 0)[0]
            except (OSError, ValueError):  # Windows' select takes sockets only: no warm-up there
                waiting = False
            if waiting:  # the planner still runs: draw a stand-in first, the plan's figure then draws warm
                warm_up_plan_figure()
            plot_plan(*pickle.load(inbox))
            outcome: object = None
        except (Exception, SystemExit) as exc:
            outcome = exc if isinstance(exc, OSError) else f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    with contextlib.suppress(OSError):  # the command is gone: nothing to tell
        pickle.dump((outcome, [" ".join(str(w.message).split()) for w in caught]), outbox)
        outbox.flush()


def _settings(args: argparse.Namespace) -> tuple[PlanSpec, IKSettings, Thresholds]:
    """The planner's inputs from the options (each already range-checked by argparse), with the
    checks that involve two options; the spacing is --spacing-mm's or the scanner's nominal
    (:data:`~brachycal.imaging.DEFAULT_SPACING_M`; a --result's replaces it once the result is read).

    Raises:
        InputError: naming the options that do not go together.
    """
    from brachycal.imaging import DEFAULT_SPACING_M
    from brachycal.planning import IKSettings, Thresholds

    # Unset geometry is the robot's workspace (the SDA10F's are PlanSpec's defaults).
    if getattr(args, "robot", None) is None:
        workspace = PlanSpec()
    else:
        from brachycal.model.description import load_description

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

"""``brachycal plan``: the calibration sample poses, solved with mink and checked with Pinocchio
(the default sub-command of ``brachycal plan``; ``plan check`` and ``plan excitation`` are beside it)."""

from __future__ import annotations

import argparse
import contextlib
import pickle
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_quiet_option, command_inputs, output_file, print_next, progress_bar, robot_words
from brachycal.cli.plan.options import (
    add_grid_options,
    add_imaging_options,
    add_tool_options,
    planner_settings,
    planning_robot,
)
from brachycal.errors import InputError
from brachycal.planning.spec import PlanSpec

if TYPE_CHECKING:
    from brachycal.io import OutputSet
    from brachycal.planning import Plan

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
EPILOG = """\
sub-commands (each with its own --help):
  brachycal plan check --out check_plan.csv
      the few poses of a check before each procedure ('brachycal verify')
  brachycal plan excitation SESSION --out excitation.csv
      extra poses that identify the robot where a recorded session does not
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "plan", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="CSV", help="plan file to write")
    defaults = PlanSpec()  # the planner's defaults are the options' defaults (one home)
    add_grid_options(parser.add_argument_group("grid"), defaults)
    add_imaging_options(parser.add_argument_group("imaging"), defaults)
    add_tool_options(parser.add_argument_group("tools and safety"))
    o = parser.add_argument_group("output")
    o.add_argument("--figure", metavar="PNG", help="figure path (default: --out with .png; never --out itself)")
    o.add_argument("--allow-partial", action="store_true", help="write the plan even if some points are infeasible")
    o.add_argument("--force", action="store_true", help="replace existing outputs")
    add_quiet_option(o)
    parser.epilog = EPILOG
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet  # lazy: start-up (the output writer is loaded by the run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs, _FigureProcess() as drawer:
        _run(args, outputs, drawer)
    print("wrote " + ", ".join(map(str, outputs.written)))
    # The lab drives the robot through the plan's poses and records; the recording becomes a session.
    print_next(
        "brachycal session template DIR",
        f"brachycal session build JOINT_LOG --marks DIR/marks.csv --images DIR/images.csv "
        f"--template DIR/session.toml --plan {args.out}{robot_words(args)} --out SESSION",
        quiet=args.quiet,
    )
    return 0


def _run(args: argparse.Namespace, outputs: OutputSet, drawer: _FigureProcess) -> None:
    """Plan and write the plan, its figure (drawn by ``drawer``) and (with infeasible points) their
    list into ``outputs``."""
    # lazy: start-up (the command's run only)
    from brachycal.planning import infeasible_path, plan_poses, write_infeasible, write_plan
    from brachycal.reporting import plan_text  # lazy: start-up (the command's run only)

    spec, settings, thresholds = planner_settings(args)  # every option checked before any work
    out = Path(args.out)
    figure = Path(args.figure) if args.figure else out.with_suffix(".png")
    staged_plan = outputs.claim(out, label="--out")
    staged_infeasible = outputs.claim(infeasible_path(out), label="the list of infeasible points")
    staged_figure = outputs.claim(figure, label="--figure" if args.figure else "the figure (--out with .png)")
    drawer.start()  # loads matplotlib in a second process while this one plans
    robot, spec = planning_robot(args, spec)
    n = args.points**3
    with progress_bar(n, "planning", args.quiet, unit="point") as bar:
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
    path. The figure is drawn by :func:`brachycal.reporting.plot_plan` into the staging
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
        import signal  # lazy: start-up (the command's run only)
        import threading  # lazy: start-up (the command's run only)

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
        import warnings  # lazy: start-up (the command's run only)

        from brachycal.errors import OutputError  # lazy: start-up (the command's run only)

        assert self._job is not None, "draw() first"
        reply = b""
        if self._process is not None and self._process.stdout is not None:
            with self._process.stdout as pipe:
                reply = pipe.read()
        if not reply:  # no process, or it could not start brachycal or died: draw here
            # lazy: start-up (the command's run only)
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
    import signal  # lazy: start-up (the command's run only)
    import warnings  # lazy: start-up (the command's run only)

    inbox, outbox = sys.stdin.buffer, sys.stdout.buffer
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the command's: it ends this process
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(143))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        try:
            import select  # lazy: start-up (the command's run only)

            from brachycal.reporting import plot_plan  # lazy: start-up (the command's run only)
            from brachycal.reporting.plan_plot import warm_up_plan_figure  # lazy: start-up (the command's run only)

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

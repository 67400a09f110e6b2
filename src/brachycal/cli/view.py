"""``brachycal view``: the robot, a plan or a calibrated session in 3D, in the browser."""

from __future__ import annotations

import argparse
import time

from brachycal.cli.common import add_method_option, add_robot_option, load_robot, method_said
from brachycal.cli.option_types import bounded_int
from brachycal.errors import InputError

HELP = "an interactive 3D view in the browser: the robot, a plan, or a calibrated session"
DESCRIPTION = """\
Serves an interactive 3D view (viser, WebGL) and prints its address; open it in a browser, step
through the poses with the slider, Ctrl-C to stop. What it shows:
  (nothing given)          the robot at its ready stance, its tool frames and image plane
  --plan PLAN.csv          the robot at each planned pose (brachycal plan)
  --session DIR            the robot at each image sample of a session
  RESULT --session DIR     also, per sample, the needle tip through the needle arm and through
                           the probe arm and the image, joined by their residual, and the sample
                           cube; if DIR is a twin's session (brachycal demo: it has truth.json),
                           targets and where the needle landed
The page's side panel has the legend (what each colour is), the calibration shown, the frame and
units, the chosen sample's residual (mm), and a checkbox per layer. The first view shows the
whole scene, robot included. Everything in the robot's base frame. --host 0.0.0.0 serves it to
other machines.

example:
  brachycal demo
  brachycal view demo_output/result.json --session demo_output/session
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "view", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("result", metavar="RESULT", nargs="?", help="calibration result (JSON); needs --session")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--session", metavar="DIR", help="session folder: the robot at its image samples")
    source.add_argument("--plan", metavar="CSV", help="plan (brachycal plan): the robot at its poses")
    add_method_option(parser, "RESULT")
    targets = bounded_int(low=1, high=1000)
    parser.add_argument(
        "--targets", type=targets, default=50, help=f"targets shown for a twin's session, {targets.rule} (default 50)"
    )
    parser.add_argument("--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine)")
    port = bounded_int(low=0, high=65535)
    parser.add_argument(
        "--port", type=port, default=8080, help=f"TCP port, {port.rule}; 0 picks a free one (default 8080)"
    )
    add_robot_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.reporting.viewer import Viewer  # lazy: start-up (the command's run only)

    content, said = _content(args)
    try:
        viewer = Viewer(content, host=args.host, port=args.port)
    except OSError as exc:  # the port is taken, or the host is not this machine's
        raise InputError(f"cannot serve on {args.host}:{args.port}: {exc.strerror or exc}") from None
    print(f"brachycal view: {viewer.url}  ({len(content.poses_q)} poses; Ctrl-C to stop)", flush=True)
    if said is not None:
        print(f"shown method: {said}", flush=True)
    try:
        while True:
            time.sleep(3600)
    finally:
        viewer.close()


def _content(args: argparse.Namespace):  # -> (ViewContent (imported lazily), the method in words or None)
    from brachycal.imaging.pixels import DEFAULT_IMAGE_SIZE_PX  # lazy: start-up (the command's run only)
    from brachycal.reporting.viewer import calibration_content, poses_content  # lazy: start-up (the command's run only)

    robot = load_robot(args)
    if args.result is not None:
        if args.session is None:
            raise InputError("RESULT needs --session DIR: the samples to show it on")
        from pathlib import Path  # lazy: start-up (the command's run only)

        from brachycal.calibration import read_result  # lazy: start-up (the command's run only)
        from brachycal.data import read_session  # lazy: start-up (the command's run only)

        stored = read_result(args.result)
        method = stored.method(args.method)  # the robot is checked with the result's corrections
        session = read_session(args.session, robot)
        twin = None
        if (Path(args.session) / "truth.json").is_file():
            from brachycal.simulation.twin_files import read_twin  # lazy: start-up (the command's run only)

            twin = read_twin(args.session, robot)
        shown = calibration_content(robot, stored, session, method, twin=twin, n_targets=args.targets)
        return shown, method_said(stored, args.method)
    if args.method is not None:
        raise InputError("--method needs a RESULT")
    if args.session is not None:
        from brachycal.data import read_session  # lazy: start-up (the command's run only)

        session = read_session(args.session, robot)
        size = (int(session.size_px[0]), int(session.size_px[1]))
        return poses_content(
            robot, session.samples_q, session.sample_ids, image_size_px=size, spacing_m=session.spacing_m
        ), None
    if args.plan is not None:
        from brachycal.data.session_build import read_plan  # lazy: start-up (the command's run only)

        plan = read_plan(args.plan, robot)
        return poses_content(robot, plan.q, plan.names, image_size_px=DEFAULT_IMAGE_SIZE_PX), None
    return poses_content(robot, robot.rig.ready[None], ["ready"], image_size_px=DEFAULT_IMAGE_SIZE_PX), None

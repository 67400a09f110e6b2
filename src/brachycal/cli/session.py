"""``brachycal session build``: a lab's recording (joint log, marks, frames) → a session folder."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_quiet_option, add_robot_option, command_inputs, load_robot, print_next, robot_words
from brachycal.cli.option_types import finite_float, number_list, spacing_mm
from brachycal.errors import InputError
from brachycal.validate import MAX_IMAGE_PX

HELP = "session folders: build one from a lab's recording (joint log, marks, frames), or write blank templates"
TEMPLATE_HELP = (
    "write blank templates of a lab's session.toml, marks.csv and images.csv, with a README (--check: a check's)"
)
TEMPLATE_DESCRIPTION = """\
Writes into DIR the blanks a lab fills in for its own session:

  session.toml  the set-up's pixel spacing, frame size and top-model tip, a comment on every key;
                the values are empty lists to fill in (an empty one is refused, naming its key)
  marks.csv     the header time,kind,tool,name: add one row per mark
  images.csv    the header time,u_px,v_px: add one row per captured frame
  README.txt    every file and column explained, with an example row

then `brachycal session build JOINT_LOG --marks DIR/marks.csv --images DIR/images.csv
--template DIR/session.toml --out SESSION` turns the joint log and these into a session folder.
--check: the blanks of a check before a procedure (the same files; the README says what a check
records: the frames at the poses of `brachycal plan check` and its single touches), for
`brachycal session build --check`. All files are written or none; existing files are replaced
only with --force.

examples:
  brachycal session template my_session
  brachycal session template --check my_check --force
"""
BUILD_HELP = (
    "build a session folder from a joint log, the operator's marks and the annotated frames (--check: a check session)"
)
BUILD_DESCRIPTION = """\
Turns what a lab records during a calibration into a session folder (brachycal-session/1) that
`brachycal calibrate` reads:

  LOG          the joint states: CSV (time,<joints>) or a ROS 1/2 bag (sensor_msgs/JointState);
               the joints are the --robot's (default the SDA10F's 15)
  --marks      marks.csv: time,kind,tool,name, one row per moment the operator marked:
               touch,<top_model|needle|probe>,<rtip1|rtip2> or axes,<needle|probe>,<p1|p2|p3>;
               trial numbers follow the order in time (or --marks-topic: the same as
               std_msgs/String 'kind,tool,name' messages on a topic of the bag)
  --images     images.csv: time,u_px,v_px[,sample], one row per captured frame with the needle
               tip annotated (empty u_px,v_px: not annotated, skipped and reported); with
               --markups, time[,sample] only and the tips from a 3D Slicer .mrk.json
  --plan       the plan CSV of `brachycal plan`: frames without a sample name are paired with
               the nearest planned pose, and the planned samples without a frame are reported

The joints at each mark and frame are the mean of the log over a still window around its time
(--still-window-s, default {still_window_s:g} s). The robot must be still over it: every joint
slower than --max-speed-rad-s (default {max_speed_rad_s:g} rad/s), judged by the slope of its
readings over spans of --speed-span-s (default {speed_span_s:g} s). A mark or annotated frame
taken while the robot moved, or whose window is not inside the log, is refused, naming it and
its time. session.toml comes from --template, each value replaced by --spacing-mm, --size-px,
--top-model-tip-mm; without a template all three are needed.

--check builds a check session (for `brachycal verify`) from a check recording instead: the
frames at the poses of `brachycal plan check` (--plan its CSV) and the single touches it planned
(--touches, as plan check's: probe by default, each must be marked; none: --marks may be left
out). A check recording has no top-model touches and no axes moves: they are refused, naming the
mark (a calibration's recording is built without --check), as is a check of fewer than 3 frames.
It writes session.toml, samples.csv, touches.csv and the build report.

SESSION receives session.toml, touches.csv, axes.csv, samples.csv and the build report
(build_report.json, build_report.csv: every mark and frame, its still window, readings, joint
spread and speed, skipped frames and why, planned samples missing), all or nothing; existing
files are replaced only with --force.

examples:
  brachycal demo --recording --out run     (the twin's recording: run/recording)
  brachycal session build run/recording/joint_log.csv --marks run/recording/marks.csv \\
      --images run/recording/images.csv --plan run/recording/plan.csv \\
      --template run/recording/session.toml --out run/built_session
  brachycal session build run/recording/bag --marks-topic /brachycal/marks --images run/recording/images.csv \\
      --plan run/recording/plan.csv --spacing-mm 0.19,0.19 --size-px 1080,720 --top-model-tip-mm 0,0,150 \\
      --out run/session_from_bag
  brachycal calibrate run/built_session --out result.json --report report
  brachycal demo --recording --check --out run --force   (also the twin's check recordings)
  brachycal session build run/check_recording/joint_log.csv --check --marks run/check_recording/marks.csv \\
      --images run/check_recording/images.csv --plan run/check_recording/plan.csv \\
      --template run/check_recording/session.toml --out run/check_session --force
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.data.formats.bags import DEFAULT_TOPIC  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.data.recording import MAX_SPEED_RAD_S, SPEED_SPAN_S, STILL_WINDOW_S

    # lazy: start-up (the command's run only)
    from brachycal.data.session_build import MAX_STILL_SPEED_RAD_S, MAX_WINDOW_S
    from brachycal.planning.check_poses import DEFAULT_TOUCHES, TOUCH_CHOICES  # lazy: start-up (only this parser)

    parser = sub.add_parser("session", help=HELP, description=HELP)
    actions = parser.add_subparsers(title="actions", metavar="ACTION", required=True)
    description = BUILD_DESCRIPTION.format(
        still_window_s=STILL_WINDOW_S, max_speed_rad_s=MAX_SPEED_RAD_S, speed_span_s=SPEED_SPAN_S
    )
    build = actions.add_parser(
        "build", help=BUILD_HELP, description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    build.add_argument("log", metavar="LOG", help="joint log: CSV file, ROS 1 .bag or ROS 2 bag folder")
    marks = build.add_mutually_exclusive_group()
    marks.add_argument("--marks", metavar="CSV", help="marks.csv (time,kind,tool,name)")
    marks.add_argument("--marks-topic", metavar="TOPIC", help="read the marks from this std_msgs/String topic of LOG")
    build.add_argument(
        "--joints-topic",
        default=DEFAULT_TOPIC,
        metavar="TOPIC",
        help=f"the sensor_msgs/JointState topic of a bag (default {DEFAULT_TOPIC})",
    )
    build.add_argument(
        "--check",
        action="store_true",
        help="build a check session (for brachycal verify) from a check recording: the frames at the poses of "
        "'brachycal plan check' and single touches of rtip1 (no top-model touches, no axes moves)",
    )
    build.add_argument(
        "--touches",
        choices=list(TOUCH_CHOICES),
        help=f"with --check: which tools' touches of rtip1 the check planned, as 'plan check --touches' "
        f"(default {DEFAULT_TOUCHES}); each must be marked",
    )
    build.add_argument("--images", required=True, metavar="CSV", help="images.csv (time,u_px,v_px[,sample])")
    build.add_argument(
        "--markups", metavar="MRK_JSON", help="3D Slicer markups: one control point per row of --images, in order"
    )
    build.add_argument(
        "--markups-spacing-mm",
        type=spacing_mm,
        metavar="SU,SV",
        help="pixel spacing of the frames as loaded in Slicer, mm/px (default: the session's; 1,1 for plain images)",
    )
    build.add_argument("--plan", metavar="CSV", help="the plan CSV of `brachycal plan`")
    build.add_argument("--template", metavar="TOML", help="a session.toml to start from")
    build.add_argument("--spacing-mm", type=spacing_mm, metavar="SU,SV", help=f"pixel spacing, {spacing_mm.rule}")
    size = number_list(count=2, kind=int, low=1, high=MAX_IMAGE_PX)
    build.add_argument("--size-px", type=size, metavar="W,H", help=f"image width and height, {size.rule} px")
    tip = number_list(count=3, low=-2000.0, high=2000.0, unit="mm")
    build.add_argument(
        "--top-model-tip-mm",
        type=tip,
        metavar="X,Y,Z",
        help=f"top-model tip on the needle arm's flange (the SDA10F's right), {tip.rule}",
    )
    window = finite_float(low=0.0, high=MAX_WINDOW_S, low_open=True, unit="s")
    build.add_argument(
        "--still-window-s",
        type=window,
        default=STILL_WINDOW_S,
        metavar="S",
        help=f"still window around each mark and frame, {window.rule} (default {STILL_WINDOW_S:g})",
    )
    build.add_argument(
        "--speed-span-s",
        type=window,
        default=SPEED_SPAN_S,
        metavar="S",
        help=f"span of each joint-speed estimate, at most the still window (default {SPEED_SPAN_S:g})",
    )
    speed = finite_float(low=0.0, high=MAX_STILL_SPEED_RAD_S, low_open=True, unit="rad/s")
    build.add_argument(
        "--max-speed-rad-s",
        type=speed,
        default=MAX_SPEED_RAD_S,
        metavar="V",
        help=f"largest joint speed of a still robot, {speed.rule} (default {MAX_SPEED_RAD_S:g})",
    )
    build.add_argument(
        "--lag-s",
        type=finite_float(unit="s"),
        default=0.0,
        metavar="L",
        help="clock lag of the joint log behind the frames (brachycal temporal's lag_s): each frame's time t in "
        "--images becomes t + L on the log's clock before its pose is taken (default 0)",
    )
    build.add_argument(
        "--lag-sd-s",
        type=finite_float(low=0.0, unit="s"),
        default=0.0,
        metavar="SD",
        help="the lag's SD: warn about frames whose still window fails within 2 SD of the lag (default 0: no check)",
    )
    add_robot_option(build)
    build.add_argument("--out", required=True, metavar="SESSION", help="session folder to write (created if needed)")
    build.add_argument("--force", action="store_true", help="replace the files of an existing session in SESSION")
    add_quiet_option(build, "next: line")
    build.set_defaults(run=run_build)
    template = actions.add_parser(
        "template",
        help=TEMPLATE_HELP,
        description=TEMPLATE_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    template.add_argument("folder", metavar="DIR", help="folder to write the templates into (created if needed)")
    template.add_argument(
        "--check",
        action="store_true",
        help="the blanks of a check recording (before a procedure: brachycal verify) instead of a calibration's",
    )
    template.add_argument("--force", action="store_true", help="replace existing template files in DIR")
    add_quiet_option(template, "next: lines")
    template.set_defaults(run=run_template)


def run_template(args: argparse.Namespace) -> int:
    # lazy: start-up (the command's run only)
    from brachycal.data.session_template import TEMPLATE_FILES, write_session_template
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    folder = Path(args.folder)
    with OutputSet(force=args.force) as outputs:
        for name in TEMPLATE_FILES:
            outputs.claim(folder / name, make_parents=True, label="DIR")
        write_session_template(folder, force=args.force, outputs=outputs, check=args.check)
    print(f"wrote {folder}: {', '.join(TEMPLATE_FILES)}")
    if args.quiet:
        return 0
    marks, images, toml = folder / "marks.csv", folder / "images.csv", folder / "session.toml"
    if args.check:
        print(
            f"next: fill in {toml} (the calibration's), record the check at the poses of "
            f"'brachycal plan check --out CHECK_PLAN', add the rows (see {folder / 'README.txt'}), then"
        )
        print(
            f"  brachycal session build JOINT_LOG --check --marks {marks} --images {images} --plan CHECK_PLAN "
            f"--template {toml} --out CHECK_SESSION"
        )
        return 0
    print(f"next: fill in {toml}, record, add the rows (see {folder / 'README.txt'}), then")
    print(f"  brachycal session build JOINT_LOG --marks {marks} --images {images} --template {toml} --out SESSION")
    return 0


def run_build(args: argparse.Namespace) -> int:
    from brachycal.data.session import CHECK_FILES  # lazy: start-up (the command's run only)
    from brachycal.data.session import FILES as SESSION_FILES  # lazy: start-up (the command's run only)
    from brachycal.data.session_build import (  # lazy: start-up (the command's run only)
        REPORT_FILES,
        StillSettings,
        build_session_from_files,
        session_settings,
        write_build,
    )
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)
    from brachycal.planning.check_poses import DEFAULT_TOUCHES, touch_choice  # lazy: start-up (the command's run only)

    out = Path(args.out)
    if args.touches is not None and not args.check:
        raise InputError("--touches says which touches a check planned: give --check too")
    if args.speed_span_s > args.still_window_s:
        raise InputError(
            f"--speed-span-s {args.speed_span_s:g} s is longer than --still-window-s {args.still_window_s:g} s: "
            "the speed is judged inside the window"
        )
    check = touch_choice(args.touches or DEFAULT_TOUCHES) if args.check else None
    if check and args.marks is None and args.marks_topic is None:
        raise InputError(
            "give the check's marks (--marks or --marks-topic): it planned touches of rtip1 by "
            f"{' and '.join(f'the {tool}' for tool in check)} "
            "(a check planned without touches builds with --touches none)"
        )
    files = (*CHECK_FILES, *REPORT_FILES) if args.check else (*SESSION_FILES, *REPORT_FILES)
    still = StillSettings(args.still_window_s, args.speed_span_s, args.max_speed_rad_s)
    with OutputSet(
        force=args.force, inputs=command_inputs(args, "log", "marks", "images", "plan", "template", "markups")
    ) as outputs:
        for name in files:
            outputs.claim(out / name, make_parents=True, label="--out")
        settings = session_settings(
            args.template, spacing_mm=args.spacing_mm, size_px=args.size_px, top_model_tip_mm=args.top_model_tip_mm
        )
        robot = load_robot(args)
        build = build_session_from_files(
            args.log,
            robot=robot,
            images=args.images,
            marks=args.marks,
            marks_topic=args.marks_topic,
            joints_topic=args.joints_topic,
            markups=args.markups,
            markups_spacing_mm=args.markups_spacing_mm,
            plan=args.plan,
            settings=settings,
            still=still,
            lag_s=args.lag_s,
            lag_sd_s=args.lag_sd_s,
            check=check,
        )
        write_build(build, out, force=args.force, outputs=outputs)
    print(build.report.summary())
    print(f"\nwrote {out}{' (a check session)' if args.check else ''}: {', '.join(files)}")
    if args.check:
        print_next(
            f"brachycal verify RESULT {out} --calibration-session SESSION{robot_words(args)} --out check.json",
            quiet=args.quiet,
        )
    else:
        print_next(f"brachycal calibrate {out}{robot_words(args)} --out result.json", quiet=args.quiet)
    return 0

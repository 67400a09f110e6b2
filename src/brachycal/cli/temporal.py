"""``brachycal temporal``: the lag between ultrasound frames and tracker readings (or joint states)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from brachycal.cli.common import add_quiet_option, add_robot_option, command_inputs, load_robot, output_file, print_next
from brachycal.cli.option_types import finite_float

if TYPE_CHECKING:
    from brachycal.calibration.temporal import TemporalResult

HELP = "temporal calibration: lag of the tracker (or joint log) behind the ultrasound frames"
DESCRIPTION = """\
Estimates how much the pose stream's timestamps lag the ultrasound frames' from a recording of the
flat bottom of a water tank while the probe moves up and down (PLUS's temporal calibration): the
bottom's line in each frame against the probe's position along its main motion axis, aligned by
normalised cross-correlation.

Sign (PLUS's TrackerLagSec): a positive lag means the pose stream's timestamps are late; a frame
stamped t on the video clock was taken at t + lag on the pose stream's clock. Pass the lag to
'brachycal session build --lag-s' or 'brachycal fk --lag-s'.

routes:
  PLUS files: VIDEO.mha and TRACKER.mha (ProbeToTracker and ReferenceToTracker per item; the
    probe's position in the reference frame is used). --config reads the clip rectangle and
    MaximumMovingLagSec of a PLUS device set's vtkPlusTemporalCalibrationAlgo element.
  robot: VIDEO.mha with --joints LOG (the joint log on the robot's clock) and --robot; the
    position of --frame (default us_image) in base_link by forward kinematics.

On the bundled water-tank pair (`brachycal examples examples`), made with a lag of 137 ms:

example:
  brachycal temporal examples/temporal/tank_video.mha examples/temporal/tank_tracker.mha --out tank_lag.json

On PLUS's public test data (PlusToolkit/PlusLibData TestImages/):
  brachycal temporal WaterTankBottomTranslationVideoBuffer.igs.mha \\
      WaterTankBottomTranslationTrackerBuffer.igs.mha --out lag.json
"""


def _clip(text: str) -> tuple[int, int, int, int]:
    try:
        values = tuple(int(v) for v in text.replace(",", " ").split())
    except ValueError:
        values = ()
    if len(values) != 4 or min(values) < 0 or values[2] < 2 or values[3] < 2:
        raise argparse.ArgumentTypeError(f"expected 'U,V,WIDTH,HEIGHT' (whole pixels, size >= 2), got {text!r}")
    return values[0], values[1], values[2], values[3]


#: A positive, finite number of seconds.
_SECONDS = finite_float(low=0.0, low_open=True, unit="s")


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "temporal", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("video", metavar="VIDEO", help="B-mode sequence of the tank bottom (.mha, with Timestamp)")
    parser.add_argument("tracker", metavar="TRACKER", nargs="?", help="PLUS tracker sequence (.mha)")
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument("--config", metavar="XML", help="PLUS device set (clip rectangle, search range)")
    parser.add_argument("--probe", default="ProbeToTracker", help="probe transform name (default ProbeToTracker)")
    parser.add_argument(
        "--reference", default="ReferenceToTracker", help="reference transform name (default ReferenceToTracker)"
    )
    parser.add_argument("--joints", metavar="LOG", help="joint log on the robot's clock (robot route)")
    parser.add_argument("--frame", default="us_image", help="robot frame whose position is used (default us_image)")
    parser.add_argument("--topic", help="JointState topic in a bag")
    add_robot_option(parser, any_arm=True)
    parser.add_argument(
        "--clip",
        type=_clip,
        metavar="U,V,W,H",
        help="line search rectangle in PLUS's MF image pixels (origin u, v, size)",
    )
    parser.add_argument(
        "--max-lag-s",
        type=_SECONDS,
        metavar="S",
        help=f"search range ±S seconds, {_SECONDS.rule} (default 0.5, PLUS's)",
    )
    parser.add_argument(
        "--resolution-s",
        type=_SECONDS,
        default=0.001,
        metavar="S",
        help=f"search step, {_SECONDS.rule} (default 0.001)",
    )
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(parser, "next: line")
    parser.set_defaults(run=run)


def _robot_route(args: argparse.Namespace) -> TemporalResult:
    import numpy as np  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.temporal import DEFAULT_MAX_LAG_S, lag_from_signals
    from brachycal.data import read_joint_log  # lazy: start-up (the command's run only)
    from brachycal.data.formats.metaimage import read_image_sequence  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.imaging.tank_line import find_tank_line  # lazy: start-up (the command's run only)

    robot = load_robot(args, any_arm=True)
    if args.frame not in robot.frame_names:
        raise InputError(f"--frame: no frame {args.frame!r} in the robot", file=robot.source)
    log = read_joint_log(args.joints, robot, topic=args.topic)
    sequence = read_image_sequence(args.video)
    if np.isnan(sequence.timestamps_s).any():
        k = int(np.argmax(np.isnan(sequence.timestamps_s)))
        raise InputError("frame has no Timestamp", file=args.video, row=k, row_label="frame", column="Timestamp")
    origin, size = ((args.clip[0], args.clip[1]), (args.clip[2], args.clip[3])) if args.clip else (None, None)
    try:
        line = find_tank_line(sequence.pixels, clip_origin=origin, clip_size=size)
    except InputError as exc:
        raise InputError(str(exc), file=args.video) from None
    positions = robot.fk(args.frame, log.q)[:, :3, 3]
    return lag_from_signals(
        sequence.timestamps_s,
        line,
        log.time,
        positions,
        max_lag_s=args.max_lag_s or DEFAULT_MAX_LAG_S,
        resolution_s=args.resolution_s,
        names=("video", "joint log"),
        sources=(args.video, args.joints),
    )


def run(args: argparse.Namespace) -> int:
    from brachycal.calibration.temporal import lag_from_plus_files  # lazy: start-up (the command's run only)
    from brachycal.data.formats.metaimage import MF_FRAME_TEXT  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, sha256_file, write_json  # lazy: start-up (the command's run only)

    if (args.tracker is None) == (args.joints is None):
        raise InputError("give either TRACKER (PLUS route) or --joints LOG (robot route), not both or neither")
    if args.joints is not None and args.config is not None:
        raise InputError("--config applies to the PLUS route (TRACKER), not to --joints")
    with OutputSet(force=args.force, inputs=command_inputs(args, "video", "tracker", "config", "joints")) as outputs:
        staged = outputs.claim(args.out, label="--out")
        if args.joints is None:
            result = lag_from_plus_files(
                args.video,
                args.tracker,
                config=args.config,
                probe=args.probe,
                reference=args.reference,
                max_lag_s=args.max_lag_s,
                resolution_s=args.resolution_s,
                clip=args.clip,
            )
            inputs = [args.video, args.tracker] + ([args.config] if args.config else [])
        else:
            result = _robot_route(args)
            inputs = [args.video, args.joints]
        estimate = result.estimate
        line = result.line
        skipped = [{"frame": k, "reason": line.reasons[k]} for k in range(len(line)) if not bool(line.detected[k])]
        write_json(
            staged,
            {
                "format": "brachycal-temporal/1",
                "route": "plus" if args.joints is None else "robot",
                "sign": "lag_s > 0: the pose stream's timestamps are late; video time t is pose time t + lag_s",
                "pixel_frame": MF_FRAME_TEXT,
                **estimate.as_dict(),
                "search": {
                    "max_lag_s": round(float(-estimate.lags_s[0]), 9),
                    "resolution_s": args.resolution_s,
                },
                "motion": {
                    "axis": [float(v) for v in result.axis],
                    "swing_mm": result.swing_m * 1e3,
                    "swing_px": result.swing_px,
                },
                "frames": {"total": len(line), "with_line": int(line.detected.sum()), "skipped": skipped},
                "inputs": {str(p): sha256_file(p) for p in inputs},
            },
        )
    print(
        f"lag of the {'tracker' if args.joints is None else 'joint log'} behind the video: "
        f"{estimate.lag_s * 1e3:+.1f} ± {estimate.sd_s * 1e3:.1f} ms (1 SD), correlation {estimate.correlation:.3f}"
    )
    print(
        f"  {int(line.detected.sum())} of {len(line)} frames with the tank bottom; probe swing "
        f"{result.swing_m * 1e3:.1f} mm, line swing {result.swing_px:.0f} px"
    )
    print(f"  pixels: {MF_FRAME_TEXT}")
    print(f"wrote {args.out}")
    print_next(
        f"brachycal session build JOINT_LOG --marks marks.csv --images images.csv --template session.toml "
        f"--lag-s {estimate.lag_s:.4f} --out SESSION",
        quiet=args.quiet,
    )
    return 0

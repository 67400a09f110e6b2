"""``brachycal pivot``: pivot calibration of a tracked tool from a pose list."""

from __future__ import annotations

import argparse

from brachycal.cli.common import add_quiet_option, command_inputs, output_file

HELP = "pivot calibration: tool tip and pivot point from poses rotating about a fixed tip"
DESCRIPTION = """\
Estimates the tip of a tool in its own (marker or flange) frame and the fixed pivot point in the
reference frame from poses of the tool rotating about its tip.

POSES is a CSV pose list: a header, then one row-major 4x4 homogeneous matrix per row
(m00,m01,...,m33), optionally after a first key column (e.g. timestamp_ns). Results are in the
units of the poses (--units records which); a tip found beyond 3 m or within 3 mm of the tool's
origin is refused, as poses in the other unit. Residuals are given per axis (RMS over all 3N
coordinates, as SciKit-Surgery reports) and in 3D (RMS of the N distances).

methods: algebraic (linear least squares, Yaniv 2015) or robust (soft-L1 loss, flags outliers).

example:
  brachycal pivot examples/pivot/pointer_pivot.csv --units mm --out pivot.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.calibration.labels import PIVOT_METHODS  # lazy: start-up (the command's run only)
    from brachycal.calibration.labels import POSE_UNITS as UNITS  # lazy: start-up (the command's run only)

    parser = sub.add_parser(
        "pivot", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("poses", metavar="POSES", help="CSV pose list")
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument("--method", choices=tuple(PIVOT_METHODS), default="algebraic")
    parser.add_argument("--units", choices=UNITS, default="m", help="units of the poses' translations (default m)")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(parser, "report (only the file written)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.calibration import calibrate_pivot_files, write_pivot  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "poses")) as outputs:
        staged = outputs.claim(args.out, label="--out")
        calibration = calibrate_pivot_files(args.poses, args.method, args.units)
        write_pivot(calibration, staged, force=args.force)
    if args.quiet:
        print(f"wrote {args.out}")
        return 0
    result, u = calibration.result, calibration.units
    fmt = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
    print(
        f"pivot calibration ({result.method}) of {len(calibration.pose_names)} poses, {int(result.inliers.sum())} used"
    )
    print(f"  tip in tool frame      {fmt(result.p_marker_tip)} {u}")
    print(f"  pivot in reference     {fmt(result.p_ref_pivot)} {u}")
    print(f"  residual RMS           {result.rms_per_axis:.3f} {u} per axis, {result.rms_3d:.3f} {u} in 3D")
    print(
        f"  predicted SD (3D)      tip {result.tip_sd:.3f} {u}, pivot {result.pivot_sd:.3f} {u} "
        f"(rotation spread {result.rotation_spread_deg:.1f} deg about the two least-covered axes)"
    )
    print(f"wrote {args.out}")
    return 0

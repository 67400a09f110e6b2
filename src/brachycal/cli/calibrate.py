"""``brachycal calibrate``: the paper's calibration of a session, Tables I and II, result file."""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from brachycal.calibration import METHODS, calibrate, write_result
from brachycal.calibration.chain_report import calibrate_chain
from brachycal.cli.common import add_urdf_option, load_robot, progress_bar
from brachycal.data.session import read_session
from brachycal.errors import InputError
from brachycal.reporting import chain_summary, table_i, table_ii
from brachycal.reporting.html_report import write_report

HELP = "calibrate a session: tool tips, tool rotations, image-to-probe; prints Tables I and II"
DESCRIPTION = """\
Runs the mechanism-image fusion calibration on a session folder (format brachycal-session/1:
session.toml, touches.csv, axes.csv, samples.csv): reference tips with the top-model, the needle
and probe tips (Table I, validated at rtip2), the tool rotations from three points, and the
image-to-probe transform by ICP, Kabsch, Horn ("Landmark"), a similarity fit and a fit with
separate u/v pixel spacings, each evaluated by leave-one-out cross-validation (Table II).

With --method chain, the whole chain is also solved as one robust least-squares problem over
all the data (touches, axes moves, images), the image model (rigid, similarity, scaled u/v, or
speed of sound) chosen by cross-validation, with 95% intervals and the predicted landing error
over the sample poses and the image; the result then carries the chain's transforms.

The result (brachycal-result/1, JSON, metres) is written atomically to --out and never replaces
an existing file without --force.

example:
  brachycal calibrate examples/session --out result.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "calibrate", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("session", metavar="SESSION", help="session folder")
    parser.add_argument("--out", required=True, metavar="JSON", help="result file to write")
    parser.add_argument(
        "--methods",
        default=",".join(METHODS),
        metavar="A,B",
        help=f"registration methods (default all: {','.join(METHODS)})",
    )
    parser.add_argument(
        "--method",
        choices=("sequential", "chain"),
        default="sequential",
        help="sequential: the paper's steps (default); chain: one least-squares problem over all data, "
        "image model chosen by cross-validation, with uncertainty",
    )
    parser.add_argument(
        "--joint-offsets",
        action="store_true",
        help="with --method chain: also estimate the joint zero offsets this session identifies",
    )
    parser.add_argument(
        "--bootstrap",
        type=int,
        default=0,
        metavar="N",
        help="with --method chain: N bootstrap refits for percentile intervals (default 0)",
    )
    add_urdf_option(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--report", metavar="DIR", help="also write a self-contained HTML report (DIR/report.html)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise InputError(f"unknown method(s) {', '.join(unknown) or '(none)'}; choose from {', '.join(METHODS)}")
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("already exists; pass --force to replace it", file=out)
    robot = load_robot(args)
    session = read_session(args.session, robot)
    result = calibrate(session, robot, methods)
    chain = None
    if args.method == "chain":
        if args.bootstrap < 0:
            raise InputError("--bootstrap must be 0 or more")
        with progress_bar(args.bootstrap, "bootstrap", args.quiet or not args.bootstrap) as bar:
            chain = calibrate_chain(
                session,
                robot,
                result,
                bootstrap_replicates=args.bootstrap,
                joint_offsets=args.joint_offsets,
                progress=bar.update,
            )
    print(table_i(result))
    print()
    print(table_ii(result, chain.loocv if chain else None))
    if chain is not None:
        print()
        print(chain_summary(chain, session.sample_ids))
    urdf_sha = hashlib.sha256(robot.urdf_xml.encode()).hexdigest()
    write_result(result, out, force=args.force, robot_source=robot.source, robot_sha256=urdf_sha, chain=chain)
    if args.report:
        report = write_report(args.report, result, session, robot, str(args.session), chain)
        print(f"report: {report}")
    print(f"\nwrote {out}")
    return 0

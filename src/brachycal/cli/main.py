"""The ``brachycal`` command: one sub-command per job, one-line errors with exit code 2."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from brachycal import __version__
from brachycal.cli import calibrate, demo, design, export, fk, locate, model, nwire, pivot, plan, study
from brachycal.errors import InputError

DESCRIPTION = """\
brachycal calibrates an ultrasound-guided dual-arm robot (Yaskawa SDA10F) for prostate
brachytherapy: the needle tip on the right flange, the probe tip on the left flange and the
ultrasound image on the probe. Units: metres and radians in files, unless a column name says
otherwise (u_px, mae_mm).

start here:
  brachycal demo                      calibrate the bundled example (a digital twin)
  brachycal model                     joints, limits and tool frames of the robot model
  brachycal fk LOG --frames needle_tip,probe_tip --out poses.csv
                                      tool poses from a joint log (CSV or ROS bag)
  brachycal plan --out plan.csv        plan the 4x4x4 calibration sample poses
  brachycal calibrate SESSION --out result.json
                                      calibrate a session folder (Tables I and II)
  brachycal locate RESULT JOINTS --uv U,V
                                      where an image pixel is in base_link
  brachycal export RESULT --out DIR   calibrated URDF, Slicer/ITK, PLUS and ROS files
  brachycal pivot POSES.csv --out pivot.json
                                      pivot calibration of a tracked tool
  brachycal nwire CONFIG FRAMES --out nwire.json
                                      N-wire phantom calibration of a tracked probe (PLUS files)
  brachycal study --out DIR           how many samples? truth error vs LOO on the twin
  brachycal design --out DIR          which sample design gives most accuracy per robot minute
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="brachycal", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"brachycal {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for module in (demo, model, fk, plan, calibrate, locate, export, pivot, nwire, study, design):
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except InputError as exc:
        print(f"brachycal: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("brachycal: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())

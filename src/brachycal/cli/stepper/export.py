"""``brachycal stepper export``: a stepper Image → Probe result as PLUS and Slicer/ITK files."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_quiet_option, command_inputs

NAME = "stepper-export"
HELP = "export a stepper Image -> Probe result: PLUS CoordinateDefinitions, 3D Slicer/ITK transforms"
DESCRIPTION = """\
Writes into DIR: ImageToProbe.tfm (pixels -> mm, the chosen model as PLUS writes it: its third
column the image normal times the mean pixel size) and PhantomToStepperHome.tfm (the phantom's
registration, the template at home), 3D Slicer and ITK transform files in millimetres, and
PlusCoordinateDefinitions.xml (a PLUS <CoordinateDefinitions> element with Image->Probe and
Phantom->StepperHome). The Image->Probe belongs with stepper poses built along the axes the result
records (its comment says which): a result of --recorded-poses with PLUS's poses as recorded.

example:
  brachycal stepper export stepper_image.json --out stepper_exports
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal stepper export",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("result", metavar="RESULT", help="`brachycal stepper image` result (JSON)")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder to write")
    parser.add_argument("--force", action="store_true", help="replace existing files")
    add_quiet_option(parser, "line per file (one line says how many were written where)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.stepper_probe import read_stepper_image
    from brachycal.export import STEPPER_EXPORT_FILES, write_stepper_exports  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "result")) as outputs:
        for name in STEPPER_EXPORT_FILES:
            outputs.claim(Path(args.out) / name, make_parents=True)
        result = read_stepper_image(args.result)
        write_stepper_exports(result, args.out, force=args.force, outputs=outputs)
    if args.quiet:
        print(f"wrote {len(outputs.written)} files to {args.out}")
        return 0
    for path in outputs.written:
        print(f"wrote {path}")
    return 0

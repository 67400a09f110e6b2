"""``brachycal stepper`` (``stepper calibrate``): a brachytherapy stepper's axes, pixel spacing and
centre of rotation from PLUS's single-axis recordings."""

from __future__ import annotations

import argparse

from brachycal.cli.common import command_inputs, output_file

HELP = "calibrate a TRUS probe's brachytherapy stepper: axes, pixel spacing, centre of rotation"
DESCRIPTION = """\
Calibrates a transrectal probe on a brachytherapy stepper (PLUS's iCal set-up) from three B-mode
recordings of an N-wire phantom whose wires run along the probe, each made while one stepper axis
moves: the probe turned (ROTATION), the probe translated (PROBE_TRANSLATION), the template
translated (TEMPLATE_TRANSLATION). The frames are segmented as `brachycal nwire segment` does and
each frame's encoder values (ProbePosition, ProbeRotation, TemplatePosition, mm and degrees) read
from the recording. As PLUS's stepper calibration, from them:

  - the pixel spacing (mm/px along u and v), from the known distances between wires;
  - the centre of rotation (where the probe's rotation axis crosses the image, px);
  - the rotation axis's tilt, only when the rotation was recorded at two probe positions or more
    (a rotation at one depth cannot give it: the result says so), and the rotation encoder's scale;
  - the probe and the template translation axes (PLUS's form x, y, 1, relative to the phantom's
    wires; their sum, the template axis relative to the probe axis, does not depend on the wires),
    from each still wire's dot against the encoder's position.

Each value comes with its standard deviation. A recording without the encoder fields, whose axis
does not move, whose rotation covers less than 10 degrees, whose translation covers less than
5 mm, or in which another axis moves, is refused, naming the file and the field. Writes JSON
(format brachycal-stepper/1), only if the whole calibration succeeds.

The first example runs on the bundled twin of a stepper (`brachycal examples examples` copies it;
examples/stepper/truth.json holds its truth), the second on PLUS's own iCal recordings.

examples:
  brachycal stepper calibrate examples/stepper/twin_ProbeRotation.igs.mha \\
      examples/stepper/twin_ProbeTranslation.igs.mha examples/stepper/twin_TemplateTranslation.igs.mha \\
      --config examples/stepper/PlusDeviceSet_twin_iCal.xml --out stepper.json
  brachycal stepper calibrate $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_ProbeRotation.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_ProbeTranslation.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_TemplateTranslation.igs.mha \\
      --config $BRACHYCAL_REFERENCE/plus_trus_stepper/PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml \\
      --out stepper.json
"""
EPILOG = """\
sub-commands (each with its own --help):
  brachycal stepper [calibrate] ROTATION.mha PROBE_TRANSLATION.mha TEMPLATE_TRANSLATION.mha \\
      --config DEVICE_SET.xml --out stepper.json
      this page: the stepper's axes, pixel spacing and centre of rotation (the default)
  brachycal stepper image ROTATION.mha CAL.mha VAL.mha --config DEVICE_SET.xml --out stepper_image.json
      Image -> Probe of the probe on the stepper, from random stepper motion (N-wire phantom)
  brachycal stepper template RESULT --config DEVICE_SET.xml --hole D4 --depth 100 --probe-position -50
      where a needle through a template hole lands in the image (u, v px) at a stepper pose
  brachycal stepper export RESULT --out DIR
      a stepper result as PLUS CoordinateDefinitions and 3D Slicer/ITK transforms
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "stepper",
        help=HELP,
        description=DESCRIPTION,
        epilog=EPILOG,
        prog="brachycal stepper calibrate",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("rotation", metavar="ROTATION.mha", help="B-mode sequence: the probe turned by the stepper")
    parser.add_argument(
        "probe_translation", metavar="PROBE_TRANSLATION.mha", help="B-mode sequence: the probe translated"
    )
    parser.add_argument(
        "template_translation", metavar="TEMPLATE_TRANSLATION.mha", help="B-mode sequence: the template translated"
    )
    parser.add_argument(
        "--config", required=True, metavar="DEVICE_SET.xml", help="PLUS device set (PhantomDefinition, Segmentation)"
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.stepper_file import calibrate_stepper_files, summary_lines, write_stepper
    from brachycal.cli.common import progress_bar  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    with OutputSet(
        force=args.force,
        inputs=command_inputs(args, "rotation", "probe_translation", "template_translation", "config"),
    ) as outputs:
        staged = outputs.claim(args.out, label="--out")
        result = calibrate_stepper_files(
            args.config,
            args.rotation,
            args.probe_translation,
            args.template_translation,
            progress=lambda name, frames: progress_bar(frames, name, args.quiet, unit="frame"),
        )
        write_stepper(result, staged)
    for line in summary_lines(result):
        print(line)
    print(f"wrote {args.out}")
    return 0

"""``brachycal stepper template``: where a planned needle (template hole, depth) lands in the image."""

from __future__ import annotations

import argparse

from brachycal.cli.option_types import finite_float

# What a stepper and its needles can reach: a brachytherapy needle is 200 mm long, a stepper's
# strokes are well under 300 mm either way, and its rotation encoder reads less than a turn.
# A value beyond these is a typo or a unit slip, not a pose.
DEPTH_MM = finite_float(low=0.0, high=300.0, unit="mm")
TRANSLATION_MM = finite_float(low=-300.0, high=300.0, unit="mm")
ROTATION_DEG = finite_float(low=-360.0, high=360.0, unit="deg")

NAME = "stepper-template"
HELP = "where a needle through a template hole lands in the image (u, v px) at a stepper pose"
DESCRIPTION = """\
For a planned needle -- a template hole (its ID on the template grid, e.g. D4) and an insertion
depth past the template -- prints where it lands in the ultrasound image at a stepper pose (probe
translation and rotation, template translation as the encoders read them): the pixel (u, v) of
the needle point projected onto the image plane, and its signed distance from the plane (mm,
along the image's z = u x v). RESULT is `brachycal stepper image`'s result (Image -> Probe, the
phantom's registration and the stepper's axes); the template's holes and its place on the phantom
(CoordinateDefinitions TemplateHolder->TemplateHome and TemplateHolder->Phantom) are read from
the device set's TemplateModel. --hole may be given more than once; one row per hole and depth.

The first example reads `brachycal stepper image`'s result on the bundled twin of a stepper (its
--help shows it), the second a result on PLUS's own iCal recordings.

examples:
  brachycal stepper template stepper_image.json --config examples/stepper/PlusDeviceSet_twin_iCal.xml \\
      --hole D4 --depth 100 --probe-position -50
  brachycal stepper template stepper_image.json \\
      --config $BRACHYCAL_REFERENCE/plus_trus_stepper/PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml \\
      --hole D4 --depth 100 --probe-position -50 --probe-rotation 0
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal stepper template",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("result", metavar="RESULT", help="`brachycal stepper image` result (JSON)")
    parser.add_argument(
        "--config", required=True, metavar="DEVICE_SET.xml", help="PLUS device set with the TemplateModel"
    )
    parser.add_argument("--hole", required=True, action="append", metavar="ID", help="template hole ID, e.g. D4")
    parser.add_argument(
        "--depth",
        type=DEPTH_MM,
        action="append",
        metavar="MM",
        help=f"insertion depth past the template, {DEPTH_MM.rule} (default 0)",
    )
    parser.add_argument(
        "--probe-position",
        type=TRANSLATION_MM,
        required=True,
        metavar="MM",
        help=f"probe translation encoder reading, {TRANSLATION_MM.rule}",
    )
    parser.add_argument(
        "--probe-rotation",
        type=ROTATION_DEG,
        default=0.0,
        metavar="DEG",
        help=f"probe rotation encoder reading, {ROTATION_DEG.rule}",
    )
    parser.add_argument(
        "--template-position",
        type=TRANSLATION_MM,
        default=0.0,
        metavar="MM",
        help=f"template translation reading, {TRANSLATION_MM.rule}",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.stepper_probe import hole_in_image, read_stepper_image
    from brachycal.data.formats.plus_stepper import read_template  # lazy: start-up (the command's run only)

    result = read_stepper_image(args.result)
    template = read_template(args.config)
    rows = [
        hole_in_image(
            result.image_to_probe,
            result.T_template_phantom,
            template,
            hole,
            depth * 1e-3,
            probe_translation_m=args.probe_position * 1e-3,
            probe_rotation_rad=np.radians(args.probe_rotation),
            template_translation_m=args.template_position * 1e-3,
            axes=result.axes,
        )
        for hole in args.hole
        for depth in (args.depth or [0.0])
    ]
    print(
        f"# image frame (pixels) of {args.result}; probe at {args.probe_position:g} mm, "
        f"{args.probe_rotation:g} deg; template at {args.template_position:g} mm"
    )
    print("hole,depth_mm,u_px,v_px,distance_from_image_plane_mm")
    for row in rows:
        print(f"{row.hole},{row.depth_m * 1e3:.3f},{row.u_px:.2f},{row.v_px:.2f},{row.distance_m * 1e3:.3f}")
    return 0

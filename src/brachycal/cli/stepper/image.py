"""``brachycal stepper image``: Image → Probe of a TRUS probe on a brachytherapy stepper (PLUS's iCal recordings)."""

from __future__ import annotations

import argparse

from brachycal.cli.common import add_quiet_option, command_inputs, output_file, print_next, progress_bar
from brachycal.cli.nwire.calibrate import MODELS

NAME = "stepper-image"
HELP = "Image -> Probe of a TRUS probe on a stepper, from random stepper motion (N-wire phantom)"
DESCRIPTION = """\
Calibrates Image -> Probe of a transrectal probe on a brachytherapy stepper (PLUS's iCal set-up:
no tracker, the stepper's encoders give the poses in StepperHome) from B-mode recordings of the
N-wire phantom mounted on the template holder:

  1. the phantom's registration to the stepper, as PLUS's brachy-stepper phantom registration:
     from ROTATION.mha (the probe turned), the pixel spacing and the centre of rotation, and the
     distances from the rotation axis to two lines of wires, place the probe's axis in the phantom;
  2. the N-wire calibration of `brachycal nwire` (PLUS's affine fit, brachycal's rigid + two
     spacings, PLUS fCal's four refinements) on CALIBRATION.mha, with the stepper as the
     reference, validated on VALIDATION.mha as PLUS reports it (3D reprojection error of the
     middle wires, best 95%, and per-wire 2D errors in pixels).

The recorded poses move the probe along the stepper's z exactly; the device set's
StepperCalibration (ProbeTranslationAxisOrientation, 'Tx Ty 1') says along which axis it really
travels, and each pose is rebuilt from its encoder values along it (as PLUS's stepper device does
when it compensates); --stepper takes the axes (and the rotation encoder's scale) from
`brachycal stepper calibrate`'s result instead; a device set without StepperCalibration needs one
of them. The fit on the poses as recorded, PLUS's own, is validated beside it; --recorded-poses
uses only those (a stepper axis off z then goes uncorrected into Image -> Probe). CALIBRATION may
also be a segmented-frames XML holding both frame sets (PLUS's results file, or `brachycal nwire
segment`'s output); then leave out VALIDATION.

Writes JSON (brachycal-nwire/1 with a 'stepper' block: the registration T_Template_Phantom, the
axes, the recorded poses' errors), which `brachycal stepper template` and `brachycal stepper
export` read.

The first example runs on the bundled twin of a stepper (`brachycal examples examples` copies it;
examples/stepper/truth.json holds its truth), the second on PLUS's own iCal recordings.

examples:
  brachycal stepper image examples/stepper/twin_ProbeRotation.igs.mha \\
      examples/stepper/twin_RandomStepperMotionCalibration.igs.mha \\
      examples/stepper/twin_RandomStepperMotionValidation.igs.mha \\
      --config examples/stepper/PlusDeviceSet_twin_iCal.xml --out stepper_image.json
  brachycal stepper image $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_ProbeRotation.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_RandomStepperMotionCalibration.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_RandomStepperMotionValidation.igs.mha \\
      --config $BRACHYCAL_REFERENCE/plus_trus_stepper/PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml \\
      --out stepper_image.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal stepper image",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("rotation", metavar="ROTATION.mha", help="B-mode sequence: the probe turned by the stepper")
    parser.add_argument(
        "calibration",
        metavar="CALIBRATION",
        help="B-mode sequence (.mha) of random stepper motion, or a segmented-frames XML with both frame sets",
    )
    parser.add_argument(
        "validation", metavar="VALIDATION.mha", nargs="?", help="B-mode sequence of the validation frames"
    )
    parser.add_argument(
        "--config", required=True, metavar="DEVICE_SET.xml", help="PLUS stepper device set (phantom, segmentation)"
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument(
        "--model", choices=MODELS, default=None, help="model to choose (default: the lowest best-95%% validation mean)"
    )
    parser.add_argument(
        "--recorded-poses",
        action="store_true",
        help="use the poses as recorded (PLUS's fit), not rebuilt along the device set's calibrated axes "
        "(needed when it has no StepperCalibration and no --stepper is given)",
    )
    parser.add_argument(
        "--stepper",
        metavar="STEPPER.json",
        help="the stepper's axes from `brachycal stepper calibrate` (default: the device set's StepperCalibration)",
    )
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(parser, "the progress bars and next: lines")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.calibration.phantom.nwire import best_fraction  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.stepper_probe import (
        calibrate_stepper_image_files,
        read_calibrated_axes,
        write_stepper_image,
    )
    from brachycal.data.formats.metaimage import MF_FRAME_TEXT  # lazy: start-up (the command's run only)
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    if args.stepper is not None and args.recorded_poses:
        raise InputError("--recorded-poses uses no axes: give it without --stepper")
    with OutputSet(
        force=args.force, inputs=command_inputs(args, "rotation", "calibration", "validation", "config", "stepper")
    ) as outputs:
        staged = outputs.claim(args.out, label="--out")
        axes = read_calibrated_axes(args.stepper) if args.stepper is not None else None
        result = calibrate_stepper_image_files(
            args.config,
            args.rotation,
            args.calibration,
            args.validation,
            model=args.model,
            correct_axes=not args.recorded_poses,
            axes=axes,
            progress=lambda name, frames: progress_bar(frames, name, args.quiet, unit="frame"),
        )
        write_stepper_image(result, staged, force=args.force)
    r = result.registration
    t = r.T_template_phantom[:3, 3] * 1e3
    print(
        f"phantom registration: {r.frames} rotation frames, spacing {r.spacing.value[0] * 1e3:.5f} x "
        f"{r.spacing.value[1] * 1e3:.5f} mm/px, centre of rotation "
        f"{r.centre.value[0]:.2f}, {r.centre.value[1]:.2f} px; "
        f"Phantom->StepperHome translation {t[0]:.3f} {t[1]:.3f} {t[2]:.3f} mm"
    )
    print(f"pixels: {MF_FRAME_TEXT}")
    a = result.axes.probe_translation
    if args.recorded_poses:
        poses = (
            "as recorded (--recorded-poses): the probe and the template taken to move along the stepper's z "
            "exactly; a stepper axis off z is not corrected and its error goes into Image -> Probe"
        )
    elif result.recorded is None:
        poses = f"as recorded: the axes of {result.axes.source} are the stepper's z (0 0 1), nothing to correct"
    else:
        poses = f"along the probe axis {a[0]:.6f} {a[1]:.6f} 1 (from {result.axes.source})"
    print(f"poses: {poses}")
    n = result.nwire
    print(
        f"N-wire calibration: {n.frames_used} of {n.frames_total} calibration frames ({n.calibration_points} points), "
        f"{n.validation_frames} validation frames ({n.validation_points} points)"
    )
    print("3D reprojection error, best 95% (mm, mean ± SD), as PLUS reports it:")
    print(
        f"  {'model':9s} {'validation':>15s} {'calibration':>15s}"
        + ("   recorded poses: validation, calibration" if result.recorded else "")
    )
    for model, v in n.models.items():
        mark = "*" if model == n.model else " "
        best, cal = v.validation_best95, best_fraction(v.calibration_3d)
        line = f"{mark} {model:9s} {best.mae_mm:7.3f} ± {best.sd_mm:5.3f} {cal.mae_mm:7.3f} ± {cal.sd_mm:5.3f}"
        if result.recorded is not None:
            recorded = result.recorded.models[model]
            rb, rc = recorded.validation_best95, best_fraction(recorded.calibration_3d)
            line += f"   {rb.mae_mm:7.3f} ± {rb.sd_mm:5.3f} {rc.mae_mm:7.3f} ± {rc.sd_mm:5.3f}"
        print(line)
    print(f"  chosen: {n.model} ({n.chosen_by})")
    print(f"wrote {args.out}")
    print_next(
        f"brachycal stepper export {args.out} --out DIR",
        f"brachycal stepper template {args.out} --config {args.config} --hole D4 --depth 100 --probe-position -50",
        quiet=args.quiet,
    )
    return 0

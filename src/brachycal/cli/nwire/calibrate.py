"""``brachycal nwire`` (``nwire calibrate``): N-wire phantom calibration of a tracked probe from PLUS files."""

from __future__ import annotations

import argparse

from brachycal.cli.common import command_inputs, output_file
from brachycal.cli.nwire import segment as nwire_segment

#: The image models (:data:`brachycal.calibration.phantom.nwire_file.NWIRE_MODELS`, here so --help imports
#: nothing heavy).
MODELS = ("affine", "rigid", "3d-aniso", "3d-iso", "2d-aniso", "2d-iso")
HELP = "N-wire phantom calibration of a tracked probe (PLUS configuration + segmented frames)"
DESCRIPTION = """\
Calibrates Image -> Probe from a PLUS device-set configuration (phantom wire geometry and the
Phantom->Reference registration) and a PLUS segmented-frames file (wire intersections in pixels
and the ProbeToTracker / ReferenceToTracker readings per frame), like PLUS's fCal: the middle
wire of each N is located by similar triangles, carried into the probe frame, and the image is
fitted with six models: 'affine' (PLUS's linear least squares with per-coordinate 3-sigma
outlier rejection), 'rigid' (a proper rotation plus separate u/v pixel spacings), and PLUS fCal's
four refinements of a rotation and pixel spacing minimising the middle wires' 3D distance ('3d-')
or every wire's in-plane pixel distance ('2d-'), with one ('-iso') or two ('-aniso') spacings
(PLUS's OPEI/OPEA/IPEI/IPEA settings). Every model is validated on the validation frames: 3D
reprojection error (all points, and the best 95% as PLUS reports it) and per-wire 2D errors in
pixels. The chosen model is --model, or the lowest best-95% validation mean. Writes JSON (metres;
'affine_mm' and each model's 'image_to_probe_mm' in PLUS's units).

example:
  brachycal nwire examples/nwire/PlusDeviceSet_twin_fCal2.xml examples/nwire/twin_segmented_frames.xml \\
      --out nwire.json
"""
EPILOG = """\
sub-commands (each with its own --help):
  brachycal nwire [calibrate] CONFIG FRAMES --out nwire.json
      this page: calibrate (the default, so 'calibrate' may be left out)
  brachycal nwire segment CALIBRATION.mha VALIDATION.mha --config CONFIG --out frames.xml
      the N-wire phantom's points in tracked B-mode sequences (PLUS's segmented-frames XML)
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "nwire",
        help=HELP,
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("config", metavar="CONFIG", help="PLUS device-set configuration XML")
    parser.add_argument(
        "frames", metavar="FRAMES", nargs="?", help="PLUS segmented-frames XML (calibration + validation)"
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument(
        "--model",
        choices=MODELS,
        default=None,
        help="model to choose (default: the lowest best-95%% validation mean)",
    )
    nwire_segment.add_sequence_options(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.calibration import calibrate_nwire_files, write_nwire  # lazy: start-up (the command's run only)
    from brachycal.data.formats.metaimage import MF_FRAME_TEXT  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "config", "frames")) as outputs:
        staged = outputs.claim(args.out, label="--out")
        with nwire_segment.frames_file(args) as frames:
            run = calibrate_nwire_files(args.config, frames, model=args.model)
        write_nwire(run, staged, force=args.force)
    c = run.calibration
    spacing_affine = run.affine_spacing_m
    print(
        f"N-wire calibration: {run.frames_used} of {run.frames_total} calibration frames "
        f"({run.calibration_points} middle-wire points), {run.validation_frames} validation frames "
        f"({run.validation_points} points)"
    )
    print(
        f"  pixel spacing: affine {spacing_affine[0] * 1e3:.5f} x {spacing_affine[1] * 1e3:.5f} mm/px, "
        f"rigid {c.spacing_m[0] * 1e3:.5f} x {c.spacing_m[1] * 1e3:.5f} mm/px "
        f"(configuration's approximate spacing {run.start_spacing_m * 1e3:.3f})"
    )
    print(f"  pixels: {MF_FRAME_TEXT}")
    print(f"  rigid and affine rotations differ by {run.rigid_vs_affine_deg:.3f} deg")
    print("  3D reprojection error on the validation frames (mm), every model:")
    for model, validation in run.models.items():
        v, best = validation.validation_3d, validation.validation_best95
        mark = "*" if model == run.model else " "
        s_u, s_v = np.linalg.norm(run.matrix(model)[:3, :2], axis=0) * 1e3
        print(
            f"  {mark} {model:8s}  all {v.mae_mm:.3f} ± {v.sd_mm:.3f} (max {v.max_mm:.2f}), "
            f"best 95% {best.mae_mm:.3f} ± {best.sd_mm:.3f}; spacing {s_u:.5f} x {s_v:.5f} mm/px"
        )
    print(f"  chosen: {run.model} ({run.chosen_by})")
    print(f"  per-wire 2D error on the validation frames, {run.model} model (px, mean du, dv ± SD):")
    for name, e in run.models[run.model].wires_2d.items():
        print(f"    {name:8s} {e.mean_px[0]:+6.2f} {e.mean_px[1]:+6.2f}  ± {e.sd_px[0]:.2f} {e.sd_px[1]:.2f}")
    print(f"wrote {args.out}")
    return 0

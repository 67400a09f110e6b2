"""``brachycal nwire``: N-wire phantom calibration of a tracked probe from PLUS files."""

from __future__ import annotations

import argparse

HELP = "N-wire phantom calibration of a tracked probe (PLUS configuration + segmented frames)"
DESCRIPTION = """\
Calibrates Image -> Probe from a PLUS device-set configuration (phantom wire geometry and the
Phantom->Reference registration) and a PLUS segmented-frames file (wire intersections in pixels
and the ProbeToTracker / ReferenceToTracker readings per frame), like PLUS's fCal: the middle
wire of each N is located by similar triangles, carried into the probe frame, and the image is
fitted with two models — 'affine' (PLUS's linear least squares with per-coordinate 3-sigma
outlier rejection) and 'rigid' (a proper rotation plus separate u/v pixel spacings). Both are
validated on the validation frames: 3D reprojection error (all points, and the best 95% as PLUS
reports it) and per-wire 2D errors in pixels. Writes JSON (metres; 'affine_mm' in PLUS's units).

example:
  brachycal nwire examples/nwire/PlusDeviceSet_twin_fCal2.xml examples/nwire/twin_segmented_frames.xml \\
      --out nwire.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "nwire", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("config", metavar="CONFIG", help="PLUS device-set configuration XML")
    parser.add_argument("frames", metavar="FRAMES", help="PLUS segmented-frames XML (calibration + validation)")
    parser.add_argument("--out", required=True, metavar="JSON", help="result file to write")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.calibration import nwire_from_files, write_nwire
    from brachycal.files import OutputSet

    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(args.out, label="--out")
        run = nwire_from_files(args.config, args.frames)
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
    print(f"  rigid and affine rotations differ by {run.rigid_vs_affine_deg:.3f} deg")
    print("  3D reprojection error on the validation frames (mm):")
    for model, validation in run.models.items():
        v, best = validation.validation_3d, validation.validation_best95
        print(
            f"    {model:6s}  all {v.mae_mm:.3f} ± {v.sd_mm:.3f} (max {v.max_mm:.2f}), "
            f"best 95% {best.mae_mm:.3f} ± {best.sd_mm:.3f}"
        )
    print("  per-wire 2D error on the validation frames, affine model (px, mean dx, dy ± SD):")
    for name, e in run.models["affine"].wires_2d.items():
        print(f"    {name:8s} {e.mean_px[0]:+6.2f} {e.mean_px[1]:+6.2f}  ± {e.sd_px[0]:.2f} {e.sd_px[1]:.2f}")
    print(f"wrote {args.out}")
    return 0

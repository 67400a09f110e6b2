"""``brachycal nwire``: N-wire phantom calibration of a tracked probe from PLUS files."""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np

from brachycal.calibration.nwire import (
    best_fraction,
    calibrate_nwire,
    reprojection_errors,
    rotation_difference_deg,
    wire_errors_2d,
    wire_point_pairs,
)
from brachycal.data.plus_files import read_plus_config, read_segmented_frames
from brachycal.errors import InputError
from brachycal.files import atomic_open

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
  brachycal nwire PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml fCal_3NWires_segmented_frames.xml --out nwire.json
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


def _stats(stats) -> dict:
    best = best_fraction(stats)
    return {
        "n": stats.n,
        "mean_mm": stats.mae_mm,
        "sd_mm": stats.sd_mm,
        "max_mm": stats.max_mm,
        "best95_mean_mm": best.mae_mm,
        "best95_sd_mm": best.sd_mm,
    }


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("already exists; pass --force to replace it", file=out)
    config = read_plus_config(args.config)
    calibration_frames, validation_frames = read_segmented_frames(args.frames)
    uv, p_probe, _ = wire_point_pairs(config, calibration_frames)
    spacing0 = config.approximate_spacing_m or 1e-4
    result = calibrate_nwire(uv, p_probe, spacing0)
    if not any(f.ok for f in validation_frames):
        raise InputError("no usable validation frames", file=args.frames)
    uv_v, p_v, _ = wire_point_pairs(config, validation_frames)
    report = {}
    for model in ("affine", "rigid"):
        wires = wire_errors_2d(result, config, validation_frames, model)
        report[model] = {
            "validation_3d": _stats(reprojection_errors(result, uv_v, p_v, model)),
            "calibration_3d": _stats(reprojection_errors(result, uv, p_probe, model)),
            "wires_2d_px": {
                name: {"mean": e.mean(axis=0).tolist(), "sd": e.std(axis=0).tolist(), "n": len(e)}
                for name, e in wires.items()
            },
        }
    affine_mm = result.affine.copy()
    affine_mm[:3, :] *= 1e3
    spacing_affine = np.linalg.norm(result.affine[:3, :2], axis=0)
    payload = {
        "format": "brachycal-nwire/1",
        "T_Probe_Image": result.T_probe_image.tolist(),
        "spacing_mm": (result.spacing_m * 1e3).tolist(),
        "affine_mm": affine_mm.tolist(),
        "affine_spacing_mm": (spacing_affine * 1e3).tolist(),
        "rigid_vs_affine_deg": rotation_difference_deg(result.T_probe_image, result.affine),
        "calibration_points": len(uv),
        "rigid_inliers": int(result.inliers.sum()),
        "validation_points": len(uv_v),
        "errors": report,
        "inputs": {Path(p).name: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in (args.config, args.frames)},
    }
    with atomic_open(out, force=args.force) as handle:
        json.dump(payload, handle, indent=2)
        handle.write("\n")
    ok_cal = sum(f.ok for f in calibration_frames)
    print(
        f"N-wire calibration: {ok_cal} of {len(calibration_frames)} calibration frames "
        f"({len(uv)} middle-wire points), {len(validation_frames)} validation frames ({len(uv_v)} points)"
    )
    print(
        f"  pixel spacing: affine {spacing_affine[0] * 1e3:.5f} x {spacing_affine[1] * 1e3:.5f} mm/px, "
        f"rigid {result.spacing_m[0] * 1e3:.5f} x {result.spacing_m[1] * 1e3:.5f} mm/px "
        f"(configuration's approximate spacing {spacing0 * 1e3:.3f})"
    )
    print(f"  rigid and affine rotations differ by {payload['rigid_vs_affine_deg']:.3f} deg")
    print("  3D reprojection error on the validation frames (mm):")
    for model in ("affine", "rigid"):
        v = report[model]["validation_3d"]
        print(
            f"    {model:6s}  all {v['mean_mm']:.3f} ± {v['sd_mm']:.3f} (max {v['max_mm']:.2f}), "
            f"best 95% {v['best95_mean_mm']:.3f} ± {v['best95_sd_mm']:.3f}"
        )
    print("  per-wire 2D error on the validation frames, affine model (px, mean dx, dy ± SD):")
    for name, e in report["affine"]["wires_2d_px"].items():
        print(f"    {name:8s} {e['mean'][0]:+6.2f} {e['mean'][1]:+6.2f}  ± {e['sd'][0]:.2f} {e['sd'][1]:.2f}")
    print(f"wrote {out}")
    return 0

"""``brachycal phantom``: tracked-probe calibration with a multi-wedge, arbitrary-wire or N-wire phantom."""

from __future__ import annotations

import argparse

from brachycal.cli.common import command_inputs, output_file

HELP = "tracked-probe phantom calibration: multi-wedge, arbitrary-wire or N-wire (Table III's image-based methods)"
METHODS = ("wedge", "wire", "nwire")
DESCRIPTION = """\
Calibrates Image -> Marker (the image frame on the probe's tracked marker body, rigid, with the two
pixel spacings) from a phantom of known geometry and a tracked session:

  --method wedge   multi-wedge phantom (Najafi et al. 2014): planar faces seen as lines.
                   GEOMETRY: brachycal-phantom/1 TOML of kind "multi-wedge";
                   OBSERVATIONS: CSV, one row per face seen in a frame, its line by two points
                   (u0_px,v0_px,u1_px,v1_px).
  --method wire    arbitrary-wire phantom (Shen et al. 2019): wires of known 3D placement.
                   GEOMETRY: brachycal-phantom/1 TOML of kind "wire";
                   OBSERVATIONS: CSV, one row per wire seen in a frame (u_px,v_px).
  --method nwire   N-wire phantom, PLUS files (as brachycal nwire): GEOMETRY is the PLUS
                   device-set configuration, OBSERVATIONS the segmented-frames file.

Observation CSV columns (wedge and wire): frame,feature,probe_x,probe_y,probe_z,probe_qx,
probe_qy,probe_qz,probe_qw,reference_x,...,reference_qw, then the pixels: the tracker's readings
of the probe's marker body and of the phantom's reference body (metres, unit quaternions in ROS
order), the same on every row of a frame. Geometry files: millimetres in the phantom frame; the
bundled defaults are src/brachycal/phantoms/multi_wedge.toml and arbitrary_wire.toml.

Wedge and wire: a closed-form linear start, Levenberg-Marquardt over all frames, and a
conditioning check: refused when the predicted SD 50 mm from the image centre exceeds 2 mm with
0.5 px segmentation error alone; a warning above 0.5 mm with the fit's own residual level.
Layouts that cannot fix the image plane in one image (one wedge, parallel or coplanar wires) are
refused when the geometry is read. Writes JSON (brachycal-phantom-result/1, metres). The example
files (brachycal examples DIR) hold a twin session of each phantom, each geometry with the
session's landmark registration (the twin writes such sessions: brachycal.studies.simulate_phantom
and brachycal.calibration.write_phantom_observations).

example:
  brachycal phantom --method wedge examples/phantom/multi_wedge.toml \\
      examples/phantom/wedge_observations.csv --out phantom_wedge.json
  brachycal phantom --method wire examples/phantom/arbitrary_wire.toml \\
      examples/phantom/wire_observations.csv --out phantom_wire.json
  brachycal phantom --method nwire examples/nwire/PlusDeviceSet_twin_fCal2.xml \\
      examples/nwire/twin_segmented_frames.xml --out phantom_nwire.json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "phantom", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--method", required=True, choices=METHODS, help="the phantom: wedge, wire or nwire")
    parser.add_argument("geometry", metavar="GEOMETRY", help="phantom geometry (TOML; nwire: PLUS configuration XML)")
    parser.add_argument(
        "observations", metavar="OBSERVATIONS", help="tracked observations (CSV; nwire: PLUS segmented frames XML)"
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet, sha256_file, write_json  # lazy: start-up (the command's run only)

    if args.method == "nwire":
        return _nwire(args)
    from brachycal.calibration.phantom.phantom_file import result_payload  # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.wedge import calibrate_wedge_files  # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.wire import calibrate_wire_files  # lazy: start-up (the command's run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "geometry", "observations")) as outputs:
        staged = outputs.claim(args.out, label="--out")
        calibrate_files = calibrate_wedge_files if args.method == "wedge" else calibrate_wire_files
        fit, phantom, _ = calibrate_files(args.geometry, args.observations)
        inputs = {"geometry": sha256_file(args.geometry), "observations": sha256_file(args.observations)}
        write_json(staged, result_payload(fit, inputs), force=args.force)
    rms_mm = float((fit.residuals_m**2).mean() ** 0.5 * 1e3)
    print(
        f"{args.method} phantom calibration ({phantom.geometry.name}): {fit.frames} frames, "
        f"{fit.observations} observations, {fit.iterations} refinement iterations"
    )
    print(f"  pixel spacing: {fit.spacing_m[0] * 1e3:.5f} x {fit.spacing_m[1] * 1e3:.5f} mm/px")
    print(f"  residual RMS {rms_mm:.3f} mm (point to {'plane' if args.method == 'wedge' else 'wire'})")
    print(
        f"  predicted SD 50 mm from the image centre: {fit.reach_sd_m * 1e3:.3f} mm (segmentation alone), "
        f"{fit.reach_sd_fit_m * 1e3:.3f} mm (with the fit's residual level)"
    )
    print(f"wrote {args.out}")
    return 0


def _nwire(args: argparse.Namespace) -> int:
    """``--method nwire``: ``brachycal nwire GEOMETRY OBSERVATIONS --out …`` with that command's own defaults."""
    from brachycal.cli.nwire import calibrate as nwire  # lazy: start-up (the command's run only)

    parser = argparse.ArgumentParser(prog="brachycal")
    nwire.add_parser(parser.add_subparsers())
    words = ["nwire", args.geometry, args.observations, "--out", args.out] + (["--force"] if args.force else [])
    return int(nwire.run(parser.parse_args(words)) or 0)

"""``brachycal phantom KIND``: tracked-probe calibration with a multi-wedge (``wedge``), arbitrary-wire (``wire``)
or N-wire (``nwire``) phantom; the kind is a sub-command. An earlier release's spelling,
``phantom --method KIND``, still runs, with a one-line note (:func:`current_spelling`)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from brachycal.cli.common import add_quiet_option, command_inputs, earlier_spelling, output_file, spelling_note

HELP = "tracked-probe calibration with a multi-wedge, arbitrary-wire or N-wire phantom (Table III's phantom routes)"
#: The phantom kinds, each a sub-command: ``brachycal phantom KIND GEOMETRY OBSERVATIONS``.
KINDS = ("wedge", "wire", "nwire")
DESCRIPTION = """\
Calibrates Image -> Marker (the image frame on the probe's tracked marker body, rigid, with the two
pixel spacings) from a phantom of known geometry and a tracked session. The phantom kind is the
sub-command:

  brachycal phantom wedge GEOMETRY OBSERVATIONS --out JSON
                   multi-wedge phantom (Najafi et al. 2014): planar faces seen as lines
  brachycal phantom wire GEOMETRY OBSERVATIONS --out JSON
                   arbitrary-wire phantom (Shen et al. 2019): wires of known 3D placement
  brachycal phantom nwire CONFIG FRAMES --out JSON
                   N-wire phantom, PLUS files (as brachycal nwire)

Each kind's --help (brachycal phantom wedge --help) gives its files. Writes JSON, metres:
brachycal-phantom-result/1 (wedge, wire) or brachycal-nwire/1 (nwire). The example files
(brachycal examples DIR) hold a twin session of each phantom, each geometry with the session's
landmark registration (the twin writes such sessions: brachycal.studies.simulate_phantom and
brachycal.calibration.write_phantom_observations).

examples:
  brachycal phantom wedge examples/phantom/multi_wedge.toml \\
      examples/phantom/wedge_observations.csv --out phantom_wedge.json
  brachycal phantom wire examples/phantom/arbitrary_wire.toml \\
      examples/phantom/wire_observations.csv --out phantom_wire.json
  brachycal phantom nwire examples/nwire/PlusDeviceSet_twin_fCal2.xml \\
      examples/nwire/twin_segmented_frames.xml --out phantom_nwire.json
"""

_OBSERVATION_COLUMNS = """\
Observation CSV columns: frame,feature,probe_x,probe_y,probe_z,probe_qx,probe_qy,probe_qz,probe_qw,
reference_x,...,reference_qw, then the pixels: the tracker's readings of the probe's marker body
and of the phantom's reference body (metres, unit quaternions in ROS order), the same on every row
of a frame. Geometry files: millimetres in the phantom frame.

A closed-form linear start, Levenberg-Marquardt over all frames, and a conditioning check: refused
when the predicted SD 50 mm from the image centre exceeds 2 mm with 0.5 px segmentation error
alone; a warning above 0.5 mm with the fit's own residual level. Layouts that cannot fix the image
plane in one image ({degenerate}) are refused when the geometry is read. Writes
JSON (brachycal-phantom-result/1, metres).
"""

#: Each kind's one-line help and its --help text.
KIND_HELP = {
    "wedge": "multi-wedge phantom (Najafi et al. 2014): planar faces seen as lines",
    "wire": "arbitrary-wire phantom (Shen et al. 2019): wires of known 3D placement",
    "nwire": "N-wire phantom from PLUS files (the job of brachycal nwire, its defaults)",
}
KIND_DESCRIPTION = {
    "wedge": """\
Calibrates Image -> Marker with a multi-wedge phantom (Najafi et al. 2014): planar faces seen in
the image as lines.

GEOMETRY: brachycal-phantom/1 TOML of kind "multi-wedge" (bundled default:
src/brachycal/phantoms/multi_wedge.toml). OBSERVATIONS: CSV, one row per face seen in a frame,
its line by two points (u0_px,v0_px,u1_px,v1_px).

"""
    + _OBSERVATION_COLUMNS.format(degenerate="one wedge")
    + """
example:
  brachycal phantom wedge examples/phantom/multi_wedge.toml \\
      examples/phantom/wedge_observations.csv --out phantom_wedge.json
""",
    "wire": """\
Calibrates Image -> Marker with an arbitrary-wire phantom (Shen et al. 2019): wires of known 3D
placement, each seen in the image as a point.

GEOMETRY: brachycal-phantom/1 TOML of kind "wire" (bundled default:
src/brachycal/phantoms/arbitrary_wire.toml). OBSERVATIONS: CSV, one row per wire seen in a frame
(u_px,v_px).

"""
    + _OBSERVATION_COLUMNS.format(degenerate="parallel or coplanar wires")
    + """
example:
  brachycal phantom wire examples/phantom/arbitrary_wire.toml \\
      examples/phantom/wire_observations.csv --out phantom_wire.json
""",
    "nwire": """\
Calibrates Image -> Marker with an N-wire phantom from PLUS files, as brachycal nwire does with its
defaults: CONFIG is the PLUS device-set configuration (the phantom's wires and its registration),
FRAMES the segmented-frames file. Writes JSON (brachycal-nwire/1, metres), as brachycal nwire.

example:
  brachycal phantom nwire examples/nwire/PlusDeviceSet_twin_fCal2.xml \\
      examples/nwire/twin_segmented_frames.xml --out phantom_nwire.json
""",
}


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "phantom", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    kinds = parser.add_subparsers(title="phantom kinds", metavar="KIND", dest="kind", required=True)
    for kind in KINDS:
        nwire = kind == "nwire"
        one = kinds.add_parser(
            kind,
            help=KIND_HELP[kind],
            description=KIND_DESCRIPTION[kind],
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        one.add_argument(
            "geometry",
            metavar="CONFIG" if nwire else "GEOMETRY",
            help="PLUS device-set configuration (XML)" if nwire else "phantom geometry (brachycal-phantom/1 TOML)",
        )
        one.add_argument(
            "observations",
            metavar="FRAMES" if nwire else "OBSERVATIONS",
            help="PLUS segmented frames (XML)" if nwire else "tracked observations (CSV)",
        )
        one.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
        one.add_argument("--force", action="store_true", help="replace --out if it exists")
        add_quiet_option(one, "progress bar (as brachycal nwire's)" if nwire else "report (only the file written)")
        one.set_defaults(run=run)


def current_spelling(arguments: Sequence[str]) -> list[str]:
    """``arguments`` (after ``brachycal``) with an earlier release's ``phantom --method KIND …`` replaced by
    ``phantom KIND …``; says so on stderr, in one line, when KIND is a phantom kind. Anything else: unchanged."""
    arguments = list(arguments)
    at = earlier_spelling(arguments, "phantom", KINDS)
    if at is None:
        return arguments
    head, rest = arguments[: at + 1], arguments[at + 1 :]
    for k, word in enumerate(rest):
        if word == "--method" and k + 1 < len(rest):
            kind, rest = rest[k + 1], rest[:k] + rest[k + 2 :]
        elif word.startswith("--method="):
            kind, rest = word.partition("=")[2], rest[:k] + rest[k + 1 :]
        else:
            continue
        if kind in KINDS:
            spelling_note(f"phantom --method {kind}", f"phantom {kind}")
        return [*head, kind, *rest]
    return arguments


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet, sha256_file, write_json  # lazy: start-up (the command's run only)

    if args.kind == "nwire":
        return _nwire(args)
    from brachycal.calibration.phantom.phantom_file import result_payload  # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.wedge import calibrate_wedge_files  # lazy: start-up (the command's run only)
    from brachycal.calibration.phantom.wire import calibrate_wire_files  # lazy: start-up (the command's run only)

    with OutputSet(force=args.force, inputs=command_inputs(args, "geometry", "observations")) as outputs:
        staged = outputs.claim(args.out, label="--out")
        calibrate_files = calibrate_wedge_files if args.kind == "wedge" else calibrate_wire_files
        fit, phantom, _ = calibrate_files(args.geometry, args.observations)
        inputs = {"geometry": sha256_file(args.geometry), "observations": sha256_file(args.observations)}
        write_json(staged, result_payload(fit, inputs), force=args.force)
    if args.quiet:
        print(f"wrote {args.out}")
        return 0
    rms_mm = float((fit.residuals_m**2).mean() ** 0.5 * 1e3)
    print(
        f"{args.kind} phantom calibration ({phantom.geometry.name}): {fit.frames} frames, "
        f"{fit.observations} observations, {fit.iterations} refinement iterations"
    )
    print(f"  pixel spacing: {fit.spacing_m[0] * 1e3:.5f} x {fit.spacing_m[1] * 1e3:.5f} mm/px")
    print(f"  residual RMS {rms_mm:.3f} mm (point to {'plane' if args.kind == 'wedge' else 'wire'})")
    print(
        f"  predicted SD 50 mm from the image centre: {fit.reach_sd_m * 1e3:.3f} mm (segmentation alone), "
        f"{fit.reach_sd_fit_m * 1e3:.3f} mm (with the fit's residual level)"
    )
    print(f"wrote {args.out}")
    return 0


def _nwire(args: argparse.Namespace) -> int:
    """``phantom nwire``: ``brachycal nwire GEOMETRY OBSERVATIONS --out …`` with that command's own defaults."""
    from brachycal.cli.nwire import calibrate as nwire  # lazy: start-up (the command's run only)

    parser = argparse.ArgumentParser(prog="brachycal")
    nwire.add_parser(parser.add_subparsers())
    words = ["nwire", args.geometry, args.observations, "--out", args.out]
    words += [flag for flag, given in (("--force", args.force), ("--quiet", args.quiet)) if given]
    return int(nwire.run(parser.parse_args(words)) or 0)

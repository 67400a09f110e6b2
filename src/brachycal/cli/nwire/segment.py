"""``brachycal nwire segment``: N-wire phantom frames of tracked B-mode sequences → PLUS segmented-frames XML."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from brachycal.cli.common import command_inputs, output_file

NAME = "nwire-segment"
HELP = "segment the N-wire phantom in tracked B-mode sequences (PLUS .mha) into a PLUS segmented-frames XML"
DESCRIPTION = """\
Finds the wire intersections of an N-wire phantom in every frame of tracked B-mode sequences
(MetaImage .mha as PLUS records them: 8-bit frames, ProbeToTracker and ReferenceToTracker readings
per frame) as PLUS's fCal does: dots (bar top-hats, disc opening, threshold, weighted centroids),
then the phantom's Ns (three collinear dots each, parallel lines at the N planes' distances) from
the configuration's PhantomDefinition and its Segmentation settings. Writes PLUS's segmented-frames
XML (pixels; tracker readings in mm), which `brachycal nwire CONFIG FRAMES` calibrates from.
Frames where the pattern is not found are written as Failed and counted by reason.

The first sequence gives the calibration frames, the second (optional) the validation frames;
`brachycal nwire` needs both.

example:
  brachycal nwire segment examples/nwire/twin_calibration.mha examples/nwire/twin_validation.mha \\
      --config examples/nwire/PlusDeviceSet_twin_fCal2.xml --orientation UF --out twin_frames.xml

(the twin's N-wire frames of `brachycal examples examples`, rendered; its image is PLUS's MF
mirrored left to right, UF). On PLUS's fCal 2.0 recording, from PlusLibData, in
$BRACHYCAL_REFERENCE/plus_fcal_nwire:

example:
  brachycal nwire segment $BRACHYCAL_REFERENCE/plus_fcal_nwire/fCal_Test_Calibration_3NWires_fCal2.0.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_fcal_nwire/fCal_Test_Validation_3NWires_fCal2.0.igs.mha \\
      --config $BRACHYCAL_REFERENCE/plus_fcal_nwire/PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml \\
      --out frames.xml
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME,
        help=HELP,
        description=DESCRIPTION,
        prog="brachycal nwire segment",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("calibration", metavar="CALIBRATION.mha", help="tracked B-mode sequence: calibration frames")
    parser.add_argument(
        "validation", metavar="VALIDATION.mha", nargs="?", help="tracked B-mode sequence: validation frames"
    )
    parser.add_argument(
        "--config", required=True, metavar="CONFIG", help="PLUS device set (PhantomDefinition and Segmentation)"
    )
    parser.add_argument("--out", required=True, type=output_file, metavar="XML", help="segmented-frames file to write")
    add_orientation_option(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


#: PLUS's image orientations (as :data:`brachycal.imaging.nwire_patterns.ORIENTATIONS`; here so --help imports nothing).
ORIENTATIONS = ("MF", "UF", "MN", "UN")


def add_orientation_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--orientation``: which side of the image is the probe's marked side, which the far side."""
    parser.add_argument(
        "--orientation",
        choices=ORIENTATIONS,
        default=None,
        help="the frames' ultrasound orientation, which says which dot is which wire (PLUS's labels are "
        "for MF: u towards the probe's marked side, v away from the transducer); default: the "
        "sequence's UltrasoundImageOrientation, else MF",
    )


def segment_files(
    config: str | os.PathLike[str],
    calibration: str | os.PathLike[str],
    validation: str | os.PathLike[str] | None,
    out: Path,
    *,
    quiet: bool,
    orientation: str | None = None,
) -> list[str]:
    """Segment the sequences and write the XML to ``out`` (a staged path); the summary lines to print.

    Every input is read and checked before anything is written.
    """
    from brachycal.cli.common import progress_bar  # lazy: start-up (the command's run only)
    from brachycal.data.formats.metaimage import read_image_sequence  # lazy: start-up (the command's run only)
    from brachycal.data.formats.plus_files import read_plus_config  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.data.formats.plus_segmentation import read_segmentation_parameters

    # lazy: start-up (the command's run only)
    from brachycal.data.formats.plus_segmented_xml import write_segmented_frames
    from brachycal.imaging.nwire_segmentation import segment_sequence  # lazy: start-up (the command's run only)

    phantom = read_plus_config(config, require_registration=False)
    params = read_segmentation_parameters(config)
    sequences = [
        (label, path, read_image_sequence(path))
        for label, path in (
            ("CalibrationData", calibration),
            ("ValidationData", validation),
        )
        if path is not None
    ]
    results = {}
    lines = []
    for label, path, sequence in sequences:
        with progress_bar(len(sequence), Path(path).name, quiet, unit="frame") as bar:
            bar.unit = "frame"
            result = segment_sequence(
                sequence,
                phantom,
                params,
                source=path,
                label=f"{label} Frame",
                orientation=orientation,
                progress=bar.update,
            )
        results[label] = result
        skipped = ", ".join(f"{count} {reason}" for reason, count in sorted(result.skipped.items()))
        lines.append(
            f"{Path(path).name}: {result.found} of {len(sequence)} frames segmented"
            + (f" (skipped: {skipped})" if skipped else "")
        )
    calibration_result = results["CalibrationData"]
    validation_result = results.get("ValidationData")
    write_segmented_frames(
        out,
        calibration_result.frames,
        validation_result.frames if validation_result is not None else [],
        calibration_times_s=calibration_result.timestamps_s,
        validation_times_s=validation_result.timestamps_s if validation_result is not None else None,
    )
    return lines


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    with OutputSet(
        force=args.force,
        inputs=command_inputs(
            args, "calibration", "validation", "config", "calibration_sequence", "validation_sequence"
        ),
    ) as outputs:
        staged = outputs.claim(args.out, label="--out")
        lines = segment_files(
            args.config, args.calibration, args.validation, staged, quiet=args.quiet, orientation=args.orientation
        )
    for line in lines:
        print(line)
    print(f"wrote {args.out}")
    return 0


def add_sequence_options(parser: argparse.ArgumentParser) -> None:
    """``--calibration-sequence`` and ``--validation-sequence`` of ``brachycal nwire`` (in place of FRAMES)."""
    group = parser.add_argument_group("sequences in place of FRAMES (segmented first, as `brachycal nwire segment`)")
    group.add_argument("--calibration-sequence", metavar="MHA", help="tracked B-mode sequence: calibration frames")
    group.add_argument("--validation-sequence", metavar="MHA", help="tracked B-mode sequence: validation frames")
    add_orientation_option(group)
    group.add_argument("--quiet", action="store_true", help="no progress bar")


@contextmanager
def frames_file(args: argparse.Namespace) -> Iterator[str]:
    """The segmented-frames XML ``brachycal nwire`` calibrates from: FRAMES, or the sequences segmented.

    Raises:
        InputError: neither FRAMES nor both sequences given, or both.
    """
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    # getattr: other commands hand `brachycal nwire`'s run a namespace of their own, without these options
    calibration = getattr(args, "calibration_sequence", None)
    validation = getattr(args, "validation_sequence", None)
    if args.frames is not None:
        if calibration is not None or validation is not None:
            raise InputError("give FRAMES or --calibration-sequence and --validation-sequence, not both")
        yield args.frames
        return
    if calibration is None or validation is None:
        raise InputError("give FRAMES, or both --calibration-sequence and --validation-sequence")
    with tempfile.TemporaryDirectory(prefix="brachycal-nwire-") as folder:
        path = Path(folder) / "segmented_frames.xml"
        lines = segment_files(
            args.config,
            calibration,
            validation,
            path,
            quiet=getattr(args, "quiet", False),
            orientation=getattr(args, "orientation", None),
        )
        for line in lines:
            print(line)
        yield str(path)

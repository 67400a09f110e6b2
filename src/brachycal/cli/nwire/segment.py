"""``brachycal nwire segment``: N-wire phantom frames of B-mode sequences → PLUS segmented-frames XML."""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_quiet_option, command_inputs, output_file, print_next

if TYPE_CHECKING:
    from brachycal.data.formats.plus_files import PoseStreams

NAME = "nwire-segment"
HELP = "segment the N-wire phantom in B-mode sequences (PLUS .mha) into a PLUS segmented-frames XML"
DESCRIPTION = """\
Finds the wire intersections of an N-wire phantom in every frame of B-mode sequences (MetaImage
.mha as PLUS records them: 8-bit frames, poses per frame) as PLUS's fCal does: dots (bar
top-hats, disc opening, threshold, weighted centroids), then the phantom's Ns (three collinear dots
each, parallel lines at the N planes' distances) from the configuration's PhantomDefinition and its
Segmentation settings. Writes PLUS's segmented-frames XML (pixels; poses in mm), which
`brachycal nwire CONFIG FRAMES` calibrates from. Frames where the pattern is not found are written
as Failed and counted by reason.

Every frame is read in PLUS's MF image frame, as PLUS reads it: turned from the orientation the
sequence states in UltrasoundImageOrientation (UF: columns reversed, MN: rows, UN: both; a sequence
without the field is read as MF), so the clip rectangle of the device set and every written point
are MF pixels (u towards the probe's marked side, v away from the transducer).

Segmentation reads the image alone. Each frame's poses are copied from two named streams: by
default those the device set records: an optical tracker's ProbeToTracker and ReferenceToTracker,
or, for a TRUS probe on a brachytherapy stepper (a BrachyTracker device, PLUS's iCal set-up), the
stepper encoders' ProbeToStepperHome and TemplateToStepperHome. --probe-transform and
--reference-transform name other streams. A frame without an OK pose is segmented all the same and
its points written, the pose recorded as missing (a calibration does not use that frame). A
stream that no frame of a sequence has is refused; --images-only reads no poses.

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

On PLUS's TRUS-on-stepper recording (iCal), in $BRACHYCAL_REFERENCE/plus_trus_stepper (the poses
are the stepper's, from its device set):

example:
  brachycal nwire segment $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_RandomStepperMotionCalibration.igs.mha \\
      $BRACHYCAL_REFERENCE/plus_trus_stepper/USTC_3NWires_RandomStepperMotionValidation.igs.mha \\
      --config $BRACHYCAL_REFERENCE/plus_trus_stepper/PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml \\
      --out stepper_frames.xml
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
    add_pose_options(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(parser, "progress bar and no next: line")
    parser.set_defaults(run=run)


#: PLUS's image orientations (as :data:`brachycal.imaging.nwire_patterns.ORIENTATIONS`; here so --help imports nothing).
ORIENTATIONS = ("MF", "UF", "MN", "UN")


def add_orientation_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--orientation``: which side of the image is the probe's marked side, which the far side."""
    parser.add_argument(
        "--orientation",
        choices=ORIENTATIONS,
        default=None,
        help="label the wires as PLUS would in an image of this orientation, for a phantom seen "
        "mirrored (the frames are in MF, turned from their UltrasoundImageOrientation when read; the "
        "points stay MF pixels); default MF, PLUS's labels. Only for sequences stored MF",
    )


STREAM_OPTIONS = "--probe-transform and --reference-transform"
#: What `nwire segment` offers when a recording lacks the pose streams it reads.
POSES_FIX = f"give --images-only to segment the images without poses, or name the recorded ones with {STREAM_OPTIONS}"


def transform_name(text: str) -> str:
    """A PLUS transform name, ``<From>To<To>`` (``ProbeToStepperHome``); a trailing ``Transform``
    (the frame field's name) is taken off."""
    from brachycal.data.formats.plus_files import TRANSFORM_NAME  # lazy: start-up (parsing this option only)

    name = text.strip()
    if name.endswith("Transform") and len(name) > len("Transform"):
        name = name[: -len("Transform")]
    if not TRANSFORM_NAME.fullmatch(name):
        raise argparse.ArgumentTypeError(f"expected a transform name <From>To<To> (e.g. ProbeToTracker), got {text!r}")
    return name


def add_pose_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup, *, images_only: bool = True) -> None:
    """``--probe-transform``, ``--reference-transform`` (and ``--images-only``): where the frames' poses come from."""
    parser.add_argument(
        "--probe-transform",
        type=transform_name,
        metavar="NAME",
        help="the probe's pose stream, e.g. ProbeToTracker or ProbeToStepperHome "
        "(default: the device set's: a tracker's ProbeToTracker, a stepper's ProbeToStepperHome)",
    )
    parser.add_argument(
        "--reference-transform",
        type=transform_name,
        metavar="NAME",
        help="the reference's pose stream in the same base frame, e.g. ReferenceToTracker or "
        "TemplateToStepperHome (default: the device set's)",
    )
    if not images_only:  # a calibration needs the poses
        return
    parser.add_argument(
        "--images-only",
        action="store_true",
        help="read no poses: segment the images alone (every pose written as missing)",
    )


def pose_streams(
    config: str | os.PathLike[str],
    probe: str | None,
    reference: str | None,
    images_only: bool,
) -> PoseStreams | None:
    """The pose streams to read: the options' names, else the device set's; None for images only.

    Raises:
        InputError: ``images_only`` together with a named stream, or a device set that does not
            name its stepper's frames (when an option does not name the stream).
    """
    from brachycal.data.formats.plus_files import PoseStreams, read_pose_streams  # lazy: start-up
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    if images_only:
        if probe is not None or reference is not None:
            raise InputError("--images-only reads no poses: give it without --probe-transform or --reference-transform")
        return None
    if probe is not None and reference is not None:
        return PoseStreams(probe, reference, "options")
    streams = read_pose_streams(config)
    return PoseStreams(probe or streams.probe, reference or streams.reference, streams.source)


def segment_files(
    config: str | os.PathLike[str],
    calibration: str | os.PathLike[str],
    validation: str | os.PathLike[str] | None,
    out: Path,
    *,
    quiet: bool,
    orientation: str | None = None,
    probe_transform: str | None = None,
    reference_transform: str | None = None,
    images_only: bool = False,
    fix: str = POSES_FIX,
) -> list[str]:
    """Segment the sequences and write the XML to ``out`` (a staged path); the summary lines to print.

    Every input is read and checked before anything is written. The poses are read from the
    streams :func:`pose_streams` names; a stream that no frame of a sequence has is refused,
    ``fix`` (the command's options that help) appended to the refusal.
    """
    from brachycal.cli.common import progress_bar  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.data.formats.metaimage import pixel_frame_text, read_image_sequence
    from brachycal.data.formats.plus_files import read_plus_config  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.data.formats.plus_segmentation import read_segmentation_parameters

    # lazy: start-up (the command's run only)
    from brachycal.data.formats.plus_segmented_xml import write_segmented_frames
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.imaging.nwire_segmentation import check_pose_fields, segment_sequence

    phantom = read_plus_config(config, require_registration=False)
    params = read_segmentation_parameters(config)
    poses = pose_streams(config, probe_transform, reference_transform, images_only)
    sequences = [
        (label, path, read_image_sequence(path))
        for label, path in (
            ("CalibrationData", calibration),
            ("ValidationData", validation),
        )
        if path is not None
    ]
    if poses is not None:
        for _, path, sequence in sequences:
            check_pose_fields(sequence, poses, path, fix=fix)
    if orientation not in (None, "MF"):
        for _, path, sequence in sequences:
            if sequence.file_orientation not in (None, "MF"):
                raise InputError(
                    f"--orientation {orientation} mirrors the labels of MF frames, and this sequence is stored "
                    f"{sequence.file_orientation} (turned to MF when read: PLUS's labels need no option)",
                    file=path,
                )
    results = {}
    lines = []
    for label, path, sequence in sequences:
        with progress_bar(len(sequence), Path(path).name, quiet, unit="frame") as bar:
            result = segment_sequence(
                sequence,
                phantom,
                params,
                source=path,
                label=f"{label} Frame",
                orientation=orientation,
                progress=bar.update,
                poses=poses,
                require_poses=True,
            )
        results[label] = result
        skipped = ", ".join(f"{count} {reason}" for reason, count in sorted(result.skipped.items()))
        posed = (
            "no poses read"
            if poses is None
            else f"poses {poses.probe}, {poses.reference}"
            + (f"; {result.without_pose} frames without an OK pose" if result.without_pose else "")
        )
        lines.append(
            f"{Path(path).name}: {result.found} of {len(sequence)} frames segmented"
            + (f" (skipped: {skipped})" if skipped else "")
            + f" [{posed}]"
        )
    frame = pixel_frame_text(sequences[0][2].file_orientation)
    lines.append(f"pixels: {frame}")
    calibration_result = results["CalibrationData"]
    validation_result = results.get("ValidationData")
    write_segmented_frames(
        out,
        calibration_result.frames,
        validation_result.frames if validation_result is not None else [],
        calibration_times_s=calibration_result.timestamps_s,
        validation_times_s=validation_result.timestamps_s if validation_result is not None else None,
        pixel_frame=frame,
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
            args.config,
            args.calibration,
            args.validation,
            staged,
            quiet=args.quiet,
            orientation=args.orientation,
            probe_transform=args.probe_transform,
            reference_transform=args.reference_transform,
            images_only=args.images_only,
        )
    for line in lines:
        print(line)
    print(f"wrote {args.out}")
    if not args.images_only:
        print_next(f"brachycal nwire {args.config} {args.out} --out nwire.json", quiet=args.quiet)
    return 0


def add_sequence_options(parser: argparse.ArgumentParser) -> None:
    """``--calibration-sequence`` and ``--validation-sequence`` of ``brachycal nwire`` (in place of FRAMES)."""
    group = parser.add_argument_group("sequences in place of FRAMES (segmented first, as `brachycal nwire segment`)")
    group.add_argument("--calibration-sequence", metavar="MHA", help="tracked B-mode sequence: calibration frames")
    group.add_argument("--validation-sequence", metavar="MHA", help="tracked B-mode sequence: validation frames")
    add_orientation_option(group)
    add_pose_options(group, images_only=False)
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
            probe_transform=getattr(args, "probe_transform", None),
            reference_transform=getattr(args, "reference_transform", None),
            images_only=getattr(args, "images_only", False),
            fix=f"name the recorded ones with {STREAM_OPTIONS}",
        )
        for line in lines:
            print(line)
        yield str(path)

"""Segment a B-mode sequence of an N-wire phantom into PLUS-style segmented frames.

Segmentation is image-only: every frame is searched for dot candidates
(:mod:`brachycal.imaging.nwire_dots`), then the phantom's N pattern
(:mod:`brachycal.imaging.nwire_patterns`), whatever its poses. The poses each frame carries are
those of two named streams (:class:`~brachycal.data.formats.plus_files.PoseStreams`): a tracker's
``ProbeToTracker`` and ``ReferenceToTracker``, or a brachytherapy stepper's ``ProbeToStepperHome``
and ``TemplateToStepperHome`` (millimetres → metres). A frame becomes a
:class:`~brachycal.data.formats.plus_files.SegmentedFrame`, which is what
:func:`brachycal.calibration.phantom.nwire_file.calibrate_nwire_files` calibrates from. A frame
without a pattern is kept with ``ok=False`` and its reason; a frame without an OK pose keeps its
points, its pose None with the recording's status (counted apart: it is not a segmentation failure).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brachycal.data.formats.metaimage import MF, ImageSequence
from brachycal.data.formats.plus_files import (
    TRANSFORM_NAME,
    PlusConfig,
    PoseStreams,
    SegmentedFrame,
    pose_status,
    sequence_transform,
)
from brachycal.errors import InputError
from brachycal.imaging.nwire_dots import find_dots
from brachycal.imaging.nwire_parameters import NWireSegmentationParameters
from brachycal.imaging.nwire_patterns import NWireGeometry, PatternResult, find_pattern, nwire_geometry
from brachycal.se3 import FloatArray

#: The default pose streams: a tracker's ``ProbeToTracker`` and ``ReferenceToTracker``.
DEFAULT_POSES = PoseStreams()


def segment_frame(
    frame: np.ndarray, geometry: NWireGeometry, params: NWireSegmentationParameters, *, orientation: str = "MF"
) -> PatternResult:
    """The N pattern of one ``(H, W)`` uint8 frame: wire name → ``(u, v)`` pixel, or why not.

    ``orientation``: the frame's ultrasound orientation (:data:`~brachycal.imaging.nwire_patterns.ORIENTATIONS`).
    """
    return find_pattern(find_dots(frame, params), geometry, params, orientation=orientation)


@dataclass(frozen=True)
class SequenceSegmentation:
    """A segmented sequence: one :class:`SegmentedFrame` per image frame, in order.

    Attributes:
        frames: every frame, ``ok=False`` where no pattern was found.
        reasons: per frame, None if segmented, else why not.
        timestamps_s: ``(N,)`` frame times, seconds (NaN where the sequence has none).
        poses: the pose streams read (None: images only, no poses).
    """

    frames: list[SegmentedFrame]
    reasons: list[str | None]
    timestamps_s: FloatArray
    poses: PoseStreams | None = None

    @property
    def found(self) -> int:
        """Frames segmented."""
        return sum(reason is None for reason in self.reasons)

    @property
    def skipped(self) -> dict[str, int]:
        """Reason → number of frames not segmented for it."""
        return dict(Counter(reason for reason in self.reasons if reason is not None))

    @property
    def without_pose(self) -> int:
        """Frames (segmented or not) missing an OK probe or reference pose; 0 for images only."""
        if self.poses is None:
            return 0
        return sum(f.T_tracker_probe is None or f.T_tracker_reference is None for f in self.frames)


def check_pose_fields(
    sequence: ImageSequence, poses: PoseStreams, source: str | os.PathLike[str], *, fix: str = ""
) -> None:
    """Refuse a recording in which no frame has one of the named pose streams (a wrong name, or a
    recording without poses), naming the field and the transforms the recording has.

    Args:
        fix: what the user can do instead (the command's options), appended to the refusal.

    Raises:
        InputError: naming the file and the missing field.
    """
    present = {name for fields in sequence.frame_fields for name in fields}
    for role, name in zip(("probe", "reference"), poses.fields, strict=True):
        if name in present or name + "Status" in present:
            continue
        recorded = sorted(
            n for n in present if n.endswith("Transform") and TRANSFORM_NAME.fullmatch(n[: -len("Transform")])
        )
        has = ", ".join(recorded) if recorded else "none"
        raise InputError(
            f"no frame has the {role} pose {name} (the recording's transforms: {has})" + (f"; {fix}" if fix else ""),
            file=source,
            column=name,
        )


def segment_sequence(
    sequence: ImageSequence,
    config: PlusConfig,
    params: NWireSegmentationParameters,
    *,
    source: str | os.PathLike[str],
    label: str = "frame",
    orientation: str | None = None,
    progress: Callable[[int], None] | None = None,
    poses: PoseStreams | None = DEFAULT_POSES,
    require_poses: bool = False,
) -> SequenceSegmentation:
    """Segment every frame of a B-mode sequence of the configuration's N-wire phantom, image only.

    Args:
        sequence: ``(N, H, W)`` uint8 frames with PLUS's per-frame fields (poses in mm).
        config: the phantom's N patterns (wire names and geometry).
        params: segmentation settings (:func:`brachycal.data.formats.plus_segmentation.read_segmentation_parameters`).
        source: the sequence's file, for messages and the frames' ``source``.
        label: what a frame index counts (``"CalibrationData Frame"``), for messages.
        orientation: label the wires as PLUS would in a frame of this orientation (``MF``, ``UF``,
            ``MN``, ``UN``; None: ``MF``, PLUS's labels, the frames being in ``MF`` as
            :func:`~brachycal.data.formats.metaimage.read_image_sequence` returns them). Another
            value mirrors the labels, for a phantom seen mirrored; the points stay the frames' pixels.
        progress: called with 1 after each frame.
        poses: the pose streams each frame carries (a tracker's by default); None reads no poses.
        require_poses: refuse a recording in which no frame has one of the streams
            (:func:`check_pose_fields`); frames without an OK pose are segmented all the same.

    Raises:
        InputError: frames that are not 8-bit (PLUS's fCal segments 8-bit B-mode only), a pose
            stream absent from every frame (with ``require_poses``), or a pose that is not 16
            numbers of a rigid transform (naming the frame and the field).
    """
    if sequence.pixels.dtype != np.uint8:
        raise InputError(f"expected 8-bit B-mode frames (MET_UCHAR / mono8), got {sequence.pixels.dtype}", file=source)
    if poses is not None and require_poses:
        check_pose_fields(sequence, poses, source)
    geometry = nwire_geometry(config.patterns)
    if orientation is None:
        orientation = MF
    frames: list[SegmentedFrame] = []
    reasons: list[str | None] = []
    for k in range(len(sequence)):
        fields = sequence.frame_fields[k] if k < len(sequence.frame_fields) else {}
        names = (poses or DEFAULT_POSES).fields  # images only: recorded as the tracker's, missing
        status = ("MISSING", "MISSING")
        T_probe = T_reference = None
        if poses is not None:
            T_probe = sequence_transform(fields, names[0], source, k)
            T_reference = sequence_transform(fields, names[1], source, k)
            status = (pose_status(fields, names[0]), pose_status(fields, names[1]))
        result = segment_frame(sequence.pixels[k], geometry, params, orientation=orientation)
        reasons.append(result.reason)
        frames.append(
            SegmentedFrame(
                k,
                result.points_px is not None,
                result.points_px or {},
                T_probe,
                T_reference,
                source=str(source),
                label=label,
                pose_status=status,
                pose_names=names,
            )
        )
        if progress is not None:
            progress(1)
    return SequenceSegmentation(frames, reasons, np.asarray(sequence.timestamps_s, dtype=float), poses)

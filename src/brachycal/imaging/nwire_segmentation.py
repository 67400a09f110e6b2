"""Segment a tracked B-mode sequence of an N-wire phantom into PLUS-style segmented frames.

Each frame: dot candidates (:mod:`brachycal.imaging.nwire_dots`), then the phantom's N pattern
(:mod:`brachycal.imaging.nwire_patterns`); with the frame's tracker readings (``ProbeToTracker``,
``ReferenceToTracker`` from the sequence's frame fields, millimetres → metres) it becomes a
:class:`~brachycal.data.formats.plus_files.SegmentedFrame`, which is what :func:`brachycal.calibration.
nwire_file.calibrate_nwire_files` calibrates from. A frame without a pattern, or without both tracker
readings, is kept with ``ok=False`` and its reason, and counted.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brachycal.data.formats.metaimage import ImageSequence
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame, sequence_transform
from brachycal.errors import InputError
from brachycal.imaging.nwire_dots import find_dots
from brachycal.imaging.nwire_parameters import NWireSegmentationParameters
from brachycal.imaging.nwire_patterns import ORIENTATIONS, NWireGeometry, PatternResult, find_pattern, nwire_geometry
from brachycal.se3 import FloatArray

#: The tracker readings a segmented frame carries (PLUS's frame-field names, ``<From>To<To>Transform``).
PROBE_TRANSFORM = "ProbeToTrackerTransform"
REFERENCE_TRANSFORM = "ReferenceToTrackerTransform"
#: Reason of a frame skipped for a missing (or not OK) tracker reading.
NO_TRACKING = "no OK ProbeToTracker and ReferenceToTracker readings"


def segment_frame(
    frame: np.ndarray, geometry: NWireGeometry, params: NWireSegmentationParameters, *, orientation: str = "MF"
) -> PatternResult:
    """The N pattern of one ``(H, W)`` uint8 frame: wire name → ``(u, v)`` pixel, or why not.

    ``orientation``: the frame's ultrasound orientation (:data:`~brachycal.imaging.nwire_patterns.ORIENTATIONS`).
    """
    return find_pattern(find_dots(frame, params), geometry, params, orientation=orientation)


def sequence_orientation(sequence: ImageSequence, source: str | os.PathLike[str]) -> str:
    """The sequence's ultrasound orientation: its header's ``UltrasoundImageOrientation`` (first two
    letters, PLUS writes e.g. ``MFA``), ``MF`` if the header has none.

    Raises:
        InputError: an orientation that is not one of :data:`~brachycal.imaging.nwire_patterns.ORIENTATIONS`.
    """
    text = sequence.fields.get("UltrasoundImageOrientation", "MF").strip().upper()
    if text[:2] not in ORIENTATIONS:
        raise InputError(
            f"expected one of {', '.join(ORIENTATIONS)} (PLUS's orientations), got {text!r}",
            file=source,
            column="UltrasoundImageOrientation",
        )
    return text[:2]


@dataclass(frozen=True)
class SequenceSegmentation:
    """A segmented sequence: one :class:`SegmentedFrame` per image frame, in order.

    Attributes:
        frames: every frame, ``ok=False`` where no pattern (or no tracking) was found.
        reasons: per frame, None if segmented, else why not.
        timestamps_s: ``(N,)`` frame times, seconds (NaN where the sequence has none).
    """

    frames: list[SegmentedFrame]
    reasons: list[str | None]
    timestamps_s: FloatArray

    @property
    def found(self) -> int:
        """Frames segmented."""
        return sum(reason is None for reason in self.reasons)

    @property
    def skipped(self) -> dict[str, int]:
        """Reason → number of frames skipped for it."""
        return dict(Counter(reason for reason in self.reasons if reason is not None))


def segment_sequence(
    sequence: ImageSequence,
    config: PlusConfig,
    params: NWireSegmentationParameters,
    *,
    source: str | os.PathLike[str],
    label: str = "frame",
    orientation: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> SequenceSegmentation:
    """Segment every frame of a tracked B-mode sequence of the configuration's N-wire phantom.

    Args:
        sequence: ``(N, H, W)`` uint8 frames with PLUS's per-frame fields (tracker readings in mm).
        config: the phantom's N patterns (wire names and geometry).
        params: segmentation settings (:func:`brachycal.data.formats.plus_segmentation.read_segmentation_parameters`).
        source: the sequence's file, for messages and the frames' ``source``.
        label: what a frame index counts (``"CalibrationData Frame"``), for messages.
        orientation: the frames' ultrasound orientation (``MF``, ``UF``, ``MN``, ``UN``), which says
            which dot is which wire; None: the header's (:func:`sequence_orientation`).
        progress: called with 1 after each frame.

    Raises:
        InputError: frames that are not 8-bit (PLUS's fCal segments 8-bit B-mode only), or a tracker
            reading that is not 16 numbers of a rigid transform (naming the frame and the field).
    """
    if sequence.pixels.dtype != np.uint8:
        raise InputError(f"expected 8-bit B-mode frames (MET_UCHAR / mono8), got {sequence.pixels.dtype}", file=source)
    geometry = nwire_geometry(config.patterns)
    if orientation is None:
        orientation = sequence_orientation(sequence, source)
    frames: list[SegmentedFrame] = []
    reasons: list[str | None] = []
    for k in range(len(sequence)):
        fields = sequence.frame_fields[k] if k < len(sequence.frame_fields) else {}
        T_tracker_probe = sequence_transform(fields, PROBE_TRANSFORM, source, k)
        T_tracker_reference = sequence_transform(fields, REFERENCE_TRANSFORM, source, k)
        if T_tracker_probe is None or T_tracker_reference is None:
            result = PatternResult(None, NO_TRACKING)
        else:
            result = segment_frame(sequence.pixels[k], geometry, params, orientation=orientation)
        reasons.append(result.reason)
        frames.append(
            SegmentedFrame(
                k,
                result.points_px is not None,
                result.points_px or {},
                T_tracker_probe,
                T_tracker_reference,
                source=str(source),
                label=label,
            )
        )
        if progress is not None:
            progress(1)
    return SequenceSegmentation(frames, reasons, np.asarray(sequence.timestamps_s, dtype=float))

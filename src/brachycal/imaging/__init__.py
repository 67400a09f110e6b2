"""Imaging: pixels of the ultrasound image as points of its frame ``us_image``, and back.

Units: pixels (``_px``) for image coordinates, metres per pixel for spacings, metres for points.

N-wire phantom segmentation as PLUS's fCal does it (imported on first use: SciPy): dot candidates
of a B-mode frame (:func:`find_dots`), the phantom's N patterns among them (:func:`find_pattern`,
:func:`nwire_geometry`), a whole tracked sequence (:func:`segment_sequence`), with PLUS's settings
(:class:`NWireSegmentationParameters`).

The water-tank bottom for temporal calibration: one bright line per B-mode frame, its offset to
sub-pixel (:func:`find_tank_line`, a :class:`TankLineTrack`).

A multi-wedge phantom's face lines in a B-mode frame, sub-pixel, each assigned to its face
(:func:`find_wedge_lines`; every bright line: :func:`find_lines`).

The needle tip in a B-mode frame, sub-pixel with a confidence (:func:`detect_tip`,
:func:`detect_tips`, a :class:`TipDetection`; frames below :data:`MIN_CONFIDENCE` are for a person).
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach
from brachycal.imaging.pixels import (
    DEFAULT_IMAGE_SIZE_PX,
    DEFAULT_SPACING_M,
    SCANNER_SOUND_SPEED_M_S,
    image_points,
    pixels,
)

if TYPE_CHECKING:  # N-wire segmentation: imported on first use (SciPy)
    from brachycal.imaging.needle_tip import MIN_CONFIDENCE, TipDetection, detect_tip, detect_tips
    from brachycal.imaging.nwire_dots import Dots, find_dots
    from brachycal.imaging.nwire_parameters import NWireSegmentationParameters
    from brachycal.imaging.nwire_patterns import NWireGeometry, PatternResult, find_pattern, nwire_geometry
    from brachycal.imaging.nwire_segmentation import SequenceSegmentation, segment_frame, segment_sequence
    from brachycal.imaging.tank_line import TankLineTrack, find_tank_line
    from brachycal.imaging.wedge_lines import find_lines, find_wedge_lines

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "DEFAULT_IMAGE_SIZE_PX",
    "DEFAULT_SPACING_M",
    "MIN_CONFIDENCE",
    "SCANNER_SOUND_SPEED_M_S",
    "Dots",
    "NWireGeometry",
    "NWireSegmentationParameters",
    "PatternResult",
    "SequenceSegmentation",
    "TankLineTrack",
    "TipDetection",
    "detect_tip",
    "detect_tips",
    "find_dots",
    "find_lines",
    "find_pattern",
    "find_tank_line",
    "find_wedge_lines",
    "image_points",
    "nwire_geometry",
    "pixels",
    "segment_frame",
    "segment_sequence",
]

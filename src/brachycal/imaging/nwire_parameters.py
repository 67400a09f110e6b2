"""Fixed tolerances of N-wire phantom segmentation, and its settings' type.

The settings a device set gives (PLUS fCal's ``<Segmentation>`` element) are a
:class:`~brachycal.data.formats.plus_segmentation.NWireSegmentationParameters` (metres, radians), defined
with its reader in the data layer; the tolerances here are those PLUS hard-codes.
"""

from __future__ import annotations

from brachycal.data.formats.plus_segmentation import NWireSegmentationParameters

__all__ = [
    "EDGE_MARGIN_PX",
    "MIDDLE_DISTANCE_TOLERANCE_M",
    "SIDE_DISTANCE_TOLERANCE_M",
    "NWireSegmentationParameters",
]

#: Tolerance on the distance between the two side wires of an N in the image, metres. PLUS's fCal
#: hard-codes 4 mm (``m_MaxLineLengthToleranceMm``): the side-to-side distance in the image grows as
#: 1/cos of the angle between the image plane and the wires' normal plane, so 4 mm on fCal 2.0's
#: 30 mm accepts tilts up to ~30°, and still refuses a pair of dots from two different Ns.
SIDE_DISTANCE_TOLERANCE_M = 4e-3
#: Tolerance on where the middle (diagonal) wire's dot lies from the first side wire's dot, metres.
#: PLUS hard-codes 15 mm: on fCal 2.0 (middle wire half-way along the 30 mm N) it only asks the
#: dot to lie between the two side dots — which is all the N geometry guarantees, since the
#: diagonal's dot moves from one side to the other as the image plane slides along the wires.
MIDDLE_DISTANCE_TOLERANCE_M = 15e-3
#: Distance (pixels) a dot's centroid must keep from the clip rectangle's edges (PLUS's
#: ``MIN_WINDOW_DIST``): a blob cut by the edge has a centroid pulled inwards.
EDGE_MARGIN_PX = 8

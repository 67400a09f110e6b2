"""Imaging: pixels of the ultrasound image as points of its frame ``us_image``, and back.

Units: pixels (``_px``) for image coordinates, metres per pixel for spacings, metres for points.
"""

from brachycal.imaging.pixels import (
    DEFAULT_IMAGE_SIZE_PX,
    DEFAULT_SPACING_M,
    SCANNER_SOUND_SPEED_M_S,
    image_points,
    pixels,
)

__all__ = ["DEFAULT_IMAGE_SIZE_PX", "DEFAULT_SPACING_M", "SCANNER_SOUND_SPEED_M_S", "image_points", "pixels"]

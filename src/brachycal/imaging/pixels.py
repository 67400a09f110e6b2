"""The ultrasound image frame ``us_image``: pixels as points, points as pixels, the scanner's figures.

Image frame I (``docs/conventions.md``): origin at the centre of pixel (0, 0), x along the image
columns (u grows to the right), y along the rows (v grows downward, with depth), z = x × y. A
pixel ``(u, v)`` is the point ``(u·s_u, v·s_v, 0)`` of I, with the pixel spacing ``(s_u, s_v)`` in
metres per pixel. Every conversion between pixels and points of I goes through this module.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from brachycal.se3 import FloatArray

#: The paper's scanner: 0.19 mm per pixel along u and v, ``(s_u, s_v)`` in metres per pixel. The
#: nominal spacing wherever none is given (planning, the twin, scenes).
DEFAULT_SPACING_M: tuple[float, float] = (0.19e-3, 0.19e-3)
#: The paper's image size, ``(width, height)`` in pixels.
DEFAULT_IMAGE_SIZE_PX: tuple[int, int] = (1080, 720)
#: Speed of sound a scanner assumes when it turns echo times into depths, m/s (soft tissue): in
#: a medium of speed ``c`` a depth pixel is really ``c / 1540`` of its stated spacing.
SCANNER_SOUND_SPEED_M_S = 1540.0


def image_points(uv_px: ArrayLike, spacing_m: ArrayLike, elevation_m: ArrayLike = 0.0) -> FloatArray:
    """``p_I (N, 3)``: pixels ``(N, 2)`` (or one ``(2,)``) as points of the image frame, metres.

    Args:
        uv_px: ``(u, v)`` pixel coordinates.
        spacing_m: ``(2,)`` pixel spacing ``(s_u, s_v)``, metres per pixel.
        elevation_m: ``z`` of the points, a scalar or ``(N,)``: their distance from the image plane
            (0 for a point in the plane; the twin uses it for the beam's thickness), metres.
    """
    uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
    z = np.broadcast_to(np.asarray(elevation_m, dtype=float), (len(uv),))
    return np.column_stack([uv * np.asarray(spacing_m, dtype=float), z])


def pixels(p_I: ArrayLike, spacing_m: ArrayLike) -> FloatArray:
    """``uv_px (N, 2)``: where points of the image frame ``(N, 3)`` (or ``(N, 2)``) show, pixels.

    The inverse of :func:`image_points` in the plane: a point's elevation is dropped.
    """
    p = np.atleast_2d(np.asarray(p_I, dtype=float))
    return p[:, :2] / np.asarray(spacing_m, dtype=float)

"""Wire dots in one B-mode frame: candidates for the wire intersections of an N-wire phantom.

A wire crossing the image plane shows as a small bright blob (~0.5 mm) among speckle and long
bright structures (the phantom's walls, reverberations). The steps follow PLUS's fCal
(``PlusFidSegmentation``), written here with :mod:`scipy.ndimage`:

1. four white top-hats with flat bars of ``2·bar_px + 1`` pixels at 0°, 45°, 90° and 135°: the
   grey opening by a bar keeps only what is at least a bar long in that direction, so the image
   minus its opening keeps what is shorter — dots survive all four, lines and walls do not;
2. a grey opening by a disc of ``circle_radius_px``: removes speckle smaller than a dot;
3. everything outside the clip rectangle is dropped; pixels below ``min + fraction · (max − min)``
   of what is left are dropped;
4. each 8-connected region left is a candidate: its centroid weighted by the processed intensities
   (sub-pixel, pixel centres at whole numbers as in PLUS and ``docs/conventions.md``), its score
   the sum of those intensities (/255), the brightest :attr:`~NWireSegmentationParameters.max_candidates` kept.

Pixel coordinates ``(u, v)``: u along columns, v along rows; frames are ``(H, W)`` arrays ``frame[v, u]``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from brachycal.imaging.nwire_parameters import EDGE_MARGIN_PX, NWireSegmentationParameters
from brachycal.se3 import FloatArray

_EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class Dots:
    """Dot candidates of one frame, brightest first.

    Attributes:
        uv_px: ``(K, 2)`` intensity-weighted centroids ``(u, v)``, pixels.
        intensity: ``(K,)`` scores (sum of the processed intensities / 255), descending.
        found: candidates before keeping the brightest ``max_candidates`` (≥ K).
    """

    uv_px: FloatArray
    intensity: FloatArray
    found: int


def region_of_interest(shape: tuple[int, int], params: NWireSegmentationParameters) -> tuple[int, int, int, int]:
    """``(u0, v0, u1, v1)``: the searched part of a ``(H, W)`` frame, ``[u0, u1) × [v0, v1)``.

    The clip rectangle, kept a bar's length inside the frame so that every opening sees whole bars
    (as PLUS does); the whole frame less that margin without a clip rectangle. Empty (u1 ≤ u0 or
    v1 ≤ v0) if the frame is smaller than a bar.
    """
    height, width = shape
    bar = params.bar_px
    if params.clip_origin_px is None or params.clip_size_px is None:
        u0, v0, u1, v1 = 0, 0, width, height
    else:
        u0, v0 = params.clip_origin_px
        u1, v1 = u0 + params.clip_size_px[0], v0 + params.clip_size_px[1]
    u0, v0 = max(u0, bar + 1), max(v0, bar + 1)
    u1, v1 = min(u1, width - bar - 1), min(v1, height - bar - 1)
    return u0, v0, u1, v1


def _skew_indices(shape: tuple[int, int], direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices that shear a ``(H, W)`` frame so that one diagonal becomes a column.

    ``direction`` +1: the anti-diagonal (down-left to up-right) lines up; −1: the main diagonal.
    """
    height, width = shape
    rows = np.arange(height)[:, None]
    shift = rows if direction > 0 else (height - 1 - rows)
    cols = np.arange(width)[None, :] + shift
    return np.broadcast_to(rows, shape), cols


def _bar_opening(image: np.ndarray, half_length: int, angle_deg: int) -> np.ndarray:
    """Grey opening of a uint8 ``(H, W)`` image by a flat bar of ``2·half_length + 1`` pixels."""
    size = 2 * half_length + 1
    if angle_deg == 0:
        eroded = ndimage.minimum_filter1d(image, size, axis=1, mode="constant", cval=255)
        return ndimage.maximum_filter1d(eroded, size, axis=1, mode="constant", cval=0)
    if angle_deg == 90:
        eroded = ndimage.minimum_filter1d(image, size, axis=0, mode="constant", cval=255)
        return ndimage.maximum_filter1d(eroded, size, axis=0, mode="constant", cval=0)
    # A diagonal bar: shear so the diagonal is a column, filter along columns, shear back. Cells of
    # the sheared array outside the frame count as "absent": 255 for the minimum, 0 for the maximum.
    height, width = image.shape
    rows, cols = _skew_indices(image.shape, +1 if angle_deg == 45 else -1)
    sheared = np.full((height, width + height - 1), 255, dtype=image.dtype)
    sheared[rows, cols] = image
    eroded = ndimage.minimum_filter1d(sheared, size, axis=0, mode="constant", cval=255)
    inside = np.zeros(sheared.shape, dtype=bool)
    inside[rows, cols] = True
    eroded[~inside] = 0
    opened = ndimage.maximum_filter1d(eroded, size, axis=0, mode="constant", cval=0)
    return opened[rows, cols]


def _disc_filter(
    image: np.ndarray,
    radius: int,
    row_filter: Callable[..., np.ndarray],
    pick: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> np.ndarray:
    """Grey erosion (``minimum_filter1d``, ``np.minimum``) or dilation (maximum) by a disc of ``radius``
    pixels (the pixels within ``radius`` of the centre), edges replicated.

    A disc is a stack of rows of half-widths ``⌊√(r² − dy²)⌋``: a 1D filter per distinct width and
    one shifted min (or max) per row, rather than a 2D filter over the whole footprint.
    """
    height = image.shape[0]
    by_width: dict[int, np.ndarray] = {}
    padded = np.pad(image, ((radius, radius), (0, 0)), mode="edge")
    out: np.ndarray | None = None
    for dy in range(-radius, radius + 1):
        half = int(np.floor(np.sqrt(radius**2 - dy**2)))
        if half not in by_width:
            by_width[half] = row_filter(padded, 2 * half + 1, axis=1, mode="nearest")
        rows = by_width[half][radius + dy : radius + dy + height]
        out = rows.copy() if out is None else pick(out, rows)
    assert out is not None
    return out


def _disc_opening(image: np.ndarray, radius: int) -> np.ndarray:
    """Grey opening of a ``(H, W)`` image by a flat disc of ``radius`` pixels (edges replicated)."""
    eroded = _disc_filter(image, radius, ndimage.minimum_filter1d, np.minimum)
    return _disc_filter(eroded, radius, ndimage.maximum_filter1d, np.maximum)


def dot_image(frame: np.ndarray, params: NWireSegmentationParameters) -> np.ndarray:
    """The processed ``(H, W)`` uint8 image whose bright regions are dot candidates (steps 1–3).

    Args:
        frame: ``(H, W)`` uint8 B-mode frame.
        params: segmentation settings (bar and disc sizes, clip rectangle, threshold).
    """
    if frame.ndim != 2 or frame.dtype != np.uint8:
        raise ValueError(f"expected a (H, W) uint8 frame, got {frame.dtype} {frame.shape}")
    work = frame.copy()
    u0, v0, u1, v1 = region_of_interest(frame.shape, params)
    if u1 <= u0 or v1 <= v0:
        return np.zeros_like(frame)
    for angle in (0, 45, 90, 135):
        # opening <= image pointwise, so the difference is the (non-negative) white top-hat
        work = work - _bar_opening(work, params.bar_px, angle)
    work = _disc_opening(work, params.circle_radius_px)
    inside = np.zeros(frame.shape, dtype=bool)
    inside[v0:v1, u0:u1] = True
    work[~inside] = 0
    low, high = int(work.min()), int(work.max())
    threshold = low + int(np.floor((high - low) * params.threshold_fraction + 0.5))
    work[work < threshold] = 0
    return work


def find_dots(frame: np.ndarray, params: NWireSegmentationParameters) -> Dots:
    """Dot candidates of one ``(H, W)`` uint8 frame, brightest first (see the module's steps).

    A candidate whose centroid lies within :data:`EDGE_MARGIN_PX` of the searched rectangle's edge
    is dropped (a blob cut by the edge has a biased centroid).
    """
    work = dot_image(frame, params)
    labels, count = ndimage.label(work > 0, structure=_EIGHT_CONNECTED)
    if count == 0:
        return Dots(np.zeros((0, 2)), np.zeros(0), 0)
    v_index, u_index = np.nonzero(labels)
    label = labels[v_index, u_index]
    weight = work[v_index, u_index].astype(float) / 255.0
    total = np.bincount(label, weight, minlength=count + 1)[1:]
    u = np.bincount(label, weight * u_index, minlength=count + 1)[1:] / total
    v = np.bincount(label, weight * v_index, minlength=count + 1)[1:] / total
    if params.use_original_intensity:
        # PLUS's alternative score: the original image's intensities within 3 px of the centroid
        near = (u_index - u[label - 1]) ** 2 + (v_index - v[label - 1]) ** 2 <= 9.0
        original = frame[v_index, u_index].astype(float) / 255.0 * near
        total = np.bincount(label, original, minlength=count + 1)[1:]
    u0, v0, u1, v1 = region_of_interest(frame.shape, params)
    keep = (
        (u >= u0 + EDGE_MARGIN_PX) & (u < u1 - EDGE_MARGIN_PX) & (v >= v0 + EDGE_MARGIN_PX) & (v < v1 - EDGE_MARGIN_PX)
    )
    uv, score = np.column_stack([u, v])[keep], total[keep]
    order = np.argsort(-score, kind="stable")[: params.max_candidates]
    return Dots(uv[order].astype(float), score[order].astype(float), int(keep.sum()))

"""The water-tank bottom in B-mode frames: one bright straight line per frame, found to sub-pixel.

Temporal calibration (:mod:`brachycal.calibration.temporal`) images the flat bottom of a water
tank while the probe moves up and down; the line's position in each frame is the image side of
the motion. Method (after PLUS's ``vtkPlusLineSegmentationAlgo``, re-derived):

1. ``scanlines`` image columns evenly spaced over the clip rectangle; along each, the brightest
   ridge: the run of pixels above half the column's maximum with the largest summed intensity,
   located at its intensity-weighted centre (sub-pixel). Columns whose maximum is below
   ``min_ridge_fraction`` of the frame's brightest column hold no echo of the bottom (beyond the
   line's ends) and are dropped.
2. A robust line through the ridge points: every pair of points proposes a line, the one with most
   points within ``inlier_px`` wins, and the inliers are refitted by total least squares.
3. The line's position: its signed distance from the clip rectangle's centre along its unit
   normal (the normal taken pointing down the image, ``n_v > 0``), in pixels. A probe moved along
   the tank's normal moves the line by the same distance along the line's normal. Measured from
   the rectangle's centre, not the image origin: a probe that also tilts turns the line about the
   imaged region, and the distance from a far-away origin would mix that rotation into the
   position (on PLUS's recording the lag moves by 78 ms when measured from pixel (0, 0)).

A frame is reported without a line (``detected`` false, with the reason) when fewer than
``min_points`` ridge points agree on a line, or the line is within 45° of vertical (the bottom
of a tank seen by a probe facing it is near horizontal; a steep "line" is a wall or clutter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

#: PLUS's number of scanlines.
DEFAULT_SCANLINES = 40
#: PLUS's fewest valid scanlines for a line.
MIN_POINTS = 5
#: Ridge points farther than this from the line are outliers (pixels). The bottom's echo is a few
#: pixels thick and its centre of gravity wanders by about a pixel along its speckle.
INLIER_PX = 2.0
#: A column whose brightest pixel is below this fraction of the frame's brightest column has no
#: echo of the bottom (B-mode noise is a few percent of the bottom's echo).
MIN_RIDGE_FRACTION = 0.25


@dataclass(frozen=True)
class TankLineTrack:
    """The tank bottom in every frame of a sequence.

    Attributes:
        offset_px: ``(N,)`` signed distance of the line from the clip rectangle's centre along its
            downward unit normal, pixels (NaN where not detected).
        v_mid_px: ``(N,)`` the line's row at the clip rectangle's middle column, pixels (PLUS's
            position metric; NaN where not detected).
        angle_rad: ``(N,)`` the line's angle from the image's u axis, radians (NaN where not detected).
        rms_px: ``(N,)`` RMS distance of the inlier ridge points from the line, pixels.
        inliers: ``(N,)`` ridge points on the line.
        detected: ``(N,)`` whether a line was found.
        reasons: per frame, why no line was found (empty string when found).
    """

    offset_px: FloatArray
    v_mid_px: FloatArray
    angle_rad: FloatArray
    rms_px: FloatArray
    inliers: np.ndarray
    detected: np.ndarray
    reasons: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.detected.shape[0])


def _clip(
    shape: tuple[int, int], origin: tuple[int, int] | None, size: tuple[int, int] | None
) -> tuple[int, int, int, int]:
    height, width = shape
    u0, v0 = origin if origin is not None else (0, 0)
    w, h = size if size is not None else (width - u0, height - v0)
    if min(u0, v0) < 0 or w < 2 or h < 2 or u0 + w > width or v0 + h > height:
        raise InputError(
            f"the clip rectangle (origin ({u0}, {v0}), size ({w}, {h})) is not inside the {width}x{height} frames"
        )
    return u0, v0, w, h


def _ridge(profile: FloatArray) -> float | None:
    """Sub-pixel centre of the strongest bright run along one column (index along the profile)."""
    top = profile.max()
    if top <= 0:
        return None
    above = profile > 0.5 * top
    edges = np.diff(np.concatenate([[0], above.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    areas = np.add.reduceat(np.where(above, profile, 0.0), starts) if starts.size else np.empty(0)
    if starts.size == 0:
        return None
    k = int(np.argmax(areas))
    run = profile[starts[k] : ends[k]]
    return float(starts[k] + (run @ np.arange(run.size)) / run.sum())


def _total_least_squares(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit normal ``(2,)`` and centroid ``(2,)`` of the line closest to ``(K, 2)`` points (orthogonal distances)."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre)
    return vt[1], centre


def _fit(points: FloatArray, inlier_px: float) -> tuple[FloatArray, float, FloatArray] | None:
    """Robust line ``(unit normal (2,), offset, inlier mask)`` through ``(K, 2)`` points ``(u, v)``."""
    k = points.shape[0]
    i, j = np.triu_indices(k, 1)
    direction = points[j] - points[i]
    length = np.linalg.norm(direction, axis=1)
    keep = length > 0
    i, j, direction, length = i[keep], j[keep], direction[keep], length[keep]
    if i.size == 0:
        return None
    normals = np.column_stack([-direction[:, 1], direction[:, 0]]) / length[:, None]
    distances = np.abs(points @ normals.T - np.sum(normals * points[i], axis=1))
    counts = (distances <= inlier_px).sum(axis=0)
    best = int(np.argmax(counts))
    mask = distances[:, best] <= inlier_px
    for _ in range(3):  # refit on the inliers, re-select them with the refined line
        normal, centre = _total_least_squares(points[mask])
        new_mask = np.abs((points - centre) @ normal) <= inlier_px
        if new_mask.sum() < 2 or np.array_equal(new_mask, mask):
            break
        mask = new_mask
    else:  # the last re-selection changed the inliers: the line returned is fitted on those returned
        normal, centre = _total_least_squares(points[mask])
    if normal[1] < 0:
        normal = -normal
    return normal, float(normal @ centre), mask


def find_tank_line(
    pixels: ArrayLike,
    *,
    clip_origin: tuple[int, int] | None = None,
    clip_size: tuple[int, int] | None = None,
    scanlines: int = DEFAULT_SCANLINES,
    inlier_px: float = INLIER_PX,
    min_points: int = MIN_POINTS,
    min_ridge_fraction: float = MIN_RIDGE_FRACTION,
) -> TankLineTrack:
    """The tank-bottom line in every frame (module docstring for the method).

    Args:
        pixels: ``(N, H, W)`` or ``(H, W)`` B-mode frames (``pixels[k, v, u]``).
        clip_origin: ``(u, v)`` of the searched rectangle's first pixel (PLUS's ``ClipRectangleOrigin``).
        clip_size: ``(width, height)`` of the rectangle in pixels (PLUS's ``ClipRectangleSize``).
        scanlines: columns searched per frame.
        inlier_px: largest distance of a ridge point from the line, pixels.
        min_points: fewest ridge points on a line.
        min_ridge_fraction: a column's maximum must reach this fraction of the frame's brightest.

    Returns:
        The :class:`TankLineTrack`, positions in pixels of the full image (not the clip).

    Raises:
        InputError: frames that are not ``(N, H, W)``, or a clip rectangle outside them.
    """
    frames = np.asarray(pixels)
    if frames.ndim == 2:
        frames = frames[None]
    if frames.ndim != 3 or frames.shape[0] == 0:
        raise InputError(f"expected (N, H, W) frames, got shape {frames.shape}")
    if scanlines < min_points or min_points < 2:
        raise InputError(f"scanlines={scanlines}: need at least {max(min_points, 2)} scanlines per frame")
    u0, v0, w, h = _clip(frames.shape[1:], clip_origin, clip_size)
    columns = np.round(u0 + np.linspace(0, w - 1, scanlines)).astype(int)
    u_mid, v_centre = u0 + 0.5 * (w - 1), v0 + 0.5 * (h - 1)
    n = frames.shape[0]
    offset, v_mid, angle, rms = (np.full(n, np.nan) for _ in range(4))
    inliers = np.zeros(n, dtype=int)
    reasons: list[str] = []
    for f in range(n):
        profiles = frames[f, v0 : v0 + h][:, columns].astype(float)  # (h, S)
        tops = profiles.max(axis=0)
        bright = tops >= min_ridge_fraction * tops.max() if tops.max() > 0 else np.zeros_like(tops, dtype=bool)
        points = [
            (float(columns[s]), v0 + r) for s in np.flatnonzero(bright) if (r := _ridge(profiles[:, s])) is not None
        ]
        if len(points) < min_points:
            reasons.append(f"{len(points)} bright columns, need {min_points}")
            continue
        fit = _fit(np.array(points), inlier_px)
        if fit is None or fit[2].sum() < min_points:
            reasons.append(f"fewer than {min_points} ridge points on one line")
            continue
        normal, distance, mask = fit
        if normal[1] < np.sqrt(0.5):
            reasons.append("the line is steeper than 45 degrees: not a tank bottom")
            continue
        P = np.array(points)[mask]
        offset[f] = distance - normal @ (u_mid, v_centre)
        v_mid[f] = (distance - normal[0] * u_mid) / normal[1]
        angle[f] = float(np.arctan2(-normal[0], normal[1]))
        rms[f] = float(np.sqrt(np.mean((P @ normal - distance) ** 2)))
        inliers[f] = int(mask.sum())
        reasons.append("")
    detected = np.isfinite(offset)
    return TankLineTrack(offset, v_mid, angle, rms, inliers, detected, tuple(reasons))

"""A multi-wedge phantom's face lines in a B-mode frame, sub-pixel, each assigned to its face.

Pixels of the image frame (``u`` along columns, ``v`` along rows); each line is given by its two
ends, as the observations file holds them (``u0_px,v0_px,u1_px,v1_px``).

Design: ``docs/design/image_analysis.md``, "A multi-wedge phantom's face lines".
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

__all__ = [
    "INLIER_PX",
    "MAX_GAP_PX",
    "MAX_SLOPE",
    "MIN_COLUMNS",
    "SMOOTH_SD_PX",
    "THRESHOLD_DB",
    "find_lines",
    "find_wedge_lines",
]

#: Gaussian smoothing before the search, SD ``(lateral, axial)`` pixels (the renderer's PSF SDs are
#: ~1.8 and ~0.8 px at 0.19 mm/px).
SMOOTH_SD_PX = (2.0, 0.7)
#: A candidate stands this far above the sector's median grey, dB (module docstring).
THRESHOLD_DB = 12.0
#: RANSAC inlier distance (perpendicular), pixels: a few times the candidates' sub-pixel scatter.
INLIER_PX = 1.5
#: Longest run of columns without a candidate inside one line, pixels.
MAX_GAP_PX = 12
#: Fewest columns of a line (~4 mm at 0.19 mm/px: a third of a face's 12 mm width).
MIN_COLUMNS = 20
#: Steepest line taken for a face, |dv/du| (60°).
MAX_SLOPE = float(np.tan(np.radians(60.0)))
_TRIALS = 300
_MAX_LINES = 12


def _candidates(frame: np.ndarray, dynamic_range_db: float) -> FloatArray:
    """``(M, 2)`` sub-pixel ``(u, v)`` of the columns' local maxima above the threshold."""
    from scipy.ndimage import gaussian_filter  # lazy: start-up (scipy)

    grey = frame.astype(np.float32)
    inside = grey > 0  # the renderer's sector is black outside
    if not np.any(inside):
        return np.zeros((0, 2))
    smooth = gaussian_filter(grey, sigma=(SMOOTH_SD_PX[1], SMOOTH_SD_PX[0]))
    threshold = float(np.median(grey[inside])) + THRESHOLD_DB * 255.0 / dynamic_range_db
    up, mid, down = smooth[:-2], smooth[1:-1], smooth[2:]
    peak = (mid > up) & (mid >= down) & (mid > threshold) & inside[1:-1]
    v, u = np.nonzero(peak)
    a, b, c = up[v, u], mid[v, u], down[v, u]
    denominator = a - 2.0 * b + c
    offset = np.where(denominator < 0, 0.5 * (a - c) / np.where(denominator < 0, denominator, -1.0), 0.0)
    return np.column_stack([u.astype(float), v + 1 + np.clip(offset, -0.5, 0.5)])


def _fit(points: FloatArray) -> tuple[float, float]:
    """Least-squares ``v = a + b·u`` over ``points (K, 2)``."""
    A = np.column_stack([np.ones(len(points)), points[:, 0]])
    (a, b), *_ = np.linalg.lstsq(A, points[:, 1], rcond=None)
    return float(a), float(b)


def _inliers(points: FloatArray, a: float, b: float) -> np.ndarray:
    """Indices of ``points`` within :data:`INLIER_PX` of ``v = a + b·u``, the nearest one per column."""
    distance = np.abs(points[:, 1] - (a + b * points[:, 0])) / np.hypot(1.0, b)
    near = np.flatnonzero(distance < INLIER_PX)
    if near.size == 0:
        return near
    # One candidate per column: the nearest (a column can hold candidates of other lines).
    order = near[np.lexsort((distance[near], points[near, 0]))]
    _, first = np.unique(points[order, 0], return_index=True)
    return order[first]


def _longest_run(points: FloatArray, index: np.ndarray) -> np.ndarray:
    """The indices of the longest run of ``index``'s columns without a gap over :data:`MAX_GAP_PX`."""
    index = index[np.argsort(points[index, 0])]
    breaks = np.flatnonzero(np.diff(points[index, 0]) > MAX_GAP_PX)
    runs = np.split(index, breaks + 1)
    return max(runs, key=len)


def _lines(points: FloatArray, rng: np.random.Generator) -> list[tuple[float, float, float, float]]:
    """Sequential RANSAC: ``(a, b, u_first, u_last)`` of each line found."""
    found = []
    remaining = points
    for _ in range(_MAX_LINES):
        if len(remaining) < MIN_COLUMNS:
            break
        best: np.ndarray | None = None
        pairs = rng.integers(0, len(remaining), size=(_TRIALS, 2))
        for i, j in pairs:
            (u0, v0), (u1, v1) = remaining[i], remaining[j]
            if abs(u1 - u0) < MIN_COLUMNS / 2:
                continue
            b = (v1 - v0) / (u1 - u0)
            if abs(b) > MAX_SLOPE:
                continue
            inliers = _inliers(remaining, v0 - b * u0, b)
            if best is None or len(inliers) > len(best):
                best = inliers
        if best is None or len(best) < MIN_COLUMNS:
            break
        a, b = _fit(remaining[best])
        run = _longest_run(remaining, _inliers(remaining, a, b))
        if len(run) < MIN_COLUMNS:
            break
        a, b = _fit(remaining[run])
        run = _longest_run(remaining, _inliers(remaining, a, b))
        if len(run) >= MIN_COLUMNS and abs(b) <= MAX_SLOPE:
            found.append((a, b, float(remaining[run, 0].min()), float(remaining[run, 0].max())))
        remaining = np.delete(remaining, run, axis=0)
    return found


def find_lines(frame: np.ndarray, *, dynamic_range_db: float = 60.0, seed: int = 0) -> FloatArray:
    """Every bright straight line of a B-mode frame (steps 1 and 2 of the module docstring).

    Args:
        frame: ``(H, W)`` uint8 B-mode frame (``frame[v, u]``; black outside the sector).
        dynamic_range_db: the display's dynamic range (grey 0–255 spans it), dB.
        seed: RANSAC's generator.

    Returns:
        ``(L, 2, 2)`` each line's two ends ``[[u0, v0], [u1, v1]]``, pixels, sorted left to right by
        their middle (``(0, 2, 2)`` when there is none).

    Raises:
        InputError: a frame that is not 2D.
    """
    frame = np.asarray(frame)
    if frame.ndim != 2:
        raise InputError(f"a B-mode frame must be 2D (H, W), got shape {frame.shape}")
    lines = _lines(_candidates(frame, dynamic_range_db), np.random.default_rng(seed))
    lines.sort(key=lambda line: line[2] + line[3])
    return np.array([[[u0, a + b * u0], [u1, a + b * u1]] for a, b, u0, u1 in lines]).reshape(-1, 2, 2)


def find_wedge_lines(
    frame: np.ndarray,
    faces: Sequence[str],
    slopes: Sequence[int],
    *,
    dynamic_range_db: float = 60.0,
    seed: int = 0,
) -> dict[str, FloatArray] | None:
    """Each face's line in a B-mode frame, or ``None`` when not every face is found (module docstring).

    Args:
        frame: ``(H, W)`` uint8 B-mode frame (``frame[v, u]``; black outside the sector).
        faces: the face names, left to right as the nominal scan shows them.
        slopes: ``(len(faces),)`` the sign of each face's ``dv/du`` in the nominal scan (±1).
        dynamic_range_db: the display's dynamic range (grey 0–255 spans it), dB.
        seed: RANSAC's generator.

    Returns:
        ``{face: (2, 2) [[u0, v0], [u1, v1]]}`` pixels, the line's two ends, for every face; ``None``
        when the lines found are not as many as the faces or a slope's sign disagrees.

    Raises:
        InputError: a frame that is not 2D, or ``slopes`` not one per face.
    """
    if len(slopes) != len(faces):
        raise InputError(f"{len(slopes)} slope signs for {len(faces)} faces")
    lines = find_lines(frame, dynamic_range_db=dynamic_range_db, seed=seed)
    if len(lines) != len(faces):
        return None
    out = {}
    for name, sign, ends in zip(faces, slopes, lines, strict=True):
        if np.sign(ends[1, 1] - ends[0, 1]) != sign:
            return None
        out[name] = ends
    return out

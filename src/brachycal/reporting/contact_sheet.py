"""Contact sheet of needle-tip detections: every frame, cropped around its proposed tip.

One tile per frame (a square crop of the frame centred on the proposed tip), the proposed tip as a
cross coloured by its confidence (green at or above the threshold, red below: those frames are to
be annotated by a person), the true tip as a circle where it is known (the twin), and the frame's
number and confidence in its title. The builder returns a :class:`matplotlib.figure.Figure` and
touches neither pyplot, the backend nor ``rcParams``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

from brachycal.reporting.figures import save_figure

__all__ = ["contact_sheet", "contact_sheet_figure"]

#: Side of a tile's crop, pixels (15 mm at 0.19 mm/px: the tip, its shaft and its shadow).
CROP_PX = 80
#: Tiles per row of the sheet.
COLUMNS = 8


def contact_sheet_figure(
    frames: np.ndarray,
    proposed_px: ArrayLike,
    confidence: ArrayLike,
    *,
    min_confidence: float,
    true_px: ArrayLike | None = None,
    labels: Sequence[str] | None = None,
) -> Figure:
    """The contact sheet of ``frames`` ``(N, H, W)`` with their proposed tips.

    Args:
        frames: ``(N, H, W)`` grey frames (``frames[k, v, u]``).
        proposed_px: ``(N, 2)`` proposed tips ``(u, v)``, pixels (NaN: none; the tile shows the frame's centre).
        confidence: ``(N,)`` confidences in [0, 1].
        min_confidence: frames below it are drawn in red (to be annotated).
        true_px: ``(N, 2)`` true tips, pixels, where known (the twin), else ``None``.
        labels: ``(N,)`` tile titles (default the frame numbers from 1).
    """
    n, height, width = frames.shape
    proposed = np.asarray(proposed_px, dtype=float).reshape(n, 2)
    conf = np.asarray(confidence, dtype=float).reshape(n)
    truth = None if true_px is None else np.asarray(true_px, dtype=float).reshape(n, 2)
    names = list(labels) if labels is not None else [str(k + 1) for k in range(n)]
    columns = min(COLUMNS, max(n, 1))
    rows = max(math.ceil(n / columns), 1)
    fig = Figure(figsize=(1.6 * columns, 1.75 * rows + 0.4), layout="constrained")
    flagged = int(np.sum(conf < min_confidence))
    fig.suptitle(
        f"{n} frames, proposed tip (+), {flagged} below confidence {min_confidence:g} in red"
        + (", true tip (o)" if truth is not None else ""),
        fontsize=9,
    )
    half = CROP_PX // 2
    for k in range(n):
        ax = fig.add_subplot(rows, columns, k + 1)
        centre = proposed[k] if np.all(np.isfinite(proposed[k])) else np.array([width / 2, height / 2])
        u0 = int(np.clip(round(centre[0]) - half, 0, max(width - CROP_PX, 0)))
        v0 = int(np.clip(round(centre[1]) - half, 0, max(height - CROP_PX, 0)))
        crop = frames[k, v0 : v0 + CROP_PX, u0 : u0 + CROP_PX]
        # Pixel (u, v) is the centre of its square: the image spans u0 - 0.5 .. u0 + width - 0.5.
        extent = (u0 - 0.5, u0 + crop.shape[1] - 0.5, v0 + crop.shape[0] - 0.5, v0 - 0.5)
        ax.imshow(crop, cmap="gray", vmin=0, vmax=255, extent=extent, interpolation="nearest")
        colour = "lime" if conf[k] >= min_confidence else "red"
        if truth is not None and np.all(np.isfinite(truth[k])):
            ax.plot(*truth[k], "o", mfc="none", mec="cyan", ms=8, mew=1.0)
        if np.all(np.isfinite(proposed[k])):
            ax.plot(*proposed[k], "+", color=colour, ms=9, mew=1.2)
        ax.set_title(f"{names[k]}  {conf[k]:.2f}", fontsize=7, color="black" if colour == "lime" else "red")
        ax.set_xticks([])
        ax.set_yticks([])
    return fig


def contact_sheet(
    path: str | os.PathLike[str],
    frames: np.ndarray,
    proposed_px: ArrayLike,
    confidence: ArrayLike,
    *,
    min_confidence: float,
    true_px: ArrayLike | None = None,
    labels: Sequence[str] | None = None,
    dpi: int = 110,
) -> None:
    """Write :func:`contact_sheet_figure` as a PNG (or any format matplotlib knows from the suffix)."""
    fig = contact_sheet_figure(
        frames, proposed_px, confidence, min_confidence=min_confidence, true_px=true_px, labels=labels
    )
    save_figure(fig, path, dpi=dpi)

"""A small synthetic PLUS water-tank recording (video + tracker sequence files) with a known lag.

The probe bobs along the tracker's z axis (two incommensurate periods, ±20 mm); the video frames
(10 Hz, 120×160 px) show the tank bottom as a bright horizontal band that moves 2 px per mm, up
when the probe moves down. The tracker stamps each instant ``lag_s`` later than the video does
(PLUS's TrackerLagSec = ``lag_s``). Deterministic (no noise): the example files' temporal pair
(``examples/temporal/``) and the temporal tests' recordings.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from brachycal.data.formats.metaimage import write_image_sequence

WIDTH, HEIGHT = 160, 120
PX_PER_MM = 2.0


def motion_mm(t: np.ndarray) -> np.ndarray:
    """The probe's height over the tank, millimetres."""
    return 14.0 * np.sin(2 * np.pi * t / 2.1) + 6.0 * np.sin(2 * np.pi * t / 0.8 + 0.7)


def tank_frames(offset_px: np.ndarray, *, blank: bool = False) -> np.ndarray:
    """``(N, H, W)`` uint8 frames with the bottom centred ``offset_px`` below the image's middle row."""
    v = np.arange(HEIGHT, dtype=float)[None, :, None]
    centre = (HEIGHT - 1) / 2 + np.asarray(offset_px, dtype=float)[:, None, None]
    frames = 220.0 * np.exp(-0.5 * ((v - centre) / 1.5) ** 2) * np.ones((1, 1, WIDTH))
    frames[:, :, : WIDTH // 8] = 0.0
    frames[:, :, -WIDTH // 8 :] = 0.0
    if blank:
        frames[:] = 0.0
    return frames.astype(np.uint8)


def matrix_text(T: np.ndarray) -> str:
    """A 4×4 matrix as PLUS writes a transform field: 16 numbers, row by row."""
    return " ".join(f"{x:.6f}" for x in T.ravel())


def write_tank_recording(
    folder: Path,
    *,
    lag_s: float = 0.1,
    blank: bool = False,
    still: bool = False,
    probe_matrix: np.ndarray | None = None,
    timestamps: bool = True,
) -> tuple[Path, Path]:
    """Write ``video.mha`` and ``tracker.mha`` into ``folder`` (created if needed); returns their paths.

    Args:
        lag_s: the tracker's lag behind the video (seconds).
        blank: frames without any tank bottom.
        still: the probe does not move.
        probe_matrix: every ProbeToTracker reading replaced by this matrix (e.g. not rigid).
        timestamps: write the video frames' Timestamp fields.
    """
    folder.mkdir(parents=True, exist_ok=True)
    video, tracker = folder / "video.mha", folder / "tracker.mha"
    write_tank_files(
        video, tracker, lag_s=lag_s, blank=blank, still=still, probe_matrix=probe_matrix, timestamps=timestamps
    )
    return video, tracker


def write_tank_files(
    video: str | os.PathLike[str],
    tracker: str | os.PathLike[str],
    *,
    lag_s: float = 0.1,
    duration_s: float = 12.0,
    video_period_s: float = 0.1,
    tracker_period_s: float = 0.025,
    blank: bool = False,
    still: bool = False,
    probe_matrix: np.ndarray | None = None,
    timestamps: bool = True,
) -> None:
    """Write the video and tracker sequences to the paths given (staged paths for all-or-nothing outputs).

    The video's frames are taken every ``video_period_s`` over ``duration_s`` seconds; the tracker
    samples every ``tracker_period_s`` from 1.5 s before to 1.5 s after, stamped ``lag_s`` late.
    """
    t_video = np.arange(0.0, duration_s, video_period_s)
    height = np.zeros_like(t_video) if still else motion_mm(t_video)
    write_image_sequence(
        video,
        tank_frames(-PX_PER_MM * height, blank=blank),
        timestamps_s=t_video if timestamps else None,
    )
    s_tracker = np.arange(-1.5, duration_s + 1.5, tracker_period_s)  # the instants the tracker samples
    fields = []
    for s in s_tracker:
        T = np.eye(4)
        T[:3, 3] = [100.0, -20.0, 0.0 if still else float(motion_mm(np.array([s]))[0])]
        fields.append(
            {
                "ProbeToTrackerTransform": matrix_text(T if probe_matrix is None else probe_matrix),
                "ProbeToTrackerTransformStatus": "OK",
                "ReferenceToTrackerTransform": matrix_text(np.eye(4)),
                "ReferenceToTrackerTransformStatus": "OK",
                "Timestamp": f"{s + lag_s:.6f}",
            }
        )
    write_image_sequence(tracker, np.zeros((len(fields), 1, 1), np.uint8), frame_fields=fields)

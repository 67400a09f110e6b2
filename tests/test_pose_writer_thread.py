"""The pose table written from a worker thread (``brachycal fk``): the same text as written in the
caller's thread, blocks in order, and a failure of the worker raised in the caller's thread."""

from __future__ import annotations

import io

import numpy as np
import pytest

from brachycal.data.pose_table import BackgroundPoseWriter, PoseTableWriter
from brachycal.se3 import make_transform


def random_poses(n: int, frames: int, seed: int) -> np.ndarray:
    """``(frames, n, 4, 4)`` rigid poses: rotations about random axes, positions within 1 m."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=(frames * n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(-np.pi, np.pi, frames * n)
    K = np.zeros((frames * n, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= K.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    R = np.eye(3) + s * K + (1 - c) * K @ K  # Rodrigues
    return make_transform(R, rng.uniform(-1, 1, (frames * n, 3))).reshape(frames, n, 4, 4)


@pytest.mark.parametrize("continuity", [False, True])
def test_background_writer_writes_the_same_text_in_order(continuity):
    time = 1.7e9 + np.arange(500) * 0.001
    poses = random_poses(500, 2, seed=3)
    direct, threaded = io.StringIO(), io.StringIO()
    writer = PoseTableWriter(direct, ["a", "b"], continuity=continuity)
    for start in range(0, 500, 37):  # many small blocks: the queue fills and the worker lags behind
        writer.write(time[start : start + 37], poses[:, start : start + 37])
    with BackgroundPoseWriter(PoseTableWriter(threaded, ["a", "b"], continuity=continuity), depth=1) as background:
        for start in range(0, 500, 37):
            background.write(time[start : start + 37], poses[:, start : start + 37])
    assert threaded.getvalue() == direct.getvalue()  # the same characters: formatting is exact, order kept
    assert background.writer.rows == 1000


class FailingFile(io.StringIO):
    """A file whose second write fails, as a full disk would."""

    def __init__(self) -> None:
        super().__init__()
        self.writes = 0

    def write(self, text: str) -> int:
        self.writes += 1
        if self.writes == 3:  # the header, the first block, then the failure
            raise OSError(28, "No space left on device")
        return super().write(text)


def test_a_failed_write_is_raised_in_the_callers_thread():
    poses = random_poses(10, 1, seed=4)
    with pytest.raises(OSError, match="No space left"):  # by a later write() or on leaving
        with BackgroundPoseWriter(PoseTableWriter(FailingFile(), ["a"])) as background:
            for k in range(10):
                background.write([float(k)], poses[:, k : k + 1])


def test_leaving_by_an_exception_drops_the_queued_blocks_and_ends_the_worker():
    handle = io.StringIO()
    with pytest.raises(KeyboardInterrupt):
        with BackgroundPoseWriter(PoseTableWriter(handle, ["a"])) as background:
            background.write([0.0], random_poses(1, 1, seed=5))
            raise KeyboardInterrupt  # e.g. SIGTERM's Terminated: a BaseException
    assert not background._thread.is_alive()
    assert handle.getvalue().count("\n") <= 2  # the header and at most the block being written

"""The pose table written by ``brachycal fk``: ``time,frame,x,y,z,qx,qy,qz,qw``.

For a table of still configurations without time (:mod:`brachycal.data.formats.joint_table`) the
first column is ``sample`` instead: the sample number 1, 2, ... (a whole number), the rest alike.

Positions in metres in ``base_link``; unit quaternions in ROS order (x, y, z, w); one row per
(time, frame), frames in the order asked for. Time and positions are written with 9 decimals
(1 ns, 1 nm), quaternion components with 12.

Quaternion sign: q and −q are the same rotation. By default every quaternion has qw ≥ 0 (the
conventions' canonical form), so a frame that turns through qw = 0 jumps from q to −q between
neighbouring rows, which breaks plots and naive interpolation of the components. With
``continuity=True`` (``brachycal fk --quaternion-continuity``) only each frame's first row is
canonical; every later quaternion takes the sign that makes it closest to the previous row's
(non-negative dot product), also across the blocks of :class:`PoseTableWriter`.

The rows are formatted by :func:`format_fixed`: the same text as ``'%.9f' % x`` (checked in the
tests against Python's formatting), an order of magnitude faster than formatting floats one by one.
"""

from __future__ import annotations

import io
import os
import queue
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.csv_log import table_blocks, to_float
from brachycal.errors import InputError
from brachycal.io import atomic_open
from brachycal.se3 import FloatArray, make_transform
from brachycal.validate import MAX_POSITION_M, check_positions

HEADER = ("time", "frame", "x", "y", "z", "qx", "qy", "qz", "qw")
#: What the first column may hold: ``time`` in seconds, or ``sample``, a sample number (no time).
INDEX_COLUMNS = ("time", "sample")
#: Decimals of each numeric column of the table: time and position 9 (1 ns, 1 nm), quaternion 12.
DECIMALS = (9, 9, 9, 9, 12, 12, 12, 12)

# Four decimal digits of every number below 10,000 as ASCII, each packed in one uint32: one lookup
# renders four digits.
_DIGITS4 = (
    (np.arange(10_000)[:, None] // np.array([1000, 100, 10, 1]) % 10 + ord("0")).astype(np.uint8).view(np.uint32)[:, 0]
)
_PAD = 0  # byte that marks the unused left part of a fixed-width field; removed before writing


def _digits(n: np.ndarray, count: int) -> np.ndarray:
    """``(N, count)`` ASCII digits of the non-negative integers ``n`` ``(N,)``, zero-padded on the left."""
    groups = -(-count // 4)
    out = np.empty((len(n), groups), dtype=np.uint32)
    rest = n
    for g in range(groups - 1, 0, -1):
        rest, four = np.divmod(rest, 10_000)
        out[:, g] = _DIGITS4[four]
    out[:, 0] = _DIGITS4[rest]  # n < 10**count <= 10**(4 groups): what is left is below 10,000
    return out.view(np.uint8)[:, 4 * groups - count :]


def format_fixed(x: ArrayLike, decimals: int) -> np.ndarray:
    """``'%.{decimals}f' % v`` for every ``v`` of ``x`` ``(N,)``, as a ``(N, W)`` byte matrix.

    Each row holds one number right-aligned, with :data:`_PAD` bytes on its left. The text is that
    of Python's correctly rounded formatting (round half to even on the exact binary value): the
    fraction ``v − floor(v)`` is exact, so ``fraction × 10^decimals`` is off the exact product by at
    most half an ulp, and the rare value within two ulps of a rounding tie (and any value of
    magnitude ≥ 2^53 or not finite) is formatted by Python itself.
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    scale = 10.0**decimals
    negative = np.signbit(x)
    a = np.abs(x)
    simple = a < 2.0**53  # False for inf and NaN too
    a = np.where(simple, a, 0.0)
    whole = np.floor(a)
    scaled = (a - whole) * scale  # a − whole is exact
    fraction = np.rint(scaled)
    # |scaled − exact| ≤ ulp(scale)/2; a tie closer than two ulps may round either way: Python decides.
    simple &= np.abs(scaled - np.floor(scaled) - 0.5) > 2.0 * np.spacing(scale)
    carry = fraction >= scale
    whole = (whole + carry).astype(np.int64)
    fraction = np.where(carry, 0.0, fraction).astype(np.int64)
    fallback = np.flatnonzero(~simple)
    texts = [(f"%.{decimals}f" % x[i]).encode() for i in fallback]

    width_int = max(1, len(str(int(whole.max()))) if len(whole) else 1)  # digits of the integer part
    width = 1 + width_int + 1 + decimals  # sign, integer part, point, fraction
    width = max([width, *(len(t) for t in texts)])
    out = np.full((len(x), width), _PAD, dtype=np.uint8)
    out[:, width - decimals - 1] = ord(".")
    if decimals:
        out[:, width - decimals :] = _digits(fraction, decimals)
    int_digits = _digits(whole, width_int)
    # blank the leading zeros of the integer part (keep one digit), then place the sign before it
    length = 1 + np.searchsorted(10 ** np.arange(1, width_int, dtype=np.int64), whole, side="right")
    column = np.arange(width_int)
    int_digits[column[None, :] < (width_int - length)[:, None]] = _PAD
    out[:, width - decimals - 1 - width_int : width - decimals - 1] = int_digits
    rows = np.flatnonzero(negative)
    out[rows, width - decimals - 2 - length[rows]] = ord("-")
    for i, text in zip(fallback, texts, strict=True):
        out[i] = _PAD
        out[i, width - len(text) :] = np.frombuffer(text, dtype=np.uint8)
    return out


def continuous_signs(quat: FloatArray, previous: FloatArray | None) -> FloatArray:
    """``quat`` ``(N, 4)`` with signs flipped so that each has a non-negative dot product with the one
    before it (the first with ``previous`` ``(4,)``, if given); the same rotations."""
    if len(quat) == 0:
        return quat
    dots = np.einsum("ij,ij->i", quat[1:], quat[:-1])
    first = 1.0 if previous is None or float(quat[0] @ previous) >= 0.0 else -1.0
    flips = np.concatenate([[first < 0], dots < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)  # each flip carries to every later row
    return quat * sign[:, None]


def quaternions(R: FloatArray) -> FloatArray:
    """Unit quaternions ``(N, 4)`` (x, y, z, w), canonical (w > 0, or w = 0 and the first non-zero
    of x, y, z positive), of rotation matrices ``R`` ``(N, 3, 3)``, orthonormal to ~1e-12.

    The arithmetic of SciPy's ``Rotation.from_matrix(R).as_quat(canonical=True)`` for orthonormal
    matrices (the largest of trace and diagonal picks the formula; then normalised), in the same
    order of operations, so the same numbers to the bit (the tests check it), without importing
    SciPy (half a second of start-up) or testing every matrix for orthonormality: forward
    kinematics multiplies rotations, so its matrices are orthonormal to ~1e-15.
    """
    m = [[R[:, i, j] for j in range(3)] for i in range(3)]
    trace = m[0][0] + m[1][1] + m[2][2]
    choice = np.argmax(np.stack([m[0][0], m[1][1], m[2][2], trace]), axis=0)
    cases = np.empty((4, 4, len(R)))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        cases[i, i] = 1 - trace + 2 * m[i][i]
        cases[i, j] = m[j][i] + m[i][j]
        cases[i, k] = m[k][i] + m[i][k]
        cases[i, 3] = m[k][j] - m[j][k]
    cases[3, 0] = m[2][1] - m[1][2]
    cases[3, 1] = m[0][2] - m[2][0]
    cases[3, 2] = m[1][0] - m[0][1]
    cases[3, 3] = 1 + trace
    q = np.take_along_axis(cases, choice[None, None, :], axis=0)[0]  # (4, N)
    q = (q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])).T
    x, y, z, w = q.T
    flip = (w < 0) | ((w == 0) & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0))))))
    return np.where(flip[:, None], -q, q)


def _position_quaternion(T_base_frames: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Positions ``(F, N, 3)`` and :func:`quaternions` ``(F, N, 4)`` of poses ``(F, N, 4, 4)``."""
    quat = quaternions(T_base_frames[..., :3, :3].reshape(-1, 3, 3)).reshape(*T_base_frames.shape[:-2], 4)
    return T_base_frames[..., :3, 3].copy(), quat


class PoseTableWriter:
    """Writes a pose table block by block to an open file (header first).

    Args:
        handle: file opened for writing: binary (the rows go as they are formatted, ASCII bytes:
            ``brachycal fk``), or text with ``newline=""`` (decoded first).
        frames: ``(F,)`` frame names, the order of the rows of each time.
        continuity: quaternion sign continuity (see the module docstring); default qw ≥ 0.
    """

    def __init__(
        self, handle: IO[str] | IO[bytes], frames: Sequence[str], *, continuity: bool = False, index: str = "time"
    ) -> None:
        if index not in INDEX_COLUMNS:
            raise ValueError(f"index must be one of {INDEX_COLUMNS}, got {index!r}")
        self.index = index
        self.handle = handle
        self.frames = list(frames)
        self.continuity = continuity
        self.rows = 0
        self._binary = not isinstance(handle, io.TextIOBase)
        self._previous: list[FloatArray | None] = [None] * len(self.frames)
        self._names = [np.frombuffer(f",{f},".encode(), dtype=np.uint8) for f in self.frames]
        self._put((",".join((index, *HEADER[1:])) + "\n").encode("ascii"))

    def _put(self, text: bytes) -> None:
        if self._binary:
            cast("IO[bytes]", self.handle).write(text)
        else:
            cast("IO[str]", self.handle).write(text.decode("ascii"))

    def write(self, time: ArrayLike, T_base_frames: ArrayLike) -> None:
        """Append the rows of ``time`` ``(N,)`` seconds and ``T_base_frames`` ``(F, N, 4, 4)`` (metres)."""
        self.write_numbers(*self.numbers(time, T_base_frames))

    def numbers(self, time: ArrayLike, T_base_frames: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(time (N,), numbers (F, N, 7))``: the rows' numbers, position (metres) then quaternion (x, y,
        z, w) with this table's sign convention; the blocks must be taken in order (continuity)."""
        time = np.asarray(time, dtype=float).reshape(-1)
        poses = np.asarray(T_base_frames, dtype=float)
        if len(time) == 0:
            return time, np.zeros((len(self.frames), 0, 7))
        position, quat = _position_quaternion(poses)  # (F, N, 3), (F, N, 4)
        if self.continuity:
            for k in range(len(self.frames)):
                quat[k] = continuous_signs(quat[k], self._previous[k])
                self._previous[k] = quat[k, -1].copy()
        return time, np.concatenate([position, quat], axis=2)

    def write_numbers(self, time: FloatArray, numbers: FloatArray) -> None:
        """Append the rows of :meth:`numbers`' output."""
        n, frames = len(time), len(self.frames)
        if n == 0:
            return
        first = _format_whole(time) if self.index == "sample" else format_fixed(time, DECIMALS[0])
        texts = [first[None].repeat(frames, axis=0)]  # (F, N, width) each
        texts += [format_fixed(numbers[:, :, c].reshape(-1), DECIMALS[c + 1]).reshape(frames, n, -1) for c in range(7)]
        # A row: time ",frame," x "," y "," z "," qx "," qy "," qz "," qw "\n", right-aligned in one width
        # so that rows of all frames interleave by time; the pad bytes on the left are dropped at the end.
        widths = [sum(t.shape[2] for t in texts) + len(name) + 6 + 1 for name in self._names]
        width = max(widths)
        block = np.zeros((n, frames, width), dtype=np.uint8)  # zeros: _PAD
        for k, name in enumerate(self._names):
            at = width - widths[k]
            for c, text in enumerate(texts):
                if c == 1:
                    block[:, k, at : at + len(name)] = name
                    at += len(name)
                elif c > 1:
                    block[:, k, at] = ord(",")
                    at += 1
                block[:, k, at : at + text.shape[2]] = text[k]
                at += text.shape[2]
            block[:, k, at] = ord("\n")
        flat = block.reshape(-1)
        self._put(flat[flat != _PAD].tobytes())
        self.rows += len(time) * len(self.frames)


def _format_whole(n: FloatArray) -> np.ndarray:
    """``(N, W)`` byte matrix of the whole numbers ``n`` ``(N,)`` (sample numbers), right-aligned as
    :func:`format_fixed`'s."""
    texts = [str(int(v)).encode("ascii") for v in n]
    width = max(len(t) for t in texts)
    out = np.full((len(texts), width), _PAD, dtype=np.uint8)
    for i, text in enumerate(texts):
        out[i, width - len(text) :] = np.frombuffer(text, dtype=np.uint8)
    return out


class BackgroundPoseWriter:
    """A :class:`PoseTableWriter` whose blocks are formatted and written in a worker thread, in order.

    ``brachycal fk`` computes block k + 1 while block k is turned into text: the formatting is
    NumPy work on large arrays and the file writes are I/O, both mostly without the GIL, so on a
    second core they take the writing off the command's path (the log's parsing is a third thread,
    :func:`~brachycal.data.formats.csv_log.prefetched`). :meth:`write` takes the quaternions in the caller's
    thread (:meth:`PoseTableWriter.numbers`, ~20 % of a block's writing) so that the two threads'
    shares of a block are about even; the worker formats and writes (:meth:`PoseTableWriter.write_numbers`).
    The text is the same as :meth:`PoseTableWriter.write`'s: one worker, blocks in the order given.

    Use as a context manager: leaving it normally waits for every block to be written; leaving it
    by an exception (a refusal, SIGTERM) drops the blocks not yet written and waits only for the one
    being written. An exception of the worker (e.g. ``OSError``: disk full) is raised in the
    caller's thread by the next :meth:`write` or on leaving.

    Args:
        writer: the writer the blocks go to.
        depth: blocks waiting at most (each ``F × N`` poses: a few MB); :meth:`write` waits beyond it.
    """

    _DONE = None

    def __init__(self, writer: PoseTableWriter, depth: int = 2) -> None:
        self.writer = writer
        self._queue: queue.Queue[tuple[FloatArray, FloatArray] | None] = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name="brachycal-pose-writer", daemon=True)

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is self._DONE:
                return
            if self._stop.is_set() or self._error is not None:
                continue  # drain: the caller is leaving, or a block failed (its error is raised there)
            try:
                self.writer.write_numbers(*item)
            except BaseException as exc:  # handed to the caller's thread
                self._error = exc

    def _raise_error(self) -> None:
        if self._error is not None:
            self._stop.set()  # first: the worker must not write another block after the failed one
            error, self._error = self._error, None
            raise error

    def write(self, time: ArrayLike, T_base_frames: ArrayLike) -> None:
        """Queue the rows of ``time`` ``(N,)`` seconds and ``T_base_frames`` ``(F, N, 4, 4)`` (metres);
        ``time`` must not be changed afterwards (it is written later)."""
        self._raise_error()
        # The quaternions here, the text there: the two threads' shares of a block's work are about even.
        self._queue.put(self.writer.numbers(time, T_base_frames))

    def __enter__(self) -> BackgroundPoseWriter:
        self._thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        if kind is not None:
            self._stop.set()
        self._queue.put(self._DONE)  # the worker drains the queue, so this cannot wait for long
        self._thread.join()
        if kind is None:
            self._raise_error()


def write_pose_table(
    path: str | os.PathLike[str],
    time: ArrayLike,
    frames: Sequence[str],
    T_base_frames: ArrayLike,
    *,
    force: bool = False,
    progress: Callable[[int], None] | None = None,
    continuity: bool = False,
) -> Path:
    """Write poses atomically.

    Args:
        path: output CSV.
        time: ``(N,)`` seconds.
        frames: ``(F,)`` frame names.
        T_base_frames: ``(F, N, 4, 4)`` poses ``T_base_frame``, metres.
        force: replace an existing file.
        progress: called with the number of samples written after each block.
        continuity: quaternion sign continuity instead of qw ≥ 0 (see the module docstring).
    """
    time = np.asarray(time, dtype=float)
    poses = np.asarray(T_base_frames, dtype=float)
    block = 10_000
    with atomic_open(path, force=force) as handle:
        writer = PoseTableWriter(handle, frames, continuity=continuity)
        for start in range(0, len(time), block):
            stop = min(start + block, len(time))
            writer.write(time[start:stop], poses[:, start:stop])
            if progress is not None:
                progress(stop - start)
    return Path(path)


def read_pose_table(path: str | os.PathLike[str]) -> tuple[FloatArray, list[str], FloatArray]:
    """Read a pose table back: ``(time (R,), frame (R,), T_base_frame (R, 4, 4))``, one per row
    (``time`` holds the sample numbers of a table whose first column is ``sample``).

    Read a block of rows at a time (:func:`~brachycal.data.formats.csv_log.table_blocks`): memory
    is the poses and frame names, not every field as a Python string."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    path = Path(path)
    times: list[FloatArray] = []
    frames: list[str] = []
    poses: list[FloatArray] = []
    for header, rows, records in table_blocks(path, list(HEADER[1:])):
        index = "sample" if "sample" in header and "time" not in header else "time"
        if index not in header:
            raise InputError("no 'time' (or 'sample') column in the header", file=path, row=1)
        numbers = to_float(path, header, rows, records, [index, *HEADER[2:]])
        check_positions(
            numbers[:, 1:4], "", limit=MAX_POSITION_M, unit="m", file=path, rows=rows, columns=["x", "y", "z"]
        )
        k = header.index("frame")
        frames += [fields[k] for fields in records]
        times.append(numbers[:, 0])
        R = Rotation.from_quat(numbers[:, 4:8]).as_matrix() if len(numbers) else np.zeros((0, 3, 3))
        poses.append(make_transform(R, numbers[:, 1:4]))
    return np.concatenate(times), frames, np.concatenate(poses)

"""Joint logs: timestamped configurations of the robot, validated and in model joint order.

Every reader (CSV, ROS 1 bag, ROS 2 bag) ends in :func:`joint_log_from_columns`, so the same
refusals apply whatever the source: a missing joint or one listed twice, a non-finite value,
time that does not strictly increase, values that look like degrees, values outside the joint
limits by more than encoder noise (:data:`LIMIT_TOLERANCE_RAD`), and a mimic joint
(``torso_joint_b2``) that disagrees with the axis it mirrors. Readings a hair beyond a limit are
kept as read, with one :class:`~brachycal.errors.BrachycalWarning` per file.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import BrachycalWarning, InputError
from brachycal.model.names import MIMIC_JOINTS
from brachycal.se3 import FloatArray

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot

#: Largest |angle| in radians a revolute joint can report; beyond it the log is taken for degrees.
DEGREES_THRESHOLD = 2.0 * np.pi
#: How far beyond a URDF limit a revolute joint's reading may lie and still be taken as read (rad).
#: A pose planned on a limit is reported by the encoders a few counts to either side of it (for
#: example 1.919869 against 1.919862, 7e-6 rad over); encoder resolution and noise are
#: of order 1e-5 rad (the twin's encoder noise is 2e-5 rad SD). 1e-3 rad (0.06°, ~1 mm at the end
#: of a 1 m arm) is fifty such SDs, so every honest reading passes, while what the limit check is
#: for — degrees, another robot's log, swapped columns — lands far beyond it.
LIMIT_TOLERANCE_RAD = 1e-3
#: The same for prismatic joints (m): 1 µm, well above a linear encoder's resolution.
LIMIT_TOLERANCE_M = 1e-6


def limit_tolerance(robot: Robot) -> FloatArray:
    """``(nq,)`` slack on each joint's limits: :data:`LIMIT_TOLERANCE_M` for prismatic joints
    (metres), :data:`LIMIT_TOLERANCE_RAD` for the others (radians)."""
    kinds = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismatic")  # Pinocchio's prismatic joints
    prismatic = [
        robot.model.joints[robot.model.getJointId(name)].shortname().startswith(kinds) for name in robot.joint_names
    ]
    return np.where(prismatic, LIMIT_TOLERANCE_M, LIMIT_TOLERANCE_RAD)


#: Largest |b2 − b1| (rad) accepted for a mimic joint; more means the log is not what we think.
MIMIC_TOLERANCE = 1e-3


@dataclass(frozen=True, repr=False)
class JointLog:
    """Configurations of a robot over time.

    Attributes:
        time: ``(N,)`` seconds, strictly increasing (any origin).
        q: ``(N, nq)`` radians, columns in ``joint_names`` order (the robot's order).
        joint_names: names of the columns of ``q``.
        source: file the log came from (for messages).
        rows: ``(N,)`` where each sample sits in the source (file row or message number).
        row_label: what ``rows`` counts (``"row"`` or ``"message"``).
    """

    time: FloatArray
    q: FloatArray
    joint_names: tuple[str, ...]
    source: str
    rows: np.ndarray
    row_label: str = "row"

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def __repr__(self) -> str:
        span = f", {self.time[0]:g} to {self.time[-1]:g} s" if len(self) else ""
        return (
            f"JointLog of {self.source or 'no file'}: {len(self)} configurations{span}, "
            f"{len(self.joint_names)} joints (radians)"
        )

    def interpolate(self, times: ArrayLike) -> FloatArray:
        """``(M, nq)`` configurations at ``times`` ``(M,)`` by linear interpolation per joint.

        Used to pair robot poses with ultrasound frames stamped on another clock tick.

        Raises:
            InputError: a requested time lies outside the log (no extrapolation).
        """
        times = np.asarray(times, dtype=float).reshape(-1)
        if not np.all(np.isfinite(times)):
            raise InputError("requested times must be finite", file=self.source)
        outside = (times < self.time[0]) | (times > self.time[-1])
        if outside.any():
            t = times[np.argmax(outside)]
            raise InputError(
                f"requested time {t:.6f} s is outside the log's span [{self.time[0]:.6f}, {self.time[-1]:.6f}] s",
                file=self.source,
            )
        return np.column_stack([np.interp(times, self.time, self.q[:, k]) for k in range(self.q.shape[1])])


def mimic_joints(robot: Robot) -> Mapping[str, str]:
    """The joints ``robot``'s controller publishes that only copy a coordinate: its rig's
    (``[controller] mimic``), or the SDA10F's (:data:`~brachycal.model.names.MIMIC_JOINTS`) for a
    model without a description."""
    try:
        return robot.rig.mimic_joints
    except InputError:
        return MIMIC_JOINTS


def joint_columns(robot: Robot, header: Sequence[str]) -> list[str]:
    """The columns of ``header`` that hold joint values, in header order: the robot's joints and the
    mimic joints (:func:`mimic_joints`, which :func:`configurations_from_columns` checks against the
    axes they mirror). Other columns (time, labels, pixels) are not joints."""
    mimic = mimic_joints(robot)
    return [name for name in header if name in robot.joint_names or name in mimic]


def configurations_from_columns(
    robot: Robot,
    names: Sequence[str],
    values: ArrayLike,
    *,
    source: str,
    rows: ArrayLike | None = None,
    row_label: str = "row",
) -> FloatArray:
    """Validate joint columns and reorder them into the robot's joint order.

    Args:
        robot: the model whose joints (order and limits) the values must match.
        names: ``(C,)`` names of the columns of ``values``, in the source's order; names the
            robot does not know are ignored, mimic joints are checked against their leader.
        values: ``(N, C)`` joint values in radians.
        source: file name for messages.
        rows: ``(N,)`` row or message number of each sample in the source (default 1..N).
        row_label: what ``rows`` counts.

    Returns:
        ``(N, nq)`` configurations in ``robot.joint_names`` order.

    Raises:
        InputError: one line naming the file, the row and the column of the first problem.

    Warns:
        BrachycalWarning: once per call (per file) when readings lie beyond a joint limit by less
            than :func:`limit_tolerance`; they are kept as read (what the encoder said).
    """
    check_names(robot, names, source=source, row_label=row_label)
    values = np.asarray(values, dtype=float).reshape(-1, len(names))
    rows = np.arange(1, len(values) + 1) if rows is None else np.asarray(rows)
    q, near = _check_configurations(robot, names, values, source=source, rows=rows, row_label=row_label)
    if near is not None:
        _warn_near_limit(robot, near, source=source, row_label=row_label)
    return q


def check_names(robot: Robot, names: Sequence[str], *, source: str, row_label: str = "row") -> None:
    """Refuse a joint listed twice among ``names`` or a robot joint missing from them."""
    for k, name in enumerate(names):
        if name in names[:k]:  # which reading would be the joint's? A log must say it once.
            raise InputError(
                f"joint listed twice (columns {list(names).index(name) + 1} and {k + 1})",
                file=source,
                column=name,
                row_label=row_label,
            )
    missing = [j for j in robot.joint_names if j not in names]
    if missing:
        raise InputError(f"missing joint(s) {', '.join(missing)}", file=source, row_label=row_label)


@dataclass(frozen=True)
class _NearLimit:
    """Readings beyond a joint limit by less than the tolerance: the first one and how many."""

    row: int  # its row (or message) number in the source
    joint: int  # its column in the robot's joint order
    value: float  # the reading (rad or m)
    beyond: float  # by how much it lies beyond the limit (rad or m)
    count: int  # how many such readings


def _units(robot: Robot) -> tuple[FloatArray, np.ndarray, np.ndarray]:
    """``(tolerance (nq,), unit (nq,) 'm'/'rad', digits (nq,))`` of each joint's limit messages."""
    tolerance = limit_tolerance(robot)
    unit = np.where(tolerance == LIMIT_TOLERANCE_M, "m", "rad")
    digits = np.where(tolerance == LIMIT_TOLERANCE_M, 9, 6)  # a thousandth of the tolerance
    return tolerance, unit, digits


def _check_configurations(
    robot: Robot, names: Sequence[str], values: FloatArray, *, source: str, rows: np.ndarray, row_label: str
) -> tuple[FloatArray, _NearLimit | None]:
    """The checks of :func:`configurations_from_columns` on ``values`` ``(N, C)`` (names already
    checked): ``(q (N, nq) in the robot's order, the readings a hair beyond a limit or None)``."""

    def fail(message: str, index: int | None = None, column: str | None = None) -> InputError:
        row = None if index is None else int(rows[index])
        return InputError(message, file=source, row=row, column=column, row_label=row_label)

    position = {name: k for k, name in enumerate(names)}
    q = values[:, [position[j] for j in robot.joint_names]]
    finite = np.isfinite(q)
    if not finite.all():
        for k, joint in enumerate(robot.joint_names):
            bad = ~finite[:, k]
            if bad.any():
                raise fail("value is not a finite number", int(np.argmax(bad)), joint)
    too_big = np.abs(q) > DEGREES_THRESHOLD
    if too_big.any():
        i, k = (int(v) for v in np.unravel_index(int(np.argmax(too_big)), q.shape))
        raise fail(
            f"value {q[i, k]:g} looks like degrees (|value| > 2π); joint values are in radians",
            int(i),
            robot.joint_names[k],
        )
    tolerance, unit, digits = _units(robot)
    beyond = np.maximum(robot.lower - q, q - robot.upper)  # > 0 outside the limits
    outside = beyond > tolerance
    if outside.any():
        i, k = (int(v) for v in np.unravel_index(int(np.argmax(outside)), q.shape))
        raise fail(
            f"value {q[i, k]:.{digits[k]}f} {unit[k]} is outside the joint limits "
            f"[{robot.lower[k]:.{digits[k]}f}, {robot.upper[k]:.{digits[k]}f}] "
            f"by {beyond[i, k]:.3g} {unit[k]} (more than the {tolerance[k]:g} {unit[k]} allowed for encoder noise)",
            int(i),
            robot.joint_names[k],
        )
    for mimic, leader in mimic_joints(robot).items():
        if mimic in position and leader in position and mimic not in robot.joint_names:
            diff = np.abs(values[:, position[mimic]] - values[:, position[leader]])
            bad = ~(diff <= MIMIC_TOLERANCE)
            if bad.any():
                raise fail(f"{mimic} must equal {leader} (it only mirrors it)", int(np.argmax(bad)), mimic)
    near = beyond > 0  # warned about only once the file is accepted: a refusal stays one line
    if not near.any():
        return q, None
    i, k = (int(v) for v in np.unravel_index(int(np.argmax(near)), q.shape))
    return q, _NearLimit(int(rows[i]), k, float(q[i, k]), float(beyond[i, k]), int(near.sum()))


def _warn_near_limit(robot: Robot, near: _NearLimit, *, source: str, row_label: str) -> None:
    tolerance, unit, digits = _units(robot)
    k = near.joint
    where = f"{source}, {row_label} {near.row}, column {robot.joint_names[k]!r}"
    warnings.warn(
        f"{where}: value {near.value:.{digits[k]}f} {unit[k]} is {near.beyond:.2g} {unit[k]} beyond the "
        f"joint limit, within the {tolerance[k]:g} {unit[k]} allowed for encoder noise; kept as read "
        f"({near.count} reading(s) in this file beyond a limit by less than that)",
        BrachycalWarning,
        stacklevel=3,
    )


class JointLogChecker:
    """The checks of :func:`joint_log_from_columns`, applied block by block to a log read in pieces.

    A long log is read, checked, computed and written in blocks so that memory does not grow with
    its length. Each block is checked as a whole log would be (time finite and strictly increasing,
    also across the boundary with the previous block; joints as :func:`configurations_from_columns`);
    the warning about readings a hair beyond a limit is given once, by :meth:`finish`, for the file.

    Args:
        robot: the model the joints belong to.
        names: ``(C,)`` names of the joint columns of every block's ``values``, in the source's order.
        source: file name for messages.
        row_label: what the blocks' ``rows`` count (``"row"`` or ``"message"``).

    Raises:
        InputError: a joint listed twice or missing among ``names``.
    """

    def __init__(self, robot: Robot, names: Sequence[str], *, source: str, row_label: str = "row") -> None:
        self.robot = robot
        self.names = list(names)
        self.source = source
        self.row_label = row_label
        self.samples = 0
        self._last: tuple[float, int] | None = None  # time (s) and row of the previous block's last sample
        self._near: _NearLimit | None = None
        self._near_count = 0
        check_names(robot, self.names, source=source, row_label=row_label)

    def check(self, time: ArrayLike, values: ArrayLike, rows: ArrayLike) -> FloatArray:
        """Check one block: ``time`` ``(N,)`` s, ``values`` ``(N, C)`` rad, ``rows`` ``(N,)`` source rows.

        Returns:
            ``(N, nq)`` configurations in the robot's joint order.

        Raises:
            InputError: one line naming the file, the row and the column of the block's first problem.
        """
        time = np.asarray(time, dtype=float).reshape(-1)
        values = np.asarray(values, dtype=float).reshape(len(time), len(self.names))
        rows = np.asarray(rows)

        def fail(message: str, index: int) -> InputError:
            return InputError(message, file=self.source, row=int(rows[index]), column="time", row_label=self.row_label)

        if len(time) == 0:
            return np.empty((0, self.robot.nq))
        bad_time = ~np.isfinite(time)
        if bad_time.any():
            raise fail("time is not a finite number", int(np.argmax(bad_time)))
        if self._last is not None and not time[0] > self._last[0]:
            raise fail(f"time {float(time[0])!r} does not increase (previous {self._last[0]!r})", 0)
        step = np.diff(time)
        if (step <= 0).any():
            i = int(np.argmax(step <= 0)) + 1
            raise fail(f"time {float(time[i])!r} does not increase (previous {float(time[i - 1])!r})", i)
        q, near = _check_configurations(
            self.robot, self.names, values, source=self.source, rows=rows, row_label=self.row_label
        )
        if near is not None:
            self._near = self._near or near
            self._near_count += near.count
        self._last = (float(time[-1]), int(rows[-1]))
        self.samples += len(time)
        return q

    def finish(self) -> None:
        """After the last block: refuse an empty log; warn once about readings a hair beyond a limit.

        Raises:
            InputError: the log has no samples.

        Warns:
            BrachycalWarning: see :func:`configurations_from_columns`.
        """
        if self.samples == 0:
            raise InputError("the log has no samples", file=self.source)
        if self._near is not None:
            near = _NearLimit(self._near.row, self._near.joint, self._near.value, self._near.beyond, self._near_count)
            _warn_near_limit(self.robot, near, source=self.source, row_label=self.row_label)


def joint_log_from_columns(
    robot: Robot,
    names: Sequence[str],
    time: ArrayLike,
    values: ArrayLike,
    *,
    source: str,
    rows: ArrayLike | None = None,
    row_label: str = "row",
) -> JointLog:
    """Validate a timed log (see :func:`configurations_from_columns`) and build a :class:`JointLog`.

    Besides the joint checks, time must be finite and strictly increasing and the log non-empty.
    """
    time = np.asarray(time, dtype=float).reshape(-1)
    rows = np.arange(1, len(time) + 1) if rows is None else np.asarray(rows)
    checker = JointLogChecker(robot, names, source=source, row_label=row_label)
    if len(time) == 0:
        raise InputError("the log has no samples", file=source)
    q = checker.check(time, values, rows)
    checker.finish()
    return JointLog(time=time, q=q, joint_names=robot.joint_names, source=source, rows=rows, row_label=row_label)


def interpolate_blocks(blocks: Iterable[tuple[FloatArray, FloatArray]], times: ArrayLike, *, source: str) -> FloatArray:
    """Configurations at ``times`` ``(M,)`` s from a log read block by block: ``(M, nq)`` radians.

    The streamed form of :meth:`JointLog.interpolate` (linear per joint, no extrapolation): each
    ``(time (N,), q (N, nq))`` block, joined to the last sample of the block before it, gives the
    requested times that fall within it. Memory grows with ``M``, not with the log.

    Raises:
        InputError: a requested time is not finite, or lies outside the log (the first such time
            in the order given, as :meth:`JointLog.interpolate` says it).
    """
    times = np.asarray(times, dtype=float).reshape(-1)
    if not np.all(np.isfinite(times)):
        raise InputError("requested times must be finite", file=source)
    order = np.argsort(times, kind="stable")
    sorted_times = times[order]
    Q: FloatArray | None = None
    span: list[float] = []
    previous: tuple[FloatArray, FloatArray] | None = None
    for time, q in blocks:
        if Q is None:
            Q = np.full((len(times), q.shape[1]), np.nan)
            span = [float(time[0]), float(time[-1])]
        if previous is not None:
            time = np.concatenate([previous[0], time])
            q = np.concatenate([previous[1], q])
        span[1] = float(time[-1])
        lo = int(np.searchsorted(sorted_times, time[0], side="left"))
        hi = int(np.searchsorted(sorted_times, time[-1], side="right"))
        if hi > lo:
            at = order[lo:hi]
            Q[at] = np.column_stack([np.interp(times[at], time, q[:, k]) for k in range(q.shape[1])])
        previous = (time[-1:], q[-1:])
    assert Q is not None  # a log has samples: the readers refuse an empty one
    outside = (times < span[0]) | (times > span[1])
    if outside.any():
        t = times[np.argmax(outside)]
        raise InputError(
            f"requested time {t:.6f} s is outside the log's span [{span[0]:.6f}, {span[1]:.6f}] s", file=source
        )
    return Q

"""A lab's recording of a calibration session: operator marks, captured frames, still windows.

Times in seconds on the joint log's clock; pixels with the origin at the centre of pixel (0, 0),
``u`` along columns, ``v`` along rows.

Design: ``docs/design/files.md``, "A lab's recording".
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.bags import bag_folder, bag_messages
from brachycal.data.formats.csv_log import read_table, to_float
from brachycal.data.joint_log import JointLog
from brachycal.data.json_files import read_json
from brachycal.errors import InputError
from brachycal.se3 import FloatArray
from brachycal.validate import check_range, check_token, number_from_text

if TYPE_CHECKING:  # the message's fields, for the type checker; rosbags is imported where it is used
    from rosbags.typesys.stores.ros2_humble import std_msgs__msg__String as StringMsg

__all__ = [
    "AXES_POINTS",
    "AXES_TOOLS",
    "MARK_KINDS",
    "MARK_TYPE",
    "MAX_SPEED_RAD_S",
    "REFERENCES",
    "SPEED_SPAN_S",
    "STILL_WINDOW_S",
    "TOUCH_TOOLS",
    "Frame",
    "Mark",
    "StillWindow",
    "read_bag_marks",
    "read_images",
    "read_marks",
    "read_slicer_markups",
    "still_configuration",
]

#: What a mark can be: a tool touching a reference tip, or a point of a tool's axes moves.
MARK_KINDS = ("touch", "axes")
#: Tools that touch reference tips, and the tips (as in the session format).
TOUCH_TOOLS = ("top_model", "needle", "probe")
REFERENCES = ("rtip1", "rtip2")
#: Tools whose axes are measured, and the three points of the moves.
AXES_TOOLS = ("needle", "probe")
AXES_POINTS = ("p1", "p2", "p3")
#: ROS message type of marks on a bag topic.
MARK_TYPE = "std_msgs/msg/String"

#: Length of the still window, seconds: the configuration at a mark is the mean of the log over
#: this window centred on the mark's time. At 100 Hz it averages ~100 readings, which divides
#: the encoder noise by ~10 (2e-5 rad → 2e-6 rad, ~2 µm at 1 m); an operator holds the robot at
#: a touch for several seconds, so only a mark within half a second of arriving or leaving is
#: refused.
STILL_WINDOW_S = 1.0
#: Time over which a joint's speed is estimated (least-squares slope of its readings), seconds.
#: Long enough to average encoder noise, short enough that a move inside the still window is seen.
SPEED_SPAN_S = 0.2
#: Largest joint speed of a still robot, rad/s. Encoder noise of SD σ read at rate f gives a
#: slope over a span L (m = f·L readings) with SD σ·√(12/(m·L²)): 7.7e-5 rad/s for the twin's
#: σ = 2e-5 rad at 100 Hz over 0.2 s, so 1e-3 rad/s is 13 such SDs and a still robot is never
#: called moving (about 1500 slopes are tested per window; noise up to ~4e-5 rad stays below 6
#: SDs). The slowest deliberate motion of an industrial arm — jogging at 1–2 % of its 2–3.5 rad/s
#: limits — is 30 times faster than the threshold, and its accelerations and decelerations pass
#: through it within a few hundredths of a second.
MAX_SPEED_RAD_S = 1e-3
#: Fewest readings a speed span may hold: a slope from fewer says nothing about noise.
MIN_SPAN_READINGS = 3


@dataclass(frozen=True)
class Mark:
    """One operator mark.

    Attributes:
        time_s: seconds on the joint log's clock.
        kind: ``touch`` or ``axes``.
        tool: ``top_model``/``needle``/``probe`` (touch) or ``needle``/``probe`` (axes).
        name: reference tip (``rtip1``, ``rtip2``) or axes point (``p1``–``p3``).
        source: file (or bag) it was read from; ``row`` where in it (``row_label`` says what counts).
    """

    time_s: float
    kind: str
    tool: str
    name: str
    source: str = ""
    row: int = 0
    row_label: str = "row"

    @property
    def label(self) -> str:
        return f"{self.kind} mark {self.tool} {self.name}"


@dataclass(frozen=True, eq=False)  # holds arrays: compare fields, not objects
class Frame:
    """One captured ultrasound frame.

    Attributes:
        time_s: seconds on the joint log's clock.
        uv_px: ``(2,)`` annotated needle tip in pixels, or ``None`` when not annotated.
        sample: the sample's name if the file gives one, else ``None``.
        source, row: where it was read from (``images.csv`` row, header = row 1).
        annotated_in: where the annotation came from when not from ``source`` (a markups file and
            its control point), for messages.
    """

    time_s: float
    uv_px: FloatArray | None
    sample: str | None = None
    source: str = ""
    row: int = 0
    annotated_in: str = ""


@dataclass(frozen=True, eq=False)  # holds arrays: compare fields, not objects
class StillWindow:
    """The robot's configuration at a moment, from the still window around it.

    Attributes:
        time_s: the moment (seconds on the log's clock).
        q: ``(nq,)`` mean configuration over the window, radians (the time-average of the log's
            piecewise-linear interpolation, so irregular sampling weighs each instant alike).
        start_s, end_s: the window.
        samples: log readings inside the window.
        spread: ``(nq,)`` standard deviation of each joint's readings in the window (radians): the
            encoder noise a still robot shows.
        speed: ``(nq,)`` largest speed of each joint in the window (rad/s), as judged.
    """

    time_s: float
    q: FloatArray
    start_s: float
    end_s: float
    samples: int
    spread: FloatArray
    speed: FloatArray

    @property
    def window_s(self) -> float:
        return self.end_s - self.start_s


def _at(log: JointLog, s: float) -> FloatArray:
    """``(nq,)`` the log linearly interpolated at ``s`` (inside its span)."""
    k = int(np.searchsorted(log.time, s, side="right"))
    if k >= len(log):
        return log.q[-1].copy()
    if k == 0:
        return log.q[0].copy()
    w = (s - log.time[k - 1]) / (log.time[k] - log.time[k - 1])
    return log.q[k - 1] + w * (log.q[k] - log.q[k - 1])


def _span_slopes(
    times: FloatArray, q: FloatArray, span_s: float, end: float
) -> tuple[FloatArray, np.ndarray, np.ndarray]:
    """Least-squares slopes ``(S, nq)`` of ``q`` over every span ``[t_k, t_k + span_s]`` that ends by
    ``end``, the number of readings ``(S,)`` in each and the index ``k`` of each span's first
    reading (cumulative sums: one pass)."""
    starts = np.flatnonzero(times + span_s <= end + 1e-12)
    ends = np.searchsorted(times, times[starts] + span_s + 1e-12, side="right")
    zero = np.zeros((1,))
    c_t = np.concatenate([zero, np.cumsum(times)])
    c_tt = np.concatenate([zero, np.cumsum(times * times)])
    c_q = np.vstack([np.zeros((1, q.shape[1])), np.cumsum(q, axis=0)])
    c_tq = np.vstack([np.zeros((1, q.shape[1])), np.cumsum(times[:, None] * q, axis=0)])
    n = (ends - starts).astype(float)
    s_t = c_t[ends] - c_t[starts]
    s_tt = c_tt[ends] - c_tt[starts]
    s_q = c_q[ends] - c_q[starts]
    s_tq = c_tq[ends] - c_tq[starts]
    denominator = n * s_tt - s_t * s_t
    with np.errstate(divide="ignore", invalid="ignore"):
        slopes = (n[:, None] * s_tq - s_t[:, None] * s_q) / denominator[:, None]
    return slopes, ends - starts, starts


def still_configuration(
    log: JointLog,
    time_s: float,
    *,
    window_s: float = STILL_WINDOW_S,
    speed_span_s: float = SPEED_SPAN_S,
    max_speed: float | ArrayLike = MAX_SPEED_RAD_S,
    speed_unit: Sequence[str] | None = None,
) -> StillWindow:
    """The configuration at ``time_s``: the mean over the still window around it.

    The robot is still when, over ``[time_s − window_s/2, time_s + window_s/2]``, every joint's
    speed — the least-squares slope of its readings over each span of ``speed_span_s`` in the
    window — stays at or below ``max_speed``. The window must lie inside the log (it is
    interpolated at its ends, never extrapolated).

    Args:
        log: the joint log.
        time_s: the moment, seconds on the log's clock.
        window_s: length of the still window, seconds (:data:`STILL_WINDOW_S`).
        speed_span_s: span of each speed estimate, seconds (:data:`SPEED_SPAN_S`); at most ``window_s``.
        max_speed: largest speed of a still joint, one number or ``(nq,)`` (rad/s for revolute
            joints; :data:`MAX_SPEED_RAD_S`).
        speed_unit: ``(nq,)`` unit of each joint's speed for messages (default ``rad/s``).

    Returns:
        the :class:`StillWindow`.

    Raises:
        InputError: naming the log and the time: outside the log, window beyond the log, too few
            readings to judge, or the robot moving (the fastest joint and its speed).
    """
    t = check_range(time_s, "time", unit="s")
    window_s = check_range(window_s, "still window", low=0.0, low_open=True, unit="s")
    speed_span_s = check_range(speed_span_s, "speed span", low=0.0, high=window_s, low_open=True, unit="s")
    nq = log.q.shape[1]
    limit = np.broadcast_to(np.asarray(max_speed, dtype=float), (nq,))
    if not np.all(np.isfinite(limit) & (limit > 0)):
        raise InputError(f"the largest still speed must be positive and finite, got {np.asarray(max_speed)}")
    units = list(speed_unit) if speed_unit is not None else ["rad/s"] * nq
    t0, t1 = float(log.time[0]), float(log.time[-1])
    when = f"{t:.3f} s ({t - t0:.3f} s into the log)"
    span = f"the log's span [{t0:.3f}, {t1:.3f}] s"
    if not t0 <= t <= t1:
        raise InputError(f"time {t:.3f} s is outside {span}", file=log.source)
    a, b = t - window_s / 2, t + window_s / 2
    if a < t0 or b > t1:
        raise InputError(
            f"the {window_s:g} s still window around {when} reaches beyond {span}; the log is never extrapolated",
            file=log.source,
        )
    i = int(np.searchsorted(log.time, a, side="left"))
    j = int(np.searchsorted(log.time, b, side="right"))
    times = log.time[i:j] - t  # relative: stamps near 1.7e9 s would lose digits in the sums
    readings = log.q[i:j]
    centre = readings.mean(axis=0) if len(readings) else np.zeros(nq)
    slopes, counts, starts = _span_slopes(times, readings - centre, speed_span_s, b - t)
    if len(counts) == 0 or counts.min() < MIN_SPAN_READINGS:
        fewest = int(counts.min()) if len(counts) else len(times)
        raise InputError(
            f"at {when} the log holds only {fewest} reading(s) in {speed_span_s:g} s: too sparse to tell "
            f"whether the robot was still (at least {MIN_SPAN_READINGS} per speed span are needed)",
            file=log.source,
        )
    speed = np.abs(slopes).max(axis=0)
    ratio = speed / limit
    if ratio.max() > 1.0:
        k = int(np.argmax(ratio))
        span_k = int(np.argmax(np.abs(slopes[:, k])))
        moving_at = t + times[starts[span_k]] + speed_span_s / 2
        raise InputError(
            f"the robot was moving at {when}: {log.joint_names[k]} at {speed[k]:.3g} {units[k]} "
            f"around {moving_at - t0:.2f} s into the log (still means at most {limit[k]:g} {units[k]} "
            f"for {window_s:g} s around the moment)",
            file=log.source,
        )
    qa, qb = _at(log, a), _at(log, b)
    T = np.concatenate([[a - t], times, [b - t]])
    Q = np.vstack([qa, readings, qb])
    integral = (np.diff(T)[:, None] * (Q[1:] + Q[:-1]) / 2).sum(axis=0)
    q = integral / (b - a)
    spread = readings.std(axis=0)
    return StillWindow(time_s=t, q=q, start_s=a, end_s=b, samples=len(times), spread=spread, speed=speed)


# --- marks ---------------------------------------------------------------------------------------
def _mark(time_s: float, kind: str, tool: str, name: str, *, source: str, row: int, row_label: str) -> Mark:
    """A validated mark; refusals name the source, the row and the field."""

    def fail(message: str, column: str) -> InputError:
        return InputError(message, file=source, row=row, column=column, row_label=row_label)

    if not math.isfinite(time_s):
        raise fail(f"time must be a finite number, got {time_s}", "time")
    if kind not in MARK_KINDS:
        raise fail(f"unknown kind {kind!r} (expected {', '.join(MARK_KINDS)})", "kind")
    tools, names, what = (
        (TOUCH_TOOLS, REFERENCES, "reference tip") if kind == "touch" else (AXES_TOOLS, AXES_POINTS, "axes point")
    )
    article = "a touch" if kind == "touch" else "an axes"
    if tool not in tools:
        raise fail(f"unknown tool {tool!r} for {article} mark (expected {', '.join(tools)})", "tool")
    if name not in names:
        raise fail(f"unknown {what} {name!r} for {article} mark (expected {', '.join(names)})", "name")
    return Mark(float(time_s), kind, tool, name, source, row, row_label)


def _in_time_order(marks: list[Mark]) -> list[Mark]:
    return sorted(marks, key=lambda m: m.time_s)  # stable: equal times keep the file's order


def read_marks(path: str | os.PathLike[str], *, allow_empty: bool = False) -> list[Mark]:
    """Read ``marks.csv`` (``time,kind,tool,name``), in time order.

    Raises:
        InputError: naming the row and column: a time that is not a finite number, an unknown
            kind, tool or name; or a file without marks (unless ``allow_empty``: a check without touches).
    """
    path = Path(path)
    header, rows, records = read_table(path, ["time", "kind", "tool", "name"])
    times = to_float(path, header, rows, records, ["time"])[:, 0]
    k_kind, k_tool, k_name = (header.index(c) for c in ("kind", "tool", "name"))
    marks = [
        _mark(
            float(time),
            fields[k_kind].strip(),
            fields[k_tool].strip(),
            fields[k_name].strip(),
            source=str(path),
            row=row,
            row_label="row",
        )
        for time, row, fields in zip(times, rows, records, strict=True)
    ]
    if not marks and not allow_empty:
        raise InputError("no marks (expected one row per touch and axes point)", file=path)
    return _in_time_order(marks)


def read_bag_marks(path: str | os.PathLike[str], topic: str, *, allow_empty: bool = False) -> list[Mark]:
    """Read marks from ``std_msgs/String`` messages ``kind,tool,name`` on ``topic`` of a ROS bag.

    A mark's time is the time the bag recorded the message (``String`` carries no header).
    ``path`` is a ROS 1 ``.bag`` file or a ROS 2 bag folder (or its ``.db3``/``.mcap`` file).

    Raises:
        InputError: unreadable bag, no such topic, another message type, a message that is not
            three comma-separated fields (naming its number on the topic), or no marks (unless
            ``allow_empty``).
    """
    source = str(bag_folder(path))
    marks: list[Mark] = []
    for source, number, bag_time, message in bag_messages(path, topic, MARK_TYPE):
        # The topic was checked to carry MARK_TYPE; rosbags returns `object`.
        text = str(cast("StringMsg", message).data)
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != 3:
            raise InputError(
                f"mark {text!r} is not 'kind,tool,name' (e.g. 'touch,needle,rtip1')",
                file=source,
                row=number,
                row_label="message",
            )
        marks.append(_mark(bag_time * 1e-9, *fields, source=source, row=number, row_label="message"))
    if not marks and not allow_empty:
        raise InputError(f"topic {topic!r} has no marks", file=source)
    return _in_time_order(marks)


# --- frames --------------------------------------------------------------------------------------
def read_images(
    path: str | os.PathLike[str], *, markups: Sequence[FloatArray | None] | None = None, markups_source: str = ""
) -> list[Frame]:
    """Read ``images.csv``: ``time,u_px,v_px[,sample]``, one row per captured frame.

    Args:
        path: the CSV file. Empty ``u_px`` and ``v_px`` mark a frame without annotation.
        markups: annotations from elsewhere (:func:`read_slicer_markups`), one per row of the file
            in order (``None`` for a frame not annotated); the file then has no ``u_px``/``v_px``.
        markups_source: where ``markups`` came from, for messages.

    Returns:
        the frames in the file's order.

    Raises:
        InputError: naming the row and column: a time or pixel that is not a finite number, one
            of ``u_px``/``v_px`` empty without the other, a sample name given twice, annotations
            both in the file and from markups, or as many markups as rows.
    """
    path = Path(path)
    header, rows, records = read_table(path, ["time"])
    has_uv = "u_px" in header or "v_px" in header
    if markups is not None and has_uv:
        raise InputError(
            f"has u_px/v_px columns and annotations come from {markups_source or 'markups'}: give them in one place",
            file=path,
            row=1,
        )
    if markups is None:
        for column in ("u_px", "v_px"):
            if column not in header:
                raise InputError(f"no {column!r} column in the header (or give the annotations as markups)", file=path)
    times = to_float(path, header, rows, records, ["time"])[:, 0]
    k_sample = header.index("sample") if "sample" in header else None
    if markups is not None and len(markups) != len(records):
        raise InputError(
            f"{len(records)} frames but {len(markups)} control points in {markups_source or 'the markups'} "
            "(one per frame, in order)",
            file=path,
        )
    frames: list[Frame] = []
    seen: dict[str, int] = {}
    times_seen: dict[float, int] = {}
    for k, (time, row, fields) in enumerate(zip(times, rows, records, strict=True)):
        if not math.isfinite(time):
            raise InputError(f"time must be a finite number, got {time}", file=path, row=row, column="time")
        sample = (fields[k_sample].strip() or None) if k_sample is not None else None
        if time in times_seen:  # one image listed twice would become two samples of one pose
            raise InputError(
                f"the frame at {time:g} s is listed twice (also row {times_seen[time]})",
                file=path,
                row=row,
                column="time",
            )
        times_seen[time] = row
        if sample is not None:
            check_token(sample, "sample", file=path, row=row, column="sample")
            if sample in seen:
                raise InputError(
                    f"sample {sample!r} appears twice (also row {seen[sample]})", file=path, row=row, column="sample"
                )
            seen[sample] = row
        if markups is not None:
            uv, annotated_in = markups[k], f"{markups_source or 'markups'}, control point {k + 1}"
        else:
            uv, annotated_in = _uv_field(path, header, row, fields), ""
        frames.append(Frame(float(time), uv, sample, str(path), row, annotated_in))
    if not frames:
        raise InputError("no frames (expected one row per captured image)", file=path)
    return frames


def _uv_field(path: Path, header: list[str], row: int, fields: list[str]) -> FloatArray | None:
    text = {c: fields[header.index(c)] for c in ("u_px", "v_px")}
    if not text["u_px"].strip() and not text["v_px"].strip():
        return None
    uv = []
    for column, value in text.items():
        if not value.strip():
            other = "v_px" if column == "u_px" else "u_px"
            raise InputError(
                f"empty while {other} is given (leave both empty for a frame not annotated)",
                file=path,
                row=row,
                column=column,
            )
        x = number_from_text(value)
        if x is None:
            raise InputError(f"{value!r} is not a number", file=path, row=row, column=column)
        if not math.isfinite(x):
            raise InputError(f"must be a finite number, got {value!r}", file=path, row=row, column=column)
        uv.append(x)
    return np.array(uv)


def read_slicer_markups(path: str | os.PathLike[str], spacing_mm: ArrayLike) -> list[FloatArray | None]:
    """Annotated pixels from a 3D Slicer markups file (``.mrk.json``): one control point per frame.

    Convention: each frame was loaded into Slicer as a 2D image volume whose origin is the centre
    of pixel (0, 0), with identity directions in LPS (x along columns, y along rows: what ITK and
    Slicer give a 2D image) and pixel spacing ``spacing_mm``. A control point at LPS position
    ``(x, y, z)`` mm is then the pixel ``(u, v) = (x / s_u, y / s_v)``; RAS positions are turned to
    LPS first (``x_LPS = −x_RAS``, ``y_LPS = −y_RAS``). A point more than half a pixel off the
    frame's plane (``|z| > min(s_u, s_v) / 2``) does not fit the convention and is refused.

    Args:
        path: the ``.mrk.json`` file: one markup (a point list) with one control point per frame.
        spacing_mm: ``(2,)`` the image volume's spacing in Slicer, mm/px (the scanner's spacing, or
            1, 1 for frames loaded as plain images).

    Returns:
        per control point in order, ``(2,)`` pixels or ``None`` when its position is not defined
        (``positionStatus`` ``undefined`` or ``preview``: a frame not annotated).

    Raises:
        InputError: not JSON, not one point list, an unknown coordinate system or unit, a position
            that is not three finite numbers, or a point off the frame's plane (naming the point).
    """
    path = Path(path)
    spacing = np.asarray(spacing_mm, dtype=float)
    raw = read_json(path)
    markups = raw.get("markups") if isinstance(raw, dict) else None
    if not isinstance(markups, list) or len(markups) != 1 or not isinstance(markups[0], dict):
        count = len(markups) if isinstance(markups, list) else "no"
        raise InputError(
            f"expected a Slicer markups file with one point list ('markups': [ ... ]), found {count} markups",
            file=path,
        )
    markup = markups[0]
    if markup.get("type", "Fiducial") != "Fiducial":
        raise InputError(f"the markup is a {markup.get('type')!r}, expected a point list ('Fiducial')", file=path)
    system = markup.get("coordinateSystem", "LPS")
    if system not in ("LPS", "RAS"):
        raise InputError(f"coordinateSystem {system!r} is neither LPS nor RAS", file=path)
    units = markup.get("coordinateUnits", "mm")
    unit = units[0] if isinstance(units, list) and units else units
    if unit not in ("mm", "um"):
        raise InputError(f"coordinateUnits {units!r}: expected mm or um", file=path)
    scale = 1.0 if unit == "mm" else 1e-3  # to millimetres
    points = markup.get("controlPoints")
    if not isinstance(points, list) or not points:
        raise InputError("the point list has no control points (expected one per frame)", file=path)
    out: list[FloatArray | None] = []

    def fail(message: str, row: int) -> InputError:
        return InputError(message, file=path, row=row, row_label="control point")

    for k, point in enumerate(points, start=1):
        label = point.get("label", "") if isinstance(point, dict) else ""
        named = f" ({label!r})" if label else ""
        if not isinstance(point, dict):
            raise fail("is not an object", k)
        status = point.get("positionStatus", "defined")
        if status in ("undefined", "preview"):
            out.append(None)
            continue
        if status != "defined":
            raise fail(f"positionStatus {status!r}{named} is not defined, undefined or preview", k)
        position = point.get("position")
        if (
            not isinstance(position, list)
            or len(position) != 3
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in position)
            or not all(math.isfinite(x) for x in position)
        ):
            raise fail(f"position{named} must be three finite numbers, got {position!r}", k)
        x, y, z = (float(v) * scale for v in position)
        if system == "RAS":
            x, y = -x, -y
        if abs(z) > spacing.min() / 2:
            raise fail(
                f"point{named} lies {z:g} mm off the frame's plane: markups must be placed on the 2D frame "
                "(origin at pixel (0, 0), identity directions)",
                k,
            )
        out.append(np.array([x / spacing[0], y / spacing[1]]))
    return out

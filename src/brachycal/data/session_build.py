"""Session build: a lab's recording → a session folder (``brachycal-session/1``) and a build report.

Inputs (:mod:`brachycal.data.recording` reads them): the joint log (CSV or ROS bag), the operator's
marks, the captured frames with their annotations, and optionally the plan from ``brachycal
plan``. Each mark and each annotated frame gets the configuration of the still window around its
time (:func:`~brachycal.data.recording.still_configuration`); a mark or annotated frame taken
while the robot moved, or outside the log, is refused — the whole build, naming it and its time,
since a session silently short of a touch would calibrate something else. A frame without an
annotation is skipped and reported.

Frames become samples named by ``images.csv``'s ``sample`` column; without it, with a plan, each
frame is paired with the planned pose nearest in joint space (and must be at least twice as near
to it as to any other: :data:`PAIRING_RATIO`), otherwise named ``frame<k>`` (the k-th frame). The report lists
every entry (marks and frames) with its still window — readings, the joints' spread (the encoder
noise a still robot shows) and largest speed — the frames skipped and why, and the planned samples
without a used frame.

The build report is written into the session folder beside the session's files:
``build_report.json`` (format ``brachycal-session-build/1``, with the SHA-256 of every input) and
``build_report.csv`` (one row per entry).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data import read_joint_log  # the package's reader dispatch (CSV or bag)
from brachycal.data.formats.bags import DEFAULT_TOPIC, is_bag
from brachycal.data.formats.csv_log import read_table, to_float
from brachycal.data.joint_log import (
    LIMIT_TOLERANCE_RAD,
    JointLog,
    configurations_from_columns,
    joint_columns,
    limit_tolerance,
)
from brachycal.data.recording import (
    AXES_POINTS,
    AXES_TOOLS,
    MAX_SPEED_RAD_S,
    REFERENCES,
    SPEED_SPAN_S,
    STILL_WINDOW_S,
    TOUCH_TOOLS,
    Frame,
    Mark,
    StillWindow,
    read_bag_marks,
    read_images,
    read_marks,
    read_slicer_markups,
    still_configuration,
)
from brachycal.data.session import (
    CHECK_TOOLS,
    MIN_CHECK_SAMPLES,
    ImageSector,
    Session,
    Touches,
    read_image_sector,
    read_session_toml,
    write_check_session,
    write_session,
)
from brachycal.errors import BrachycalWarning, InputError
from brachycal.io import OutputSet, output_set, sha256_file, write_csv, write_json
from brachycal.se3 import FloatArray
from brachycal.validate import MAX_IMAGE_PX, check_pixel, check_range, check_spacing_mm, check_token, check_vector

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot

__all__ = [
    "FORMAT",
    "PAIRING_RATIO",
    "REPORT_FILES",
    "BuildEntry",
    "BuildReport",
    "ImageSettings",
    "PlannedSamples",
    "SessionBuild",
    "StillSettings",
    "build_check_session",
    "build_session",
    "build_session_from_files",
    "read_plan",
    "session_settings",
    "write_build",
]

FORMAT = "brachycal-session-build/1"
#: The build report's files, written into the session folder.
REPORT_FILES = ("build_report.json", "build_report.csv")
#: A frame without a sample name is paired with its nearest planned pose only if that pose is at
#: most this fraction of the distance (joint space, Euclidean) to the next nearest one: then the
#: frame lies on its pose's side of every midpoint with a margin of a quarter of the poses'
#: spacing. On the twin the largest ratio is 0.19 (the probe's adjustment moves the left arm by up
#: to 0.018 rad; neighbouring poses lie 0.08 rad or more apart).
PAIRING_RATIO = 0.5
#: Longest still window accepted, seconds: longer than an operator holds a pose is a typo.
MAX_WINDOW_S = 60.0
#: Largest "still" speed accepted, rad/s: at 1 rad/s a robot is moving (a typo guard).
MAX_STILL_SPEED_RAD_S = 1.0


@dataclass(frozen=True)
class StillSettings:
    """What "the robot was still" means (see :mod:`brachycal.data.recording` for the defaults' reasons).

    Attributes:
        window_s: still window centred on each mark or frame, seconds, in (0, 60].
        speed_span_s: span of each speed estimate, seconds, in (0, ``window_s``].
        max_speed_rad_s: largest speed of a still joint, rad/s, in (0, 1] (a prismatic joint's
            in m/s, scaled as the joint-limit tolerances: 1e-3 m per rad).

    Raises:
        InputError: a setting out of its range (named).
    """

    window_s: float = STILL_WINDOW_S
    speed_span_s: float = SPEED_SPAN_S
    max_speed_rad_s: float = MAX_SPEED_RAD_S

    def __post_init__(self) -> None:
        check_range(self.window_s, "still window", low=0.0, high=MAX_WINDOW_S, low_open=True, unit="s")
        check_range(self.speed_span_s, "speed span", low=0.0, low_open=True, unit="s")
        if self.speed_span_s > self.window_s:
            raise InputError(
                f"speed span {self.speed_span_s:g} s is longer than the still window {self.window_s:g} s; "
                "the speed is judged inside the window"
            )
        check_range(
            self.max_speed_rad_s, "still speed", low=0.0, high=MAX_STILL_SPEED_RAD_S, low_open=True, unit="rad/s"
        )


@dataclass(frozen=True)
class ImageSettings:
    """What ``session.toml`` holds.

    Attributes:
        spacing_m: ``(2,)`` nominal pixel spacing ``(s_u, s_v)``, metres per pixel.
        size_px: ``(2,)`` image width and height, pixels.
        p_ER_Mtip: ``(3,)`` top-model tip on the right flange, metres.
        sector: the probe's imaging sector, if the template states it (``[image.sector]``).
    """

    spacing_m: FloatArray
    size_px: np.ndarray
    p_ER_Mtip: FloatArray
    sector: ImageSector | None = None


def session_settings(
    template: str | os.PathLike[str] | None = None,
    *,
    spacing_mm: ArrayLike | None = None,
    size_px: ArrayLike | None = None,
    top_model_tip_mm: ArrayLike | None = None,
) -> ImageSettings:
    """The session's image and top-model settings: from a template ``session.toml``, each value
    replaced by the one given; without a template every value must be given.

    Args:
        template: a ``session.toml`` (format ``brachycal-session/1``), read and validated.
        spacing_mm: ``(2,)`` pixel spacing, mm/px.
        size_px: ``(2,)`` image width and height, whole pixels.
        top_model_tip_mm: ``(3,)`` ``p_ER_Mtip`` in millimetres.

    Raises:
        InputError: a value missing (no template) or out of range, or the template refused.
    """
    spacing_m: FloatArray | None
    size: np.ndarray | None
    tip_m: FloatArray | None
    sector: ImageSector | None
    if template is not None:
        given = {
            "image.spacing_mm": spacing_mm,
            "image.size_px": size_px,
            "top_model.tip_in_flange_mm": top_model_tip_mm,
        }
        spacing_m, size, tip_m = read_session_toml(template, blank_ok=[k for k, v in given.items() if v is not None])
        sector = read_image_sector(template)
    else:
        missing = [
            option
            for option, value in (
                ("--spacing-mm", spacing_mm),
                ("--size-px", size_px),
                ("--top-model-tip-mm", top_model_tip_mm),
            )
            if value is None
        ]
        if missing:
            raise InputError(
                f"without a template session.toml, give {', '.join(missing)} (the session's image and top-model tip)"
            )
        spacing_m = size = tip_m = sector = None
    if spacing_mm is not None:
        spacing_m = check_spacing_mm(spacing_mm, "--spacing-mm") * 1e-3
    if size_px is not None:
        size_values = check_vector(size_px, "--size-px", 2, low=1, high=MAX_IMAGE_PX, unit="px")
        if np.any(size_values != np.round(size_values)):
            raise InputError(f"--size-px must be whole pixels, got {np.asarray(size_px).tolist()}")
        size = size_values.astype(int)
    if top_model_tip_mm is not None:
        # 2 m from the flange is beyond any tool the arm can carry: a typo or metres given as mm.
        tip_m = check_vector(top_model_tip_mm, "--top-model-tip-mm", 3, low=-2000.0, high=2000.0, unit="mm") * 1e-3
    return ImageSettings(np.asarray(spacing_m, float), np.asarray(size, int), np.asarray(tip_m, float), sector)


@dataclass(frozen=True)
class PlannedSamples:
    """The sample poses of a plan CSV (``brachycal plan``), in visiting order.

    Attributes:
        names: ``(N,)`` grid point names.
        q: ``(N, nq)`` planned configurations, radians, in the robot's joint order.
        uv_px: ``(N, 2)`` where the needle tip should show in the image.
        source: the plan file.
    """

    names: list[str]
    q: FloatArray
    uv_px: FloatArray
    source: str


def read_plan(path: str | os.PathLike[str], robot: Robot) -> PlannedSamples:
    """Read the pose table written by ``brachycal plan`` (the radian joint columns; ``_deg`` ignored).

    Raises:
        InputError: naming the row and column (a missing joint, a non-number, a name twice, …).
    """
    path = Path(path)
    header, rows, records = read_table(path, ["point", "u_px", "v_px"])
    k = header.index("point")
    names = [fields[k].strip() for fields in records]
    seen: dict[str, int] = {}
    for row, name in zip(rows, names, strict=True):
        if not name:
            raise InputError("empty point name", file=path, row=row, column="point")
        check_token(name, "point", file=path, row=row, column="point")
        if name in seen:
            raise InputError(
                f"point {name!r} appears twice (also row {seen[name]})", file=path, row=row, column="point"
            )
        seen[name] = row
    if not names:
        raise InputError("the plan has no poses", file=path)
    uv = to_float(path, header, rows, records, ["u_px", "v_px"])
    joints = joint_columns(robot, header)
    q = configurations_from_columns(
        robot, joints, to_float(path, header, rows, records, joints), source=str(path), rows=rows
    )
    return PlannedSamples(names, q, uv, str(path))


@dataclass(frozen=True)
class BuildEntry:
    """One mark or frame of the recording and what the build made of it.

    Attributes:
        kind: ``touch``, ``axes`` or ``frame``.
        what: ``needle rtip1 trial 2``, ``probe p3``, or the sample's name (``frame <k>`` for a skipped
            frame without one).
        time_s: its time on the log's clock, seconds.
        source, row, row_label: where it was read.
        used: whether it is in the session.
        reason: why not (``""`` when used).
        planned: the planned sample it was paired with (frames with a plan; ``""`` otherwise).
        readings: log readings in its still window (0 when no window was taken).
        window_s: the still window's length, seconds.
        spread_rad: the largest standard deviation of a joint's readings in the window, radians
            (``None`` without a window).
        speed_rad_s: the largest joint speed in the window, rad/s (``None`` without a window).
    """

    kind: str
    what: str
    time_s: float
    source: str
    row: int
    row_label: str
    used: bool
    reason: str = ""
    planned: str = ""
    readings: int = 0
    window_s: float = 0.0
    spread_rad: float | None = None
    speed_rad_s: float | None = None

    def as_dict(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "what": self.what,
            "time_s": self.time_s,
            "status": "used" if self.used else "skipped",
            "reason": self.reason,
            "source": self.source,
            "row": self.row,
            "row_label": self.row_label,
            "planned": self.planned,
            "readings": self.readings,
            "window_s": self.window_s,
            "spread_rad": self.spread_rad,
            "speed_rad_s": self.speed_rad_s,
        }


@dataclass(frozen=True)
class BuildReport:
    """What the build used, skipped and missed.

    Attributes:
        log: the joint log's source; ``log_readings``, ``log_start_s``, ``log_end_s`` its size and span.
        still: the still settings used.
        entries: every mark (in time order) then every frame (in file order).
        plan: the plan's source (``""`` without a plan); ``planned`` its sample names.
        planned_missing: planned samples without a used frame, in plan order.
        inputs: input name → SHA-256 (filled by :func:`build_session_from_files`).
        lag_s, lag_sd_s: the frames' clock lag applied (:func:`build_session`) and its SD, seconds.
        lag_sensitive: frames whose still window would not hold at the lag ± :data:`LAG_COVERAGE_SD` SD.
        kind: ``calibration`` (a calibration session) or ``check`` (a check session, ``brachycal verify``'s).
    """

    log: str
    log_readings: int
    log_start_s: float
    log_end_s: float
    still: StillSettings
    entries: tuple[BuildEntry, ...]
    plan: str = ""
    planned: tuple[str, ...] = ()
    planned_missing: tuple[str, ...] = ()
    inputs: dict[str, str] = field(default_factory=dict)
    lag_s: float = 0.0
    lag_sd_s: float = 0.0
    lag_sensitive: tuple[str, ...] = ()
    kind: str = "calibration"

    @property
    def marks(self) -> list[BuildEntry]:
        return [e for e in self.entries if e.kind != "frame"]

    @property
    def frames_used(self) -> list[BuildEntry]:
        return [e for e in self.entries if e.kind == "frame" and e.used]

    @property
    def frames_skipped(self) -> list[BuildEntry]:
        return [e for e in self.entries if e.kind == "frame" and not e.used]

    def summary(self) -> str:
        """A few lines for a person: counts, still windows, skipped frames, missing planned samples."""
        touches = [e for e in self.marks if e.kind == "touch"]
        axes = [e for e in self.marks if e.kind == "axes"]
        windowed = [e for e in self.entries if e.used]
        readings = sorted({e.readings for e in windowed})
        counts = f"{readings[0]}" if len(readings) == 1 else f"{readings[0]}-{readings[-1]}"
        span = self.log_end_s - self.log_start_s
        rate = (self.log_readings - 1) / span if span > 0 else 0.0
        lines = [
            f"joint log: {self.log} ({self.log_readings} readings over {span:.1f} s, ~{rate:.0f} Hz)",
            f"marks: {len(self.marks)} used ({len(touches)} touches, {len(axes)} axes points)",
            f"frames: {len(self.frames_used)} used as samples, {len(self.frames_skipped)} skipped",
        ]
        for e in self.frames_skipped:
            lines.append(f"  skipped {e.source}, row {e.row} ({e.time_s - self.log_start_s:.2f} s): {e.reason}")
        if windowed:
            lines.append(
                f"still windows: {self.still.window_s:g} s, {counts} readings, joint spread "
                f"<= {max(e.spread_rad or 0.0 for e in windowed):.2g} rad (SD), speed <= "
                f"{max(e.speed_rad_s or 0.0 for e in windowed):.2g} rad/s (still: <= {self.still.max_speed_rad_s:g})"
            )
        if self.plan:
            missing = ", ".join(self.planned_missing) if self.planned_missing else "none"
            lines.append(f"plan: {self.plan}: {len(self.planned)} planned samples, missing: {missing}")
        return "\n".join(lines)

    def as_json(self) -> dict[str, object]:
        return {
            "format": FORMAT,
            "kind": self.kind,
            "log": {
                "source": self.log,
                "readings": self.log_readings,
                "start_s": self.log_start_s,
                "end_s": self.log_end_s,
            },
            "still": {
                "window_s": self.still.window_s,
                "speed_span_s": self.still.speed_span_s,
                "max_speed_rad_s": self.still.max_speed_rad_s,
            },
            "counts": {
                "touches": sum(e.kind == "touch" for e in self.entries),
                "axes": sum(e.kind == "axes" for e in self.entries),
                "frames_used": len(self.frames_used),
                "frames_skipped": len(self.frames_skipped),
                "planned": len(self.planned),
                "planned_missing": len(self.planned_missing),
            },
            "plan": {"source": self.plan, "missing": list(self.planned_missing)},
            "clock": {"lag_s": self.lag_s, "lag_sd_s": self.lag_sd_s, "lag_sensitive": list(self.lag_sensitive)},
            "entries": [e.as_dict() for e in self.entries],
            "inputs": dict(self.inputs),
        }


@dataclass(frozen=True)
class SessionBuild:
    """A built session and its report; a check session (``report.kind == "check"``) has no axes and
    only the needle's and the probe's touches."""

    session: Session
    report: BuildReport

    @property
    def check(self) -> bool:
        return self.report.kind == "check"


def _speed_limits(robot: Robot, max_speed_rad_s: float) -> tuple[FloatArray, list[str]]:
    """Per joint: the still speed (rad/s, or m/s for prismatic joints at 1e-3 m per rad) and its unit."""
    scale = limit_tolerance(robot) / LIMIT_TOLERANCE_RAD
    units = ["rad/s" if s == 1.0 else "m/s" for s in scale]
    return max_speed_rad_s * scale, units


def _window(log: JointLog, time_s: float, still: StillSettings, limits: FloatArray, units: list[str]) -> StillWindow:
    return still_configuration(
        log,
        time_s,
        window_s=still.window_s,
        speed_span_s=still.speed_span_s,
        max_speed=limits,
        speed_unit=units,
    )


def _entry(kind: str, what: str, item: Mark | Frame, window: StillWindow | None, **extra: object) -> BuildEntry:
    row_label = item.row_label if isinstance(item, Mark) else "row"
    stats: dict[str, object] = {}
    if window is not None:
        stats = {
            "readings": window.samples,
            "window_s": window.window_s,
            "spread_rad": float(window.spread.max()),
            "speed_rad_s": float(window.speed.max()),
        }
    return BuildEntry(kind, what, item.time_s, item.source, item.row, row_label, **stats, **extra)  # type: ignore[arg-type]


def _mark_window(log: JointLog, mark: Mark, still: StillSettings, limits: FloatArray, units: list[str]) -> StillWindow:
    """The still window of ``mark``; a refusal names the mark, its file and row."""
    try:
        return _window(log, mark.time_s, still, limits, units)
    except InputError as exc:
        raise InputError(
            f"{mark.label}: {exc.problem}", file=mark.source, row=mark.row, row_label=mark.row_label
        ) from None


def _marks(
    log: JointLog, marks: Sequence[Mark], still: StillSettings, limits: FloatArray, units: list[str]
) -> tuple[dict[tuple[str, str], Touches], dict[str, dict[str, FloatArray]], list[BuildEntry]]:
    if not marks:
        raise InputError("no marks: a session needs the touches and the axes points")
    source = marks[0].source
    touch_q: dict[tuple[str, str], list[FloatArray]] = {}
    axes: dict[str, dict[str, FloatArray]] = {tool: {} for tool in AXES_TOOLS}
    axes_row: dict[tuple[str, str], int] = {}
    entries = []
    for mark in sorted(marks, key=lambda m: m.time_s):
        window = _mark_window(log, mark, still, limits, units)
        if mark.kind == "touch":
            trials = touch_q.setdefault((mark.tool, mark.name), [])
            trials.append(window.q)
            what = f"{mark.tool} {mark.name} trial {len(trials)}"
        else:
            if mark.name in axes[mark.tool]:
                raise InputError(
                    f"{mark.tool} {mark.name} is marked twice (also {mark.row_label} "
                    f"{axes_row[mark.tool, mark.name]}); keep the one taken at the pose",
                    file=mark.source,
                    row=mark.row,
                    row_label=mark.row_label,
                )
            axes[mark.tool][mark.name] = window.q
            axes_row[mark.tool, mark.name] = mark.row
            what = f"{mark.tool} {mark.name}"
        entries.append(_entry(mark.kind, what, mark, window, used=True))
    if not any(tool == "top_model" for tool, _ in touch_q) and not any(axes.values()):
        raise InputError(
            "no top-model touches and no axes points: a check recording? build it with --check (a calibration "
            "session needs every tool's touches on rtip1 and rtip2 and the axes moves)",
            file=source,
        )
    for tool in TOUCH_TOOLS:
        for reference in REFERENCES:
            if (tool, reference) not in touch_q:
                raise InputError(
                    f"no touch mark of {tool} on {reference} (a session needs every tool on both)", file=source
                )
    for reference in REFERENCES:
        counts = {tool: len(touch_q[tool, reference]) for tool in TOUCH_TOOLS}
        if len(set(counts.values())) > 1:
            listed = ", ".join(f"{tool} {n}" for tool, n in counts.items())
            raise InputError(
                f"unequal touches on {reference} ({listed}): validation pairs the tools trial by trial", file=source
            )
    for tool in AXES_TOOLS:
        for point in AXES_POINTS:
            if point not in axes[tool]:
                raise InputError(f"no axes mark of {tool} at {point} (the axes moves need p1, p2 and p3)", file=source)
    touches = {
        key: Touches(np.arange(1, len(q) + 1), np.array(q))
        for key in ((t, r) for t in TOUCH_TOOLS for r in REFERENCES)
        for q in [touch_q[key]]
    }
    axes_sorted = {tool: {point: axes[tool][point] for point in AXES_POINTS} for tool in AXES_TOOLS}
    return touches, axes_sorted, entries


def _check_marks(
    log: JointLog,
    marks: Sequence[Mark],
    still: StillSettings,
    limits: FloatArray,
    units: list[str],
    required: Sequence[str],
    source: str,
) -> tuple[dict[tuple[str, str], Touches], list[BuildEntry]]:
    """A check's marks: touches of the needle and the probe only (any tip, any count, trials in time
    order); each tool of ``required`` must touch ``rtip1``."""
    touch_q: dict[tuple[str, str], list[FloatArray]] = {}
    entries = []
    for mark in sorted(marks, key=lambda m: m.time_s):
        if mark.kind != "touch" or mark.tool not in CHECK_TOOLS:
            what = "top-model touches" if mark.kind == "touch" else "axes moves"
            raise InputError(
                f"{mark.label}: a check recording has no {what}, only the needle's and the probe's touches "
                "(a calibration recording? build it without --check)",
                file=mark.source,
                row=mark.row,
                row_label=mark.row_label,
            )
        window = _mark_window(log, mark, still, limits, units)
        trials = touch_q.setdefault((mark.tool, mark.name), [])
        trials.append(window.q)
        entries.append(_entry(mark.kind, f"{mark.tool} {mark.name} trial {len(trials)}", mark, window, used=True))
    for tool in required:
        if (tool, "rtip1") not in touch_q:
            raise InputError(
                f"no touch mark of {tool} on rtip1: the check's touches ({' and '.join(required)} on rtip1) "
                "need one each; a check planned without touches builds with --touches none",
                file=marks[0].source if marks else source or None,
            )
    touches = {key: Touches(np.arange(1, len(q) + 1), np.array(q)) for key, q in touch_q.items()}
    return touches, entries


def _nearest_planned(q: FloatArray, plan: PlannedSamples) -> tuple[int, float, int, float]:
    """Index and distance of the nearest planned pose and of the next nearest (joint space, radians)."""
    distance = np.linalg.norm(plan.q - q, axis=1)
    order = np.argsort(distance)
    if len(order) == 1:  # one planned pose: nothing to confuse it with
        return int(order[0]), float(distance[order[0]]), int(order[0]), np.inf
    return int(order[0]), float(distance[order[0]]), int(order[1]), float(distance[order[1]])


def _frames(
    log: JointLog,
    frames: Sequence[Frame],
    settings: ImageSettings,
    plan: PlannedSamples | None,
    still: StillSettings,
    limits: FloatArray,
    units: list[str],
) -> tuple[list[str], FloatArray, FloatArray, list[BuildEntry]]:
    names: list[str] = []
    qs: list[FloatArray] = []
    uvs: list[FloatArray] = []
    entries: list[BuildEntry] = []
    used_names: set[str] = set()
    for index, frame in enumerate(frames, start=1):
        label = frame.sample or f"frame {index}"
        if frame.uv_px is None:
            try:
                window = _window(log, frame.time_s, still, limits, units)
            except InputError:
                window = None  # never used, so neither refused: reported with the reason it has
            planned = ""
            if window is not None and plan is not None and frame.sample is None:
                k, d1, _, d2 = _nearest_planned(window.q, plan)
                planned = plan.names[k] if d1 <= PAIRING_RATIO * d2 else ""
            elif plan is not None and frame.sample in plan.names:
                planned = frame.sample or ""
            entries.append(_entry("frame", label, frame, window, used=False, reason="not annotated", planned=planned))
            continue
        annotated = f" (annotated in {frame.annotated_in})" if frame.annotated_in else ""
        try:
            uv = check_pixel(frame.uv_px, "annotated needle tip", size_px=settings.size_px)
        except InputError as exc:
            raise InputError(f"{exc.problem}{annotated}", file=frame.source, row=frame.row) from None
        try:
            window = _window(log, frame.time_s, still, limits, units)
        except InputError as exc:
            raise InputError(f"{label}: {exc.problem}", file=frame.source, row=frame.row) from None
        planned = ""
        if frame.sample is not None:
            name = frame.sample
            planned = name if plan is not None and name in plan.names else ""
        elif plan is not None:
            k, d1, k2, d2 = _nearest_planned(window.q, plan)
            if d1 > PAIRING_RATIO * d2:
                raise InputError(
                    f"{label} at {frame.time_s:.3f} s is about as near planned {plan.names[k]} ({d1:.3g} rad) as "
                    f"{plan.names[k2]} ({d2:.3g} rad): give its sample name in a 'sample' column",
                    file=frame.source,
                    row=frame.row,
                )
            name = planned = plan.names[k]
        else:
            name = f"frame{index}"
        unique, n = name, 1
        while unique in used_names:  # a pose captured twice: both images are samples, said so
            n += 1
            unique = f"{name}-{n}"
        if unique != name:
            warnings.warn(
                f"{frame.source}, row {frame.row}: {label} is a second image of {name}; it becomes sample {unique}",
                stacklevel=2,
            )
        used_names.add(unique)
        names.append(unique)
        qs.append(window.q)
        uvs.append(uv)
        entries.append(_entry("frame", unique, frame, window, used=True, planned=planned))
    return names, np.array(qs).reshape(len(qs), log.q.shape[1]), np.array(uvs).reshape(len(uvs), 2), entries


def build_session(
    log: JointLog,
    marks: Sequence[Mark],
    frames: Sequence[Frame],
    *,
    robot: Robot,
    settings: ImageSettings,
    plan: PlannedSamples | None = None,
    still: StillSettings = StillSettings(),
    lag_s: float = 0.0,
    lag_sd_s: float = 0.0,
) -> SessionBuild:
    """Assemble a session from a joint log, the marks and the frames.

    The frames' times may be on the ultrasound's clock: ``lag_s`` (``brachycal temporal``'s lag of
    the joint log behind the video) moves each to ``time_s + lag_s`` on the log's clock before its
    pose is taken. With ``lag_sd_s`` > 0, a used frame whose still window would not hold at the lag
    ± :data:`LAG_COVERAGE_SD` SD (the robot moves within the lag's uncertainty of it, or the log
    ends there) is warned about (:class:`~brachycal.errors.BrachycalWarning`) and listed in the
    report's ``lag_sensitive``. Marks stay on the log's clock.

    Args:
        log: the joint log (its configurations in ``robot``'s joint order).
        marks: touch and axes marks (any order; trials follow the order in time).
        frames: captured frames; those without an annotation are skipped and reported.
        robot: the model the log belongs to.
        settings: the session's image spacing and size and the top-model tip.
        plan: the planned samples, to name frames and report the ones missing.
        still: what "still" means.
        lag_s: added to every frame's time (seconds): the log's clock minus the frames'.
        lag_sd_s: the lag's standard deviation (seconds), for the warning above.

    Returns:
        the :class:`SessionBuild` (session in SI units, and the report).

    Raises:
        InputError: naming the mark or frame (file, row, time): outside the log, robot moving,
            a pixel outside the image, an axes point marked twice, a frame between two planned
            poses; or naming the file: a tool without touches on a tip, unequal trials, an axes
            point missing, no top-model touch nor axes point (a check recording), fewer than 3
            annotated frames or frames whose points are collinear.
    """
    return _build(log, marks, frames, robot, settings, plan, still, lag_s, lag_sd_s, check=None)


def build_check_session(
    log: JointLog,
    marks: Sequence[Mark],
    frames: Sequence[Frame],
    *,
    robot: Robot,
    settings: ImageSettings,
    touches: Sequence[str],
    plan: PlannedSamples | None = None,
    still: StillSettings = StillSettings(),
    lag_s: float = 0.0,
    lag_sd_s: float = 0.0,
    marks_source: str = "",
) -> SessionBuild:
    """Assemble a check session (``brachycal verify``'s CHECK_SESSION) from a check recording: the
    frames at the check's poses and the single touches of a reference tip, as :func:`build_session`
    reads them (still windows, clock lag, pairing with ``plan``: ``brachycal plan check``'s).

    Args:
        log: the joint log (its configurations in ``robot``'s joint order).
        marks: touch marks of the needle and the probe only (may be empty when ``touches`` is).
        frames: captured frames at the check's poses; those without an annotation are skipped.
        robot: the model the log belongs to.
        settings: the set-up's image spacing and size and the top-model tip (the calibration's).
        touches: the tools (``needle``, ``probe``) whose touch of ``rtip1`` the check planned: each
            must have one.
        plan: the check's planned poses (``brachycal plan check``'s), to name frames.
        still: what "still" means.
        lag_s: added to every frame's time (seconds), as for :func:`build_session`.
        lag_sd_s: the lag's standard deviation (seconds).
        marks_source: where the marks were read (a file that holds none is named by a refusal).

    Returns:
        the :class:`SessionBuild` (no axes; ``report.kind`` ``check``).

    Raises:
        InputError: as :func:`build_session` for a mark or frame; naming the mark: a top-model touch
            or an axes mark (a calibration recording); naming the file: a planned touch missing,
            fewer than :data:`~brachycal.data.session.MIN_CHECK_SAMPLES` annotated frames.
    """
    for tool in touches:
        if tool not in CHECK_TOOLS:
            raise InputError(f"a check's touches are by {' or '.join(CHECK_TOOLS)}, not {tool!r}")
    return _build(
        log, marks, frames, robot, settings, plan, still, lag_s, lag_sd_s, check=tuple(touches), source=marks_source
    )


def _build(
    log: JointLog,
    marks: Sequence[Mark],
    frames: Sequence[Frame],
    robot: Robot,
    settings: ImageSettings,
    plan: PlannedSamples | None,
    still: StillSettings,
    lag_s: float,
    lag_sd_s: float,
    *,
    check: tuple[str, ...] | None,
    source: str = "",
) -> SessionBuild:
    """:func:`build_session` (``check`` None) or :func:`build_check_session` (``check``: its touches)."""
    if tuple(log.joint_names) != tuple(robot.joint_names):
        raise InputError("the joint log's joints are not the robot's", file=log.source)
    lag_s = check_range(lag_s, "--lag-s", unit="s")
    lag_sd_s = check_range(lag_sd_s, "--lag-sd-s", low=0.0, unit="s")
    limits, units = _speed_limits(robot, still.max_speed_rad_s)
    axes: dict[str, dict[str, FloatArray]] = {}
    if check is None:
        touches, axes, mark_entries = _marks(log, marks, still, limits, units)
    else:
        touches, mark_entries = _check_marks(log, marks, still, limits, units, check, source)
    if lag_s != 0.0:
        frames = [replace(frame, time_s=frame.time_s + lag_s) for frame in frames]
    names, samples_q, uv, frame_entries = _frames(log, frames, settings, plan, still, limits, units)
    sensitive = _lag_sensitive(log, frame_entries, lag_s, lag_sd_s, still, limits, units)
    images = frames[0].source if frames else "images"
    if check is not None and len(names) < MIN_CHECK_SAMPLES:
        raise InputError(
            f"{len(names)} annotated frame(s) usable: a check needs at least {MIN_CHECK_SAMPLES} "
            "(brachycal plan check plans 5 to 16)",
            file=images,
        )
    if check is None and len(names) < 3:
        raise InputError(
            f"{len(names)} annotated frame(s) usable: at least 3 with non-collinear image points are needed",
            file=images,
        )
    centred = uv - uv.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if check is None and (s[0] == 0 or s[1] / s[0] < 1e-6):  # the session reader's own test
        raise InputError("the annotated image points are collinear: the image rotation is undetermined", file=images)
    session = Session(
        spacing_m=np.asarray(settings.spacing_m, float).copy(),
        size_px=np.asarray(settings.size_px).copy(),
        p_ER_Mtip=np.asarray(settings.p_ER_Mtip, float).copy(),
        sector=settings.sector,
        touches=touches,
        axes=axes,
        sample_ids=names,
        samples_q=samples_q,
        uv_px=uv,
        joint_names=tuple(robot.joint_names),
    )
    used_planned = {e.planned for e in frame_entries if e.used and e.planned}
    report = BuildReport(
        log=log.source,
        log_readings=len(log),
        log_start_s=float(log.time[0]),
        log_end_s=float(log.time[-1]),
        still=still,
        entries=(*mark_entries, *frame_entries),
        plan=plan.source if plan is not None else "",
        planned=tuple(plan.names) if plan is not None else (),
        planned_missing=tuple(n for n in plan.names if n not in used_planned) if plan is not None else (),
        lag_s=lag_s,
        lag_sd_s=lag_sd_s,
        lag_sensitive=sensitive,
        kind="calibration" if check is None else "check",
    )
    return SessionBuild(session, report)


#: A frame's pose must hold over the lag ± this many of its SDs (2: a normal lag error's 95 % interval).
LAG_COVERAGE_SD = 2.0


def _lag_sensitive(
    log: JointLog,
    entries: Sequence[BuildEntry],
    lag_s: float,
    lag_sd_s: float,
    still: StillSettings,
    limits: FloatArray,
    units: list[str],
) -> tuple[str, ...]:
    """Used frames whose still window fails at ``time ± LAG_COVERAGE_SD × lag_sd_s``, each warned about."""
    if lag_sd_s <= 0:
        return ()
    margin = LAG_COVERAGE_SD * lag_sd_s
    sensitive = []
    for entry in entries:
        if entry.kind != "frame" or not entry.used:
            continue
        for shift in (-margin, margin):
            try:
                _window(log, entry.time_s + shift, still, limits, units)
            except InputError as exc:
                sensitive.append(entry.what)
                where = f" ({entry.source}, row {entry.row})" if entry.source else ""
                warnings.warn(
                    f"{entry.what}{where}: its pose depends on the clock lag: with the lag at "
                    f"{(lag_s + shift) * 1e3:+.1f} ms ({lag_s * 1e3:+.1f} ms {'+' if shift > 0 else '-'} "
                    f"{LAG_COVERAGE_SD:g} SD) {exc.problem}",
                    BrachycalWarning,
                    stacklevel=3,
                )
                break
    return tuple(sensitive)


def build_session_from_files(
    log_path: str | os.PathLike[str],
    *,
    robot: Robot,
    images: str | os.PathLike[str],
    marks: str | os.PathLike[str] | None = None,
    marks_topic: str | None = None,
    joints_topic: str = DEFAULT_TOPIC,
    markups: str | os.PathLike[str] | None = None,
    markups_spacing_mm: ArrayLike | None = None,
    plan: str | os.PathLike[str] | None = None,
    settings: ImageSettings,
    still: StillSettings = StillSettings(),
    lag_s: float = 0.0,
    lag_sd_s: float = 0.0,
    check: Sequence[str] | None = None,
) -> SessionBuild:
    """:func:`build_session` from files (with ``check``, :func:`build_check_session` with those
    touches): everything is read and validated before anything is built.

    Args:
        log_path: the joint log, a CSV file or a ROS bag (:func:`~brachycal.data.read_joint_log`).
        images: ``images.csv`` (``time,u_px,v_px[,sample]``; ``time[,sample]`` with ``markups``).
        marks: ``marks.csv``; or, with ``marks_topic``, the marks are read from that topic of the bag.
        joints_topic: the bag's ``sensor_msgs/JointState`` topic.
        markups: a 3D Slicer ``.mrk.json`` with one control point per row of ``images``.
        markups_spacing_mm: the image spacing in Slicer (default: the session's spacing).
        plan: the plan CSV of ``brachycal plan``.
        settings: the session's image and top-model settings (:func:`session_settings`).
        still: what "still" means.
        lag_s: the frames' clock lag (:func:`build_session`), seconds.
        lag_sd_s: its standard deviation, seconds.
        check: build a check session whose touches of ``rtip1`` are by these tools (``()``: none;
            then the marks may be left out, or hold only their header).

    Raises:
        InputError: marks given both ways (or neither, for a calibration session), a marks topic on
            a CSV log, or any refusal of the readers and of the build.
    """
    log_path = Path(log_path)
    if (marks is not None and marks_topic is not None) or (marks is None and marks_topic is None and check is None):
        raise InputError("give the marks either as a file (--marks) or as a topic of the bag (--marks-topic)")
    if marks_topic is not None and not is_bag(log_path):
        raise InputError(f"--marks-topic needs a ROS bag, and {log_path} is not one")
    log = read_joint_log(log_path, robot, joints_topic)
    mark_list: list[Mark] = []
    if marks is not None:
        mark_list = read_marks(marks, allow_empty=check is not None)
    elif marks_topic is not None:
        mark_list = read_bag_marks(log_path, marks_topic, allow_empty=check is not None)
    markup_uv = None
    if markups is not None:
        spacing = settings.spacing_m * 1e3 if markups_spacing_mm is None else markups_spacing_mm
        spacing = check_spacing_mm(spacing, "--markups-spacing-mm")
        markup_uv = read_slicer_markups(markups, spacing)
    frame_list = read_images(images, markups=markup_uv, markups_source=str(markups) if markups else "")
    planned = read_plan(plan, robot) if plan is not None else None
    if check is None:
        build = build_session(
            log,
            mark_list,
            frame_list,
            robot=robot,
            settings=settings,
            plan=planned,
            still=still,
            lag_s=lag_s,
            lag_sd_s=lag_sd_s,
        )
    else:
        build = build_check_session(
            log,
            mark_list,
            frame_list,
            robot=robot,
            settings=settings,
            touches=check,
            plan=planned,
            still=still,
            lag_s=lag_s,
            lag_sd_s=lag_sd_s,
            marks_source=str(marks) if marks is not None else str(log_path),
        )
    inputs = {"log": sha256_file(log_path), "images": sha256_file(Path(images))}
    for name, path in (("marks", marks), ("markups", markups), ("plan", plan)):
        if path is not None:
            inputs[name] = sha256_file(Path(path))
    return replace(build, report=replace(build.report, inputs=inputs))


def write_build(
    build: SessionBuild, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> Path:
    """Write the session folder (a check session's, :data:`~brachycal.data.session.CHECK_FILES`, for a
    check) and the build report in it (:data:`REPORT_FILES`), all or nothing.

    With ``outputs`` (a command's :class:`~brachycal.io.OutputSet`) the files join that set.
    """
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        if build.check:
            write_check_session(build.session, folder, force=force, outputs=out)
        else:
            write_session(build.session, folder, force=force, outputs=out)
        write_json(out.path(folder / "build_report.json", make_parents=True), build.report.as_json(), indent=1)
        write_csv(out.path(folder / "build_report.csv", make_parents=True), [e.as_dict() for e in build.report.entries])
    return folder

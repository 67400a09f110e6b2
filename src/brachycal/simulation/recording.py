"""The twin records too: what a lab's session leaves behind, with a known truth.

Design: ``docs/design/twin.md``, "The twin's recordings".
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from brachycal.data.formats.bags import DEFAULT_TOPIC, JOINT_STATE
from brachycal.data.formats.metaimage import write_image_sequence
from brachycal.data.joint_log import JointLog, joint_log_from_columns
from brachycal.data.recording import AXES_POINTS, MARK_TYPE, REFERENCES, STILL_WINDOW_S, TOUCH_TOOLS, Frame, Mark
from brachycal.data.session import Session, write_session
from brachycal.errors import InputError
from brachycal.io import OutputSet, atomic_open, output_set
from brachycal.model.robot import Robot
from brachycal.planning import Plan, plan_poses
from brachycal.planning.output import write_plan
from brachycal.se3 import FloatArray
from brachycal.simulation.bmode import BModeSettings, needle_views, render_samples, true_tip_px
from brachycal.simulation.twin import Twin, TwinConfig, simulate
from brachycal.validate import check_int, check_range

__all__ = [
    "FRAME_FILES",
    "MARKS_TOPIC",
    "RECORDING_FILES",
    "Recording",
    "RecordingConfig",
    "Stop",
    "frame_samples",
    "record",
    "record_stops",
    "write_recording",
    "write_recording_frames",
]

#: Files :func:`write_recording` writes (the bag, if asked for, is a folder beside them).
RECORDING_FILES = ("joint_log.csv", "marks.csv", "images.csv", "plan.csv", "session.toml")
#: Topic of the marks in the twin's bag.
MARKS_TOPIC = "/brachycal/marks"
#: Seeds the recording's own random streams (moments of marks, encoder noise), apart from the twin's.
_TIMING, _ENCODER = 1, 2
#: Peak speed of a minimum-jerk move over its mean speed.
_MIN_JERK_PEAK = 1.875


@dataclass(frozen=True)
class RecordingConfig:
    """How the twin's session is recorded.

    Attributes:
        rate_hz: joint states per second, in [10, 1000] (MotoROS publishes at some tens of Hz;
            a lab may log faster).
        speed_scale: fraction of the vendor's velocity limits the moves use, in (0, 1].
        min_move_s: shortest move, seconds (no move is a jump), in [0.1, 60].
        hold_s: time held at each stop, seconds; at least a still window plus twice ``margin_s``.
        margin_s: least time between a hold's ends and its still windows, seconds, in [0, 10].
        start_time_s: clock time of the first reading, seconds (ROS time: since 1970).
        unannotated_frames: extra frames captured at sample stops and left without annotation.
        image_lag_s: the joint log's clock lag behind the ultrasound's (``brachycal temporal``'s
            sign), seconds, in [-10, 10]: a frame captured at log time ``t`` is stamped
            ``t - image_lag_s`` (plus the drift), so ``session build --lag-s image_lag_s`` undoes it.
        image_clock_drift_ppm: the ultrasound clock's rate error, parts per million, in
            [-1000, 1000]: its stamps gain ``drift × 1e-6 × (t − start_time_s)`` over the recording.
    """

    rate_hz: float = 100.0
    speed_scale: float = 0.1
    min_move_s: float = 1.0
    hold_s: float = 3.0
    margin_s: float = 0.25
    start_time_s: float = 1.7e9
    unannotated_frames: int = 2
    image_lag_s: float = 0.0
    image_clock_drift_ppm: float = 0.0

    def __post_init__(self) -> None:
        check_range(self.rate_hz, "recording rate", low=10.0, high=1000.0, unit="Hz")
        check_range(self.speed_scale, "recording speed scale", low=0.0, high=1.0, low_open=True)
        check_range(self.min_move_s, "recording min_move_s", low=0.1, high=60.0, unit="s")
        check_range(self.margin_s, "recording margin_s", low=0.0, high=10.0, unit="s")
        check_range(self.hold_s, "recording hold_s", low=STILL_WINDOW_S + 2 * self.margin_s, high=600.0, unit="s")
        check_range(self.start_time_s, "recording start_time_s", low=0.0, high=4e9, unit="s")
        check_int(self.unannotated_frames, "recording unannotated_frames", low=0, high=1000)
        check_range(self.image_lag_s, "recording image_lag_s", low=-10.0, high=10.0, unit="s")
        check_range(self.image_clock_drift_ppm, "recording image_clock_drift_ppm", low=-1000.0, high=1000.0, unit="ppm")

    def image_time(self, log_time_s: float) -> float:
        """The ultrasound clock's stamp of the moment ``log_time_s`` on the joint log's clock, seconds."""
        elapsed = log_time_s - self.start_time_s
        return log_time_s - self.image_lag_s + self.image_clock_drift_ppm * 1e-6 * elapsed


@dataclass(frozen=True, eq=False)  # holds arrays: compare fields, not objects
class Recording:
    """A recorded session of the twin.

    Attributes:
        time: ``(N,)`` seconds, at ``rate_hz``.
        q: ``(N, nq)`` joint readings, radians (true joints plus encoder noise).
        q_true: ``(N, nq)`` the true joints.
        joint_names: names of the columns of ``q``.
        marks: the operator's marks, in time order.
        frames: the captured frames, in time order (annotated, or not), stamped on the ultrasound's
            clock (:meth:`RecordingConfig.image_time`; the log's clock when lag and drift are 0).
        plan: the plan whose poses the samples are.
        twin: the twin (encoder noise off): its ``session`` is the direct session, with the true
            joints of every stop.
        config: the twin's settings (as given: the encoder noise is the recording's).
        recording: the recording settings.
    """

    time: FloatArray
    q: FloatArray
    q_true: FloatArray
    joint_names: tuple[str, ...]
    marks: list[Mark]
    frames: list[Frame]
    plan: Plan
    twin: Twin
    config: TwinConfig
    recording: RecordingConfig

    @property
    def session(self) -> Session:
        """The direct session: the stops' true joints, the twin's annotations."""
        return self.twin.session

    def joint_log(self) -> JointLog:
        """The readings as a :class:`~brachycal.data.JointLog` (validated as a file's would be)."""
        return joint_log_from_columns(self.twin.nominal, self.joint_names, self.time, self.q, source="<twin>")


def _min_jerk(s: FloatArray) -> FloatArray:
    return s**3 * (10.0 + s * (-15.0 + 6.0 * s))


@dataclass(frozen=True, eq=False)  # holds arrays: compare fields, not objects
class Stop:
    """One place a recording holds the robot still, and what is taken there.

    Attributes:
        q: ``(nq,)`` the true joints held, radians.
        kind: ``touch`` or ``axes`` (the operator marks it: ``tool``, ``name``) or ``frame`` (an
            ultrasound frame is captured, its needle tip annotated at ``uv_px``).
    """

    q: FloatArray
    kind: str
    tool: str = ""
    name: str = ""
    uv_px: FloatArray | None = None


def record(nominal: Robot, config: TwinConfig | None = None, recording: RecordingConfig | None = None) -> Recording:
    """Simulate a session (:func:`~brachycal.simulation.simulate`) and record it.

    Args:
        nominal: the URDF model (the twin's physical robot differs from it, as usual).
        config: the twin's settings (default ``TwinConfig()``); its encoder noise is applied to
            every reading of the log.
        recording: how it is recorded (default ``RecordingConfig()``).

    Raises:
        SolverError: a pose of the set-up is unreachable for the physical robot (as ``simulate``).
    """
    config = TwinConfig() if config is None else config
    twin = simulate(nominal, replace(config, encoder_noise=False))
    plan = plan_poses(nominal, twin.config.spec)  # the spec the twin used (the robot's workspace by default)
    session = twin.session
    # The stops, in the order a lab works: touches (calibration tip, then validation tip), axes, samples.
    stops: list[Stop] = []
    for reference in REFERENCES:
        for tool in TOUCH_TOOLS:
            for q in session.touches[tool, reference].q:
                stops.append(Stop(q, "touch", tool, reference))
    for tool, points in session.axes.items():
        for point in AXES_POINTS:
            stops.append(Stop(points[point], "axes", tool, point))
    for k in range(len(session.sample_ids)):
        stops.append(Stop(session.samples_q[k], "frame", uv_px=session.uv_px[k]))
    return record_stops(nominal, stops, twin, plan, config, recording)


def record_stops(
    nominal: Robot,
    stops: Sequence[Stop],
    twin: Twin,
    plan: Plan,
    config: TwinConfig,
    recording: RecordingConfig | None = None,
    *,
    stream: Sequence[int] = (),
) -> Recording:
    """Record the robot moving from its ready stance through ``stops`` (minimum-jerk moves, each
    stop held ``hold_s``), a mark or a frame taken at a random moment of each hold, the joints read
    at ``rate_hz`` with ``config``'s encoder noise.

    Args:
        nominal: the model whose joints are logged.
        stops: where the robot holds still, in order.
        twin: the twin recorded (its truth and set-up); ``plan`` the poses the frames were planned at.
        config: the twin's settings (seed, encoder noise).
        recording: how it is recorded (default ``RecordingConfig()``).
        stream: more seeds of the recording's random streams after ``config.seed`` (another
            recording of the same twin draws other moments and other encoder noise).
    """
    recording = RecordingConfig() if recording is None else recording
    timing = np.random.default_rng([config.seed, *stream, _TIMING])
    scale = recording.speed_scale * nominal.velocity_limit
    lo = STILL_WINDOW_S / 2 + recording.margin_s
    hi = recording.hold_s - lo

    # Segments: (start, duration, q_from, q_to); a hold has q_from == q_to.
    segments: list[tuple[float, float, FloatArray, FloatArray]] = []
    t = 0.0
    q_prev = nominal.rig.ready
    segments.append((t, recording.hold_s, q_prev, q_prev))
    t += recording.hold_s
    marks: list[Mark] = []
    frames: list[Frame] = []
    n_frames = sum(stop.kind == "frame" for stop in stops)
    extra = set(timing.choice(n_frames, size=min(recording.unannotated_frames, n_frames), replace=False))
    k = 0
    for stop in stops:
        q = stop.q
        move_s = max(recording.min_move_s, _MIN_JERK_PEAK * float(np.max(np.abs(q - q_prev) / scale)))
        segments.append((t, move_s, q_prev, q))
        t += move_s
        segments.append((t, recording.hold_s, q, q))
        moment = recording.start_time_s + t + timing.uniform(lo, hi)
        if stop.kind == "frame":
            assert stop.uv_px is not None
            frames.append(Frame(moment, np.array(stop.uv_px, dtype=float)))
            if k in extra:
                frames.append(Frame(recording.start_time_s + t + timing.uniform(lo, hi), None))
            k += 1
        else:
            marks.append(Mark(moment, stop.kind, stop.tool, stop.name))
        t += recording.hold_s
        q_prev = q
    segments.append((t, recording.hold_s, q_prev, q_prev))
    t += recording.hold_s

    n = int(np.floor(t * recording.rate_hz)) + 1
    clock = np.arange(n) / recording.rate_hz
    starts = np.array([s[0] for s in segments])
    which = np.clip(np.searchsorted(starts, clock, side="right") - 1, 0, len(segments) - 1)
    q_true = np.empty((n, nominal.nq))
    for index, (start, duration, q0, q1) in enumerate(segments):
        mask = which == index
        s = np.clip((clock[mask] - start) / duration, 0.0, 1.0)
        q_true[mask] = q0 + _min_jerk(s)[:, None] * (q1 - q0)
    noise = np.random.default_rng([config.seed, *stream, _ENCODER])
    q = q_true + noise.normal(scale=config.encoder_sd_rad, size=q_true.shape) if config.encoder_noise else q_true.copy()
    if recording.image_lag_s != 0.0 or recording.image_clock_drift_ppm != 0.0:
        frames = [replace(f, time_s=recording.image_time(f.time_s)) for f in frames]
    frames.sort(key=lambda f: f.time_s)
    return Recording(
        time=recording.start_time_s + clock,
        q=q,
        q_true=q_true,
        joint_names=tuple(nominal.joint_names),
        marks=sorted(marks, key=lambda m: m.time_s),
        frames=frames,
        plan=plan,
        twin=twin,
        config=config,
        recording=recording,
    )


def _write_log_csv(path: Path, rec: Recording) -> None:
    with atomic_open(path) as f:
        f.write("time," + ",".join(rec.joint_names) + "\n")
        rows = np.column_stack([rec.time, rec.q])
        # Times to the microsecond, joints to 1e-10 rad (encoder noise is 2e-5 rad).
        np.savetxt(f, rows, fmt=["%.6f"] + ["%.10f"] * len(rec.joint_names), delimiter=",")


def _write_marks_csv(path: Path, rec: Recording) -> None:
    with atomic_open(path) as f:
        f.write("time,kind,tool,name\n")
        for m in rec.marks:
            f.write(f"{m.time_s:.6f},{m.kind},{m.tool},{m.name}\n")


def _write_images_csv(path: Path, rec: Recording) -> None:
    with atomic_open(path) as f:
        f.write("time,u_px,v_px\n")
        for frame in rec.frames:
            uv = ",".join(f"{x!r}" for x in map(float, frame.uv_px)) if frame.uv_px is not None else ","
            f.write(f"{frame.time_s:.6f},{uv}\n")


def _write_bag(folder: Path, rec: Recording, storage: str) -> None:
    """A ROS 2 bag at ``folder`` (must not exist): joint states and marks, in time order."""
    from rosbags.rosbag2 import StoragePlugin, Writer  # lazy: start-up (rosbags)
    from rosbags.typesys import Stores, get_typestore  # lazy: start-up (rosbags)

    typestore = get_typestore(Stores.ROS2_HUMBLE)
    JointState = typestore.types[JOINT_STATE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    String = typestore.types[MARK_TYPE]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    names = list(rec.joint_names)
    empty = np.zeros(0)
    marks = [(round(m.time_s * 1e9), f"{m.kind},{m.tool},{m.name}") for m in rec.marks]
    with Writer(folder, version=9, storage_plugin=plugin) as writer:
        joints = writer.add_connection(DEFAULT_TOPIC, JOINT_STATE, typestore=typestore)
        mark_topic = writer.add_connection(MARKS_TOPIC, MARK_TYPE, typestore=typestore)
        k = 0
        for t, q in zip(rec.time, rec.q, strict=True):
            ns = round(t * 1e9)
            while k < len(marks) and marks[k][0] <= ns:
                writer.write(mark_topic, marks[k][0], typestore.serialize_cdr(String(data=marks[k][1]), MARK_TYPE))
                k += 1
            msg = JointState(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                name=names,
                position=q,
                velocity=empty,
                effort=empty,
            )
            writer.write(joints, ns, typestore.serialize_cdr(msg, JOINT_STATE))
        for ns, text in marks[k:]:
            writer.write(mark_topic, ns, typestore.serialize_cdr(String(data=text), MARK_TYPE))


def write_recording(
    rec: Recording,
    folder: str | os.PathLike[str],
    *,
    bag: str | None = None,
    images: BModeSettings | None = None,
    force: bool = False,
    outputs: OutputSet | None = None,
) -> Path:
    """Write the recording as a lab would have it: :data:`RECORDING_FILES` in ``folder``.

    Args:
        rec: the recording.
        folder: created if needed.
        bag: also write the joint states (``/joint_states``) and the marks (:data:`MARKS_TOPIC`) as
            a ROS 2 bag folder ``folder/bag``: ``"sqlite3"`` or ``"mcap"``; ``None`` for none.
        images: also render the frames as B-mode images with these settings: ``frames.mha`` and
            ``frames_truth.csv`` (:func:`write_recording_frames`).
        force: replace existing files.
        outputs: a command's :class:`~brachycal.io.OutputSet` to join (all or nothing with it).

    Raises:
        InputError: an unknown bag storage.
        OutputError: a file exists (without ``force``) or cannot be written.
    """
    if bag not in (None, "sqlite3", "mcap"):
        raise InputError(f"bag storage must be sqlite3 or mcap, got {bag!r}")
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        _write_log_csv(out.path(folder / "joint_log.csv", make_parents=True), rec)
        _write_marks_csv(out.path(folder / "marks.csv", make_parents=True), rec)
        _write_images_csv(out.path(folder / "images.csv", make_parents=True), rec)
        write_plan(rec.plan, rec.twin.nominal, out.path(folder / "plan.csv", make_parents=True))
        if images is not None:
            write_recording_frames(rec, folder, images, out)
        # The session.toml of the set-up (what the lab knows before recording), as a template.
        with tempfile.TemporaryDirectory(prefix="brachycal-recording-") as tmp:
            write_session(rec.session, tmp)
            shutil.copyfile(Path(tmp) / "session.toml", out.path(folder / "session.toml", make_parents=True))
            if bag is not None:
                _write_bag(Path(tmp) / "bag", rec, bag)
                for item in sorted((Path(tmp) / "bag").iterdir()):
                    shutil.copyfile(item, out.path(folder / "bag" / item.name, make_parents=True))
    return folder


#: The files :func:`write_recording_frames` adds to a recording.
FRAME_FILES = ("frames.mha", "frames_truth.csv")


def frame_samples(rec: Recording) -> np.ndarray:
    """``(M,)`` the sample each of the recording's frames shows: the sample whose stop the robot
    holds at the frame's time on the joint log's clock (a hold repeats its stop's joints exactly).

    Frames stamped on the ultrasound's clock (a lag and a drift: ``RecordingConfig.image_time``, an
    affine map of the log's clock) are taken back to the log's clock first.
    """
    samples_q = rec.session.samples_q
    to_image = getattr(rec.recording, "image_time", None)
    scale, offset = 1.0, 0.0
    if to_image is not None:  # affine: image = scale * log + offset
        t0 = float(rec.time[0])
        offset_at_t0 = float(to_image(t0))
        scale = float(to_image(t0 + 1.0)) - offset_at_t0
        offset = offset_at_t0 - scale * t0
    out = np.empty(len(rec.frames), dtype=int)
    for m, frame in enumerate(rec.frames):
        log_time = (frame.time_s - offset) / scale
        i = int(np.clip(np.searchsorted(rec.time, log_time), 0, len(rec.time) - 1))
        out[m] = int(np.argmin(np.abs(samples_q - rec.q_true[i]).max(axis=1)))
    return out


def write_recording_frames(
    rec: Recording, folder: str | os.PathLike[str], settings: BModeSettings, outputs: OutputSet
) -> None:
    """Add the recording's frames to ``folder`` as part of ``outputs``: :data:`FRAME_FILES`.

    ``frames.mha``: one rendered frame per row of ``images.csv`` (same order, ``Timestamp`` = its
    time), the header's spacing in mm. ``frames_truth.csv`` (``time,sample,u_px,v_px,elevation_mm``):
    per frame the sample it shows and where the tip truly is (pixels; mm off the image plane).
    """
    folder = Path(folder)
    samples = frame_samples(rec)
    pixels = render_samples(rec.twin, settings, samples)
    times = np.array([f.time_s for f in rec.frames])
    truth_px = true_tip_px(rec.twin)
    elevation_mm = np.array([v.tip_I_m[2] * 1e3 for v in needle_views(rec.twin)])
    spacing_mm = tuple(float(x) * 1e3 for x in rec.session.spacing_m)
    write_image_sequence(
        outputs.path(folder / "frames.mha", make_parents=True),
        pixels,
        timestamps_s=times,
        spacing=(spacing_mm[0], spacing_mm[1]),
    )
    with outputs.path(folder / "frames_truth.csv", make_parents=True).open("w") as f:
        f.write("time,sample,u_px,v_px,elevation_mm\n")
        for t, k in zip(times, samples, strict=True):
            u, v = (float(x) for x in truth_px[k])
            f.write(f"{t:.6f},{rec.session.sample_ids[k]},{u!r},{v!r},{float(elevation_mm[k])!r}\n")

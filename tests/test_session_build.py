"""Session build: the twin's recording → a session → a calibration that agrees with the twin's own.

The twin records its session as a lab would (:func:`brachycal.simulation.record`): a 100 Hz joint
log with minimum-jerk moves between the stops and encoder noise on every reading, the marks and
the frames. Its direct session holds the true joints of every stop, so a built session must
match it within the encoder noise averaged over the still window, and its calibration must match
the direct session's calibration to what that noise moves a tool tip.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from brachycal import InputError
from brachycal.calibration import calibrate
from brachycal.data import (
    Frame,
    ImageSettings,
    Mark,
    PlannedSamples,
    build_session,
    build_session_from_files,
    read_plan,
    read_session,
    session_settings,
    write_build,
    write_session,
)
from brachycal.data.recording import MAX_SPEED_RAD_S
from brachycal.simulation import RecordingConfig, TwinConfig, record, write_recording
from brachycal.simulation.recording import MARKS_TOPIC

SIGMA = TwinConfig().encoder_sd_rad  # 2e-5 rad per reading


@pytest.fixture(scope="module")
def rec(robot):
    return record(robot, TwinConfig(seed=0))


@pytest.fixture(scope="module")
def folder(rec, tmp_path_factory):
    return write_recording(rec, tmp_path_factory.mktemp("recording") / "rec")


@pytest.fixture(scope="module")
def built(folder, robot):
    return build_session_from_files(
        folder / "joint_log.csv",
        robot=robot,
        images=folder / "images.csv",
        marks=folder / "marks.csv",
        plan=folder / "plan.csv",
        settings=session_settings(folder / "session.toml"),
    )


def entries_q(session):
    """``(M, nq)`` every configuration of a session, in one order: touches, axes, samples."""
    touches = [session.touches[key].q for key in sorted(session.touches)]
    axes = [session.axes[tool][point] for tool in sorted(session.axes) for point in sorted(session.axes[tool])]
    return np.vstack([*touches, np.array(axes), session.samples_q])


def test_the_built_session_is_the_twins_session(rec, built):
    direct, session = rec.session, built.session
    assert session.sample_ids == direct.sample_ids  # frames paired with the plan's points, in order
    np.testing.assert_array_equal(session.uv_px, direct.uv_px)
    np.testing.assert_array_equal(session.spacing_m, direct.spacing_m)  # from the template session.toml
    np.testing.assert_array_equal(session.p_ER_Mtip, direct.p_ER_Mtip)
    assert direct.sector is not None and session.sector is not None  # the template states the twin's sector
    assert session.sector.apex_px == direct.sector.apex_px
    assert session.sector.depth_m == pytest.approx(direct.sector.depth_m, rel=1e-12)
    assert session.sector.angle_rad == pytest.approx(direct.sector.angle_rad, rel=1e-12)
    assert set(session.touches) == set(direct.touches)
    for key, touches in direct.touches.items():
        np.testing.assert_array_equal(session.touches[key].trials, touches.trials)


def test_joints_are_the_stops_within_the_averaged_encoder_noise(rec, built):
    """Each entry is the mean over ~100 readings of white noise of SD σ: off by ~σ/√n per joint.
    5σ/√n bounds all 88 × 15 values with odds of ~1e-3 against; one unaveraged reading (SD σ, ten
    times more) would break it at once."""
    n = min(e.readings for e in built.report.entries if e.used)
    assert n >= 100
    error = np.abs(entries_q(built.session) - entries_q(rec.session))
    assert error.max() < 5 * SIGMA / np.sqrt(n)
    assert error.max() > 0.5 * SIGMA / np.sqrt(n)  # and the noise is there: the recording is not the truth


def test_calibration_agrees_with_the_direct_session(rec, built, robot):
    """Tolerance 10 µm, from the averaged noise: σ/√n = 2e-6 rad per joint; a tool tip hangs at most
    1.5 m from any of the ≤ 8 joints that carry it (torso and one arm), so one averaged reading
    moves it by at most √8 · 1.5 m · 2e-6 rad ≈ 8.5 µm (1 SD, every lever at its longest), and the
    estimates average several readings. A build without averaging (one reading, σ = 2e-5 rad) gives
    differences of ~15 µm on the same data; the measured ones are ~1.5 µm."""
    a = calibrate(rec.session, robot)
    b = calibrate(built.session, robot)
    tolerance = 10e-6
    assert np.linalg.norm(a.T_ER_Ntip[:3, 3] - b.T_ER_Ntip[:3, 3]) < tolerance
    assert np.linalg.norm(a.T_EL_Ptip[:3, 3] - b.T_EL_Ptip[:3, 3]) < tolerance
    centre = np.array([540 * rec.session.spacing_m[0], 360 * rec.session.spacing_m[1], 0.0, 1.0])
    for method in ("kabsch", "scaled_uv"):
        image_a = a.T_EL_Ptip @ a.image[method].T_Ptip_I @ centre
        image_b = b.T_EL_Ptip @ b.image[method].T_Ptip_I @ centre
        assert np.linalg.norm(image_a - image_b) < tolerance, method


def test_without_encoder_noise_the_build_is_exact(robot):
    """No noise: every still window is constant, so the build returns the stops' joints exactly
    (1e-12 rad: rounding of a mean of ~100 equal numbers)."""
    quiet = record(robot, TwinConfig(seed=1, encoder_noise=False), RecordingConfig(rate_hz=25.0, hold_s=1.6))
    s = quiet.session
    build = build_session(
        quiet.joint_log(),
        quiet.marks,
        quiet.frames,
        robot=robot,
        settings=ImageSettings(s.spacing_m, s.size_px, s.p_ER_Mtip),
    )
    np.testing.assert_allclose(entries_q(build.session), entries_q(s), rtol=0, atol=1e-12)


def test_written_folder_reads_back_as_built(built, robot, tmp_path):
    write_build(built, tmp_path / "session")
    back = read_session(tmp_path / "session", robot)
    np.testing.assert_array_equal(entries_q(back), entries_q(built.session))  # repr(float): exact
    report = json.loads((tmp_path / "session" / "build_report.json").read_text())
    assert report["format"] == "brachycal-session-build/1"
    assert report["counts"] == {
        "touches": 18,
        "axes": 6,
        "frames_used": 64,
        "frames_skipped": 2,
        "planned": 64,
        "planned_missing": 0,
    }
    assert set(report["inputs"]) == {"log", "images", "marks", "plan"}
    skipped = [e for e in report["entries"] if e["status"] == "skipped"]
    assert [e["reason"] for e in skipped] == ["not annotated"] * 2
    assert all(e["planned"] for e in skipped)  # the poses they were taken at
    csv_rows = (tmp_path / "session" / "build_report.csv").read_text().splitlines()
    assert len(csv_rows) == 1 + 18 + 6 + 66


def test_report_states_each_window(built):
    used = [e for e in built.report.entries if e.used]
    assert all(e.window_s == pytest.approx(1.0) for e in used)
    spread = np.array([e.spread_rad for e in used])
    np.testing.assert_allclose(np.median(spread), SIGMA, rtol=0.3)  # the largest of 15 SDs of σ-noise
    assert max(e.speed_rad_s for e in used) < MAX_SPEED_RAD_S
    text = built.report.summary()
    assert "marks: 24 used (18 touches, 6 axes points)" in text
    assert "frames: 64 used as samples, 2 skipped" in text and "missing: none" in text


def test_planned_samples_missing_are_reported(rec, robot, built, folder):
    plan = read_plan(folder / "plan.csv", robot)
    s = rec.session
    frames = [f for f in rec.frames if f.uv_px is not None][3:]  # the first three planned poses were not imaged
    build = build_session(
        rec.joint_log(),
        rec.marks,
        frames,
        robot=robot,
        settings=ImageSettings(s.spacing_m, s.size_px, s.p_ER_Mtip),
        plan=plan,
    )
    assert build.report.planned_missing == tuple(s.sample_ids[:3])
    assert build.session.sample_ids == s.sample_ids[3:]


# --- refusals ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def parts(rec):
    s = rec.session
    return rec.joint_log(), ImageSettings(s.spacing_m, s.size_px, s.p_ER_Mtip)


def moving_time(rec) -> float:
    """A moment in the middle of the fastest move."""
    speed = np.abs(np.diff(rec.q_true, axis=0)).max(axis=1)
    return float(rec.time[int(np.argmax(speed))])


def test_a_mark_while_moving_is_refused(rec, robot, parts):
    log, settings = parts
    marks = list(rec.marks)
    marks[4] = replace(marks[4], time_s=moving_time(rec), source="marks.csv", row=6)
    with pytest.raises(InputError, match=r"marks\.csv, row 6: touch mark needle rtip1: the robot was moving at "):
        build_session(log, marks, rec.frames, robot=robot, settings=settings)


def test_a_mark_outside_the_log_is_refused(rec, robot, parts):
    log, settings = parts
    marks = [*rec.marks, Mark(float(rec.time[-1]) + 10, "touch", "probe", "rtip2", "marks.csv", 99)]
    with pytest.raises(InputError, match=r"row 99: touch mark probe rtip2: time .* is outside the log's span"):
        build_session(log, marks, rec.frames, robot=robot, settings=settings)


@pytest.mark.parametrize(
    ("drop", "message"),
    [
        (lambda m: m.kind == "touch" and m.tool == "probe" and m.name == "rtip2", "no touch mark of probe on rtip2"),
        (lambda m: m.kind == "axes" and m.tool == "needle" and m.name == "p3", "no axes mark of needle at p3"),
    ],
)
def test_an_incomplete_session_is_refused(rec, robot, parts, drop, message):
    log, settings = parts
    marks = [replace(m, source="marks.csv") for m in rec.marks if not drop(m)]
    with pytest.raises(InputError, match=rf"marks\.csv: {message}"):
        build_session(log, marks, rec.frames, robot=robot, settings=settings)


def test_unequal_trials_and_a_repeated_axes_point_are_refused(rec, robot, parts):
    log, settings = parts
    needle_rtip1 = [m for m in rec.marks if (m.kind, m.tool, m.name) == ("touch", "needle", "rtip1")]
    marks = [m for m in rec.marks if m is not needle_rtip1[-1]]
    with pytest.raises(InputError, match=r"unequal touches on rtip1 \(top_model 3, needle 2, probe 3\)"):
        build_session(log, marks, rec.frames, robot=robot, settings=settings)
    p1 = next(m for m in rec.marks if (m.kind, m.tool, m.name) == ("axes", "probe", "p1"))
    p2 = next(m for m in rec.marks if (m.kind, m.tool, m.name) == ("axes", "probe", "p2"))
    marks = [*rec.marks, replace(p2, name="p1", row=30)]
    assert p1.time_s < p2.time_s
    with pytest.raises(InputError, match=r"row 30: probe p1 is marked twice \(also row 0\)"):
        build_session(log, marks, rec.frames, robot=robot, settings=settings)


def test_frames_while_moving_or_outside_the_image_are_refused_unannotated_ones_skipped(rec, robot, parts):
    log, settings = parts
    frames = list(rec.frames)
    frames[5] = replace(frames[5], time_s=moving_time(rec), source="images.csv", row=7)
    with pytest.raises(InputError, match=r"images\.csv, row 7: frame 6: the robot was moving at "):
        build_session(log, rec.marks, frames, robot=robot, settings=settings)
    frames[5] = replace(rec.frames[5], uv_px=np.array([1080.0, 10.0]), source="images.csv", row=7)
    with pytest.raises(InputError, match=r"row 7: annotated needle tip u = 1080 px is outside the 1080 x 720 px image"):
        build_session(log, rec.marks, frames, robot=robot, settings=settings)
    # The same frame while moving but not annotated: skipped, never refused.
    frames[5] = replace(rec.frames[5], time_s=moving_time(rec), uv_px=None)
    build = build_session(log, rec.marks, frames, robot=robot, settings=settings)
    skipped = build.report.frames_skipped
    assert len(skipped) == 3 and all(e.reason == "not annotated" for e in skipped)


def test_too_few_frames_are_refused(rec, robot, parts):
    log, settings = parts
    frames = [replace(f, source="images.csv") for f in rec.frames if f.uv_px is not None][:2]
    with pytest.raises(InputError, match=r"images\.csv: 2 annotated frame\(s\) usable: at least 3"):
        build_session(log, rec.marks, frames, robot=robot, settings=settings)


def test_a_frame_between_two_planned_poses_is_refused(rec, robot, parts):
    log, settings = parts
    plan = read_plan_from(rec)
    q = plan.q.copy()
    q[1] = q[0] + 1e-3  # two planned poses closer together than the frame's noise can tell apart
    ambiguous = PlannedSamples(plan.names, q, plan.uv_px, "plan.csv")
    frames = [replace(f, source="images.csv", row=k + 2) for k, f in enumerate(rec.frames)]
    with pytest.raises(InputError, match=r"images\.csv, row 2: frame 1 at .* is about as near planned .* sample name"):
        build_session(log, rec.marks, frames, robot=robot, settings=settings, plan=ambiguous)


def read_plan_from(rec) -> PlannedSamples:
    return PlannedSamples(
        [p.point.name for p in rec.plan.poses],
        np.array([p.q for p in rec.plan.poses]),
        np.array([p.point.uv_px for p in rec.plan.poses]),
        "plan",
    )


def test_marks_from_the_bag_or_from_csv_need_one_of_them(folder, robot):
    settings = session_settings(folder / "session.toml")
    with pytest.raises(InputError, match="either as a file"):
        build_session_from_files(folder / "joint_log.csv", robot=robot, images=folder / "images.csv", settings=settings)
    with pytest.raises(InputError, match="--marks-topic needs a ROS bag"):
        build_session_from_files(
            folder / "joint_log.csv", robot=robot, images=folder / "images.csv", marks_topic="/m", settings=settings
        )


# --- ROS 2 bags ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def short(robot):
    """A quick recording (25 Hz, fast moves, short holds): a small bag."""
    return record(robot, TwinConfig(seed=2), RecordingConfig(rate_hz=25.0, speed_scale=0.5, hold_s=1.6))


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_bag_round_trip(robot, short, tmp_path, storage):
    """The same recording as CSV files and as a ROS 2 bag (joint states and marks on a topic)
    builds the same session: the bag stores float64 exactly, the CSV log to 1e-10 rad."""
    folder = write_recording(short, tmp_path / "rec", bag=storage)
    settings = session_settings(folder / "session.toml")
    from_bag = build_session_from_files(
        folder / "bag", robot=robot, images=folder / "images.csv", marks_topic=MARKS_TOPIC, settings=settings
    )
    from_csv = build_session_from_files(
        folder / "joint_log.csv",
        robot=robot,
        images=folder / "images.csv",
        marks=folder / "marks.csv",
        settings=settings,
    )
    np.testing.assert_allclose(entries_q(from_bag.session), entries_q(from_csv.session), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        entries_q(from_bag.session), entries_q(short.session), rtol=0, atol=5 * SIGMA / np.sqrt(25)
    )
    assert [e.what for e in from_bag.report.marks] == [e.what for e in from_csv.report.marks]
    with pytest.raises(InputError, match=r"no topic '/marks' \(topics: /brachycal/marks, /joint_states\)"):
        build_session_from_files(
            folder / "bag", robot=robot, images=folder / "images.csv", marks_topic="/marks", settings=settings
        )
    shutil.rmtree(folder)


def test_frames_pair_with_their_marks_in_memory(rec):
    """The recording's own bookkeeping: one frame per planned pose plus the unannotated extras, and
    the marks in the lab's order (touches on rtip1, then rtip2, then the axes points)."""
    assert sum(f.uv_px is not None for f in rec.frames) == len(rec.plan.poses)
    assert sum(f.uv_px is None for f in rec.frames) == RecordingConfig().unannotated_frames
    kinds = [m.kind for m in rec.marks]
    assert kinds == ["touch"] * 18 + ["axes"] * 6
    assert all(isinstance(f, Frame) for f in rec.frames)


def test_two_commands_from_the_recording_to_a_result(short, tmp_path, capsys):
    """The tour's path (README and the procedure): ``brachycal session build`` then ``brachycal calibrate``."""
    from brachycal.cli.main import main

    rec = write_recording(short, tmp_path / "rec")
    build = [
        "session",
        "build",
        str(rec / "joint_log.csv"),
        "--marks",
        str(rec / "marks.csv"),
        "--images",
        str(rec / "images.csv"),
        "--plan",
        str(rec / "plan.csv"),
        "--template",
        str(rec / "session.toml"),
        "--out",
        str(tmp_path / "session"),
    ]
    assert main(build) == 0
    out = capsys.readouterr().out
    assert "frames: 64 used as samples, 2 skipped" in out and "next: brachycal calibrate" in out
    assert main(["calibrate", str(tmp_path / "session"), "--out", str(tmp_path / "result.json"), "--quiet"]) == 0
    result = json.loads((tmp_path / "result.json").read_text())
    assert set(result["inputs"]) >= {"touches.csv", "axes.csv", "samples.csv"}
    assert main([*build, "--force"]) == 0  # a second build replaces the session only when asked


def test_demo_recording_prints_a_build_command_that_works(tmp_path, capsys):
    """``brachycal demo --recording`` writes the twin's recording and the exact command that turns
    it into a session; that command, run as printed, builds a session that calibrates."""
    import shlex

    from brachycal.cli.main import main

    assert main(["demo", "--recording", "--out", str(tmp_path / "demo"), "--targets", "5"]) == 0
    out = capsys.readouterr().out
    command = next(line.strip() for line in out.splitlines() if line.strip().startswith("brachycal session build"))
    assert main(shlex.split(command)[1:]) == 0
    assert main(["calibrate", str(tmp_path / "demo" / "built_session"), "--out", str(tmp_path / "r.json")]) == 0


def test_two_images_of_one_planned_pose_are_both_samples_and_said_so(rec, robot, parts):
    """A pose imaged twice (two frames at different times, paired with one planned pose) gives two
    samples, ``g…`` and ``g…-2``, with a warning naming the second image: never silently."""
    log, settings = parts
    plan = read_plan_from(rec)
    frames = [replace(f, source="images.csv", row=k + 2) for k, f in enumerate(rec.frames)]
    used = [k for k, f in enumerate(frames) if f.uv_px is not None]
    first, second = used[0], used[1]
    frames[second] = replace(frames[second], sample=None)
    frames[first] = replace(frames[first], sample=None)
    baseline = build_session(log, rec.marks, frames, robot=robot, settings=settings, plan=plan)
    name = baseline.session.sample_ids[0]
    frames[second] = replace(frames[second], sample=name)  # the second image named as the first's pose
    said = rf"images\.csv, row {second + 2}: .* second image of {name}.* sample {name}-2"
    with pytest.warns(UserWarning, match=said):
        build = build_session(log, rec.marks, frames, robot=robot, settings=settings, plan=plan)
    assert build.session.sample_ids[:2] == [name, f"{name}-2"]


def test_a_sample_name_that_is_not_a_plain_token_is_never_written(rec, robot, parts, tmp_path):
    log, settings = parts
    build = build_session(log, rec.marks, rec.frames, robot=robot, settings=settings)
    session = replace(build.session, sample_ids=['a,"b', *build.session.sample_ids[1:]])
    with pytest.raises(InputError, match="not a plain token"):
        write_session(session, tmp_path / "s")
    assert not (tmp_path / "s").exists()


def test_a_filled_in_template_builds_the_recordings_session(short, robot, tmp_path, capsys):
    """``brachycal session template``: its session.toml is refused, naming the key, until its empty
    lists are filled in; its CSV headers take the rows of a recording as they are and build the
    same session as the recording's own files."""
    from brachycal.cli.main import main
    from brachycal.data.session_template import TEMPLATE_FILES

    rec = write_recording(short, tmp_path / "rec")
    blank = tmp_path / "blank"
    assert main(["session", "template", str(blank)]) == 0
    assert sorted(p.name for p in blank.iterdir()) == sorted(TEMPLATE_FILES)
    with pytest.raises(InputError, match=r"key 'image.spacing_mm': expected a list of 2 numbers"):
        session_settings(blank / "session.toml")
    # The documented edit: fill in the three lists (here with the recording's own values).
    known = session_settings(rec / "session.toml")
    toml = (blank / "session.toml").read_text()
    for key, values in (
        ("spacing_mm", known.spacing_m * 1e3),
        ("size_px", known.size_px),
        ("tip_in_flange_mm", known.p_ER_Mtip * 1e3),
    ):
        assert toml.count(f"\n{key} = []\n") == 1
        toml = toml.replace(f"\n{key} = []\n", f"\n{key} = [{', '.join(repr(float(v)) for v in values)}]\n")
    (blank / "session.toml").write_text(toml)
    for name in ("marks.csv", "images.csv"):  # the recording's rows under the template's header
        rows = (rec / name).read_text().splitlines(keepends=True)[1:]
        with (blank / name).open("a") as f:
            f.writelines(rows)
    settings = session_settings(blank / "session.toml")
    np.testing.assert_array_equal(settings.size_px, known.size_px)
    assert settings.sector is None  # the template's sector is an example, commented out
    built = build_session_from_files(
        rec / "joint_log.csv", robot=robot, images=blank / "images.csv", marks=blank / "marks.csv", settings=settings
    )
    direct = build_session_from_files(
        rec / "joint_log.csv", robot=robot, images=rec / "images.csv", marks=rec / "marks.csv", settings=known
    )
    np.testing.assert_array_equal(entries_q(built.session), entries_q(direct.session))
    np.testing.assert_allclose(built.session.spacing_m, known.spacing_m, rtol=1e-12, atol=0)
    np.testing.assert_allclose(built.session.p_ER_Mtip, known.p_ER_Mtip, rtol=1e-12, atol=0)
    capsys.readouterr()
    assert main(["session", "template", str(blank)]) == 2  # a filled-in template is never overwritten silently
    assert "already exists; pass --force" in capsys.readouterr().err
    assert (blank / "session.toml").read_text() == toml


def test_the_templates_sector_example_uncommented_is_the_sessions_sector(tmp_path):
    """The template documents the optional ``[image.sector]`` as commented lines; uncommented,
    they are the built session's sector (for the report's landing error map)."""
    from brachycal.data.session_template import write_session_template

    write_session_template(tmp_path / "blank")
    template = tmp_path / "blank" / "session.toml"
    lines = template.read_text().splitlines()
    start = lines.index("# [image.sector]")
    lines[start : start + 4] = [line.removeprefix("# ") for line in lines[start : start + 4]]
    template.write_text("\n".join(lines) + "\n")
    given = {"spacing_mm": [0.19, 0.19], "size_px": [1080, 720], "top_model_tip_mm": [0.0, 0.0, 150.0]}
    sector = session_settings(template, **given).sector
    assert sector is not None and sector.apex_px == (540.0, 0.0)
    assert sector.depth_m == pytest.approx(0.070, rel=1e-12)
    assert sector.angle_rad == pytest.approx(np.radians(120.0), rel=1e-12)


def test_an_unfilled_template_takes_the_values_given_as_options(tmp_path):
    """A blank of ``brachycal session template`` is allowed where the caller gives its value
    (``session build --spacing-mm/--size-px/--top-model-tip-mm``); a blank left ungiven is refused
    naming its key."""
    from brachycal.data.session_template import write_session_template

    write_session_template(tmp_path / "blank")
    template = tmp_path / "blank" / "session.toml"
    given = {"spacing_mm": [0.19, 0.2], "size_px": [1080, 720], "top_model_tip_mm": [0.0, 0.0, 150.0]}
    settings = session_settings(template, **given)
    np.testing.assert_allclose(settings.spacing_m, [0.19e-3, 0.2e-3], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(settings.size_px, [1080, 720])
    np.testing.assert_allclose(settings.p_ER_Mtip, [0.0, 0.0, 0.15], rtol=1e-12, atol=0)
    for left_out, key in (
        ("spacing_mm", "image.spacing_mm"),
        ("size_px", "image.size_px"),
        ("top_model_tip_mm", "top_model.tip_in_flange_mm"),
    ):
        partial = {k: v for k, v in given.items() if k != left_out}
        with pytest.raises(InputError, match=rf"key '{key}': expected a list of"):
            session_settings(template, **partial)


@pytest.fixture(scope="module")
def check_rec(rec, robot):
    """The twin's check before a procedure (nothing changed), recorded as a lab records it."""
    from brachycal.studies.check_twin import CHANGES, check_recording

    return check_recording(rec, robot, CHANGES["unchanged"], 1)


def build_check(folder, robot, touches, *, marks=True):
    """``session build --check`` of the recording in ``folder`` (its marks unless not ``marks``)."""
    return build_session_from_files(
        folder / "joint_log.csv",
        robot=robot,
        images=folder / "images.csv",
        marks=folder / "marks.csv" if marks else None,
        plan=folder / "plan.csv",
        settings=session_settings(folder / "session.toml"),
        check=touches,
    )


def test_a_check_recording_builds_the_check_the_twin_recorded(check_rec, robot, tmp_path):
    """``session build --check``: the check recording (the probe's touch of rtip1, a frame at each pose
    of ``plan check``) gives the check session of its stops' true joints, within the encoder noise
    averaged over the still window, each frame named by its planned pose; ``verify`` reads it back."""
    from brachycal.calibration.verify.check import read_check_session
    from brachycal.data.session import CHECK_FILES
    from brachycal.data.session_build import REPORT_FILES

    build = build_check(write_recording(check_rec, tmp_path / "rec"), robot, ("probe",))
    assert build.check and not build.session.axes
    assert build.session.sample_ids == [p.point.name for p in check_rec.plan.poses]

    def true_q(t: float) -> np.ndarray:
        return check_rec.q_true[int(np.argmin(np.abs(check_rec.time - t)))]  # a hold repeats its stop's joints

    averaged = SIGMA / np.sqrt(check_rec.recording.rate_hz * build.report.still.window_s)
    for q, frame in zip(build.session.samples_q, check_rec.frames, strict=True):
        np.testing.assert_allclose(q, true_q(frame.time_s), rtol=0, atol=6 * averaged)
    assert list(build.session.touches) == [("probe", "rtip1")]
    (mark,) = check_rec.marks
    np.testing.assert_allclose(
        build.session.touches["probe", "rtip1"].q[0], true_q(mark.time_s), rtol=0, atol=6 * averaged
    )

    write_build(build, tmp_path / "check")
    assert sorted(p.name for p in (tmp_path / "check").iterdir()) == sorted((*CHECK_FILES, *REPORT_FILES))
    assert json.loads((tmp_path / "check" / "build_report.json").read_text())["kind"] == "check"
    read = read_check_session(tmp_path / "check", robot)
    assert read.sample_ids == build.session.sample_ids
    np.testing.assert_array_equal(read.samples_q, build.session.samples_q)
    assert [(tool, reference, trial) for tool, reference, trial, _ in read.touches] == [("probe", "rtip1", 1)]


def test_a_check_template_explains_a_check_recording(tmp_path, capsys):
    """``session template --check``: the same blanks, a README of what a check records, and the next command."""
    from brachycal.cli.main import main
    from brachycal.data.session_template import TEMPLATE_FILES

    assert main(["session", "template", "--check", str(tmp_path / "blank")]) == 0
    assert sorted(p.name for p in (tmp_path / "blank").iterdir()) == sorted(TEMPLATE_FILES)
    readme = (tmp_path / "blank" / "README.txt").read_text()
    assert "session build JOINT_LOG --check" in readme and "brachycal verify RESULT CHECK_SESSION" in readme
    assert "no top-model touches and no axes moves" in readme
    out = capsys.readouterr().out
    assert "next:" in out and "--check" in out


def test_a_check_planned_without_touches_builds_from_its_frames_alone(check_rec, robot, tmp_path):
    """``--touches none``: no marks are needed; the check folder's touches.csv holds its header alone (a
    rebuild never keeps an earlier check's touches), and ``verify`` reads the check without touches."""
    from brachycal.calibration.verify.check import read_check_session

    build = build_check(write_recording(check_rec, tmp_path / "rec"), robot, (), marks=False)
    assert not build.session.touches and len(build.session.sample_ids) == len(check_rec.plan.poses)
    write_build(build, tmp_path / "check")
    assert (tmp_path / "check" / "touches.csv").read_text().count("\n") == 1
    assert read_check_session(tmp_path / "check", robot).touches == []

"""Hostile input files: every command refuses, in one line naming the file, an input that is not a
regular file — a device without end (``/dev/zero``), a FIFO (a named pipe: no writer, or one that
never stops), a folder — at once, before reading a byte of it (exit code 2, nothing written).

The table is every command × every input file it takes × the three kinds of file; the other
inputs of each row are valid (a calibration result, a twin recording, a water-tank recording and
the bundled examples), so that the row's input is the one refused. A FIFO row would hang forever
if the FIFO were opened for reading: the refusal happens when it is checked.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli

from brachycal.model import Robot
from brachycal.model.description_file import example_robot_data_share
from brachycal.simulation import RecordingConfig, TwinConfig, record, write_recording
from brachycal.studies.tank_recording import write_tank_recording

EXAMPLES = ROOT / "examples"
SESSION = EXAMPLES / "session_exact"

#: The kinds of non-regular file: (id, path given on the command line, setup, words of the refusal).
KINDS: list[tuple[str, str, Callable[[Path], None] | None, tuple[str, ...]]] = [
    ("dev-zero", "/dev/zero", None, ("/dev/zero", "is a device", "regular file")),
    ("fifo", "{tmp}/bad", lambda tmp: os.mkfifo(tmp / "bad"), ("bad", "FIFO", "regular file")),
    ("folder", "{tmp}/bad", lambda tmp: (tmp / "bad").mkdir(), ("bad", "is a folder")),
]

BUILD = "session build {rec}/joint_log.csv --marks {rec}/marks.csv --images {rec}/images.csv --plan {rec}/plan.csv"

#: Each command's input files: (id, the command with ``{bad}`` where the input goes).
USES = [
    ("locate-result", "locate {bad} {examples}/joints.csv --uv 10,10"),
    ("locate-joints", "locate {result} {bad} --uv 10,10"),
    ("export-result", "export {bad} --out {tmp}/x"),
    ("verify-result", "verify {bad} {session} --out {tmp}/r.json"),
    ("plan-result", "plan --result {bad} --out {tmp}/p.csv"),
    ("plan-robot", "plan --robot {bad} --out {tmp}/p.csv"),
    ("plan-check-result", "plan check --result {bad} --out {tmp}/p.csv"),
    ("fk-log", "fk {bad} --frames needle_tip --out {tmp}/p.csv --quiet"),
    ("fk-times", "fk {examples}/joint_log.csv --frames needle_tip --times {bad} --out {tmp}/p.csv --quiet"),
    ("pivot-poses", "pivot {bad} --out {tmp}/p.json"),
    ("phantom-geometry", "phantom wedge {bad} {examples}/phantom/wedge_observations.csv --out {tmp}/p.json"),
    ("phantom-observations", "phantom wedge {examples}/phantom/multi_wedge.toml {bad} --out {tmp}/p.json"),
    (
        "session-build-log",
        BUILD.replace("{rec}/joint_log.csv", "{bad}") + " --template {rec}/session.toml --out {tmp}/s",
    ),
    ("session-build-marks", BUILD.replace("{rec}/marks.csv", "{bad}") + " --template {rec}/session.toml --out {tmp}/s"),
    (
        "session-build-images",
        BUILD.replace("{rec}/images.csv", "{bad}") + " --template {rec}/session.toml --out {tmp}/s",
    ),
    ("session-build-plan", BUILD.replace("{rec}/plan.csv", "{bad}") + " --template {rec}/session.toml --out {tmp}/s"),
    ("session-build-template", BUILD + " --template {bad} --out {tmp}/s"),
    ("session-build-markups", BUILD + " --markups {bad} --template {rec}/session.toml --out {tmp}/s"),
    ("calibrate-robot", "calibrate {session} --robot {bad} --out {tmp}/r.json --quiet"),
    ("calibrate-urdf", "calibrate {session} --urdf {bad} --out {tmp}/r.json --quiet"),
    ("nwire-config", "nwire {bad} {examples}/nwire/twin_segmented_frames.xml --out {tmp}/n.json"),
    ("nwire-frames", "nwire {examples}/nwire/PlusDeviceSet_twin_fCal2.xml {bad} --out {tmp}/n.json"),
    (
        "nwire-segment-sequence",
        "nwire segment {bad} --config {examples}/nwire/PlusDeviceSet_twin_fCal2.xml --out {tmp}/f.xml",
    ),
    ("nwire-segment-config", "nwire segment {tank}/video.mha --config {bad} --out {tmp}/f.xml"),
    ("tips-frames", "tips {bad} --out {tmp}/i.csv"),
    ("tips-truth", "tips {tank}/video.mha --truth {bad} --out {tmp}/i.csv"),
    ("temporal-video", "temporal {bad} {tank}/tracker.mha --out {tmp}/t.json"),
    ("temporal-tracker", "temporal {tank}/video.mha {bad} --out {tmp}/t.json"),
    ("temporal-config", "temporal {tank}/video.mha {tank}/tracker.mha --config {bad} --out {tmp}/t.json"),
    ("temporal-joints", "temporal {tank}/video.mha --joints {bad} --out {tmp}/t.json"),
    ("view-result", "view {bad} --session {session}"),
    ("view-plan", "view --plan {bad}"),
    (
        "stepper-calibrate-recording",
        "stepper calibrate {bad} {tank}/video.mha {tank}/video.mha --config {stepper_config} --out {tmp}/s.json",
    ),
    (
        "stepper-calibrate-config",
        "stepper calibrate {tank}/video.mha {tank}/video.mha {tank}/video.mha --config {bad} --out {tmp}/s.json",
    ),
    (
        "stepper-image-rotation",
        "stepper image {bad} {tank}/video.mha {tank}/video.mha --config {stepper_config} --recorded-poses "
        "--out {tmp}/s.json",
    ),
    (
        "stepper-image-config",
        "stepper image {tank}/video.mha {tank}/video.mha {tank}/video.mha --config {bad} --out {tmp}/s.json",
    ),
    ("stepper-template-result", "stepper template {bad} --config {stepper_config} --hole D4 --probe-position 0"),
    ("stepper-export-result", "stepper export {bad} --out {tmp}/x"),
    (
        "robot-touches-urdf",
        "robot identify touches {examples}/touches/front {examples}/touches/left --urdf {bad} "
        "--tool-frame panda_hand_tcp --train front --out {tmp}/x",
    ),
    (
        "robot-tracker-table",
        "robot identify tracker {bad} --columns {examples}/tracker/columns.toml --urdf {ur10} --out {tmp}/x",
    ),
    (
        "robot-tracker-columns",
        "robot identify tracker {examples}/tracker/table.csv --columns {bad} --urdf {ur10} --out {tmp}/x",
    ),
]

CASES = [
    Case(f"{use}-{kind}", command.replace("{bad}", bad).split(), words, setup)
    for use, command in USES
    for kind, bad, setup, words in KINDS
]


def session_file_is(name: str, make: Callable[[Path], None]) -> Callable[[Path], None]:
    """A copy of the example session in ``{tmp}/s`` whose ``name`` is made by ``make(path)``."""

    def setup(tmp: Path) -> None:
        shutil.copytree(SESSION, tmp / "s")
        (tmp / "s" / name).unlink()
        make(tmp / "s" / name)

    return setup


# A session's own files (the folder is the input): refused naming the file, not "missing".
for _name in ("samples.csv", "session.toml", "touches.csv"):
    CASES += [
        Case(
            f"calibrate-session-{_name}-fifo",
            ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"],
            (_name, "FIFO"),
            session_file_is(_name, os.mkfifo),
        ),
        Case(
            f"calibrate-session-{_name}-folder",
            ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"],
            (_name, "is a folder"),
            session_file_is(_name, Path.mkdir),
        ),
    ]
CASES += [
    Case(
        "verify-check-session-samples-fifo",
        ["verify", "{result}", "{tmp}/s", "--out", "{tmp}/r.json"],
        ("samples.csv", "FIFO"),
        session_file_is("samples.csv", os.mkfifo),
    ),
    Case(
        "session-symlink-to-dev-zero",
        ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"],
        ("axes.csv", "is a device"),
        session_file_is("axes.csv", lambda path: path.symlink_to("/dev/zero")),
    ),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Valid inputs, outside the cases' folders: a result, a twin recording, a water-tank recording."""
    folder = tmp_path_factory.mktemp("inputs")
    result = folder / "result.json"
    assert run_cli(["calibrate", str(SESSION), "--out", str(result), "--quiet"]).code == 0
    rec = record(Robot.load(), TwinConfig(seed=4), RecordingConfig(rate_hz=25.0, speed_scale=0.5, hold_s=1.6))
    write_recording(rec, folder / "rec")
    write_tank_recording(folder / "tank")
    # A stepper device set: the twin's N-wire set with an iCal element (PLUS's TRUS-on-stepper set-up).
    twin_config = (EXAMPLES / "nwire" / "PlusDeviceSet_twin_fCal2.xml").read_text()
    ical = '<iCal ProbeCoordinateFrame="Probe" TemplateCoordinateFrame="Template" />'
    (folder / "stepper.xml").write_text(twin_config.replace("</PlusConfiguration>", ical + "</PlusConfiguration>"))
    return {
        "result": result,
        "rec": folder / "rec",
        "tank": folder / "tank",
        "session": SESSION,
        "examples": EXAMPLES,
        "stepper_config": folder / "stepper.xml",
        "ur10": example_robot_data_share() / "robots" / "ur_description" / "urdf" / "ur10_robot.urdf",
    }


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_a_non_regular_input_file_is_refused_at_once(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)


def test_every_command_that_reads_a_file_is_in_the_table():
    """A new command (or input option) gets its rows here: every command of ``brachycal --help``
    that names an input file is used by some row."""
    from brachycal.cli.main import COMMANDS, TWO_WORD_COMMANDS

    used = {TWO_WORD_COMMANDS.get(tuple(command.split()[:2]), command.split()[0]) for _, command in USES}
    # plan excitation reads a session folder (its refusals: tests/test_hostile_excitation.py)
    without_input_files = {"demo", "model", "study", "design", "examples", "plan-excitation"}
    assert set(COMMANDS) - without_input_files - {"session"} <= used | {"session"}
    assert "session" in {command.split()[0] for _, command in USES}


# --- messages that misled -------------------------------------------------------------------------
def session_with(name: str, edit: Callable[[str], str]) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        shutil.copytree(SESSION, tmp / "s")
        (tmp / "s" / name).write_text(edit((tmp / "s" / name).read_text()))

    return setup


def poses(count: int) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        lines = (EXAMPLES / "pivot" / "pointer_pivot.csv").read_text().splitlines()
        (tmp / "p.csv").write_text("\n".join(lines[: 1 + count]) + "\n")

    return setup


MISLED = [
    Case(
        "session-size-px-1e30",  # was printed as 9223372036854775807
        ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"],
        ("session.toml", "image.size_px", "1e+30", "at most 10000 px"),
        session_with("session.toml", lambda text: text.replace("[1080, 720]", "[1e30, 720]")),
    ),
    *(
        Case(
            f"session-sector-{name}",
            ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--quiet"],
            ("session.toml", *words),
            session_with(
                "session.toml", lambda text, lines=sector: text.replace("[top_model]", f"{lines}\n[top_model]")
            ),
        )
        for name, sector, words in (
            ("not-a-table", "sector = 70", ("image.sector", "expected a table")),
            (
                "apex-one-number",
                "[image.sector]\napex_px = 540\ndepth_mm = 70\nangle_deg = 120",
                ("image.sector.apex_px", "a list of 2 numbers"),
            ),
            (
                "depth-missing",
                "[image.sector]\napex_px = [540, 0]\nangle_deg = 120",
                ("image.sector.depth_mm", "expected a number, got None"),
            ),
            (
                "depth-in-metres-zero",
                "[image.sector]\napex_px = [540, 0]\ndepth_mm = 0\nangle_deg = 120",
                ("image.sector.depth_mm", "(0, 500] mm", "got 0 mm"),
            ),
            (
                "depth-nan",
                "[image.sector]\napex_px = [540, 0]\ndepth_mm = nan\nangle_deg = 120",
                ("image.sector.depth_mm", "finite"),
            ),
            (
                "angle-beyond-180",
                "[image.sector]\napex_px = [540, 0]\ndepth_mm = 70\nangle_deg = 200",
                ("image.sector.angle_deg", "(0, 180] deg", "got 200 deg"),
            ),
            (
                "apex-1e30",
                "[image.sector]\napex_px = [1e30, 0]\ndepth_mm = 70\nangle_deg = 120",
                ("image.sector.apex_px", "[-10000, 10000] px"),
            ),
        )
    ),
    Case("pivot-no-poses", ["pivot", "{tmp}/p.csv", "--out", "{tmp}/o.json"], ("p.csv", "0 poses"), poses(0)),
    Case("pivot-two-poses", ["pivot", "{tmp}/p.csv", "--out", "{tmp}/o.json"], ("p.csv", "2 poses"), poses(2)),
    Case(
        "result-nested-too-deeply",  # was a traceback (RecursionError)
        ["locate", "{tmp}/r.json", "{examples}/joints.csv", "--uv", "10,10"],
        ("r.json", "not valid JSON", "nested more than"),
        lambda tmp: (tmp / "r.json").write_text("[" * 100_000 + "]" * 100_000),
    ),
    Case(
        "robot-description-nested-too-deeply",
        ["calibrate", "{session}", "--robot", "{tmp}/r.toml", "--out", "{tmp}/o.json", "--quiet"],
        ("r.toml", "not valid TOML", "recursion"),
        lambda tmp: (tmp / "r.toml").write_text("a = " + "[" * 100_000 + "]" * 100_000),
    ),
    Case(
        "template-dev-zero",  # was "no such file"
        [*BUILD.split(), "--template", "/dev/zero", "--out", "{tmp}/s"],
        ("/dev/zero", "is a device"),
    ),
]


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in MISLED])
def test_a_refusal_says_what_is_wrong_and_names_the_file(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)


# --- a UTF-8 byte-order mark (a spreadsheet's CSV export) is accepted -------------------------------
def with_bom(source: Path, target: Path) -> Path:
    target.write_bytes(b"\xef\xbb\xbf" + source.read_bytes())
    return target


@pytest.mark.parametrize(
    "argv",
    [
        ["fk", "{input}", "--frames", "needle_tip", "--out", "{out}/p.csv", "--quiet"],
        ["locate", "{result}", "{input}", "--uv", "10,10"],
    ],
    ids=["fk", "locate"],
)
def test_a_joint_log_with_a_byte_order_mark_reads_as_without(argv, tmp_path, inputs):
    """Was refused as having "no 'time' column" (the header's first name was '\\ufefftime')."""
    outcomes = []
    for name, log in (
        ("plain", EXAMPLES / "joint_log.csv"),
        ("bom", with_bom(EXAMPLES / "joint_log.csv", tmp_path / "b.csv")),
    ):
        (tmp_path / name).mkdir()
        words = [a.format(input=log, out=tmp_path / name, result=inputs["result"]) for a in argv]
        outcome = run_cli(words)
        assert outcome.code == 0, outcome.err
        outcomes.append((outcome.out, *(p.read_bytes() for p in sorted((tmp_path / name).iterdir()))))
    assert outcomes[0] == outcomes[1]


def test_session_files_and_a_pose_list_with_a_byte_order_mark_read_as_without(tmp_path):
    shutil.copytree(SESSION, tmp_path / "s")
    for name in ("samples.csv", "touches.csv", "session.toml"):
        with_bom(SESSION / name, tmp_path / "s" / name)
    plain = run_cli(["calibrate", str(SESSION), "--out", str(tmp_path / "a.json"), "--quiet"])
    bom = run_cli(["calibrate", str(tmp_path / "s"), "--out", str(tmp_path / "b.json"), "--quiet"])
    assert plain.code == bom.code == 0, bom.err
    assert plain.out.replace("a.json", "b.json") == bom.out
    pivot = EXAMPLES / "pivot" / "pointer_pivot.csv"
    plain = run_cli(["pivot", str(pivot), "--units", "mm", "--out", str(tmp_path / "p.json")])
    bom = run_cli(
        [
            "pivot",
            str(with_bom(pivot, tmp_path / "pointer_pivot.csv")),
            "--units",
            "mm",
            "--out",
            str(tmp_path / "q.json"),
        ]
    )
    assert plain.code == bom.code == 0, bom.err
    assert plain.out.replace("p.json", "q.json") == bom.out


def test_a_fifo_being_written_slowly_is_refused_at_once_not_read(tmp_path):
    """A writer holds the FIFO open and feeds it a joint log line by line: read, it would never end
    (and a read blocked in C would not see SIGTERM); ``fk`` refuses it before reading a byte."""
    import subprocess
    import sys
    import threading
    import time

    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    stop = threading.Event()

    def write_slowly() -> None:
        # open blocks until a reader opens the FIFO (ours does, to check it); the reader's going
        # away ends the writing with a broken pipe
        with contextlib.suppress(BrokenPipeError), open(fifo, "w") as handle:
            for line in (EXAMPLES / "joint_log.csv").read_text().splitlines(keepends=True):
                if stop.is_set():
                    return
                handle.write(line)
                handle.flush()
                time.sleep(0.05)

    writer = threading.Thread(target=write_slowly, daemon=True)
    writer.start()
    argv = [sys.executable, "-m", "brachycal.cli.main", "fk", str(fifo), "--frames", "needle_tip"]
    try:
        done = subprocess.run([*argv, "--out", str(tmp_path / "p.csv")], capture_output=True, text=True, timeout=120)
    finally:
        stop.set()
        with contextlib.suppress(OSError):  # let the writer's open return if no reader ever came
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))
        writer.join(timeout=10)
    assert done.returncode == 2
    assert (
        done.stderr
        == f"brachycal: error: {fifo}: is a FIFO (named pipe), not a regular file; an input must be a regular file\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv"]

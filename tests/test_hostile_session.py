"""Hostile inputs to ``brachycal session build``: each refused with one line naming the file, the
row (or message, or control point) and the problem — a mark taken while the robot moved, a frame
outside the image, a session short of a touch, options that contradict each other — exit code 2,
nothing written.

Every case starts from a copy of one twin recording (a short one: 25 Hz, quick moves) in its own
folder, with one defect.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.model import Robot
from brachycal.simulation import RecordingConfig, TwinConfig, record, write_recording
from brachycal.studies.check_twin import CHANGES, check_recording

BUILD = [
    "session",
    "build",
    "{tmp}/joint_log.csv",
    "--marks",
    "{tmp}/marks.csv",
    "--images",
    "{tmp}/images.csv",
    "--plan",
    "{tmp}/plan.csv",
    "--template",
    "{tmp}/session.toml",
    "--out",
    "{tmp}/session",
]
#: The recording every case copies, and a moment in the middle of its fastest move.
_SOURCE: dict[str, object] = {}


@pytest.fixture(scope="module", autouse=True)
def source(tmp_path_factory):
    robot = Robot.load()
    rec = record(robot, TwinConfig(seed=4), RecordingConfig(rate_hz=25.0, speed_scale=0.5, hold_s=1.6))
    _SOURCE["folder"] = write_recording(rec, tmp_path_factory.mktemp("hostile_session") / "rec")
    check = check_recording(rec, robot, CHANGES["unchanged"], 1)
    _SOURCE["check"] = write_recording(check, tmp_path_factory.mktemp("hostile_check") / "rec")
    speed = np.abs(np.diff(rec.q_true, axis=0)).max(axis=1)
    _SOURCE["moving"] = float(rec.time[int(np.argmax(speed))])
    _SOURCE["end"] = float(rec.time[-1])
    return _SOURCE


def with_copy(*edits: Callable[[Path], None], source: str = "folder"):
    """Copy the recording (``source="check"``: the check recording) into the case's folder, then
    apply ``edits`` to it."""

    def setup(tmp: Path) -> None:
        for item in Path(_SOURCE[source]).iterdir():  # type: ignore[arg-type]
            if item.is_file():
                shutil.copyfile(item, tmp / item.name)
        for edit in edits:
            edit(tmp)

    return setup


def edit_csv(name: str, change: Callable[[list[str]], list[str]]):
    """Rewrite ``name``'s lines (header included) with ``change``."""

    def edit(tmp: Path) -> None:
        path = tmp / name
        path.write_text("\n".join(change(path.read_text().splitlines())) + "\n")

    return edit


def set_field(name: str, line: int, column: str, value: object):
    """Set ``column`` of file line ``line`` (header = 1) of ``name``; ``"{moving}"``/``"{end}"`` are
    the recording's moving moment and end."""

    def change(lines: list[str]) -> list[str]:
        header = lines[0].split(",")
        fields = lines[line - 1].split(",")
        fields[header.index(column)] = str(value).format(moving=_SOURCE["moving"], end=_SOURCE["end"])
        lines[line - 1] = ",".join(fields)
        return lines

    return edit_csv(name, change)


def drop_lines(name: str, keep: Callable[[str], bool]):
    return edit_csv(name, lambda lines: [lines[0], *(line for line in lines[1:] if keep(line))])


def images_without_uv(tmp: Path) -> None:
    lines = (tmp / "images.csv").read_text().splitlines()
    (tmp / "images.csv").write_text("time\n" + "\n".join(line.split(",")[0] for line in lines[1:]) + "\n")


def markups(z_first: float = 0.0):
    """A Slicer point list with one point per frame; the first ``z_first`` mm off the plane."""

    def edit(tmp: Path) -> None:
        count = len((tmp / "images.csv").read_text().splitlines()) - 1
        points = [{"label": f"F-{k}", "position": [19.0, 19.0, z_first if k == 0 else 0.0]} for k in range(count)]
        payload = {"markups": [{"type": "Fiducial", "coordinateSystem": "LPS", "controlPoints": points}]}
        (tmp / "tips.mrk.json").write_text(json.dumps(payload))

    return edit


def replace_text(name: str, old: str, new: str):
    """Replace the first ``old`` in ``name`` by ``new``."""

    def edit(tmp: Path) -> None:
        text = (tmp / name).read_text()
        assert old in text, f"{old!r} not in {name}"
        (tmp / name).write_text(text.replace(old, new, 1))

    return edit


def write(name: str, text: str):
    def edit(tmp: Path) -> None:
        (tmp / name).parent.mkdir(exist_ok=True)
        (tmp / name).write_text(text)

    return edit


def every_tenth_reading(tmp: Path) -> None:
    lines = (tmp / "joint_log.csv").read_text().splitlines()
    (tmp / "joint_log.csv").write_text("\n".join([lines[0], *lines[1::10]]) + "\n")


def with_samples(*names: str):
    """A ``sample`` column in ``images.csv``: ``names`` (raw CSV text) for the first frames, then ``s<k>``."""

    def change(lines: list[str]) -> list[str]:
        given = [*names, *(f"s{k}" for k in range(len(names), len(lines) - 1))]
        return [f"sample,{lines[0]}", *(f"{name},{line}" for name, line in zip(given, lines[1:], strict=True))]

    return edit_csv("images.csv", change)


def cut_last_line(name: str, keep: int = 4):
    """``name`` cut inside its last number (the last ``keep`` characters of it dropped, no final newline):
    what a logger killed mid-write leaves."""

    def edit(tmp: Path) -> None:
        path = tmp / name
        path.write_text(path.read_text().rstrip("\n")[:-keep])

    return edit


MARKUPS = [*BUILD[:6], "{tmp}/images.csv", "--markups", "{tmp}/tips.mrk.json", *BUILD[7:]]

CASES = [
    # --- marks ------------------------------------------------------------------------------------
    Case(
        "mark-while-moving",
        BUILD,
        ("marks.csv, row 3", "touch mark top_model rtip1", "the robot was moving", "rad/s"),
        with_copy(set_field("marks.csv", 3, "time", "{moving}")),
    ),
    Case(
        "mark-after-the-log",
        BUILD,
        ("marks.csv, row 2", "outside the log's span"),
        with_copy(set_field("marks.csv", 2, "time", "{end}5")),
    ),
    Case(
        "mark-at-the-log-end",
        BUILD,
        ("marks.csv, row 2", "still window", "never extrapolated"),
        with_copy(set_field("marks.csv", 2, "time", "{end}")),
    ),
    Case(
        "unknown-kind",
        BUILD,
        ("marks.csv, row 4, column 'kind'", "unknown kind 'tuch'"),
        with_copy(set_field("marks.csv", 4, "kind", "tuch")),
    ),
    Case(
        "unknown-tool",
        BUILD,
        ("marks.csv, row 4, column 'tool'", "unknown tool 'needel'"),
        with_copy(set_field("marks.csv", 4, "tool", "needel")),
    ),
    Case(
        "unknown-name",
        BUILD,
        ("marks.csv, row 4, column 'name'", "unknown reference tip 'rtip3'"),
        with_copy(set_field("marks.csv", 4, "name", "rtip3")),
    ),
    Case(
        "time-not-a-number",
        BUILD,
        ("marks.csv, row 5, column 'time'", "'12:03' is not a number"),
        with_copy(set_field("marks.csv", 5, "time", "12:03")),
    ),
    Case(
        "no-probe-touches-on-rtip2",
        BUILD,
        ("marks.csv", "no touch mark of probe on rtip2"),
        with_copy(drop_lines("marks.csv", lambda line: not line.endswith("touch,probe,rtip2"))),
    ),
    Case(
        "one-needle-touch-short",
        BUILD,
        ("marks.csv", "unequal touches on rtip1", "needle 2"),
        with_copy(edit_csv("marks.csv", lambda lines: [ln for k, ln in enumerate(lines) if k != 4])),
    ),
    Case(
        "axes-point-twice",
        BUILD,
        ("marks.csv", "needle p1 is marked twice"),
        with_copy(
            edit_csv("marks.csv", lambda lines: [ln.replace("axes,needle,p2", "axes,needle,p1") for ln in lines])
        ),
    ),
    Case("no-marks", BUILD, ("marks.csv", "no marks"), with_copy(write("marks.csv", "time,kind,tool,name\n"))),
    # --- frames -----------------------------------------------------------------------------------
    Case(
        "frame-while-moving",
        BUILD,
        ("images.csv, row 3", "the robot was moving"),
        with_copy(set_field("images.csv", 3, "time", "{moving}")),
    ),
    Case(
        "pixel-outside-image",
        BUILD,
        ("images.csv, row 3", "v = 900 px is outside the 1080 x 720 px image"),
        with_copy(set_field("images.csv", 3, "v_px", "900")),
    ),
    Case(
        "u-without-v",
        BUILD,
        ("images.csv, row 3, column 'v_px'", "empty while u_px is given"),
        with_copy(set_field("images.csv", 3, "v_px", "")),
    ),
    Case(
        "sample-twice",
        BUILD,
        ("images.csv, row 3, column 'sample'", "sample 'g000' appears twice (also row 2)"),
        with_copy(
            edit_csv(
                "images.csv",
                lambda lines: [
                    lines[0] + ",sample",
                    *(f"{ln},{'g000' if k < 2 else f's{k}'}" for k, ln in enumerate(lines[1:])),
                ],
            )
        ),
    ),
    Case(
        "two-frames-only",
        BUILD,
        ("images.csv", "2 annotated frame(s) usable"),
        with_copy(edit_csv("images.csv", lambda lines: lines[:3])),
    ),
    Case(
        "markup-off-the-plane",
        MARKUPS,
        ("tips.mrk.json, control point 1", "0.7 mm off the frame's plane"),
        with_copy(images_without_uv, markups(z_first=0.7)),
    ),
    # The markups file is read by the bounded JSON reader: no NaN, no special file.
    Case(
        "markup-position-nan",
        MARKUPS,
        ("tips.mrk.json", "markups[0].controlPoints[0].position[0]", "NaN is not a finite number"),
        with_copy(images_without_uv, markups(), replace_text("tips.mrk.json", "[19.0, 19.0, 0.0]", "[NaN, 19.0, 0.0]")),
    ),
    Case(
        "markups-a-fifo",
        MARKUPS,
        ("tips.mrk.json", "is a FIFO"),
        with_copy(images_without_uv, lambda tmp: os.mkfifo(tmp / "tips.mrk.json")),
    ),
    Case(
        "markups-and-uv-columns",
        MARKUPS,
        ("images.csv", "has u_px/v_px columns", "give them in one place"),
        with_copy(markups()),
    ),
    Case(
        "time-with-digit-separator",
        BUILD,
        ("marks.csv, row 5, column 'time'", "'1_700_000_020.5' is not a number"),
        with_copy(set_field("marks.csv", 5, "time", "1_700_000_020.5")),
    ),
    Case(
        "marks-cut-mid-number",
        BUILD,
        ("marks.csv, row", "the last line has no newline", "truncated"),
        with_copy(cut_last_line("marks.csv", keep=12)),
    ),
    # --- frames -----------------------------------------------------------------------------------
    Case(
        "sample-name-with-comma",
        BUILD,
        ("images.csv, row 3, column 'sample'", "'s,1' is not a plain token"),
        with_copy(with_samples("s0", '"s,1"')),
    ),
    Case(
        "sample-name-with-quote",
        BUILD,
        ("images.csv, row 2, column 'sample'", "is not a plain token"),
        with_copy(with_samples('s"0')),
    ),
    Case(
        "sample-name-with-newline",
        BUILD,
        ("images.csv, row 3, column 'sample'", "is not a plain token"),  # the record's last line
        with_copy(with_samples('"s\n0"')),
    ),
    Case(
        "frame-listed-twice",
        BUILD,
        ("images.csv, row 3, column 'time'", "listed twice (also row 2)"),
        with_copy(edit_csv("images.csv", lambda lines: [lines[0], lines[1], *lines[1:]])),
    ),
    Case(
        "pixel-in-hex",
        BUILD,
        ("images.csv, row 2, column 'u_px'", "'0x1b2' is not a number"),
        with_copy(set_field("images.csv", 2, "u_px", "0x1b2")),
    ),
    Case(
        "pixel-in-arabic-indic-digits",
        BUILD,
        ("images.csv, row 2, column 'v_px'", "is not a number"),
        with_copy(set_field("images.csv", 2, "v_px", "\u0661\u0661\u0660")),
    ),
    Case(
        "images-cut-mid-number",
        BUILD,
        ("images.csv, row", "the last line has no newline"),
        with_copy(cut_last_line("images.csv")),
    ),
    # --- log and plan -----------------------------------------------------------------------------
    Case(
        "log-cut-mid-number",
        BUILD,
        ("joint_log.csv, row", "the last line has no newline", "truncated"),
        with_copy(cut_last_line("joint_log.csv", keep=7)),
    ),
    Case(
        "plan-point-with-comma",
        BUILD,
        ("plan.csv, row 2, column 'point'", "'g,000' is not a plain token"),
        with_copy(edit_csv("plan.csv", lambda lines: [lines[0], lines[1].replace(",g000,", ',"g,000",'), *lines[2:]])),
    ),
    Case(
        "plan-joint-with-digit-separator",
        BUILD,
        ("plan.csv, row 2, column 'arm_left_joint_2_l'", "'1_3' is not a number"),
        with_copy(set_field("plan.csv", 2, "arm_left_joint_2_l", "1_3")),
    ),
    Case("no-log", [*BUILD[:2], "{tmp}/missing.csv", *BUILD[3:]], ("missing.csv", "no such file"), with_copy()),
    Case(
        "sparse-log",
        BUILD,
        ("marks.csv, row 2", "too sparse", "speed span"),
        with_copy(every_tenth_reading),
    ),
    Case(
        "plan-in-degrees",
        BUILD,
        ("plan.csv, row 2, column 'arm_left_joint_2_l'", "looks like degrees"),
        with_copy(set_field("plan.csv", 2, "arm_left_joint_2_l", "-57.3")),
    ),
    # --- options ----------------------------------------------------------------------------------
    Case("lag-not-a-number", [*BUILD, "--lag-s", "nan"], ("--lag-s", "nan"), with_copy()),
    Case("lag-infinite", [*BUILD, "--lag-s", "inf"], ("--lag-s", "inf"), with_copy()),
    Case("lag-sd-negative", [*BUILD, "--lag-sd-s", "-0.01"], ("--lag-sd-s", "-0.01"), with_copy()),
    Case(
        "marks-twice",
        [*BUILD, "--marks-topic", "/marks"],
        ("--marks-topic", "not allowed with argument --marks"),
        with_copy(),
    ),
    Case(
        "marks-topic-on-csv",
        [*BUILD[:3], "--marks-topic", "/marks", *BUILD[5:]],
        ("--marks-topic needs a ROS bag",),
        with_copy(),
    ),
    Case(
        "no-template-no-settings",
        BUILD[:-4] + BUILD[-2:],
        ("without a template session.toml", "--spacing-mm, --size-px, --top-model-tip-mm"),
        with_copy(),
    ),
    Case(
        "spacing-in-metres",
        [*BUILD, "--spacing-mm", "0.00019,0.00019"],
        ("--spacing-mm", "looks like a spacing in metres"),
        with_copy(),
    ),
    Case("size-one-number", [*BUILD, "--size-px", "1080"], ("--size-px", "2 comma-separated"), with_copy()),
    Case(
        "span-longer-than-window",
        [*BUILD, "--speed-span-s", "2"],
        ("--speed-span-s 2 s is longer than --still-window-s 1 s",),
        with_copy(),
    ),
    Case("still-speed-zero", [*BUILD, "--max-speed-rad-s", "0"], ("--max-speed-rad-s", "(0, 1]"), with_copy()),
    Case("window-nan", [*BUILD, "--still-window-s", "nan"], ("--still-window-s", "finite"), with_copy()),
    Case(
        "template-wrong-format",
        BUILD,
        ("session.toml", "key 'format'", "brachycal-session/1"),
        with_copy(edit_csv("session.toml", lambda lines: ['format = "brachycal-session/9"', *lines[1:]])),
    ),
    Case(
        "session-exists",
        BUILD,
        ("session/session.toml", "already exists", "--force"),
        with_copy(write("session/session.toml", "an earlier session\n")),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_session_build_refusals(case, tmp_path):
    check_refusal(case, tmp_path)


def _blank(tmp: Path) -> None:
    from brachycal.data.session_template import write_session_template

    write_session_template(tmp / "blank")


TEMPLATE = ["session", "template", "{tmp}/blank"]
TEMPLATE_CASES = [
    Case(
        "template-over-a-filled-one",
        TEMPLATE,
        ("blank/session.toml", "already exists", "--force"),
        write("blank/session.toml", "a lab's filled-in session.toml\n"),
    ),
    Case("template-dir-is-a-file", TEMPLATE, ("blank",), write("blank", "not a folder\n")),
    Case(
        "build-from-an-unfilled-template",
        [
            "session",
            "build",
            "{tmp}/joint_log.csv",
            "--marks",
            "{tmp}/blank/marks.csv",
            "--images",
            "{tmp}/blank/images.csv",
            "--template",
            "{tmp}/blank/session.toml",
            "--out",
            "{tmp}/session",
        ],
        ("blank/session.toml", "key 'image.spacing_mm'", "expected a list of 2 numbers"),
        _blank,
    ),
]


@pytest.mark.parametrize("case", TEMPLATE_CASES, ids=lambda c: c.id)
def test_session_template_refusals(case, tmp_path):
    """``session template`` never replaces a lab's files unasked; an unfilled template is refused by the build."""
    check_refusal(case, tmp_path)


CHECK = [*BUILD[:-1], "{tmp}/check_session", "--check"]
CHECK_CASES = [
    Case(
        "check-without-its-touch",
        CHECK,
        ("marks.csv", "no touch mark of probe on rtip1", "--touches none"),
        with_copy(drop_lines("marks.csv", lambda line: ",probe," not in line), source="check"),
    ),
    Case(
        "check-without-the-needles-planned-touch",
        [*CHECK, "--touches", "both"],
        ("marks.csv", "no touch mark of needle on rtip1"),
        with_copy(source="check"),
    ),
    Case(
        "check-without-marks",
        [*CHECK[:3], *CHECK[5:]],
        ("give the check's marks", "--marks", "probe"),
        with_copy(source="check"),
    ),
    Case(
        "check-of-two-frames",
        CHECK,
        ("images.csv", "2 annotated frame(s) usable", "a check needs at least 3"),
        with_copy(edit_csv("images.csv", lambda lines: lines[:3]), source="check"),
    ),
    Case(
        "check-recording-given-to-a-session-build",
        BUILD,
        ("marks.csv", "no top-model touches and no axes points", "a check recording", "--check"),
        with_copy(source="check"),
    ),
    Case(
        "session-recording-given-to-a-check-build",
        CHECK,
        ("marks.csv, row 2", "a check recording has no", "without --check"),
        with_copy(),
    ),
    Case(
        "check-with-an-axes-mark",
        CHECK,
        ("marks.csv, row 3", "axes mark needle p1", "a check recording has no axes moves"),
        with_copy(
            edit_csv("marks.csv", lambda lines: [*lines, lines[1].replace("touch,probe,rtip1", "axes,needle,p1")]),
            source="check",
        ),
    ),
    Case("demo-check-without-recording", ["demo", "--check", "--out", "{tmp}/run"], ("--check", "--recording")),
    Case(
        "touches-without-check",
        [*BUILD, "--touches", "probe"],
        ("--touches", "give --check too"),
        with_copy(),
    ),
    Case(
        "check-session-exists",
        CHECK,
        ("check_session/samples.csv", "already exists", "--force"),
        with_copy(write("check_session/samples.csv", "an earlier check\n"), source="check"),
    ),
]


@pytest.mark.parametrize("case", CHECK_CASES, ids=lambda c: c.id)
def test_check_build_refusals(case, tmp_path):
    """``session build --check`` takes a check recording and nothing else: the check's planned touches,
    at least 3 annotated frames, no top-model touch or axes move; a check recording is not a session's."""
    check_refusal(case, tmp_path)
